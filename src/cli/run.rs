//! `forgemon run --config FILE`: the always-on service. The configuration, the machine model
//! and the process sheet are read and checked before anything is opened; then the sources
//! start and the service runs until SIGTERM.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Args;
use tokio::sync::{mpsc, watch};

use super::read_text;
use crate::acquire::serial::driver::{SerialConfig, SerialFormat as WireFormat};
use crate::config::service::{SerialFormat, ServiceConfig, SourceSpec, parse_service};
use crate::config::{parse_machine, parse_process};
use crate::daemon::{Hooks, SOURCE_CHANNEL_CAPACITY, ServiceParts, serve};

#[derive(Debug, Args)]
pub struct RunArgs {
    /// The service configuration (see config/*.service.toml).
    #[arg(long)]
    pub config: PathBuf,
}

/// Read and check everything the service needs; nothing is opened yet.
pub fn load_parts(config_path: &Path) -> anyhow::Result<ServiceParts> {
    let text = read_text(config_path)?;
    let base = config_path.parent().unwrap_or(Path::new("."));
    let config: ServiceConfig = parse_service(&config_path.display().to_string(), base, &text)?;
    let machine_text = read_text(&config.machine_path).context("key 'machine'")?;
    let machine = parse_machine(&config.machine_path.display().to_string(), &machine_text)?.machine;
    let (process, process_text) = match &config.process_path {
        Some(p) => {
            let t = read_text(p).context("key 'process'")?;
            let proc_ = parse_process(&p.display().to_string(), &t)?;
            if proc_.machine != machine.kind() {
                bail!(
                    "{}: key 'machine' is \"{}\" but {} has kind \"{}\"",
                    p.display(),
                    proc_.machine.as_str(),
                    config.machine_path.display(),
                    machine.kind().as_str()
                );
            }
            (Some(proc_), Some(t))
        }
        None => (None, None),
    };
    // A CAN source's DBC file is read now, so that a bad one stops the start.
    for s in &config.sources {
        if let SourceSpec::Can(c) = s {
            c.resolve().with_context(|| format!("source '{}'", c.name))?;
        }
    }
    Ok(ServiceParts { config, config_path: config_path.to_path_buf(), machine, machine_text, process, process_text })
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
        tracing::info!(samples = summary.samples, blows = summary.blows, alerts = summary.alerts, "stopped");
        Ok::<_, anyhow::Error>(())
    })?;
    Ok(ExitCode::SUCCESS)
}

/// Logs to stderr (journald captures it under systemd), coloured only on a terminal;
/// `RUST_LOG` overrides `default_level` ("info" for the service, "error" for the demo,
/// which prints its own lines).
pub fn init_logging(default_level: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_level));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_ansi(ansi).with_writer(std::io::stderr).try_init();
}
