//! Where the gap lies, invariant to timing (issue #17): `baseline.location` in
//! `report.json`.
//!
//! The measured blow and the model are compared phase with phase, not sample with sample:
//! each phase (impact, forming, spring-back, post; `localise::Phases`, each blow on its own
//! instants) is laid on its own normalised time, from 0 at its start to 1 at its end, and
//! the two are compared there (the shape error). What the phase's length is off by is that
//! phase's error too (the duration error): the samples one blow spends in the phase and the
//! other does not carry about the phase's mean square load. A late or early first contact
//! counts to the impact's length.
//!
//! Two things are the impact's wherever they show. The measured impact starts at the ram's
//! own contact (`Reference::t_ram_contact_s`, its accelerometer leaving the approach) when
//! that comes before the load rises: the delay is a clearance closing, and counts to the
//! impact's length. And the forming's ring about its level (one period of the second mode)
//! differs in amplitude from the model's by what the impact set up (a die striking across a
//! clearance rings harder): that difference of RMS, squared, over the forming's samples, is
//! the impact's; the rest of the forming's shape error (its level, and rings drifting apart
//! when the forming runs at another pace) stays the forming's.
//!
//! A model that forms too long therefore has a forming error and a spring-back of the
//! right shape, wherever on the clock that spring-back falls; a spring-back that lasts
//! longer than the model's is the spring-back's, however long the forming was.
//!
//! Each phase's error is its sum of squares over the measured blow's length (contact to the
//! end of `post`) and the peak squared, so the four add up to the blow's mean square error
//! phase with phase; `share` is each phase's part of their sum, mean over the blows. A
//! share, not a density: a phase is named for carrying most of the error, not for being
//! short and wrong (`by_phase` keeps the density, docs/interfaces.md §6).
//!
//! Pure: fed the loads and the phases.

use serde::Serialize;

use super::phases::Phases;

/// The method, as the report states it.
pub const METHOD: &str = "phase_aligned: each phase of the measured and the modelled blow on its own normalised time; \
     a phase's error is its mean square shape error there plus its length error (|model - measured| samples; the impact's \
     is the first contact's offset, the measured one at the ram's own contact when it precedes the load's, the forming's its \
     length from contact) times the phase's mean square load; the forming's ring amplitude error (about a one-period mean of \
     the second mode) is the impact's; share: each \
     phase's part of the sum of squares over the blow, mean over the calibration blows";

/// The four phases, in order, as the report names them.
pub const PHASE_NAMES: [&str; 4] = ["impact", "forming", "spring_back", "post"];

/// One blow's (or a mean's) error by phase: sum of squares over the blow's measured length
/// and its peak squared.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Location {
    pub mean_square: [f64; 4],
}

/// Each phase's share of the error, summing to 1 (all 0 with no error).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Share {
    pub impact: f64,
    pub forming: f64,
    pub spring_back: f64,
    pub post: f64,
}

impl Location {
    /// Locate the residual of `model_load` against `measured_load`, each on its own phases.
    /// `ring_samples`: one period of the machine's second mode, samples (1: no split).
    pub fn of(
        measured_load: &[f64],
        model_load: &[f64],
        measured: &Phases,
        model: &Phases,
        peak_n: f64,
        ring_samples: usize,
    ) -> Location {
        let length = measured.0[4].min(measured_load.len()).saturating_sub(measured.contact()).max(1) as f64;
        let scale = 1.0 / ((peak_n * peak_n).max(f64::MIN_POSITIVE) * length);
        let mut mean_square: [f64; 4] = std::array::from_fn(|k| {
            let m = segment(measured_load, measured, k);
            let s = segment(model_load, model, k);
            duration_error(m, s, length_error(measured, model, k)) * scale
        });
        for k in 0..4 {
            let (m, s) = (segment(measured_load, measured, k), segment(model_load, model, k));
            let e = shape_residual(m, s);
            let (own, impacts) = if k == 1 { split_ring(m, s, &e, ring_samples) } else { (sum_sq(&e), 0.0) };
            mean_square[k] += own * scale;
            mean_square[0] += impacts * scale;
        }
        Location { mean_square }
    }

    /// The mean over blows.
    pub fn mean(all: &[Location]) -> Location {
        let k = 1.0 / all.len().max(1) as f64;
        let mut mean_square = [0.0; 4];
        for l in all {
            for (m, x) in mean_square.iter_mut().zip(l.mean_square) {
                *m += k * x;
            }
        }
        Location { mean_square }
    }

    /// Each phase's part of the error.
    pub fn share(&self) -> Share {
        let total: f64 = self.mean_square.iter().sum();
        let s = |k: usize| if total > 0.0 { self.mean_square[k] / total } else { 0.0 };
        Share { impact: s(0), forming: s(1), spring_back: s(2), post: s(3) }
    }

