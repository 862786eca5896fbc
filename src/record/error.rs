//! What can go wrong recording or reading an MCAP file. Every error that concerns a file
//! names it, and where it helps, the byte offset, topic or log time.

use std::path::PathBuf;

/// A payload that is not a valid forgemon message (sans-IO: no file, no offset; the
/// reader reports it as [`ChunkError::Payload`], in a [`super::CorruptChunk`] with both).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("not a valid protobuf message: {0}")]
    Protobuf(#[from] prost::DecodeError),
    #[error("malformed protobuf: {what}")]
    Wire { what: String },
    #[error("unknown sample role value {value}")]
    UnknownRole { value: i32 },
    #[error("{values} sample values do not fill whole samples of {channels} channels")]
    RaggedBatch { values: usize, channels: usize },
    #[error("unknown blow class {class:?} (expected soft, intermediate or hard)")]
    UnknownClass { class: String },
    #[error("unknown alert kind {kind:?} (expected elastic_blow or model_health)")]
    UnknownAlertKind { kind: String },
}

/// Why one chunk of a recording could not be used (sans-IO: the reader adds the file and
/// the byte offset in [`super::CorruptChunk`]). The chunk is skipped and the rest is read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChunkError {
    #[error("crc mismatch: stored {saved:#010x}, computed {calculated:#010x}")]
    Crc { saved: u32, calculated: u32 },
    /// Anything else the `mcap` crate's reader refused (bad compression, sizes that do not
    /// add up, a record running past the chunk's end, ...), in its words.
    #[error("{what}")]
    Mcap { what: String },
    #[error("not a chunk record (opcode {opcode:#04x})")]
    NotChunk { opcode: u8 },
    #[error("the record ends after {have} bytes, inside its header")]
    Truncated { have: u64 },
    #[error("its length field says {field} bytes, but {actual} follow")]
    Length { field: u64, actual: u64 },
    #[error("it claims {bytes} bytes, over the {limit}-byte limit")]
    TooLarge { bytes: u64, limit: u64 },
    #[error("the index puts it at bytes {start}..{end}, past the end of the {total}-byte file")]
    OutsideFile { start: u64, end: u64, total: u64 },
    #[error("message on {topic} at log time {log_time_ns} ns: {source}")]
    Payload {
        topic: String,
        log_time_ns: u64,
        #[source]
        source: DecodeError,
    },
    #[error("message on {topic} has log time {log_time_ns} ns, which is out of range")]
    LogTime { topic: String, log_time_ns: u64 },
    /// Front-to-back reading lost the record boundaries here (a damaged length field) and
    /// found the next intact chunk further on.
    #[error("unreadable records ({reason}), read on from the next intact chunk")]
    Framing { reason: String },
    /// As [`ChunkError::Framing`], with no intact chunk after it: the rest of the file.
    #[error("unreadable records to the end of the file ({reason})")]
    Tail { reason: String },
}

/// An error recording or reading a recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{path}: cannot {action}: {source}", path = path.display())]
    Io {
        path: PathBuf,
        /// What was being done: "create", "write", "sync", "rename", "open", "read", ...
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not an MCAP recording: {reason}", path = path.display())]
    NotMcap { path: PathBuf, reason: String },
    #[error("{path}: MCAP error{at}: {source}", path = path.display(),
        at = offset.map(|o| format!(" at byte {o}")).unwrap_or_default())]
    Mcap {
        path: PathBuf,
        offset: Option<u64>,
        #[source]
        source: mcap::McapError,
    },
    #[error("{path}: cannot record on {topic}: log time {time_ns} ns is negative (MCAP times are unsigned)",
        path = path.display())]
    NegativeLogTime { path: PathBuf, topic: String, time_ns: i64 },
    #[error("{path}: cannot record a sample batch from {source_name:?}: {reason}", path = path.display())]
    BadBatch { path: PathBuf, source_name: String, reason: DecodeError },
    #[error("{path}: recording target must be a .mcap file or a directory", path = path.display())]
    BadTarget { path: PathBuf },
    /// The recording is suspended after a failed write (`storage.rs`); the message was
    /// dropped and counted.
    #[error("{dir}: recording suspended, message dropped ({reason})", dir = dir.display())]
    Suspended { dir: PathBuf, reason: String },
}
