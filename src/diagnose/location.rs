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

/// Where an effect acts (issue 41, "location by counterfactual"): the base model's residual
/// less the model with the effect's, sample by sample, each sample in the earlier of its
/// phases in the measured blow and in the model (`Split::of`) and band by band (`localise::ByBand`), each as a
/// share of the base model's total squared error, mean over the same blows. A phase the
/// effect made worse has a negative share.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Acts {
    /// impact, forming, spring_back, post.
    pub removed_by_phase: [f64; 4],
    /// low, mode2, high.
    pub removed_by_band: [f64; 3],
}

/// One blow's squared error over the peak by phase (each over the blow's window length, so
/// that they add up to its nrmse²) and by band (the bands' squares).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Split {
    pub by_phase: [f64; 4],
    pub by_band: [f64; 3],
}

impl Split {
    /// The residual `measured_load − model_load` over the nrmse `window` [from, to), sample
    /// by sample, each sample charged to the earlier of its phase in the measured blow and
    /// in the model (`measured`, `model`): a model that forms too long has its error in the
    /// forming, not in the measured blow's post; a spring-back that lasts longer than the
    /// model's is the spring-back's; a load that rises after the model's is the impact's.
    /// A first contact off the measured one is the impact's (what laying the model's contact
    /// on the measured one removes); a forming that runs longer than the measured one is the
    /// forming's (what laying the model's spring-back on the measured end of forming then
    /// removes: a flow stress the model lacks ends the real forming sooner, and the model's
    /// late spring-back is that forming's doing, as in `localise`; a measured spring-back
    /// longer than the model's stays the spring-back's); and so is the forming's residual ring (its second-mode
    /// part about a one-period mean): the impact set the ring up, its amplitude and its
    /// phase. (`Location` charges only the rings' amplitude difference to the impact; a
    /// counterfactual sees the effect put the ring in phase too: the hammer's clearance of
    /// `tests/independent`, seeds 3/4, was charged 0.50 to the forming against 0.42 to the
    /// impact with the amplitude alone, 0.03 against 0.89 with the ring.) `by_band` as
    /// `localise` gives it (RMS over the peak).
    #[allow(clippy::too_many_arguments)]
    pub fn of(
        measured_load: &[f64],
        model_load: &[f64],
        measured: &Phases,
        model: &Phases,
        window: (usize, usize),
        peak_n: f64,
        ring_samples: usize,
        by_band: [f64; 3],
    ) -> Split {
        let to = window.1.min(measured_load.len());
        let from = window.0.min(measured.contact()).min(to);
        let scale = 1.0 / ((peak_n * peak_n).max(f64::MIN_POSITIVE) * (window.1 - window.0).max(1) as f64);
        let raw = |i: usize| model_load.get(i).copied().unwrap_or(0.0);
        let sum = |f: &dyn Fn(usize) -> f64| (from..to).map(|i| (measured_load[i] - f(i)).powi(2)).sum::<f64>() * scale;
        // A first contact off the measured one is the impact's, a forming that runs longer
        // than the measured one (from the same contact) the forming's: the model laid on the
        // measured contact, then its spring-back on the measured end of forming, and what
        // each step removes charged to that phase, when it removes any.
        let shift = |lag: isize| move |i: usize| usize::try_from(i as isize - lag).map_or(0.0, raw);
        let unshifted = sum(&raw);
        let lag0 = measured.contact() as isize - model.contact() as isize;
        let (lag0, offset0) = match sum(&shift(lag0)) {
            s if s < unshifted => (lag0, unshifted - s),
            _ => (0, 0.0),
        };
        let laid = shift(lag0);
        let lag2 = measured.forming_end() as isize - (model.forming_end() as isize + lag0);
        let ends = |i: usize| {
            let j = if i >= measured.forming_end() { i as isize - lag2 } else { i as isize };
            usize::try_from(j).map_or(0.0, &laid)
        };
        let contact_laid = sum(&laid);
        let (model_at, offset2, lag2): (&dyn Fn(usize) -> f64, f64, isize) = match sum(&ends) {
            s if lag2 < 0 && s < contact_laid => (&ends, contact_laid - s, lag2),
            _ => (&laid, 0.0, 0),
        };
        let mut model = *model;
        model.0 = std::array::from_fn(|k| {
            let b = model.0[k] as isize + lag0 + if k >= 2 { lag2 } else { 0 };
            b.max(0) as usize
        });
        let phase = |i: usize| measured.of(i).min(model.of(i)).clamp(0, 3) as usize;
        let mut by_phase = [offset0, offset2, 0.0, 0.0];
        for i in from..to {
            by_phase[phase(i)] += (measured_load[i] - model_at(i)).powi(2) * scale;
        }
        let forming: Vec<usize> = (from..to).filter(|&i| phase(i) == 1).collect();
        if let (Some(&a), Some(&b)) = (forming.first(), forming.last()) {
            let e: Vec<f64> = (a..=b).map(|i| measured_load[i] - model_at(i)).collect();
            let ring = if ring_samples > 1 { sum_sq(&ring_of(&e, ring_samples)) } else { 0.0 };
            let moved = (ring * scale).min(by_phase[1]);
            by_phase[1] -= moved;
            by_phase[0] += moved;
        }
        Split { by_phase, by_band: by_band.map(|b| b * b) }
    }
}

