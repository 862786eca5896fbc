//! The sans-IO CAN decoder: fed timestamped frames (from a socket or a candump log), it
//! extracts the mapped signals, numbers the samples by the sequence counter, reports jumps
//! as gaps and assembles `SampleBatch`es. It opens nothing and reads no clock: the caller
//! passes each frame's receive time.
//!
//! Device time is integer ns counted from the first frame the decoder ever saw, not the
//! receive time itself: candump and kernel stamps are epoch times (1.7e9 s), which an f64
//! of seconds downstream holds only to 0.24 µs, so sample times (and impact speeds) would
//! depend on where batches happen to start. Relative to the first frame they are exact.

use crate::acquire::{Counters, SourceEvent};
use crate::signal::sample::Gap;
use crate::signal::sample::{Role, SampleBatch};

use super::signal::{CanMapping, FrameId};

/// The sample clock of a CAN source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CanTiming {
    /// The device's sample period, ns (CAN frames carry no sample time).
    pub period_ns: f64,
    /// Samples per batch (a partial batch goes out at a gap, on `flush`, or at the end).
    pub batch_samples: usize,
    /// Whether frame times are trustworthy receive times (kernel or candump timestamps):
    /// then a silence longer than the sequence counter's wrap is counted in full, and a
    /// source without a counter detects gaps by time. A live reader stamping frames when
    /// it gets round to them must say false: a stalled reader is not a lost sample.
    pub trust_timestamps: bool,
}

impl CanTiming {
    /// `sample_rate_hz` with batches of about `batch_s` (at least one sample).
    pub fn new(sample_rate_hz: f64, batch_s: f64, trust_timestamps: bool) -> CanTiming {
        CanTiming {
            period_ns: 1e9 / sample_rate_hz,
            batch_samples: ((batch_s * sample_rate_hz).round() as usize).max(1),
            trust_timestamps,
        }
    }
}

/// What the decoder saw besides the `Counters` every transport keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CanStats {
    /// Frames with an identifier the mapping does not read (ignored).
    pub unknown_frames: u64,
    /// Remote and error frames, and data frames of the other kind: CAN FD frames on a
    /// classic mapping, classic ones on a CAN FD mapping (ignored).
    pub unsupported_frames: u64,
    /// Sample-message frames repeating the previous counter value (dropped).
    pub duplicates: u64,
    /// Sample frames whose trusted time claimed whole counter wraps lost that the next
    /// frame did not confirm (a wild stamp): dropped, never used.
    pub wild_stamps: u64,
}

/// The decoder of one CAN source. See the module docs of `acquire::can` for the frame
/// convention of forgemon's simulated DAQ; any mapping works.
#[derive(Debug)]
pub struct CanDecoder {
    source: String,
    mapping: CanMapping,
    timing: CanTiming,
    counters: Counters,
    stats: CanStats,
    roles: Vec<Role>,
    /// The frames read, with the payload bytes each needs.
    frames: Vec<(FrameId, usize)>,
    /// Latest value of each mapped signal (sample-and-hold across frames).
    held: Vec<Option<f64>>,
    /// Receive time of the first frame ever seen, ns: device time 0.
    origin_ns: Option<i64>,
    /// Receive time of sample index 0 of the current stream, ns.
    t0_ns: Option<i64>,
    /// Index of the next sample, counting lost ones.
    next_index: u64,
    last_seq: Option<u64>,
    last_t_ns: i64,
    /// A frame whose time claimed whole counter wraps lost, held back until the next frame
    /// confirms it: its receive time and counter.
    suspect: Option<(i64, u64)>,
    batch: Vec<f64>,
    batch_index0: u64,
    batch_host_ns: i64,
    batch_seq: u64,
}

impl CanDecoder {
    pub fn new(source: impl Into<String>, mapping: CanMapping, timing: CanTiming) -> CanDecoder {
        let roles = mapping.roles();
        let frames = mapping.frames();
        let held = vec![None; roles.len()];
        CanDecoder {
            source: source.into(),
            batch: Vec::with_capacity(timing.batch_samples.max(1) * roles.len()),
            mapping,
            timing,
            counters: Counters::default(),
            stats: CanStats::default(),
            roles,
            frames,
            held,
            origin_ns: None,
            t0_ns: None,
            next_index: 0,
            last_seq: None,
            last_t_ns: 0,
            suspect: None,
            batch_index0: 0,
            batch_host_ns: 0,
            batch_seq: 0,
        }
    }

