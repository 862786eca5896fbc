//! CAN transport (DESIGN.md §4, issue #4): signals mapped from a DBC file or from the
//! config, a sans-IO [`CanDecoder`] fed timestamped frames, `candump -L` logs as a source
//! (and written by the simulated device), and a live SocketCAN driver.
//!
//! Files: `signal` (bit layouts, the mapping), `dbc` (a mapping from a DBC file),
//! `config` (the `[[sources]]` table of kind `can`), `decoder` (frames to batches and
//! gaps), `candump` (the log format, read and written, classic and CAN FD lines), `device` (the simulated DAQ's
//! encoder), `live` (the SocketCAN driver [`run`]) and `log_source` (a log replayed as a
//! source, [`run_log`]).
//!
//! # The frame convention of forgemon's simulated DAQ
//!
//! One classic CAN data frame per sample, standard identifier `0x120` ("ForgeSample"),
//! DLC 8, every field Intel (little-endian), described by `fixtures/can/hammer.dbc`:
//!
//! | bits   | signal    | type | factor       | range            | resolution |
//! |--------|-----------|------|--------------|------------------|------------|
//! | 0..8   | `Seq`     | u8   | 1            | 0..255, wraps    | +1 a frame |
//! | 8..24  | `Load`    | i16  | 100 N        | ±3.2767 MN       | 100 N      |
//! | 24..40 | `Acc`     | i16  | 0.25 m/s²    | ±8191.75 m/s²    | 0.25 m/s²  |
//! | 40..64 | `Disp`    | i24  | 1 µm         | ±8.388607 m      | 1 µm       |
//!
//! The resolutions sit well under the sensors' noise (load 2 kN, acceleration 2 m/s²) and
//! the encoder's 10 µm step. The frame carries no time: the sample clock is the
//! configured rate, anchored at the first frame's receive time, and the counter numbers
//! the samples, so a jump of the counter is a gap of (jump − 1) samples (with trusted
//! receive times, whole wraps of the counter are counted too). Bus load: such a frame is
//! at most 135 bits with stuffing, so 5 kHz takes about 68 % of a 1 Mbit/s bus; the
//! fixture runs at 5 kHz for that reason.
//!
//! # The CAN FD block (50 kHz)
//!
//! One CAN FD frame (`##` in candump) per 8 consecutive samples, standard identifier
//! `0x121` ("ForgeBlock"), 64 bytes, bit rate switch on, every field Intel, described by
//! `config/hammer-canfd.dbc`:
//!
//! | bytes          | signal            | type | factor, as above |
//! |----------------|-------------------|------|------------------|
//! | 0..4           | `Seq`             | u32  | the index of the block's first sample, +8 a frame |
//! | 4..8           | reserved, zero    |      |                  |
//! | 8+7k .. 10+7k  | `Load_k`          | i16  | 100 N            |
//! | 10+7k .. 12+7k | `Acc_k`           | i16  | 0.25 m/s²        |
//! | 12+7k .. 15+7k | `Disp_k`          | i24  | 1 µm             |
//!
//! for samples k = 0..8, sample 0 the oldest. The frame is sent once its last sample is
//! taken, so its receive time belongs to sample 7 and sample k lies (7 − k) periods
//! before it. The counter counts samples: from one frame to the next it advances by 8, a
//! lost frame is a jump of 16 and a gap of exactly 8 samples (never stretched over).
//! This is the layout block-mode DAQs use (a header with a sample counter, then the
//! samples in order); a DBC multiplexer would not do, as it selects one set of signals per
//! frame, that is one sample per frame. Bus load at 50 kHz: 6250 frames/s of about
//! 29 arbitration bits at 1 Mbit/s and about 600 data-phase bits (64 bytes, CRC-21,
//! stuff bits) at 8 Mbit/s, about 105 µs a frame, 66 % of the bus; at a 5 Mbit/s data
//! phase it would be over 90 %, at 2 Mbit/s it does not fit.
//!
//! Any other layout works through a DBC file or explicit [`CanSignalSpec`]s: one signal
//! per role, optionally a sequence counter; the counter's frame (or else the first
//! signal's) completes each sample and the values of other frames are held.
//!
//! # What is counted, not fatal
//!
//! Frames with identifiers the mapping does not read (`CanStats::unknown_frames`),
//! remote and error frames and data frames of the other kind, FD on a classic mapping
//! or classic on an FD one (`unsupported_frames`), frames too short for their
//! signals (`Counters::decode_errors`), repeated counters (`duplicates`). A malformed
//! line in a candump log is an error naming the file and line; the reader can continue
//! past it (see [`candump`]).

pub mod candump;
pub mod config;
pub mod dbc;
pub mod decoder;
pub mod device;
pub mod live;
pub mod log_source;
pub mod signal;

