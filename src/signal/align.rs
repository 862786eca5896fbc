//! Each source's device clock mapped onto host time (DESIGN.md §3: crystals drift
//! 20–50 ppm, enough to misalign channels from different sources over a shift).
//!
//! The model is `host = offset + rate · device`, fitted online from (device time, host
//! receive time) pairs, one per batch. Receive times are late by a transport delay that is
//! never negative and varies, so both the rate and the offset come from the lower
//! envelope (the batches that arrived fastest): the rate is the slope through the fastest
//! batch of each stretch of a sliding window, the offset the smallest residual. Pure: the
//! caller passes both times.

use std::collections::VecDeque;

/// Pairs kept in the window: at one batch per 50 ms, 25 s of history.
pub const WINDOW: usize = 512;
/// Stretches of the window whose fastest batch the slope goes through.
pub const SEGMENTS: usize = 8;
/// Largest drift a device clock is credited with, ppm: ten times the worst crystal DESIGN.md
/// §3 names (20–50 ppm). A steeper slope comes from the transport, not the clock: a reader
/// that starts late and drains a backlog in one burst, or one starved by a busy host, gives
/// pairs whose host times are compressed (seen: slopes 30 % off in the first 0.3 s).
pub const MAX_DRIFT_PPM: f64 = 500.0;
/// The published mapping follows the fitted one without jumps: a change of the fit smaller
/// than this is slewed in (as NTP slews a clock), a larger one is a step, taken at once.
/// Each batch can move the fit's offset by tens of µs (a new fastest batch, a new slope);
/// stored at once, that is a jump within a role's track, and a 60 µs jump in a ram encoder
/// at 5 m/s is a 0.3 mm step that a 10 ms approach fit reads as a 1 % speed error.
pub const MAX_SLEW_NS: f64 = 250_000.0;
/// Fastest slew, as a rate change: 500 ppm moves the ram encoder's time base so little that
/// a speed reads 0.05 % off, and takes up 60 µs in 120 ms.
pub const SLEW_RATE: f64 = 500e-6;
/// A slewed change is taken up over this much device time, or more (`SLEW_RATE`), ns.
const SLEW_OVER_NS: f64 = 10_000_000.0;

/// What the published mapping still lacks of the fit: `gap` ns at device time `from`
/// (relative to the origin), taken up linearly over the `over` ns after it.
#[derive(Debug, Clone, Copy, Default)]
struct Slew {
    from: f64,
    gap: f64,
    over: f64,
}

impl Slew {
    /// The part of the gap still left at device time `d`.
    fn left(&self, d: f64) -> f64 {
        if self.over <= 0.0 { 0.0 } else { self.gap * (1.0 - (d - self.from) / self.over).clamp(0.0, 1.0) }
    }
}

/// The clock model of one source.
#[derive(Debug, Clone)]
pub struct ClockModel {
    /// (device ns, host ns) relative to the first pair, to keep the sums well conditioned.
    pairs: VecDeque<(f64, f64)>,
    origin: Option<(i64, i64)>,
    rate: f64,
    offset_ns: f64,
    /// The published mapping is the fit less what is still being slewed in.
    slew: Slew,
    /// The newest device time observed, relative to the origin: the last one mapped.
    newest: f64,
}

impl Default for ClockModel {
    /// No pairs yet: the device clock is taken as the host's (rate 1, offset 0).
    fn default() -> Self {
        ClockModel {
            pairs: VecDeque::new(),
            origin: None,
            rate: 1.0,
            offset_ns: 0.0,
            slew: Slew::default(),
            newest: 0.0,
        }
    }
}

impl ClockModel {
    pub fn new() -> Self {
        Self::default()
    }

