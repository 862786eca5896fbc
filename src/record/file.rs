//! One MCAP file being written: its `.part` file, the length the rotation reads, its
//! schemas and channels, and the sync, finish and rename that make it durable.

use std::collections::{BTreeMap, HashMap};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use mcap::records::MessageHeader;

use super::error::RecordError;
use super::options::{ChunkCompression, RecordOptions, SyncPoint};
use super::rotation::{Rotation, part_path_of};
use super::schema::{FILE_DESCRIPTOR_SET, MESSAGE_ENCODING, MessageKind, SCHEMA_ENCODING, samples_topic};

/// A `File` behind a `BufWriter` that counts the file's length, shared with the writer so
/// it can rotate by size (the `mcap` writer owns the stream and hides it).
struct CountingFile {
    inner: BufWriter<File>,
    pos: u64,
    len: Arc<AtomicU64>,
}

impl Write for CountingFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.pos += n as u64;
        self.len.fetch_max(self.pos, Ordering::Relaxed);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl Seek for CountingFile {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.pos = self.inner.seek(to)?;
        Ok(self.pos)
    }

    fn stream_position(&mut self) -> std::io::Result<u64> {
        Ok(self.pos)
    }
}

/// Per-channel bookkeeping inside one file.
struct ChannelSlot {
    id: u16,
    sequence: u32,
}

/// One file being written.
pub(super) struct OpenFile {
    final_path: PathBuf,
    pub(super) part_path: PathBuf,
    mcap: mcap::Writer<CountingFile>,
    /// A second handle on the same open file, for `sync_data`.
    sync_handle: File,
    bytes: Arc<AtomicU64>,
    schemas: [Option<u16>; MessageKind::ALL.len()],
    fixed_channels: [Option<ChannelSlot>; MessageKind::ALL.len()],
    sample_channels: HashMap<String, ChannelSlot>,
    first_log_time: Option<u64>,
    /// The newest log time written: a sync covers everything up to it.
    max_log_time: u64,
    pub(super) last_sync_log_time: u64,
    messages: u64,
    /// Messages other than the configuration files every file starts with.
    data_messages: u64,
    /// Blow results among them.
    results: u64,
    pub(super) last_sync: Option<SyncPoint>,
    /// `(data_messages, results)` at the last sync: what a given-up file keeps.
    synced: (u64, u64),
}

/// What giving a file up (`OpenFile::abandon`) kept and lost.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Abandoned {
    /// The `.part` kept, cut at its last sync; `None` when it held no data then (removed).
    pub(super) kept: Option<PathBuf>,
    /// Messages (configuration files aside) and blow results written after the last sync.
    pub(super) lost_messages: u64,
    pub(super) lost_results: u64,
}

impl OpenFile {
    /// The `.part` file of `final_path`, created with its header on disk; on failure nothing
    /// is left behind (a full disk fails here, and must not leave an empty file per try).
    pub(super) fn create(final_path: PathBuf, options: &RecordOptions) -> Result<OpenFile, RecordError> {
        let part_path = part_path_of(&final_path);
        OpenFile::create_at(final_path, part_path.clone(), options).inspect_err(|_| {
            let _ = std::fs::remove_file(&part_path);
        })
    }

