//! Sparkplug B 3.0 topics and payloads for one forgemon edge node (pure, no IO, no clock):
//! the NBIRTH with the node's metrics and `bdSeq`, the DBIRTH declaring every blow and
//! alert metric with its type, one DDATA per blow (docs/interfaces.md §5 fields as `blow/<field>`,
//! the blow's alert as `alert/<kind>`), the NDEATH will, and reading an NCMD rebirth.
//! Times are passed in as ms since the Unix epoch.

use prost::Message;

use super::proto::Payload;
use super::proto::payload::{Metric, metric};
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::Trace;

/// The Sparkplug B topic namespace (specification §4.1.1).
pub const NAMESPACE: &str = "spBv1.0";
/// The node metric that carries the birth/death sequence (specification §6.4.19).
pub const BD_SEQ: &str = "bdSeq";
/// The node metric a host writes `true` to in an NCMD to ask for a rebirth (§6.4.20).
pub const REBIRTH: &str = "Node Control/Rebirth";
/// Node metric: DDATA the bounded queue dropped (full or too old) since the service started.
pub const QUEUE_DROPPED: &str = "uplink/queue_dropped";
/// Node metric: blows the live feed dropped before the publisher saw them (it lagged).
pub const LIVE_LAGGED: &str = "uplink/lagged";

/// Sparkplug data types (specification §6.4.16).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum DataType {
    UInt32 = 7,
    UInt64 = 8,
    Double = 10,
    Boolean = 11,
    String = 12,
}

/// The docs/interfaces.md §5 fields published as `blow/<field>`, with their Sparkplug types. Values
/// are taken from the blow's JSON by these names, so they are the replay's names exactly.
pub const BLOW_FIELDS: &[(&str, DataType)] = &[
    ("blow", DataType::UInt32),
    ("t_contact_s", DataType::Double),
    ("v_impact_mps", DataType::Double),
    ("kinetic_in_J", DataType::Double),
    ("plastic_J", DataType::Double),
    ("friction_J", DataType::Double),
    ("damped_J", DataType::Double),
    ("elastic_J", DataType::Double),
    ("efficiency", DataType::Double),
    ("final_load_N", DataType::Double),
    ("peak_load_N", DataType::Double),
    ("h_end_m", DataType::Double),
    ("class", DataType::String),
    ("gap_s", DataType::Double),
    ("sensor_check", DataType::Double),
    // The §9 judgement object as JSON text (`null` without a recipe).
    ("judgement", DataType::String),
    ("billet", DataType::UInt32),
    ("billet_blow", DataType::UInt32),
];

/// What a blow was forged as (issue 44: `[part]`, `POST /billet`, the PLC's part block, OPC
/// UA's `SetPart`), published as `blow/<field>` strings, null when not given.
pub const TRACE_FIELDS: [&str; 3] = ["part_id", "lot", "die_set"];

/// The alert kinds of docs/interfaces.md §5, published as `alert/<kind>` holding the alert's reason.
pub const ALERT_KINDS: &[&str] = &["elastic_blow", "low_efficiency", "model_health", "sensor", "nok"];

/// Which of a node's messages a topic carries (specification §4.1.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageType {
    NBirth,
    NDeath,
    DBirth,
    DData,
    NCmd,
}

impl MessageType {
    fn as_str(self) -> &'static str {
        match self {
            MessageType::NBirth => "NBIRTH",
            MessageType::NDeath => "NDEATH",
            MessageType::DBirth => "DBIRTH",
            MessageType::DData => "DDATA",
            MessageType::NCmd => "NCMD",
        }
    }
}

/// The node's place in the namespace: `spBv1.0/<group>/<type>/<node>[/<device>]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeIds {
    pub group_id: String,
    pub edge_node_id: String,
    pub device_id: String,
}

impl NodeIds {
    /// The topic of a message of type `t` (device messages carry the device id).
    pub fn topic(&self, t: MessageType) -> String {
        let base = format!("{NAMESPACE}/{}/{}/{}", self.group_id, t.as_str(), self.edge_node_id);
        match t {
            MessageType::DBirth | MessageType::DData => format!("{base}/{}", self.device_id),
            _ => base,
        }
    }
}

/// The node's counters reported in its NBIRTH.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NodeCounters {
    pub queue_dropped: u64,
    pub lagged: u64,
}

/// The next `seq` after `seq`: 0..=255 and round again (specification §6.4.3).
pub fn next_seq(seq: u64) -> u64 {
    (seq + 1) % 256
}

