//! The MCAP recorder: chunked, zstd-compressed, crash-safe and rotating (DESIGN.md §3,
//! "MCAP layout" and "Crash safety").
//!
//! - A file is written as `NAME.mcap.part` and renamed to `NAME.mcap` when finished.
//! - Log time is the caller's: the writer reads no clock. Whenever the log time has
//!   advanced by [`RecordOptions::sync_interval_ns`] (1 s) since the last sync, the writer
//!   closes the current chunk and calls `sync_data`, so a crash loses at most the last
//!   second. [`RecordWriter::flush_and_sync`] does the same on demand.
//! - Files rotate by size and/or log-time duration; each one is finished, renamed and
//!   carries every configuration file written so far.
//! - A failed write suspends the recording rather than ending it (`storage.rs`): the file
//!   is given up (kept as `.part` when it holds data, removed when not), messages are
//!   dropped and counted, and a new file is opened once a retry finds room. No retry
//!   leaves an empty file.
//! - A retention policy ([`Retention`]) deletes the oldest whole files as files finish.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::alert::Alert;
use crate::estimate::BlowEstimate;
use crate::signal::sample::SampleBatch;

use super::codec;
use super::error::RecordError;
use super::file::OpenFile;
use super::message::{BlowBoundary, ConfigFile, Gap, Payload, Status};
use super::rotation::Naming;
pub use super::rotation::Rotation;
use super::schema::{MessageKind, pb, samples_topic};
use super::storage::{Outage, RecordingHealth, Retention, bytes_free, enforce, is_out_of_room};
use super::tap::{Tap, TappedMessage};

pub use super::options::{
    ChunkCompression, DEFAULT_CHUNK_SIZE_BYTES, DEFAULT_SYNC_INTERVAL_NS, DEFAULT_ZSTD_LEVEL, RecordOptions, SyncPoint,
};
pub use super::rotation::{DEFAULT_FILE_STEM, FINISHED_EXTENSION, PART_EXTENSION};

/// Records forgemon messages to MCAP. See the module docs for the guarantees.
///
/// `create` with a `*.mcap` path writes that file (or, when rotating, `STEM-00001.mcap`,
/// `STEM-00002.mcap`, … beside it); with any other path it creates that directory if
/// needed and writes `forgemon-NNNNN.mcap` files in it, numbered on from the files already
/// there. Dropping the writer without [`RecordWriter::finish`] leaves the current file
/// as `.mcap.part`.
pub struct RecordWriter {
    naming: Naming,
    options: RecordOptions,
    current: Option<OpenFile>,
    finished: Vec<PathBuf>,
    /// Every configuration file written, by name, rewritten into each new file.
    configs: BTreeMap<String, String>,
    buf: Vec<u8>,
    /// A live consumer of every message encoded (`tap.rs`), if one was set.
    tap: Option<Tap>,
    /// Set while the recording is suspended after a failed write.
    outage: Option<Outage>,
    retention: Retention,
    /// Counters `health` reports.
    health: RecordingHealth,
}

impl RecordWriter {
    /// Start a recording at `path` with default options and the given rotation.
    pub fn create(path: impl AsRef<Path>, rotation: Rotation) -> Result<RecordWriter, RecordError> {
        RecordWriter::create_with(path, RecordOptions { rotation, ..RecordOptions::default() })
    }

    pub fn create_with(path: impl AsRef<Path>, options: RecordOptions) -> Result<RecordWriter, RecordError> {
        let naming = Naming::new(path.as_ref(), options.rotation)?;
        let mut writer = RecordWriter {
            naming,
            options,
            current: None,
            finished: Vec::new(),
            configs: BTreeMap::new(),
            buf: Vec::new(),
            tap: None,
            outage: None,
            retention: Retention::default(),
            health: RecordingHealth::default(),
        };
        // A disk already full: the recording starts suspended, and begins once there is room.
        match writer.open_next() {
            Err(e) if is_out_of_room(&e) => writer.suspend(0, e.to_string()),
            other => other?,
        }
        Ok(writer)
    }

    /// Apply `retention` from now on: at once, and each time a file finishes or a retry
    /// looks for room.
    pub fn set_retention(&mut self, retention: Retention) {
        self.retention = retention;
        self.enforce_retention();
    }

