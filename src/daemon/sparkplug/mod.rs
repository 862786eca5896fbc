//! The Sparkplug B uplink (docs/interfaces.md §10): the service as a Sparkplug B 3.0 edge node
//! publishing each blow to a standard MQTT broker, with store-and-forward.
//!
//! Two tasks share one [`Shared`] state. The *feeder* takes each blow from the live feed
//! (`live.rs`), encodes its DDATA (`payload.rs`) and appends it to the on-disk queue
//! (`store.rs`) before anything else; the *session* (`session.rs`) connects with the NDEATH
//! as its will, publishes NBIRTH and DBIRTH, then sends the queue in order and removes each
//! blow only when the broker acknowledges it. While the broker is unreachable the queue
//! grows within its limits; on reconnecting, the node is born again (next `bdSeq`) and the
//! queued blows follow with their own timestamps, flagged historical. A restart of the
//! service finds the queue on disk and goes on from there.
//!
//! The client is rumqttc: maintained, pure Rust on tokio (no C library), MQTT 3.1.1 as
//! Sparkplug B 3.0 requires, with the will, QoS 1 acknowledgements and a request channel
//! that never blocks the caller (`try_publish`).

pub mod payload;
mod session;
pub mod store;

/// The Sparkplug B payload types, generated from `proto/sparkplug_b.proto` by `build.rs`.
#[allow(clippy::all, missing_docs)]
pub mod proto {
    include!(concat!(env!("OUT_DIR"), "/org.eclipse.tahu.protobuf.rs"));
}

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context;
use prost::Message;
use tokio::sync::Notify;
use tokio::sync::broadcast;
use tokio::sync::broadcast::error::{RecvError, TryRecvError};
use tokio::task::JoinHandle;

use super::live::{Live, LiveEvent};
use crate::config::uplink::MqttUplink;
use payload::{NodeCounters, NodeIds};

use crate::estimate::billet_book::Trace;
use store::{Store, StoreLimits};

/// The queue's directory under the recording directory.
pub const QUEUE_DIR: &str = "sparkplug-queue";

/// What the two tasks share: the queue, the live session (if connected) and the counters.
struct Shared {
    store: Store,
    session: Option<session::Live>,
    /// Blows the live feed dropped before the feeder took them.
    lagged: u64,
    /// DDATA the broker acknowledged.
    published: u64,
    /// Blows that could not be written to the queue (disk full, IO error): lost.
    store_errors: u64,
}

impl Shared {
    fn counters(&self) -> NodeCounters {
        let c = self.store.counters;
        NodeCounters { queue_dropped: c.dropped_full + c.dropped_old, lagged: self.lagged }
    }
}

type SharedState = Arc<Mutex<Shared>>;

/// How long [`Uplink::finish`] waits for the broker to take what is queued.
pub const FLUSH_TIMEOUT: Duration = Duration::from_secs(3);

/// The running uplink; stops when dropped (the broker then sends the NDEATH will).
pub struct Uplink {
    feeder: Option<JoinHandle<()>>,
    session: JoinHandle<()>,
    stop: Arc<Notify>,
    shared: SharedState,
}

impl Uplink {
    /// Stop at the end of the service: queue every blow the live feed still holds, then
    /// give a connected broker up to [`FLUSH_TIMEOUT`] to acknowledge the queue. What it has
    /// not taken stays on disk for the next start.
    pub async fn finish(mut self) {
        self.stop.notify_one();
        if let Some(feeder) = self.feeder.take() {
            let _ = feeder.await;
        }
        let deadline = tokio::time::Instant::now() + FLUSH_TIMEOUT;
        while tokio::time::Instant::now() < deadline {
            let busy = self.shared.lock().map(|s| s.session.is_some() && !s.store.is_empty()).unwrap_or(false);
            if !busy {
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
}

impl Drop for Uplink {
    fn drop(&mut self) {
        if let Some(feeder) = &self.feeder {
            feeder.abort();
        }
        self.session.abort();
        if let Ok(s) = self.shared.lock() {
            let c = s.store.counters;
            tracing::info!(
                published = s.published,
                waiting = s.store.len(),
                high_water = c.high_water,
                dropped_full = c.dropped_full,
                dropped_old = c.dropped_old,
                lagged = s.lagged,
                store_errors = s.store_errors,
                "sparkplug uplink stopped"
            );
        }
    }
}

/// The uplink finishes by flushing its queue (`Uplink::finish`).
impl crate::daemon::faces::Face for Uplink {
    fn finish(self: Box<Self>) -> futures_util::future::BoxFuture<'static, ()> {
        Box::pin(Uplink::finish(*self))
    }
}

/// The uplink as a face (`faces::FACES`): `[uplink.mqtt]`.
pub fn face<'a>(
    ctx: &'a crate::daemon::faces::FaceContext<'a>,
) -> futures_util::future::BoxFuture<'a, anyhow::Result<Option<Box<dyn crate::daemon::faces::Face>>>> {
    let uplink = start(ctx.config.uplink_mqtt.as_ref(), &ctx.config.recording_dir, ctx.bus);
    Box::pin(async move { Ok(crate::daemon::faces::boxed(uplink?)) })
}