fn metric(name: &str, t_ms: u64, datatype: DataType, value: Option<metric::Value>) -> Metric {
    Metric {
        name: Some(name.to_string()),
        timestamp: Some(t_ms),
        datatype: Some(datatype as u32),
        is_null: value.is_none().then_some(true),
        value,
        ..Default::default()
    }
}

/// The NBIRTH: `bdSeq`, the rebirth control and the uplink's counters; `seq` is 0.
pub fn nbirth(bd_seq: u64, counters: NodeCounters, t_ms: u64) -> Payload {
    let metrics = vec![
        metric(BD_SEQ, t_ms, DataType::UInt64, Some(metric::Value::LongValue(bd_seq))),
        metric(REBIRTH, t_ms, DataType::Boolean, Some(metric::Value::BooleanValue(false))),
        metric(QUEUE_DROPPED, t_ms, DataType::UInt64, Some(metric::Value::LongValue(counters.queue_dropped))),
        metric(LIVE_LAGGED, t_ms, DataType::UInt64, Some(metric::Value::LongValue(counters.lagged))),
    ];
    Payload { timestamp: Some(t_ms), metrics, seq: Some(0), ..Default::default() }
}

/// The NDEATH, registered as the MQTT will: only `bdSeq`, no `seq` (specification §6.4.19).
pub fn ndeath(bd_seq: u64) -> Payload {
    Payload {
        metrics: vec![Metric {
            name: Some(BD_SEQ.into()),
            datatype: Some(DataType::UInt64 as u32),
            value: Some(metric::Value::LongValue(bd_seq)),
            ..Default::default()
        }],
        ..Default::default()
    }
}

/// The DBIRTH: every `blow/<field>` and `alert/<kind>` metric with its type, null until the
/// first blow.
pub fn dbirth(seq: u64, t_ms: u64) -> Payload {
    let blows = BLOW_FIELDS.iter().map(|(f, t)| metric(&format!("blow/{f}"), t_ms, *t, None));
    let trace = TRACE_FIELDS.iter().map(|f| metric(&format!("blow/{f}"), t_ms, DataType::String, None));
    let alerts = ALERT_KINDS.iter().map(|k| metric(&format!("alert/{k}"), t_ms, DataType::String, None));
    let metrics = blows.chain(trace).chain(alerts).collect();
    Payload { timestamp: Some(t_ms), metrics, seq: Some(seq), ..Default::default() }
}

/// A blow's DDATA as it is queued: every `blow/<field>` at `t_ms` (when the service made
/// the result), what it was forged as (`trace`), plus `alert/<kind>` if the blow raised an
/// alert; no `seq` yet.
pub fn blow_data(e: &BlowEstimate, trace: &Trace, t_ms: u64) -> Payload {
    let json = serde_json::to_value(e).unwrap_or(serde_json::Value::Null);
    let mut metrics: Vec<Metric> =
        BLOW_FIELDS.iter().map(|(f, t)| metric(&format!("blow/{f}"), t_ms, *t, value_of(json.get(*f), *t))).collect();
    for (f, v) in TRACE_FIELDS.iter().zip([&trace.part_id, &trace.lot, &trace.die_set]) {
        let value = v.clone().map(metric::Value::StringValue);
        metrics.push(metric(&format!("blow/{f}"), t_ms, DataType::String, value));
    }
    if let Some(a) = &e.alert {
        let reason = metric::Value::StringValue(a.reason.clone());
        metrics.push(metric(&format!("alert/{}", a.kind.as_str()), t_ms, DataType::String, Some(reason)));
    }
    Payload { timestamp: Some(t_ms), metrics, ..Default::default() }
}

/// A JSON value as a Sparkplug value of type `t` (`None`: null, absent, or of another kind).
fn value_of(v: Option<&serde_json::Value>, t: DataType) -> Option<metric::Value> {
    let v = v.filter(|v| !v.is_null())?;
    match t {
        DataType::UInt32 => v.as_u64().and_then(|x| u32::try_from(x).ok()).map(metric::Value::IntValue),
        DataType::UInt64 => v.as_u64().map(metric::Value::LongValue),
        DataType::Double => v.as_f64().map(metric::Value::DoubleValue),
        DataType::Boolean => v.as_bool().map(metric::Value::BooleanValue),
        DataType::String => {
            Some(metric::Value::StringValue(v.as_str().map(str::to_string).unwrap_or_else(|| v.to_string())))
        }
    }
}

/// A queued DDATA made ready to publish: its `seq`, and the historical flag on every metric
/// when it was made before the current birth (published from the queue after an outage).
pub fn stamp_data(mut p: Payload, seq: u64, historical: bool) -> Payload {
    p.seq = Some(seq);
    for m in &mut p.metrics {
        m.is_historical = historical.then_some(true);
    }
    p
}

