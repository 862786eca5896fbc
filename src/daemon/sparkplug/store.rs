//! The store-and-forward queue: every blow's DDATA is appended here first and leaves only
//! once the broker has acknowledged it, so blows made while the broker is unreachable, or
//! while the service is down between a crash and its restart, are published later, in
//! order, with their own timestamps.
//!
//! One append-only file `queue.bin` of records `[len u32 LE][crc32 u32 LE][payload]` and a
//! `queue.head` file with the byte offset of the first record not yet acknowledged
//! (replaced atomically). Bounded by bytes and age: the oldest records are dropped first
//! and counted. A torn last record (power cut mid-write) or a bad CRC ends the readable
//! queue there; what follows is cut off and counted. The file is emptied when every record
//! in it is acknowledged, and rewritten without its dead front once that front is larger
//! than the byte limit (a long outage with the queue full). Time is passed in (ms since the epoch); no clock here.

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// The record checksum: CRC-32 (ISO-HDLC, as zip and Ethernet).
const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
/// Header bytes before each payload.
const HEADER: u64 = 8;
/// The largest record accepted back from disk (a blow's DDATA is about 1 kB).
const MAX_RECORD: u32 = 1 << 20;

/// The queue's limits (`[uplink.mqtt] queue_max_bytes`, `queue_max_age_s`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoreLimits {
    pub max_bytes: u64,
    pub max_age_ms: u64,
}

/// What the queue has counted since it was opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StoreCounters {
    /// Records dropped because the queue was full.
    pub dropped_full: u64,
    /// Records dropped because they were older than the age limit.
    pub dropped_old: u64,
    /// Bytes cut off a damaged file on opening.
    pub damaged_bytes: u64,
    /// The most records waiting at once.
    pub high_water: usize,
}

/// One record waiting: where it is and when it was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Entry {
    offset: u64,
    len: u32,
    t_ms: u64,
}

/// A record handed out to publish.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    pub t_ms: u64,
    pub payload: Vec<u8>,
}

/// The queue on disk, with an index of the records waiting in memory.
pub struct Store {
    dir: PathBuf,
    file: File,
    end: u64,
    waiting: VecDeque<Entry>,
    /// How many of `waiting` (from the front) are handed out and not yet acknowledged.
    in_flight: usize,
    limits: StoreLimits,
    pub counters: StoreCounters,
}

/// Why the queue could not be used.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("a record of {len} bytes is over the queue's {MAX_RECORD}-byte limit")]
    TooLarge { len: usize },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    move |source| StoreError::Io { path: path.to_path_buf(), source }
}

