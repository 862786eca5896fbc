//! MCAP recording and reading (DESIGN.md §3, "MCAP layout" and "Crash safety"; issue #3).
//!
//! A recording holds, on separate channels, the raw sample batches of each source
//! (`/samples/<source>`), blow boundaries (`/blows`), blow results (`/results`), alerts
//! (`/alerts`), gaps and drops (`/gaps`), transport status (`/status`), one summary per
//! billet (`/billets`) and the configuration files (`/config`). Every message is protobuf (`proto/forgemon.proto`) and
//! every schema record carries the full FileDescriptorSet, so Foxglove and the `mcap`
//! tools open the files with nothing from us.
//!
//! - [`schema`]: the generated protobuf types, the embedded descriptor set, topics.
//! - [`message`]: the typed values a recording holds ([`Recorded`], [`Payload`]).
//! - [`codec`]: values to bytes and back (sans-IO).
//! - [`batch`]: joining/cutting sample batches to 10–100 ms (sans-IO).
//! - [`writer`]: chunked zstd MCAP, `.part` then rename, sync every second of log time,
//!   rotation.
//! - [`storage`]: the disk under a recording: space left, retention, and the outage a
//!   failed write starts (the recording is suspended, never ended).
//! - [`tap`]: each message as the writer encoded it, handed to a live consumer too.
//! - [`reader`]: indexed reading, and recovery of files cut off by a crash or damaged:
//!   every chunk's CRC is checked (`chunk`), a corrupt chunk is skipped and named in the
//!   [`report`]; the summary (`summary`) is checked against its CRC; a file without a
//!   usable one is read front to back, resynchronising after damaged records (`linear`);
//!   an indexed file's chunks are read ahead and unpacked in parallel (`indexed`).
//!
//! This is the one layer above the pure core that does file IO; nothing in `signal/`,
//! `estimate/` or `alert/` depends on it.

pub mod batch;
mod billets;
mod channels;
mod chunk;
pub mod codec;
pub mod error;
mod file;
mod indexed;
mod linear;
pub mod message;
pub mod options;
pub mod reader;
pub mod report;
pub mod rotation;
pub mod schema;
pub mod storage;
mod summary;
pub mod tap;
pub mod writer;

pub use batch::Rebatcher;
pub use error::{ChunkError, DecodeError, RecordError};
pub use message::{BlowBoundary, ConfigFile, Gap, Payload, Recorded, Status};
pub use reader::{RecordReader, Recording, read_recording};
pub use report::{CorruptChunk, ReadReport};
pub use schema::MessageKind;
pub use storage::{RecordingHealth, Retention};
pub use tap::{Tap, TappedMessage};
pub use writer::{ChunkCompression, RecordOptions, RecordWriter, Rotation, SyncPoint};
