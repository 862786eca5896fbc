//! Reading a recording back as typed messages, from a finished file (through its summary
//! and chunk index) or front to back (a file cut off by a crash or power loss, or one whose
//! summary is damaged), and saying how much was recovered and what was corrupt.
//!
//! Every chunk is checked against its CRC by the `mcap` crate before any of its messages
//! is yielded (`chunk.rs`): a chunk gives all its messages or none. A corrupt chunk is
//! skipped, and reading goes on at the next one (found through the chunk index, by the
//! chunk's own length field, or by resynchronising, `linear.rs`); [`ReadReport`] names each
//! skipped chunk with its byte offset and topics. A cut-off file gives back the messages of
//! the chunks written completely before the cut. Both paths yield messages in file order,
//! which is the order they were recorded; [`read_recording`] sorts them by log time.

use std::collections::VecDeque;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::mpsc::Receiver;

use mcap::records::ChunkIndex;

use super::channels::{Channels, Lookup};
use super::chunk::{self, Inner, Unpacked};
use super::codec;
use super::error::{ChunkError, RecordError};
use super::indexed::{self, Ahead};
pub use super::indexed::{MAX_RECORD_BYTES, READ_AHEAD_CHUNKS};
use super::linear::{Linear, Step};
use super::message::Recorded;
use super::report::{CorruptChunk, ReadReport};
use super::summary::{self, Found};

/// A whole recording in memory, in log-time order (ties in file order).
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub messages: Vec<Recorded>,
    pub report: ReadReport,
}

/// Read a whole recording (`.mcap` or `.mcap.part`) into memory, sorted by log time.
/// Corrupt chunks are skipped and named in the report, not errors.
pub fn read_recording(path: impl AsRef<Path>) -> Result<Recording, RecordError> {
    let mut reader = RecordReader::open(path)?;
    let mut messages = Vec::new();
    for message in reader.by_ref() {
        messages.push(message?);
    }
    // Stable: messages with equal log times keep their file order.
    messages.sort_by_key(|m| m.log_time_ns);
    Ok(Recording { messages, report: reader.report().clone() })
}

/// Streams the messages of one recording, in file (= recording) order. After the last
/// message, [`RecordReader::report`] says how much was read and what was skipped. The
/// only errors are IO errors and a file that is not MCAP at all.
pub struct RecordReader {
    path: PathBuf,
    source: Source,
    channels: Channels,
    /// The messages of the chunk being handed out.
    queue: VecDeque<Recorded>,
    report: ReadReport,
    /// Reading front to back: the corrupt chunk whose topics the message index records
    /// after it name.
    naming: Option<usize>,
    done: bool,
}

enum Source {
    Indexed {
        file: File,
        chunks: std::vec::IntoIter<ChunkIndex>,
        /// The buffer each chunk is read into.
        record: Vec<u8>,
    },
    /// The indexed chunks, read and unpacked ahead on a thread of their own.
    Ahead(Receiver<Ahead>),
    Linear(Box<Linear>),
}

/// How a recording with a chunk index is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ReadMode {
    /// A thread of the reader's own reads the chunks ahead, up to `READ_AHEAD_CHUNKS`,
    /// and each is unpacked (decompression and CRC) as a task on rayon's threads, while the
    /// caller handles the messages before them. What it yields, and the report, are the
    /// sequential mode's. A reader opened inside a rayon task reads sequentially.
    #[default]
    Parallel,
    /// Each chunk read and unpacked on the caller's thread when its turn comes.
    Sequential,
}

impl RecordReader {
    /// Open a recording. Fails when the file cannot be read or is not MCAP at all; a
    /// cut-off or damaged file opens, and yields what it holds.
    pub fn open(path: impl AsRef<Path>) -> Result<RecordReader, RecordError> {
        RecordReader::open_with(path, ReadMode::default())
    }