impl Store {
    /// Open (or create) the queue in `dir`, reading back what a previous run left waiting;
    /// `t_ms` is now, for the age limit.
    pub fn open(dir: &Path, limits: StoreLimits, t_ms: u64) -> Result<Store, StoreError> {
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let path = dir.join("queue.bin");
        let mut file =
            OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&path).map_err(io(&path))?;
        let head = read_head(&dir.join("queue.head"));
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io(&path))?;
        let (waiting, end) = scan(&bytes, head.min(bytes.len() as u64));
        let mut counters = StoreCounters::default();
        if end < bytes.len() as u64 {
            counters.damaged_bytes = bytes.len() as u64 - end;
            file.set_len(end).map_err(io(&path))?;
        }
        let mut store = Store { dir: dir.to_path_buf(), file, end, waiting, in_flight: 0, limits, counters };
        store.enforce_limits(t_ms)?;
        store.counters.high_water = store.waiting.len();
        Ok(store)
    }

    /// Records waiting (handed out or not).
    pub fn len(&self) -> usize {
        self.waiting.len()
    }

    pub fn is_empty(&self) -> bool {
        self.waiting.is_empty()
    }

    /// Bytes the waiting records take on disk.
    pub fn bytes(&self) -> u64 {
        self.waiting.iter().map(|e| HEADER + u64::from(e.len)).sum()
    }

    /// Append `payload`, made at `t_ms`, and make room by dropping the oldest if the queue is
    /// over its limits. The record is on disk (synced) when this returns.
    pub fn push(&mut self, payload: &[u8], t_ms: u64) -> Result<(), StoreError> {
        let path = self.dir.join("queue.bin");
        let len = u32::try_from(payload.len())
            .ok()
            .filter(|l| *l <= MAX_RECORD)
            .ok_or(StoreError::TooLarge { len: payload.len() })?;
        let mut rec = Vec::with_capacity(payload.len() + HEADER as usize);
        rec.extend_from_slice(&len.to_le_bytes());
        rec.extend_from_slice(&CRC.checksum(payload).to_le_bytes());
        rec.extend_from_slice(payload);
        self.file.seek(SeekFrom::Start(self.end)).map_err(io(&path))?;
        self.file.write_all(&rec).map_err(io(&path))?;
        self.file.sync_data().map_err(io(&path))?;
        self.waiting.push_back(Entry { offset: self.end, len, t_ms });
        self.end += rec.len() as u64;
        self.enforce_limits(t_ms)?;
        self.counters.high_water = self.counters.high_water.max(self.waiting.len());
        Ok(())
    }

    /// The next record not yet handed out, marked in flight.
    pub fn take_next(&mut self) -> Result<Option<Record>, StoreError> {
        let Some(e) = self.waiting.get(self.in_flight).copied() else { return Ok(None) };
        let path = self.dir.join("queue.bin");
        let mut payload = vec![0; e.len as usize];
        self.file.seek(SeekFrom::Start(e.offset + HEADER)).map_err(io(&path))?;
        self.file.read_exact(&mut payload).map_err(io(&path))?;
        self.in_flight += 1;
        Ok(Some(Record { t_ms: e.t_ms, payload }))
    }

    /// Records handed out and not yet acknowledged.
    pub fn in_flight(&self) -> usize {
        self.in_flight
    }

    /// Everything handed out goes back to waiting (the connection dropped before the acks).
    pub fn rewind(&mut self) {
        self.in_flight = 0;
    }

    /// Drop the record `take_next` handed out last (it could not be sent and never will be).
    pub fn discard_last(&mut self) {
        if self.in_flight > 0 {
            self.in_flight -= 1;
            self.waiting.remove(self.in_flight);
        }
    }

    /// The broker has the oldest record in flight: remove it. Acks come in publish order
    /// (MQTT 3.1.1 §4.6); an ack that matches nothing (dropped meanwhile) is ignored.
    pub fn ack_oldest(&mut self) -> Result<(), StoreError> {
        if self.in_flight == 0 {
            return Ok(());
        }
        self.waiting.pop_front();
        self.in_flight -= 1;
        self.save_head()
    }

    /// Drop the oldest records over the byte or age limit (never one in flight: the
    /// broker may have it already).
    fn enforce_limits(&mut self, t_ms: u64) -> Result<(), StoreError> {
        let mut changed = false;
        let mut bytes = self.bytes();
        while self.waiting.len() > self.in_flight {
            let Some(e) = self.waiting.get(self.in_flight).copied() else { break };
            let full = bytes > self.limits.max_bytes;
            let old = t_ms.saturating_sub(e.t_ms) > self.limits.max_age_ms;
            if !(full || old) {
                break;
            }
            if full {
                self.counters.dropped_full += 1;
            } else {
                self.counters.dropped_old += 1;
            }
            bytes -= HEADER + u64::from(e.len);
            self.waiting.remove(self.in_flight);
            changed = true;
        }
        if changed { self.save_head() } else { Ok(()) }
    }

    /// Write the head (the first waiting record's offset), compacting when nothing waits
    /// or the dead front has grown past the byte limit.
    fn save_head(&mut self) -> Result<(), StoreError> {
        let path = self.dir.join("queue.bin");
        let head = match self.waiting.front() {
            Some(e) if e.offset > self.limits.max_bytes => return self.compact(e.offset),
            Some(e) => e.offset,
            None => {
                self.file.set_len(0).map_err(io(&path))?;
                self.end = 0;
                0
            }
        };
        // A record dropped while an older one is in flight keeps its bytes until the next
        // compaction; the index no longer points at it.
        write_head(&self.dir, head)
    }

    /// Rewrite the file from `head` on. The head is reset before the rename: a crash between
    /// the two replays records already sent (duplicates), never loses one.
    fn compact(&mut self, head: u64) -> Result<(), StoreError> {
        let path = self.dir.join("queue.bin");
        let tmp = self.dir.join("queue.bin.tmp");
        let mut live = Vec::new();
        self.file.seek(SeekFrom::Start(head)).map_err(io(&path))?;
        self.file.read_to_end(&mut live).map_err(io(&path))?;
        let mut new = File::create(&tmp).map_err(io(&tmp))?;
        new.write_all(&live).map_err(io(&tmp))?;
        new.sync_data().map_err(io(&tmp))?;
        write_head(&self.dir, 0)?;
        std::fs::rename(&tmp, &path).map_err(io(&path))?;
        self.file = OpenOptions::new().read(true).write(true).open(&path).map_err(io(&path))?;
        self.end -= head;
        for e in &mut self.waiting {
            e.offset -= head;
        }
        Ok(())
    }
}

