//! The segmenter's pre-trigger window (`segment::Segmenter`): the latest `cap` samples
//! before a trigger. Between blows every sample passes through it, so it keeps them as the
//! batch values they came in (one copy of a slice), and makes `Sample`s of them only when a
//! trigger takes the window. A sample stepped on its own (one bridging a hole) is kept as
//! it is.

use std::collections::VecDeque;

use super::sample::{Sample, SampleBatch, sample_time_s};

/// Value buffers kept for reuse, so that the window allocates nothing once running.
const SPARE_BUFFERS: usize = 4;

#[derive(Debug, Default)]
pub(crate) struct PreTrigger {
    pieces: VecDeque<Piece>,
    /// Samples held.
    len: usize,
    cap: usize,
    spare: Vec<Vec<f64>>,
}

#[derive(Debug)]
enum Piece {
    One(Sample),
    Run(Run),
}

/// Consecutive samples of one batch.
#[derive(Debug)]
struct Run {
    device_time_ns: i64,
    period_ns: f64,
    /// Channels per sample in `values`, and where load, displacement and acceleration are.
    stride: usize,
    cols: [usize; 3],
    /// The batch's index of the first sample in `values`.
    first: usize,
    /// Samples at the front of `values` already out of the window.
    skip: usize,
    values: Vec<f64>,
}

impl Run {
    fn len(&self) -> usize {
        self.values.len() / self.stride - self.skip
    }

    /// The run's `k`-th sample in the window, timed as its batch times it.
    fn sample(&self, k: usize) -> Sample {
        let i = self.skip + k;
        let t_s = sample_time_s(self.device_time_ns, self.period_ns, self.first + i);
        Sample::from_row(t_s, &self.values[i * self.stride..(i + 1) * self.stride], self.cols)
    }
}

impl Piece {
    fn len(&self) -> usize {
        match self {
            Piece::One(_) => 1,
            Piece::Run(r) => r.len(),
        }
    }
}

impl PreTrigger {
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Keep at most `cap` samples from now on.
    pub fn set_cap(&mut self, cap: usize) {
        self.cap = cap;
        self.trim();
    }

    pub fn push(&mut self, s: Sample) {
        self.pieces.push_back(Piece::One(s));
        self.len += 1;
        self.trim();
    }

    /// Samples `from..to` of `batch`, whose load, displacement and acceleration are the
    /// channels `cols`: the latest `cap` of them copied.
    pub fn extend_from(&mut self, batch: &SampleBatch, from: usize, to: usize, cols: [usize; 3]) {
        let stride = batch.roles.len();
        let first = to - (to - from).min(self.cap);
        if first == to {
            return;
        }
        let mut values = self.spare.pop().unwrap_or_default();
        values.clear();
        values.extend_from_slice(&batch.values[first * stride..to * stride]);
        let run = Run {
            device_time_ns: batch.device_time_ns,
            period_ns: batch.period_ns,
            stride,
            cols,
            first,
            skip: 0,
            values,
        };
        self.pieces.push_back(Piece::Run(run));
        self.len += to - first;
        self.trim();
    }

    pub fn clear(&mut self) {
        while let Some(p) = self.pieces.pop_front() {
            self.recycle(p);
        }
        self.len = 0;
    }

    /// The window's samples appended to `out`, oldest first; the window is left empty.
    pub fn drain_into(&mut self, out: &mut Vec<Sample>) {
        out.reserve(self.len);
        for p in &self.pieces {
            match p {
                Piece::One(s) => out.push(*s),
                Piece::Run(r) => out.extend((0..r.len()).map(|k| r.sample(k))),
            }
        }
        self.clear();
    }

    /// Drop the oldest samples beyond `cap`.
    fn trim(&mut self) {
        while self.len > self.cap {
            let excess = self.len - self.cap;
            let Some(front) = self.pieces.front_mut() else { break };
            let n = front.len();
            if n <= excess {
                if let Some(p) = self.pieces.pop_front() {
                    self.recycle(p);
                }
                self.len -= n;
            } else if let Piece::Run(r) = front {
                r.skip += excess;
                self.len -= excess;
            }
        }
    }

    fn recycle(&mut self, p: Piece) {
        if let Piece::Run(r) = p
            && self.spare.len() < SPARE_BUFFERS
        {
            self.spare.push(r.values);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::sample::Role;

    fn batch(t0_ns: i64, n: usize) -> SampleBatch {
        // Channels in another order than the roles' own: acceleration, load, displacement.
        let values = (0..n).flat_map(|i| [-(i as f64), 1000.0 + i as f64, 0.5 * i as f64]).collect();
        SampleBatch {
            source: "s".into(),
            seq: 0,
            device_time_ns: t0_ns,
            host_time_ns: 0,
            period_ns: 10_000.0,
            roles: vec![Role::Acc, Role::Load, Role::Disp],
            values,
        }
    }

    fn sample_of(b: &SampleBatch, i: usize) -> Sample {
        Sample {
            t_s: b.time_s(i),
            load_n: b.values[i * 3 + 1],
            disp_m: b.values[i * 3 + 2],
            acc_mps2: b.values[i * 3],
            filled: false,
        }
    }

    /// Against the plain window it replaces: a deque of samples, the oldest popped at the cap.
    #[test]
    fn keeps_what_a_deque_of_samples_keeps() {
        for cap in [1, 2, 7, 25, 60] {
            let (mut w, mut plain) = (PreTrigger::default(), VecDeque::new());
            w.set_cap(cap);
            let push = |plain: &mut VecDeque<Sample>, s: Sample| {
                if plain.len() == cap {
                    plain.pop_front();
                }
                plain.push_back(s);
            };
            let filled = Sample { t_s: 9.0, load_n: 1.0, disp_m: 2.0, acc_mps2: 3.0, filled: true };
            let steps: [(i64, usize, usize, usize); 5] =
                [(0, 10, 0, 10), (100_000, 40, 3, 37), (500_000, 5, 0, 5), (0, 0, 0, 0), (900_000, 30, 29, 30)];
            for (t0, n, from, to) in steps {
                let b = batch(t0, n);
                w.extend_from(&b, from, to, [1, 2, 0]);
                (from..to).for_each(|i| push(&mut plain, sample_of(&b, i)));
                w.push(filled);
                push(&mut plain, filled);
                assert_eq!(w.len(), plain.len(), "cap {cap}");
            }
            let mut out = vec![filled];
            w.drain_into(&mut out);
            let expected: Vec<Sample> = std::iter::once(filled).chain(plain.iter().copied()).collect();
            assert_eq!(out, expected, "cap {cap}");
            assert_eq!(w.len(), 0);
        }
    }
}
