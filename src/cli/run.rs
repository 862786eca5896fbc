//! `forgemon run --config FILE`: the always-on service. The configuration and every file it
//! names are read and checked before anything is opened (`ServiceParts::load`); then the
//! sources start and the service runs until SIGTERM.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use tokio::sync::{mpsc, watch};

use crate::acquire::serial::driver::{SerialConfig, SerialFormat as WireFormat};
use crate::config::service::{SerialFormat, SourceSpec};
use crate::daemon::{Hooks, SOURCE_CHANNEL_CAPACITY, ServiceParts, serve};

#[derive(Debug, Args)]
pub struct RunArgs {
    /// The service configuration: /etc/forgemon/forgemon.toml once the package is installed;
    /// annotated examples in config/*.service.toml (packaged: /usr/share/doc/forgemon/examples).
    #[arg(long)]
    pub config: PathBuf,
}

/// Read and check everything the service needs (`ServiceParts::load`); nothing is opened
/// yet. The process sheet's warnings go to stderr.
pub fn load_parts(config_path: &Path) -> anyhow::Result<ServiceParts> {
    let (parts, warnings) = ServiceParts::load(config_path)?;
    for w in warnings {
        eprintln!("forgemon: warning: {w}");
    }
    Ok(parts)
}

/// Start a source's task; it stops when `shutdown` turns true.
pub fn spawn_source(spec: &SourceSpec, tx: mpsc::Sender<crate::acquire::SourceEvent>, shutdown: watch::Receiver<bool>) {
    match spec {
        SourceSpec::Serial { name, path, baud, format, channels } => {
            let wire = match format {
                SerialFormat::Binary => WireFormat::Binary,
                SerialFormat::Ascii => WireFormat::Ascii,
            };
            let cfg = SerialConfig::new(name.clone(), path.clone(), *baud, wire, channels.clone());
            tokio::spawn(crate::acquire::serial::driver::run(cfg, tx, shutdown));
        }
        SourceSpec::Modbus(m) => {
            tokio::spawn(crate::acquire::modbus::run(m.clone(), tx, shutdown));
        }
        SourceSpec::Can(c) => {
            use crate::acquire::can::CanInput;
            let Ok(cfg) = c.resolve() else {
                tracing::error!(source = %c.name, "the DBC file changed since the start and no longer reads");
                return;
            };
            match &c.input {
                CanInput::Interface(_) => {
                    tokio::spawn(crate::acquire::can::run(cfg, tx, shutdown));
                }
                CanInput::Log(path) => {
                    let (path, name) = (path.clone(), c.name.clone());
                    tokio::spawn(async move {
                        if let Err(e) = crate::acquire::can::run_log(cfg, path, true, tx, shutdown).await {
                            tracing::error!(source = %name, "{e}");
                        }
                    });
                }
            }
        }
    }
}

pub fn run(args: RunArgs) -> anyhow::Result<ExitCode> {
    let parts = load_parts(&args.config)?;
    init_logging("info");
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async move {
        let (tx, rx) = mpsc::channel(SOURCE_CHANNEL_CAPACITY);
        let (shutdown_tx, shutdown_rx) = watch::channel(false);
        for s in &parts.config.sources {
            spawn_source(s, tx.clone(), shutdown_rx.clone());
        }
        // The service is always on: a source that ends (a log played out) does not stop it;
        // only SIGTERM does. Holding a sender keeps the channel open.
        let _hold_open = tx;
        let (_stop_tx, stop_rx) = watch::channel(false);
        let summary = serve(parts, rx, shutdown_tx, stop_rx, Hooks::default(), None).await?;
        tracing::info!(
            samples = summary.samples,
            blows = summary.blows,
            incomplete = summary.incomplete_blows,
            alerts = summary.alerts,
            dropped_events = summary.dropped_events,
            record_errors = summary.record_errors,
            blows_not_recorded = summary.dropped_blows,
            "stopped"
        );
        Ok::<_, anyhow::Error>(())
    })?;
    Ok(ExitCode::SUCCESS)
}

/// Logs to stderr (journald captures it under systemd), coloured only on a terminal;
/// `RUST_LOG` overrides `default_level` ("info" for the service, "error" for the demo,
/// which prints its own lines).
pub fn init_logging(default_level: &str) {
    // async-opcua logs an error when its certificate store is empty, which it is on purpose
    // for anonymous loopback sessions; a secured server that cannot make its certificate
    // stops the start with forgemon's own error (`daemon::opcua`).
    let quiet = "opcua_crypto::certificate_store=off";
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("{default_level},{quiet}")));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_ansi(ansi).with_writer(std::io::stderr).try_init();
}