/// Save `head` atomically (a temporary file renamed over the old).
fn write_head(dir: &Path, head: u64) -> Result<(), StoreError> {
    let tmp = dir.join("queue.head.tmp");
    let path = dir.join("queue.head");
    std::fs::write(&tmp, head.to_le_bytes()).map_err(io(&tmp))?;
    std::fs::rename(&tmp, &path).map_err(io(&path))
}

/// The head offset a previous run saved (0 when there is none or it is damaged).
fn read_head(path: &Path) -> u64 {
    std::fs::read(path).ok().and_then(|b| <[u8; 8]>::try_from(b.as_slice()).ok()).map_or(0, u64::from_le_bytes)
}

/// The records in `bytes` from `head` on, and where the readable part ends.
fn scan(bytes: &[u8], head: u64) -> (VecDeque<Entry>, u64) {
    let mut waiting = VecDeque::new();
    let mut at = head as usize;
    while let Some(h) = bytes.get(at..at + HEADER as usize) {
        let len = u32::from_le_bytes([h[0], h[1], h[2], h[3]]);
        let crc = u32::from_le_bytes([h[4], h[5], h[6], h[7]]);
        let Some(payload) = bytes.get(at + HEADER as usize..at + HEADER as usize + len as usize) else { break };
        if len > MAX_RECORD || CRC.checksum(payload) != crc {
            break;
        }
        waiting.push_back(Entry { offset: at as u64, len, t_ms: made_ms(payload) });
        at += HEADER as usize + len as usize;
    }
    (waiting, at as u64)
}

