//! The session core (DESIGN.md §3, live equals replay): one owner of everything between a
//! sample source and the faces, driven the same way by `run` and `demo` (the service,
//! `daemon::service`) and by `replay`:
//!
//! merge the sources' roles onto one timeline → feed the pipeline (segment, estimate,
//! judge, alert) → record what came in and what came out.
//!
//! It also owns the control markers, each recorded where it took effect so that a replay
//! of the recording takes it at the same sample: a new billet (now, or from a device time
//! on), a recipe switch, a new machine model, new alert rules; and the stop, which closes
//! the blow and billet in progress and finishes the recording.
//!
//! The drivers differ only in what they do with the outcomes (`Outcome`): the service
//! serves them to its faces, `replay` prints them. A recording write that fails does not
//! stop the session: it is kept for the driver (`take_record_errors`), which counts it
//! (the service) or stops (replay).

use crate::alert::AlertConfig;
use crate::config::history::{Trace, trace_text};
use crate::config::parse_machine;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::pipeline::{Cut, Feeder, Pipeline, PipelineEvent};
use crate::recipe::Recipe;
use crate::record::{Gap, Payload, RecordError, RecordWriter, Status};
use crate::signal::merge::Merger;
use crate::signal::sample::{Channels, SampleBatch};

/// Source name of the control markers in a recording.
pub const CONTROL_SOURCE: &str = "control";
/// State of the marker that says a new billet was put in the dies here.
pub const NEW_BILLET_STATE: &str = "new_billet";
/// Name of the active recipe as a recording stores it (topic `/config`): a replay judges
/// with it unless given another.
pub const RECIPE_CONFIG_NAME: &str = "recipe.toml";
/// Name of the machine file as a recording stores it (topic `/config`): at the start and
/// again at each reload, where the model it holds took effect.
pub const MACHINE_CONFIG_NAME: &str = "machine.toml";
/// Name of the service configuration as a recording stores it (topic `/config`), at the
/// start and again at each reload.
pub const SERVICE_CONFIG_NAME: &str = "service.toml";
/// The recorded channels no source carries (issue 43): `absent = ["load"]`, recorded when
/// they are set (`Session::set_absent`), so that a replay does not wait for them.
pub const CHANNELS_CONFIG_NAME: &str = "channels.toml";

/// What the blows from here on are forged as (issue 44: part id, lot, die set), recorded
/// when set (`Session::set_trace`): at the start from `[part]`, and at a new billet given
/// its own. A replay takes it where it is recorded, and the history reads it.
pub const PART_CONFIG_NAME: &str = "part.toml";

/// The text of `CHANNELS_CONFIG_NAME` for `absent`.
pub fn channels_text(absent: Channels) -> String {
    let names: Vec<String> = absent.names().iter().map(|n| format!("\"{n}\"")).collect();
    format!("# the channels no source carries\nabsent = [{}]\n", names.join(", "))
}

/// The channels of a recorded `CHANNELS_CONFIG_NAME` text, `None` when it is not one.
pub fn parse_channels_text(text: &str) -> Option<Channels> {
    let line = text.lines().find_map(|l| l.trim().strip_prefix("absent"))?.trim().strip_prefix('=')?.trim();
    let inner = line.strip_prefix('[')?.strip_suffix(']')?;
    let names = inner.split(',').map(|n| n.trim().trim_matches('"')).filter(|n| !n.is_empty());
    Channels::parse(names).ok()
}

/// The status message that marks a new billet in a recording, in stream order.
pub fn new_billet_marker() -> Status {
    Status { source: CONTROL_SOURCE.into(), state: NEW_BILLET_STATE.into(), ..Default::default() }
}

/// Whether `st` is the new-billet marker.
pub fn is_new_billet_marker(st: &Status) -> bool {
    st.source == CONTROL_SOURCE && st.state == NEW_BILLET_STATE
}

/// State of the marker that says the dies were changed here (issue 44): a new die set's
/// life starts (`history::die`), under the `part.toml` recorded just before it.
pub const DIE_CHANGE_STATE: &str = "die_change";

/// The status message that marks a die change in a recording.
pub fn die_change_marker() -> Status {
    Status { source: CONTROL_SOURCE.into(), state: DIE_CHANGE_STATE.into(), ..Default::default() }
}

