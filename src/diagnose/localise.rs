//! Where a model and a measured blow part (CONTRACTS.md §6): the normalised RMS load error
//! over the blow, split by phase and by frequency band.
//!
//! - The window runs from the model's first contact until the measured load has returned
//!   to zero after forming, plus 5 ms.
//! - Phases (on the model's clock, aligned to the measurement as `identify::objective`
//!   aligns them): `impact` the first 10 % of the forming time, `forming` the rest up to
//!   the end of forming, `spring_back` until the measured load returns to zero, `post` the
//!   5 ms after. Each phase's value is the RMS error within it over the blow's peak, so a
//!   short phase that is badly wrong stands out.
//! - Bands split the residual's energy over the window (Parseval, so the squares of the
//!   three values add up to the window's nrmse²): `low` below half the second-mode
//!   frequency, `mode2` from half to twice it, `high` above.
//!
//! Pure: fed the aligned signals.

use realfft::RealFftPlanner;
use serde::Serialize;

use crate::identify::objective::{Reference, Simulated};

/// Kept after the load returns to zero, s (CONTRACTS.md §6).
pub const POST_S: f64 = 5e-3;
/// The load has returned to zero when it falls below this fraction of the peak.
pub const ZERO_FRACTION: f64 = 0.02;
/// `impact` is this fraction of the forming time.
pub const IMPACT_FRACTION: f64 = 0.10;

/// RMS error by phase, fraction of the peak.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ByPhase {
    pub impact: f64,
    pub forming: f64,
    pub spring_back: f64,
    pub post: f64,
}

impl ByPhase {
    /// The mean over blows.
    pub fn mean(all: &[ByPhase]) -> ByPhase {
        let k = 1.0 / all.len().max(1) as f64;
        all.iter().fold(ByPhase::default(), |m, p| ByPhase {
            impact: m.impact + k * p.impact,
            forming: m.forming + k * p.forming,
            spring_back: m.spring_back + k * p.spring_back,
            post: m.post + k * p.post,
        })
    }

    /// The phase with the largest error.
    pub fn dominant(&self) -> &'static str {
        let all = [
            ("impact", self.impact),
            ("forming", self.forming),
            ("spring_back", self.spring_back),
            ("post", self.post),
        ];
        all.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1)).map_or("forming", |(n, _)| n)
    }
}

/// RMS error by band, fraction of the peak; the squares add up to nrmse².
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ByBand {
    pub low: f64,
    pub mode2: f64,
    pub high: f64,
}

impl ByBand {
    /// The mean over blows.
    pub fn mean(all: &[ByBand]) -> ByBand {
        let k = 1.0 / all.len().max(1) as f64;
        all.iter().fold(ByBand::default(), |m, b| ByBand {
            low: m.low + k * b.low,
            mode2: m.mode2 + k * b.mode2,
            high: m.high + k * b.high,
        })
    }
}

/// One blow's residual, localised.
#[derive(Debug, Clone, PartialEq)]
pub struct Localised {
    pub nrmse: f64,
    pub by_phase: ByPhase,
    pub by_band: ByBand,
    /// The window, sample indices [start, end).
    pub window: (usize, usize),
    /// Phase boundaries, sample indices: impact end, forming end, load back at zero.
    pub boundaries: [usize; 3],
}

/// Localise the residual of `model` against the measured `r`, with the machine's second
/// mode at `mode2_hz`.
pub fn localise(r: &Reference, model: &Simulated, mode2_hz: f64) -> Localised {
    let n = r.load_n.len();
    let dt = r.dt_s;
    let idx = |t: f64| ((t / dt).round().max(0.0) as usize).min(n);
    let start = idx(model.t_contact_s);
    let i_peak = r.load_n.iter().enumerate().fold(0, |b, (i, v)| if *v > r.load_n[b] { i } else { b });
    let forming_end = model.t_forming_end_s.map_or(i_peak, idx).max(start);
    let impact_end = (start + ((forming_end - start) as f64 * IMPACT_FRACTION).round() as usize).min(forming_end);
    // The measured load back at zero: the first sample below the threshold after the end of
    // forming (or after the peak, whichever is later).
    let threshold = ZERO_FRACTION * r.peak_n;
    let from = forming_end.max(i_peak);
    let zero = (from..n).find(|&i| r.load_n[i] < threshold).unwrap_or(n);
    let end = (zero + (POST_S / dt).round() as usize).min(n);
    let resid: Vec<f64> = (0..n).map(|i| r.load_n[i] - model.load_n.get(i).copied().unwrap_or(0.0)).collect();
    let rms = |a: usize, b: usize| {
        if b <= a {
            return 0.0;
        }
        (resid[a..b].iter().map(|x| x * x).sum::<f64>() / (b - a) as f64).sqrt() / r.peak_n
    };
    let nrmse = rms(start, end);
    let by_phase = ByPhase {
        impact: rms(start, impact_end),
        forming: rms(impact_end, forming_end),
        spring_back: rms(forming_end, zero.min(end)),
        post: rms(zero.min(end), end),
    };
    let by_band = bands(&resid[start..end.max(start)], dt, mode2_hz, nrmse);
    Localised { nrmse, by_phase, by_band, window: (start, end), boundaries: [impact_end, forming_end, zero.min(end)] }
}

