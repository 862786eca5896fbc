//! The running service's state and what it does with each thing that happens: a source's
//! batch, gap or status, events the live queue dropped, a control command, a SIGHUP reload,
//! the watchdog tick, and the stop. `serve` (mod.rs) owns the event loop and calls one method
//! per event; everything it touches lives here.
//!
//! Nothing from outside stops the service: a recording write that fails is logged, counted
//! (`record_errors` in `/status`, the metrics and the summary) and the service goes on; the
//! recorder suspends the recording and resumes it once the disk has room (`record::storage`).
//! The disk is watched every second: a `storage` alert is raised when its free space falls
//! under `[recording] min_free_bytes`, and again if the recording is suspended.

use std::sync::Arc;

use crate::acquire::SourceEvent;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::estimate::result::{Alert, AlertKind};
use crate::record::Gap;
use crate::session::{End, Outcome, Session};
use crate::signal::sample::SampleBatch;

use super::live::{Live, LiveEvent};
use super::reload::{InForce, Plan, ReloadReport};
use super::status::{SharedStatus, StorageStatus};
use super::{Control, Hooks, Summary, host_now_ns};

/// The service between its start and its stop.
pub(super) struct Service {
    /// Merge, pipeline and recording: the same core `replay` drives.
    session: Session,
    outcomes: Vec<Outcome>,
    status: SharedStatus,
    live: Live,
    hooks: Hooks,
    summary: Summary,
    /// The files the service runs with, as a SIGHUP reload compares them.
    in_force: InForce,
    /// `[recording] min_free_bytes`.
    min_free_bytes: u64,
    /// How bad the disk was at the last check (`StorageLevel`): an alert when it worsens.
    storage_level: StorageLevel,
    /// The number of the last blow reported, for alerts that are not a blow's.
    last_blow: u32,
    /// The die set in the hammer and what it has taken.
    dies: super::die_life::DieLife,
    /// The drift alarms (`[drift]`).
    drift: Option<crate::alert::drift::Drift>,
}

/// What the service watches over the billets beside each blow's alerts.
pub(super) struct Watches {
    /// The die set in the hammer (`[die_life]`).
    pub dies: super::die_life::DieLife,
    /// The drift alarms (`[drift]`).
    pub drift: Option<crate::alert::drift::Drift>,
}

/// The recording's disk, from good to worst.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum StorageLevel {
    Ok,
    /// Free space under `[recording] min_free_bytes`.
    Low,
    /// A write failed: the recording is suspended.
    Suspended,
}

impl Service {
    pub fn new(
        session: Session,
        status: SharedStatus,
        live: Live,
        hooks: Hooks,
        in_force: InForce,
        min_free_bytes: u64,
        watches: Watches,
    ) -> Self {
        Service {
            session,
            outcomes: Vec::new(),
            status,
            live,
            hooks,
            summary: Summary::default(),
            in_force,
            min_free_bytes,
            storage_level: StorageLevel::Ok,
            last_blow: 0,
            dies: watches.dies,
            drift: watches.drift,
        }
    }

    pub fn on_source_event(&mut self, ev: SourceEvent) {
        match ev {
            SourceEvent::Batch(batch) => self.on_batch(&batch),
            SourceEvent::Gap(g) => {
                tracing::warn!(source = %g.source, lost = g.samples_lost, reason = %g.reason, "gap");
                self.session.gap(host_now_ns(), &g);
                self.status.lock().map(|mut s| s.on_gap(&g)).ok();
            }
            SourceEvent::Status(st) => {
                self.session.status(host_now_ns(), &st);
                self.status.lock().map(|mut s| s.on_status(st)).ok();
            }
        }
        self.counted();
    }

    /// The pipeline fell behind a live source: the oldest `n` events went. Their samples'
    /// hole shows in the device times, so a blow they fell in is reported incomplete.
    pub fn on_dropped(&mut self, n: u64) {
        self.summary.dropped_events += n;
        tracing::warn!(events = n, "the pipeline fell behind: oldest events dropped");
        let gap = Gap {
            source: "service".into(),
            t_s: 0.0,
            samples_lost: 0,
            reason: format!("backpressure: {n} events dropped"),
        };
        self.session.gap(host_now_ns(), &gap);
        self.counted();
        self.status.lock().map(|mut s| s.dropped_events += n).ok();
    }

