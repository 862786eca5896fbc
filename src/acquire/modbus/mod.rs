//! Modbus TCP and RTU (DESIGN.md §4, issue #4): slow signals polled from a register map
//! (setpoints, temperatures) and DAQs that buffer blocks of samples in registers, with a
//! small server for simulated devices and tests and a coil writer for the PLC alert sink.
//!
//! - [`registers`]: the register map and its sans-IO decoding (types, word order, scale).
//! - [`block`]: the block-mode convention below, sans-IO on both sides.
//! - [`client`]: the tokio driver, `run`, and `write_coil`; every request under a timeout.
//! - [`server`]: a register bank served over TCP or RTU, with fault switches.
//!
//! # Block mode (forgemon's own convention)
//!
//! A DAQ that samples faster than anyone can poll keeps its last N samples of C channels
//! in a ring of holding registers and counts what it wrote. At `base` (all 16-bit
//! registers, 32-bit values high word first):
//!
//! | registers | content |
//! |---|---|
//! | `base+0..1` | u32 sample counter: samples written since the device started, wrapping |
//! | `base+2..3` | u32 sample period, ns |
//! | `base+4` | N, ring length in samples |
//! | `base+5` | C, channels per sample |
//! | `base+6` | W, registers per value: 1 = i16 counts, 2 = i32 counts (high word first) |
//! | `base+7` | reserved, 0 |
//! | `base+8 ..` | the ring: the sample of counter value `c` in slot `c mod N`, at `base+8+slot·C·W` |
//!
//! Channels follow each other within a slot. The device writes a sample's slot before
//! bumping the counter. The client reads the header, then the slots written since its
//! last read (in reads of at most 125 registers), and turns counts into physical values
//! with each channel's `gain` and `offset`. Its first read only sets the starting point.
//! The slot about to be overwritten may change while it is read, so only the newest
//! `N − N/8` samples count as readable: a counter jump beyond that is a `Gap`
//! (`ring_overflow`) of the samples skipped. A counter that goes backwards means the
//! device restarted (`device_reset`). The sample index (the counter extended past its
//! wrap) times the period is the device time. When N does not divide 2^32 the slots jump
//! back to 0 at the counter's wrap, so the last `2^32 mod N` samples before it are
//! overwritten that many samples later instead of N: they are read only while they keep
//! the same margin, and are otherwise part of the `ring_overflow` gap (`block.rs`).
//!
//! # Plain polling
//!
//! `Mode::Poll` reads the whole register map every `poll_interval` in as few reads as
//! possible and sends a 1-sample batch of the map's roles (device time = host time).
//! Named signals that are no sample role (a setpoint, a temperature) are reported in the
//! status detail as `name=value`, because a `SampleBatch` carries roles only.
//!
//! # Faults
//!
//! - A Modbus exception is counted (`exceptions=` in the status detail) and the poll is
//!   retried at the next tick; the connection stays.
//! - A request that times out is counted (`timeouts=`) and the connection is reopened at
//!   once: its reply may still come, and would be taken for the next request's.
//! - A lost link (refused, reset) is reopened with `acquire::next_backoff_ms`; the first
//!   good read after it sends a `Gap` with reason `link_down` and the samples lost (in
//!   block mode 0 when the ring covered the outage; the outage is recorded anyway).
//! - Replies that do not decode count in `decode_errors`. Status: `connected` on connect
//!   and every second, `reconnecting` after each failure, `stopped` at shutdown.

pub mod block;
pub mod client;
pub mod registers;
pub mod server;

pub use block::{BlockError, BlockHeader, BlockTracker, RingWriter};
pub use client::{ModbusConfig, ModbusError, Mode, Transport, detail_count, run, write_coil};
pub use registers::{DataType, DecodeError, RegisterKind, RegisterSpec, Signal, WordOrder, decode_registers};
pub use server::{BankService, Faults, RegisterBank, SharedBank, TcpServer, serve_rtu, shared_bank};