    pub fn source(&self) -> &str {
        &self.source
    }

    pub fn mapping(&self) -> &CanMapping {
        &self.mapping
    }

    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// The driver counts its own drops and reconnects here.
    pub fn counters_mut(&mut self) -> &mut Counters {
        &mut self.counters
    }

    pub fn stats(&self) -> &CanStats {
        &self.stats
    }

    /// Whether frame times are trusted receive times (see [`CanTiming`]); the live driver
    /// sets it by whether the kernel stamps its frames.
    pub fn set_trust_timestamps(&mut self, trust: bool) {
        self.timing.trust_timestamps = trust;
    }

    /// A remote or error frame, or a data frame of the other kind (FD on a classic
    /// mapping, classic on an FD one) arrived: counted and ignored.
    pub fn skip_unsupported(&mut self) {
        self.stats.unsupported_frames += 1;
    }

    /// Device time of sample `index`, ns from the first frame ever seen.
    fn device_time_ns(&self, index: u64) -> i64 {
        let t0 = self.t0_ns.unwrap_or(0).saturating_sub(self.origin_ns.unwrap_or(0));
        t0.saturating_add((index as f64 * self.timing.period_ns).round() as i64)
    }

    /// Feed one data frame received at `t_ns` (host or log time). Batches and gaps go to
    /// `out`. A frame of a block mapping carries several samples: its time belongs to the
    /// last of them, and the others precede it at the sample period.
    pub fn push(&mut self, t_ns: i64, frame: FrameId, data: &[u8], out: &mut Vec<SourceEvent>) {
        let Some(&(_, needed)) = self.frames.iter().find(|(f, _)| *f == frame) else {
            self.stats.unknown_frames += 1;
            return;
        };
        self.counters.frames += 1;
        if data.len() < needed {
            // Bad DLC: too short for the signals it should carry.
            self.counters.decode_errors += 1;
            return;
        }
        let sample_frame = self.mapping.sample_frame();
        for (i, s) in self.mapping.signals().iter().enumerate() {
            if s.layout.frame == frame && frame != sample_frame {
                self.held[i] = s.layout.extract(data);
            }
        }
        if frame != sample_frame {
            return;
        }
        let n = self.mapping.samples_per_frame();
        // The time of the frame's first sample.
        let t_first_ns = t_ns - ((n - 1) as f64 * self.timing.period_ns).round() as i64;
        let seq = self.mapping.sequence().and_then(|l| l.extract_raw(data)).map(|r| r as u64);
        if self.t0_ns.is_none() {
            self.origin_ns.get_or_insert(t_first_ns);
            self.t0_ns = Some(t_first_ns);
        } else if let Some(lost) = self.lost_before(seq, t_ns) {
            if !self.wraps_confirmed(lost, seq, t_ns) {
                self.stats.wild_stamps += 1;
                self.counters.decode_errors += 1;
                return;
            }
            if lost < 0 {
                self.stats.duplicates += 1;
                return;
            }
            if lost > 0 {
                self.flush(out);
                self.counters.gaps += 1;
                out.push(SourceEvent::Gap(Gap {
                    source: self.source.clone(),
                    t_s: self.device_time_ns(self.next_index) as f64 * 1e-9,
                    samples_lost: lost as u64,
                    reason: "sequence_jump".to_string(),
                }));
                self.next_index += lost as u64;
            }
        }
        self.last_seq = seq;
        self.last_t_ns = t_ns;
        for k in 0..n {
            for (i, l) in self.mapping.slot(k).iter().enumerate() {
                if l.frame == frame {
                    self.held[i] = l.extract(data);
                }
            }
            let host_ns = t_first_ns + (k as f64 * self.timing.period_ns).round() as i64;
            self.push_sample(host_ns, out);
        }
    }

    /// Append the held values as the next sample, received at `host_ns`.
    fn push_sample(&mut self, host_ns: i64, out: &mut Vec<SourceEvent>) {
        let index = self.next_index;
        self.next_index += 1;
        if self.held.iter().any(Option::is_none) {
            // A role carried by another frame has not been seen yet.
            return;
        }
        if !self.batch.is_empty() && index != self.batch_index0 + (self.batch.len() / self.roles.len()) as u64 {
            self.flush(out);
        }
        if self.batch.is_empty() {
            self.batch_index0 = index;
            self.batch_host_ns = host_ns;
        }
        self.batch.extend(self.held.iter().map(|v| v.unwrap_or(f64::NAN)));
        self.counters.samples += 1;
        if self.batch.len() / self.roles.len() >= self.timing.batch_samples {
            self.flush(out);
        }
    }