impl Acts {
    /// From each blow's split under the base model (`before`) and under the model with the
    /// effect (`after`), the same blows in the same order.
    pub fn of(before: &[Split], after: &[Split]) -> Acts {
        // Each part's removed error over the base model's total, summed over the blows.
        fn removed<const N: usize>(pairs: impl Iterator<Item = ([f64; N], [f64; N])>) -> [f64; N] {
            let mut out = [0.0; N];
            let mut total = 0.0;
            for (b, a) in pairs {
                for (o, (x, y)) in out.iter_mut().zip(b.iter().zip(&a)) {
                    *o += x - y;
                }
                total += b.iter().sum::<f64>();
            }
            out.map(|v| if total > 0.0 { v / total } else { 0.0 })
        }
        let pairs = before.iter().zip(after);
        Acts {
            removed_by_phase: removed(pairs.clone().map(|(b, a)| (b.by_phase, a.by_phase))),
            removed_by_band: removed(pairs.map(|(b, a)| (b.by_band, a.by_band))),
        }
    }

    /// The phase whose error the effect removes most.
    pub fn phase(&self) -> &'static str {
        PHASE_NAMES[argmax(&self.removed_by_phase)]
    }

    /// The band whose error the effect removes most.
    pub fn band(&self) -> &'static str {
        BAND_NAMES[argmax(&self.removed_by_band)]
    }
}

fn argmax(x: &[f64]) -> usize {
    (0..x.len()).max_by(|a, b| x[*a].total_cmp(&x[*b])).unwrap_or(0)
}

/// `Acts`' method, as the report states it.
pub const ACTS_METHOD: &str = "counterfactual: the base model's squared load residual less the verdict model's on the holdout \
     blows, sample by sample, each sample charged to the earlier of its phase in the measured blow and in the model (a \
     first contact's offset and the forming's residual ring about its one-period mean are the impact's, a model forming longer \
     than measured the forming's), and band by band, each over the base model's total";

/// The bands' names, in `Acts::removed_by_band` order.
pub const BAND_NAMES: [&str; 3] = ["low", "mode2", "high"];

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

#[cfg(test)]
mod acts_tests {
    use super::*;

    /// A blow's load: a rise over 10 samples from `start`, a forming plateau of `level` to
    /// sample 100 with a ring of `ring` (period 8), a fall over `fall` samples, then zero.
    fn blow(start: usize, level: f64, ring: f64, fall: usize) -> Vec<f64> {
        (0..200)
            .map(|i| {
                let t = i as f64;
                if i < start {
                    0.0
                } else if i < start + 10 {
                    level * (t - start as f64) / 10.0
                } else if i < 100 {
                    level + ring * (std::f64::consts::TAU * t / 8.0).sin()
                } else if i < 100 + fall {
                    level * (1.0 - (t - 100.0) / fall as f64)
                } else {
                    0.0
                }
            })
            .collect()
    }

    fn split(measured: &[f64], model: &[f64], model_phases: Phases) -> Split {
        let phases = Phases([20, 28, 100, 120, 150]);
        Split::of(measured, model, &phases, &model_phases, (model_phases.contact().min(20), 150), 1.0, 8, [0.0; 3])
    }

    // What an effect removes is charged where it acts: a ring the model lacks to the impact
    // that set it up, a level the model misses to the forming, a longer spring-back to the
    // spring-back, a late rise to the impact.
    #[test]
    fn the_counterfactual_names_the_phase_the_correction_acts_in() {
        let measured = blow(20, 1.0, 0.2, 20);
        let same = Phases([20, 28, 100, 120, 150]);
        for (model, phases, expected) in [
            (blow(20, 1.0, 0.0, 20), same, "impact"),
            (blow(20, 0.8, 0.2, 20), same, "forming"),
            (blow(20, 1.0, 0.2, 8), Phases([20, 28, 100, 108, 138]), "spring_back"),
            (blow(14, 1.0, 0.2, 20), Phases([14, 23, 100, 120, 150]), "impact"),
        ] {
            let before = split(&measured, &model, phases);
            let after = split(&measured, &measured, same);
            let acts = Acts::of(&[before], &[after]);
            assert_eq!(acts.phase(), expected, "{acts:?}");
            let total: f64 = acts.removed_by_phase.iter().sum();
            assert!((total - 1.0).abs() < 1e-9, "all of the error is removed: {acts:?}");
        }
    }

    // A model the effect made worse somewhere has a negative share there.
    #[test]
    fn a_phase_made_worse_has_a_negative_share() {
        let measured = blow(20, 1.0, 0.0, 20);
        let same = Phases([20, 28, 100, 120, 150]);
        let before = split(&measured, &blow(20, 0.8, 0.0, 20), same);
        let after = split(&measured, &blow(20, 1.0, 0.0, 40), Phases([20, 28, 100, 140, 170]));
        let acts = Acts::of(&[before], &[after]);
        assert_eq!(acts.phase(), "forming");
        assert!(acts.removed_by_phase[2] < 0.0, "{acts:?}");
    }
}
