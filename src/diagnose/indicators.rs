//! Localisation by indicator (issue #6): the numbers a forge engineer reads off a blow,
//! each taken the same way from the measurement and from the base model, so that the gap
//! shows as "the model forms on for 15 % of the blow after the billet stopped" rather than
//! as a load error somewhere.
//!
//! - `peak_load`: the largest load.
//! - `final_load`: the load at the end of forming, averaged over the last second-mode
//!   period before it (the ring would otherwise decide it).
//! - `forming_time`, `spring_back_time`: the phases' lengths (`localise::Phases`: the
//!   measured blow's from its own instants, the model's from its own).
//! - `final_height`: the model's billet height after the blow, and the same start height
//!   less the permanent set the model run on the measured signals sees (its compression
//!   when the load is back at zero); `None` without measured instants.
//! - `mode2_frequency`, `mode2_damping`: the ring of the second mode during forming, from
//!   the load less its running mean over one period: the frequency from the zero crossings,
//!   the damping ratio from the log decrement of the cycles' amplitudes. `None` when fewer
//!   than three cycles stand above 1 % of the peak (a press rarely rings that long).
//!
//! The same estimator on both sides: its own bias (a ring read from a forced response)
//! cancels in the comparison.
//!
//! Each error is read against a scale that keeps the indicators comparable, so that a
//! spring-back of 50 µs measured against 0.8 ms modelled is not a "1500 %" error that
//! outranks a forming 15 % too long: loads against the measured peak (as the nrmse), times
//! against the measured blow's duration (contact to the load back at zero), the final
//! height against the measured height reduction of the blow, the ring's frequency and
//! damping against their measured values.

use serde::Serialize;

use crate::identify::objective::{Reference, Simulated};

use super::localise::Localised;

/// One indicator, measured and modelled, and the scale its error is read against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pair {
    pub measured: f64,
    pub model: f64,
    pub scale: f64,
}

impl Pair {
    /// (model − measured) / scale.
    pub fn rel_error(&self) -> f64 {
        (self.model - self.measured) / self.scale
    }
}

/// A blow's indicators.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Indicators {
    pub peak_load_n: Pair,
    pub final_load_n: Pair,
    pub forming_time_s: Pair,
    pub spring_back_time_s: Pair,
    pub final_height_m: Option<Pair>,
    pub mode2_frequency_hz: Option<Pair>,
    pub mode2_damping_ratio: Option<Pair>,
}

impl Indicators {
    /// The names and relative errors of the indicators, in a fixed order (`None`: not
    /// found on one side).
    pub fn rel_errors(&self) -> Vec<(&'static str, Option<f64>)> {
        vec![
            ("peak_load", Some(self.peak_load_n.rel_error())),
            ("final_load", Some(self.final_load_n.rel_error())),
            ("forming_time", Some(self.forming_time_s.rel_error())),
            ("spring_back_time", Some(self.spring_back_time_s.rel_error())),
            ("final_height", self.final_height_m.map(|p| p.rel_error())),
            ("mode2_frequency", self.mode2_frequency_hz.map(|p| p.rel_error())),
            ("mode2_damping", self.mode2_damping_ratio.map(|p| p.rel_error())),
        ]
    }
}

/// The indicators of the measured `r` and the `model`, on the phases `loc` found.
pub fn indicators(r: &Reference, model: &Simulated, loc: &Localised, mode2_hz: f64) -> Indicators {
    let dt = r.dt_s;
    let n = r.load_n.len();
    let model_load = &model.load_n[..n.min(model.load_n.len())];
    let (m, s) = (&loc.measured, &loc.model);
    let period = if mode2_hz > 0.0 { ((1.0 / mode2_hz) / dt).round().max(1.0) as usize } else { 1 };
    let before = |load: &[f64], end: usize| {
        let end = end.min(load.len());
        let a = end.saturating_sub(period);
        if end > a { load[a..end].iter().sum::<f64>() / (end - a) as f64 } else { 0.0 }
    };
    let ring_of =
        |load: &[f64], a: usize, b: usize| ring(&load[a.min(load.len())..b.min(load.len())], dt, period, r.peak_n);
    let (ring_m, ring_s) =
        (ring_of(&r.load_n, m.contact(), m.forming_end()), ring_of(model_load, s.contact(), s.forming_end()));
    let both = |a: Option<(f64, f64)>, b: Option<(f64, f64)>, pick: fn((f64, f64)) -> f64| {
        let (a, b) = (pick(a?), pick(b?));
        Some(Pair { measured: a, model: b, scale: a.abs() })
    };
    let final_height = r.measured.and_then(|mi| {
        let (h0, set) = (model.h_start_m?, mi.set_m?);
        (set > 0.0).then_some(Pair { measured: h0 - set, model: model.h_end_m?, scale: set })
    });
    let load = |measured: f64, model: f64| Pair { measured, model, scale: r.peak_n };
    let duration = (m.zero() - m.contact()).max(1) as f64 * dt;
    let time = |measured: usize, model: usize| Pair {
        measured: measured as f64 * dt,
        model: model as f64 * dt,
        scale: duration,
    };
    Indicators {
        peak_load_n: load(r.peak_n, model_load.iter().copied().fold(0.0, f64::max)),
        final_load_n: load(before(&r.load_n, m.forming_end()), before(model_load, s.forming_end())),
        forming_time_s: time(m.forming_end() - m.contact(), s.forming_end() - s.contact()),
        spring_back_time_s: time(m.zero() - m.forming_end(), s.zero() - s.forming_end()),
        final_height_m: final_height,
        mode2_frequency_hz: both(ring_m, ring_s, |x| x.0),
        mode2_damping_ratio: both(ring_m, ring_s, |x| x.1),
    }
}

