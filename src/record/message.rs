//! What a recording holds, as typed values: the pipeline's own types (sample batches, blow
//! estimates, alerts, billet summaries) plus the few that exist only to be recorded (blow boundaries; the gaps and
//! transport status of `signal::sample`, re-exported here; configuration files), and [`Recorded`], one message with its log time.

use crate::alert::Alert;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::signal::sample::SampleBatch;
pub use crate::signal::sample::{Gap, Status};

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