    /// The recording's state: writing or suspended, the space left, what was dropped.
    pub fn health(&self) -> RecordingHealth {
        RecordingHealth {
            state: if self.outage.is_some() { "suspended" } else { "recording" },
            path: self.current.as_ref().map(|f| f.part_path.clone()),
            reason: self.outage.as_ref().map(|o| o.reason.clone()),
            bytes_free: bytes_free(&self.naming.dir),
            ..self.health.clone()
        }
    }

    /// Record a batch of samples on `/samples/<source>`. Log time is its `host_time_ns`,
    /// publish time its `device_time_ns` (or the log time when that is negative).
    /// Batches should hold 10–100 ms of samples ([`super::Rebatcher`] makes them so).
    pub fn write_samples(&mut self, batch: &SampleBatch) -> Result<(), RecordError> {
        let topic_for_errors = || samples_topic(&batch.source);
        let log_time = self.log_time(batch.host_time_ns, topic_for_errors)?;
        let publish_time = u64::try_from(batch.device_time_ns).unwrap_or(log_time);
        self.buf.clear();
        if let Err(reason) = codec::encode_samples(batch, &mut self.buf) {
            let path = self.current_path();
            return Err(RecordError::BadBatch { path, source_name: batch.source.clone(), reason });
        }
        self.write_encoded(MessageKind::Samples, Some(&batch.source), log_time, publish_time)
    }

    /// Record where a blow was cut, on `/blows`.
    pub fn write_boundary(&mut self, log_time_ns: i64, boundary: &BlowBoundary) -> Result<(), RecordError> {
        self.write_payload(log_time_ns, &Payload::Boundary(boundary.clone()))
    }

    /// Record a blow's result, on `/results`.
    pub fn write_result(&mut self, log_time_ns: i64, result: &BlowEstimate) -> Result<(), RecordError> {
        self.write_payload(log_time_ns, &Payload::Result(Box::new(result.clone())))
    }

    /// Record an alert, on `/alerts`.
    pub fn write_alert(&mut self, log_time_ns: i64, alert: &Alert) -> Result<(), RecordError> {
        self.write_payload(log_time_ns, &Payload::Alert(alert.clone()))
    }

    /// Record lost samples, on `/gaps`.
    pub fn write_gap(&mut self, log_time_ns: i64, gap: &Gap) -> Result<(), RecordError> {
        self.write_payload(log_time_ns, &Payload::Gap(gap.clone()))
    }

    /// Record a source's status, on `/status`.
    pub fn write_status(&mut self, log_time_ns: i64, status: &Status) -> Result<(), RecordError> {
        self.write_payload(log_time_ns, &Payload::Status(status.clone()))
    }

    /// Record a billet's summary, on `/billets`.
    pub fn write_billet(
        &mut self,
        log_time_ns: i64,
        billet: &crate::estimate::billet_book::BilletSummary,
    ) -> Result<(), RecordError> {
        self.write_payload(log_time_ns, &Payload::Billet(Box::new(billet.clone())))
    }

    /// Store a configuration file on `/config`. It is also written into every later file of
    /// a rotated recording (a later one with the same name replaces it there).
    pub fn write_config(&mut self, log_time_ns: i64, name: &str, text: &str) -> Result<(), RecordError> {
        self.write_payload(log_time_ns, &Payload::Config(ConfigFile { name: name.to_string(), text: text.to_string() }))
    }

    /// Record any payload on its channel. Samples go to `/samples/<source>` with their own
    /// host time, whatever `log_time_ns` says.
    pub fn write_payload(&mut self, log_time_ns: i64, payload: &Payload) -> Result<(), RecordError> {
        if let Payload::Samples(batch) = payload {
            return self.write_samples(batch);
        }
        let kind = payload.kind();
        let log_time = self.log_time(log_time_ns, || kind.fixed_topic().unwrap_or_default().to_string())?;
        if let Payload::Config(c) = payload {
            self.configs.insert(c.name.clone(), c.text.clone());
        }
        self.buf.clear();
        // Only sample batches can fail to encode.
        if let Err(reason) = codec::encode_payload(payload, &mut self.buf) {
            let path = self.current_path();
            return Err(RecordError::BadBatch { path, source_name: String::new(), reason });
        }
        self.write_encoded(kind, None, log_time, log_time)
    }

