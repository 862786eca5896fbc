//! Frames into samples (CONTRACTS.md §7): `FrameTracker` turns decoded frames into
//! `SampleBatch`es in physical units with the configured channels (`offset + gain *
//! count`), and reports a jump in the wrapping u32 sequence as a `Gap` of (jump − 1) × N
//! samples. It keeps its state across reconnects, so an outage shows as a gap. Pure code.

use super::frame::Frame;
use crate::acquire::ChannelSpec;
use crate::record::Gap;
use crate::signal::sample::SampleBatch;

/// Why a well-formed frame could not become samples.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TrackError {
    #[error("frame has {got} channels, the config gives {expected}")]
    ChannelMismatch { expected: usize, got: u8 },
    #[error("frame has sample_period_ns 0")]
    ZeroPeriod,
}

/// A frame turned into samples, with the gap its sequence number reveals.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracked {
    /// Samples lost before this batch (a sequence jump), if any.
    pub gap: Option<Gap>,
    pub batch: SampleBatch,
}

/// Turns frames into `SampleBatch`es with the configured channels (`offset + gain * count`)
/// and watches the sequence: a jump of `j` (wrapping u32) loses `(j − 1) × N` samples
/// (CONTRACTS.md §7). A backwards jump (more than 2³¹ ahead) is a device restart: no gap,
/// the count starts over.
#[derive(Debug, Clone)]
pub struct FrameTracker {
    source: String,
    channels: Vec<ChannelSpec>,
    last_seq: Option<u32>,
    /// The unwrapped sequence of the last frame (`SampleBatch::seq`).
    seq: u64,
    /// Device time just after the last frame's last sample, ns.
    next_device_ns: u64,
    restarts: u64,
}

impl FrameTracker {
    pub fn new(source: impl Into<String>, channels: Vec<ChannelSpec>) -> Self {
        FrameTracker { source: source.into(), channels, last_seq: None, seq: 0, next_device_ns: 0, restarts: 0 }
    }

    /// How often the sequence went backwards (device restarts).
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// The samples of `frame`, received at host time `host_time_ns`.
    pub fn track(&mut self, frame: &Frame, host_time_ns: i64) -> Result<Tracked, TrackError> {
        if frame.channel_count as usize != self.channels.len() {
            return Err(TrackError::ChannelMismatch { expected: self.channels.len(), got: frame.channel_count });
        }
        if frame.sample_period_ns == 0 {
            return Err(TrackError::ZeroPeriod);
        }
        let mut gap = None;
        match self.last_seq {
            None => self.seq = frame.sequence as u64,
            Some(last) => {
                let jump = frame.sequence.wrapping_sub(last);
                if jump == 0 || jump > u32::MAX / 2 {
                    // Repeated or backwards: the device restarted its count.
                    self.restarts += 1;
                    self.seq += 1;
                } else {
                    self.seq += jump as u64;
                    if jump > 1 {
                        gap = Some(Gap {
                            source: self.source.clone(),
                            t_s: self.next_device_ns as f64 * 1e-9,
                            samples_lost: (jump as u64 - 1) * frame.sample_count as u64,
                            reason: "sequence_jump".to_string(),
                        });
                    }
                }
            }
        }
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
        // u32::MAX - 1, u32::MAX, 0 (wrap, no gap), 3 (frames 1 and 2 lost), 4
        for s in [u32::MAX - 1, u32::MAX, 0, 3, 4] {
            f.sequence = s;
            f.device_time_ns = 20_000 * s as u64;
            let out = t.track(&f, 0).unwrap();
            seqs.push(out.batch.seq);
            gaps.extend(out.gap);
        }
        let base = (u32::MAX - 1) as u64;
        assert_eq!(seqs, vec![base, base + 1, base + 2, base + 5, base + 6]);
        assert_eq!(gaps.len(), 1);
        assert_eq!(gaps[0].samples_lost, 2 * 2); // (jump 3 - 1) frames × 2 samples
        assert_eq!(gaps[0].reason, "sequence_jump");
        assert!((gaps[0].t_s - 20e-6).abs() < 1e-12, "the gap starts where frame 0 ended");
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
}
