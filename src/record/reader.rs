//! Reading a recording back as typed messages, from a finished file (through its summary
//! and chunk index) or from one cut off by a crash or power loss (no footer, maybe half a
//! chunk at the end), and saying how much was recovered.
//!
//! A cut-off file is read front to back with the `mcap` crate's sans-IO message reader,
//! each chunk checked against its CRC before any of its messages is yielded, so exactly
//! the messages of the chunks written completely before the cut come back; reading stops
//! at the first record that is incomplete or corrupt, and [`ReadReport`] says where and
//! why. Both paths yield messages in file order, which is the order they were recorded;
//! [`read_recording`] sorts them by log time.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mcap::sans_io::{
    IndexedReadEvent, IndexedReader, IndexedReaderOptions, LinearReaderOptions, MessageReadEvent, MessageReader,
    SummaryReadEvent, SummaryReader, SummaryReaderOptions,
};

use super::codec;
use super::error::RecordError;
use super::message::Recorded;
use super::schema::{MESSAGE_ENCODING, MessageKind, SCHEMA_ENCODING};

/// The largest record (chunk, compressed or not) the reader accepts. forgemon's chunks are
/// about 1 MiB; the limit keeps a corrupt length from allocating gigabytes.
pub const MAX_RECORD_BYTES: usize = 256 * 1024 * 1024;

/// How much of a file was read, and whether it was whole.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadReport {
    pub path: PathBuf,
    /// The file has its summary and footer: it was finished properly.
    pub complete: bool,
    /// Read through the summary's chunk index (else front to back).
    pub indexed: bool,
    /// Messages yielded.
    pub messages: u64,
    /// Messages on channels that are not forgemon's (other schemas), passed over.
    pub skipped: u64,
    /// Bytes from the start of the file through the last chunk recovered (approximately:
    /// read-ahead inside the cut chunk is not counted).
    pub bytes_recovered: u64,
    pub total_bytes: u64,
    /// Why reading stopped before the end, for a cut-off or corrupt file.
    pub stopped_by: Option<String>,
}

impl std::fmt::Display for ReadReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} messages, {} of {} bytes{}",
            self.path.display(),
            self.messages,
            self.bytes_recovered,
            self.total_bytes,
            if self.complete { String::new() } else { ", file was cut off".to_string() }
        )?;
        if let Some(why) = &self.stopped_by {
            write!(f, " ({why})")?;
        }
        Ok(())
    }
}

/// A whole recording in memory, in log-time order (ties in file order).
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub messages: Vec<Recorded>,
    pub report: ReadReport,
}

/// Read a whole recording (`.mcap` or `.mcap.part`) into memory, sorted by log time.
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
/// message, [`RecordReader::report`] says how much was read.
pub struct RecordReader {
    path: PathBuf,
    mode: Mode,
    report: ReadReport,
    /// What each channel id holds: its kind and topic, or `None` for foreign channels.
    channels: HashMap<u16, Option<(MessageKind, String)>>,
    done: bool,
}

enum Mode {
    Indexed { file: File, summary: Box<mcap::Summary>, reader: Box<IndexedReader>, chunk: Vec<u8> },
    Linear { file: BufReader<File>, reader: Box<MessageReader>, fed: u64 },
}

impl RecordReader {
    /// Open a recording. Fails when the file cannot be read or is not MCAP at all; a
    /// cut-off file opens, and yields what it holds.
    pub fn open(path: impl AsRef<Path>) -> Result<RecordReader, RecordError> {
        let path = path.as_ref().to_path_buf();
        let io_err = |action: &'static str| {
            let path = path.clone();
            move |source| RecordError::Io { path, action, source }
        };
        let mut file = File::open(&path).map_err(io_err("open"))?;
        let total_bytes = file.metadata().map_err(io_err("stat"))?.len();
        check_magic(&path, &mut file, total_bytes)?;