/// When a queued DDATA was made: its payload's timestamp (0 if unreadable, so the age limit
/// drops it first).
fn made_ms(payload: &[u8]) -> u64 {
    use prost::Message;
    super::proto::Payload::decode(payload).ok().and_then(|p| p.timestamp).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::sparkplug::proto::Payload;
    use prost::Message;

    const LIMITS: StoreLimits = StoreLimits { max_bytes: 1 << 20, max_age_ms: 3_600_000 };

    fn rec(t_ms: u64) -> Vec<u8> {
        Payload { timestamp: Some(t_ms), seq: Some(t_ms % 7), ..Default::default() }.encode_to_vec()
    }

    fn drain(s: &mut Store) -> Vec<u64> {
        let mut ts = Vec::new();
        while let Some(r) = s.take_next().expect("read") {
            ts.push(r.t_ms);
            s.ack_oldest().expect("ack");
        }
        ts
    }

    #[test]
    fn records_come_back_in_order_after_a_restart() {
        let dir = tempfile::tempdir().expect("tmp");
        {
            let mut s = Store::open(dir.path(), LIMITS, 0).expect("open");
            for t in 1..=5 {
                s.push(&rec(t), t).expect("push");
            }
            let first = s.take_next().expect("read").expect("a record");
            assert_eq!(first.t_ms, 1);
            s.ack_oldest().expect("ack");
            // Record 2 is in flight but not acknowledged when the service stops.
            assert!(s.take_next().expect("read").is_some());
        }
        let mut s = Store::open(dir.path(), LIMITS, 10).expect("reopen");
        assert_eq!(drain(&mut s), vec![2, 3, 4, 5]);
        assert!(s.is_empty());
    }

    #[test]
    fn rewind_hands_out_the_unacknowledged_again() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut s = Store::open(dir.path(), LIMITS, 0).expect("open");
        for t in 1..=3 {
            s.push(&rec(t), t).expect("push");
        }
        s.take_next().expect("read");
        s.take_next().expect("read");
        s.rewind();
        assert_eq!(drain(&mut s), vec![1, 2, 3]);
    }

    #[test]
    fn full_queue_drops_the_oldest_and_counts() {
        let dir = tempfile::tempdir().expect("tmp");
        let one = HEADER + rec(1).len() as u64;
        let limits = StoreLimits { max_bytes: 3 * one, ..LIMITS };
        let mut s = Store::open(dir.path(), limits, 0).expect("open");
        for t in 1..=5 {
            s.push(&rec(t), t).expect("push");
        }
        assert_eq!(s.counters.dropped_full, 2);
        assert_eq!(drain(&mut s), vec![3, 4, 5]);
    }

    #[test]
    fn old_records_are_dropped_and_counted() {
        let dir = tempfile::tempdir().expect("tmp");
        let limits = StoreLimits { max_age_ms: 100, ..LIMITS };
        let mut s = Store::open(dir.path(), limits, 0).expect("open");
        s.push(&rec(1), 1).expect("push");
        s.push(&rec(150), 150).expect("push");
        assert_eq!(s.counters.dropped_old, 1);
        assert_eq!(drain(&mut s), vec![150]);
    }

    #[test]
    fn torn_tail_is_cut_off_and_the_rest_kept() {
        let dir = tempfile::tempdir().expect("tmp");
        {
            let mut s = Store::open(dir.path(), LIMITS, 0).expect("open");
            s.push(&rec(1), 1).expect("push");
            s.push(&rec(2), 2).expect("push");
        }
        // A power cut mid-write: a header and half a payload.
        let path = dir.path().join("queue.bin");
        let mut bytes = std::fs::read(&path).expect("read");
        bytes.extend_from_slice(&[40, 0, 0, 0, 1, 2, 3, 4, 9, 9]);
        std::fs::write(&path, &bytes).expect("write");
        let mut s = Store::open(dir.path(), LIMITS, 3).expect("reopen");
        assert_eq!(s.counters.damaged_bytes, 10);
        assert_eq!(drain(&mut s), vec![1, 2]);
    }

    #[test]
    fn long_outage_with_a_full_queue_keeps_the_file_bounded() {
        let dir = tempfile::tempdir().expect("tmp");
        let one = HEADER + rec(1).len() as u64;
        let limits = StoreLimits { max_bytes: 4 * one, ..LIMITS };
        let mut s = Store::open(dir.path(), limits, 0).expect("open");
        for t in 1..=100 {
            s.push(&rec(t), t).expect("push");
        }
        let file_len = std::fs::metadata(dir.path().join("queue.bin")).expect("stat").len();
        assert!(file_len <= 10 * one, "file {file_len} bytes, a record {one}");
        assert_eq!(s.counters.dropped_full, 96);
        drop(s);
        let mut s = Store::open(dir.path(), limits, 101).expect("reopen");
        assert_eq!(drain(&mut s), vec![97, 98, 99, 100]);
    }

    #[test]
    fn oversized_record_is_refused_and_the_queue_unchanged() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut s = Store::open(dir.path(), LIMITS, 0).expect("open");
        let big = vec![0u8; MAX_RECORD as usize + 1];
        assert!(matches!(s.push(&big, 1), Err(StoreError::TooLarge { .. })));
        s.push(&rec(2), 2).expect("push");
        assert_eq!(drain(&mut s), vec![2]);
    }

    #[test]
    fn acknowledged_queue_is_compacted_to_nothing() {
        let dir = tempfile::tempdir().expect("tmp");
        let mut s = Store::open(dir.path(), LIMITS, 0).expect("open");
        s.push(&rec(1), 1).expect("push");
        drain(&mut s);
        assert_eq!(std::fs::metadata(dir.path().join("queue.bin")).expect("stat").len(), 0);
    }
}