/// Whether `st` is the die-change marker.
pub fn is_die_change_marker(st: &Status) -> bool {
    st.source == CONTROL_SOURCE && st.state == DIE_CHANGE_STATE
}

/// The log time a blow's or a billet's messages are recorded at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stamp {
    /// When the samples that completed it arrived (live: the batch's host time).
    Arrival,
    /// Its end on the device's clock (replay of files that carry no arrival time).
    DeviceEnd,
}

/// What a driver gets from the session.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// A blow, estimated and recorded; `log_ns` is the log time it was recorded at.
    Blow { estimate: Box<BlowEstimate>, log_ns: i64 },
    /// A blow was cut but could not be estimated.
    Rejected { cut: Cut, error: crate::estimate::EstimateError },
    /// A billet's summary, recorded.
    Billet { summary: Box<BilletSummary>, log_ns: i64 },
    /// A new billet started here (its marker recorded).
    NewBillet,
    /// The blows from here on are forged as this (a new billet given its own, recorded).
    Forged(Trace),
}

/// How a session's stream ended (`Session::finish`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum End {
    /// The source was stopped while it could still send: the service's stop, and the end
    /// of a recording, which is where a service stopped.
    Stopped,
    /// The input had nothing more: a capture file's end, after its blow.
    InputEnded,
}

/// The session: the input merge, the pipeline and the recording.
pub struct Session {
    feeder: Feeder,
    merger: Merger,
    merged: Vec<SampleBatch>,
    events: Vec<PipelineEvent>,
    /// A new billet announced for a device time the samples have not reached yet.
    pending_billet: Option<i64>,
    /// What the blows are forged as now; each billet's summary carries it.
    trace: Trace,
    /// What the next billet started by a signal is forged as, when it was given.
    next_trace: Option<Trace>,
    writer: Option<RecordWriter>,
    /// The recording's state when it was finished (`recording_health` after `finish`).
    finished_health: Option<crate::record::RecordingHealth>,
    stamp: Stamp,
    record_errors: Vec<(&'static str, RecordError)>,
}

impl Session {
    /// A session feeding `pipeline`, recording to `writer` (none: nothing recorded).
    pub fn new(pipeline: Pipeline, writer: Option<RecordWriter>, stamp: Stamp) -> Self {
        Session {
            feeder: Feeder::new(pipeline),
            merger: Merger::default(),
            merged: Vec::new(),
            events: Vec::new(),
            pending_billet: None,
            trace: Trace::default(),
            next_trace: None,
            writer,
            finished_health: None,
            stamp,
            record_errors: Vec::new(),
        }
    }

    /// The roles no source carries (a hammer without a load cell): the merge does not wait
    /// for them, and the blows are estimated without them (`Merger::set_absent`).
    /// Recorded (`CHANNELS_CONFIG_NAME`) when it changes, at `log_ns`.
    pub fn set_absent(&mut self, absent: Channels, log_ns: i64) {
        if self.merger.absent() != absent {
            self.merger.set_absent(absent);
            self.record("the absent channels", |w| {
                w.write_config(log_ns, CHANNELS_CONFIG_NAME, &channels_text(absent))
            });
        }
    }

    /// A source's batch: recorded, merged with the other sources' roles, fed (a new billet
    /// announced for a device time inside it starts there), and the outcomes appended.
    pub fn batch(&mut self, batch: &SampleBatch, out: &mut Vec<Outcome>) {
        self.record("samples", |w| w.write_samples(batch));
        let direct = self.merger.push(batch, &mut self.merged);
        let merged = std::mem::take(&mut self.merged);
        for b in direct.then_some(batch).into_iter().chain(merged.iter()) {
            let batch_end_ns = b.device_time_ns + (b.period_ns * b.len() as f64) as i64;
            if self.pending_billet.is_some_and(|at| batch_end_ns > at) {
                self.pending_billet = None;
                self.start_billet(batch.host_time_ns, out);
            }
            self.feeder.push(b, &mut self.events);
        }
        self.merged = merged;
        self.merged.clear();
        self.drain(batch.host_time_ns, out);
    }