/// Split `nrmse` of the residual `x` by band, in proportion to the energy in each.
fn bands(x: &[f64], dt: f64, mode2_hz: f64, nrmse: f64) -> ByBand {
    let n = x.len();
    if n < 4 || !(mode2_hz.is_finite() && mode2_hz > 0.0) {
        return ByBand { low: nrmse, ..ByBand::default() };
    }
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let mut input = x.to_vec();
    let mut spectrum = fft.make_output_vec();
    if fft.process(&mut input, &mut spectrum).is_err() {
        return ByBand { low: nrmse, ..ByBand::default() };
    }
    let df = 1.0 / (n as f64 * dt);
    let (mut low, mut mid, mut high) = (0.0, 0.0, 0.0);
    for (k, c) in spectrum.iter().enumerate() {
        // One-sided: every bin but DC and (for even n) Nyquist stands for two.
        let w = if k == 0 || (n.is_multiple_of(2) && k == n / 2) { 1.0 } else { 2.0 };
        let e = w * c.norm_sqr();
        let f = k as f64 * df;
        if f < 0.5 * mode2_hz {
            low += e;
        } else if f <= 2.0 * mode2_hz {
            mid += e;
        } else {
            high += e;
        }
    }
    let total = low + mid + high;
    if total <= 0.0 {
        return ByBand::default();
    }
    let part = |e: f64| nrmse * (e / total).sqrt();
    ByBand { low: part(low), mode2: part(mid), high: part(high) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A blow: contact at 1 ms, forming to 9 ms, unloading to 10 ms, 20 ms of record, at
    /// 100 kHz, peak 1 MN.
    fn blow(extra: impl Fn(f64) -> f64) -> (Reference, Simulated) {
        let dt = 1e-5;
        let load = |t: f64| {
            if t < 1e-3 {
                0.0
            } else if t < 9e-3 {
                1e6 * ((t - 1e-3) / 8e-3 * std::f64::consts::PI).sin().max(0.3)
            } else if t < 10e-3 {
                3e5 * (10e-3 - t) / 1e-3
            } else {
                0.0
            }
        };
        let n = 2000;
        let model: Vec<f64> = (0..n).map(|i| load(i as f64 * dt)).collect();
        let measured: Vec<f64> = (0..n).map(|i| load(i as f64 * dt) + extra(i as f64 * dt)).collect();
        let peak = measured.iter().copied().fold(0.0, f64::max);
        let r = Reference {
            label: "b".into(),
            v0_mps: 4.0,
            dt_s: dt,
            load_n: measured,
            t_align_s: 1e-3,
            peak_n: peak,
            blow_index: Some(1),
        };
        let s = Simulated {
            load_n: model,
            spectrum: Vec::new(),
            h_end_m: None,
            t_contact_s: 1e-3,
            t_forming_end_s: Some(9e-3),
        };
        (r, s)
    }

    #[test]
    fn a_slow_spring_back_is_found_in_its_phase() {
        // The measured unloading lasts 3 ms longer (hammer paper §4.2: 3.7 ms measured
        // against 0.8 ms simulated).
        let (r, s) = blow(|t| if (9e-3..13e-3).contains(&t) { 2e5 * (1.0 - (t - 9e-3) / 4e-3) } else { 0.0 });
        let l = localise(&r, &s, 2000.0);
        assert_eq!(l.by_phase.dominant(), "spring_back", "{:?}", l.by_phase);
        assert!(l.by_phase.impact < 1e-12 && l.by_phase.forming < 1e-12);
    }

    #[test]
    fn a_ring_at_the_second_mode_is_found_in_its_band_and_the_bands_add_up() {
        let (r, s) = blow(|t| if t > 1e-3 { 3e4 * (2.0 * std::f64::consts::PI * 2000.0 * t).sin() } else { 0.0 });
        let l = localise(&r, &s, 2000.0);
        assert!(l.by_band.mode2 > 5.0 * (l.by_band.low + l.by_band.high), "{:?}", l.by_band);
        // Parseval: the bands' squares add up to the window's nrmse².
        let sum = l.by_band.low.powi(2) + l.by_band.mode2.powi(2) + l.by_band.high.powi(2);
        assert!((sum / l.nrmse.powi(2) - 1.0).abs() < 1e-9, "{sum} vs {}", l.nrmse.powi(2));
    }

    #[test]
    fn a_perfect_model_has_no_error_and_the_window_follows_the_contract() {
        let (r, s) = blow(|_| 0.0);
        let l = localise(&r, &s, 2000.0);
        assert_eq!(l.nrmse, 0.0);
        // From contact (1 ms) to the load back at zero (just before 10 ms) plus 5 ms.
        assert_eq!(l.window.0, 100);
        assert!((1490..=1500).contains(&l.window.1), "{:?}", l.window);
    }
}
