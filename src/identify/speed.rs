//! The impact speed's own standard error, for the fit's covariance (issue 18).
//!
//! `estimate::approach` fits the encoder's approach with a parabola whose curvature is the
//! accelerometer's mean over the window, and takes the slope at contact. The fit of the
//! machine then treats that speed as exact, yet the ram mass follows the blow's momentum,
//! impulse over speed, so the speed's error passes one for one into m1. Two parts:
//!
//! - the accelerometer's mean is off by sd(acc)/√n; a curvature error δa moves the fitted
//!   slope at contact by δa·∂v/∂a, with ∂v/∂a = −½ Σ(t − t̄) t² / Σ(t − t̄)² (about T/2
//!   over a window of length T ending at contact): on the tests' hammer, 2 m/s² of noise
//!   over 1000 samples and T = 10 ms give 0.3 mm/s, 0.0075 % of 4.2 m/s;
//! - the line's slope, s/√Σ(t − t̄)², s the residuals' spread (the encoder's quantisation).
//!
//! Both are inflated for noise correlated in time by (1 + ρ)/(1 − ρ), ρ the lag-1
//! autocorrelation, as `fit::uncertainty` does for the load. The window is
//! `fit_impact_speed`'s own (`approach::GUARD_SAMPLES`, `MIN_FIT_SAMPLES`).

use crate::estimate::approach::{GUARD_SAMPLES, MIN_FIT_SAMPLES};
use crate::signal::segment::Blow;

/// Standard error of the impact speed `fit_impact_speed` gives for `blow` with the approach
/// window `fit_s`, m/s (`None`: too few samples, as the fit itself refuses).
pub fn impact_speed_sd_mps(blow: &Blow, fit_s: f64) -> Option<f64> {
    let end = blow.i_contact.saturating_sub(GUARD_SAMPLES);
    let want = (fit_s / blow.period_s).round() as usize;
    let start = end.saturating_sub(want);
    let w = blow.samples.get(start..end)?;
    let n = w.len();
    if n < MIN_FIT_SAMPLES {
        return None;
    }
    let tc = blow.samples.get(blow.i_contact)?.t_s;
    let nf = n as f64;
    let t: Vec<f64> = w.iter().map(|s| s.t_s - tc).collect();
    let t_mean = t.iter().sum::<f64>() / nf;
    let sxx: f64 = t.iter().map(|x| (x - t_mean).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    // The curvature's share.
    let acc: Vec<f64> = w.iter().map(|s| s.acc_mps2).collect();
    let acc_mean = acc.iter().sum::<f64>() / nf;
    let acc_dev: Vec<f64> = acc.iter().map(|a| a - acc_mean).collect();
    let var_acc_mean = acc_dev.iter().map(|d| d * d).sum::<f64>() / (nf - 1.0) / nf * inflation(&acc_dev);
    let dv_da = -0.5 * t.iter().map(|x| (x - t_mean) * x * x).sum::<f64>() / sxx;
    // The line's share: residuals of the fit `fit_impact_speed` makes.
    let y: Vec<f64> = w.iter().zip(&t).map(|(s, x)| s.disp_m - 0.5 * acc_mean * x * x).collect();
    let y_mean = y.iter().sum::<f64>() / nf;
    let slope = t.iter().zip(&y).map(|(x, v)| (x - t_mean) * (v - y_mean)).sum::<f64>() / sxx;
    let resid: Vec<f64> = t.iter().zip(&y).map(|(x, v)| v - y_mean - slope * (x - t_mean)).collect();
    let s2 = resid.iter().map(|r| r * r).sum::<f64>() / (nf - 2.0);
    let var_slope = s2 / sxx * inflation(&resid);
    let var = dv_da * dv_da * var_acc_mean + var_slope;
    var.is_finite().then(|| var.sqrt())
}

/// Variance inflation of a mean or a slope for AR(1) noise, (1 + ρ)/(1 − ρ), at least 1.
fn inflation(dev: &[f64]) -> f64 {
    let var: f64 = dev.iter().map(|d| d * d).sum();
    if var <= 0.0 || dev.len() < 3 {
        return 1.0;
    }
    let rho = (dev.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / var).clamp(-0.99, 0.99);
    ((1.0 + rho) / (1.0 - rho)).max(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::approach::fit_impact_speed;
    use crate::signal::segment::Sample;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};

    /// A free-fall approach to 4.2 m/s at 100 kHz through a 10 µm encoder with 2 m/s² of
    /// accelerometer noise (`synth::CaptureSpec::hammer`'s sensors), built here, not by synth.
    fn approach(seed: u64) -> Blow {
        let dt = 1e-5;
        let mut rng = StdRng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 2.0).unwrap();
        let samples: Vec<Sample> = (-3000..=10)
            .map(|k| {
                let t = k as f64 * dt;
                let x = 4.2 * t + 0.5 * 9.81 * t * t;
                Sample {
                    t_s: 10.0 + t,
                    load_n: 0.0,
                    disp_m: ((0.3 + x) / 10e-6).round() * 10e-6,
                    acc_mps2: 9.81 + noise.sample(&mut rng),
                    filled: false,
                }
            })
            .collect();
        Blow { samples, i_trigger: 3000, i_contact: 3000, i_end: 3010, load_zero_n: 0.0, period_s: dt, lost_s: 0.0 }
    }

    #[test]
    fn the_reported_sd_matches_the_spread_over_noise_seeds() {
        // 200 approaches that differ only in the accelerometer's noise: the RMS of
        // (fitted − true) / sd must lie in the χ²(200) band's 0.5–99.5 % points,
        // sqrt(151.3/200) … sqrt(255.3/200) = 0.87 … 1.13.
        let n = 200;
        let mut sum = 0.0;
        for seed in 0..n {
            let b = approach(seed);
            let v = fit_impact_speed(&b.samples, b.i_contact, 0.01, b.period_s).map(|f| f.v_impact_mps);
            let (Ok(v), Some(sd)) = (v, impact_speed_sd_mps(&b, 0.01)) else { panic!("seed {seed}: no fit") };
            sum += ((v - 4.2) / sd).powi(2);
        }
        let rms = (sum / n as f64).sqrt();
        assert!((0.87..=1.13).contains(&rms), "RMS z {rms}");
    }

    #[test]
    fn too_short_a_window_has_no_sd() {
        let b = approach(1);
        assert!(impact_speed_sd_mps(&b, 1e-4).is_none());
    }
}
