//! The always-on service (DESIGN.md §5): source events in; everything recorded to MCAP;
//! the live pipeline (the same `pipeline::Feeder` replay uses) on the samples; results and
//! alerts to the log, the recording, the status/metrics endpoint, the webhook and the PLC
//! coil. systemd `Type=notify`: READY once listening, WATCHDOG pings, STOPPING on the way
//! out; SIGTERM finishes the recording cleanly; SIGHUP reloads the alert rules.
//!
//! The sources are spawned by the caller and speak `acquire::SourceEvent` on one channel,
//! so the service neither knows nor cares which transport (or simulated device) feeds it.

pub mod queue;
pub mod sinks;
pub mod status;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use tokio::sync::{mpsc, watch};

use crate::acquire::SourceEvent;
use crate::config::service::{PipelineTuning, ServiceConfig, parse_service};
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::pipeline::{Feeder, Pipeline, PipelineConfig, PipelineEvent};
use crate::record::{BlowBoundary, Payload, RecordOptions, RecordWriter, Rotation};
use crate::signal::merge::Merger;
use status::{SharedStatus, StatusSnapshot};

/// Capacity of the channel from the sources to the service. Live, a relay empties it into
/// the drop-oldest queue (`queue::LIVE_QUEUE_EVENTS`) as fast as it fills; a source that can
/// wait waits for room in it.
pub const SOURCE_CHANNEL_CAPACITY: usize = 1024;

/// Everything the service needs, read and validated.
pub struct ServiceParts {
    pub config: ServiceConfig,
    pub config_path: PathBuf,
    pub machine: Machine,
    pub machine_text: String,
    pub process: Option<Process>,
    pub process_text: Option<String>,
    /// Whether the sources can wait for the service (a simulated device run fast) or not.
    pub backpressure: crate::acquire::Backpressure,
}

/// Commands to the running service (from the status endpoint or a front end).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// A new billet is in the dies (an operator's button, a PLC input, the simulator):
    /// now (`None`), or from the source's sample at this device time on, so that samples
    /// still queued from the last billet are estimated as that billet's.
    NewBillet { at_device_ns: Option<i64> },
}

/// Source name of the control markers in a recording.
pub const CONTROL_SOURCE: &str = "control";
/// State of the marker that says a new billet was put in the dies here.
pub const NEW_BILLET_STATE: &str = "new_billet";

/// The status message that marks a new billet in a recording, in stream order, so that a
/// replay starts the billet at the same point as the live run did.
pub fn new_billet_marker() -> crate::record::Status {
    crate::record::Status { source: CONTROL_SOURCE.into(), state: NEW_BILLET_STATE.into(), ..Default::default() }
}

/// A front end's callback for each blow.
pub type BlowHook = Box<dyn FnMut(&BlowEstimate) + Send>;
/// A front end's callback for each blow that could not be estimated.
pub type RejectHook = Box<dyn FnMut(&str) + Send>;
/// A front end's callback for each billet's summary.
pub type BilletHook = Box<dyn FnMut(&BilletSummary) + Send>;

/// Callbacks for a front end (the demo prints each blow).
#[derive(Default)]
pub struct Hooks {
    /// Called once the status endpoint listens, with its address.
    pub on_listening: Option<Box<dyn FnOnce(std::net::SocketAddr) + Send>>,
    pub on_blow: Option<BlowHook>,
    pub on_rejected: Option<RejectHook>,
    /// Called with each billet's summary, when the next starts and at the end of the run.
    pub on_billet: Option<BilletHook>,
}

/// What the service did, when it stops.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub samples: u64,
    /// Billets started, by the encoder or a signal.
    pub billets: u64,
    /// Billets finished (the next one started); the last one is summarised unfinished.
    pub billets_finished: u64,
    pub blows: u64,
    pub alerts: u64,
    /// Events the live queue dropped because the pipeline fell behind.
    pub dropped_events: u64,
    /// Blows reported incomplete (samples lost inside them).
    pub incomplete_blows: u64,
    pub files: Vec<PathBuf>,
}