/// Smallest ring amplitude that counts, fraction of the peak.
const RING_FLOOR: f64 = 0.01;

/// The ring in `x` (sampled every `dt`, nominal period `period` samples): its frequency and
/// damping ratio, or `None` with fewer than three cycles above `RING_FLOOR` of `peak`.
fn ring(x: &[f64], dt: f64, period: usize, peak: f64) -> Option<(f64, f64)> {
    let n = x.len();
    if period < 4 || n < 3 * period {
        return None;
    }
    // Less the running mean over one period (the forming load under the ring).
    let half = period / 2;
    let mut prefix = vec![0.0; n + 1];
    for i in 0..n {
        prefix[i + 1] = prefix[i] + x[i];
    }
    let detrended: Vec<f64> =
        (half..n - half).map(|i| x[i] - (prefix[i + half + 1] - prefix[i - half]) / (2 * half + 1) as f64).collect();
    // Upward zero crossings, interpolated; a crossing closer than half a period to the
    // last is noise.
    let mut crossings: Vec<f64> = Vec::new();
    for i in 1..detrended.len() {
        if detrended[i - 1] < 0.0 && detrended[i] >= 0.0 {
            let t = (i - 1) as f64 + detrended[i - 1] / (detrended[i - 1] - detrended[i]);
            if crossings.last().is_none_or(|&c| t - c > 0.5 * period as f64) {
                crossings.push(t);
            }
        }
    }
    // Each cycle's amplitude, until the ring sinks under the floor.
    let mut amps = Vec::new();
    for w in crossings.windows(2) {
        let (a, b) = (w[0].ceil() as usize, (w[1].floor() as usize).min(detrended.len()));
        let amp = 0.5
            * (detrended[a..b].iter().copied().fold(f64::MIN, f64::max)
                - detrended[a..b].iter().copied().fold(f64::MAX, f64::min));
        if amp < RING_FLOOR * peak {
            break;
        }
        amps.push(amp);
    }
    if amps.len() < 3 {
        return None;
    }
    let cycles = amps.len();
    let freq = cycles as f64 / ((crossings[cycles] - crossings[0]) * dt);
    // Log decrement: the least-squares slope of ln(amplitude) against the cycle.
    let k_mean = (cycles - 1) as f64 / 2.0;
    let l_mean = amps.iter().map(|a| a.ln()).sum::<f64>() / cycles as f64;
    let (mut num, mut den) = (0.0, 0.0);
    for (k, a) in amps.iter().enumerate() {
        num += (k as f64 - k_mean) * (a.ln() - l_mean);
        den += (k as f64 - k_mean).powi(2);
    }
    let delta = -num / den;
    let zeta = delta / (4.0 * std::f64::consts::PI * std::f64::consts::PI + delta * delta).sqrt();
    Some((freq, zeta))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_damped_ring_is_read_back() {
        // 2 kHz, ζ = 0.03, on a rising forming load, 100 kHz: the frequency within 1 % and
        // the damping within 10 % (a least-squares log decrement over ≥ 3 cycles).
        let (f, zeta, dt) = (2000.0, 0.03, 1e-5);
        let w = 2.0 * std::f64::consts::PI * f;
        let x: Vec<f64> = (0..1500)
            .map(|i| {
                let t = i as f64 * dt;
                5e5 + 2e7 * t + 3e5 * (-zeta * w * t).exp() * (w * (1.0 - zeta * zeta).sqrt() * t).sin()
            })
            .collect();
        let (fr, z) = ring(&x, dt, 50, 1e6).unwrap();
        assert!((fr / (f * (1.0 - zeta * zeta).sqrt()) - 1.0).abs() < 0.01, "{fr}");
        assert!((z / zeta - 1.0).abs() < 0.1, "{z}");
    }

    #[test]
    fn no_ring_gives_none() {
        let x: Vec<f64> = (0..1500).map(|i| 5e5 + 10.0 * i as f64).collect();
        assert_eq!(ring(&x, 1e-5, 50, 1e6), None);
    }
}

/// An indicator over the blows: the means and the mean relative error of the blows that
/// have it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    pub name: &'static str,
    pub blows: usize,
    pub mean_rel_error: f64,
    pub per_blow_rel_error: Vec<Option<f64>>,
}

/// Every indicator over `all`, in `Indicators::rel_errors` order.
pub fn summarise(all: &[Indicators]) -> Vec<Summary> {
    let per: Vec<Vec<(&'static str, Option<f64>)>> = all.iter().map(|i| i.rel_errors()).collect();
    let names: Vec<&'static str> = per.first().map(|p| p.iter().map(|(n, _)| *n).collect()).unwrap_or_default();
    names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let v: Vec<Option<f64>> = per.iter().map(|p| p[k].1.filter(|x| x.is_finite())).collect();
            let present: Vec<f64> = v.iter().flatten().copied().collect();
            let mean = if present.is_empty() { f64::NAN } else { present.iter().sum::<f64>() / present.len() as f64 };
            Summary { name, blows: present.len(), mean_rel_error: mean, per_blow_rel_error: v }
        })
        .collect()
}

/// The indicator with the largest mean relative error.
pub fn dominant(summary: &[Summary]) -> Option<&Summary> {
    summary
        .iter()
        .filter(|s| s.mean_rel_error.is_finite())
        .max_by(|a, b| a.mean_rel_error.abs().total_cmp(&b.mean_rel_error.abs()))
}
