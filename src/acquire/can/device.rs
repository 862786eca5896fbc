//! The simulated DAQ's side of the bus: samples in physical units become CAN frames under
//! a mapping (by default the convention of the module docs), and a session becomes a
//! `candump -L` log. The inverse of the decoder, used by the fixtures, the tests and the
//! simulated devices. Pure apart from the `Write` it is given.
//!
//! A block mapping (CAN FD, `acquire::can` "The CAN FD block") collects its samples
//! until a block is full, then sends one frame stamped with the block's last sample's
//! time; its counter counts samples.

use std::io::Write;

use crate::signal::capture::CaptureRow;
use crate::signal::sample::Role;

use super::BLOCK_FD_FLAGS;
use super::candump::{write_candump_fd_line, write_candump_line};
use super::signal::{CanMapping, FrameId, fd_len_for};

/// Encodes samples into frames, numbering them with the sequence counter.
#[derive(Debug, Clone)]
pub struct CanDevice {
    mapping: CanMapping,
    frames: Vec<(FrameId, usize)>,
    seq: u64,
    /// Samples of a block not yet sent.
    pending: Vec<CaptureRow>,
    /// Values that did not fit their signal and were clipped.
    pub saturated: u64,
}

impl CanDevice {
    pub fn new(mapping: CanMapping) -> CanDevice {
        let frames = mapping.frames();
        let pending = Vec::with_capacity(mapping.samples_per_frame());
        CanDevice { mapping, frames, seq: 0, pending, saturated: 0 }
    }

    /// Samples collected for the next block frame, not yet written.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// The sample frame of one block of `rows` (exactly `samples_per_frame` of them): the
    /// counter is the block's first sample's index; the payload is padded to a valid FD
    /// length (or 8 bytes for classic).
    pub fn encode_block(&mut self, rows: &[CaptureRow]) -> (FrameId, Vec<u8>) {
        let frame = self.mapping.sample_frame();
        let needed = self.frames.iter().find(|(f, _)| *f == frame).map_or(8, |(_, n)| *n);
        let len = if self.mapping.is_fd() { fd_len_for(needed).unwrap_or(64) } else { needed.max(8) };
        let mut data = vec![0u8; len];
        if let Some(seq) = self.mapping.sequence() {
            seq.insert_raw(self.seq as i64, &mut data);
        }
        let roles = self.mapping.roles();
        for (k, r) in rows.iter().enumerate().take(self.mapping.samples_per_frame()) {
            for (layout, role) in self.mapping.slot(k).iter().zip(&roles) {
                if layout.insert(value(r, *role), &mut data) {
                    self.saturated += 1;
                }
            }
        }
        self.seq = self.seq.wrapping_add(rows.len() as u64);
        (frame, data)
    }

    /// The frames of one sample, the sample frame last (so a receiver holding values of
    /// the other frames completes the sample with this one's). Payloads are as long as
    /// the signals need, rounded up to 8 bytes for the sample frame.
    pub fn encode(&mut self, value_of: impl Fn(Role) -> f64) -> Vec<(FrameId, Vec<u8>)> {
        let sample_frame = self.mapping.sample_frame();
        let mut out: Vec<(FrameId, Vec<u8>)> = Vec::with_capacity(self.frames.len());
        for &(frame, needed) in &self.frames {
            let len = if frame == sample_frame { needed.max(8) } else { needed };
            let mut data = vec![0u8; len];
            for s in self.mapping.signals().iter().filter(|s| s.layout.frame == frame) {
                if s.layout.insert(value_of(s.role), &mut data) {
                    self.saturated += 1;
                }
            }
            if let Some(seq) = self.mapping.sequence().filter(|l| l.frame == frame) {
                seq.insert_raw(self.seq as i64, &mut data);
            }
            out.push((frame, data));
        }
        out.sort_by_key(|(f, _)| *f == sample_frame);
        self.seq = self.seq.wrapping_add(1);
        out
    }