    /// Observe that the sample at `device_ns` reached the host at `host_ns`.
    pub fn observe(&mut self, device_ns: i64, host_ns: i64) {
        let first = self.origin.is_none();
        let (d0, h0) = *self.origin.get_or_insert((device_ns, host_ns));
        // Where the published mapping stands at the last device time it has mapped: the
        // next mapping starts from there, whatever the new fit says.
        let before = self.newest;
        let published = self.published(before);
        let (d, h) = ((device_ns - d0) as f64, (host_ns - h0) as f64);
        if self.pairs.len() == WINDOW {
            self.pairs.pop_front();
        }
        self.pairs.push_back((d, h));
        // The slope through the fastest batch of each of SEGMENTS stretches of the window:
        // minima of the delay carry almost none of its jitter.
        if self.pairs.len() >= 2 * SEGMENTS {
            let per = self.pairs.len() / SEGMENTS;
            let rate = self.rate;
            let fastest: Vec<(f64, f64)> = (0..SEGMENTS)
                .filter_map(|k| {
                    self.pairs
                        .range(k * per..(k + 1) * per)
                        .copied()
                        .min_by(|a, b| (a.1 - rate * a.0).total_cmp(&(b.1 - rate * b.0)))
                })
                .collect();
            let n = fastest.len() as f64;
            let (sd, sh) = fastest.iter().fold((0.0, 0.0), |(a, b), (d, h)| (a + d, b + h));
            let (md, mh) = (sd / n, sh / n);
            let (num, den) =
                fastest.iter().fold((0.0, 0.0), |(a, b), (d, h)| (a + (d - md) * (h - mh), b + (d - md) * (d - md)));
            if den > 0.0 {
                let bound = MAX_DRIFT_PPM * 1e-6;
                self.rate = (num / den).clamp(1.0 - bound, 1.0 + bound);
            }
        }
        self.offset_ns = self.pairs.iter().map(|(d, h)| h - self.rate * d).fold(f64::INFINITY, f64::min);
        // Publish: from where the published mapping stood, slew onto the fit, or step.
        let gap = self.offset_ns + self.rate * before - published;
        self.slew = if first || gap.abs() > MAX_SLEW_NS {
            Slew::default()
        } else {
            Slew { from: before, gap, over: SLEW_OVER_NS.max(gap.abs() / SLEW_RATE) }
        };
        self.newest = self.newest.max(d);
    }

    /// The published mapping at device time `d` relative to the origin, host ns relative
    /// to the origin.
    fn published(&self, d: f64) -> f64 {
        self.offset_ns + self.rate * d - self.slew.left(d)
    }

    /// Host time of device time `device_ns` (the device time itself before any pair), on
    /// the published mapping: the fit, slewed in (`MAX_SLEW_NS`).
    pub fn map(&self, device_ns: i64) -> i64 {
        match self.origin {
            None => device_ns,
            Some((d0, h0)) => h0 + self.published((device_ns - d0) as f64).round() as i64,
        }
    }

    /// Host ns per device ns, as fitted (the published mapping's slope within 500 ppm).
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Device clock drift against the host, ppm (positive: the device runs slow).
    pub fn drift_ppm(&self) -> f64 {
        (self.rate - 1.0) * 1e6
    }

