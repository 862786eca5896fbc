//! The running service's state and what it does with each thing that happens: a source's
//! batch, gap or status, events the live queue dropped, a control command, a SIGHUP reload,
//! the watchdog tick, and the stop. `serve` (mod.rs) owns the event loop and calls one method
//! per event; everything it touches lives here.
//!
//! Nothing from outside stops the service: a recording write that fails is logged, counted
//! (`record_errors` in `/status`, the metrics and the summary) and the service goes on.

use std::path::PathBuf;
use std::sync::Arc;

use crate::acquire::SourceEvent;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::pipeline::{Feeder, PipelineEvent};
use crate::record::{Gap, Payload, RecordError, RecordWriter};
use crate::signal::merge::Merger;
use crate::signal::sample::SampleBatch;

use super::live::{Live, LiveEvent};
use super::status::SharedStatus;
use super::{
    Control, Hooks, MACHINE_CONFIG_NAME, SERVICE_CONFIG_NAME, Summary, host_now_ns, new_billet_marker, reload, sinks,
};

/// The service between its start and its stop.
pub(super) struct Service {
    writer: RecordWriter,
    feeder: Feeder,
    /// The pipeline's input: a source carrying every role as it is, or the roles of several
    /// sources merged onto one timeline through each source's clock model (signal::merge).
    merger: Merger,
    merged: Vec<SampleBatch>,
    events: Vec<PipelineEvent>,
    /// A new billet announced for a device time the samples have not reached yet.
    pending_billet: Option<i64>,
    status: SharedStatus,
    live: Live,
    sinks: sinks::Sinks,
    hooks: Hooks,
    summary: Summary,
    config_path: PathBuf,
}

impl Service {
    pub fn new(
        writer: RecordWriter,
        feeder: Feeder,
        status: SharedStatus,
        live: Live,
        sinks: sinks::Sinks,
        hooks: Hooks,
        config_path: PathBuf,
    ) -> Self {
        Service {
            writer,
            feeder,
            merger: Merger::default(),
            merged: Vec::new(),
            events: Vec::new(),
            pending_billet: None,
            status,
            live,
            sinks,
            hooks,
            summary: Summary::default(),
            config_path,
        }
    }

    pub fn on_source_event(&mut self, ev: SourceEvent) {
        match ev {
            SourceEvent::Batch(batch) => self.on_batch(&batch),
            SourceEvent::Gap(g) => {
                tracing::warn!(source = %g.source, lost = g.samples_lost, reason = %g.reason, "gap");
                let r = self.writer.write_gap(host_now_ns(), &g);
                self.recorded("a gap", r);
                self.status.lock().map(|mut s| s.on_gap(&g)).ok();
            }
            SourceEvent::Status(st) => {
                let r = self.writer.write_status(host_now_ns(), &st);
                self.recorded("a source's status", r);
                self.status.lock().map(|mut s| s.on_status(st)).ok();
            }
        }
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
        let r = self.writer.write_gap(host_now_ns(), &gap);
        self.recorded("a gap", r);
        self.status.lock().map(|mut s| s.dropped_events += n).ok();
    }

    fn on_batch(&mut self, batch: &SampleBatch) {
        let r = self.writer.write_samples(batch);
        self.recorded("samples", r);
        let direct = self.merger.push(batch, &mut self.merged);
        let (clock, stats) = (self.merger.clock(&batch.source), self.merger.stats());
        self.status.lock().map(|mut s| s.on_samples(batch, clock, stats)).ok();
        let merged = std::mem::take(&mut self.merged);
        for b in direct.then_some(batch).into_iter().chain(merged.iter()) {
            let batch_end_ns = b.device_time_ns + (b.period_ns * b.len() as f64) as i64;
            if self.pending_billet.is_some_and(|at| batch_end_ns > at) {
                self.pending_billet = None;
                self.start_billet();
            }
            self.feeder.push(b, &mut self.events);
        }
        self.merged = merged;
        self.merged.clear();
        self.emit(batch.host_time_ns);
    }

    pub fn on_control(&mut self, c: Control) {
        match c {
            Control::NewBillet { at_device_ns: None } => {
                self.start_billet();
                self.emit(host_now_ns());
            }
            Control::NewBillet { at_device_ns: Some(at) } => self.pending_billet = Some(at),
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
        self.feeder.pipeline_mut().set_recipe(change.recipe);
        let r = self.writer.write_config(host_now_ns(), super::RECIPE_CONFIG_NAME, &change.text);
        self.recorded("the new recipe", r);
        tracing::info!(recipe = name.as_deref().unwrap_or("none"), "recipe switched");
        self.status.lock().map(|mut s| s.recipe = name).ok();
    }

    /// SIGHUP: read the service file again and take its alert rules, and read its machine
    /// file again and take its model (an effect adopted by `forgemon diagnose --adopt`); a bad
    /// file keeps the old ones. Each new file is recorded where it took effect, so that a
    /// replay changes the rules and the model at the same point.
    pub fn reload(&mut self) {
        match reload(&self.config_path) {
            Ok((new, text)) => {
                self.feeder.pipeline_mut().set_alert_config(new.alerts);
                let r = self.writer.write_config(host_now_ns(), SERVICE_CONFIG_NAME, &text);
                self.recorded("the reloaded service file", r);
                tracing::info!("SIGHUP: alert rules reloaded");
                self.reload_model(&new.machine_path);
            }
            Err(e) => tracing::error!("SIGHUP: keeping the old alert rules and model: {e:#}"),
        }
    }

    /// The machine file at `path`, read again and taken as the model from the next blow on.
    fn reload_model(&mut self, path: &std::path::Path) {
        let read = std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read: {e}", path.display())).and_then(
            |text| {
                let file =
                    crate::config::parse_machine(&path.display().to_string(), &text).map_err(|e| e.to_string())?;
                let effects = file.effect_set();
                self.feeder
                    .pipeline_mut()
                    .set_model(file.machine, effects)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                Ok((text, file.effects.len()))
            },
        );
        match read {
            Ok((text, n)) => {
                let r = self.writer.write_config(host_now_ns(), MACHINE_CONFIG_NAME, &text);
                self.recorded("the reloaded machine file", r);
                tracing::info!(effects = n, "SIGHUP: machine model reloaded from {}", path.display());
            }
            Err(e) => tracing::error!("SIGHUP: keeping the old machine model: {e}"),
        }
    }

