//! The live writer: the recorder's messages (`record::tap`) into the history database on a
//! thread of its own, so that a slow disk never holds up the pipeline. The tap only copies
//! the messages that make rows into a bounded queue; a full queue drops the message and
//! counts it (`HistoryCounters::dropped`), and `forgemon history rebuild` into the same
//! database later fills exactly those rows from the recording.
//!
//! The thread writes whatever the queue holds in one transaction, so a burst costs one
//! commit. Retention runs once per hour of log time and at the end.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::{History, HistoryError};
use crate::record::codec::decode_payload;
use crate::record::{MessageKind, Payload, Tap};

/// Messages the queue holds before it drops: about an hour of blows at one a second, and
/// 4 MB at most of results.
pub const QUEUE_MESSAGES: usize = 4096;
/// Messages written in one transaction at most.
const BATCH: usize = 512;
/// Retention runs at most this often, in log time.
const PRUNE_EVERY_NS: i64 = 3_600_000_000_000;

/// What the writer has done, shared with `/status`.
#[derive(Debug, Default)]
pub struct HistoryCounters {
    pub blows: AtomicU64,
    pub billets: AtomicU64,
    /// Messages the full queue dropped, or whose write failed.
    pub dropped: AtomicU64,
    /// Messages waiting in the queue.
    pub queued: AtomicU64,
    pub pruned: AtomicU64,
    /// The last write error, if any.
    pub last_error: Mutex<Option<String>>,
}

/// The counters as `/status` shows them.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct HistoryStatus {
    pub path: String,
    pub blows: u64,
    pub billets: u64,
    pub dropped: u64,
    pub queued: u64,
    pub pruned: u64,
    pub last_error: Option<String>,
}

impl HistoryCounters {
    pub fn status(&self, path: &std::path::Path) -> HistoryStatus {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        HistoryStatus {
            path: path.display().to_string(),
            blows: get(&self.blows),
            billets: get(&self.billets),
            dropped: get(&self.dropped),
            queued: get(&self.queued),
            pruned: get(&self.pruned),
            last_error: self.last_error.lock().ok().and_then(|e| e.clone()),
        }
    }
}

enum Msg {
    Recorded { kind: MessageKind, data: Vec<u8>, log_time_ns: i64 },
    Finish,
}

/// The running writer.
pub struct LiveHistory {
    tx: SyncSender<Msg>,
    counters: Arc<HistoryCounters>,
    path: PathBuf,
    thread: Option<JoinHandle<()>>,
}

impl LiveHistory {
    /// Open the database at `path` (its schema brought up to date) and start the thread.
    pub fn start(path: PathBuf, keep_days: Option<f64>) -> Result<Self, HistoryError> {
        Self::start_with_queue(path, keep_days, QUEUE_MESSAGES)
    }

    fn start_with_queue(path: PathBuf, keep_days: Option<f64>, queue: usize) -> Result<Self, HistoryError> {
        let history = History::open(&path, keep_days)?;
        let (tx, rx) = mpsc::sync_channel(queue);
        let counters = Arc::new(HistoryCounters::default());
        let c = counters.clone();
        let thread = std::thread::Builder::new()
            .name("history".into())
            .spawn(move || write_loop(history, rx, &c))
            .map_err(HistoryError::Thread)?;
        Ok(LiveHistory { tx, counters, path, thread: Some(thread) })
    }

    pub fn counters(&self) -> Arc<HistoryCounters> {
        self.counters.clone()
    }

    pub fn path(&self) -> &std::path::Path {
        &self.path
    }

    /// The recorder's tap: copies each message that makes a row into the queue, or drops
    /// and counts it when the queue is full. It never blocks.
    pub fn tap(&self) -> Tap {
        let tx = self.tx.clone();
        let counters = self.counters.clone();
        Box::new(move |m| {
            // Configs: the part's trace (`session::PART_CONFIG_NAME`) is one.
            if !matches!(m.kind, MessageKind::Result | MessageKind::Billet | MessageKind::Config) {
                return;
            }
            let msg = Msg::Recorded { kind: m.kind, data: m.data.to_vec(), log_time_ns: m.log_time_ns as i64 };
            offer(&tx, &counters, msg);
        })
    }