/// Wall-clock time in ns since the epoch (the service is the one place that reads it).
pub fn host_now_ns() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos() as i64).unwrap_or(0)
}

/// Run the service until SIGTERM/SIGINT, until `stop` turns true, or until every source
/// has hung up. `shutdown` tells the sources to stop.
pub async fn serve(
    parts: ServiceParts,
    rx: mpsc::Receiver<SourceEvent>,
    shutdown: watch::Sender<bool>,
    mut stop: watch::Receiver<bool>,
    mut hooks: Hooks,
    control: Option<(mpsc::Sender<Control>, mpsc::Receiver<Control>)>,
) -> anyhow::Result<Summary> {
    let (control_tx, mut control_rx) = control.unwrap_or_else(|| mpsc::channel(16));
    let cfg = &parts.config;
    std::fs::create_dir_all(&cfg.recording_dir)
        .with_context(|| format!("{}: cannot create the recording directory", cfg.recording_dir.display()))?;
    let rotation =
        Rotation { max_bytes: Some(cfg.rotate_bytes), max_duration_ns: Some(cfg.rotate_seconds * 1_000_000_000) };
    let mut writer =
        RecordWriter::create_with(&cfg.recording_dir, RecordOptions { rotation, ..RecordOptions::default() })
            .with_context(|| format!("{}: cannot record", cfg.recording_dir.display()))?;
    let t0 = host_now_ns();
    writer.write_config(t0, "machine.toml", &parts.machine_text)?;
    if let Some(t) = &parts.process_text {
        writer.write_config(t0, "process.toml", t)?;
    }
    writer.write_config(t0, SERVICE_CONFIG_NAME, &std::fs::read_to_string(&parts.config_path).unwrap_or_default())?;

    let status: SharedStatus = Arc::new(Mutex::new(StatusSnapshot::new(parts.machine.kind().as_str())));
    let listener = tokio::net::TcpListener::bind(cfg.http_listen)
        .await
        .with_context(|| format!("http.listen {}: cannot listen", cfg.http_listen))?;
    if let (Some(f), Ok(addr)) = (hooks.on_listening.take(), listener.local_addr()) {
        f(addr);
    }
    let http = tokio::spawn(status::serve_http(listener, status.clone(), control_tx));
    let sinks = sinks::Sinks::new(cfg.webhook.clone(), cfg.plc_coil);

    let mut feeder =
        Feeder::new(Pipeline::new(parts.machine, parts.process.clone(), pipeline_config(cfg, &parts.machine)));
    let mut summary = Summary::default();
    let mut events = Vec::new();
    // The pipeline's input: a source carrying every role as it is, or the roles of several
    // sources merged onto one timeline through each source's clock model (signal::merge).
    let mut merger = Merger::default();
    let mut to_pipeline = Vec::new();
    // A new billet announced for a device time the samples have not reached yet.
    let mut pending_billet: Option<i64> = None;
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let mut sighup = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())?;
    // systemd's watchdog wants a ping at least every WATCHDOG_USEC; ping at half of it.
    let watchdog = sd_notify::watchdog_enabled();
    let mut tick = tokio::time::interval(watchdog.map_or(Duration::from_secs(1), |d| d / 2));
    let mut rx = queue::SourceQueue::new(rx, parts.backpressure);
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    tracing::info!(listen = %cfg.http_listen, dir = %cfg.recording_dir.display(), "forgemon service ready");

    loop {
        tokio::select! {
            ev = rx.recv() => {
                let ev = match ev {
                    None => break,
                    Some(queue::Received::Event(ev)) => ev,
                    Some(queue::Received::Dropped(n)) => {
                        // The pipeline fell behind a live source: the oldest events went.
                        // Their samples' hole shows in the device times, so a blow they
                        // fell in is reported incomplete.
                        summary.dropped_events += n;
                        tracing::warn!(events = n, "the pipeline fell behind: oldest events dropped");
                        let gap = crate::record::Gap {
                            source: "service".into(),
                            t_s: 0.0,
                            samples_lost: 0,
                            reason: format!("backpressure: {n} events dropped"),
                        };
                        let _ = writer.write_gap(host_now_ns(), &gap);
                        status.lock().map(|mut s| s.dropped_events += n).ok();
                        continue;
                    }
                };
                match ev {
                    SourceEvent::Batch(batch) => {
                        if let Err(e) = writer.write_samples(&batch) {
                            tracing::error!("recording samples: {e}");
                        }
                        let direct = merger.push(&batch, &mut to_pipeline);
                        status.lock().map(|mut s| s.on_samples(&batch, merger.clock(&batch.source), merger.stats())).ok();
                        for b in direct.then_some(&batch).into_iter().chain(to_pipeline.iter()) {
                            let batch_end_ns = b.device_time_ns + (b.period_ns * b.len() as f64) as i64;
                            if pending_billet.is_some_and(|at| batch_end_ns > at) {
                                pending_billet = None;
                                start_billet(&mut feeder, &mut writer, &status, &mut events);
                            }
                            feeder.push(b, &mut events);
                        }
                        to_pipeline.clear();
                        for e in events.drain(..) {
                            on_event(e, batch.host_time_ns, &mut writer, &status, &sinks, &mut hooks, &mut summary);
                        }
                    }
                    SourceEvent::Gap(g) => {
                        tracing::warn!(source = %g.source, lost = g.samples_lost, reason = %g.reason, "gap");
                        let _ = writer.write_gap(host_now_ns(), &g);
                        status.lock().map(|mut s| s.on_gap(&g)).ok();
                    }
                    SourceEvent::Status(st) => {
                        let _ = writer.write_status(host_now_ns(), &st);
                        status.lock().map(|mut s| s.on_status(st)).ok();
                    }
                }
            }
            Some(c) = control_rx.recv() => match c {
                Control::NewBillet { at_device_ns: None } => {
                    start_billet(&mut feeder, &mut writer, &status, &mut events);
                    for e in events.drain(..) {
                        on_event(e, host_now_ns(), &mut writer, &status, &sinks, &mut hooks, &mut summary);
                    }
                }
                Control::NewBillet { at_device_ns: Some(at) } => pending_billet = Some(at),
            },
            _ = sigterm.recv() => { tracing::info!("SIGTERM: finishing the recording"); break; }
            _ = tokio::signal::ctrl_c() => { tracing::info!("interrupted: finishing the recording"); break; }
            _ = stop.changed() => { if *stop.borrow() { break; } }
            _ = sighup.recv() => {
                match reload(&parts.config_path) {
                    Ok((new, text)) => {
                        feeder.pipeline_mut().set_alert_config(new.alerts);
                        // In stream order, so that a replay changes the rules where this run did.
                        let _ = writer.write_config(host_now_ns(), SERVICE_CONFIG_NAME, &text);
                        tracing::info!("SIGHUP: alert rules reloaded");
                    }
                    Err(e) => tracing::error!("SIGHUP: keeping the old alert rules: {e:#}"),
                }
            }
            _ = tick.tick() => {
                if watchdog.is_some() {
                    let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
                }
                status.lock().map(|mut s| s.recording = writer.current_path().display().to_string()).ok();
            }
        }
    }
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    let _ = shutdown.send(true);
    feeder.pipeline_mut().end_of_stream(&mut events);
    feeder.pipeline_mut().close_billet(&mut events);
    for e in events.drain(..) {
        on_event(e, host_now_ns(), &mut writer, &status, &sinks, &mut hooks, &mut summary);
    }
    summary.samples = feeder.samples();
    summary.billets = u64::from(feeder.pipeline_mut().billets());
    summary.files = writer.finish()?;
    http.abort();
    Ok(summary)
}

