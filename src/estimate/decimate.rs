//! The blow the model fit sees (issue 16, latency): above `FIT_MAX_RATE_HZ` the fit runs on
//! a copy decimated by an integer factor, the way a DAQ at the lower rate would have
//! sampled it: the analogue channels (load, accelerometer) through the nominal linear-phase
//! anti-alias low-pass at 0.4 × the lower rate, the encoder (a counter) read directly. The
//! fit costs its window's samples, so a 50 kHz hammer blow fitted at 10 kHz costs what a
//! 10 kHz one does, and the fit is as accurate at 10 kHz as at 50 kHz (docs/guide.md "Sample
//! rate"): what the sampling cannot resolve, the model supplies either way.
//!
//! The decimated grid keeps the segmenter's contact sample, so the approach fit and the
//! contact instant, both counted from that sample, carry over with only their unit of
//! samples scaled.

use crate::estimate::fit::{NOMINAL_ANTI_ALIAS_CUTOFF, NOMINAL_ANTI_ALIAS_TRANSITION};
use crate::signal::fir::LowPass;
use crate::signal::segment::{Blow, Sample};

/// The model fit runs at most at this sample rate, Hz: the lowest rate whose fit meets the
/// 10 ms latency target of issue 16 on this machine's bench (docs/guide.md "Sample rate"), and a
/// rate the fit is tested at directly.
pub const FIT_MAX_RATE_HZ: f64 = 10e3;

/// Coarse samples kept before the contact sample: the fit reads 22 (`fit::PRE_SAMPLES` and
/// its analysis filter's half width), the rest of the pre-trigger is not decimated at all
/// (at 100 kHz that saved a millisecond of each fit's latency).
pub const KEPT_BEFORE_CONTACT: usize = 64;

/// The decimation factor for a blow sampled every `period_s`: 1 at or below
/// `FIT_MAX_RATE_HZ`.
pub fn factor(period_s: f64) -> usize {
    let rate = 1.0 / period_s;
    ((rate / FIT_MAX_RATE_HZ) * (1.0 + 1e-9)).floor().max(1.0) as usize
}

/// `blow` decimated by `f` on a grid through its contact sample (a clone for `f` ≤ 1).
pub fn decimate(blow: &Blow, f: usize) -> Blow {
    if f <= 1 {
        return blow.clone();
    }
    let fl = f as f64;
    let lp = LowPass::design(NOMINAL_ANTI_ALIAS_CUTOFF / fl, NOMINAL_ANTI_ALIAS_TRANSITION / fl);
    let load: Vec<f64> = blow.samples.iter().map(|s| s.load_n).collect();
    let acc: Vec<f64> = blow.samples.iter().map(|s| s.acc_mps2).collect();
    // The grid through the contact sample, from `KEPT_BEFORE_CONTACT` coarse samples before it.
    let r = blow.i_contact - (blow.i_contact / f).min(KEPT_BEFORE_CONTACT) * f;
    let samples: Vec<Sample> = (r..blow.samples.len())
        .step_by(f)
        .map(|k| {
            let s = &blow.samples[k];
            // A sample stands for what its filter saw: filled in if any of that was.
            let lo = k.saturating_sub(lp.half());
            let hi = (k + lp.half() + 1).min(blow.samples.len());
            Sample {
                t_s: s.t_s,
                load_n: lp.at(&load, k),
                disp_m: s.disp_m,
                acc_mps2: lp.at(&acc, k),
                filled: blow.samples[lo..hi].iter().any(|s| s.filled),
            }
        })
        .collect();
    let to_grid = |i: usize| i.saturating_sub(r) / f;
    let i_contact = to_grid(blow.i_contact);
    let last = samples.len().saturating_sub(1);
    Blow {
        i_trigger: to_grid(blow.i_trigger),
        i_contact,
        i_end: to_grid(blow.i_end).max(i_contact + 1).min(samples.len().saturating_sub(1)),
        samples,
        load_zero_n: blow.load_zero_n,
        period_s: blow.period_s * fl,
        lost_s: blow.lost_s,
        open_end_n: blow.open_end_n,
        ram_cut: blow.ram_cut.map(|(c, e)| (to_grid(c), to_grid(e).min(last))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blow(rate_hz: f64, n: usize, i_contact: usize) -> Blow {
        let dt = 1.0 / rate_hz;
        let samples = (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                // A 500 Hz tone plus one at 0.45 × the rate, which the decimation must remove.
                let tone = (2.0 * std::f64::consts::PI * 500.0 * t).sin();
                let alias = (2.0 * std::f64::consts::PI * 0.45 * rate_hz * t).sin();
                Sample { t_s: t, load_n: tone + alias, disp_m: k as f64, acc_mps2: tone, filled: false }
            })
            .collect();
        Blow {
            samples,
            i_trigger: i_contact,
            i_contact,
            i_end: n - 10,
            load_zero_n: 0.0,
            period_s: dt,
            lost_s: 0.0,
            open_end_n: None,
            ram_cut: None,
        }
    }

    #[test]
    fn the_factor_keeps_the_fit_at_or_below_its_rate() {
        assert_eq!(factor(1.0 / 5e3), 1);
        assert_eq!(factor(1.0 / 10e3), 1);
        assert_eq!(factor(1.0 / 20e3), 2);
        assert_eq!(factor(1.0 / 50e3), 5);
        assert_eq!(factor(1.0 / 100e3), 10);
    }

    /// The contact sample stays on the grid with its time and encoder reading, the tone
    /// below the new band passes, and the one above the old Nyquist/5 is gone.
    #[test]
    fn decimation_keeps_the_contact_sample_and_the_band() {
        let b = blow(50e3, 2000, 1003);
        let d = decimate(&b, 5);
        assert!((d.period_s - 1e-4).abs() < 1e-12);
        let c = &d.samples[d.i_contact];
        assert_eq!(c.t_s, b.samples[b.i_contact].t_s);
        assert_eq!(c.disp_m, b.samples[b.i_contact].disp_m);
        // Away from the ends, the 500 Hz tone within the filter's pass-band ripple
        // (Blackman window: below 0.1 %), the 22.5 kHz tone attenuated below 0.1 %.
        assert_eq!(d.i_contact, KEPT_BEFORE_CONTACT);
        for s in &d.samples[30..230] {
            let tone = (2.0 * std::f64::consts::PI * 500.0 * s.t_s).sin();
            assert!((s.load_n - tone).abs() < 2e-3, "{} vs {tone} at {}", s.load_n, s.t_s);
        }
    }
}
