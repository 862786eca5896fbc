//! The always-on service (DESIGN.md §5): source events in; everything recorded to MCAP;
//! the live pipeline (the same `pipeline::Feeder` replay uses) on the samples; results and
//! alerts to the log, the recording, the status/metrics endpoint, the webhook and the PLC
//! coil. systemd `Type=notify`: READY once listening, WATCHDOG pings, STOPPING on the way
//! out; SIGTERM finishes the recording cleanly; SIGHUP reloads the alert rules and the
//! machine model after checking every file again, and names what needs a restart.
//!
//! The sources are spawned by the caller and speak `acquire::SourceEvent` on one channel,
//! so the service neither knows nor cares which transport (or simulated device) feeds it.

pub mod advisor;
pub mod dashboard;
pub mod die_life;
mod drift;
pub mod faces;
pub mod foxglove;
mod history;
pub mod http_server;
pub mod idle;
pub mod live;
pub mod opcua;
mod parts;
pub mod plc_server;
pub mod queue;
pub mod recipe_switch;
pub mod reload;
pub mod secret;
mod service;
pub mod sinks;
pub mod slots;
pub mod sparkplug;
pub mod status;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use tokio::sync::{mpsc, watch};

use crate::acquire::SourceEvent;
use crate::config::service::{PipelineTuning, ServiceConfig};
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::pipeline::{Pipeline, PipelineConfig};
use crate::record::{RecordOptions, RecordWriter, Retention, Rotation};
pub use crate::session::{
    CONTROL_SOURCE, MACHINE_CONFIG_NAME, NEW_BILLET_STATE, RECIPE_CONFIG_NAME, SERVICE_CONFIG_NAME, new_billet_marker,
};
use crate::session::{Session, Stamp};
use status::{SharedStatus, StatusSnapshot};

/// Capacity of the channel from the sources to the service. Live, a relay empties it into
/// the drop-oldest queue (`queue::LIVE_QUEUE_EVENTS`) as fast as it fills; a source that can
/// wait waits for room in it.
pub const SOURCE_CHANNEL_CAPACITY: usize = 1024;

/// Everything the service needs, read and validated.
pub struct ServiceParts {
    pub config: ServiceConfig,
    pub config_path: PathBuf,
    /// The service file's text as it was read and checked, recorded on `/config`.
    pub config_text: String,
    pub machine: Machine,
    /// The machine file's effects (`[effects.NAME]`): part of the model every blow is
    /// estimated with.
    pub effects: crate::physics::effects::EffectSet,
    pub machine_text: String,
    pub process: Option<Process>,
    pub process_text: Option<String>,
    /// Whether the sources can wait for the service (a simulated device run fast) or not.
    pub backpressure: crate::acquire::Backpressure,
}

/// Commands to the running service (from the status endpoint or a front end).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Control {
    /// A new billet is in the dies (an operator's button, a PLC input, the simulator):
    /// now (`None`), or from the source's sample at this device time on, so that samples
    /// still queued from the last billet are estimated as that billet's.
    NewBillet { at_device_ns: Option<i64> },
    /// The operator acknowledged the latched alert (`POST /ack`, the PLC's coil 0).
    Acknowledge,
    /// A new billet, as `NewBillet`, forged as the trace in force changed by `change`
    /// (`POST /billet` with a body, the PLC's part block, OPC UA).
    NewBilletAs { at_device_ns: Option<i64>, change: Box<crate::config::history::TraceUpdate> },
    /// The dies were changed (`POST /die`): a new die set's life starts, forged as the trace
    /// in force changed by this (its `die_set` the new set's name).
    DieChange(Box<crate::config::history::TraceUpdate>),
}

/// A front end's callback for each blow.
pub type BlowHook = Box<dyn FnMut(&BlowEstimate) + Send>;
/// A front end's callback for each blow that could not be estimated.
pub type RejectHook = Box<dyn FnMut(&str) + Send>;
/// A front end's callback for each billet's summary.
pub type BilletHook = Box<dyn FnMut(&BilletSummary) + Send>;

/// A front end's callback for each plan of the live advisor.
pub type AdviceHook = Box<dyn FnMut(&advisor::Advice) + Send>;

/// Callbacks for a front end (the demo prints each blow).
#[derive(Default)]
pub struct Hooks {
    /// Called once the status endpoint listens, with its address.
    pub on_listening: Option<Box<dyn FnOnce(std::net::SocketAddr) + Send>>,
    pub on_blow: Option<BlowHook>,
    pub on_rejected: Option<RejectHook>,
    /// Called with each billet's summary, when the next starts and at the end of the run.
    pub on_billet: Option<BilletHook>,
    /// Called with each plan of the live advisor (`[advisor]`).
    pub on_advice: Option<AdviceHook>,
}

