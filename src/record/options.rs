//! How a recording is written: its options (compression, chunk size, sync interval,
//! rotation) and the sync point a crash keeps. Shared by
//! the writer, the open file and the rotation, which all read it; it reads only the rotation's limits.

use super::rotation::Rotation;

/// Close the chunk and `sync_data` after this much log time (DESIGN.md §3: "at least every
/// second").
pub const DEFAULT_SYNC_INTERVAL_NS: u64 = 1_000_000_000;
/// Target uncompressed chunk size. A chunk also closes at every sync.
pub const DEFAULT_CHUNK_SIZE_BYTES: u64 = 1024 * 1024;
/// zstd level: 1 is the fastest standard level; sample doubles barely compress at any level.
pub const DEFAULT_ZSTD_LEVEL: u32 = 1;

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkCompression {
    Zstd { level: u32 },
    Lz4,
    None,
}

/// How to record. [`RecordOptions::default`] is zstd, 1 MiB chunks, sync every second of
/// log time, no rotation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordOptions {
    pub rotation: Rotation,
    pub compression: ChunkCompression,
    pub chunk_size_bytes: u64,
    pub sync_interval_ns: u64,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            rotation: Rotation::NEVER,
            compression: ChunkCompression::Zstd { level: DEFAULT_ZSTD_LEVEL },
            chunk_size_bytes: DEFAULT_CHUNK_SIZE_BYTES,
            sync_interval_ns: DEFAULT_SYNC_INTERVAL_NS,
        }
    }
}

/// The state of the current file at its last `sync_data`: everything up to `file_bytes`
/// survives a crash, and holds `file_messages` messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncPoint {
    pub file_bytes: u64,
    pub file_messages: u64,
    pub log_time_ns: u64,
}