        let indexed = match read_summary(&mut file, total_bytes) {
            Some(summary) if is_indexed(&summary) => {
                let options = IndexedReaderOptions::new()
                    .with_order(mcap::sans_io::indexed_reader::ReadOrder::File)
                    .with_record_length_limit(MAX_RECORD_BYTES);
                IndexedReader::new_with_options(&summary, options).ok().map(|r| (summary, r))
            }
            _ => None,
        };
        let is_indexed = indexed.is_some();
        let mode = match indexed {
            Some((summary, reader)) => {
                Mode::Indexed { file, summary: Box::new(summary), reader: Box::new(reader), chunk: Vec::new() }
            }
            None => {
                file.seek(SeekFrom::Start(0)).map_err(io_err("seek"))?;
                let options = LinearReaderOptions::default()
                    .with_prevalidate_chunk_crcs(true)
                    .with_record_length_limit(MAX_RECORD_BYTES);
                Mode::Linear {
                    file: BufReader::with_capacity(256 * 1024, file),
                    reader: Box::new(MessageReader::new_with_options(options)),
                    fed: 0,
                }
            }
        };
        let report = ReadReport {
            path: path.clone(),
            complete: is_indexed,
            indexed: is_indexed,
            messages: 0,
            skipped: 0,
            bytes_recovered: 0,
            total_bytes,
            stopped_by: None,
        };
        Ok(RecordReader { path, mode, report, channels: HashMap::new(), done: false })
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
            let (log_time, decoded) = match &mut self.mode {
                Mode::Indexed { file, summary, reader, chunk } => {
                    let Some(event) = reader.next_event() else {
                        self.report.bytes_recovered = self.report.total_bytes;
                        return Ok(None);
                    };
                    match event.map_err(|source| RecordError::Mcap { path: self.path.clone(), offset: None, source })? {
                        IndexedReadEvent::ReadChunkRequest { offset, length } => {
                            let io_err = |source| RecordError::Io { path: self.path.clone(), action: "read", source };
                            chunk.resize(length, 0);
                            file.seek(SeekFrom::Start(offset)).map_err(io_err)?;
                            file.read_exact(chunk).map_err(|source| RecordError::Io {
                                path: self.path.clone(),
                                action: "read",
                                source,
                            })?;
                            reader.insert_chunk_record_data(offset, chunk).map_err(|source| RecordError::Mcap {
                                path: self.path.clone(),
                                offset: Some(offset),
                                source,
                            })?;
                            continue;
                        }
                        IndexedReadEvent::Message { header, data } => {
                            let kind = channel_kind(&mut self.channels, header.channel_id, || {
                                summary.channels.get(&header.channel_id).map(|c| c.as_ref().clone())
                            });
                            let decoded = kind.map(|(kind, topic)| (topic, codec::decode_payload(kind, data)));
                            (header.log_time, decoded)
                        }
                    }
                }
                Mode::Linear { file, reader, fed } => {
                    let Some(event) = reader.next_event() else {
                        // The end magic was read: the file is whole even without an index.
                        self.report.complete = true;
                        self.report.bytes_recovered = *fed;
                        return Ok(None);
                    };
                    match event {
                        Ok(MessageReadEvent::ReadRequest(need)) => {
                            let buf = reader.insert(need);
                            let n = loop {
                                match file.read(buf) {
                                    Ok(n) => break n,
                                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                                    Err(source) => {
                                        return Err(RecordError::Io {
                                            path: self.path.clone(),
                                            action: "read",
                                            source,
                                        });
                                    }
                                }
                            };
                            reader.notify_read(n);
                            *fed += n as u64;
                            continue;
                        }
                        Ok(MessageReadEvent::Message(message)) => {
                            let id = message.channel.id;
                            let kind = channel_kind(&mut self.channels, id, || Some(message.channel.as_ref().clone()));
                            let decoded = kind.map(|(kind, topic)| (topic, codec::decode_payload(kind, &message.data)));
                            self.report.bytes_recovered = *fed;
                            (message.log_time, decoded)
                        }
                        Err(e) => {
                            // A cut-off or corrupt file: keep what came before.
                            self.report.stopped_by = Some(describe_stop(&e, *fed, self.report.total_bytes));
                            return Ok(None);
                        }
                    }
                }
            };
            let Some((topic, decoded)) = decoded else {
                self.report.skipped += 1;
                continue;
            };
            let payload = decoded.map_err(|source| RecordError::Decode {
                path: self.path.clone(),
                topic: topic.clone(),
                log_time_ns: log_time,
                source,
            })?;
            let log_time_ns = i64::try_from(log_time).map_err(|_| RecordError::LogTimeOutOfRange {
                path: self.path.clone(),
                topic,
                log_time_ns: log_time,
            })?;
            self.report.messages += 1;
            return Ok(Some(Recorded { log_time_ns, payload }));
        }
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

/// The kind and topic of a channel, looked up once per channel id.
fn channel_kind(
    cache: &mut HashMap<u16, Option<(MessageKind, String)>>,
    id: u16,
    channel: impl FnOnce() -> Option<mcap::Channel<'static>>,
) -> Option<(MessageKind, String)> {
    cache
        .entry(id)
        .or_insert_with(|| {
            let channel = channel()?;
            if channel.message_encoding != MESSAGE_ENCODING {
                return None;
            }
            let schema = channel.schema.as_ref()?;
            if schema.encoding != SCHEMA_ENCODING {
                return None;
            }
            MessageKind::from_schema_name(&schema.name).map(|k| (k, channel.topic.clone()))
        })
        .clone()
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

/// The summary section, if the file has a valid footer and summary.
fn read_summary(file: &mut File, total_bytes: u64) -> Option<mcap::Summary> {
    let options =
        SummaryReaderOptions::default().with_file_size(total_bytes).with_record_length_limit(MAX_RECORD_BYTES);
    let mut reader = SummaryReader::new_with_options(options);
    while let Some(event) = reader.next_event() {
        match event.ok()? {
            SummaryReadEvent::ReadRequest(need) => {
                let n = file.read(reader.insert(need)).ok()?;
                reader.notify_read(n);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let pos = file.seek(to).ok()?;
                reader.notify_seeked(pos);
            }
        }
    }
    reader.finish()
}

/// A summary the indexed reader can use: every message is in an indexed chunk.
fn is_indexed(summary: &mcap::Summary) -> bool {
    let messages = summary.stats.as_ref().map_or(0, |s| s.message_count);
    !summary.chunk_indexes.is_empty() || messages == 0
}

fn describe_stop(e: &mcap::McapError, fed: u64, total: u64) -> String {
    match e {
        mcap::McapError::UnexpectedEof => format!("the file ends inside a record (read {fed} of {total} bytes)"),
        other => format!("{other} (near byte {fed} of {total})"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stop_descriptions_name_the_offset() {
        let s = describe_stop(&mcap::McapError::UnexpectedEof, 10, 20);
        assert!(s.contains("10 of 20"), "{s}");
        let s = describe_stop(&mcap::McapError::BadMagic, 3, 20);
        assert!(s.contains("near byte 3"), "{s}");
    }
}
