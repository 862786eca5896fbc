//! Frames into samples (docs/interfaces.md §7): `FrameTracker` turns decoded frames into
//! `SampleBatch`es in physical units with the configured channels (`offset + gain *
//! count`), and records every hole in the stream as a `Gap`: a jump in the wrapping u32
//! sequence, and a frame whose sequence continues but whose `device_time_ns` does not
//! (the DAQ lost samples in its own buffer, so a frame starts late). It keeps its state
//! across reconnects, so an outage shows as a gap. Pure code.

use super::frame::Frame;
use crate::acquire::ChannelSpec;
use crate::signal::sample::Gap;
use crate::signal::sample::SampleBatch;

/// Why a well-formed frame could not become samples.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TrackError {
    #[error("frame has {got} channels, the config gives {expected}")]
    ChannelMismatch { expected: usize, got: u8 },
    #[error("frame has sample_period_ns 0")]
    ZeroPeriod,
}

/// A frame turned into samples, with the gap its sequence number or device time reveals.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracked {
    /// Samples lost before this batch (a sequence jump or a time slip), if any.
    pub gap: Option<Gap>,
    pub batch: SampleBatch,
}

/// What the tracker saw besides samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TrackStats {
    /// The sequence went backwards or repeated: the device restarted its count.
    pub restarts: u64,
    /// Frames whose sequence continued but whose device time did not (each is a gap).
    pub time_slips: u64,
}

/// Turns frames into `SampleBatch`es with the configured channels (`offset + gain * count`)
/// and checks each frame against the one before it:
///
/// - Sequence: a jump of `j` (wrapping u32) loses `(j − 1) × N` samples (docs/interfaces.md §7).
///   A backwards jump (more than 2³¹ ahead) or a repeat is a device restart: no gap, the
///   count starts over.
/// - Device time: the frame should start where the previous one ended, plus the samples
///   the sequence says were lost. A start off by half a period or more is a hole the
///   sequence cannot see (the DAQ dropped a sample from its buffer): a gap of the samples
///   the time jump spans (`round(Δt / period)`, zero if time went back), reason
///   `time_slip: device time jumped by k periods at sequence s`. When the sequence also
///   jumped, the time's count wins and the reason names both.
#[derive(Debug, Clone)]
pub struct FrameTracker {
    source: String,
    channels: Vec<ChannelSpec>,
    last_seq: Option<u32>,
    /// The unwrapped sequence of the last frame (`SampleBatch::seq`).
    seq: u64,
    /// Device time just after the last frame's last sample, ns.
    next_device_ns: u64,
    stats: TrackStats,
}

impl FrameTracker {
    pub fn new(source: impl Into<String>, channels: Vec<ChannelSpec>) -> Self {
        FrameTracker {
            source: source.into(),
            channels,
            last_seq: None,
            seq: 0,
            next_device_ns: 0,
            stats: TrackStats::default(),
        }
    }

    /// How often the sequence went backwards (device restarts).
    pub fn restarts(&self) -> u64 {
        self.stats.restarts
    }

    pub fn stats(&self) -> TrackStats {
        self.stats
    }

    /// The gap before `frame`, whose sequence is `jump` (≥ 1) past the previous frame's:
    /// what the sequence says and what the device time says (struct docs).
    fn hole_before(&mut self, frame: &Frame, jump: u32) -> Option<Gap> {
        let period = frame.sample_period_ns as i128;
        let n = frame.sample_count as i128;
        let by_seq = (jump as i128 - 1) * n;
        let expected_ns = self.next_device_ns as i128 + by_seq * period;
        let slip_ns = frame.device_time_ns as i128 - expected_ns;
        let on_time = 2 * slip_ns.abs() < period;
        let gap = |samples_lost: i128, reason: String| Gap {
            source: self.source.clone(),
            t_s: self.next_device_ns as f64 * 1e-9,
            samples_lost: u64::try_from(samples_lost.max(0)).unwrap_or(u64::MAX),
            reason,
        };
        if on_time {
            return (jump > 1).then(|| gap(by_seq, "sequence_jump".to_string()));
        }
        self.stats.time_slips += 1;
        // Whole periods, rounded half away from zero.
        let slip_periods = (2 * slip_ns + slip_ns.signum() * period) / (2 * period);
        let by_time = by_seq + slip_periods;
        let s = frame.sequence;
        let reason = if jump > 1 {
            format!(
                "sequence_jump: {} frames ({by_seq} samples) lost before sequence {s}, device time says {by_time} samples",
                jump - 1
            )
        } else if slip_periods > 0 {
            format!("time_slip: device time jumped by {slip_periods} periods at sequence {s}")
        } else {
            format!("time_slip: device time went back by {} periods at sequence {s}", -slip_periods)
        };
        Some(gap(by_time, reason))
    }