    /// With trusted times, a time that credits whole counter wraps as lost is believed only
    /// when the next frame's time and counter continue from it; the first such frame is held
    /// back (false: drop it, it only costs its own sample, which the next frame's counter then
    /// counts as lost) and forgotten when the next frame continues the old timeline.
    fn wraps_confirmed(&mut self, lost: i64, seq: Option<u64>, t_ns: i64) -> bool {
        let (Some(seq), Some(layout)) = (seq, self.mapping.sequence()) else { return true };
        let modulus = 1i64 << layout.length;
        let suspect = self.suspect.take();
        if lost < modulus {
            return true;
        }
        let continues = suspect.is_some_and(|(st, sseq)| {
            let diff = (seq as i64 - sseq as i64).rem_euclid(modulus);
            let elapsed = (t_ns - st) as f64 / self.timing.period_ns;
            diff > 0 && (elapsed - diff as f64).abs() < 0.5
        });
        if !continues {
            self.suspect = Some((t_ns, seq));
        }
        continues
    }

    /// Samples lost between the previous sample frame and this one (negative: a repeat),
    /// or None when nothing tells. The counter counts samples, so from one frame of `n`
    /// samples to the next it advances by `n`, and so do the frames' times.
    fn lost_before(&self, seq: Option<u64>, t_ns: i64) -> Option<i64> {
        let n = self.mapping.samples_per_frame() as i64;
        let elapsed = (t_ns - self.last_t_ns) as f64 / self.timing.period_ns;
        match (seq, self.last_seq, self.mapping.sequence()) {
            (Some(seq), Some(last), Some(layout)) => {
                let modulus = 1i64 << layout.length;
                let diff = (seq as i64 - last as i64).rem_euclid(modulus);
                if !self.timing.trust_timestamps {
                    // Back, still, or forward by less than a block: a repeat.
                    return Some(if diff < n { -1 } else { diff - n });
                }
                let lost0 = (diff - n).rem_euclid(modulus);
                let wraps = ((elapsed - n as f64 - lost0 as f64) / modulus as f64).round() as i64;
                Some(lost0 + wraps * modulus)
            }
            _ if self.timing.trust_timestamps => Some((elapsed.round() as i64 - n).max(0)),
            _ => None,
        }
    }

    /// Send the samples collected so far as a batch.
    pub fn flush(&mut self, out: &mut Vec<SourceEvent>) {
        if self.batch.is_empty() {
            return;
        }
        let values =
            std::mem::replace(&mut self.batch, Vec::with_capacity(self.timing.batch_samples * self.roles.len()));
        out.push(SourceEvent::Batch(SampleBatch {
            source: self.source.clone(),
            seq: self.batch_seq,
            device_time_ns: self.device_time_ns(self.batch_index0),
            host_time_ns: self.batch_host_ns,
            period_ns: self.timing.period_ns,
            roles: self.roles.clone(),
            values,
        }));
        self.batch_seq += 1;
    }

    /// The stream broke (link lost, new log): flush, and start the next frame as a new
    /// stream whose device time is anchored afresh at its receive time (still counted from
    /// the first frame ever seen, so device time does not go back). Counters are kept.
    pub fn restart(&mut self, out: &mut Vec<SourceEvent>) {
        self.flush(out);
        self.t0_ns = None;
        self.next_index = 0;
        self.last_seq = None;
        self.suspect = None;
        self.held.iter_mut().for_each(|v| *v = None);
    }

    /// A status line's detail: what the counters do not hold.
    pub fn detail(&self) -> String {
        format!(
            "unknown frames {}, remote/error/other-kind frames {}, repeated counters {}, wild stamps {}",
            self.stats.unknown_frames, self.stats.unsupported_frames, self.stats.duplicates, self.stats.wild_stamps
        )
    }
}

#[cfg(test)]
mod tests {
    use super::super::{SAMPLE_FRAME, forgemon_mapping};
    use super::*;

    fn encode(seq: u8, load_n: f64, disp_m: f64, acc: f64) -> [u8; 8] {
        let m = forgemon_mapping();
        let mut d = [0u8; 8];
        m.sequence().unwrap().insert_raw(seq as i64, &mut d);
        for s in m.signals() {
            let v = match s.role {
                Role::Load => load_n,
                Role::Disp => disp_m,
                Role::Acc => acc,
            };
            s.layout.insert(v, &mut d);
        }
        d
    }

