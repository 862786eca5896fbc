//! Acquisition: the transports that turn a DAQ's bytes into `SampleBatch`es (DESIGN.md §4).
//! Each transport is a sans-IO decoder (fed bytes or frames, returns samples or "need
//! more", resyncs after garbage, counts what it drops) plus a thin tokio driver that
//! reconnects with backoff, reports its status and never blocks the pipeline.
//!
//! The drivers all speak the same language to the service: `SourceEvent`s on a bounded
//! channel. A full channel drops the event and counts it; acquisition never waits.

pub mod can;
pub mod modbus;
pub mod outage;
pub mod serial;

pub use crate::signal::sample::Counters;
use crate::signal::sample::{Gap, Status};
use crate::signal::sample::{Role, SampleBatch};

/// What a transport hands the service.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceEvent {
    /// Samples, in physical units, with the device's sequence and time.
    Batch(SampleBatch),
    /// Samples known lost (a sequence jump, a dropped frame, a link down).
    Gap(Gap),
    /// The source's state and counters changed (connected, reconnecting, ...).
    Status(Status),
}

/// How one channel's raw value becomes a physical one: `offset + gain * raw`
/// (docs/interfaces.md §7), and which role it plays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelSpec {
    pub role: Role,
    pub gain: f64,
    pub offset: f64,
}

impl ChannelSpec {
    pub fn physical(&self, raw: f64) -> f64 {
        self.offset + self.gain * raw
    }
}

/// What a source does when the service cannot keep up (issue 15, DESIGN.md §4–§5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Backpressure {
    /// A live device cannot wait: the source never blocks, and the service's queue drops
    /// its oldest events when full, counting them (`daemon::LIVE_QUEUE_EVENTS`).
    #[default]
    DropOldest,
    /// The source can wait (a simulated device run `--fast`, a file): it reads its input
    /// only while the channel has room for what one read can produce, so nothing is lost.
    Wait,
}

/// Free channel slots a waiting source wants before it reads more: one read of
/// `READ_BUF_BYTES` completes at most a few frames, so this is ample.
pub const WAIT_HEADROOM_EVENTS: usize = 64;

/// Under `Backpressure::Wait`, return once the channel has room for a read's events (or
/// the receiver is gone); under `DropOldest`, at once.
pub async fn room(tx: &tokio::sync::mpsc::Sender<SourceEvent>, policy: Backpressure) {
    if policy == Backpressure::Wait {
        // The permits are released at once: only the room is wanted, the events are sent
        // by `offer` as they are decoded.
        let _ = tx.reserve_many(WAIT_HEADROOM_EVENTS.min(tx.max_capacity())).await;
    }
}

/// Send without waiting: a full channel drops the event and counts it (DESIGN.md §4:
/// backpressure never stalls acquisition). Returns false once the receiver is gone.
pub fn offer(tx: &tokio::sync::mpsc::Sender<SourceEvent>, event: SourceEvent, counters: &mut Counters) -> bool {
    match tx.try_send(event) {
        Ok(()) => true,
        Err(tokio::sync::mpsc::error::TrySendError::Full(_)) => {
            counters.drops += 1;
            true
        }
        Err(tokio::sync::mpsc::error::TrySendError::Closed(_)) => false,
    }
}

/// Reconnect backoff: doubles from `BACKOFF_START_MS` up to `BACKOFF_MAX_MS`, so a
/// returning link is picked up within 2 s (issue #4).
pub const BACKOFF_START_MS: u64 = 50;
pub const BACKOFF_MAX_MS: u64 = 1000;

/// The next backoff after `current_ms`.
pub fn next_backoff_ms(current_ms: u64) -> u64 {
    (current_ms * 2).clamp(BACKOFF_START_MS, BACKOFF_MAX_MS)
}
