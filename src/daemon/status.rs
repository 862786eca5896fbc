//! The service's live state, served on loopback: `/status` (JSON) and `/metrics`
//! (Prometheus text format): samples, drops, gaps, transport states, blows, the last
//! efficiency and class, alerts. The same server carries the dashboard (`dashboard`) and,
//! when a token is configured, refuses every request without it (`dashboard::auth`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::{Arc, Mutex};

use axum::Router;
use axum::extract::State;
use axum::http::StatusCode;
use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::{get, post};
use serde::Serialize;

use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::estimate::curve::BlowCurve;
use crate::estimate::result::Alert;
use crate::record::{Gap, Status};
use crate::signal::align::ClockModel;
use crate::signal::merge::MergeStats;
use crate::signal::sample::SampleBatch;

use super::dashboard::auth::{Token, require_token};
use super::dashboard::board::Board;

/// Shared between the service loop and the HTTP handlers.
pub type SharedStatus = Arc<Mutex<StatusSnapshot>>;

/// One source as the status endpoint shows it.
#[derive(Debug, Clone, Default, Serialize)]
pub struct SourceState {
    pub state: String,
    pub samples: u64,
    pub drops: u64,
    pub gaps: u64,
    pub samples_lost: u64,
    pub crc_errors: u64,
    pub decode_errors: u64,
    pub reconnects: u64,
    pub detail: String,
    /// The device clock against the host's (signal::align), once batches arrived.
    pub clock_drift_ppm: Option<f64>,
    /// Host time minus device time at the latest batch, s.
    pub clock_offset_s: Option<f64>,
}

/// The recording's disk, as `/status` shows it (`storage`): the recorder's state, and the
/// watermark under which a `storage` alert is raised.
#[derive(Debug, Clone, Default, Serialize)]
pub struct StorageStatus {
    #[serde(flatten)]
    pub recording: crate::record::RecordingHealth,
    /// `[recording] min_free_bytes`.
    pub min_free_bytes: u64,
    /// Free space under the watermark, or the recording suspended: the alert's condition.
    pub low: bool,
}

/// What `/status` returns.
#[derive(Debug, Clone, Serialize)]
pub struct StatusSnapshot {
    pub machine: String,
    /// Billets started, by the encoder's billet detection or a signal (`POST /billet`, the
    /// PLC coil); 0 before the first blow.
    pub billets: u64,
    /// Billets finished: each billet is finished when the next one starts.
    pub billets_finished: u64,
    /// Blows on the billet in the dies so far.
    pub billet_blows: u64,
    /// Blows the last finished billet took.
    pub last_billet_blows: Option<u64>,
    /// The last billet summarised (`/billets` in the recording).
    pub last_billet: Option<BilletSummary>,
    pub samples: u64,
    pub blows: u64,
    pub alerts: u64,
    /// Blows reported incomplete (samples lost inside them).
    pub incomplete_blows: u64,
    /// Blows reported implausible (a value outside its physical range, issue 36).
    pub implausible_blows: u64,
    /// Events the live queue dropped because the pipeline fell behind.
    pub dropped_events: u64,
    /// Recording writes that failed (logged; the service goes on).
    pub record_errors: u64,
    pub last_efficiency: Option<f64>,
    pub last_class: Option<String>,
    pub last_blow: Option<BlowEstimate>,
    /// The last alert raised, latched until the operator acknowledges it (`POST /ack`, the
    /// PLC's coil 0); `None` when there is none or it was acknowledged.
    pub latched_alert: Option<Alert>,
    /// The name of the recipe the blows are judged against (`recipe` in `service.toml`),
    /// `None` without one.
    pub recipe: Option<String>,
    /// The last SIGHUP reload: what it took (`applied`), which changed keys wait for a
    /// restart (`needs_restart`), or why it took nothing (`error`); `None` before the first.
    pub reload: Option<super::reload::ReloadReport>,
    /// The live advisor's plan for the billet's next blows (`[advisor]`), `None` without
    /// one.
    pub advice: Option<crate::advise::Advice>,
    /// From the host receiving the samples that ended the last blow to its result, ms.
    pub last_result_latency_ms: Option<f64>,
    /// From the host receiving the samples that ended the last alerting blow to the
    /// webhook's answer, ms.
    pub last_webhook_latency_ms: Option<f64>,
    pub sources: BTreeMap<String, SourceState>,
    /// Roles merged from several sources onto one timeline (signal::merge), when no
    /// source carries all three.
    pub merge: MergeStats,
    pub recording: String,
    /// The recording's state and its disk (filled every second).
    pub storage: StorageStatus,
    /// What the blows are forged as now (`[part]`, `POST /billet`'s body): part id, lot,
    /// die set, each absent until set.
    pub part: crate::estimate::billet_book::Trace,
    /// The die set in the hammer: what it has taken, where it stands against `[die_life]`.
    pub die_life: super::die_life::DieLifeStatus,
    /// The drift alarms' state (`[drift]`), `None` when disabled.
    pub drift: Option<crate::alert::drift::DriftStatus>,
    /// The history database's writer (`[history]`, filled every second): rows written,
    /// messages dropped by its full queue or a failed write; `None` when it is off.
    pub history: Option<crate::history::writer::HistoryStatus>,
    /// What the dashboard shows beyond this (`GET /dashboard/state`), not in `/status`.
    #[serde(skip)]
    pub board: Board,
}