    /// Write what the queue holds, prune, and stop the thread.
    pub fn finish(mut self) {
        let _ = self.tx.send(Msg::Finish);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn offer(tx: &SyncSender<Msg>, counters: &HistoryCounters, msg: Msg) {
    match tx.try_send(msg) {
        Ok(()) => {
            counters.queued.fetch_add(1, Ordering::Relaxed);
        }
        Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
            counters.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The thread: each wake-up writes what is queued (up to `BATCH`) in one transaction.
fn write_loop(mut history: History, rx: Receiver<Msg>, counters: &HistoryCounters) {
    let mut last_prune = i64::MIN;
    let mut finishing = false;
    while !finishing {
        let Ok(first) = rx.recv() else { break };
        let mut batch = Vec::new();
        let mut next = Some(first);
        while let Some(msg) = next.take() {
            counters.queued.fetch_sub(1, Ordering::Relaxed);
            match msg {
                Msg::Recorded { kind, data, log_time_ns } => match decode_payload(kind, &data) {
                    Ok(p) => batch.push((log_time_ns, p)),
                    Err(e) => failed(counters, 1, &format!("a {kind:?} message: {e}")),
                },
                Msg::Finish => finishing = true,
            }
            if batch.len() < BATCH && !finishing {
                next = rx.try_recv().ok();
            }
        }
        let newest = batch.iter().map(|(t, _)| *t).max().unwrap_or(i64::MIN);
        write(&mut history, &mut batch, counters);
        if finishing || newest.saturating_sub(last_prune) >= PRUNE_EVERY_NS {
            last_prune = newest;
            match history.prune() {
                Ok(n) => drop(counters.pruned.fetch_add(n, Ordering::Relaxed)),
                Err(e) => failed(counters, 0, &e.to_string()),
            }
        }
    }
}

/// Write and empty `batch`, counting its rows or its loss.
fn write(history: &mut History, batch: &mut Vec<(i64, Payload)>, counters: &HistoryCounters) {
    if batch.is_empty() {
        return;
    }
    match history.ingest(batch) {
        Ok(n) => {
            counters.blows.fetch_add(n.blows, Ordering::Relaxed);
            counters.billets.fetch_add(n.billets, Ordering::Relaxed);
        }
        Err(e) => failed(counters, batch.len() as u64, &e.to_string()),
    }
    batch.clear();
}

fn failed(counters: &HistoryCounters, lost: u64, why: &str) {
    counters.dropped.fetch_add(lost, Ordering::Relaxed);
    tracing::warn!("history: {why}");
    if let Ok(mut e) = counters.last_error.lock() {
        *e = Some(why.to_string());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::TappedMessage;
    use crate::record::codec::encode_payload;
    use crate::record::codec::tests::estimate;

    #[test]
    fn a_blocked_disk_never_blocks_the_tap_and_every_message_is_written_or_counted() {
        let dir = std::env::temp_dir().join(format!("forgemon-history-writer-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a temp dir");
        let path = dir.join("h.sqlite");
        let live = LiveHistory::start_with_queue(path.clone(), None, 8).expect("starts");
        // Another writer holds the database: the history's inserts wait on it.
        let blocker = rusqlite::Connection::open(&path).expect("opens");
        blocker.execute_batch("BEGIN EXCLUSIVE").expect("locked");
        let mut tap = live.tap();
        let sent = 50;
        let t0 = std::time::Instant::now();
        for blow in 1..=sent {
            let mut e = estimate(false);
            e.blow = blow;
            let mut data = Vec::new();
            encode_payload(&Payload::Result(Box::new(e)), &mut data).expect("encodes");
            let topic = "/results";
            let m = TappedMessage {
                topic,
                kind: MessageKind::Result,
                data: &data,
                log_time_ns: u64::from(blow),
                publish_time_ns: 0,
            };
            tap(&m);
        }
        // The pipeline's thread went on: 50 taps against a locked disk, far under the
        // writer's 5 s wait for the lock.
        assert!(t0.elapsed() < std::time::Duration::from_secs(2), "{:?}", t0.elapsed());
        let dropped = live.counters().dropped.load(Ordering::Relaxed);
        assert!(dropped > 0, "a queue of 8 holds 50 messages only by dropping");
        blocker.execute_batch("COMMIT").expect("unlocked");
        let counters = live.counters();
        live.finish();
        let written = counters.blows.load(Ordering::Relaxed);
        let dropped = counters.dropped.load(Ordering::Relaxed);
        assert_eq!(written + dropped, u64::from(sent), "written {written}, dropped {dropped}");
        let rows: i64 = rusqlite::Connection::open(&path)
            .and_then(|c| c.query_row("SELECT count(*) FROM blows", [], |r| r.get(0)))
            .expect("counts");
        assert_eq!(rows as u64, written);
    }
}