/// Whether an NCMD payload asks for a rebirth (`Node Control/Rebirth` = true); garbage is
/// not a request.
pub fn is_rebirth_request(bytes: &[u8]) -> bool {
    Payload::decode(bytes).is_ok_and(|p| {
        p.metrics
            .iter()
            .any(|m| m.name.as_deref() == Some(REBIRTH) && matches!(m.value, Some(metric::Value::BooleanValue(true))))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids() -> NodeIds {
        NodeIds { group_id: "forge".into(), edge_node_id: "hammer-1".into(), device_id: "lg1000".into() }
    }

    #[test]
    fn topics_follow_the_namespace() {
        assert_eq!(ids().topic(MessageType::NBirth), "spBv1.0/forge/NBIRTH/hammer-1");
        assert_eq!(ids().topic(MessageType::DData), "spBv1.0/forge/DDATA/hammer-1/lg1000");
        assert_eq!(ids().topic(MessageType::NCmd), "spBv1.0/forge/NCMD/hammer-1");
    }

    #[test]
    fn seq_wraps_after_255() {
        assert_eq!(next_seq(254), 255);
        assert_eq!(next_seq(255), 0);
    }

    #[test]
    fn death_and_birth_carry_the_same_bd_seq() {
        let birth = nbirth(7, NodeCounters::default(), 1000);
        let death = ndeath(7);
        let bd =
            |p: &Payload| p.metrics.iter().find(|m| m.name.as_deref() == Some(BD_SEQ)).and_then(|m| m.value.clone());
        assert_eq!(bd(&birth), Some(metric::Value::LongValue(7)));
        assert_eq!(bd(&birth), bd(&death));
        assert_eq!((birth.seq, death.seq), (Some(0), None));
    }

    #[test]
    fn dbirth_declares_every_field_and_alert_with_a_type() {
        let p = dbirth(1, 5);
        assert_eq!(p.metrics.len(), BLOW_FIELDS.len() + TRACE_FIELDS.len() + ALERT_KINDS.len());
        assert!(p.metrics.iter().all(|m| m.datatype.is_some() && m.is_null == Some(true)));
    }

    #[test]
    fn rebirth_request_is_read_and_garbage_is_not_one() {
        let mut p = Payload::default();
        p.metrics.push(Metric {
            name: Some(REBIRTH.into()),
            value: Some(metric::Value::BooleanValue(true)),
            ..Default::default()
        });
        assert!(is_rebirth_request(&p.encode_to_vec()));
        p.metrics[0].value = Some(metric::Value::BooleanValue(false));
        assert!(!is_rebirth_request(&p.encode_to_vec()));
        assert!(!is_rebirth_request(&[0xff, 0xff, 0xff]));
    }

    #[test]
    fn json_values_take_their_declared_type() {
        let j = serde_json::json!({"blow": 3, "plastic_J": 6020.5, "class": "hard", "judgement": {"ok": true}});
        assert_eq!(value_of(j.get("blow"), DataType::UInt32), Some(metric::Value::IntValue(3)));
        assert_eq!(value_of(j.get("plastic_J"), DataType::Double), Some(metric::Value::DoubleValue(6020.5)));
        assert_eq!(value_of(j.get("class"), DataType::String), Some(metric::Value::StringValue("hard".into())));
        assert_eq!(
            value_of(j.get("judgement"), DataType::String),
            Some(metric::Value::StringValue("{\"ok\":true}".into()))
        );
        assert_eq!(value_of(j.get("missing"), DataType::Double), None);
    }

    #[test]
    fn a_blow_carries_what_it_was_forged_as_and_null_for_what_was_not_given() {
        let trace = Trace { part_id: None, lot: Some("4711".into()), die_set: Some("17".into()) };
        let p = blow_data(&crate::estimate::result::examples::soft(3), &trace, 9);
        let m = |name: &str| p.metrics.iter().find(|m| m.name.as_deref() == Some(name)).expect(name);
        assert_eq!(m("blow/lot").value, Some(metric::Value::StringValue("4711".into())));
        assert_eq!(m("blow/die_set").value, Some(metric::Value::StringValue("17".into())));
        assert_eq!((m("blow/part_id").value.as_ref(), m("blow/part_id").is_null), (None, Some(true)));
    }

    #[test]
    fn stamping_marks_every_metric_historical() {
        let mut p = dbirth(0, 1);
        p.seq = None;
        let s = stamp_data(p, 42, true);
        assert_eq!(s.seq, Some(42));
        assert!(s.metrics.iter().all(|m| m.is_historical == Some(true)));
    }
}
