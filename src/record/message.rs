//! What a recording holds, as typed values: the pipeline's own types (sample batches, blow
//! estimates, alerts, billet summaries) plus the few that exist only to be recorded (blow boundaries, gaps,
//! transport status, configuration files), and [`Recorded`], one message with its log time.

use crate::alert::Alert;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::signal::sample::SampleBatch;

use super::schema::MessageKind;

/// Where the segmenter cut a blow (topic `/blows`). Times are device times, s.
#[derive(Debug, Clone, PartialEq)]
pub struct BlowBoundary {
    pub blow: u32,
    /// The acceleration trigger fired.
    pub t_trigger_s: f64,
    /// First contact.
    pub t_contact_s: f64,
    /// End of the blow.
    pub t_end_s: f64,
    /// The source whose samples hold the blow.
    pub source: String,
}

impl BlowBoundary {
    /// Blow `blow` as the pipeline cut it (the source left unnamed).
    pub fn of(blow: u32, cut: &crate::pipeline::Cut) -> Self {
        BlowBoundary {
            blow,
            t_trigger_s: cut.t_trigger_s,
            t_contact_s: cut.t_contact_s,
            t_end_s: cut.t_end_s,
            source: String::new(),
        }
    }
}

/// Samples lost or dropped (topic `/gaps`).
#[derive(Debug, Clone, PartialEq)]
pub struct Gap {
    pub source: String,
    /// Device time of the gap, s.
    pub t_s: f64,
    pub samples_lost: u64,
    /// Why: "sequence_jump", "crc", "overflow", "backpressure", ...
    pub reason: String,
}

/// A source's state and counters since it started (topic `/status`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Status {
    pub source: String,
    /// "connected", "reconnecting", "stopped", ...
    pub state: String,
    pub samples: u64,
    pub frames: u64,
    pub drops: u64,
    pub gaps: u64,
    pub crc_errors: u64,
    pub decode_errors: u64,
    pub reconnects: u64,
    /// Free text: last error, port name, ...
    pub detail: String,
}

/// A configuration file stored in the recording (topic `/config`): `machine.toml`,
/// `process.toml`, the service config.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigFile {
    pub name: String,
    pub text: String,
}

/// The content of one recorded message.
#[derive(Debug, Clone, PartialEq)]
pub enum Payload {
    Samples(SampleBatch),
    Boundary(BlowBoundary),
    Result(Box<BlowEstimate>),
    Alert(Alert),
    Gap(Gap),
    Status(Status),
    Config(ConfigFile),
    /// A billet's summary (topic `/billets`).
    Billet(Box<BilletSummary>),
}

impl Payload {
    pub fn kind(&self) -> MessageKind {
        match self {
            Payload::Samples(_) => MessageKind::Samples,
            Payload::Boundary(_) => MessageKind::Boundary,
            Payload::Result(_) => MessageKind::Result,
            Payload::Alert(_) => MessageKind::Alert,
            Payload::Gap(_) => MessageKind::Gap,
            Payload::Status(_) => MessageKind::Status,
            Payload::Config(_) => MessageKind::Config,
            Payload::Billet(_) => MessageKind::Billet,
        }
    }
}

/// One message read from a recording, with its MCAP log time (host time, ns).
#[derive(Debug, Clone, PartialEq)]
pub struct Recorded {
    pub log_time_ns: i64,
    pub payload: Payload,
}