/// The pipeline's thresholds: the machine's defaults with the service file's alert rules
/// and billet detection.
pub fn pipeline_config(cfg: &ServiceConfig, machine: &Machine) -> PipelineConfig {
    tuned_config(&cfg.tuning(), machine)
}

/// The machine's defaults with a service file's alert rules and billet detection (live, or
/// as a recording stored them for its replay).
pub fn tuned_config(tuning: &PipelineTuning, machine: &Machine) -> PipelineConfig {
    let mut p = PipelineConfig { alerts: tuning.alerts, ..PipelineConfig::for_machine(machine) };
    p.estimate.new_billet_rise_m = tuning.new_billet_rise_m;
    p.estimate.idle_new_billet_s = tuning.idle_new_billet_s;
    p
}

/// Name of the service configuration as a recording stores it (topic `/config`), at the
/// start and again at each SIGHUP reload.
pub const SERVICE_CONFIG_NAME: &str = "service.toml";

/// The service file read again (SIGHUP), checked, with its text.
fn reload(path: &std::path::Path) -> anyhow::Result<(ServiceConfig, String)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let cfg = parse_service(&path.display().to_string(), path.parent().unwrap_or(std::path::Path::new(".")), &text)?;
    Ok((cfg, text))
}

/// A new billet from here on: restart the height tracking and alert memory, and mark the
/// point in the recording so that a replay restarts it at the same sample.
fn start_billet(
    feeder: &mut Feeder,
    writer: &mut RecordWriter,
    status: &SharedStatus,
    events: &mut Vec<PipelineEvent>,
) {
    feeder.pipeline_mut().new_billet(events);
    let _ = writer.write_status(host_now_ns(), &new_billet_marker());
    let billets = feeder.pipeline_mut().billets();
    status.lock().map(|mut s| s.billets = u64::from(billets)).ok();
    tracing::info!("new billet");
}

