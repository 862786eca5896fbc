//! Uniformly sampled signals, shifted and smoothed on their own step: a fit's simulated
//! trace read at the measured samples (`shifted`, and `aligned` from a finer trace), and
//! the centred moving average of the envelope fidelity (`moving_average`). Pure code.

/// Centred moving average over `w` samples (shorter at the ends).
pub fn moving_average(v: &[f64], w: usize) -> Vec<f64> {
    let n = v.len();
    let half = w / 2;
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    for x in v {
        prefix.push(prefix.last().copied().unwrap_or(0.0) + x);
    }
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + w - half).min(n));
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect()
}

/// `n` samples of `v` linearly interpolated at the indices `i + shift` (0 before the first,
/// the last value after): one fractional part for all, so one floor in all.
pub fn shifted(v: &[f64], n: usize, shift: f64) -> Vec<f64> {
    let (Some(&last), true) = (v.last(), shift.is_finite()) else { return vec![0.0; n] };
    // Far beyond the trace either way, every sample is a constant; the clamp keeps the
    // integer arithmetic in range.
    let bound = (v.len() + n + 1) as f64;
    let k_f = shift.floor().clamp(-bound, bound);
    let f = if k_f == shift.floor() { shift - k_f } else { 0.0 };
    let k = k_f as i64;
    // Sample i reads v at j = i + k: 0 while j < 0, the last value from j + 1 = len on, the
    // interpolation between (a loop over slices the compiler vectorises).
    let clamp = |j: i64| j.clamp(0, n as i64) as usize;
    let (lead, tail) = (clamp(-k), clamp(v.len() as i64 - 1 - k).max(clamp(-k)));
    let mut out = Vec::with_capacity(n);
    out.resize(lead, 0.0);
    if lead < tail {
        // Here 0 <= i + k and i + k + 1 < len: both ends index v.
        let (j0, j1) = ((lead as i64 + k) as usize, (tail as i64 + k) as usize);
        out.extend(v[j0..j1].iter().zip(&v[j0 + 1..=j1]).map(|(a, b)| a * (1.0 - f) + b * f));
    }
    out.resize(n, last);
    out
}

/// The model read at a window's `n` samples from its `trace` (step `fine_dt`, `over` steps
/// to a sample), and the model time put at the window's `t_align_s`: the trace's own
/// crossing of `threshold` (the damper's share of the load jumps at first contact, so it
/// may be the very first point).
///
/// Read between finer steps than the samples (`over` > 1), the model is then shifted until
/// its samples, their crossing interpolated as the measured one is, cross at `t_align_s`:
/// the measured crossing, interpolated between samples where the load curves, is late or
/// early by a part of a sample, and the model's then carries the same error.
pub fn aligned(trace: &[f64], fine_dt: f64, over: usize, n: usize, threshold: f64, t_align_s: f64) -> (Vec<f64>, f64) {
    let mut t_cross = crossing(trace, threshold).map_or(0.0, |k| k * fine_dt);
    let len = (n.max(1) - 1) * over + 1;
    let dt = fine_dt * over as f64;
    let read =
        |t: f64| -> Vec<f64> { shifted(trace, len, (t - t_align_s) / fine_dt).into_iter().step_by(over).collect() };
    let mut load = read(t_cross);
    for _ in 0..if over > 1 { ALIGN_ROUNDS } else { 0 } {
        // A sample or more off, the samples crossed elsewhere (a ring's dip): keep the last.
        let Some(off) = crossing(&load, threshold).map(|k| k * dt - t_align_s) else { break };
        if off.abs() >= dt {
            break;
        }
        t_cross += off;
        load = read(t_cross);
    }
    (load, t_cross)
}

/// Rounds of `aligned`'s shift.
const ALIGN_ROUNDS: usize = 2;

/// The fractional index where `v` first rises to `threshold`, interpolated between the
/// samples either side (0 when the first sample is already there; `None` when never).
fn crossing(v: &[f64], threshold: f64) -> Option<f64> {
    match v.iter().position(|&x| x >= threshold)? {
        0 => Some(0.0),
        k => Some((k - 1) as f64 + (threshold - v[k - 1]) / (v[k] - v[k - 1])),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn a_finely_read_model_is_shifted_to_the_sampling_phase_of_the_measured_blow() {
        // A curved rise, 1 - cos, sampled every 100 µs at a phase of 0.37 sample after its
        // start: the measured crossing of 10 %, interpolated between samples, is biased;
        // the model read from a 10 µs trace of the same curve must land on those samples.
        let (dt, over, rise_s) = (1e-4, 10, 6e-4);
        let f = |t: f64| if t <= 0.0 { 0.0 } else { 1.0 - (PI * (t / rise_s).min(1.0)).cos() };
        let phase = 0.37 * dt;
        let measured: Vec<f64> = (0..40).map(|i| f(i as f64 * dt - 10.0 * dt + phase)).collect();
        let threshold = 0.2;
        let t_align = crossing(&measured, threshold).unwrap() * dt;
        let fine_dt = dt / over as f64;
        let trace: Vec<f64> = (0..400).map(|j| f(j as f64 * fine_dt)).collect();
        let (load, _) = aligned(&trace, fine_dt, over, measured.len(), threshold, t_align);
        let worst = load.iter().zip(&measured).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        // Read at the trace's own crossing instead (no shift), the rise is off by more.
        let plain = shifted(&trace, 391, (crossing(&trace, threshold).unwrap() * fine_dt - t_align) / fine_dt);
        let plain_worst = plain.iter().step_by(over).zip(&measured).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 0.01 && plain_worst > 3.0 * worst, "shifted {worst}, unshifted {plain_worst}");
    }

    #[test]
    fn a_shifted_trace_is_the_trace_interpolated_at_each_shifted_index() {
        // Another path: each sample's own index, its own floor and fraction.
        let at = |v: &[f64], x: f64| {
            if x < 0.0 {
                return 0.0;
            }
            let i = x.floor() as usize;
            if i + 1 >= v.len() { v[v.len() - 1] } else { v[i] * (1.0 - (x - i as f64)) + v[i + 1] * (x - i as f64) }
        };
        let v: Vec<f64> = (0..50).map(|i| (f64::from(i) * 0.37).sin() * 1e6).collect();
        for shift in [0.0, 0.25, -0.25, -3.75, 7.5, 48.6, -70.2, 120.0] {
            let got = shifted(&v, 60, shift);
            assert_eq!(got.len(), 60);
            for (i, g) in got.iter().enumerate() {
                // The fraction rounds once here and once per sample there: within 1e-9 of
                // the 1e6 N scale.
                let want = at(&v, i as f64 + shift);
                assert!((g - want).abs() <= 1e-9 * 1e6, "shift {shift}, sample {i}: {g} vs {want}");
            }
        }
        assert_eq!(shifted(&[], 3, 0.5), vec![0.0; 3]);
        assert_eq!(shifted(&v, 2, f64::NAN), vec![0.0; 2]);
        assert_eq!(shifted(&v, 2, 1e300), vec![v[49]; 2]);
        assert_eq!(shifted(&v, 2, -1e300), vec![0.0; 2]);
    }
}