impl StatusSnapshot {
    pub fn new(machine: &str) -> Self {
        StatusSnapshot {
            machine: machine.to_string(),
            billets: 0,
            billets_finished: 0,
            billet_blows: 0,
            last_billet_blows: None,
            last_billet: None,
            samples: 0,
            blows: 0,
            alerts: 0,
            incomplete_blows: 0,
            implausible_blows: 0,
            dropped_events: 0,
            record_errors: 0,
            last_efficiency: None,
            last_class: None,
            last_blow: None,
            latched_alert: None,
            recipe: None,
            reload: None,
            advice: None,
            last_result_latency_ms: None,
            last_webhook_latency_ms: None,
            sources: BTreeMap::new(),
            merge: MergeStats::default(),
            recording: String::new(),
            storage: StorageStatus::default(),
            history: None,
            part: Default::default(),
            die_life: Default::default(),
            drift: None,
            board: Board::default(),
        }
    }

    pub fn on_samples(&mut self, b: &SampleBatch, clock: Option<&ClockModel>, merge: MergeStats) {
        self.samples += b.len() as u64;
        self.merge = merge;
        let s = self.sources.entry(b.source.clone()).or_default();
        s.samples += b.len() as u64;
        if let Some(clock) = clock.filter(|c| c.len() >= 2) {
            s.clock_drift_ppm = Some(clock.drift_ppm());
            s.clock_offset_s = Some((clock.map(b.device_time_ns) - b.device_time_ns) as f64 * 1e-9);
        }
        self.board.on_samples(b, clock);
    }

    pub fn on_gap(&mut self, g: &Gap) {
        let s = self.sources.entry(g.source.clone()).or_default();
        s.gaps += 1;
        s.samples_lost += g.samples_lost;
    }

    pub fn on_status(&mut self, st: Status) {
        let s = self.sources.entry(st.source.clone()).or_default();
        s.state = st.state;
        s.drops = st.drops;
        s.crc_errors = st.crc_errors;
        s.decode_errors = st.decode_errors;
        s.reconnects = st.reconnects;
        s.detail = st.detail;
    }

    pub fn on_blow(&mut self, e: &BlowEstimate) {
        self.blows += 1;
        self.billets = self.billets.max(u64::from(e.billet.billet));
        self.billet_blows = u64::from(e.billet.billet_blow);
        self.alerts += u64::from(e.alert.is_some());
        self.incomplete_blows += u64::from(!e.is_complete());
        self.implausible_blows += u64::from(e.class == crate::estimate::BlowClass::Implausible);
        self.last_efficiency = e.efficiency;
        self.last_class = Some(e.class.as_str().to_string());
        self.last_blow = Some(e.clone());
        if let Some(a) = &e.alert {
            self.latched_alert = Some(a.clone());
        }
        self.board.on_blow(e);
    }

    /// The last blow's curve, for the dashboard.
    pub fn on_curve(&mut self, c: Option<Arc<BlowCurve>>) {
        self.board.curve = c;
    }

    /// The operator acknowledged the latched alert; whether there was one.
    pub fn acknowledge(&mut self) -> bool {
        let acked = self.latched_alert.take();
        let was = acked.is_some();
        if was {
            self.board.acknowledged_alert = acked;
        }
        was
    }

    /// A billet was summarised: finished when the next one started, or the run's last.
    pub fn on_billet(&mut self, b: &BilletSummary) {
        if b.finished {
            self.billets_finished += 1;
            self.last_billet_blows = Some(u64::from(b.blows));
            self.billet_blows = 0;
            self.board.on_billet_finished();
        }
        self.last_billet = Some(b.clone());
    }

    /// Prometheus text exposition (version 0.0.4).
    pub fn metrics(&self) -> String {
        let mut m = String::new();
        for (name, kind, help, value) in METRICS {
            let rows: Vec<(String, f64)> = match value {
                Value::Service(f) => f(self).map(|v| (String::new(), v)).into_iter().collect(),
                Value::Source(f) => self.sources.iter().map(|(k, s)| (format!("{{source=\"{k}\"}}"), f(s))).collect(),
            };
            // A gauge with no value yet (no blow, no finished billet) is left out.
            if matches!(value, Value::Service(_)) && rows.is_empty() {
                continue;
            }
            let _ = writeln!(m, "# HELP forgemon_{name} {help}\n# TYPE forgemon_{name} {kind}");
            for (labels, v) in rows {
                let _ = writeln!(m, "forgemon_{name}{labels} {v}");
            }
        }
        m
    }
}