/// Every face `serve` starts, by its config section (`faces.rs`). A new face is one line.
pub const FACES: [(&str, faces::Start); 9] = [
    ("http", dashboard::face),
    ("foxglove", foxglove::face),
    ("plc_server", plc_server::face),
    ("opcua", opcua::face),
    ("uplink.mqtt", sparkplug::face),
    ("advisor", advisor::face),
    ("alerts.webhook", sinks::webhook_face),
    ("alerts.plc_coil", sinks::coil_face),
    ("history", history::face),
];

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
    /// Recording writes that failed (logged; the service went on).
    pub record_errors: u64,
    /// Blow results not recorded (the recording was suspended or a write failed).
    pub dropped_blows: u64,
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
    stop: watch::Receiver<bool>,
    mut hooks: Hooks,
    control: Option<(mpsc::Sender<Control>, mpsc::Receiver<Control>)>,
) -> anyhow::Result<Summary> {
    let (control_tx, control_rx) = control.unwrap_or_else(|| mpsc::channel(16));
    let cfg = &parts.config;
    let mut writer = open_recording(&parts)?;
    let status: SharedStatus = Arc::new(Mutex::new(StatusSnapshot::new(parts.machine.kind().as_str())));
    let listener = tokio::net::TcpListener::bind(cfg.http_listen)
        .await
        .with_context(|| format!("http.listen {}: cannot listen", cfg.http_listen))?;
    if let (Some(f), Ok(addr)) = (hooks.on_listening.take(), listener.local_addr()) {
        f(addr);
    }
    let live = live::Live::default();
    let token = dashboard::auth::Token::read(cfg.http_token_file.as_deref())?;
    let (recipe_tx, recipe_rx) = mpsc::channel::<recipe_switch::RecipeChange>(4);
    let on_advice = Mutex::new(hooks.on_advice.take());
    let (routes, recorded) = (Mutex::new(Vec::new()), Mutex::new(Vec::new()));
    let ctx = faces::FaceContext {
        config: cfg,
        machine: &parts.machine,
        machine_text: &parts.machine_text,
        process: parts.process.as_ref(),
        bus: &live,
        status: &status,
        control: &control_tx,
        on_advice: &on_advice,
        routes: &routes,
        recorded: &recorded,
    };
    let running = start_faces(&ctx).await?;
    let pages = routes
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .fold(recipe_switch::routes(recipe_tx, parts.machine.kind().as_str()), axum::Router::merge);
    let routes = status::routes(status.clone(), control_tx.clone(), token, pages);
    let http = tokio::spawn(http_server::serve(listener, routes, cfg.http_limits));
    let mut taps = recorded.into_inner().unwrap_or_default();
    if !taps.is_empty() {
        writer.set_tap(Box::new(move |m| taps.iter_mut().for_each(|tap| tap(m))));
    }
    let (pipeline, recipe_text) = pipeline_with_recipe(&parts, &mut writer, &status)?;
    let mut session = Session::new(pipeline, Some(writer), Stamp::Arrival);
    session.set_absent(cfg.absent_channels, 0);
    // Always recorded, unset parts too: a replay or a history rebuild from here on forgets
    // what an earlier run set.
    session.set_trace(cfg.part.clone(), host_now_ns());
    status.lock().map(|mut s| s.part = cfg.part.clone()).ok();
    let in_force = reload::InForce::new(&parts, recipe_text);
    let history = cfg.history.as_ref().map(|h| h.path.clone());
    let dies = die_life::DieLife::start(cfg.die_life, history.clone(), cfg.part.die_set.as_deref(), host_now_ns());
    status.lock().map(|mut s| s.die_life = dies.status()).ok();
    let drift = cfg.drift.map(|d| drift::start(d, history.as_deref(), &mut session));
    status.lock().map(|mut s| s.drift = drift.as_ref().map(crate::alert::drift::Drift::status)).ok();
    let watches = service::Watches { dies, drift };
    let service = service::Service::new(session, status, live.clone(), hooks, in_force, cfg.min_free_bytes, watches);
    let rx = queue::SourceQueue::new(rx, parts.backpressure);
    tracing::info!(listen = %cfg.http_listen, dir = %cfg.recording_dir.display(), "forgemon service ready");
    let summary = run_loop(service, rx, control_rx, recipe_rx, stop, &shutdown).await?;
    live.publish(live::LiveEvent::Stopping);
    for face in running {
        face.finish().await;
    }
    http.abort();
    Ok(summary)
}