    /// Pairs in the window.
    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Exp};

    /// A device whose crystal runs 40 ppm slow, 3.7 s off the host, delivering 50 ms
    /// batches with exponential transport delays (mean 1 ms, some far longer).
    #[test]
    fn recovers_drift_and_offset_through_jittery_delays() {
        let mut m = ClockModel::new();
        let mut rng = StdRng::seed_from_u64(3);
        let delay = Exp::new(1.0 / 1e6).unwrap(); // mean 1 ms, in ns
        let true_host = |device_ns: i64| 3_700_000_000 + (device_ns as f64 * (1.0 + 40e-6)) as i64;
        for k in 0..1200 {
            let d = 50_000_000 * k;
            m.observe(d, true_host(d) + delay.sample(&mut rng) as i64);
        }
        // 60 s of batches: the drift within 1 ppm (crystals drift 20–50 ppm, DESIGN.md §3)...
        assert!((m.drift_ppm() - 40.0).abs() < 1.0, "{}", m.drift_ppm());
        // ... and a mapped time within 0.1 ms of the truth, 10 times better than the delays.
        let d = 60_000_000_000;
        let err_ns = (m.map(d) - true_host(d)).abs();
        assert!(err_ns < 100_000, "{err_ns} ns");
    }

    /// A service that starts late: the first 300 ms of batches wait in the serial buffer
    /// and are read in one burst (their receive times 1 ms apart), then the device is
    /// read as it sends. The burst's compressed times are transport, not drift.
    #[test]
    fn a_backlog_read_in_one_burst_is_not_taken_for_drift() {
        let mut m = ClockModel::new();
        let true_host = |device_ns: i64| 2_000_000_000 + (device_ns as f64 * (1.0 + 40e-6)) as i64;
        let batch_ns = 10_000_000;
        let burst_at = true_host(30 * batch_ns);
        let mut worst_ns = 0;
        for k in 0..100 {
            let d = batch_ns * k;
            let host = if k < 30 { burst_at + 1_000_000 * k } else { true_host(d) + 200_000 };
            m.observe(d, host);
            // Once the burst is drained, every batch maps within 0.5 ms of its true time
            // (the jitterless 0.2 ms transport delay, plus at most 500 ppm over 1 s).
            if k >= 30 {
                worst_ns = worst_ns.max((m.map(d) - true_host(d)).abs());
            }
        }
        assert!(worst_ns < 500_000, "{worst_ns} ns");
        assert!(m.drift_ppm().abs() <= MAX_DRIFT_PPM, "{}", m.drift_ppm());
    }

    /// 1 s of `batch_ns` batches of 100 kHz samples, each received 1 ms after its last
    /// sample until batch `fast_from`, `faster_ns` sooner from then on (a new fastest batch:
    /// the fit's offset moves by `faster_ns`). Returns the worst gap between a batch's first
    /// mapped sample and the previous batch's last beyond one sample period, and the model.
    fn consecutive_samples(batch_ns: i64, fast_from: i64, faster_ns: i64) -> (f64, ClockModel) {
        let mut m = ClockModel::new();
        let period_ns = 10_000i64;
        let mut worst_gap: f64 = 0.0;
        let mut last_mapped: Option<i64> = None;
        for k in 0..1_000_000_000 / batch_ns {
            let first = batch_ns * k;
            let last = first + batch_ns - period_ns;
            let delay = if k >= fast_from { 1_000_000 - faster_ns } else { 1_000_000 };
            m.observe(last, 5_000_000_000 + last + delay);
            // The merge maps the batch's samples as it arrives: its first sample must follow
            // the previous batch's last by one sample period.
            if let Some(prev) = last_mapped {
                worst_gap = worst_gap.max(((m.map(first) - prev) as f64 - period_ns as f64).abs());
            }
            last_mapped = Some(m.map(last));
        }
        (worst_gap, m)
    }

    /// The fit's own mapping of `d`, unslewed.
    fn fitted(m: &ClockModel, d: i64) -> i64 {
        let (d0, h0) = m.origin.unwrap();
        h0 + (m.offset_ns + m.rate * (d - d0) as f64).round() as i64
    }

    #[test]
    fn a_fit_that_moves_by_tens_of_microseconds_is_slewed_in_not_jumped() {
        // Batches of 10 ms (the merge test's) and 50 ms (`capture::DEFAULT_BATCH_S`); the
        // fit moves by 60 µs at 0.3 s.
        for batch_ns in [10_000_000, 50_000_000] {
            let (gap, m) = consecutive_samples(batch_ns, 300_000_000 / batch_ns, 60_000);
            // Continuous: one period on, within what the slope may differ from 1 over it
            // (MAX_DRIFT_PPM + SLEW_RATE, 1000 ppm of 10 µs: 10 ns) and two roundings to
            // 1 ns. The unslewed fit jumps by 60 µs: a 0.3 mm step in a ram encoder at
            // 5 m/s, a 1 % speed error in the 10 ms approach fit (the two-DAQ merge test).
            let bound = 10_000.0 * (MAX_DRIFT_PPM * 1e-6 + SLEW_RATE) + 1.0;
            assert!(gap <= bound, "{batch_ns} ns batches: {gap} ns");
            // And on the fit (to its rounding) once 60 µs at 500 ppm, 120 ms, have passed.
            let d = 1_000_000_000;
            assert!((m.map(d) - fitted(&m, d)).abs() <= 1, "{batch_ns} ns batches: {} vs {}", m.map(d), fitted(&m, d));
        }
    }

    #[test]
    fn a_fit_that_moves_by_more_than_the_slew_bound_is_a_step() {
        // A transport 1 ms faster from 0.6 s on: the fit's offset moves by 1 ms, more than
        // MAX_SLEW_NS, and the mapping takes it at once.
        let (gap, _) = consecutive_samples(10_000_000, 60, 1_000_000);
        assert!((gap - 1e6).abs() < 1e3, "{gap} ns");
    }

    #[test]
    fn before_any_pair_the_device_time_is_kept() {
        assert_eq!(ClockModel::new().map(42), 42);
    }
}