async fn status_json(State(s): State<SharedStatus>) -> impl IntoResponse {
    let body = s.lock().map(|s| serde_json::to_string(&*s).unwrap_or_default()).unwrap_or_default();
    ([(header::CONTENT_TYPE, "application/json")], body)
}

async fn metrics_text(State(s): State<SharedStatus>) -> impl IntoResponse {
    let body = s.lock().map(|s| s.metrics()).unwrap_or_default();
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], body)
}

/// `POST /die`: the dies were changed; a JSON body as `POST /billet`'s names the new set
/// (`{"die_set": "18"}`; without one, the same name starts again from zero).
async fn die_change(
    State(tx): State<tokio::sync::mpsc::Sender<super::Control>>,
    body: axum::body::Bytes,
) -> impl IntoResponse {
    let change = if body.iter().all(u8::is_ascii_whitespace) {
        crate::config::history::TraceUpdate::default()
    } else {
        match crate::config::history::TraceUpdate::from_json(&body) {
            Ok(change) => change,
            Err(why) => return (StatusCode::BAD_REQUEST, format!("POST /die: {why}\n")),
        }
    };
    match tx.try_send(super::Control::DieChange(Box::new(change))) {
        Ok(()) => (StatusCode::ACCEPTED, "die change\n".to_string()),
        Err(_) => (StatusCode::SERVICE_UNAVAILABLE, "the service is busy or stopping\n".to_string()),
    }
}

/// `POST /billet`: a new billet now; a JSON body (`{"part_id": .., "lot": .., "die_set":
/// ..}`, each a string or null, any left out) also says what it is forged as.
async fn new_billet(
    State(tx): State<tokio::sync::mpsc::Sender<super::Control>>,
    body: axum::body::Bytes,
) -> impl IntoResponse {
    let control = if body.iter().all(u8::is_ascii_whitespace) {
        super::Control::NewBillet { at_device_ns: None }
    } else {
        match crate::config::history::TraceUpdate::from_json(&body) {
            Ok(change) => super::Control::NewBilletAs { at_device_ns: None, change: Box::new(change) },
            Err(why) => return (StatusCode::BAD_REQUEST, format!("POST /billet: {why}\n")),
        }
    };
    match tx.try_send(control) {
        Ok(()) => (StatusCode::ACCEPTED, "new billet\n".to_string()),
        Err(_) => (StatusCode::SERVICE_UNAVAILABLE, "the service is busy or stopping\n".to_string()),
    }
}

/// `GET /status`, `GET /metrics`, `POST /billet` and `more` (the dashboard's `GET /`, its
/// state and events, `POST /ack`; `POST /recipe`), with a token only to requests that
/// present it: what the service's HTTP server (`http_server`) serves.
pub fn routes(
    status: SharedStatus,
    control: tokio::sync::mpsc::Sender<super::Control>,
    token: Option<Token>,
    more: Router,
) -> Router {
    Router::new()
        .route("/status", get(status_json))
        .route("/metrics", get(metrics_text))
        .with_state(status)
        .merge(Router::new().route("/billet", post(new_billet)).route("/die", post(die_change)).with_state(control))
        .merge(more)
        .layer(axum::middleware::from_fn_with_state(token, require_token))
}

/// Where a metric's value comes from: the service's state, or each source's (labelled).
enum Value {
    Service(fn(&StatusSnapshot) -> Option<f64>),
    Source(fn(&SourceState) -> f64),
}

