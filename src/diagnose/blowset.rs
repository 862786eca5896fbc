//! The blows a diagnosis fits or scores (`BlowSet`): the objective's references with each
//! blow's baseline window, and how a model with given effects is scored on them.

use crate::identify::clip::adc_step;
use crate::identify::objective::{Objective, Reference, Setting, Simulated};
use crate::physics::billet::{BilletLaw, LoadEffects};
use crate::physics::effects::EffectSet;
use crate::physics::machine::Machine;

use super::localise::nrmse;

/// The fewest periods of a ring in a blow's window that `ring_band_hz` counts: under two,
/// a foundation's spring is a compliance to the blow, which the coarse grid and the local
/// search fit without a fine scan.
const RING_MIN_PERIODS: f64 = 2.0;
/// The fewest samples a period of a ring that `ring_band_hz` counts: a ring sampled more
/// coarsely is lost in the sensor's anti-alias filter and the blow's own high band.
const RING_SAMPLES_PER_PERIOD: f64 = 10.0;

/// Blows to fit or score: the objective (references, process, kind) and each blow's
/// baseline window.
#[derive(Debug, Clone)]
pub struct BlowSet {
    pub obj: Objective,
    pub windows: Vec<(usize, usize)>,
    pub mode2_hz: f64,
}

impl BlowSet {
    /// Residuals of the model with `effects`: over each blow's window, error over the
    /// peak, weighted so the sum of squares is the mean over blows of nrmse².
    pub fn residuals(&self, machine: &Machine, effects: &EffectSet) -> Option<Vec<f64>> {
        self.residuals_weighted(machine, effects, &vec![1.0; self.obj.refs.len()])
    }

    /// `residuals` with blow `i` counted `weights[i]` times (a bootstrap resample's
    /// multiplicities, `confidence.rs`): its residuals scaled by √weight, so the sum of
    /// squares is the weighted mean over blows of nrmse².
    pub fn residuals_weighted(&self, machine: &Machine, effects: &EffectSet, weights: &[f64]) -> Option<Vec<f64>> {
        let sims = self.obj.with_effects(*effects).simulate(machine)?;
        let nb: f64 = weights.iter().sum();
        let mut out = Vec::new();
        for (((r, s), w), wt) in self.obj.refs.iter().zip(&sims).zip(&self.windows).zip(weights) {
            out.extend(blow_residuals(r, s, *w, wt / nb));
        }
        Some(out)
    }

    /// A lower bound of the cost (the sum of squares of `residuals`) that simulates only the
    /// first blow: its part of the sum, the same terms in the same order, so no larger in
    /// floating point either. INFINITY when it fails.
    pub fn first_blow_cost(&self, machine: &Machine, effects: &EffectSet) -> f64 {
        let Some(sims) = self.obj.with_effects(*effects).simulate_to(machine, 1) else { return f64::INFINITY };
        let (Some(r), Some(s), Some(w)) = (self.obj.refs.first(), sims.first(), self.windows.first()) else {
            return 0.0;
        };
        blow_residuals(r, s, *w, 1.0 / self.obj.refs.len() as f64).map(|x| x * x).sum()
    }

    /// The frequencies (Hz) of a ring these blows can show: at least `RING_MIN_PERIODS`
    /// periods in the longest window, at most the highest sample rate over
    /// `RING_SAMPLES_PER_PERIOD`. Empty (its floor above its ceiling) without blows.
    pub fn ring_band_hz(&self) -> (f64, f64) {
        let longest =
            self.obj.refs.iter().zip(&self.windows).map(|(r, w)| (w.1 - w.0) as f64 * r.dt_s).fold(0.0, f64::max);
        let finest = self.obj.refs.iter().map(|r| r.dt_s).fold(f64::INFINITY, f64::min);
        (RING_MIN_PERIODS / longest, 1.0 / (RING_SAMPLES_PER_PERIOD * finest))
    }