    /// Hand every message encoded from now on to `tap` too (replacing any tap set before),
    /// whether or not the file write that follows succeeds: a live view goes on showing the
    /// pipeline's messages while the disk is full. The configuration files that rotation
    /// writes again into each new file are not handed over again.
    pub fn set_tap(&mut self, tap: Tap) {
        self.tap = Some(tap);
    }

    /// Close the current chunk, flush, and `sync_data` the current file.
    pub fn flush_and_sync(&mut self) -> Result<(), RecordError> {
        match self.current.as_mut() {
            Some(file) => file.flush_and_sync(),
            None => Ok(()),
        }
    }

    /// The current file's last sync point, if it has synced since it was opened.
    pub fn last_sync(&self) -> Option<SyncPoint> {
        self.current.as_ref().and_then(|f| f.last_sync)
    }

    /// The file being written now (a `.mcap.part`).
    pub fn current_path(&self) -> PathBuf {
        self.current.as_ref().map(|f| f.part_path.clone()).unwrap_or_else(|| self.naming.dir.clone())
    }

    /// Bytes written to the current file so far.
    pub fn current_bytes(&self) -> u64 {
        self.current.as_ref().map_or(0, |f| f.bytes())
    }

    /// Files finished (by rotation) so far, in order.
    pub fn finished_files(&self) -> &[PathBuf] {
        &self.finished
    }

    /// Finish the current file (summary, footer, sync, rename) and return every finished
    /// file of the recording, in order.
    pub fn finish(mut self) -> Result<Vec<PathBuf>, RecordError> {
        if let Some(file) = self.current.take() {
            self.finished.push(file.finish()?);
        }
        Ok(std::mem::take(&mut self.finished))
    }

    fn log_time(&self, time_ns: i64, topic: impl FnOnce() -> String) -> Result<u64, RecordError> {
        u64::try_from(time_ns).map_err(|_| RecordError::NegativeLogTime {
            path: self.current_path(),
            topic: topic(),
            time_ns,
        })
    }

    /// Write `self.buf` as a message of `kind`: handed to the tap, then to the file unless
    /// the recording is suspended and no retry is due. A failed write suspends it.
    fn write_encoded(
        &mut self,
        kind: MessageKind,
        source: Option<&str>,
        log_time: u64,
        publish_time: u64,
    ) -> Result<(), RecordError> {
        self.tap_message(kind, source, log_time, publish_time);
        if self.outage.is_some() && !self.try_resume(log_time) {
            self.count_dropped(kind);
            let reason = self.outage.as_ref().map(|o| o.reason.clone()).unwrap_or_default();
            return Err(RecordError::Suspended { dir: self.naming.dir.clone(), reason });
        }
        let mut in_file = false;
        self.write_to_file(kind, source, log_time, publish_time, &mut in_file).inspect_err(|e| {
            // A message that reached the file is among those `abandon` counts lost.
            if !in_file {
                self.count_dropped(kind);
            }
            self.suspend(log_time, e.to_string());
        })
    }

    fn tap_message(&mut self, kind: MessageKind, source: Option<&str>, log_time: u64, publish_time: u64) {
        let Some(tap) = self.tap.as_mut() else { return };
        let samples;
        let topic = match (kind.fixed_topic(), source) {
            (Some(t), _) => t,
            (None, s) => {
                samples = samples_topic(s.unwrap_or_default());
                samples.as_str()
            }
        };
        tap(&TappedMessage { topic, kind, data: &self.buf, log_time_ns: log_time, publish_time_ns: publish_time });
    }