/// `/metrics`, in order: name (after `forgemon_`), type, help, value.
const METRICS: [(&str, &str, &str, Value); 26] = [
    ("samples_total", "counter", "Samples received.", Value::Source(|s| s.samples as f64)),
    ("drops_total", "counter", "Events dropped at a full pipeline channel.", Value::Source(|s| s.drops as f64)),
    (
        "queue_dropped_events_total",
        "counter",
        "Oldest events the live queue dropped because the pipeline fell behind.",
        Value::Service(|s| Some(s.dropped_events as f64)),
    ),
    (
        "record_errors_total",
        "counter",
        "Recording writes that failed.",
        Value::Service(|s| Some(s.record_errors as f64)),
    ),
    (
        "record_dropped_blows_total",
        "counter",
        "Blow results not recorded: the recording was suspended or the write failed.",
        Value::Service(|s| Some(s.storage.recording.dropped_blows as f64)),
    ),
    (
        "recording_suspended",
        "gauge",
        "1 while the recording is suspended after a failed write, else 0.",
        Value::Service(|s| Some(f64::from(u8::from(s.storage.recording.state == "suspended")))),
    ),
    (
        "storage_bytes_free",
        "gauge",
        "Bytes free for the recording in its directory.",
        Value::Service(|s| s.storage.recording.bytes_free.map(|b| b as f64)),
    ),
    ("billets_total", "counter", "Billets started.", Value::Service(|s| Some(s.billets as f64))),
    (
        "billets_finished_total",
        "counter",
        "Billets finished (the next one started).",
        Value::Service(|s| Some(s.billets_finished as f64)),
    ),
    ("billet_blows", "gauge", "Blows on the billet in the dies.", Value::Service(|s| Some(s.billet_blows as f64))),
    (
        "last_billet_blows",
        "gauge",
        "Blows the last finished billet took.",
        Value::Service(|s| s.last_billet_blows.map(|n| n as f64)),
    ),
    (
        "incomplete_blows_total",
        "counter",
        "Blows with samples lost inside them, reported without energies.",
        Value::Service(|s| Some(s.incomplete_blows as f64)),
    ),
    (
        "implausible_blows_total",
        "counter",
        "Blows with a value outside its physical range, reported without energies.",
        Value::Service(|s| Some(s.implausible_blows as f64)),
    ),
    ("gaps_total", "counter", "Gaps in the sample stream.", Value::Source(|s| s.gaps as f64)),
    ("samples_lost_total", "counter", "Samples lost in gaps.", Value::Source(|s| s.samples_lost as f64)),
    ("crc_errors_total", "counter", "Frames with a bad CRC.", Value::Source(|s| s.crc_errors as f64)),
    (
        "decode_errors_total",
        "counter",
        "Frames or lines that did not decode.",
        Value::Source(|s| s.decode_errors as f64),
    ),
    ("reconnects_total", "counter", "Transport reconnections.", Value::Source(|s| s.reconnects as f64)),
    (
        "source_up",
        "gauge",
        "1 when the source is connected.",
        Value::Source(|s| f64::from(u8::from(s.state == "connected"))),
    ),
    (
        "merged_samples_total",
        "counter",
        "Timeline samples with roles merged from several sources.",
        Value::Service(|s| Some(s.merge.merged_samples as f64)),
    ),
    (
        "merge_held_values_total",
        "counter",
        "Merged role values held because their source was late.",
        Value::Service(|s| Some(s.merge.held_values as f64)),
    ),
    (
        "merge_dropped_samples_total",
        "counter",
        "Timeline samples dropped because a role's source had sent nothing.",
        Value::Service(|s| Some(s.merge.dropped_samples as f64)),
    ),
    ("blows_total", "counter", "Blows estimated.", Value::Service(|s| Some(s.blows as f64))),
    ("alerts_total", "counter", "Alerts raised.", Value::Service(|s| Some(s.alerts as f64))),
    (
        "result_latency_ms",
        "gauge",
        "Receipt of the blow's last samples to its result, ms.",
        Value::Service(|s| s.last_result_latency_ms),
    ),
    (
        "last_efficiency",
        "gauge",
        "Efficiency of the last blow (plastic / kinetic in).",
        Value::Service(|s| s.last_efficiency),
    ),
];

#[cfg(test)]
mod tests {
    use super::*;

    /// The user guide's `/status` table names exactly the fields the endpoint returns, so
    /// the two cannot drift apart.
    #[test]
    fn the_guide_documents_every_status_field() {
        let readme = include_str!("../../docs/guide.md");
        let start = readme.find("### `/status`: what the service reports").expect("the guide's /status section");
        let table: Vec<&str> = readme[start..]
            .lines()
            .skip_while(|l| !l.starts_with("| field"))
            .skip(2)
            .take_while(|l| l.starts_with("| `"))
            .filter_map(|l| l.split('`').nth(1))
            .collect();
        let json = serde_json::to_value(StatusSnapshot::new("hammer")).expect("serialises");
        let mut fields: Vec<&str> = json.as_object().expect("an object").keys().map(String::as_str).collect();
        let mut documented = table.clone();
        fields.sort_unstable();
        documented.sort_unstable();
        assert_eq!(documented, fields);
        // The per-source and merge objects' keys are named in their rows.
        let row = |name: &str| readme[start..].lines().find(|l| l.starts_with(&format!("| `{name}`"))).unwrap_or("");
        let source = serde_json::to_value(SourceState::default()).expect("serialises");
        for key in source.as_object().expect("an object").keys() {
            assert!(row("sources").contains(&format!("`{key}`")), "sources.{key} is not documented");
        }
        for key in serde_json::to_value(MergeStats::default()).expect("serialises").as_object().expect("object").keys()
        {
            assert!(row("merge").contains(&format!("`{key}`")), "merge.{key} is not documented");
        }
    }
}