    fn create_at(final_path: PathBuf, part_path: PathBuf, options: &RecordOptions) -> Result<OpenFile, RecordError> {
        let io_err = |action: &'static str| {
            let path = part_path.clone();
            move |source| RecordError::Io { path, action, source }
        };
        let file =
            OpenOptions::new().write(true).create(true).truncate(true).open(&part_path).map_err(io_err("create"))?;
        let sync_handle = file.try_clone().map_err(io_err("open a second handle on"))?;
        let bytes = Arc::new(AtomicU64::new(0));
        let sink = CountingFile { inner: BufWriter::with_capacity(256 * 1024, file), pos: 0, len: bytes.clone() };
        let (compression, level) = match options.compression {
            ChunkCompression::Zstd { level } => (Some(mcap::Compression::Zstd), level),
            ChunkCompression::Lz4 => (Some(mcap::Compression::Lz4), 0),
            ChunkCompression::None => (None, 0),
        };
        let mcap = mcap::WriteOptions::new()
            .profile("")
            .library(concat!("forgemon/", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .compression_level(level)
            .compression_threads(0)
            .chunk_size(Some(options.chunk_size_bytes))
            .create(sink)
            .map_err(|source| RecordError::Mcap { path: part_path.clone(), offset: None, source })?;
        let mut file = OpenFile {
            final_path,
            part_path,
            mcap,
            sync_handle,
            bytes,
            schemas: [None; MessageKind::ALL.len()],
            fixed_channels: Default::default(),
            sample_channels: HashMap::new(),
            first_log_time: None,
            max_log_time: 0,
            last_sync_log_time: 0,
            messages: 0,
            data_messages: 0,
            results: 0,
            last_sync: None,
            synced: (0, 0),
        };
        // Magic and header on disk from the start: a crash before the first sync leaves
        // an empty recording, not an empty file.
        file.flush_to_disk()?;
        if let Some(dir) = file.part_path.parent() {
            sync_dir(dir);
        }
        Ok(file)
    }

    /// Bytes written so far.
    pub(super) fn bytes(&self) -> u64 {
        self.bytes.load(Ordering::Relaxed)
    }

    fn mcap_err(&self, source: mcap::McapError) -> RecordError {
        RecordError::Mcap { path: self.part_path.clone(), offset: Some(self.bytes.load(Ordering::Relaxed)), source }
    }

    pub(super) fn rotation_due(&self, rotation: &Rotation, log_time: u64) -> bool {
        let Some(first) = self.first_log_time else { return false };
        rotation.max_bytes.is_some_and(|max| self.bytes.load(Ordering::Relaxed) >= max)
            || rotation.max_duration_ns.is_some_and(|max| log_time.saturating_sub(first) >= max)
    }

    fn channel_id(&mut self, kind: MessageKind, source: Option<&str>) -> Result<(u16, u32), RecordError> {
        let existing = match source {
            Some(s) => self.sample_channels.get_mut(s),
            None => self.fixed_channels[kind.index()].as_mut(),
        };
        if let Some(slot) = existing {
            let seq = slot.sequence;
            slot.sequence = slot.sequence.wrapping_add(1);
            return Ok((slot.id, seq));
        }
        let schema_id = match self.schemas[kind.index()] {
            Some(id) => id,
            None => {
                let id = self
                    .mcap
                    .add_schema(kind.schema_name(), SCHEMA_ENCODING, FILE_DESCRIPTOR_SET)
                    .map_err(|e| self.mcap_err(e))?;
                self.schemas[kind.index()] = Some(id);
                id
            }
        };
        let topic = match source {
            Some(s) => samples_topic(s),
            None => kind.fixed_topic().unwrap_or_default().to_string(),
        };
        let id = self
            .mcap
            .add_channel(schema_id, &topic, MESSAGE_ENCODING, &BTreeMap::new())
            .map_err(|e| self.mcap_err(e))?;
        let slot = ChannelSlot { id, sequence: 1 };
        match source {
            Some(s) => {
                self.sample_channels.insert(s.to_string(), slot);
            }
            None => self.fixed_channels[kind.index()] = Some(slot),
        }
        Ok((id, 0))
    }

    pub(super) fn write(
        &mut self,
        kind: MessageKind,
        source: Option<&str>,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), RecordError> {
        // Counted before the write: a message whose write fails is among the unsynced ones
        // `abandon` reports lost.
        self.data_messages += u64::from(kind != MessageKind::Config);
        self.results += u64::from(kind == MessageKind::Result);
        let (channel_id, sequence) = self.channel_id(kind, source)?;
        let header = MessageHeader { channel_id, sequence, log_time, publish_time };
        self.mcap.write_to_known_channel(&header, data).map_err(|e| self.mcap_err(e))?;
        if self.first_log_time.is_none() {
            self.first_log_time = Some(log_time);
            self.last_sync_log_time = log_time;
        }
        self.max_log_time = self.max_log_time.max(log_time);
        self.messages += 1;
        Ok(())
    }

    /// Everything written so far onto the disk: the MCAP writer's buffer, then the file's data.
    fn flush_to_disk(&mut self) -> Result<(), RecordError> {
        self.mcap.flush().map_err(|e| self.mcap_err(e))?;
        self.sync_handle.sync_data().map_err(|source| RecordError::Io {
            path: self.part_path.clone(),
            action: "sync",
            source,
        })
    }

    pub(super) fn flush_and_sync(&mut self) -> Result<(), RecordError> {
        self.flush_to_disk()?;
        let log_time = self.max_log_time;
        self.last_sync_log_time = log_time;
        self.last_sync = Some(SyncPoint {
            file_bytes: self.bytes.load(Ordering::Relaxed),
            file_messages: self.messages,
            log_time_ns: log_time,
        });
        self.synced = (self.data_messages, self.results);
        Ok(())
    }

    /// Summary, footer, flush, sync, rename to the final name, sync the directory.
    pub(super) fn finish(mut self) -> Result<PathBuf, RecordError> {
        self.mcap.finish().map_err(|e| self.mcap_err(e))?;
        let OpenFile { mcap, final_path, part_path, sync_handle, .. } = self;
        let mut sink = mcap.into_inner();
        sink.flush().map_err(|source| RecordError::Io { path: part_path.clone(), action: "write", source })?;
        sync_handle.sync_data().map_err(|source| RecordError::Io {
            path: part_path.clone(),
            action: "sync",
            source,
        })?;
        drop(sink);
        std::fs::rename(&part_path, &final_path).map_err(|source| RecordError::Io {
            path: part_path.clone(),
            action: "rename",
            source,
        })?;
        if let Some(dir) = final_path.parent() {
            sync_dir(dir);
        }
        Ok(final_path)
    }
}

impl OpenFile {
    /// Give the file up after a failed write. It is cut back to its last sync, which ends
    /// at a whole chunk, so what it keeps is exactly what was synced and what it loses is
    /// counted. It stays a `.part` (read like a crash's) when it keeps data, and is removed
    /// when it does not.
    pub(super) fn abandon(self) -> Abandoned {
        let OpenFile { mcap, part_path, sync_handle, data_messages, results, last_sync, synced, .. } = self;
        // The `mcap` writer tries to finish the file when dropped; after a failed write it
        // refuses, and whatever it adds is cut off below.
        drop(mcap);
        let lost = Abandoned { kept: None, lost_messages: data_messages - synced.0, lost_results: results - synced.1 };
        let cut = last_sync.map(|s| s.file_bytes).filter(|_| synced.0 > 0);
        match cut.map(|len| sync_handle.set_len(len).and_then(|()| sync_handle.sync_data())) {
            Some(Ok(())) => Abandoned { kept: Some(part_path), ..lost },
            // Uncut, the reader still finds the synced chunks and skips a torn tail.
            Some(Err(_)) => Abandoned { kept: Some(part_path), ..lost },
            None => {
                let _ = std::fs::remove_file(&part_path);
                lost
            }
        }
    }
}

/// Make a create or rename durable. Best effort: not every platform can open a directory.
fn sync_dir(dir: &Path) {
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}