    /// `self.buf` into the current file, rotating first and syncing after as due;
    /// `in_file` turns true once the message is handed to the file.
    fn write_to_file(
        &mut self,
        kind: MessageKind,
        source: Option<&str>,
        log_time: u64,
        publish_time: u64,
        in_file: &mut bool,
    ) -> Result<(), RecordError> {
        if self.current.as_ref().is_some_and(|f| f.rotation_due(&self.options.rotation, log_time)) {
            // Synced first, so that a finish that fails (a full disk) loses nothing.
            self.flush_and_sync()?;
            if let Some(file) = self.current.take() {
                self.finished.push(file.finish()?);
                self.enforce_retention();
            }
            self.open_next()?;
            self.write_configs(log_time)?;
        }
        let file = match self.current.as_mut() {
            Some(file) => file,
            None => {
                self.open_next()?;
                self.current.as_mut().ok_or_else(|| RecordError::BadTarget { path: self.naming.dir.clone() })?
            }
        };
        *in_file = true;
        file.write(kind, source, log_time, publish_time, &self.buf)?;
        if log_time >= file.last_sync_log_time.saturating_add(self.options.sync_interval_ns) {
            file.flush_and_sync()?;
        }
        Ok(())
    }

    /// A write failed: give the file up (counting what it loses) and drop messages until
    /// a retry finds room.
    fn suspend(&mut self, log_time: u64, reason: String) {
        self.abandon_current();
        self.health.suspensions += 1;
        self.outage = Some(Outage::new(log_time, reason));
    }

    /// A retry, if one is due: room for a chunk, then a new file with the configuration
    /// files. Whether the recording is back.
    fn try_resume(&mut self, log_time: u64) -> bool {
        let Some(outage) = self.outage.as_mut() else { return true };
        if !outage.retry_due(log_time) {
            return false;
        }
        self.enforce_retention();
        let room = 2 * self.options.chunk_size_bytes;
        let free = bytes_free(&self.naming.dir);
        let opened = if free.is_some_and(|b| b < room) {
            Err(format!("{} bytes free in {}, waiting for {room}", free.unwrap_or(0), self.naming.dir.display()))
        } else {
            self.open_next().and_then(|()| self.write_configs(log_time)).map_err(|e| e.to_string())
        };
        match opened {
            Ok(()) => {
                self.outage = None;
                true
            }
            Err(reason) => {
                self.abandon_current();
                if let Some(o) = self.outage.as_mut() {
                    o.retry_failed(log_time, reason);
                }
                false
            }
        }
    }

    fn abandon_current(&mut self) {
        if let Some(file) = self.current.take() {
            let gone = file.abandon();
            self.health.dropped_messages += gone.lost_messages;
            self.health.dropped_blows += gone.lost_results;
        }
    }

    fn count_dropped(&mut self, kind: MessageKind) {
        self.health.dropped_messages += 1;
        self.health.dropped_blows += u64::from(kind == MessageKind::Result);
    }

    fn enforce_retention(&mut self) {
        let current = self.current.as_ref().map(|f| f.part_path.as_path());
        self.health.deleted_files +=
            enforce(&self.naming.dir, self.naming.stem(), current, self.retention, std::time::SystemTime::now());
    }

    /// Rewrite every stored configuration file into the (new) current file. Uses its own
    /// buffer: `self.buf` holds the message that triggered the rotation.
    fn write_configs(&mut self, log_time: u64) -> Result<(), RecordError> {
        let Some(file) = self.current.as_mut() else { return Ok(()) };
        let mut buf = Vec::new();
        for (name, text) in &self.configs {
            buf.clear();
            let config = pb::ConfigFile { name: name.clone(), text: text.clone() };
            prost::Message::encode_raw(&config, &mut buf);
            file.write(MessageKind::Config, None, log_time, log_time, &buf)?;
        }
        Ok(())
    }