    /// Skip `n` counter values, as a device whose frames were lost on the bus.
    pub fn skip(&mut self, n: u64) {
        self.seq = self.seq.wrapping_add(n);
    }

    /// Write `rows` as `candump -L` lines on `iface`, each sample's frames stamped with
    /// its time rounded to the log's microsecond. A block mapping writes a frame each time
    /// a block is full, stamped with its last sample's time, and keeps the rest for the
    /// next call.
    pub fn write_log<W: Write>(&mut self, w: &mut W, iface: &str, rows: &[CaptureRow]) -> std::io::Result<()> {
        let n = self.mapping.samples_per_frame();
        let stamp = |r: &CaptureRow| (r.t_s * 1e6).round() as i64 * 1000;
        if n > 1 || self.mapping.is_fd() {
            for r in rows {
                self.pending.push(*r);
                if self.pending.len() == n {
                    let block = std::mem::take(&mut self.pending);
                    let (frame, data) = self.encode_block(&block);
                    let t_ns = stamp(&block[n - 1]);
                    if self.mapping.is_fd() {
                        write_candump_fd_line(w, t_ns, iface, frame, BLOCK_FD_FLAGS, &data)?;
                    } else {
                        write_candump_line(w, t_ns, iface, frame, &data)?;
                    }
                    self.pending = block;
                    self.pending.clear();
                }
            }
            return Ok(());
        }
        for r in rows {
            let frames = self.encode(|role| value(r, role));
            for (frame, data) in frames {
                write_candump_line(w, stamp(r), iface, frame, &data)?;
            }
        }
        Ok(())
    }
}

/// The value of `role` in `r`.
fn value(r: &CaptureRow, role: Role) -> f64 {
    match role {
        Role::Load => r.load_n,
        Role::Disp => r.disp_m,
        Role::Acc => r.acc_mps2,
    }
}

#[cfg(test)]
mod tests {
    use super::super::{CanDecoder, CanTiming, SAMPLE_FRAME, candump, forgemon_mapping};
    use super::*;
    use crate::acquire::SourceEvent;

    #[test]
    fn a_logged_session_decodes_to_the_same_samples_within_resolution() {
        let rows: Vec<CaptureRow> = (0..300)
            .map(|k| CaptureRow {
                t_s: 12.5 + k as f64 * 200e-6,
                load_n: 1000.0 * k as f64 - 7e3,
                disp_m: 0.4375 - 1e-5 * k as f64,
                acc_mps2: 9.81 - 0.3 * k as f64,
            })
            .collect();
        let mut dev = CanDevice::new(forgemon_mapping());
        let mut log = Vec::new();
        dev.write_log(&mut log, "can0", &rows).unwrap();
        assert_eq!(dev.saturated, 0);
        let text = String::from_utf8(log).unwrap();
        assert_eq!(text.lines().count(), 300);
        assert!(text.starts_with("(12.500000) can0 120#00"), "{}", &text[..40]);

        let mut dec = CanDecoder::new("can", forgemon_mapping(), CanTiming::new(5000.0, 0.01, true));
        let mut r = candump::CandumpReader::new("mem", text.as_bytes());
        let events = candump::read_candump(&mut r, &mut dec, candump::BadLines::Fail).unwrap();
        let mut k = 0;
        for e in &events {
            let SourceEvent::Batch(b) = e else { panic!("no gaps expected: {e:?}") };
            for i in 0..b.len() {
                let row = &rows[k];
                // Device time counts from the first frame (12.5 s in the log).
                assert!((b.time_s(i) - (row.t_s - 12.5)).abs() < 1e-6);
                assert!((b.values[3 * i] - row.load_n).abs() <= 50.0);
                assert!((b.values[3 * i + 1] - row.disp_m).abs() <= 0.5e-6);
                assert!((b.values[3 * i + 2] - row.acc_mps2).abs() <= 0.125);
                k += 1;
            }
        }
        assert_eq!(k, 300);
        assert_eq!(dec.counters().samples, 300);
    }