/// The recording directory's writer, with the machine, process and service files recorded;
/// on a disk with no room the recording starts suspended and keeps them for its first file.
fn open_recording(parts: &ServiceParts) -> anyhow::Result<RecordWriter> {
    let cfg = &parts.config;
    std::fs::create_dir_all(&cfg.recording_dir)
        .with_context(|| format!("{}: cannot create the recording directory", cfg.recording_dir.display()))?;
    let rotation =
        Rotation { max_bytes: Some(cfg.rotate_bytes), max_duration_ns: Some(cfg.rotate_seconds * 1_000_000_000) };
    let mut writer =
        RecordWriter::create_with(&cfg.recording_dir, RecordOptions { rotation, ..RecordOptions::default() })
            .with_context(|| format!("{}: cannot record", cfg.recording_dir.display()))?;
    writer.set_retention(Retention { keep_bytes: cfg.keep_bytes, keep_days: cfg.keep_days });
    let t0 = host_now_ns();
    let configs = [
        (MACHINE_CONFIG_NAME, Some(&parts.machine_text)),
        ("process.toml", parts.process_text.as_ref()),
        (SERVICE_CONFIG_NAME, Some(&parts.config_text)),
    ];
    for (name, text) in configs {
        if let Some(text) = text
            && let Err(e) = writer.write_config(t0, name, text)
        {
            tracing::warn!("recording {name}: {e}");
        }
    }
    Ok(writer)
}

/// Every face on the bus, each from its own section (`FACES`).
async fn start_faces(ctx: &faces::FaceContext<'_>) -> anyhow::Result<Vec<Box<dyn faces::Face>>> {
    let mut running = Vec::new();
    for (_, start) in FACES {
        running.extend(start(ctx).await?);
    }
    Ok(running)
}

/// The pipeline of `parts`, judging with `recipe` when set: read, checked and recorded (so a
/// replay judges with it), or the start stops here; with the recipe file's text.
fn pipeline_with_recipe(
    parts: &ServiceParts,
    writer: &mut RecordWriter,
    status: &SharedStatus,
) -> anyhow::Result<(Pipeline, Option<String>)> {
    let cfg = &parts.config;
    let kind = parts.machine.kind().as_str();
    let mut pipeline = Pipeline::new(parts.machine, parts.process.clone(), pipeline_config(cfg, &parts.machine))
        .with_effects(parts.effects);
    let recipe = parts::read_recipe(cfg, kind)?;
    if let Some((recipe, text)) = &recipe {
        writer.write_config(host_now_ns(), RECIPE_CONFIG_NAME, text)?;
        status.lock().map(|mut s| s.recipe = Some(recipe.name.clone())).ok();
        pipeline.set_recipe(Some(recipe.clone()));
    }
    Ok((pipeline, recipe.map(|(_, text)| text)))
}

/// The event loop: one `Service` method per event, until SIGTERM/SIGINT, `stop` or the
/// sources hang up; then the sources are told to stop (`shutdown`) and the service finishes.
async fn run_loop(
    mut service: service::Service,
    mut rx: queue::SourceQueue,
    mut control_rx: mpsc::Receiver<Control>,
    mut recipe_rx: mpsc::Receiver<recipe_switch::RecipeChange>,
    mut stop: watch::Receiver<bool>,
    shutdown: &watch::Sender<bool>,
) -> anyhow::Result<Summary> {
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let mut sighup = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())?;
    // systemd's watchdog wants a ping at least every WATCHDOG_USEC; ping at half of it.
    let watchdog = sd_notify::watchdog_enabled();
    let mut tick = tokio::time::interval(watchdog.map_or(Duration::from_secs(1), |d| d / 2));
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    loop {
        tokio::select! {
            ev = rx.recv() => match ev {
                None => break,
                Some(queue::Received::Event(ev)) => service.on_source_event(ev),
                Some(queue::Received::Dropped(n)) => service.on_dropped(n),
            },
            Some(c) = control_rx.recv() => service.on_control(c),
            Some(r) = recipe_rx.recv() => service.switch_recipe(r),
            _ = sigterm.recv() => { tracing::info!("SIGTERM: finishing the recording"); break; }
            _ = tokio::signal::ctrl_c() => { tracing::info!("interrupted: finishing the recording"); break; }
            _ = stop.changed() => if *stop.borrow() { break },
            _ = sighup.recv() => service.reload(),
            _ = tick.tick() => {
                if watchdog.is_some() {
                    let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
                }
                service.on_tick();
            }
        }
    }
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    let _ = shutdown.send(true);
    service.finish()
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
    p.estimate.encoder_at_die_m = tuning.encoder_at_die_m;
    p.estimate.encoder_direction = tuning.encoder_direction;
    p
}
