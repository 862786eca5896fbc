//! A measured reference blow, ready for the fit (`objective`): its load, or without a load
//! channel its ram's force (`Signal`), aligned where it first rises, with its impact speed,
//! noise and the encoder's approach.

use crate::estimate::approach::ApproachFit;
use crate::signal::segment::Blow;

/// Fraction of the measured peak where the two blows are aligned.
pub const ALIGN_FRACTION: f64 = 0.10;

/// Measured samples kept before the alignment crossing, s.
pub const PRE_S: f64 = 1e-3;

/// The force a reference compares (`Reference::load_n`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Signal {
    /// The load sensor's (docs/interfaces.md §1 `load_N`).
    Load,
    /// Without a load channel: the ram's force, its mass (the data sheet's, held in the fit:
    /// `ParamSet::holding`) times its deceleration from the approach, `−m (a − a_approach)`,
    /// measured by the accelerometer and modelled from the ram's acceleration.
    RamForce { m_ram_kg: f64 },
}

/// Why a reference could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReferenceError {
    #[error(
        "{label}: the load is clipped at {peak_kn:.1} kN ({run} equal samples at the maximum); the fit needs the peak"
    )]
    Clipped { label: String, peak_kn: f64, run: usize },
    #[error("{label}: no impact speed: {reason}")]
    NoSpeed { label: String, reason: String },
    #[error("{label}: the load never rises above the noise (peak {peak_kn:.1} kN)")]
    NoLoad { label: String, peak_kn: f64 },
}

/// The accelerometer's mean over the approach window before contact (`fit_s`, less the
/// anti-alias filter's reach, `approach::ACC_GUARD_SAMPLES`), m/s²; `None` without samples.
fn approach_acceleration(blow: &Blow, fit_s: f64) -> Option<f64> {
    let end = blow.i_contact.saturating_sub(crate::estimate::approach::ACC_GUARD_SAMPLES);
    let start = end.saturating_sub((fit_s / blow.period_s).round() as usize);
    let pre: Vec<f64> = blow.samples[start..end].iter().map(|s| s.acc_mps2).filter(|a| a.is_finite()).collect();
    (!pre.is_empty()).then(|| pre.iter().sum::<f64>() / pre.len() as f64)
}

/// A measured reference blow, ready for the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    pub label: String,
    pub v0_mps: f64,
    pub dt_s: f64,
    /// Zeroed sensor load over the window, N; sample i at i·dt from the window's start.
    pub load_n: Vec<f64>,
    /// The window's first sample in the segmented blow.
    pub i_window_start: usize,
    /// The measured phases' instants, `None` until located (`diagnose::localise::locate_phases`).
    pub measured: Option<MeasuredInstants>,
    /// The alignment crossing, s from the window's start.
    pub t_align_s: f64,
    pub peak_n: f64,
    /// The load channel's noise, N: the standard deviation of the samples before the
    /// trigger, where the ram is still in flight and the load is zero (`None`: fewer than
    /// `MIN_NOISE_SAMPLES` of them).
    pub noise_n: Option<f64>,
    /// 1-based blow number on its billet (`None`: a bare strike).
    pub blow_index: Option<usize>,
    /// The ram's own first contact, s from the window's start (`ram_contact`): where its
    /// motion sensors leave the approach, which may come before the load rises (a clearance
    /// closing under the billet). `None` when they show no clear departure.
    pub t_ram_contact_s: Option<f64>,
    /// The encoder's approach: the ram's reading along its fitted parabola, to place the
    /// model's first contact on the encoder (`Heights::Encoder`). `None` where the fit gave
    /// no finite reading.
    pub approach: Option<EncoderApproach>,
}

/// The ram's approach as the encoder shows it: the parabola fitted before the load's
/// contact sample, and that sample's instant, s from the reference window's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderApproach {
    pub fit: ApproachFit,
    pub t_s: f64,
}

impl EncoderApproach {
    /// The reading the ram would show at `t_s` (window clock) on its approach's parabola
    /// (`ApproachFit::at`): where it met the billet, when `t_s` is the first contact.
    pub fn at(&self, t_s: f64) -> f64 {
        self.fit.at(t_s - self.t_s).x_contact_m
    }

    /// The reading at the load's contact sample, m.
    pub fn x_m(&self) -> f64 {
        self.fit.x_contact_m
    }
}

