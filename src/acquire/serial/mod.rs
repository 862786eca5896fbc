//! The serial DAQ transport (docs/interfaces.md §7, DESIGN.md §4): the binary COBS/CRC-32C
//! framing and the ASCII line variant, each a sans-IO decoder, plus the tokio driver that
//! opens the port, reconnects with backoff and reports status, gaps and counters.
//!
//! - `frame`: the binary frame codec and its decoder with resync.
//! - `tracker`: frames into samples; sequence jumps and device-time slips into gaps.
//! - `ascii`: the `t_s,v0,v1,...` line decoder.
//! - `stamps`: the time-stamp check of the ASCII lines (next sample, hole, restart, garbage).
//! - `driver`: the IO (tokio-serial, or any `AsyncRead` for tests and ptys).
//! - `identity`: which device a path opened, so that a reopen takes only the same one.

pub mod ascii;
pub mod driver;
pub mod frame;
pub mod identity;
pub mod stamps;
pub mod tracker;

pub use ascii::{AsciiEvent, LineDecoder, LineStats};
pub use driver::{
    HostClock, SerialConfig, SerialFormat, SerialSource, StreamEnd, open_port, run, run_on_stream, run_with,
    system_clock_ns,
};
pub use frame::{DecoderStats, Frame, FrameDecoder, FrameError, encode_frame};
pub use tracker::{FrameTracker, TrackError, TrackStats, Tracked};
