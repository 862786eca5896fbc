//! Uniformly sampled signals, shifted and smoothed on their own step: a fit's simulated
//! trace read at the measured samples (`shifted`), and the centred moving average of the
//! envelope fidelity (`moving_average`). Pure code.

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

#[cfg(test)]
mod tests {
    use super::*;

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