    /// A source's gap, recorded.
    pub fn gap(&mut self, log_ns: i64, gap: &Gap) {
        self.record("a gap", |w| w.write_gap(log_ns, gap));
    }

    /// A source's status, recorded.
    pub fn status(&mut self, log_ns: i64, status: &Status) {
        self.record("a source's status", |w| w.write_status(log_ns, status));
    }

    /// A new billet in the dies: now (`None`), or from the sample at device time `at` on.
    pub fn new_billet(&mut self, at_device_ns: Option<i64>, log_ns: i64, out: &mut Vec<Outcome>) {
        match at_device_ns {
            None => {
                self.start_billet(log_ns, out);
                self.drain(log_ns, out);
            }
            Some(at) => self.pending_billet = Some(at),
        }
    }

    /// The blows from here on are forged as `trace` (already checked): recorded now.
    pub fn set_trace(&mut self, trace: Trace, log_ns: i64) {
        let text = trace_text(&trace);
        self.trace = trace;
        self.record("the part's trace", |w| w.write_config(log_ns, PART_CONFIG_NAME, &text));
    }

    /// Record `text` as the configuration file `name` (`/config`): what a replay or a history
    /// rebuild takes up from here, such as the drift alarms' learnt reference.
    pub fn record_config(&mut self, what: &'static str, name: &str, text: &str, log_ns: i64) {
        self.record(what, |w| w.write_config(log_ns, name, text));
    }

    /// The dies were changed: forged as `trace` from here on (its `die_set` the new set's
    /// name), then the die-change marker, both recorded now.
    pub fn change_dies(&mut self, trace: Trace, log_ns: i64) {
        self.set_trace(trace, log_ns);
        self.dies_changed(log_ns);
    }

    /// The die-change marker alone (a replay, which took the trace from its own marker).
    pub fn dies_changed(&mut self, log_ns: i64) {
        self.record("the die-change marker", |w| w.write_status(log_ns, &die_change_marker()));
    }

    /// The next billet a signal starts (`new_billet`) is forged as `trace`: recorded just
    /// after its marker.
    pub fn trace_next_billet(&mut self, trace: Trace) {
        self.next_trace = Some(trace);
    }

    /// What the blows are forged as now.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// What the next billet a signal starts is forged as: as given for it, or as now.
    pub fn next_trace(&self) -> &Trace {
        self.next_trace.as_ref().unwrap_or(&self.trace)
    }

    /// Judge the following blows against `recipe` (already checked), whose text is `text`.
    pub fn set_recipe(&mut self, recipe: Option<Recipe>, text: &str, log_ns: i64) {
        self.feeder.pipeline_mut().set_recipe(recipe);
        self.record("the new recipe", |w| w.write_config(log_ns, RECIPE_CONFIG_NAME, text));
    }

    /// Take the machine file `text` (from `origin`) as the model from the next blow on;
    /// the number of its effects, or why not (the old model kept).
    pub fn set_model(&mut self, origin: &str, text: &str, log_ns: i64) -> Result<usize, String> {
        let file = parse_machine(origin, text).map_err(|e| e.to_string())?;
        let effects = file.effect_set();
        self.feeder.pipeline_mut().set_model(file.machine, effects).map_err(|e| format!("{origin}: {e}"))?;
        self.record("the machine file", |w| w.write_config(log_ns, MACHINE_CONFIG_NAME, text));
        Ok(file.effects.len())
    }

    /// Take `alerts` (from the service file `text`) from the next blow on.
    pub fn set_alerts(&mut self, alerts: AlertConfig, text: &str, log_ns: i64) {
        self.feeder.pipeline_mut().set_alert_config(alerts);
        self.record("the service file", |w| w.write_config(log_ns, SERVICE_CONFIG_NAME, text));
    }

