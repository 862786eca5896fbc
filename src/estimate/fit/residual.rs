//! What the fitted model still misses (`fit_blow`'s residual by channel and phase), and the
//! billet's set the encoder saw it miss.

use super::{Eval, PEAK_FRACTION_SD, Setup};

/// The set the model missed, from the encoder. In the spring-back the billet no longer
/// flows: the ram sits at the contact position, less the billet's final set, less the
/// machine's elastic deflection under the load, which the fit matched. So the encoder's
/// mean residual over the spring-back's samples is the set's error, in the encoder's own
/// terms. On the hammer's tuning seeds (11, 12; `tests/estimate_rates`) the fitted set
/// missed by up to 21 µm on the fourth and fifth blows, where a billet off its sheet's
/// height bends the load's shape away from the sheet's law, and the spring-back's mean
/// residual tracked that miss to within 3 µm at 10–50 kHz. Measured is the ram's position
/// against the approach's contact; `tau_s` is the contact after the contact sample.
pub(super) fn spring_back_set_offset(setup: &Setup<'_>, cur: &Eval, tau_s: f64) -> Option<f64> {
    let fm = cur.blow.forming?;
    let b = setup.p.blow;
    let t_forming_end = fm.forming_time_s;
    let t_separation = t_forming_end + fm.spring_back_time_s?;
    let first = setup.lp.half();
    // The full residual interleaves encoder, load, acceleration per sample.
    let (sum, n) = (first..=setup.k1 - setup.k0)
        .filter(|&k| {
            let t = (setup.k0 + k) as f64 * b.period_s - b.i_contact as f64 * b.period_s - tau_s;
            t > t_forming_end && t <= t_separation
        })
        .filter_map(|k| cur.r.get(3 * (k - first)))
        .fold((0.0, 0usize), |(s, n), r| (s + r * setup.sd_x, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// How far the fitted model is from what was measured, per channel: the root mean square of
/// each residual, the load and the acceleration as fractions of their (low-passed) measured
/// peaks, the encoder in metres. A model that fits leaves the noise and the sampling; a
/// missing effect leaves its shape (`alert`'s model-health rule).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelResidual {
    /// The load's, from the end of impact to separation (forming and spring-back; the whole
    /// window when the fitted blow has no end of forming). The impact is left out: its rise
    /// takes a sample or two, where DAQ filters differ most (a linear-phase filter's
    /// precursors, a minimum-phase filter's lag, none at all), so there the residual
    /// measures the DAQ, not the machine. On the project's own 5 kHz CAN fixture, sampled
    /// without a filter, the impact's residual is 9 % of the peak against 0.7 % in forming.
    pub load: f64,
    /// The acceleration's and the encoder's over the fit's window.
    pub acc: f64,
    pub encoder_m: f64,
    /// The load's, by phase of the fitted blow.
    pub load_by_phase: PhaseResidual,
}

/// A residual by phase of the blow, as docs/interfaces.md §6 splits `diagnose`'s: `impact` the first
/// 10 % of the forming time, `forming` the rest of it, `spring_back` from the end of forming
/// to separation. Each is the RMS within the phase over the peak (0 for a phase without a
/// sample), so a short phase that is badly wrong stands out.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct PhaseResidual {
    pub impact: f64,
    pub forming: f64,
    pub spring_back: f64,
}

impl PhaseResidual {
    /// The phase with the largest residual.
    pub fn dominant(&self) -> &'static str {
        [("impact", self.impact), ("forming", self.forming), ("spring_back", self.spring_back)]
            .into_iter()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or("forming", |(n, _)| n)
    }
}

/// `impact` is this fraction of the forming time (docs/interfaces.md §6).
const IMPACT_FRACTION: f64 = 0.10;

/// The residual by channel and the load's by phase, at the evaluation `e` of contact `tau_s`
/// after the contact sample.
pub(super) fn residual_by_channel(setup: &Setup<'_>, e: &Eval, tau_s: f64) -> ModelResidual {
    // The residuals interleave encoder, load, acceleration per sample, from the filter's
    // half width into the window.
    let rms = |k: usize| {
        let (s, n) = e.r.iter().skip(k).step_by(3).fold((0.0, 0usize), |(s, n), r| (s + r * r, n + 1));
        (s / n.max(1) as f64).sqrt()
    };
    let b = setup.p.blow;
    let first = setup.lp.half();
    let (mut sum, mut n) = ([0.0; 3], [0usize; 3]);
    if let Some(fm) = e.blow.forming {
        let impact_end = IMPACT_FRACTION * fm.forming_time_s;
        let separation = fm.forming_time_s + fm.spring_back_time_s.unwrap_or(0.0);
        for (i, r) in e.r.iter().skip(1).step_by(3).enumerate() {
            let k = setup.k0 + first + i;
            let t = (k as f64 - b.i_contact as f64) * b.period_s - tau_s;
            let phase = if t < 0.0 || t > separation {
                continue;
            } else if t < impact_end {
                0
            } else if t < fm.forming_time_s {
                1
            } else {
                2
            };
            sum[phase] += r * r;
            n[phase] += 1;
        }
    }
    let by = |p: usize| if n[p] == 0 { 0.0 } else { PEAK_FRACTION_SD * (sum[p] / n[p] as f64).sqrt() };
    let after_impact = if n[1] + n[2] > 0 {
        PEAK_FRACTION_SD * ((sum[1] + sum[2]) / (n[1] + n[2]) as f64).sqrt()
    } else {
        PEAK_FRACTION_SD * rms(1)
    };
    ModelResidual {
        encoder_m: setup.sd_x * rms(0),
        load: after_impact,
        acc: PEAK_FRACTION_SD * rms(2),
        load_by_phase: PhaseResidual { impact: by(0), forming: by(1), spring_back: by(2) },
    }
}