pub use candump::{
    BadLines, CandumpReader, LogFrame, LoggedFrame, read_candump, write_candump_fd_line, write_candump_line,
};
pub use config::{CanInput, CanSignals, CanSourceSpec, MAX_SAMPLES_PER_FRAME};
pub use dbc::{DbcNames, block_mapping_from_dbc, mapping_from_dbc};
pub use decoder::{CanDecoder, CanStats, CanTiming};
pub use device::CanDevice;
pub use live::{CanSourceConfig, run};
pub use log_source::run_log;
pub use signal::{ByteOrder, CanMapping, CanSignalSpec, FrameId, SignalLayout};

use crate::signal::sample::Role;

/// The simulated DAQ's sample frame.
pub const SAMPLE_FRAME: FrameId = FrameId::standard(0x120);
/// Its payload length.
pub const SAMPLE_FRAME_DLC: usize = 8;
/// Load resolution, N per count.
pub const LOAD_N_PER_COUNT: f64 = 100.0;
/// Acceleration resolution, m/s² per count.
pub const ACC_MPS2_PER_COUNT: f64 = 0.25;
/// Displacement resolution, m per count.
pub const DISP_M_PER_COUNT: f64 = 1e-6;
/// The simulated DAQ's CAN FD block frame (module docs).
pub const BLOCK_FRAME: FrameId = FrameId::standard(0x121);
/// Samples per block frame.
pub const BLOCK_SAMPLES: usize = 8;
/// The FD flags the simulated DAQ sends with (bit rate switch).
pub const BLOCK_FD_FLAGS: u8 = 0x1;
/// The interface name written in simulated logs.
pub const DEFAULT_IFACE: &str = "can0";

/// What can go wrong building a mapping or reading a log.
#[derive(Debug, thiserror::Error)]
pub enum CanError {
    #[error("CAN signal '{signal}': {why}")]
    BadSignal { signal: String, why: String },
    #[error("{origin}: not a valid DBC file: {message}")]
    Dbc { origin: String, message: String },
    #[error("{origin}: {why}")]
    DbcSignal { origin: String, why: String },
    #[error("{origin}:{line}: not a candump -L line ({why}): {text:?}")]
    LogLine { origin: String, line: u64, why: String, text: String },
    #[error("{origin}: {source}")]
    Io { origin: String, source: std::io::Error },
}

fn intel(start_bit: u16, length: u16, signed: bool, factor: f64) -> SignalLayout {
    SignalLayout {
        frame: SAMPLE_FRAME,
        start_bit,
        length,
        byte_order: ByteOrder::LittleEndian,
        signed,
        factor,
        offset: 0.0,
    }
}

/// The simulated DAQ's convention (module docs) as a mapping; `fixtures/can/hammer.dbc`
/// describes the same frame.
pub fn forgemon_mapping() -> CanMapping {
    let signals = vec![
        CanSignalSpec { role: Role::Load, layout: intel(8, 16, true, LOAD_N_PER_COUNT) },
        CanSignalSpec { role: Role::Acc, layout: intel(24, 16, true, ACC_MPS2_PER_COUNT) },
        CanSignalSpec { role: Role::Disp, layout: intel(40, 24, true, DISP_M_PER_COUNT) },
    ];
    match CanMapping::new(signals, Some(intel(0, 8, false, 1.0))) {
        Ok(m) => m,
        // The layout above is constant and fits: a failure is a bug here, not bad input.
        Err(e) => unreachable!("the built-in CAN mapping is valid: {e}"),
    }
}

/// The simulated DAQ's CAN FD block (module docs) as a mapping; `config/hammer-canfd.dbc`
/// describes the same frame.
pub fn forgemon_fd_mapping() -> CanMapping {
    let at = |start_bit: u16, length: u16, factor: f64| SignalLayout {
        frame: BLOCK_FRAME,
        ..intel(start_bit, length, true, factor)
    };
    let slots = (0..BLOCK_SAMPLES as u16)
        .map(|k| {
            let b = 64 + 56 * k;
            vec![
                CanSignalSpec { role: Role::Load, layout: at(b, 16, LOAD_N_PER_COUNT) },
                CanSignalSpec { role: Role::Acc, layout: at(b + 16, 16, ACC_MPS2_PER_COUNT) },
                CanSignalSpec { role: Role::Disp, layout: at(b + 32, 24, DISP_M_PER_COUNT) },
            ]
        })
        .collect();
    let seq = SignalLayout { frame: BLOCK_FRAME, ..intel(0, 32, false, 1.0) };
    match CanMapping::block(slots, Some(seq), true) {
        Ok(m) => m,
        // The layout above is constant and fits: a failure is a bug here, not bad input.
        Err(e) => unreachable!("the built-in CAN FD mapping is valid: {e}"),
    }
}
