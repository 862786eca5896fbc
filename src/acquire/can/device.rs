//! The simulated DAQ's side of the bus: samples in physical units become CAN frames under
//! a mapping (by default the convention of the module docs), and a session becomes a
//! `candump -L` log. The inverse of the decoder, used by the fixtures, the tests and the
//! simulated devices. Pure apart from the `Write` it is given.

use std::io::Write;

use crate::signal::capture::CaptureRow;
use crate::signal::sample::Role;

use super::candump::write_candump_line;
use super::signal::{CanMapping, FrameId};

/// Encodes samples into frames, numbering them with the sequence counter.
#[derive(Debug, Clone)]
pub struct CanDevice {
    mapping: CanMapping,
    frames: Vec<(FrameId, usize)>,
    seq: u64,
    /// Values that did not fit their signal and were clipped.
    pub saturated: u64,
}

impl CanDevice {
    pub fn new(mapping: CanMapping) -> CanDevice {
        let frames = mapping.frames();
        CanDevice { mapping, frames, seq: 0, saturated: 0 }
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
    /// its time rounded to the log's microsecond.
    pub fn write_log<W: Write>(&mut self, w: &mut W, iface: &str, rows: &[CaptureRow]) -> std::io::Result<()> {
        for r in rows {
            let t_ns = (r.t_s * 1e6).round() as i64 * 1000;
            let frames = self.encode(|role| match role {
                Role::Load => r.load_n,
                Role::Disp => r.disp_m,
                Role::Acc => r.acc_mps2,
            });
            for (frame, data) in frames {
                write_candump_line(w, t_ns, iface, frame, &data)?;
            }
        }
        Ok(())
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
