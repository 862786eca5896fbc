//! Re-batching samples for recording: DESIGN.md §3 wants one message per 10–100 ms per
//! source (a message per sample costs ~47 bytes of MCAP overhead; a DAQ frame may hold a
//! millisecond, a capture file a whole blow). Sans-IO: batches in, batches out.
//!
//! A [`Rebatcher`] serves one source. It joins batches that continue each other (same
//! source, channels and period, and the next device time where the last one ended) and
//! cuts them into pieces of the target duration. Each output batch takes the `seq` and
//! `host_time_ns` of the input batch that holds its first sample, and its `device_time_ns`
//! is that sample's device time. So `seq` jumps by the number of frames joined: in a
//! recording, lost samples are the `/gaps` messages, not `seq` jumps.

use crate::signal::sample::SampleBatch;

/// Default duration of a recorded batch.
pub const DEFAULT_BATCH_NS: f64 = 50e6;

/// Joins and cuts one source's sample batches into batches of a target duration.
#[derive(Debug, Clone)]
pub struct Rebatcher {
    target_ns: f64,
    pending: Option<Pending>,
}

#[derive(Debug, Clone)]
struct Pending {
    batch: SampleBatch,
    /// (first sample index, seq, host time) of each input batch in `batch`.
    frames: Vec<(usize, u64, i64)>,
}

impl Rebatcher {
    /// `target_ns` is the duration of the batches it emits (at least one sample each).
    pub fn new(target_ns: f64) -> Rebatcher {
        Rebatcher { target_ns, pending: None }
    }

    /// Add a batch; every batch that is now complete is appended to `out`.
    pub fn push(&mut self, batch: SampleBatch, out: &mut Vec<SampleBatch>) {
        if batch.is_empty() {
            return;
        }
        match &mut self.pending {
            Some(p) if continues(&p.batch, &batch) => {
                p.frames.push((p.batch.len(), batch.seq, batch.host_time_ns));
                p.batch.values.extend_from_slice(&batch.values);
            }
            _ => {
                if let Some(p) = self.pending.take() {
                    out.push(p.batch);
                }
                let frames = vec![(0, batch.seq, batch.host_time_ns)];
                self.pending = Some(Pending { batch, frames });
            }
        }
        self.cut_complete(out);
    }

    /// Emit what is pending (end of stream, or before a pause).
    pub fn flush(&mut self) -> Option<SampleBatch> {
        self.pending.take().map(|p| p.batch)
    }

    fn cut_complete(&mut self, out: &mut Vec<SampleBatch>) {
        let Some(p) = self.pending.as_mut() else { return };
        let per_batch = samples_per_batch(self.target_ns, p.batch.period_ns);
        while p.batch.len() >= per_batch {
            let channels = p.batch.roles.len();
            if p.batch.len() == per_batch {
                if let Some(done) = self.pending.take() {
                    out.push(done.batch);
                }
                return;
            }
            let rest_values = p.batch.values.split_off(per_batch * channels);
            // The input batch holding sample `per_batch` gives the rest its seq and host time.
            let holder = p.frames.iter().rposition(|f| f.0 <= per_batch).unwrap_or(0);
            let (_, seq, host_time_ns) = p.frames[holder];
            let rest_frames: Vec<(usize, u64, i64)> = std::iter::once((0, seq, host_time_ns))
                .chain(p.frames[holder + 1..].iter().map(|&(i, s, h)| (i - per_batch, s, h)))
                .collect();
            let rest = SampleBatch {
                source: p.batch.source.clone(),
                seq,
                device_time_ns: p.batch.device_time_ns + (p.batch.period_ns * per_batch as f64).round() as i64,
                host_time_ns,
                period_ns: p.batch.period_ns,
                roles: p.batch.roles.clone(),
                values: rest_values,
            };
            let done = std::mem::replace(&mut p.batch, rest);
            p.frames = rest_frames;
            out.push(done);
        }
    }
}

impl Default for Rebatcher {
    fn default() -> Self {
        Rebatcher::new(DEFAULT_BATCH_NS)
    }
}