    fn decoder(trust: bool) -> CanDecoder {
        CanDecoder::new(
            "can",
            forgemon_mapping(),
            CanTiming { period_ns: 200_000.0, batch_samples: 4, trust_timestamps: trust },
        )
    }

    fn batches(out: &[SourceEvent]) -> Vec<&SampleBatch> {
        out.iter().filter_map(|e| if let SourceEvent::Batch(b) = e { Some(b) } else { None }).collect()
    }

    #[test]
    fn frames_become_batches_of_physical_values() {
        let mut d = decoder(true);
        let mut out = Vec::new();
        for k in 0..10u8 {
            let t = 1_000_000_000 + k as i64 * 200_000;
            d.push(t, SAMPLE_FRAME, &encode(k, 1000.0 * k as f64, 0.4 + 1e-5 * k as f64, 9.75), &mut out);
        }
        d.flush(&mut out);
        let b = batches(&out);
        assert_eq!(b.iter().map(|b| b.len()).collect::<Vec<_>>(), vec![4, 4, 2]);
        assert_eq!(b[0].roles, vec![Role::Load, Role::Disp, Role::Acc]);
        assert_eq!(b[0].device_time_ns, 0, "device time counts from the first frame");
        assert_eq!(b[1].device_time_ns, 4 * 200_000);
        assert_eq!(b[1].host_time_ns, 1_000_000_000 + 4 * 200_000, "host time is the receive time");
        assert_eq!(b[1].seq, 1);
        // sample 5: load 5 kN (100 N steps), disp 0.40005 m (1 µm steps), acc 9.75 (0.25 steps).
        assert_eq!(b[1].values[3], 5000.0);
        assert!((b[1].values[4] - 0.40005).abs() < 1e-9);
        assert_eq!(b[1].values[5], 9.75);
        assert_eq!(d.counters().samples, 10);
        assert_eq!(d.counters().gaps, 0);
    }

    #[test]
    fn a_counter_jump_is_a_gap_and_device_time_skips_the_lost_samples() {
        let mut d = decoder(false);
        let mut out = Vec::new();
        for (k, seq) in [(0i64, 254u8), (1, 255), (5, 3), (6, 4)] {
            d.push(k * 200_000, SAMPLE_FRAME, &encode(seq, 0.0, 0.0, 0.0), &mut out);
        }
        d.flush(&mut out);
        let gaps: Vec<&Gap> =
            out.iter().filter_map(|e| if let SourceEvent::Gap(g) = e { Some(g) } else { None }).collect();
        assert_eq!(gaps.len(), 1);
        assert_eq!(gaps[0].samples_lost, 3, "255 -> 3 wraps and skips 0, 1, 2");
        assert!((gaps[0].t_s - 2.0 * 200e-6).abs() < 1e-12);
        let b = batches(&out);
        assert_eq!(b.len(), 2, "the batch is cut at the gap");
        assert_eq!(b[1].device_time_ns, 5 * 200_000);
        assert_eq!(d.counters().gaps, 1);
    }

    /// A block of 8 samples a frame, untrusted times: the counter alone tells a lost frame
    /// (a gap of exactly 8) from a repeated one (dropped, counted).
    #[test]
    fn block_frames_count_lost_and_repeated_frames_by_the_sample_counter() {
        use super::super::{BLOCK_FRAME, CanDevice, forgemon_fd_mapping};
        use crate::signal::capture::CaptureRow;
        let mut dev = CanDevice::new(forgemon_fd_mapping());
        let mut d = CanDecoder::new("can", forgemon_fd_mapping(), CanTiming::new(50_000.0, 1.0, false));
        let mut out = Vec::new();
        let row = |k: usize| CaptureRow { t_s: 0.0, load_n: 100.0 * k as f64, disp_m: 0.0, acc_mps2: 0.0 };
        let mut frames = Vec::new();
        for b in 0..6usize {
            let rows: Vec<CaptureRow> = (8 * b..8 * b + 8).map(row).collect();
            frames.push(dev.encode_block(&rows));
        }
        // Frames 0, 1, 1 again, (2 lost), 3, 4, 5; receive times say nothing (all 0).
        for i in [0, 1, 1, 3, 4, 5] {
            let (f, data) = &frames[i];
            assert_eq!(*f, BLOCK_FRAME);
            d.push(0, *f, data, &mut out);
        }
        d.flush(&mut out);
        let lost: Vec<u64> =
            out.iter().filter_map(|e| if let SourceEvent::Gap(g) = e { Some(g.samples_lost) } else { None }).collect();
        assert_eq!(lost, vec![8]);
        assert_eq!((d.stats().duplicates, d.counters().samples), (1, 40));
        let loads: Vec<f64> = batches(&out).iter().flat_map(|b| b.values.chunks(3).map(|c| c[0])).collect();
        let want: Vec<f64> = (0..48).filter(|k| !(16..24).contains(k)).map(|k| 100.0 * k as f64).collect();
        assert_eq!(loads, want, "each sample in its slot, in order");
        // Device time: sample 24 (after the hole) at 24 periods.
        assert_eq!(batches(&out)[1].device_time_ns, 24 * 20_000);
    }