    fn open_next(&mut self) -> Result<(), RecordError> {
        let final_path = self.naming.next_path()?;
        self.current = Some(OpenFile::create(final_path, &self.options)?);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use prost::Message;

    use super::*;
    use crate::alert::AlertKind;
    use crate::record::reader::read_recording;
    use crate::record::schema::MessageKind;
    use crate::signal::sample::Role;

    const MS: i64 = 1_000_000;

    fn batch(k: i64, n: usize) -> SampleBatch {
        SampleBatch {
            source: "daq0".into(),
            seq: k as u64,
            device_time_ns: k * 50 * MS,
            host_time_ns: 1_000 * MS + k * 50 * MS,
            period_ns: 10_000.0,
            roles: vec![Role::Load, Role::Disp, Role::Acc],
            values: (0..3 * n).map(|i| (k * 1000 + i as i64) as f64).collect(),
        }
    }

    fn estimate() -> BlowEstimate {
        crate::estimate::result::examples::soft(1)
    }

    fn every_payload() -> Vec<(i64, Payload)> {
        let alert = Alert {
            kind: AlertKind::ModelHealth,
            blow: 1,
            reason: "energy balance residual 0.2 above 0.1".into(),
            figures: BTreeMap::from([("residual".to_string(), 0.2)]),
        };
        vec![
            (900 * MS, Payload::Config(ConfigFile { name: "machine.toml".into(), text: "kind = \"hammer\"\n".into() })),
            (
                1_000 * MS,
                Payload::Status(Status { source: "daq0".into(), state: "connected".into(), ..Status::default() }),
            ),
            (1_000 * MS, Payload::Samples(batch(0, 5000))),
            (1_050 * MS, Payload::Samples(batch(1, 5000))),
            (
                1_060 * MS,
                Payload::Gap(Gap { source: "daq0".into(), t_s: 0.06, samples_lost: 100, reason: "crc".into() }),
            ),
            (
                1_100 * MS,
                Payload::Boundary(BlowBoundary {
                    blow: 1,
                    t_trigger_s: 0.11,
                    t_contact_s: 0.12,
                    t_end_s: 0.14,
                    source: "daq0".into(),
                }),
            ),
            (1_100 * MS, Payload::Result(Box::new(BlowEstimate { alert: Some(alert.clone()), ..estimate() }))),
            (1_100 * MS, Payload::Alert(alert)),
        ]
    }

    #[test]
    fn every_message_kind_round_trips_through_a_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("run.mcap");
        let mut w = RecordWriter::create(&path, Rotation::NEVER).expect("create");
        assert!(dir.path().join("run.mcap.part").exists(), "written as .part");
        let written = every_payload();
        for (t, p) in &written {
            w.write_payload(*t, p).expect("write");
        }
        assert_eq!(w.finish().expect("finish"), vec![path.clone()]);
        assert!(!dir.path().join("run.mcap.part").exists(), "renamed on finish");

        let rec = read_recording(&path).expect("read");
        assert!(rec.report.complete && rec.report.indexed, "{}", rec.report);
        assert_eq!(rec.report.messages, written.len() as u64);
        let read: Vec<(i64, Payload)> = rec.messages.into_iter().map(|m| (m.log_time_ns, m.payload)).collect();
        assert_eq!(read, written);
    }