    /// The phase with the largest error.
    pub fn phase(&self) -> &'static str {
        (0..4)
            .max_by(|a, b| self.mean_square[*a].total_cmp(&self.mean_square[*b]))
            .map_or("forming", |k| PHASE_NAMES[k])
    }
}

/// Phase `k`'s samples of `load`.
fn segment<'a>(load: &'a [f64], phases: &Phases, k: usize) -> &'a [f64] {
    let (a, b) = (phases.0[k].min(load.len()), phases.0[k + 1].min(load.len()));
    &load[a..b.max(a)]
}

/// `x` at normalised time `u` in [0, 1] (linear between samples, sample i at (i + ½)/len).
fn at(x: &[f64], u: f64) -> f64 {
    match x.len() {
        0 => 0.0,
        1 => x[0],
        n => {
            let p = (u * n as f64 - 0.5).clamp(0.0, (n - 1) as f64);
            let i = (p.floor() as usize).min(n - 2);
            x[i] + (p - i as f64) * (x[i + 1] - x[i])
        }
    }
}

/// The measured phase's samples less the model's phase laid on the measured one's
/// normalised time (empty without a model phase).
fn shape_residual(measured: &[f64], model: &[f64]) -> Vec<f64> {
    if model.is_empty() {
        return Vec::new();
    }
    let n = measured.len();
    (0..n).map(|i| measured[i] - at(model, (i as f64 + 0.5) / n as f64)).collect()
}

fn sum_sq(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum()
}

/// `x` less its mean over `w` samples (centred, shorter at the ends): the ring about its
/// level.
fn ring_of(x: &[f64], w: usize) -> Vec<f64> {
    let n = x.len();
    let mut prefix = vec![0.0; n + 1];
    for (i, v) in x.iter().enumerate() {
        prefix[i + 1] = prefix[i] + v;
    }
    let half = w / 2;
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + w - half).min(n));
            x[i] - (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect()
}

/// The forming's shape error `e` (measured `m` less model `s`) split into the forming's own
/// and the impact's: the ring's amplitude is set by the impact (a die striking across a
/// clearance rings harder than the model's), so the difference of the two rings' RMS,
/// squared, over the phase's samples, is the impact's; the rest of the error (the level,
/// and the rings drifting apart when the forming runs at another pace) is the forming's.
/// `w`: one period of the second mode, samples (≤ 1: no split).
fn split_ring(m: &[f64], s: &[f64], e: &[f64], w: usize) -> (f64, f64) {
    let total = sum_sq(e);
    let n = m.len();
    if w <= 1 || n == 0 || s.is_empty() {
        return (total, 0.0);
    }
    let laid: Vec<f64> = (0..n).map(|i| at(s, (i as f64 + 0.5) / n as f64)).collect();
    let rms = |x: &[f64]| (sum_sq(&ring_of(x, w)) / n as f64).sqrt();
    let amplitude = (n as f64 * (rms(m) - rms(&laid)).powi(2)).min(total);
    (total - amplitude, amplitude)
}

/// The samples by which phase `k` is off: the impact by its first contact (its length is a
/// fixed part of the forming's, `localise::IMPACT_FRACTION`, and is the forming's to
/// answer for), the forming by its length from contact to its end, the others by theirs.
fn length_error(measured: &Phases, model: &Phases, k: usize) -> usize {
    let (a, b) = match k {
        0 => return model.contact().abs_diff(measured.contact()),
        1 => (0, 2),
        k => (k, k + 1),
    };
    (model.0[b] - model.0[a]).abs_diff(measured.0[b] - measured.0[a])
}