    /// Sensor noise over the peak, mean over the blows: the load's spread before each
    /// window (less 10 samples), where nothing touches the sensor, and never less than the
    /// ADC's own quantisation noise q/√12 (q the smallest step between the blow's distinct
    /// load values, as `identify::clip` finds it): a noise under one step leaves the
    /// pre-window constant, and a spread of 0 would make any residual a gap. A blow with
    /// fewer than 5 samples before its window has no spread to measure and is left out;
    /// when no blow has one, the quantisation floor alone is returned.
    pub fn noise_nrmse(&self) -> f64 {
        let blows = || self.obj.refs.iter().zip(&self.windows);
        let floor = |r: &Reference| quantisation_noise_n(&r.load_n) / r.peak_n;
        let measured: Vec<f64> = blows()
            .filter_map(|(r, w)| {
                let pre = &r.load_n[..w.0.saturating_sub(10).min(r.load_n.len())];
                (pre.len() >= 5).then(|| (spread(pre) / r.peak_n).max(floor(r)))
            })
            .collect();
        if measured.is_empty() { mean(&blows().map(|(r, _)| floor(r)).collect::<Vec<_>>()) } else { mean(&measured) }
    }

    /// The gap a clearance's closure shows on these blows, m: the distance the lower tool
    /// crosses in the lead `T` of the ram's own contact (`Reference::t_ram_contact_s`, its
    /// accelerometer) over the load's rise, median over the blows where the lead is longer
    /// than a sample (the contact's own uncertainty). None when no blow shows one.
    ///
    /// On a hammer the lower tool (`m2`) starts at rest under the gap (the library's
    /// `clearance`), pushed across by the billet's load `F` (eq. 3 at the blow's start height,
    /// the sheet's, and its impact strain rate): `F T² / (2 m2)` until it has caught up with
    /// the ram (`T = v0 m2 / F`), `v0 T - v0² m2 / (2 F)` after. Elsewhere (a press, whose die
    /// under a clearance is a fitted mass, and a bare strike) the ram's travel `v0 T`.
    pub fn closure_gap_m(&self, machine: &Machine) -> Option<f64> {
        let pushed = match (machine, &self.obj.setting) {
            (Machine::Hammer(h), Setting::Billet(p)) if h.m2_kg > 0.0 => Some((h.m2_kg, p)),
            _ => None,
        };
        let mut gaps: Vec<f64> = self
            .obj
            .refs
            .iter()
            .filter_map(|r| {
                let lead = r.measured?.contact_s - r.t_ram_contact_s?;
                if lead.is_nan() || lead <= r.dt_s {
                    return None;
                }
                let (v0, ram) = (r.v0_mps, r.v0_mps * lead);
                let Some(((m2, p), n)) = pushed.zip(r.blow_index) else { return Some(ram) };
                let h = n.checked_sub(2).and_then(|k| p.measured_final_heights_m.get(k).copied());
                let h = h.unwrap_or(p.billet.height_m);
                let law = BilletLaw::of(p, LoadEffects::NEUTRAL, n);
                let f = law.load(h, v0 / h).total_n;
                if !(f.is_finite() && f > 0.0) {
                    return Some(ram);
                }
                Some(if lead < v0 * m2 / f { 0.5 * f / m2 * lead * lead } else { ram - 0.5 * v0 * v0 * m2 / f })
            })
            .collect();
        gaps.sort_by(f64::total_cmp);
        gaps.get(gaps.len() / 2).copied()
    }