impl Reference {
    /// Cut a segmented blow. `fit_s`: approach window of the impact-speed fit.
    pub fn from_blow(
        label: &str,
        blow: &Blow,
        blow_index: Option<usize>,
        fit_s: f64,
    ) -> Result<Reference, ReferenceError> {
        Reference::of_signal(label, blow, blow_index, fit_s, Signal::Load)
    }

    /// `from_blow` comparing `signal`: the load sensor's, or, for a blow without a load
    /// channel, the ram's force from its accelerometer (`Signal::RamForce`).
    pub fn of_signal(
        label: &str,
        blow: &Blow,
        blow_index: Option<usize>,
        fit_s: f64,
        signal: Signal,
    ) -> Result<Reference, ReferenceError> {
        let approach = crate::estimate::approach::fit_impact_speed(&blow.samples, blow.i_contact, fit_s, blow.period_s)
            .map_err(|e| ReferenceError::NoSpeed { label: label.into(), reason: e.to_string() })?;
        let v0 = approach.v_impact_mps;
        let load: Vec<f64> = match signal {
            Signal::Load => blow.samples.iter().map(|s| s.load_n - blow.load_zero_n).collect(),
            Signal::RamForce { m_ram_kg } => {
                let free = approach_acceleration(blow, fit_s).ok_or_else(|| ReferenceError::NoSpeed {
                    label: label.into(),
                    reason: "no accelerometer samples before contact".into(),
                })?;
                // Before contact the ram falls (`free`, its approach); from contact the model
                // leaves its weight out (the hammer paper's eq. 1, as the renderers and the
                // estimator's fit do), so the acceleration is all the billet's.
                let weightless = |i: usize| if i < blow.i_contact { free } else { 0.0 };
                blow.samples.iter().enumerate().map(|(i, s)| -m_ram_kg * (s.acc_mps2 - weightless(i))).collect()
            }
        };
        let (i_peak, peak) =
            load.iter().copied().enumerate().fold((0, f64::MIN), |a, (i, v)| if v > a.1 { (i, v) } else { a });
        if signal == Signal::Load
            && let Some((raw_peak, run)) = super::clip::clipped(blow, i_peak)
        {
            return Err(ReferenceError::Clipped { label: label.into(), peak_kn: raw_peak * 1e-3, run });
        }
        let threshold = ALIGN_FRACTION * peak;
        let dt = blow.period_s;
        let pre = (PRE_S / dt).round() as usize;
        // The crossing is searched from a window before the segmenter's contact, not from
        // the record's start: a press's drive can trigger the cut tens of milliseconds early,
        // and one noise sample over 10 % of a small peak there took the alignment (family
        // press seed 4900, calibration blow 1: 14 ms early, its nrmse 0.69).
        let first = blow.i_contact.saturating_sub(pre).clamp(1, i_peak.max(1));
        let Some(i_cross) = (first..=i_peak).find(|&i| load[i] >= threshold && load[i - 1] < threshold) else {
            return Err(ReferenceError::NoLoad { label: label.into(), peak_kn: peak * 1e-3 });
        };
        let start = i_cross.saturating_sub(pre);
        let end = blow.i_end.max(i_peak + 1).min(load.len());
        let frac = (threshold - load[i_cross - 1]) / (load[i_cross] - load[i_cross - 1]);
        Ok(Reference {
            label: label.into(),
            v0_mps: v0,
            dt_s: dt,
            load_n: load[start..end].to_vec(),
            i_window_start: start,
            measured: None,
            t_align_s: ((i_cross - 1 - start) as f64 + frac) * dt,
            peak_n: peak,
            // Before the trigger and a window before the load's contact (which the load
            // crosses on its way up, not at its start).
            noise_n: pre_trigger_noise(&load[..blow.i_trigger.min(blow.i_contact).saturating_sub(pre)]),
            blow_index,
            t_ram_contact_s: ram_contact(blow).map(|t| t - start as f64 * dt),
            approach: Some(EncoderApproach { fit: approach, t_s: (blow.i_contact as f64 - start as f64) * dt })
                .filter(|a| a.fit.x_contact_m.is_finite() && a.fit.acc_mps2.is_finite()),
        })
    }

    pub fn duration_s(&self) -> f64 {
        self.load_n.len() as f64 * self.dt_s
    }
}