    /// `open`, reading an indexed recording as `mode` says.
    pub fn open_with(path: impl AsRef<Path>, mode: ReadMode) -> Result<RecordReader, RecordError> {
        let path = path.as_ref().to_path_buf();
        let io_err = |action: &'static str| {
            let path = path.clone();
            move |source| RecordError::Io { path, action, source }
        };
        let mut file = File::open(&path).map_err(io_err("open"))?;
        let total_bytes = file.metadata().map_err(io_err("stat"))?.len();
        check_magic(&path, &mut file, total_bytes)?;
        let mut report = ReadReport::new(path.clone(), total_bytes);
        let found = summary::read_summary(&mut file, total_bytes, MAX_RECORD_BYTES).map_err(io_err("read"))?;
        let (source, channels) = match found {
            // Every message is in an indexed chunk (forgemon writes no others).
            Found::Summary(s) if !s.chunk_indexes.is_empty() || s.message_count.unwrap_or(0) == 0 => {
                report.complete = true;
                report.indexed = true;
                let s = *s;
                // Inside a rayon task, waiting for the chunks' unpacking on rayon's threads
                // could hold the thread it needs: read in turn there.
                let mode = if rayon::current_thread_index().is_some() { ReadMode::Sequential } else { mode };
                let source = match mode {
                    ReadMode::Parallel => match indexed::read_ahead(&file, s.chunk_indexes.clone(), total_bytes) {
                        Some(rx) => Source::Ahead(rx),
                        None => Source::Indexed { file, chunks: s.chunk_indexes.into_iter(), record: Vec::new() },
                    },
                    ReadMode::Sequential => {
                        Source::Indexed { file, chunks: s.chunk_indexes.into_iter(), record: Vec::new() }
                    }
                };
                (source, s.channels)
            }
            other => {
                if let Found::Unreadable(why) = other {
                    report.summary_error = Some(why);
                }
                let linear = Linear::new(file, total_bytes, MAX_RECORD_BYTES).map_err(io_err("seek"))?;
                (Source::Linear(Box::new(linear)), Channels::default())
            }
        };
        Ok(RecordReader { path, source, channels, queue: VecDeque::new(), report, naming: None, done: false })
    }

    /// How much has been read so far; final once the iterator has ended.
    pub fn report(&self) -> &ReadReport {
        &self.report
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn next_message(&mut self) -> Result<Option<Recorded>, RecordError> {
        loop {
            if let Some(message) = self.queue.pop_front() {
                self.report.messages += 1;
                return Ok(Some(message));
            }
            if !self.advance()? {
                return Ok(None);
            }
        }
    }

    /// Read the next chunk (or record) into the queue; `false` at the end.
    fn advance(&mut self) -> Result<bool, RecordError> {
        let io_err = |source| RecordError::Io { path: self.path.clone(), action: "read", source };
        match &mut self.source {
            Source::Indexed { file, chunks, record } => {
                let Some(index) = chunks.next() else {
                    self.report.bytes_recovered = self.report.total_bytes;
                    return Ok(false);
                };
                let (start, length) = (index.chunk_start_offset, index.chunk_length);
                let unpacked = match indexed::chunk_bounds(start, length, self.report.total_bytes) {
                    Ok(()) => {
                        indexed::read_at(file, start, length as usize, record).map_err(io_err)?;
                        chunk::unpack(record, MAX_RECORD_BYTES)
                    }
                    Err(error) => Err(error),
                };
                self.take_indexed(&index, unpacked);
            }
            Source::Ahead(rx) => match rx.recv() {
                Ok(Ahead::Chunk { index, unpacked }) => match unpacked.recv() {
                    Ok(unpacked) => self.take_indexed(&index, unpacked),
                    Err(_) => {
                        let source = std::io::Error::other("a chunk's unpacking stopped");
                        return Err(RecordError::Io { path: self.path.clone(), action: "read", source });
                    }
                },
                Ok(Ahead::Io(source)) => {
                    return Err(RecordError::Io { path: self.path.clone(), action: "read", source });
                }
                Ok(Ahead::End) => {
                    self.report.bytes_recovered = self.report.total_bytes;
                    return Ok(false);
                }
                Err(_) => {
                    let source = std::io::Error::other("the read-ahead thread stopped");
                    return Err(RecordError::Io { path: self.path.clone(), action: "read", source });
                }
            },
            Source::Linear(linear) => match linear.next_step().map_err(io_err)? {
                Some(step) => self.take_step(step),
                None => return Ok(false),
            },
        }
        Ok(true)
    }

    /// The chunk `index` points at (through the summary), read or refused by its bounds.
    fn take_indexed(&mut self, index: &ChunkIndex, unpacked: Result<Unpacked, ChunkError>) {
        let mut topics: Vec<String> =
            index.message_index_offsets.keys().map(|&id| self.channels.topic_or_id(id)).collect();
        topics.sort();
        self.take_chunk(index.chunk_start_offset, index.chunk_length, unpacked, topics);
    }

    /// One step of reading front to back: a chunk, a message index naming a corrupt
    /// chunk's topics, a record outside any chunk, damaged bytes, or the end.
    fn take_step(&mut self, step: Step) {
        match step {
            Step::Chunk { offset, record } => {
                self.naming = None;
                let unpacked = chunk::unpack(&record, MAX_RECORD_BYTES);
                if !self.take_chunk(offset, record.len() as u64, unpacked, Vec::new()) {
                    self.naming = self.report.corrupt_chunks.len().checked_sub(1);
                }
            }
            Step::MessageIndex { channel_id } => self.name_topic(channel_id),
            Step::Loose { offset, length, record } => {
                self.naming = None;
                match self.decode(vec![record]) {
                    Ok(messages) => self.queue.extend(messages),
                    Err(error) => self.corrupt(offset, length, Vec::new(), error),
                }
            }
            Step::Damaged { offset, length, error } => {
                self.naming = None;
                self.corrupt(offset, length, Vec::new(), error);
            }
            Step::End { complete, stopped_by } => {
                self.report.complete = complete;
                self.report.stopped_by = stopped_by;
                if complete {
                    self.report.bytes_recovered = self.report.total_bytes;
                }
            }
        }
    }

    /// A message index after a corrupt chunk names one of the chunk's topics.
    fn name_topic(&mut self, channel_id: u16) {
        let topic = self.channels.topic_or_id(channel_id);
        if let Some(c) = self.naming.and_then(|i| self.report.corrupt_chunks.get_mut(i))
            && !c.topics.contains(&topic)
        {
            c.topics.push(topic);
            c.topics.sort();
        }
    }

    /// Decode one chunk record of `length` bytes at `offset`, checked and unpacked, into the
    /// queue; `false` when it was corrupt (and is now in the report).
    fn take_chunk(
        &mut self,
        offset: u64,
        length: u64,
        unpacked: Result<Unpacked, ChunkError>,
        topics: Vec<String>,
    ) -> bool {
        let decoded = unpacked.and_then(|u| Ok((u.verified, self.decode(u.records)?)));
        match decoded {
            Ok((verified, messages)) => {
                self.queue.extend(messages);
                if verified {
                    self.report.chunks_verified += 1;
                } else {
                    self.report.chunks_unverified += 1;
                }
                self.report.bytes_recovered = self.report.bytes_recovered.max(offset + length);
                true
            }
            Err(error) => {
                self.corrupt(offset, length, topics, error);
                false
            }
        }
    }

    /// Turn a chunk's records into messages, learning its schemas and channels on the way.
    /// One message that does not decode makes the whole chunk corrupt.
    fn decode(&mut self, records: Vec<Inner>) -> Result<Vec<Recorded>, ChunkError> {
        let mut out = Vec::new();
        let (mut foreign, mut unknown) = (0, 0);
        for record in records {
            match record {
                Inner::Schema { id, name, encoding } => self.channels.add_schema(id, name, encoding),
                Inner::Channel { id, schema_id, topic, message_encoding } => {
                    self.channels.add_channel(id, schema_id, topic, message_encoding)
                }
                Inner::Message { channel_id, log_time, data } => match self.channels.lookup(channel_id) {
                    Lookup::Ours(kind, topic) => {
                        let payload = codec::decode_payload(kind, &data).map_err(|source| ChunkError::Payload {
                            topic: topic.to_string(),
                            log_time_ns: log_time,
                            source,
                        })?;
                        let log_time_ns = i64::try_from(log_time)
                            .map_err(|_| ChunkError::LogTime { topic: topic.to_string(), log_time_ns: log_time })?;
                        out.push(Recorded { log_time_ns, payload });
                    }
                    Lookup::Foreign => foreign += 1,
                    Lookup::Unknown => unknown += 1,
                },
            }
        }
        self.report.skipped += foreign;
        self.report.unknown_channel_messages += unknown;
        Ok(out)
    }

    /// Name a corrupt chunk (or stretch of bytes) in the report. Damage that starts where
    /// the last one ended is the same damage (a chunk whose length field was hit, and the
    /// bytes after it the reader could not frame): the entry grows.
    fn corrupt(&mut self, offset: u64, length: u64, topics: Vec<String>, error: ChunkError) {
        if let Some(last) = self.report.corrupt_chunks.last_mut()
            && last.offset.saturating_add(last.length) == offset
            && matches!(error, ChunkError::Framing { .. } | ChunkError::Tail { .. })
        {
            last.length += length;
            return;
        }
        self.report.corrupt_chunks.push(CorruptChunk { offset, length, topics, error });
    }
}

