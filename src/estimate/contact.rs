//! First contact between samples (issue 16, "height from the encoder"): where the load
//! began to rise, from a hinge fitted to the start of the rise, so that the encoder's
//! height chain keeps no bias from a contact seen late.
//!
//! The segmenter's contact sample is where the load left its noise band. On a stiff blow
//! that is within a sample of contact; on a soft one it is not: the press paper's first
//! copper blow rises at about 100 kN/ms, so with 3 kN of noise the load leaves the band
//! some 75 µm of ram travel after contact, which at 50 kHz is eleven samples. A line
//! through a few samples after the contact sample cannot see that far back through the
//! noise; a hinge `load = s · shape(t − t_c)`, zero before t_c, fitted to the samples
//! before the contact sample (zero load) and the rise after it (up to `RISE_CAP_FRACTION`
//! of the peak) can.
//!
//! The shape is the billet's own when its process sheet is known (`RiseModel`): a
//! Hansel–Spittel flow stress with a negative m4 (the press paper's copper, Table 2) is
//! nearly zero for the first tens of micrometres of compression, so the load's rise is
//! convex and a straight line through it puts contact late. Without a sheet the shape is a
//! straight line, `max(0, t − t_c)`. Either way the scale `s` is free: the sheet's flow
//! stress need not be the billet's.

use crate::physics::billet::BilletLaw;
use crate::physics::machine::{Machine, series};
use crate::signal::segment::Blow;

/// The billet's load against the ram's travel from contact, for the hinge's shape.
pub struct RiseModel<'a> {
    pub law: &'a BilletLaw,
    /// The billet's height at contact, m.
    pub h0_m: f64,
    /// Impact speed, m/s.
    pub v0_mps: f64,
    /// Stiffness in series with the billet under a slowly rising load, N/m
    /// (`support_stiffness`).
    pub k_series_n_per_m: f64,
}

impl RiseModel<'_> {
    /// The load (up to the free scale) `tau_s` after contact. The ram's travel `v0 τ` is
    /// the billet's compression plus the support's deflection `F / k`: the load is the
    /// support's `k v0 τ` while the billet holds it (elastic), else the root of
    /// `F = law(h0 − v0 τ + F / k)` below that (plastic), found by regula falsi.
    fn load_n(&self, tau_s: f64) -> f64 {
        if tau_s <= 0.0 {
            return 0.0;
        }
        let k = self.k_series_n_per_m;
        let travel = self.v0_mps * tau_s;
        let rate = self.v0_mps / self.h0_m;
        let g = |f: f64| self.law.load((self.h0_m - travel + f / k).max(1e-6), rate).total_n - f;
        let (mut a, mut b) = (0.0, k * travel);
        let (mut ga, mut gb) = (g(a), g(b));
        if gb >= 0.0 {
            return b;
        }
        for _ in 0..ROOT_STEPS {
            let c = (a * gb - b * ga) / (gb - ga);
            let gc = g(c);
            if gc > 0.0 {
                (a, ga) = (c, gc);
                gb *= 0.5;
            } else {
                (b, gb) = (c, gc);
                ga *= 0.5;
            }
        }
        0.5 * (a + b)
    }

    /// `load_n` tabulated every `TABLE_STEP` samples of `period_s` up to `span` samples.
    fn table(&self, period_s: f64, span: f64) -> Vec<f64> {
        let n = (span / TABLE_STEP).ceil() as usize + 2;
        (0..n).map(|j| self.load_n(j as f64 * TABLE_STEP * period_s)).collect()
    }
}

/// Regula falsi steps of `RiseModel::load_n` (Illinois variant: superlinear).
const ROOT_STEPS: usize = 12;
/// The rise shape's table step, samples.
const TABLE_STEP: f64 = 0.05;

/// Linear interpolation in a table of step `TABLE_STEP` starting at 0, zero before it.
fn interpolate(table: &[f64], t: f64) -> f64 {
    if t <= 0.0 || table.is_empty() {
        return 0.0;
    }
    let x = t / TABLE_STEP;
    let j = x.floor() as usize;
    match (table.get(j), table.get(j + 1)) {
        (Some(a), Some(b)) => a + (b - a) * (x - j as f64),
        _ => table.last().copied().unwrap_or(0.0),
    }
}