    fn on_batch(&mut self, batch: &SampleBatch) {
        self.session.batch(batch, &mut self.outcomes);
        let merger = self.session.merger();
        let (clock, stats) = (merger.clock(&batch.source), merger.stats());
        self.status.lock().map(|mut s| s.on_samples(batch, clock, stats)).ok();
        self.serve();
    }

    pub fn on_control(&mut self, c: Control) {
        match c {
            Control::NewBillet { at_device_ns } => {
                self.session.new_billet(at_device_ns, host_now_ns(), &mut self.outcomes);
                self.serve();
            }
            Control::NewBilletAs { at_device_ns, change } => {
                let trace = change.apply(self.session.next_trace());
                self.session.trace_next_billet(trace);
                self.session.new_billet(at_device_ns, host_now_ns(), &mut self.outcomes);
                self.serve();
            }
            Control::DieChange(change) => {
                let trace = change.apply(self.session.trace());
                let now = host_now_ns();
                self.dies.change(trace.die_set.as_deref(), now);
                tracing::info!(die_set = trace.die_set, "die change");
                self.session.change_dies(trace.clone(), now);
                let dies = self.dies.status();
                self.status
                    .lock()
                    .map(|mut s| {
                        s.part = trace;
                        s.die_life = dies;
                    })
                    .ok();
                self.publish_status();
            }
            Control::Acknowledge => {
                if self.status.lock().map(|mut s| s.acknowledge()).unwrap_or(false) {
                    tracing::info!("the latched alert was acknowledged");
                    self.live.publish(LiveEvent::Acknowledged);
                }
            }
        }
    }

    /// `POST /recipe`, `DELETE /recipe`: judge the following blows against another recipe
    /// (already checked), recorded where it took effect so that a replay switches there too.
    pub fn switch_recipe(&mut self, change: super::recipe_switch::RecipeChange) {
        let name = change.recipe.as_ref().map(|r| r.name.clone());
        self.session.set_recipe(change.recipe, &change.text, host_now_ns());
        self.counted();
        tracing::info!(recipe = name.as_deref().unwrap_or("none"), "recipe switched");
        self.status.lock().map(|mut s| s.recipe = name).ok();
    }

    /// SIGHUP: the service file and every file it names read and checked again
    /// (`reload::plan`); on any error nothing is taken. Then the machine model and the alert
    /// rules are taken where they changed, each recorded where it took effect so that a
    /// replay takes it at the same point, and the keys that need a restart are named. The
    /// outcome is logged and shown in `/status` (`reload`).
    pub fn reload(&mut self) {
        let report = match super::reload::plan(&self.in_force) {
            Ok(plan) => self.take(plan),
            Err(e) => {
                tracing::error!("SIGHUP: nothing reloaded, everything in force is kept: {e:#}");
                ReloadReport::new(Vec::new(), Vec::new(), Some(format!("{e:#}")))
            }
        };
        self.status.lock().map(|mut s| s.reload = Some(report)).ok();
        self.counted();
    }

    /// Take what a checked reload changed: the model first, which the estimator may still
    /// refuse (then nothing is taken), then the alert rules.
    fn take(&mut self, plan: Plan) -> ReloadReport {
        for w in &plan.warnings {
            tracing::warn!("SIGHUP: {w}");
        }
        let mut applied = Vec::new();
        if let Some((path, text)) = plan.model {
            if let Err(e) = self.session.set_model(&path.display().to_string(), &text, host_now_ns()) {
                tracing::error!("SIGHUP: nothing reloaded, everything in force is kept: {e}");
                return ReloadReport::new(Vec::new(), plan.needs_restart, Some(e));
            }
            tracing::info!("SIGHUP: machine model reloaded from {}", path.display());
            (self.in_force.config.machine_path, self.in_force.machine_text) = (path, text);
            applied.push("machine".to_string());
        }
        if let Some((alerts, text)) = plan.alerts {
            self.session.set_alerts(alerts, &text, host_now_ns());
            tracing::info!("SIGHUP: alert rules reloaded");
            self.in_force.config.alerts = alerts;
            applied.push("alerts".to_string());
        }
        if plan.needs_restart.is_empty() {
            tracing::info!(applied = ?applied, "SIGHUP: reloaded");
        } else {
            tracing::warn!(
                applied = ?applied,
                "SIGHUP: changed, but taken only at a restart: {}; the values in force are kept",
                plan.needs_restart.join(", ")
            );
        }
        ReloadReport::new(applied, plan.needs_restart, None)
    }

    pub fn on_tick(&mut self) {
        let path = self.session.recording_path().map(|p| p.display().to_string()).unwrap_or_default();
        self.status.lock().map(|mut s| s.recording = path).ok();
        self.check_storage();
        self.publish_status();
    }