fn on_event(
    e: PipelineEvent,
    log_time_ns: i64,
    writer: &mut RecordWriter,
    status: &SharedStatus,
    sinks: &sinks::Sinks,
    hooks: &mut Hooks,
    summary: &mut Summary,
) {
    match e {
        PipelineEvent::Blow { cut, estimate } => {
            summary.blows += 1;
            summary.incomplete_blows += u64::from(!estimate.is_complete());
            let boundary = BlowBoundary::of(estimate.blow, &cut);
            let _ = writer.write_payload(log_time_ns, &Payload::Boundary(boundary));
            if let Err(err) = writer.write_result(log_time_ns, &estimate) {
                tracing::error!("recording the result of blow {}: {err}", estimate.blow);
            }
            tracing::info!(
                blow = estimate.blow,
                efficiency = estimate.efficiency,
                class = estimate.class.as_str(),
                "blow"
            );
            // From the host receiving the batch that ended the blow to its result.
            let latency_ms = (host_now_ns() - log_time_ns) as f64 * 1e-6;
            status
                .lock()
                .map(|mut s| {
                    s.on_blow(&estimate);
                    s.last_result_latency_ms = Some(latency_ms);
                })
                .ok();
            if let Some(alert) = &estimate.alert {
                summary.alerts += 1;
                tracing::warn!(kind = alert.kind.as_str(), blow = alert.blow, "{}", alert.reason);
                let _ = writer.write_alert(log_time_ns, alert);
                sinks.fire(alert, log_time_ns, status);
            }
            if let Some(f) = hooks.on_blow.as_mut() {
                f(&estimate);
            }
        }
        PipelineEvent::Billet(b) => {
            summary.billets_finished += u64::from(b.finished);
            if let Err(err) = writer.write_billet(log_time_ns, &b) {
                tracing::error!("recording billet {}: {err}", b.billet);
            }
            tracing::info!(
                billet = b.billet,
                blows = b.blows,
                efficiency = b.efficiency,
                first_hard_blow = b.first_hard_blow,
                finished = b.finished,
                "billet"
            );
            status.lock().map(|mut s| s.on_billet(&b)).ok();
            if let Some(f) = hooks.on_billet.as_mut() {
                f(&b);
            }
        }
        PipelineEvent::Rejected { cut, error } => {
            let msg = format!("blow at t = {:.6} s not estimated: {error}", cut.t_contact_s);
            tracing::warn!("{msg}");
            if let Some(f) = hooks.on_rejected.as_mut() {
                f(&msg);
            }
        }
    }
}