/// Start the uplink when `[uplink.mqtt]` is configured: open (or resume) the queue under
/// `recording_dir`, subscribe to the live feed, and connect.
pub fn start(cfg: Option<&MqttUplink>, recording_dir: &Path, live: &Live) -> anyhow::Result<Option<Uplink>> {
    let Some(cfg) = cfg else { return Ok(None) };
    let dir = recording_dir.join(QUEUE_DIR);
    let limits = StoreLimits { max_bytes: cfg.queue_max_bytes, max_age_ms: cfg.queue_max_age_s * 1000 };
    let store = Store::open(&dir, limits, now_ms()).with_context(|| "the Sparkplug store-and-forward queue")?;
    if !store.is_empty() {
        tracing::info!(blows = store.len(), dir = %dir.display(), "sparkplug: resuming the queue a previous run left");
    }
    let shared = Arc::new(Mutex::new(Shared { store, session: None, lagged: 0, published: 0, store_errors: 0 }));
    let ids = NodeIds {
        group_id: cfg.group_id.clone(),
        edge_node_id: cfg.edge_node_id.clone(),
        device_id: cfg.device_id.clone(),
    };
    let stop = Arc::new(Notify::new());
    let feeder = tokio::spawn(feed(live.subscribe(), shared.clone(), stop.clone()));
    let session = tokio::spawn(session::run(cfg.clone(), ids, dir, shared.clone()));
    tracing::info!(url = %cfg.url, node = %format!("{}/{}", cfg.group_id, cfg.edge_node_id), "sparkplug uplink started");
    Ok(Some(Uplink { feeder: Some(feeder), session, stop, shared }))
}

/// Wall-clock ms since the epoch (the daemon is where the clock is read).
fn now_ms() -> u64 {
    u64::try_from(super::host_now_ns() / 1_000_000).unwrap_or(0)
}

/// The feeder: each blow's DDATA onto the queue, then sent if a session is up. On `stop`,
/// it takes what the feed still holds and ends.
async fn feed(mut rx: broadcast::Receiver<LiveEvent>, shared: SharedState, stop: Arc<Notify>) {
    // What the blows are forged as: the status snapshot's, published just before each blow.
    let mut part = Trace::default();
    loop {
        let event = tokio::select! {
            ev = rx.recv() => ev,
            _ = stop.notified() => {
                loop {
                    match rx.try_recv() {
                        Ok(ev) => queue_event(&shared, ev, &mut part),
                        Err(TryRecvError::Lagged(n)) => count_lagged(&shared, n),
                        Err(_) => return,
                    }
                }
            }
        };
        match event {
            Ok(ev) => queue_event(&shared, ev, &mut part),
            Err(RecvError::Lagged(n)) => count_lagged(&shared, n),
            Err(RecvError::Closed) => return,
        }
    }
}

/// The live feed dropped `n` events before the feeder took them.
fn count_lagged(shared: &SharedState, n: u64) {
    tracing::warn!(events = n, "sparkplug: the live feed ran ahead; its oldest events are lost to the uplink");
    if let Ok(mut s) = shared.lock() {
        s.lagged += n;
    }
}

/// A blow's DDATA onto the queue, forged as `part`, which a status snapshot updates (other
/// events are not published).
fn queue_event(shared: &SharedState, ev: LiveEvent, part: &mut Trace) {
    let e = match ev {
        LiveEvent::Blow(e) => e,
        LiveEvent::Status(s) => {
            *part = s.part.clone();
            return;
        }
        _ => return,
    };
    let t_ms = now_ms();
    let bytes = payload::blow_data(&e, part, t_ms).encode_to_vec();
    let Ok(mut s) = shared.lock() else { return };
    if let Err(err) = s.store.push(&bytes, t_ms) {
        s.store_errors += 1;
        tracing::error!(blow = e.blow, "sparkplug: blow not queued, lost to the uplink: {err}");
    }
    session::pump(&mut s);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::BlowEstimate;

    fn estimate(blow: u32) -> BlowEstimate {
        crate::estimate::result::examples::soft(blow)
    }

    /// The metric names are the replay's JSON keys (docs/interfaces.md §5): a renamed field fails here.
    #[test]
    fn every_blow_metric_is_a_key_of_the_replay_json() {
        let json = serde_json::to_value(estimate(1)).expect("serialises");
        for (field, _) in payload::BLOW_FIELDS {
            assert!(json.get(*field).is_some(), "blow/{field} is not a key of the blow's JSON");
        }
    }

    /// A feeder that fell more than the channel's capacity behind counts what it missed and
    /// queues the rest, also when told to stop with the lag still unread.
    #[tokio::test]
    async fn a_lagging_feeder_counts_what_it_missed_and_queues_the_rest() {
        let dir = tempfile::tempdir().expect("tmp");
        let limits = StoreLimits { max_bytes: 1 << 20, max_age_ms: 3_600_000 };
        let store = Store::open(dir.path(), limits, now_ms()).expect("open");
        let shared = Arc::new(Mutex::new(Shared { store, session: None, lagged: 0, published: 0, store_errors: 0 }));
        let (tx, rx) = broadcast::channel(2);
        for b in 1..=5 {
            tx.send(LiveEvent::Blow(Arc::new(estimate(b)))).expect("a receiver");
        }
        let stop = Arc::new(Notify::new());
        stop.notify_one();
        feed(rx, shared.clone(), stop).await;
        let mut s = shared.lock().expect("lock");
        assert_eq!(s.lagged, 3, "5 blows into a channel of 2");
        assert_eq!(s.store.len(), 2);
        let first = s.store.take_next().expect("read").expect("a record");
        let p = proto::Payload::decode(first.payload.as_slice()).expect("decodes");
        let blow = p.metrics.iter().find(|m| m.name.as_deref() == Some("blow/blow")).and_then(|m| m.value.clone());
        assert_eq!(blow, Some(proto::payload::metric::Value::IntValue(4)), "the oldest kept is blow 4");
    }
}