    #[test]
    fn trusted_times_count_whole_wraps_of_the_counter() {
        let mut d = decoder(true);
        let mut out = Vec::new();
        d.push(0, SAMPLE_FRAME, &encode(10, 0.0, 0.0, 0.0), &mut out);
        // 1000 samples later the 8-bit counter reads 10 + 1000 mod 256 = 242.
        d.push(1000 * 200_000, SAMPLE_FRAME, &encode(242, 0.0, 0.0, 0.0), &mut out);
        // One frame's time alone is not believed for whole wraps (it could be a wild
        // stamp): it is held back until the next one continues from it.
        assert!(out.iter().all(|e| !matches!(e, SourceEvent::Gap(_))));
        d.push(1001 * 200_000, SAMPLE_FRAME, &encode(243, 0.0, 0.0, 0.0), &mut out);
        let lost: u64 =
            out.iter().filter_map(|e| if let SourceEvent::Gap(g) = e { Some(g.samples_lost) } else { None }).sum();
        // The 999 of the quiet and the held-back frame.
        assert_eq!(lost, 1000);
    }

    #[test]
    fn unknown_ids_short_frames_and_repeats_are_counted_not_fatal() {
        let mut d = decoder(false);
        let mut out = Vec::new();
        d.push(0, FrameId::standard(0x7FF), &[1, 2, 3], &mut out);
        d.push(0, FrameId::extended(SAMPLE_FRAME.id), &[0; 8], &mut out);
        d.push(0, SAMPLE_FRAME, &[0; 7], &mut out); // DLC 7: one byte short
        d.push(0, SAMPLE_FRAME, &[], &mut out); // empty
        d.push(0, SAMPLE_FRAME, &encode(1, 0.0, 0.0, 0.0), &mut out);
        d.push(1, SAMPLE_FRAME, &encode(1, 0.0, 0.0, 0.0), &mut out); // repeated counter
        d.push(2, SAMPLE_FRAME, &encode(2, 0.0, 0.0, 0.0), &mut out);
        assert_eq!(d.stats().unknown_frames, 2);
        assert_eq!(d.counters().decode_errors, 2);
        assert_eq!(d.stats().duplicates, 1);
        assert_eq!(d.counters().samples, 2);
        assert_eq!(d.counters().gaps, 0);
        assert!(out.iter().all(|e| !matches!(e, SourceEvent::Gap(_))));
    }