    /// The end of the stream: the blow in progress and the billet in the dies closed and
    /// recorded, and the recording finished; its files back. Nothing is recorded after.
    /// `End::Stopped` (the service's stop, a recording's end) reports a blow in progress
    /// `incomplete`; `End::InputEnded` (capture files) keeps one whose spring-back is seen.
    pub fn finish(
        &mut self,
        end: End,
        log_ns: i64,
        out: &mut Vec<Outcome>,
    ) -> Result<Vec<std::path::PathBuf>, RecordError> {
        match end {
            End::Stopped => self.feeder.pipeline_mut().stop(&mut self.events),
            End::InputEnded => self.feeder.pipeline_mut().end_of_stream(&mut self.events),
        }
        self.feeder.pipeline_mut().close_billet(&mut self.events);
        self.drain(log_ns, out);
        self.finished_health = self.recording_health();
        self.writer.take().map_or(Ok(Vec::new()), RecordWriter::finish)
    }

    /// The pipeline with what it has counted, once the session is over.
    pub fn into_feeder(self) -> Feeder {
        self.feeder
    }

    /// The failed recording writes since the last call, each with what it was writing.
    pub fn take_record_errors(&mut self) -> Vec<(&'static str, RecordError)> {
        std::mem::take(&mut self.record_errors)
    }

    pub fn feeder(&self) -> &Feeder {
        &self.feeder
    }

    pub fn pipeline_mut(&mut self) -> &mut Pipeline {
        self.feeder.pipeline_mut()
    }

    pub fn merger(&self) -> &Merger {
        &self.merger
    }

    /// The file being recorded to.
    pub fn recording_path(&self) -> Option<std::path::PathBuf> {
        self.writer.as_ref().map(RecordWriter::current_path)
    }

    /// The recording's state (writing or suspended, space left, messages dropped), as it
    /// was at the end once finished; `None` when nothing is recorded.
    pub fn recording_health(&self) -> Option<crate::record::RecordingHealth> {
        self.writer.as_ref().map(RecordWriter::health).or_else(|| self.finished_health.clone())
    }

    /// An alert the driver raised (not a blow's), recorded on `/alerts`.
    pub fn alert(&mut self, log_ns: i64, alert: &crate::alert::Alert) {
        self.record("an alert", |w| w.write_alert(log_ns, alert));
    }

    fn start_billet(&mut self, log_ns: i64, out: &mut Vec<Outcome>) {
        self.feeder.pipeline_mut().new_billet(&mut self.events);
        // The billet that ended is reported before the marker of the one that starts.
        self.drain(log_ns, out);
        self.record("the new-billet marker", |w| w.write_status(log_ns, &new_billet_marker()));
        if let Some(trace) = self.next_trace.take() {
            self.set_trace(trace.clone(), log_ns);
            out.push(Outcome::Forged(trace));
        }
        out.push(Outcome::NewBillet);
    }

    /// The pipeline's events recorded and handed on; `log_ns` is when the samples that
    /// produced them arrived.
    fn drain(&mut self, log_ns: i64, out: &mut Vec<Outcome>) {
        for e in std::mem::take(&mut self.events) {
            match e {
                PipelineEvent::Blow { cut, estimate } => {
                    let at = self.at(log_ns, cut.t_end_s);
                    self.record("a blow's boundary", |w| {
                        w.write_payload(at, &Payload::Boundary(cut.boundary(estimate.blow)))
                    });
                    self.record("a blow's result", |w| w.write_result(at, &estimate));
                    if let Some(a) = &estimate.alert {
                        self.record("an alert", |w| w.write_alert(at, a));
                    }
                    out.push(Outcome::Blow { estimate, log_ns: at });
                }
                PipelineEvent::Billet(mut summary) => {
                    summary.trace = self.trace.clone();
                    let at = self.at(log_ns, summary.t_end_s);
                    self.record("a billet's summary", |w| w.write_billet(at, &summary));
                    out.push(Outcome::Billet { summary, log_ns: at });
                }
                PipelineEvent::Rejected { cut, error } => out.push(Outcome::Rejected { cut, error }),
            }
        }
    }

    fn at(&self, log_ns: i64, t_end_s: f64) -> i64 {
        match self.stamp {
            Stamp::Arrival => log_ns,
            Stamp::DeviceEnd => (t_end_s * 1e9).round() as i64,
        }
    }

    fn record(&mut self, what: &'static str, write: impl FnOnce(&mut RecordWriter) -> Result<(), RecordError>) {
        if let Some(w) = self.writer.as_mut()
            && let Err(e) = write(w)
        {
            self.record_errors.push((what, e));
        }
    }
}