/// The stiffness that carries the load in series with the billet while it rises slowly,
/// for the rise's shape: a press's sensor, tool contact and frame. `None` for a hammer:
/// there the lower tool's inertia, not a spring, takes the first of the load (its frame
/// spring is a hundred times softer than the rise), so the rise is fitted as a line.
pub fn support_stiffness(machine: &Machine) -> Option<f64> {
    match machine {
        Machine::Hammer(_) => None,
        Machine::ScrewPress(p) => Some(series(series(p.k_sensor_n_per_m, p.k_tool_contact_n_per_m), p.k_frame_n_per_m)),
    }
}

/// The rise enters the hinge fit up to this fraction of the blow's peak load (at least the
/// first `MIN_RISE_SAMPLES`, and the whole run of rising samples among the first
/// `RISING_RUN_SAMPLES`): the start of the rise, before the billet's flow bends it far.
pub const RISE_CAP_FRACTION: f64 = 0.1;
pub const MIN_RISE_SAMPLES: usize = 2;
pub const RISING_RUN_SAMPLES: usize = 4;
/// Most rise samples fitted.
pub const MAX_RISE_SAMPLES: usize = 256;
/// The located contact lies at most this many samples before the segmenter's contact
/// sample, and at most `CONTACT_AFTER_SAMPLES` after it.
pub const CONTACT_BEFORE_SAMPLES: f64 = 64.0;
pub const CONTACT_AFTER_SAMPLES: f64 = 0.5;
/// Zero-load samples before the contact sample in the fit: at least this many, and as many
/// as the back bound allows.
pub const MIN_PRE_SAMPLES: usize = 8;
/// The hinge's grid: a coarse step over the bounds, then a fine one around the best.
const COARSE_STEP: f64 = 0.5;
const FINE_STEP: f64 = 0.01;

/// First contact, in samples after the segmenter's contact sample (negative: before it),
/// with the rise shaped by `rise` when given, else a straight line. 0 when the rise is too
/// short to fit.
pub fn contact_between_samples(blow: &Blow, rise: Option<&RiseModel<'_>>) -> f64 {
    let i = blow.i_contact;
    let Some(load) = blow.samples.get(..=blow.i_end.min(blow.samples.len().saturating_sub(1))) else {
        return 0.0;
    };
    let z: Vec<f64> = load.iter().map(|s| s.load_n - blow.load_zero_n).collect();
    if i + MIN_RISE_SAMPLES > z.len() {
        return 0.0;
    }
    let Some(model) = rise else {
        return line_through_rise(&z, i);
    };
    let rise_end = rise_end(&z, i);
    // As many zero-load samples before as the back bound allows: contact can lie that far.
    let pre = (CONTACT_BEFORE_SAMPLES as usize).max(2 * (rise_end - i)).max(MIN_PRE_SAMPLES).min(i);
    let window: Vec<(f64, f64)> = (i - pre..rise_end).map(|k| (k as f64 - i as f64, z[k])).collect();
    let lo = -(CONTACT_BEFORE_SAMPLES.min(pre as f64));
    let table = model.table(blow.period_s, (rise_end - i) as f64 - lo);
    hinge(&window, lo, CONTACT_AFTER_SAMPLES, |t| interpolate(&table, t)).unwrap_or(0.0)
}

/// Without a billet law: a line through the run of rising samples from the contact sample
/// (at most `RISING_RUN_SAMPLES`), extrapolated back to zero, at most `LINE_BEFORE_SAMPLES`
/// back: the locator the hammer's rates were tuned with. A hammer's rise is steep and
/// straight, and at 5–50 kHz the model fit places contact itself from this start. The
/// straight hinge over zero-load samples and a longer rise gave the same end heights on the
/// assert seed at every rate (within 0.2 µm), so the simpler locator stays.
fn line_through_rise(z: &[f64], i: usize) -> f64 {
    let mut pts: Vec<(f64, f64)> = Vec::with_capacity(RISING_RUN_SAMPLES);
    for (j, &v) in z.iter().skip(i).take(RISING_RUN_SAMPLES).enumerate() {
        if pts.last().is_some_and(|p: &(f64, f64)| v <= p.1) {
            break;
        }
        pts.push((j as f64, v));
    }
    if pts.len() < MIN_RISE_SAMPLES {
        return 0.0;
    }
    let n = pts.len() as f64;
    let (st, sy) = pts.iter().fold((0.0, 0.0), |(a, b), (t, y)| (a + t, b + y));
    let (stt, sty) = pts.iter().fold((0.0, 0.0), |(a, b), (t, y)| (a + t * t, b + t * y));
    let slope = (n * sty - st * sy) / (n * stt - st * st);
    let intercept = (sy - slope * st) / n;
    if !(slope.is_finite() && slope > 0.0) {
        return 0.0;
    }
    (-intercept / slope).clamp(-LINE_BEFORE_SAMPLES, CONTACT_AFTER_SAMPLES)
}