    /// The samples of `frame`, received at host time `host_time_ns`.
    pub fn track(&mut self, frame: &Frame, host_time_ns: i64) -> Result<Tracked, TrackError> {
        if frame.channel_count as usize != self.channels.len() {
            return Err(TrackError::ChannelMismatch { expected: self.channels.len(), got: frame.channel_count });
        }
        if frame.sample_period_ns == 0 {
            return Err(TrackError::ZeroPeriod);
        }
        let gap = match self.last_seq {
            None => {
                self.seq = frame.sequence as u64;
                None
            }
            Some(last) => {
                let jump = frame.sequence.wrapping_sub(last);
                if jump == 0 || jump > u32::MAX / 2 {
                    // Repeated or backwards: the device restarted its count (and its clock).
                    self.stats.restarts += 1;
                    self.seq += 1;
                    None
                } else {
                    self.seq += jump as u64;
                    self.hole_before(frame, jump)
                }
            }
        };
        self.last_seq = Some(frame.sequence);
        self.next_device_ns =
            frame.device_time_ns.saturating_add(frame.sample_period_ns as u64 * frame.sample_count as u64);
        let c = self.channels.len();
        let mut values = Vec::with_capacity(frame.counts.len());
        for (k, count) in frame.counts.iter().enumerate() {
            values.push(self.channels[k % c].physical(*count as f64));
        }
        let batch = SampleBatch {
            source: self.source.clone(),
            seq: self.seq,
            device_time_ns: i64::try_from(frame.device_time_ns).unwrap_or(i64::MAX),
            host_time_ns,
            period_ns: frame.sample_period_ns as f64,
            roles: self.channels.iter().map(|ch| ch.role).collect(),
            values,
        };
        Ok(Tracked { gap, batch })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::sample::Role;

    /// 2 channels, 2 samples, sequence 5, t = 1000 ns, period 10 µs, counts [[1, -1], [256, 2]].
    fn small_frame() -> Frame {
        Frame {
            channel_count: 2,
            sample_count: 2,
            sequence: 5,
            device_time_ns: 1000,
            sample_period_ns: 10_000,
            counts: vec![1, -1, 256, 2],
        }
    }

    fn specs() -> Vec<ChannelSpec> {
        vec![
            ChannelSpec { role: Role::Load, gain: 10.0, offset: -5.0 },
            ChannelSpec { role: Role::Disp, gain: 1e-6, offset: 0.5 },
        ]
    }

    #[test]
    fn tracker_applies_gain_and_offset() {
        let mut t = FrameTracker::new("daq", specs());
        let out = t.track(&small_frame(), 42).unwrap();
        assert_eq!(out.gap, None);
        let b = out.batch;
        assert_eq!((b.source.as_str(), b.seq, b.device_time_ns, b.host_time_ns), ("daq", 5, 1000, 42));
        assert_eq!(b.period_ns, 10_000.0);
        assert_eq!(b.roles, vec![Role::Load, Role::Disp]);
        // [[1, -1], [256, 2]] -> load -5 + 10 c, disp 0.5 + 1e-6 c
        assert_eq!(b.values, vec![5.0, 0.5 - 1e-6, 2555.0, 0.5 + 2e-6]);
    }

    #[test]
    fn sequence_jumps_become_gaps_across_the_wrap() {
        let mut t = FrameTracker::new("daq", specs());
        let mut f = small_frame();
        let mut gaps = Vec::new();
        let mut seqs = Vec::new();
        // u32::MAX - 1, u32::MAX, 0 (wrap, no gap), 3 (frames 1 and 2 lost), 4; each
        // frame 2 samples × 10 µs = 20 µs after the one before it on the device clock.
        for (k, s) in [(0u64, u32::MAX - 1), (1, u32::MAX), (2, 0), (5, 3), (6, 4)] {
            f.sequence = s;
            f.device_time_ns = 20_000 * k;
            let out = t.track(&f, 0).unwrap();
            seqs.push(out.batch.seq);
            gaps.extend(out.gap);
        }
        let base = (u32::MAX - 1) as u64;
        assert_eq!(seqs, vec![base, base + 1, base + 2, base + 5, base + 6]);
        assert_eq!(gaps.len(), 1);
        assert_eq!(gaps[0].samples_lost, 2 * 2); // (jump 3 - 1) frames × 2 samples
        assert_eq!(gaps[0].reason, "sequence_jump");
        assert!((gaps[0].t_s - 60e-6).abs() < 1e-12, "the gap starts where the frame before it ended");
        // Backwards: a restarted device, not a gap.
        f.sequence = 1;
        assert_eq!(t.track(&f, 0).unwrap().gap, None);
        assert_eq!(t.restarts(), 1);
    }

    #[test]
    fn tracker_refuses_a_channel_mismatch_and_a_zero_period() {
        let mut t = FrameTracker::new("daq", specs());
        let mut f = small_frame();
        f.channel_count = 3; // 3 channels against 2 configured
        assert_eq!(t.track(&f, 0), Err(TrackError::ChannelMismatch { expected: 2, got: 3 }));
        let mut f = small_frame();
        f.sample_period_ns = 0;
        assert_eq!(t.track(&f, 0), Err(TrackError::ZeroPeriod));
    }

    /// Frames of 2 samples at 10 µs: 20 µs of device time each.
    fn frame_at(sequence: u32, device_time_ns: u64) -> Frame {
        Frame { sequence, device_time_ns, ..small_frame() }
    }

    #[test]
    fn a_frame_starting_late_with_its_sequence_continuing_is_a_time_slip_gap() {
        let mut t = FrameTracker::new("daq", specs());
        assert_eq!(t.track(&frame_at(1233, 0), 0).unwrap().gap, None); // samples at 0, 10 µs
        assert_eq!(t.track(&frame_at(1234, 20_000), 0).unwrap().gap, None); // on time: 20, 30 µs
        // Sequence 1235 should start at 40 µs; it starts at 50 µs: the DAQ lost the sample
        // at 40 µs from its buffer (one 10 µs slip inside the stream).
        let g = t.track(&frame_at(1235, 50_000), 0).unwrap().gap.expect("a gap");
        assert_eq!(g.samples_lost, 1);
        assert_eq!(g.reason, "time_slip: device time jumped by 1 periods at sequence 1235");
        assert!((g.t_s - 40e-6).abs() < 1e-12, "the hole starts where frame 1234 ended");
        // Back on time from there (70 µs), then two periods late (110 µs instead of 90).
        assert_eq!(t.track(&frame_at(1236, 70_000), 0).unwrap().gap, None);
        let g = t.track(&frame_at(1237, 110_000), 0).unwrap().gap.expect("a gap");
        assert_eq!(g.samples_lost, 2);
        assert_eq!(g.reason, "time_slip: device time jumped by 2 periods at sequence 1237");
        assert_eq!(t.stats(), TrackStats { restarts: 0, time_slips: 2 });
    }

    #[test]
    fn jitter_under_half_a_period_is_no_gap_and_time_going_back_is_reported() {
        let mut t = FrameTracker::new("daq", specs());
        t.track(&frame_at(0, 0), 0).unwrap();
        // Due at 20 µs; 4.999 µs late or early is rounding in the device, not a hole.
        assert_eq!(t.track(&frame_at(1, 24_999), 0).unwrap().gap, None);
        assert_eq!(t.track(&frame_at(2, 40_000), 0).unwrap().gap, None);
        // Due at 60 µs, starts at 40 µs again: no sample lost, but never silent.
        let g = t.track(&frame_at(3, 40_000), 0).unwrap().gap.expect("reported");
        assert_eq!(g.samples_lost, 0);
        assert_eq!(g.reason, "time_slip: device time went back by 2 periods at sequence 3");
        assert_eq!(t.stats().time_slips, 1);
    }

    #[test]
    fn when_sequence_and_time_disagree_the_time_counts_the_lost_samples() {
        let mut t = FrameTracker::new("daq", specs());
        t.track(&frame_at(7, 0), 0).unwrap(); // ends at 20 µs
        // Sequence 9: one frame (2 samples) lost, so due at 40 µs; it starts at 50 µs.
        let g = t.track(&frame_at(9, 50_000), 0).unwrap().gap.expect("a gap");
        assert_eq!(g.samples_lost, 3);
        assert_eq!(g.reason, "sequence_jump: 1 frames (2 samples) lost before sequence 9, device time says 3 samples");
        // A restart (sequence back to 0, clock back to 0) is no gap and no slip.
        assert_eq!(t.track(&frame_at(0, 0), 0).unwrap().gap, None);
        assert_eq!(t.stats(), TrackStats { restarts: 1, time_slips: 1 });
    }
}