    #[test]
    fn schema_records_carry_a_descriptor_set_holding_their_message() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("s.mcap");
        let mut w = RecordWriter::create(&path, Rotation::NEVER).expect("create");
        for (t, p) in &every_payload() {
            w.write_payload(*t, p).expect("write");
        }
        w.finish().expect("finish");
        let bytes = std::fs::read(&path).expect("read back");
        let summary = mcap::Summary::read(&bytes).expect("summary").expect("has a summary");
        let mut topics: Vec<&str> = summary.channels.values().map(|c| c.topic.as_str()).collect();
        topics.sort_unstable();
        assert_eq!(topics, ["/alerts", "/blows", "/config", "/gaps", "/results", "/samples/daq0", "/status"]);
        for channel in summary.channels.values() {
            assert_eq!(channel.message_encoding, "protobuf");
            let schema = channel.schema.as_ref().expect("every channel has a schema");
            assert_eq!(schema.encoding, "protobuf");
            let kind = MessageKind::from_schema_name(&schema.name).expect("a forgemon schema");
            let fds = prost_types::FileDescriptorSet::decode(schema.data.as_ref()).expect("FileDescriptorSet");
            let short = kind.schema_name().trim_start_matches("forgemon.");
            assert!(
                fds.file.iter().any(|f| f.package() == "forgemon" && f.message_type.iter().any(|m| m.name() == short))
            );
        }
        // A message decodes with the generated type too (what any protobuf reader does).
        let sample = mcap::MessageStream::new(&bytes)
            .expect("stream")
            .filter_map(Result::ok)
            .find(|m| m.channel.topic == "/samples/daq0")
            .expect("a sample message");
        let pbatch = pb::SampleBatch::decode(sample.data.as_ref()).expect("decodes");
        assert_eq!(pbatch.values.len(), 15_000);
        assert_eq!(sample.publish_time, 0, "publish time = device time of the first batch");
        assert_eq!(sample.log_time, 1_000_000_000);
    }

    #[test]
    fn equal_inputs_give_identical_files() {
        // Replaying into `--out` twice must give the same bytes: nothing in a file comes
        // from a clock, a thread or a hash order.
        let dir = tempfile::tempdir().expect("temp dir");
        let write = |name: &str| {
            let mut w = RecordWriter::create(dir.path().join(name), Rotation::NEVER).expect("create");
            for (t, p) in &every_payload() {
                w.write_payload(*t, p).expect("write");
            }
            for k in 2..40 {
                w.write_samples(&batch(k, 100)).expect("write");
            }
            let files = w.finish().expect("finish");
            std::fs::read(&files[0]).expect("read back")
        };
        assert_eq!(write("a.mcap"), write("b.mcap"));
    }

    #[test]
    fn syncs_every_second_of_log_time() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut w = RecordWriter::create(dir.path().join("sync.mcap"), Rotation::NEVER).expect("create");
        // 50 ms batches: the first message starts the clock, the 21st is 1 s later.
        for k in 0..20 {
            w.write_samples(&batch(k, 10)).expect("write");
            assert_eq!(w.last_sync(), None, "batch {k}: less than 1 s of log time");
        }
        w.write_samples(&batch(20, 10)).expect("write");
        let sync = w.last_sync().expect("synced at 1 s");
        assert_eq!(sync.file_messages, 21);
        assert_eq!(sync.log_time_ns, (2_000 * MS) as u64);
        assert_eq!(sync.file_bytes, w.current_bytes(), "the chunk was closed and flushed");
        for k in 21..40 {
            w.write_samples(&batch(k, 10)).expect("write");
        }
        assert_eq!(w.last_sync().map(|s| s.file_messages), Some(21));
        w.write_samples(&batch(40, 10)).expect("write");
        assert_eq!(w.last_sync().map(|s| s.file_messages), Some(41));
        w.flush_and_sync().expect("sync on demand");
        w.finish().expect("finish");
    }

    /// One message as (topic, schema name, schema data, encodings, bytes, log and publish time).
    type Seen = (String, String, Vec<u8>, String, String, Vec<u8>, u64, u64);

    #[test]
    fn the_tap_sees_every_message_as_the_file_holds_it_and_changes_nothing() {
        let dir = tempfile::tempdir().expect("temp dir");
        let write = |path: &std::path::Path, tapped: Option<std::sync::Arc<std::sync::Mutex<Vec<Seen>>>>| {
            let mut w = RecordWriter::create(path, Rotation::by_duration_ns(500 * MS as u64)).expect("create");
            if let Some(tapped) = tapped {
                w.set_tap(Box::new(move |m: &TappedMessage<'_>| {
                    let seen = (
                        m.topic.to_string(),
                        m.schema_name().to_string(),
                        m.schema().to_vec(),
                        m.schema_encoding().to_string(),
                        m.message_encoding().to_string(),
                        m.data.to_vec(),
                        m.log_time_ns,
                        m.publish_time_ns,
                    );
                    tapped.lock().expect("not poisoned").push(seen);
                }));
            }
            for (t, p) in &every_payload() {
                w.write_payload(*t, p).expect("write");
            }
            // Past the rotation: the next file starts with the config written again.
            w.write_samples(&batch(20, 10)).expect("write");
            w.finish().expect("finish")
        };
        let tapped = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let files = write(&dir.path().join("tapped.mcap"), Some(tapped.clone()));
        let plain = write(&dir.path().join("plain.mcap"), None);
        // What the files hold, read back through the mcap crate (not our reader).
        let read = |files: &[PathBuf]| -> Vec<Seen> {
            let mut out = Vec::new();
            for f in files {
                let bytes = std::fs::read(f).expect("read back");
                for m in mcap::MessageStream::new(&bytes).expect("stream").map(|m| m.expect("message")) {
                    let schema = m.channel.schema.as_ref().expect("a schema");
                    out.push((
                        m.channel.topic.clone(),
                        schema.name.clone(),
                        schema.data.to_vec(),
                        schema.encoding.clone(),
                        m.channel.message_encoding.clone(),
                        m.data.to_vec(),
                        m.log_time,
                        m.publish_time,
                    ));
                }
            }
            out
        };
        let (recorded, recorded_plain) = (read(&files), read(&plain));
        assert_eq!(files.len(), 2, "the recording rotated");
        assert_eq!(recorded, recorded_plain, "a tap changes nothing that is recorded");
        let tapped = tapped.lock().expect("not poisoned").clone();
        // Every message once, in order; the config rewritten into the second file is not.
        let first_config_again = recorded.iter().rposition(|m| m.0 == "/config").expect("config rewritten");
        let mut expected = recorded.clone();
        expected.remove(first_config_again);
        assert_eq!(tapped.len(), every_payload().len() + 1);
        assert_eq!(tapped, expected);
    }

    #[test]
    fn rotation_by_duration_numbers_files_and_repeats_the_config() {
        let dir = tempfile::tempdir().expect("temp dir");
        // A file left by an earlier run: numbering continues after it.
        std::fs::write(dir.path().join("forgemon-00007.mcap.part"), b"crashed").expect("write");
        let mut w = RecordWriter::create(dir.path(), Rotation::by_duration_ns(500 * MS as u64)).expect("create");
        w.write_config(1_000 * MS, "process.toml", "machine = \"hammer\"\n").expect("config");
        for k in 0..25 {
            w.write_samples(&batch(k, 10)).expect("write");
        }
        let files = w.finish().expect("finish");
        let names: Vec<String> =
            files.iter().map(|p| p.file_name().and_then(|n| n.to_str()).unwrap_or_default().to_string()).collect();
        assert_eq!(names, ["forgemon-00008.mcap", "forgemon-00009.mcap", "forgemon-00010.mcap"]);
        let mut samples = 0;
        for f in &files {
            let rec = read_recording(f).expect("read");
            assert!(rec.report.complete);
            assert!(
                matches!(&rec.messages[0].payload, Payload::Config(c) if c.name == "process.toml"),
                "{} starts with the config",
                f.display()
            );
            samples += rec.messages.iter().filter(|m| matches!(m.payload, Payload::Samples(_))).count();
        }
        assert_eq!(samples, 25);
    }

    #[test]
    fn bad_input_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut w = RecordWriter::create(dir.path().join("bad.mcap"), Rotation::NEVER).expect("create");
        let err = w.write_samples(&SampleBatch { host_time_ns: -5, ..batch(0, 1) }).expect_err("negative log time");
        assert!(err.to_string().contains("bad.mcap.part") && err.to_string().contains("-5"), "{err}");
        let ragged = SampleBatch { values: vec![1.0, 2.0], ..batch(0, 0) };
        let err = w.write_samples(&ragged).expect_err("ragged");
        assert!(err.to_string().contains("daq0"), "{err}");
        let err = w.write_gap(-1, &Gap { source: "x".into(), t_s: 0.0, samples_lost: 1, reason: String::new() });
        assert!(err.expect_err("negative").to_string().contains("/gaps"));
        w.finish().expect("finish after refused writes");
        let err = RecordWriter::create(dir.path().join("no/such/dir/x.mcap"), Rotation::NEVER).err();
        assert!(err.is_some_and(|e| e.to_string().contains("no/such/dir/x.mcap.part")));
    }

    #[test]
    fn a_writer_dropped_without_finish_leaves_a_readable_part_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut w = RecordWriter::create(dir.path().join("d.mcap"), Rotation::NEVER).expect("create");
        for k in 0..3 {
            w.write_samples(&batch(k, 10)).expect("write");
        }
        drop(w);
        assert!(!dir.path().join("d.mcap").exists());
        let rec = read_recording(dir.path().join("d.mcap.part")).expect("read .part");
        assert_eq!(rec.messages.len(), 3);
    }
}