    /// A CAN FD block log decodes to the same samples at the same times, the frame's stamp
    /// on its last sample; a lost frame is a gap of exactly one block.
    #[test]
    fn a_block_log_decodes_to_the_same_samples_and_a_lost_frame_is_a_block_gap() {
        use super::super::{BLOCK_SAMPLES, forgemon_fd_mapping};
        let rows: Vec<CaptureRow> = (0..80)
            .map(|k| CaptureRow {
                t_s: 7.0 + k as f64 * 20e-6,
                load_n: 300.0 * k as f64,
                disp_m: 0.2 + 1e-6 * k as f64,
                acc_mps2: 0.25 * k as f64,
            })
            .collect();
        let mut dev = CanDevice::new(forgemon_fd_mapping());
        let mut log = Vec::new();
        // In two calls, the first ending mid-block.
        dev.write_log(&mut log, "can0", &rows[..13]).unwrap();
        assert_eq!(dev.pending(), 5);
        dev.write_log(&mut log, "can0", &rows[13..]).unwrap();
        let text = String::from_utf8(log).unwrap();
        assert_eq!(text.lines().count(), 10);
        // Stamped with sample 7's time, 7.00014 s; Seq 0; FD flags 1.
        assert!(text.starts_with("(7.000140) can0 121##100000000"), "{}", &text[..40]);
        assert_eq!(text.lines().next().unwrap().len(), "(7.000140) can0 121##1".len() + 128);
        // Drop the 4th frame (samples 24..32).
        let edited: String = text.lines().enumerate().filter(|(i, _)| *i != 3).map(|(_, l)| format!("{l}\n")).collect();
        let mut dec = CanDecoder::new("can", forgemon_fd_mapping(), CanTiming::new(50_000.0, 1.0, true));
        let mut r = candump::CandumpReader::new("mem", edited.as_bytes());
        let events = candump::read_candump(&mut r, &mut dec, candump::BadLines::Fail).unwrap();
        let mut got = Vec::new();
        for e in &events {
            match e {
                SourceEvent::Batch(b) => {
                    for i in 0..b.len() {
                        got.push((b.time_s(i), b.values[3 * i], b.values[3 * i + 1], b.values[3 * i + 2]));
                    }
                }
                SourceEvent::Gap(g) => {
                    assert_eq!(g.samples_lost, BLOCK_SAMPLES as u64);
                    assert!((g.t_s - 24.0 * 20e-6).abs() < 1e-9, "{g:?}");
                }
                SourceEvent::Status(_) => {}
            }
        }
        assert_eq!(dec.counters().gaps, 1);
        assert_eq!(got.len(), 72);
        let kept = rows.iter().enumerate().filter(|(k, _)| !(24..32).contains(k));
        for ((t, load, disp, acc), (k, r)) in got.iter().zip(kept) {
            // Device time 0 is sample 0's time (7 s), the rest on the 20 µs grid.
            assert!((t - k as f64 * 20e-6).abs() < 1e-9, "sample {k}: {t}");
            assert!((load - r.load_n).abs() <= 50.0 && (disp - r.disp_m).abs() <= 0.5e-6, "sample {k}");
            assert_eq!(*acc, r.acc_mps2);
        }
    }

    #[test]
    fn skipped_counter_values_become_a_gap_of_that_many_samples() {
        let mut dev = CanDevice::new(forgemon_mapping());
        let mut dec = CanDecoder::new("can", forgemon_mapping(), CanTiming::new(5000.0, 0.01, false));
        let mut out = Vec::new();
        for k in 0..20i64 {
            if k == 10 {
                dev.skip(4);
            }
            for (f, d) in dev.encode(|_| 1.0) {
                assert_eq!(f, SAMPLE_FRAME);
                dec.push(k * 200_000, f, &d, &mut out);
            }
        }
        let lost: Vec<u64> =
            out.iter().filter_map(|e| if let SourceEvent::Gap(g) = e { Some(g.samples_lost) } else { None }).collect();
        assert_eq!(lost, vec![4]);
    }
}