    /// The recording's disk into `/status`, and a `storage` alert each time it gets worse:
    /// free space under `[recording] min_free_bytes`, then the recording suspended. A disk
    /// that recovers re-arms the alert.
    fn check_storage(&mut self) {
        let Some(health) = self.session.recording_health() else { return };
        let level = match (health.state, health.bytes_free) {
            ("suspended", _) => StorageLevel::Suspended,
            (_, Some(free)) if free < self.min_free_bytes => StorageLevel::Low,
            _ => StorageLevel::Ok,
        };
        if level > self.storage_level {
            let dir = health.path.as_ref().and_then(|p| p.parent()).map(|d| d.display().to_string());
            let reason = match level {
                StorageLevel::Suspended => format!(
                    "recording suspended, blows are not recorded until the disk has room: {}",
                    health.reason.as_deref().unwrap_or("a write failed")
                ),
                _ => format!(
                    "{} MB free for the recording{}, under [recording] min_free_bytes = {} MB",
                    health.bytes_free.unwrap_or(0) / 1_000_000,
                    dir.map(|d| format!(" in {d}")).unwrap_or_default(),
                    self.min_free_bytes / 1_000_000
                ),
            };
            let figures = [
                ("bytes_free", health.bytes_free.map_or(f64::NAN, |b| b as f64)),
                ("min_free_bytes", self.min_free_bytes as f64),
                ("dropped_blows", health.dropped_blows as f64),
            ];
            let figures = figures.into_iter().map(|(k, v)| (k.to_string(), v)).collect();
            self.raise(Alert { kind: AlertKind::Storage, blow: self.last_blow, reason, figures });
        }
        self.storage_level = level;
        let storage =
            StorageStatus { recording: health, min_free_bytes: self.min_free_bytes, low: level != StorageLevel::Ok };
        self.status.lock().map(|mut s| s.storage = storage).ok();
    }

    /// An alert of the service's own (not a blow's): logged, recorded, latched in `/status`
    /// and handed to the faces.
    fn raise(&mut self, alert: Alert) {
        let now = host_now_ns();
        self.summary.alerts += 1;
        tracing::warn!(kind = alert.kind.as_str(), "{}", alert.reason);
        self.session.alert(now, &alert);
        self.counted();
        self.status
            .lock()
            .map(|mut s| {
                s.alerts += 1;
                s.latched_alert = Some(alert.clone());
            })
            .ok();
        self.live.publish(LiveEvent::Alert { alert: Arc::new(alert), arrived_ns: now });
    }

    /// The status snapshot on the bus.
    fn publish_status(&self) {
        if let Ok(s) = self.status.lock() {
            self.live.publish(LiveEvent::Status(Arc::new(s.clone())));
        }
    }

    /// The stream ends: the blow in progress and the billet in the dies are closed and
    /// recorded, and the recording finished.
    pub fn finish(mut self) -> anyhow::Result<Summary> {
        let files = self.session.finish(End::Stopped, host_now_ns(), &mut self.outcomes);
        self.serve();
        self.summary.samples = self.session.feeder().samples();
        self.summary.billets = u64::from(self.session.pipeline_mut().billets());
        self.summary.dropped_blows = self.session.recording_health().map_or(0, |h| h.dropped_blows);
        // A recording that cannot be finished (a full disk) is kept as `.part`, which
        // `inspect` and `replay` read; the run's summary is not lost to it.
        match files {
            Ok(files) => self.summary.files = files,
            Err(e) => {
                self.summary.record_errors += 1;
                tracing::error!("the recording could not be finished, its last file stays a .mcap.part: {e}");
            }
        }
        Ok(self.summary)
    }

    /// Hand the session's outcomes to the faces.
    fn serve(&mut self) {
        self.counted();
        for o in std::mem::take(&mut self.outcomes) {
            match o {
                Outcome::Blow { estimate, log_ns } => self.on_blow(&estimate, log_ns),
                Outcome::Billet { summary, log_ns } => self.on_billet(&summary, log_ns),
                Outcome::Rejected { cut, error } => {
                    let msg = format!("blow at t = {:.6} s not estimated: {error}", cut.t_contact_s);
                    tracing::warn!("{msg}");
                    if let Some(f) = self.hooks.on_rejected.as_mut() {
                        f(&msg);
                    }
                }
                Outcome::Forged(trace) => self.dies.struck_on(trace.die_set.as_deref()),
                Outcome::NewBillet => {
                    let billets = self.session.pipeline_mut().billets();
                    let part = self.session.trace().clone();
                    self.status
                        .lock()
                        .map(|mut s| {
                            s.billets = u64::from(billets);
                            s.part = part;
                        })
                        .ok();
                    self.live.publish(LiveEvent::NewBillet);
                    tracing::info!("new billet");
                }
            }
        }
    }