    pub fn on_tick(&mut self) {
        let path = self.writer.current_path().display().to_string();
        self.status.lock().map(|mut s| s.recording = path).ok();
    }

    /// The stream ends: the blow in progress and the billet in the dies are closed and
    /// recorded, and the recording finished.
    pub fn finish(mut self) -> anyhow::Result<Summary> {
        self.feeder.pipeline_mut().end_of_stream(&mut self.events);
        self.feeder.pipeline_mut().close_billet(&mut self.events);
        self.emit(host_now_ns());
        self.summary.samples = self.feeder.samples();
        self.summary.billets = u64::from(self.feeder.pipeline_mut().billets());
        self.summary.files = self.writer.finish()?;
        Ok(self.summary)
    }

    /// A new billet from here on: restart the height tracking and alert memory, and mark
    /// the point in the recording so that a replay restarts it at the same sample.
    fn start_billet(&mut self) {
        self.feeder.pipeline_mut().new_billet(&mut self.events);
        let r = self.writer.write_status(host_now_ns(), &new_billet_marker());
        self.recorded("the new-billet marker", r);
        let billets = self.feeder.pipeline_mut().billets();
        self.status.lock().map(|mut s| s.billets = u64::from(billets)).ok();
        self.live.publish(LiveEvent::NewBillet);
        tracing::info!("new billet");
    }

    /// Hand the pipeline's events on; `log_time_ns` is when the samples that produced them
    /// arrived.
    fn emit(&mut self, log_time_ns: i64) {
        let events = std::mem::take(&mut self.events);
        for e in events {
            match e {
                PipelineEvent::Blow { cut, estimate } => {
                    let r = self.writer.write_payload(log_time_ns, &Payload::Boundary(cut.boundary(estimate.blow)));
                    self.recorded("a blow's boundary", r);
                    self.on_blow(&estimate, log_time_ns);
                }
                PipelineEvent::Billet(b) => self.on_billet(&b, log_time_ns),
                PipelineEvent::Rejected { cut, error } => {
                    let msg = format!("blow at t = {:.6} s not estimated: {error}", cut.t_contact_s);
                    tracing::warn!("{msg}");
                    if let Some(f) = self.hooks.on_rejected.as_mut() {
                        f(&msg);
                    }
                }
            }
        }
    }

    fn on_blow(&mut self, estimate: &BlowEstimate, log_time_ns: i64) {
        self.summary.blows += 1;
        self.summary.incomplete_blows += u64::from(!estimate.is_complete());
        let r = self.writer.write_result(log_time_ns, estimate);
        self.recorded("a blow's result", r);
        tracing::info!(blow = estimate.blow, efficiency = estimate.efficiency, class = estimate.class.as_str(), "blow");
        // From the host receiving the batch that ended the blow to its result.
        let latency_ms = (host_now_ns() - log_time_ns) as f64 * 1e-6;
        let curve = self.feeder.pipeline_mut().last_curve().filter(|c| c.blow == estimate.blow);
        self.status
            .lock()
            .map(|mut s| {
                s.on_blow(estimate);
                s.on_curve(curve);
                s.last_result_latency_ms = Some(latency_ms);
            })
            .ok();
        if let Some(alert) = &estimate.alert {
            self.summary.alerts += 1;
            tracing::warn!(kind = alert.kind.as_str(), blow = alert.blow, "{}", alert.reason);
            let r = self.writer.write_alert(log_time_ns, alert);
            self.recorded("an alert", r);
            self.sinks.fire(alert, log_time_ns, &self.status);
        }
        // The hook first: a front end's line for the blow comes before what the live feed's
        // listeners (the advisor's plan after it) make of it.
        if let Some(f) = self.hooks.on_blow.as_mut() {
            f(estimate);
        }
        self.live.publish(LiveEvent::Blow(Arc::new(estimate.clone())));
    }

    fn on_billet(&mut self, b: &BilletSummary, log_time_ns: i64) {
        self.summary.billets_finished += u64::from(b.finished);
        let r = self.writer.write_billet(log_time_ns, b);
        self.recorded("a billet's summary", r);
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
    }

    /// Count a failed recording write and log it: the first, then every hundredth (a full
    /// disk fails every write).
    fn recorded(&mut self, what: &str, r: Result<(), RecordError>) {
        if let Err(e) = r {
            self.summary.record_errors += 1;
            let n = self.summary.record_errors;
            if n == 1 || n.is_multiple_of(100) {
                tracing::error!(errors = n, "recording {what}: {e}");
            }
            self.status.lock().map(|mut s| s.record_errors = n).ok();
        }
    }
}