    #[test]
    fn values_from_another_frame_are_held_until_the_sample_frame() {
        use super::super::signal::{ByteOrder, CanSignalSpec, SignalLayout};
        // Load on 0x100 (sample frame), acceleration on 0x200 at a lower rate.
        let l = |id: u16| SignalLayout {
            frame: FrameId::standard(id),
            start_bit: 0,
            length: 16,
            byte_order: ByteOrder::LittleEndian,
            signed: true,
            factor: 1.0,
            offset: 0.0,
        };
        let m = CanMapping::new(
            vec![
                CanSignalSpec { role: Role::Load, layout: l(0x100) },
                CanSignalSpec { role: Role::Acc, layout: l(0x200) },
            ],
            None,
        )
        .unwrap();
        let mut d =
            CanDecoder::new("can", m, CanTiming { period_ns: 1e6, batch_samples: 100, trust_timestamps: false });
        let mut out = Vec::new();
        d.push(0, FrameId::standard(0x100), &[1, 0], &mut out); // no acceleration yet: not a sample
        d.push(1, FrameId::standard(0x200), &[7, 0], &mut out);
        d.push(2, FrameId::standard(0x100), &[2, 0], &mut out);
        d.push(3, FrameId::standard(0x100), &[3, 0], &mut out);
        d.flush(&mut out);
        let b = batches(&out);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].values, vec![2.0, 7.0, 3.0, 7.0]);
        assert_eq!(b[0].device_time_ns, 1_000_000, "index 1: the first frame started the clock");
    }

    #[test]
    fn epoch_stamps_keep_microsecond_resolution_relative_to_the_first_frame() {
        // candump stamps (1700000000.123456), (1700000000.123656), ...: 1.7e18 ns, which an
        // f64 of seconds holds only to 0.24 µs. Device time counts from the first frame.
        let mut d = decoder(true);
        let mut out = Vec::new();
        let t0 = 1_700_000_000_123_456_000i64;
        for k in 0..9u8 {
            d.push(t0 + k as i64 * 200_000, SAMPLE_FRAME, &encode(k, 0.0, 0.0, 0.0), &mut out);
        }
        d.flush(&mut out);
        let b = batches(&out);
        assert_eq!(b.iter().map(|b| b.device_time_ns).collect::<Vec<_>>(), vec![0, 800_000, 1_600_000]);
        assert_eq!(b[2].host_time_ns, t0 + 1_600_000);
        // Sample 5's time is 1 ms exactly, whichever batch holds it.
        assert_eq!(b[1].time_s(1), 1e-3);
        // A broken stream starts afresh at its receive time, still counted from the first.
        d.restart(&mut out);
        out.clear();
        d.push(t0 + 5_000_000_000, SAMPLE_FRAME, &encode(0, 0.0, 0.0, 0.0), &mut out);
        d.flush(&mut out);
        assert_eq!(batches(&out)[0].device_time_ns, 5_000_000_000);
    }

    #[test]
    fn one_wild_stamp_with_trusted_times_is_no_gap_and_loses_no_later_frame() {
        // Frame 5's stamp is 900 s ahead (a flipped digit in a candump log); its counter
        // continues. It used to give a gap of 4,499,968 samples, a sample 900 s late, and
        // every later frame dropped as a repeat. Now frame 5 alone is dropped as wild and
        // its sample is the one-sample gap the counter shows.
        let mut d = decoder(true);
        let mut out = Vec::new();
        for k in 0..12u8 {
            let wild = if k == 5 { 900_000_000_000 } else { 0 };
            d.push(1_000_000_000 + k as i64 * 200_000 + wild, SAMPLE_FRAME, &encode(k, 0.0, 0.0, 0.0), &mut out);
        }
        d.flush(&mut out);
        let lost: u64 = out.iter().map(|e| if let SourceEvent::Gap(g) = e { g.samples_lost } else { 0 }).sum();
        assert_eq!(lost, 1, "{out:?}");
        assert_eq!(d.counters().samples, 11);
        assert_eq!(d.stats().wild_stamps, 1);
        // Every sample lies on the 0.2 ms grid from the first: none 900 s late.
        let last = batches(&out).last().map(|b| b.time_s(b.len() - 1)).unwrap();
        assert!((last - 11.0 * 200e-6).abs() < 1e-9, "{last}");
    }

    #[test]
    fn a_real_loss_of_whole_counter_wraps_is_believed_once_the_next_frame_confirms_it() {
        // The bus goes quiet for 10 s: frames 6.. arrive 10 s (50 000 samples) later and
        // keep coming on time. The first late frame is held back, the second confirms.
        let mut d = decoder(true);
        let mut out = Vec::new();
        for k in 0..12u64 {
            let late = if k >= 6 { 10_000_000_000 } else { 0 };
            let seq = (k + if k >= 6 { 50_000 } else { 0 }) % 256;
            d.push(
                1_000_000_000 + k as i64 * 200_000 + late,
                SAMPLE_FRAME,
                &encode(seq as u8, 0.0, 0.0, 0.0),
                &mut out,
            );
        }
        d.flush(&mut out);
        let lost: u64 = out.iter().map(|e| if let SourceEvent::Gap(g) = e { g.samples_lost } else { 0 }).sum();
        // 50 000 lost in the quiet, plus the held-back first frame after it.
        assert_eq!(lost, 50_001, "{out:?}");
        assert_eq!(d.counters().samples, 11);
    }
}