    fn on_blow(&mut self, estimate: &BlowEstimate, log_time_ns: i64) {
        self.summary.blows += 1;
        self.last_blow = estimate.blow;
        self.summary.incomplete_blows += u64::from(!estimate.is_complete());
        tracing::info!(blow = estimate.blow, efficiency = estimate.efficiency, class = estimate.class.as_str(), "blow");
        // From the host receiving the batch that ended the blow to its result.
        let latency_ms = (host_now_ns() - log_time_ns) as f64 * 1e-6;
        let curve = self.session.pipeline_mut().last_curve().filter(|c| c.blow == estimate.blow);
        self.status
            .lock()
            .map(|mut s| {
                s.on_blow(estimate);
                s.on_curve(curve);
                s.last_result_latency_ms = Some(latency_ms);
            })
            .ok();
        let die_alert = self.dies.on_blow(estimate, log_time_ns);
        if let Some(d) = self.drift.as_mut() {
            d.on_blow(estimate);
        }
        let dies = self.dies.status();
        self.status.lock().map(|mut s| s.die_life = dies).ok();
        if let Some(alert) = &estimate.alert {
            self.summary.alerts += 1;
            tracing::warn!(kind = alert.kind.as_str(), blow = alert.blow, "{}", alert.reason);
            self.live.publish(LiveEvent::Alert { alert: Arc::new(alert.clone()), arrived_ns: log_time_ns });
        }
        // The hook first: a front end's line for the blow comes before what the live feed's
        // listeners (the advisor's plan after it) make of it.
        if let Some(f) = self.hooks.on_blow.as_mut() {
            f(estimate);
        }
        self.publish_status();
        self.live.publish(LiveEvent::Blow(Arc::new(estimate.clone())));
        if let Some(alert) = die_alert {
            self.raise(alert);
        }
    }

    fn on_billet(&mut self, b: &BilletSummary, log_ns: i64) {
        self.summary.billets_finished += u64::from(b.finished);
        tracing::info!(
            billet = b.billet,
            blows = b.blows,
            efficiency = b.efficiency,
            first_hard_blow = b.first_hard_blow,
            finished = b.finished,
            "billet"
        );
        self.status.lock().map(|mut s| s.on_billet(b)).ok();
        self.live.publish(LiveEvent::Billet(Arc::new(b.clone())));
        if let Some(f) = self.hooks.on_billet.as_mut() {
            f(b);
        }
        let Some(drift) = self.drift.as_mut() else { return };
        let learning = !drift.watching();
        let alarms = drift.on_billet(b, log_ns);
        let state = drift.status();
        // Just learnt: recorded, so that a restart resumes it (the history keeps it).
        if let Some(r) = drift.reference().filter(|_| learning)
            && let Ok(text) = serde_json::to_string_pretty(&r)
        {
            tracing::info!(billets = r.learn_billets, "drift: the reference is learnt; watching");
            let name = crate::alert::drift::REFERENCE_CONFIG_NAME;
            self.session.record_config("the drift reference", name, &text, log_ns);
        }
        self.status.lock().map(|mut s| s.drift = Some(state)).ok();
        for a in alarms {
            let figures = [
                ("since_billet", a.since_billet as f64),
                ("at_billet", a.at_billet as f64),
                ("shift", a.shift),
                ("up", f64::from(u8::from(a.direction == crate::alert::drift::Direction::Up))),
            ];
            let figures = figures.into_iter().map(|(k, v)| (k.to_string(), v)).collect();
            self.raise(Alert { kind: AlertKind::Drift, blow: self.last_blow, reason: a.reason, figures });
        }
    }

    /// Count the failed recording writes and log them: the first, then every hundredth (a
    /// full disk fails every write).
    fn counted(&mut self) {
        for (what, e) in self.session.take_record_errors() {
            self.summary.record_errors += 1;
            let n = self.summary.record_errors;
            if n == 1 || n.is_multiple_of(100) {
                tracing::error!(errors = n, "recording {what}: {e}");
            }
            self.status.lock().map(|mut s| s.record_errors = n).ok();
        }
    }
}
