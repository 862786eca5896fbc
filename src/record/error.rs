//! What can go wrong recording or reading an MCAP file. Every error that concerns a file
//! names it, and where it helps, the byte offset, topic or log time.

use std::path::PathBuf;

/// A payload that is not a valid forgemon message (sans-IO: no file, no offset; the
/// reader wraps it in [`RecordError::Decode`] with both).
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
    #[error("{path}: message on {topic} at log time {log_time_ns} ns: {source}", path = path.display())]
    Decode {
        path: PathBuf,
        topic: String,
        log_time_ns: u64,
        #[source]
        source: DecodeError,
    },
    #[error("{path}: message on {topic} has log time {log_time_ns} ns, which is out of range",
        path = path.display())]
    LogTimeOutOfRange { path: PathBuf, topic: String, log_time_ns: u64 },
    #[error("{path}: cannot record on {topic}: log time {time_ns} ns is negative (MCAP times are unsigned)",
        path = path.display())]
    NegativeLogTime { path: PathBuf, topic: String, time_ns: i64 },
    #[error("{path}: cannot record a sample batch from {source_name:?}: {reason}", path = path.display())]
    BadBatch { path: PathBuf, source_name: String, reason: DecodeError },
    #[error("{path}: recording target must be a .mcap file or a directory", path = path.display())]
    BadTarget { path: PathBuf },
}