/// Samples in one output batch: the target duration, at least one sample.
fn samples_per_batch(target_ns: f64, period_ns: f64) -> usize {
    if period_ns > 0.0 && target_ns.is_finite() && target_ns > 0.0 {
        ((target_ns / period_ns).round() as usize).max(1)
    } else {
        usize::MAX
    }
}

/// `next` starts where `prev` ends: same source, channels, period, and a device time
/// within half a period of the expected one.
fn continues(prev: &SampleBatch, next: &SampleBatch) -> bool {
    let expected_ns = prev.device_time_ns as f64 + prev.period_ns * prev.len() as f64;
    prev.source == next.source
        && prev.roles == next.roles
        && prev.period_ns == next.period_ns
        && (next.device_time_ns as f64 - expected_ns).abs() <= 0.5 * prev.period_ns
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::sample::Role;

    /// Frame `k` of `n` samples at 100 kHz (10 µs period), 2 channels; value = sample index.
    fn frame(k: u64, n: usize) -> SampleBatch {
        let first = k as usize * n;
        SampleBatch {
            source: "daq0".into(),
            seq: 100 + k,
            device_time_ns: 5_000_000 + first as i64 * 10_000,
            host_time_ns: 9_000_000_000 + k as i64 * 1_000_000,
            period_ns: 10_000.0,
            roles: vec![Role::Load, Role::Acc],
            values: (first..first + n).flat_map(|i| [i as f64, -(i as f64)]).collect(),
        }
    }

    #[test]
    fn joins_small_frames_into_target_batches() {
        // 1 ms frames of 100 samples; 5 ms target = 500 samples = 5 frames.
        let mut r = Rebatcher::new(5e6);
        let mut out = Vec::new();
        for k in 0..12 {
            r.push(frame(k, 100), &mut out);
        }
        assert_eq!(out.len(), 2);
        assert!(out.iter().all(|b| b.len() == 500));
        assert_eq!((out[0].seq, out[1].seq), (100, 105));
        assert_eq!(out[1].device_time_ns, 5_000_000 + 500 * 10_000);
        assert_eq!(out[1].host_time_ns, frame(5, 100).host_time_ns);
        let rest = r.flush().expect("two frames pending");
        assert_eq!(rest.len(), 200);
        assert_eq!(rest.values[0], 1000.0);
        assert!(r.flush().is_none());
    }

    #[test]
    fn cuts_a_long_batch_and_keeps_every_sample_in_order() {
        let mut r = Rebatcher::new(5e6);
        let mut out = Vec::new();
        r.push(frame(0, 1234), &mut out);
        out.extend(r.flush());
        assert_eq!(out.iter().map(SampleBatch::len).collect::<Vec<_>>(), vec![500, 500, 234]);
        let all: Vec<f64> = out.iter().flat_map(|b| b.values.iter().copied()).collect();
        assert_eq!(all, frame(0, 1234).values);
        for b in &out {
            // Device time of the first sample = index × period.
            assert_eq!(b.device_time_ns, 5_000_000 + b.values[0] as i64 * 10_000);
            assert_eq!(b.seq, 100, "all from the one input batch");
        }
    }

    #[test]
    fn a_discontinuity_closes_the_batch() {
        let mut r = Rebatcher::new(5e6);
        let mut out = Vec::new();
        r.push(frame(0, 100), &mut out);
        r.push(frame(2, 100), &mut out); // frame 1 lost
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].len(), 100);
        r.push(SampleBatch { roles: vec![Role::Disp, Role::Acc], ..frame(3, 100) }, &mut out);
        assert_eq!(out.len(), 2, "other channels");
        r.push(frame(4, 100), &mut out);
        assert_eq!(out.len(), 3, "back to the first channels");
    }

    #[test]
    fn empty_batches_and_odd_periods_are_harmless() {
        let mut r = Rebatcher::new(5e6);
        let mut out = Vec::new();
        r.push(SampleBatch { values: vec![], ..frame(0, 0) }, &mut out);
        assert!(out.is_empty() && r.flush().is_none());
        r.push(SampleBatch { period_ns: 0.0, ..frame(0, 10) }, &mut out);
        assert!(out.is_empty(), "no period: never cut");
        assert_eq!(r.flush().map(|b| b.len()), Some(10));
        assert_eq!(samples_per_batch(1.0, 10_000.0), 1);
    }
}