impl Iterator for RecordReader {
    type Item = Result<Recorded, RecordError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let item = self.next_message().transpose();
        if !matches!(item, Some(Ok(_))) {
            self.done = true;
        }
        item
    }
}

/// The first bytes must be the MCAP magic; anything else is not a recording.
fn check_magic(path: &Path, file: &mut File, total_bytes: u64) -> Result<(), RecordError> {
    if total_bytes == 0 {
        return Err(RecordError::NotMcap { path: path.to_path_buf(), reason: "the file is empty".to_string() });
    }
    let mut head = [0u8; 8];
    let n = (total_bytes as usize).min(head.len());
    file.read_exact(&mut head[..n]).map_err(|source| RecordError::Io {
        path: path.to_path_buf(),
        action: "read",
        source,
    })?;
    if head[..n] != mcap::MAGIC[..n] || n < mcap::MAGIC.len() {
        let shown: String = head[..n].iter().map(|&b| if b.is_ascii_graphic() { b as char } else { '.' }).collect();
        return Err(RecordError::NotMcap {
            path: path.to_path_buf(),
            reason: format!("it does not start with the MCAP magic bytes (starts with {shown:?})"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use crate::record::message::{ConfigFile, Payload};
    use crate::record::writer::{ChunkCompression, RecordOptions, RecordWriter};
    use crate::signal::sample::{Role, SampleBatch};

    const MS: i64 = 1_000_000;
    const BATCHES: i64 = 24;

    /// A small recording in 8 kB chunks (several of them): a config file, then 24 batches
    /// of 50 samples, 50 ms apart from host time 1 s. Returns its bytes and what it holds.
    /// A chunk holds its channels' schemas, the whole protobuf descriptor (over 4 kB since
    /// issue 43): at 8 kB every chunk holds messages too.
    fn small_recording() -> (Vec<u8>, Vec<Recorded>) {
        small_recording_in(8192)
    }

    /// The same in chunks of `chunk_size_bytes`.
    fn small_recording_in(chunk_size_bytes: u64) -> (Vec<u8>, Vec<Recorded>) {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("r.mcap");
        let options = RecordOptions {
            compression: ChunkCompression::Zstd { level: 1 },
            chunk_size_bytes,
            ..RecordOptions::default()
        };
        let mut w = RecordWriter::create_with(&path, options).expect("create");
        w.write_config(1_000 * MS, "machine.toml", "kind = \"hammer\"\n").expect("config");
        for k in 0..BATCHES {
            w.write_samples(&SampleBatch {
                source: "daq0".into(),
                seq: k as u64,
                device_time_ns: k * 50 * MS,
                host_time_ns: 1_000 * MS + k * 50 * MS,
                period_ns: 1e6,
                roles: vec![Role::Load, Role::Disp, Role::Acc],
                values: (0..150).map(|i| ((k * 7919 + i * 104_729) % 10_007) as f64).collect(),
            })
            .expect("samples");
        }
        w.finish().expect("finish");
        let bytes = std::fs::read(&path).expect("read back");
        let intact = read_bytes(&bytes).expect("intact").0;
        assert_eq!(intact.len() as i64, BATCHES + 1);
        (bytes, intact)
    }

    /// Every message of `bytes` as a file, in file order, and the report.
    fn read_bytes(bytes: &[u8]) -> Result<(Vec<Recorded>, ReadReport), RecordError> {
        read_bytes_with(bytes, ReadMode::default())
    }

    fn read_bytes_with(bytes: &[u8], mode: ReadMode) -> Result<(Vec<Recorded>, ReadReport), RecordError> {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("x.mcap");
        std::fs::write(&path, bytes).expect("write");
        let mut reader = RecordReader::open_with(&path, mode)?;
        let messages = reader.by_ref().collect::<Result<Vec<_>, _>>()?;
        Ok((messages, reader.report().clone()))
    }

    /// The chunk index, by the `mcap` crate's own (non-sans-IO) summary reader.
    fn chunk_indexes(bytes: &[u8]) -> Vec<ChunkIndex> {
        let summary = mcap::Summary::read(bytes).expect("summary").expect("has one");
        let mut chunks = summary.chunk_indexes;
        chunks.sort_by_key(|c| c.chunk_start_offset);
        chunks
    }

    /// `got` is `all` with one non-empty run of messages taken out.
    fn is_all_but_one_run(got: &[Recorded], all: &[Recorded]) -> bool {
        let head = got.iter().zip(all).take_while(|(a, b)| a == b).count();
        let tail = got.iter().rev().zip(all.iter().rev()).take_while(|(a, b)| a == b).count();
        got.len() < all.len() && head + tail >= got.len()
    }

    /// Issue 42: the parallel read-ahead yields what the sequential read does, message for
    /// message, with the same report: intact, and with each chunk in turn corrupt, over
    /// several read-ahead batches (the report's paths differ only by the temp directory).
    #[test]
    fn the_parallel_read_yields_the_sequential_reads_messages_and_report() {
        let (bytes, intact) = small_recording_in(1024);
        let chunks = chunk_indexes(&bytes);
        // More chunks than the read-ahead holds: the thread waits for the reader.
        assert!(chunks.len() > READ_AHEAD_CHUNKS, "{} chunks", chunks.len());
        let mut files = vec![bytes.clone()];
        for c in &chunks {
            let mut bad = bytes.clone();
            bad[(c.compressed_data_offset().expect("offset") + c.compressed_size / 2) as usize] ^= 0x10;
            files.push(bad);
        }
        for (k, file) in files.iter().enumerate() {
            let (par, mut par_report) = read_bytes_with(file, ReadMode::Parallel).expect("parallel");
            let (seq, seq_report) = read_bytes_with(file, ReadMode::Sequential).expect("sequential");
            assert_eq!(par, seq, "file {k}: the messages");
            par_report.path.clone_from(&seq_report.path);
            assert_eq!(par_report, seq_report, "file {k}: the report");
            assert_eq!(par_report.corrupt_chunks.len(), usize::from(k > 0), "file {k}");
        }
        assert_eq!(read_bytes_with(&bytes, ReadMode::Parallel).expect("intact").0, intact);
    }

    #[test]
    fn a_flipped_bit_in_any_chunk_skips_that_chunk_only_and_names_it() {
        let (bytes, intact) = small_recording();
        let chunks = chunk_indexes(&bytes);
        assert!(chunks.len() >= 4, "{} chunks", chunks.len());
        for c in &chunks {
            let mut bad = bytes.clone();
            // Middle of the compressed data.
            let at = (c.compressed_data_offset().expect("offset") + c.compressed_size / 2) as usize;
            bad[at] ^= 0x10;
            let (got, report) = read_bytes(&bad).expect("reads");
            assert_eq!(report.corrupt_chunks.len(), 1, "{report:?}");
            let corrupt = &report.corrupt_chunks[0];
            assert_eq!((corrupt.offset, corrupt.length), (c.chunk_start_offset, c.chunk_length));
            assert!(!corrupt.topics.is_empty());
            assert!(corrupt.topics.iter().all(|t| t == "/config" || t == "/samples/daq0"), "{:?}", corrupt.topics);
            assert!(is_all_but_one_run(&got, &intact), "chunk at {}: the others read intact", c.chunk_start_offset);
            assert!(report.is_corrupt() && report.complete && report.indexed);
            assert_eq!(report.chunks_verified as usize, chunks.len() - 1);
            let line = &report.problems()[0];
            assert!(
                line.contains(&format!("chunk at byte {} is corrupt (crc mismatch", c.chunk_start_offset)),
                "{line}"
            );
        }
    }

    #[test]
    fn read_front_to_back_a_corrupt_chunk_is_skipped_and_named_by_its_message_index() {
        let (bytes, intact) = small_recording();
        let chunks = chunk_indexes(&bytes);
        // Cut the summary off: the reader goes front to back.
        let data_end = chunks.last().map(|c| c.chunk_start_offset + c.chunk_length).expect("chunks") as usize;
        let c = &chunks[2];
        let mut bad = bytes[..data_end + 40].to_vec();
        bad[(c.compressed_data_offset().expect("offset") + 3) as usize] ^= 0x01;
        let (got, report) = read_bytes(&bad).expect("reads");
        assert!(!report.indexed && !report.complete);
        assert_eq!(report.corrupt_chunks.len(), 1, "{report:?}");
        assert_eq!(report.corrupt_chunks[0].offset, c.chunk_start_offset);
        assert_eq!(report.corrupt_chunks[0].topics, vec!["/samples/daq0".to_string()]);
        assert!(is_all_but_one_run(&got, &intact));
    }

    #[test]
    fn a_damaged_chunk_length_read_front_to_back_resyncs_at_the_next_chunk() {
        let (bytes, intact) = small_recording();
        let chunks = chunk_indexes(&bytes);
        let data_end = chunks.last().map(|c| c.chunk_start_offset + c.chunk_length).expect("chunks") as usize;
        // A set bit cleared (the record ends early), and bits that make it run past the end
        // of the file (16 MiB) or past the record size limit (1 GiB).
        let lowest_set = |c: &ChunkIndex| (c.chunk_length - 9).trailing_zeros() as usize;
        for (bit, c) in [(lowest_set(&chunks[1]), &chunks[1]), (24, &chunks[2]), (30, &chunks[3])] {
            let mut bad = bytes[..data_end].to_vec();
            // The record length field, little-endian, after the opcode.
            let field = c.chunk_start_offset as usize + 1 + bit / 8;
            bad[field] ^= 1 << (bit % 8);
            let (got, report) = read_bytes(&bad).expect("reads");
            assert!(!report.corrupt_chunks.is_empty(), "bit {bit}: {report:?}");
            assert_eq!(report.corrupt_chunks[0].offset, c.chunk_start_offset, "{report:?}");
            assert!(is_all_but_one_run(&got, &intact), "bit {bit}: {report:?}");
            let kept_after = got.iter().filter(|m| m.log_time_ns as u64 > c.message_end_time).count();
            let after = intact.iter().filter(|m| m.log_time_ns as u64 > c.message_end_time).count();
            assert_eq!(kept_after, after, "bit {bit}: every later chunk is read");
        }
    }

    #[test]
    fn a_flipped_bit_outside_the_chunks_loses_nothing_or_is_named() {
        let (bytes, intact) = small_recording();
        let chunks = chunk_indexes(&bytes);
        let first = chunks[0].chunk_start_offset as usize;
        let data_end = chunks.last().map(|c| c.chunk_start_offset + c.chunk_length).expect("chunks") as usize;
        // The magic and header record, and everything after the last chunk: message
        // indexes, data end, summary, footer, closing magic. Every bit.
        for i in (0..first).chain(data_end..bytes.len()) {
            for bit in [0, 3, 6] {
                let mut bad = bytes.clone();
                bad[i] ^= 1 << bit;
                match read_bytes(&bad) {
                    Ok((got, report)) => {
                        assert_eq!(got, intact, "byte {i} bit {bit}: {report:?}");
                        assert!(report.corrupt_chunks.is_empty(), "byte {i} bit {bit}: {report:?}");
                        assert!(report.indexed || report.summary_error.is_some() || !report.complete);
                    }
                    Err(e) => assert!(i < 8 && matches!(e, RecordError::NotMcap { .. }), "byte {i}: {e}"),
                }
            }
        }
    }

    #[test]
    fn a_damaged_summary_falls_back_to_front_to_back_and_says_so() {
        let (mut bytes, intact) = small_recording();
        let chunks = chunk_indexes(&bytes);
        let data_end = chunks.last().map(|c| c.chunk_start_offset + c.chunk_length).expect("chunks") as usize;
        // A byte in the middle of the summary section.
        let at = data_end + (bytes.len() - data_end) * 3 / 4;
        bytes[at] ^= 0x04;
        let (got, report) = read_bytes(&bytes).expect("reads");
        assert_eq!(got, intact);
        assert!(!report.indexed, "{report:?}");
        let why = report.summary_error.as_deref().expect("named");
        assert!(report.problems().iter().any(|p| p.contains("summary is unusable") && p.contains(why)));
        assert!(report.is_corrupt());
    }

    /// The recording's own time range: host (log) times and device times.
    fn in_range(m: &Recorded) -> bool {
        let log_ok = (1_000 * MS..=1_000 * MS + BATCHES * 50 * MS).contains(&m.log_time_ns);
        match &m.payload {
            Payload::Samples(b) => {
                log_ok
                    && (0..BATCHES * 50 * MS).contains(&b.device_time_ns)
                    && b.values.iter().all(|v| v.is_finite())
                    && b.period_ns == 1e6
            }
            Payload::Config(ConfigFile { name, .. }) => log_ok && name == "machine.toml",
            _ => false,
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, rng_seed: proptest::test_runner::RngSeed::Fixed(0x5EED_F0E6), ..ProptestConfig::default() })]

        #[test]
        fn arbitrary_bytes_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..2000), magic in any::<bool>()) {
            let mut bytes = if magic { mcap::MAGIC.to_vec() } else { Vec::new() };
            bytes.extend_from_slice(&tail);
            // Any outcome but a panic (or a hang) will do: nothing in it is a recording.
            let _ = read_bytes(&bytes);
        }

        #[test]
        fn mutated_recordings_never_panic_and_give_only_what_was_written(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
            cut in any::<prop::sample::Index>(),
            truncate in any::<bool>(),
        ) {
            let (mut bytes, intact) = RECORDING.with(|r| r.clone());
            for (at, value) in &edits {
                let i = at.index(bytes.len());
                bytes[i] = *value;
            }
            if truncate {
                bytes.truncate(cut.index(bytes.len()));
            }
            if let Ok((got, report)) = read_bytes(&bytes) {
                for m in &got {
                    prop_assert!(in_range(m), "{m:?}");
                    prop_assert!(intact.contains(m), "a message that was never written: {m:?}");
                }
                prop_assert!(report.messages as usize == got.len());
            }
        }
    }

    thread_local! {
        static RECORDING: (Vec<u8>, Vec<Recorded>) = small_recording();
    }
}
