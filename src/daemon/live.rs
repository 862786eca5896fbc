//! The service's bus to its faces (the dashboard, the PLC image, OPC UA, Sparkplug, the
//! advisor, the webhook, the PLC coil; `faces.rs`): each blow's result, each alert, each
//! billet's summary, each change of the latched alert, the status snapshot (after each blow,
//! and every second) and the stop, as the session produced them, on a broadcast channel. A
//! front end that falls behind loses the oldest events (tokio's `broadcast` says how many)
//! and catches up from the next snapshot; it never holds up the service.

use std::sync::Arc;

use tokio::sync::broadcast;

use crate::alert::Alert;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;

/// Events a slow front end may fall behind by before it loses the oldest.
pub const LIVE_CHANNEL_EVENTS: usize = 256;

/// One thing a front end shows.
#[derive(Debug, Clone)]
pub enum LiveEvent {
    /// A blow's result (docs/interfaces.md §5), with its alert if it raised one.
    Blow(Arc<BlowEstimate>),
    /// A billet's summary (finished, or the run's last).
    Billet(Arc<BilletSummary>),
    /// A new billet is in the dies.
    NewBillet,
    /// The advisor replanned the billet's next blows (`advisor.rs`).
    Advice(Arc<crate::advise::Advice>),
    /// The latched alert was acknowledged (`POST /ack`, the PLC's coil 0).
    Acknowledged,
    /// A blow raised `alert` (published before the blow itself); `arrived_ns` is when the
    /// samples that ended the blow arrived (host clock).
    Alert { alert: Arc<Alert>, arrived_ns: i64 },
    /// The service's status (`/status`): published just before each blow's result, so a
    /// face that shows both sees the counters that include the blow, and every second.
    Status(Arc<super::status::StatusSnapshot>),
    /// The service has stopped: the last event. A face that sends what it received
    /// (`faces::Face::finish`) finishes it and ends.
    Stopping,
}

/// The sending side, cloned into whatever publishes; `subscribe` for a front end.
#[derive(Debug, Clone)]
pub struct Live {
    tx: broadcast::Sender<LiveEvent>,
}

impl Default for Live {
    fn default() -> Self {
        Live { tx: broadcast::channel(LIVE_CHANNEL_EVENTS).0 }
    }
}

impl Live {
    /// Publish `e` to every front end listening now (none listening is fine).
    pub fn publish(&self, e: LiveEvent) {
        let _ = self.tx.send(e);
    }

    pub fn subscribe(&self) -> broadcast::Receiver<LiveEvent> {
        self.tx.subscribe()
    }
}