    pub fn len(&self) -> usize {
        self.windows.iter().map(|(a, b)| b - a).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Each blow's nrmse (docs/interfaces.md §6) with `effects`.
    pub fn nrmse(&self, machine: &Machine, effects: &EffectSet) -> Option<Vec<f64>> {
        let sims = self.obj.with_effects(*effects).simulate(machine)?;
        Some(self.obj.refs.iter().zip(&sims).map(|(r, s)| nrmse(r, s)).collect())
    }
}

/// Blow `r`'s load residuals against `s` over its window `(a, b)`, over its peak, weighted so
/// that their sum of squares is `share` times its nrmse².
fn blow_residuals(r: &Reference, s: &Simulated, (a, b): (usize, usize), share: f64) -> impl Iterator<Item = f64> {
    let w = share.sqrt() / (r.peak_n * ((b - a).max(1) as f64).sqrt());
    (a..b).map(move |i| w * (r.load_n[i] - s.load_n.get(i).copied().unwrap_or(0.0)))
}

/// The population standard deviation of `v` (n ≥ 1).
fn spread(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

/// The quantisation noise q/√12 of a signal whose ADC step is q (0 with fewer than two
/// distinct values).
fn quantisation_noise_n(load_n: &[f64]) -> f64 {
    let q = adc_step(load_n.iter().copied());
    if q.is_finite() { q / 12f64.sqrt() } else { 0.0 }
}

/// The mean of `v` (NaN when empty): a set's errors over its blows.
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::machine::MachineKind;

    /// A blow of 3000 samples at 100 kHz: a half-sine of 1 MN from sample 1000 over 2000,
    /// plus `noise` (a fixed ±1 pattern, N), rounded to a step of `q` N; its window starts
    /// at `start`.
    fn blow(noise: f64, q: f64, start: usize) -> (Reference, (usize, usize)) {
        let load_n: Vec<f64> = (0..3000)
            .map(|i| {
                let x = if i >= 1000 { 1e6 * (std::f64::consts::PI * (i - 1000) as f64 / 2000.0).sin() } else { 0.0 };
                let n = if i % 3 == 0 { noise } else { -0.5 * noise };
                ((x + n) / q).round() * q
            })
            .collect();
        let r = Reference {
            label: "b".into(),
            v0_mps: 4.0,
            dt_s: 1e-5,
            load_n,
            i_window_start: 0,
            measured: None,
            t_align_s: 1e-2,
            peak_n: 1e6,
            noise_n: None,
            blow_index: None,
            t_ram_contact_s: None,
            approach: None,
        };
        (r, (start, 3000))
    }

    fn set(blows: Vec<(Reference, (usize, usize))>) -> BlowSet {
        let (refs, windows): (Vec<_>, Vec<_>) = blows.into_iter().unzip();
        let fitted = vec![true; refs.len()];
        BlowSet { obj: Objective::new(refs, fitted, Setting::Bare, MachineKind::Hammer), windows, mode2_hz: 0.0 }
    }

    // A noise well above the ADC step is the pre-window's spread: the ±1 pattern (+a, −a/2,
    // −a/2) has a standard deviation of a/√2.
    #[test]
    fn the_noise_is_the_pre_window_spread() {
        let got = set(vec![blow(2000.0, 1.0, 1000)]).noise_nrmse();
        let want = 2000.0 / 2f64.sqrt() / 1e6;
        assert!((got / want - 1.0).abs() < 0.01, "{got} against {want}");
    }

    // A noise under half the ADC step leaves the pre-window constant; the noise is then the
    // quantisation's, q/√12, not 0 (tune press 4162 of the family read 0 and its strength
    // infinite, issue 41).
    #[test]
    fn a_noise_under_the_adc_step_is_the_quantisation_noise() {
        let q = 500.0;
        let got = set(vec![blow(100.0, q, 1000)]).noise_nrmse();
        let want = q / 12f64.sqrt() / 1e6;
        assert!((got / want - 1.0).abs() < 1e-9, "{got} against {want}");
    }

    // A blow whose window leaves fewer than 5 samples before it has no spread to measure:
    // it is left out, not counted as noise 0.
    #[test]
    fn a_blow_without_a_pre_window_is_left_out() {
        let alone = set(vec![blow(2000.0, 1.0, 1000)]).noise_nrmse();
        let with_short = set(vec![blow(2000.0, 1.0, 1000), blow(2000.0, 1.0, 12)]).noise_nrmse();
        assert!((with_short / alone - 1.0).abs() < 1e-12, "{with_short} against {alone}");
        let only_short = set(vec![blow(2000.0, 500.0, 12)]).noise_nrmse();
        assert!((only_short / (500.0 / 12f64.sqrt() / 1e6) - 1.0).abs() < 1e-9, "{only_short}");
    }
}