/// How far back `line_through_rise` may put contact, samples.
pub const LINE_BEFORE_SAMPLES: f64 = 3.0;

/// One past the last rise sample fitted.
fn rise_end(z: &[f64], i: usize) -> usize {
    let peak = z[i..].iter().copied().fold(0.0, f64::max);
    let cap = RISE_CAP_FRACTION * peak;
    let limit = (i + MAX_RISE_SAMPLES).min(z.len());
    let below_cap = (i..limit).find(|&k| z[k] >= cap).unwrap_or(limit);
    let mut rising = i + 1;
    while rising < (i + RISING_RUN_SAMPLES).min(limit) && z[rising] > z[rising - 1] {
        rising += 1;
    }
    below_cap.max(rising).max(i + MIN_RISE_SAMPLES).min(limit)
}

/// The contact instant `t_c` in [`lo`, `hi`] that best fits `y = s · shape(t − t_c)`,
/// `s > 0`, to the points (t, y), by least squares. `shape` is zero for t ≤ 0.
fn hinge(pts: &[(f64, f64)], lo: f64, hi: f64, shape: impl Fn(f64) -> f64) -> Option<f64> {
    // For a fixed t_c the best s is Σ y h / Σ h² (h = shape(t − t_c)), and the squared
    // error is Σ y² less (Σ y h)² / Σ h²: maximise the latter.
    let score = |tc: f64| {
        let (mut yh, mut hh) = (0.0, 0.0);
        for &(t, y) in pts {
            let h = shape(t - tc);
            yh += y * h;
            hh += h * h;
        }
        if yh > 0.0 && hh > 0.0 { yh * yh / hh } else { f64::NEG_INFINITY }
    };
    let best_on = |from: f64, to: f64, step: f64| {
        let n = ((to - from) / step).ceil().max(0.0) as usize;
        (0..=n).map(|j| (from + j as f64 * step).min(to)).map(|t| (t, score(t))).max_by(|a, b| a.1.total_cmp(&b.1))
    };
    let (coarse, s) = best_on(lo, hi, COARSE_STEP)?;
    if !s.is_finite() {
        return None;
    }
    best_on((coarse - COARSE_STEP).max(lo), (coarse + COARSE_STEP).min(hi), FINE_STEP).map(|(t, _)| t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ramp that starts between samples, seen through noise: the hinge finds its start
    /// to a fraction of a sample, where the noise band would put it many samples late.
    #[test]
    fn the_hinge_finds_a_slow_rise_between_samples() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let noise = Normal::new(0.0, 3e3).expect("sd");
        // The press paper's first blow at 50 kHz: 2 kN a sample from t = -11.3.
        let tc = -11.3;
        let pts: Vec<(f64, f64)> =
            (-20..14).map(|k| k as f64).map(|t| (t, 2e3 * (t - tc).max(0.0) + noise.sample(&mut rng))).collect();
        let found = hinge(&pts, -20.0, 0.5, |t| t.max(0.0)).expect("a fit");
        // ±1 sample: the slope's 2 kN a sample against 3 kN of noise over 25 rise samples
        // gives the intercept a standard error near half a sample.
        assert!((found - tc).abs() < 1.0, "{found} vs {tc}");
    }

    /// A flat window has no rise to fit.
    #[test]
    fn no_rise_no_contact() {
        let pts: Vec<(f64, f64)> = (-8..4).map(|k| (k as f64, -1.0)).collect();
        assert_eq!(hinge(&pts, -8.0, 0.5, |t| t.max(0.0)), None);
    }
}