/// Pre-trigger samples the noise is measured on, at least: the sample standard deviation of
/// 32 normal samples is within ±25 % of σ with 95 % chance.
pub const MIN_NOISE_SAMPLES: usize = 32;

/// The standard deviation of `pre`, the zeroed load before the trigger, about its straight
/// line (a slow drift of the zero is not noise); `None` for fewer than `MIN_NOISE_SAMPLES`.
fn pre_trigger_noise(pre: &[f64]) -> Option<f64> {
    let n = pre.len();
    if n < MIN_NOISE_SAMPLES {
        return None;
    }
    let nf = n as f64;
    let tm = (nf - 1.0) / 2.0;
    let ym = pre.iter().sum::<f64>() / nf;
    let sxx: f64 = (0..n).map(|i| (i as f64 - tm).powi(2)).sum();
    let slope = pre.iter().enumerate().map(|(i, y)| (i as f64 - tm) * (y - ym)).sum::<f64>() / sxx;
    let ss: f64 = pre.iter().enumerate().map(|(i, y)| (y - ym - slope * (i as f64 - tm)).powi(2)).sum();
    Some((ss / (nf - 2.0)).sqrt())
}

/// Searched for the ram's contact: this long before the load's contact sample, s. A
/// clearance's closure lasts under a millisecond on the machines in the suite (0.3 mm at the
/// lower tool's ~0.6 m/s on the press, ~4 m/s on the hammer).
const RAM_CONTACT_LOOKBACK_S: f64 = 2e-3;
/// Samples of the approach that give the accelerometer's level and noise (at least).
const RAM_CONTACT_BASE_SAMPLES: usize = 64;
/// The accelerometer has left the approach when it is this many noise sd off its level on
/// `RAM_CONTACT_RUN` consecutive samples (a false start within a 2 ms search at 100 kHz:
/// ~1e-7 by the normal tail).
const RAM_CONTACT_SIGMAS: f64 = 6.0;
const RAM_CONTACT_RUN: usize = 2;

/// The ram's first contact, s on the blow's sample clock (sample i at i·dt): the first of
/// `RAM_CONTACT_RUN` samples where the ram's accelerometer leaves the approach's level by
/// `RAM_CONTACT_SIGMAS` of its noise, traced back to that level along its first two
/// samples. The accelerometer, not the encoder, because a lower tool crossing a clearance
/// costs the ram too little speed for 10 µm steps to show within the closure (a 26 kg die
/// under a 910 kg ram: 3 % of 4 m/s, about 5 µm of lag after 0.1 ms), while the billet's
/// push on the ram (~1 MN over its mass) stands far out of the accelerometer's noise.
fn ram_contact(blow: &Blow) -> Option<f64> {
    let lookback = (RAM_CONTACT_LOOKBACK_S / blow.period_s).round() as usize;
    let from = blow.i_contact.checked_sub(lookback)?;
    let base = &blow.samples[from.checked_sub(RAM_CONTACT_BASE_SAMPLES.max(lookback))?..from];
    let n = base.len() as f64;
    let level = base.iter().map(|s| s.acc_mps2).sum::<f64>() / n;
    let sd = (base.iter().map(|s| (s.acc_mps2 - level).powi(2)).sum::<f64>() / n).sqrt();
    let off = |k: usize| blow.samples.get(k).map_or(0.0, |s| s.acc_mps2 - level);
    let beyond = |k: usize| off(k).abs() > RAM_CONTACT_SIGMAS * sd.max(f64::MIN_POSITIVE);
    let end = (blow.i_contact + RAM_CONTACT_RUN).min(blow.samples.len());
    let k = (from..end).find(|&k| (k..k + RAM_CONTACT_RUN).all(beyond))?;
    // Back along the first two samples to the level, at most one sample back.
    let slope = off(k + 1) - off(k);
    let back = if slope * off(k) > 0.0 { (off(k) / slope).clamp(0.0, 1.0) } else { 1.0 };
    Some((k as f64 - back) * blow.period_s)
}

/// Instants of a measured blow, s from its reference window's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredInstants {
    pub contact_s: f64,
    pub forming_end_s: f64,
    /// The billet's permanent set: its compression when the load is back at zero, m
    /// (`None`: the load never came back to zero within the capture).
    pub set_m: Option<f64>,
}