/// `samples` of length error times the mean square load of the longer of the two phases.
fn duration_error(measured: &[f64], model: &[f64], samples: usize) -> f64 {
    let longer = if model.len() > measured.len() { model } else { measured };
    if longer.is_empty() {
        return 0.0;
    }
    samples as f64 * longer.iter().map(|x| x * x).sum::<f64>() / longer.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A trapezoid blow sampled at 1 per unit: contact at 10, impact to `10 + f/10`, forming
    /// at `level` to `10 + f`, unloading linearly over `u`, 50 samples of post; its phases.
    fn blow(level: f64, f: usize, u: usize) -> (Vec<f64>, Phases) {
        let (c, fe) = (10, 10 + f);
        let zero = fe + u;
        let load: Vec<f64> = (0..zero + 60)
            .map(|i| match i {
                i if i < c => 0.0,
                i if i < fe => level,
                i if i < zero => level * (zero - i) as f64 / u as f64,
                _ => 0.0,
            })
            .collect();
        (load, Phases([c, c + f / 10, fe, zero, zero + 50]))
    }

    #[test]
    fn a_perfect_model_has_no_error_anywhere() {
        let (m, p) = blow(1.0, 100, 20);
        let l = Location::of(&m, &m, &p, &p, 1.0, 1);
        assert_eq!(l.mean_square, [0.0; 4]);
        assert_eq!(l.share(), Share::default());
    }

    #[test]
    fn a_long_forming_is_the_formings_even_where_the_model_unloads_late() {
        // Measured: 1.2 at 70 samples of forming; model 1.0 for 90: its spring-back (same
        // 20 samples) comes 20 samples late, which sample by sample is a spring-back error.
        let (m, pm) = blow(1.2, 70, 20);
        let (s, ps) = blow(1.0, 90, 20);
        let l = Location::of(&m, &s, &pm, &ps, 1.2, 1);
        assert_eq!(l.phase(), "forming", "{l:?}");
        // The spring-back keeps only its level difference on its own time: a ramp from 1.2
        // against one from 1.0 over the same 20 samples, 0.2·k/20 apart at k = 20..1, exact
        // (equal lengths resample onto the samples), over the blow's 140 samples; against
        // the forming's 63 samples of 0.2² plus 20 of 1.0² from its length (contact to end:
        // 90 samples against 70).
        let sb = (1..=20).map(|k| (0.2 * k as f64 / 20.0).powi(2)).sum::<f64>() / 140.0 / 1.44;
        assert!((l.mean_square[2] / sb - 1.0).abs() < 1e-9, "{l:?}");
        assert!(l.share().forming > 0.8, "{:?}", l.share());
    }

    #[test]
    fn a_long_spring_back_is_the_spring_backs_even_after_a_short_forming() {
        // Measured: forming 5 samples longer and unloading over 80 samples against 20.
        let (m, pm) = blow(1.0, 75, 80);
        let (s, ps) = blow(1.0, 70, 20);
        let l = Location::of(&m, &s, &pm, &ps, 1.0, 1);
        assert_eq!(l.phase(), "spring_back", "{l:?}");
        // Laid on its own time the ramps coincide (to their sampling, half a model sample
        // of 1/20: under 0.2 % here): the error is the length's, 60 samples of the measured
        // ramp's mean square (k/80 at k = 80..1), over the blow's 205 samples.
        let ramp = (1..=80).map(|k| (k as f64 / 80.0).powi(2)).sum::<f64>() / 80.0;
        assert!((l.mean_square[2] / (60.0 * ramp / 205.0) - 1.0).abs() < 0.005, "{l:?}");
    }

    #[test]
    fn a_late_contact_is_the_impacts() {
        // The same blow, the model's 8 samples early (a clearance it lacks).
        let (m, pm) = blow(1.0, 100, 20);
        let mut s = m[8..].to_vec();
        s.extend([0.0; 8]);
        let ps = Phases(pm.0.map(|i| i - 8));
        let l = Location::of(&m, &s, &pm, &ps, 1.0, 1);
        assert_eq!(l.phase(), "impact", "{l:?}");
        assert_eq!(&l.mean_square[1..], &[0.0; 3]);
        let share = l.share();
        let sum = share.impact + share.forming + share.spring_back + share.post;
        assert!((sum - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_harder_ring_through_the_forming_is_the_impacts() {
        // The same blow, the measured one ringing at ±0.3 with a period of 8 samples through
        // its forming: a level error of none, a ring the impact set up.
        let (s, p) = blow(1.0, 100, 20);
        let mut m = s.clone();
        for (i, x) in m.iter_mut().enumerate().take(p.forming_end()).skip(p.0[1]) {
            *x += 0.3 * (2.0 * std::f64::consts::PI * i as f64 / 8.0).sin();
        }
        let l = Location::of(&m, &s, &p, &p, 1.0, 8);
        assert_eq!(l.phase(), "impact", "{l:?}");
        // The ring's RMS is 0.3/√2 over the forming's 90 samples, the model's none: all of the
        // forming's error is its amplitude (to the ends, where the mean over 8 samples is
        // cut: under 10 % of it here).
        assert!(l.mean_square[1] < 0.1 * l.mean_square[0], "{l:?}");
        // Without the split (one-sample period) it is the forming's.
        assert_eq!(Location::of(&m, &s, &p, &p, 1.0, 1).phase(), "forming");
    }

    #[test]
    fn resampling_is_linear_and_stays_within_the_samples() {
        let x = [0.0, 1.0, 2.0, 3.0];
        assert_eq!(at(&x, 0.0), 0.0);
        assert_eq!(at(&x, 1.0), 3.0);
        assert!((at(&x, 0.5) - 1.5).abs() < 1e-12);
        assert_eq!(at(&[], 0.3), 0.0);
    }
}
