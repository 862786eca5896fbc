//! `forgemon run --config FILE`: the always-on service. The configuration, the machine model
//! and the process sheet are read and checked before anything is opened; then the sources
//! start and the service runs until SIGTERM.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Args;
use tokio::sync::{mpsc, watch};

use super::{parse_process_warn, read_text};
use crate::acquire::modbus::Mode;
use crate::acquire::modbus::registers::Signal;
use crate::acquire::serial::driver::{SerialConfig, SerialFormat as WireFormat};
use crate::config::parse_machine;
use crate::config::service::{SerialFormat, ServiceConfig, SourceSpec, parse_service};
use crate::daemon::{Hooks, SOURCE_CHANNEL_CAPACITY, ServiceParts, serve};
use crate::signal::sample::Role;

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
    let machine_file = parse_machine(&config.machine_path.display().to_string(), &machine_text)?;
    let (machine, effects) = (machine_file.machine, machine_file.effect_set());
    let (process, process_text) = match &config.process_path {
        Some(p) => {
            let t = read_text(p).context("key 'process'")?;
            let proc_ = parse_process_warn(&p.display().to_string(), &t)?;
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
    let mut roles: Vec<(&str, Vec<Role>)> = Vec::new();
    for s in &config.sources {
        let r = match s {
            SourceSpec::Can(c) => c.resolve().with_context(|| format!("source '{}'", c.name))?.mapping.roles(),
            SourceSpec::Serial { channels, .. } => channels.iter().map(|c| c.role).collect(),
            SourceSpec::Modbus(m) => match &m.mode {
                Mode::Poll => m
                    .map
                    .iter()
                    .filter_map(|r| match r.signal {
                        Signal::Role(role) => Some(role),
                        Signal::Named(_) => None,
                    })
                    .collect(),
                Mode::Block { channels, .. } => channels.iter().map(|c| c.role).collect(),
            },
        };
        roles.push((s.name(), r));
    }
    check_roles(&config_path.display().to_string(), &roles)?;
    if let Some(name) = crate::estimate::unhonoured(&effects, process.as_ref()) {
        bail!(
            "{}: key 'effects.{name}': the estimator carries it in the model fit, which needs the billet's \
             process sheet; set 'process' in {}",
            config.machine_path.display(),
            config_path.display()
        );
    }
    Ok(ServiceParts {
        config,
        config_path: config_path.to_path_buf(),
        config_text: text,
        machine,
        effects,
        machine_text,
        process,
        process_text,
        // A real DAQ cannot wait for the service.
        backpressure: crate::acquire::Backpressure::DropOldest,
    })
}

/// Every blow needs the load, the ram position and the acceleration: from one source, or
/// each from exactly one of several (merged onto the acceleration's timeline,
/// `signal::merge`). Checked before anything is opened.
fn check_roles(origin: &str, roles: &[(&str, Vec<Role>)]) -> anyhow::Result<()> {
    if roles.iter().any(|(_, r)| Role::ALL.iter().all(|x| r.contains(x))) {
        return Ok(());
    }
    for role in Role::ALL {
        let from: Vec<&str> = roles.iter().filter(|(_, r)| r.contains(&role)).map(|(n, _)| *n).collect();
        match from.as_slice() {
            [] => bail!("{origin}: key 'sources': no source gives {role} (a blow needs load_N, disp_m and acc_mps2)"),
            [_] => {}
            many => bail!(
                "{origin}: key 'sources': {role} comes from sources '{}'; with no source giving all three roles, \
                 give each role from one source",
                many.join("', '")
            ),
        }
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_roles_must_be_covered_once() {
        let all = Role::ALL.to_vec();
        // One source with every role: others may repeat roles (they are recorded only).
        assert!(check_roles("s.toml", &[("daq", all.clone()), ("spare", vec![Role::Load])]).is_ok());
        // Split over two sources, each role once: merged.
        assert!(check_roles("s.toml", &[("daq", vec![Role::Load, Role::Acc]), ("enc", vec![Role::Disp])]).is_ok());
        let e = check_roles("s.toml", &[("daq", vec![Role::Load, Role::Acc])]).unwrap_err().to_string();
        assert!(e.contains("s.toml: key 'sources': no source gives disp_m"), "{e}");
        let e = check_roles("s.toml", &[("a", vec![Role::Load, Role::Acc]), ("b", vec![Role::Disp, Role::Load])])
            .unwrap_err()
            .to_string();
        assert!(e.contains("load_N comes from sources 'a', 'b'"), "{e}");
    }
}
