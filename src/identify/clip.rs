//! Is a blow's load clipped? A sensor on its full scale repeats that value for as long as the
//! load exceeds it; a flat top through noise and an ADC's quantum repeats its maximum too, by
//! chance, for a run whose length the noise and the quantum bound (`clip_run`).

use crate::signal::segment::Blow;

/// Consecutive equal samples at the maximum that mark a clipped sensor, at least. A noisy
/// sensor needs more (`clip_run`).
pub const CLIP_RUN: usize = 3;
/// The chance, per blow, that noise alone repeats the load's maximum as long as the run that
/// is called a clip. A clip is a sensor sitting on its full scale for as long as the load
/// exceeds it; a flat top of a real load through noise and an ADC's quantum repeats its
/// maximum too, by chance (issue #17: the independent renderer's seed 534, 2 kN of noise on
/// a 122 N step, repeated a 2.33 MN maximum three times, well inside its ±4 MN range).
const CLIP_FALSE_ALARM: f64 = 1e-6;
/// The largest chance counted for two consecutive samples to be equal by noise: a sensor
/// whose noise is below its quantum may repeat any value, but not dozens of times at a peak
/// that moves.
const CLIP_PAIR_P_MAX: f64 = 0.5;

/// The clipped value and the length of its run, when `blow`'s load (maximum at `i_peak`)
/// repeats its maximum for `clip_run` samples or more: a clipped sensor repeats its
/// full-scale value.
pub(crate) fn clipped(blow: &Blow, i_peak: usize) -> Option<(f64, usize)> {
    let raw_peak = blow.samples.get(i_peak)?.load_n;
    let mut run = 0usize;
    let mut best = 0usize;
    for s in &blow.samples {
        run = if s.load_n == raw_peak { run + 1 } else { 0 };
        best = best.max(run);
    }
    (best >= clip_run(blow)).then_some((raw_peak, best))
}

/// The run of equal samples at the maximum that marks a clip on `blow`'s load: the shortest
/// that noise repeats with a chance under `CLIP_FALSE_ALARM` per blow, at least `CLIP_RUN`.
/// Two samples of a flat load with noise σ (the pre-trigger window's spread) on an ADC of
/// step q (the smallest step between the blow's distinct values) round to the same value
/// with a chance p ≈ q / (2 √π σ) (their difference has sd σ√2; the chance it falls within
/// ±q/2 of 0); a run of n, anywhere among the blow's N samples, about N p^(n−1).
/// The ADC's step as a signal shows it: the smallest step between its distinct finite
/// values (INFINITY with fewer than two).
pub fn adc_step(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min)
}

fn clip_run(blow: &Blow) -> usize {
    let pre: Vec<f64> = blow.samples[..blow.i_trigger.min(blow.samples.len())].iter().map(|s| s.load_n).collect();
    if pre.len() < 2 {
        return CLIP_RUN;
    }
    let mean = pre.iter().sum::<f64>() / pre.len() as f64;
    let sd = (pre.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (pre.len() - 1) as f64).sqrt();
    let step = adc_step(blow.samples.iter().map(|s| s.load_n));
    let p = if sd > 0.0 && step.is_finite() {
        (step / (2.0 * std::f64::consts::PI.sqrt() * sd)).min(CLIP_PAIR_P_MAX)
    } else {
        CLIP_PAIR_P_MAX
    };
    let n = blow.samples.len().max(1) as f64;
    // N p^(n−1) < CLIP_FALSE_ALARM.
    let run = 1.0 + (CLIP_FALSE_ALARM / n).ln() / p.ln();
    (run.ceil() as usize).max(CLIP_RUN)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::segment::Sample;

    /// A blow of `n` samples at 100 kHz, trigger at 500: a half-sine load of `peak` N over
    /// 2000 samples from 1000, noise `sd` N (a fixed LCG through Box–Muller, so the test
    /// needs no seed crate), quantised to `q` N, clipped at `full_scale` N.
    fn pulse(peak: f64, sd: f64, q: f64, full_scale: f64) -> Blow {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut uniform = || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let samples = (0..4000)
            .map(|i| {
                let x = if (1000..3000).contains(&i) {
                    peak * (std::f64::consts::PI * (i - 1000) as f64 / 2000.0).sin()
                } else {
                    0.0
                };
                let noise = sd * (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
                let load_n = (((x + noise) / q).round() * q).min(full_scale);
                Sample { t_s: i as f64 * 1e-5, load_n, disp_m: 0.0, acc_mps2: 0.0, filled: false }
            })
            .collect();
        Blow {
            samples,
            i_trigger: 500,
            i_contact: 1000,
            i_end: 3500,
            load_zero_n: 0.0,
            period_s: 1e-5,
            lost_s: 0.0,
            open_end_n: None,
            ram_cut: None,
        }
    }

    fn peak_index(b: &Blow) -> usize {
        (0..b.samples.len()).max_by(|i, j| b.samples[*i].load_n.total_cmp(&b.samples[*j].load_n)).unwrap_or(0)
    }

    #[test]
    fn a_noisy_flat_top_that_repeats_its_maximum_is_not_a_clip() {
        // The independent renderer's DAQ (tests/independent): 2 kN of noise on a 16-bit ADC
        // over ±4 MN (122 N steps). Two samples round alike with a chance of about
        // 122 / (2 √π 2000) = 0.017, so a clip takes 1 + ln(1e-6 / 4000) / ln(0.017) ≈ 6.4,
        // that is 7 equal samples.
        let q = 8e6 / 65536.0;
        let mut b = pulse(2.33e6, 2e3, q, f64::INFINITY);
        assert_eq!(clip_run(&b), 7);
        // The maximum repeated three times (seed 534's blow 4), inside the ADC's range.
        let i = peak_index(&b);
        let top = b.samples[i].load_n;
        b.samples[i + 1].load_n = top;
        b.samples[i + 2].load_n = top;
        assert_eq!(clipped(&b, peak_index(&b)), None);
    }

    #[test]
    fn a_sensor_on_its_full_scale_is_a_clip_with_noise_or_without() {
        let q = 8e6 / 65536.0;
        // Clipped at 600 kN: the half-sine is above it on 1 − 2 asin(600 / 2330) / π = 83 % of
        // its 2000 samples.
        for sd in [2e3, 0.0] {
            let b = pulse(2.33e6, sd, q, 600e3);
            let (value, run) = clipped(&b, peak_index(&b)).unwrap_or_else(|| panic!("sd {sd}: not found clipped"));
            assert_eq!(value, 600e3);
            assert!(run > 1500, "sd {sd}: run {run}");
        }
        // Without noise the shortest clip is 1 + ln(1e-6 / 4000) / ln(0.5) ≈ 32 samples: a
        // noise-free sensor may repeat a value, but not for a third of a millisecond.
        assert_eq!(clip_run(&pulse(2.33e6, 0.0, q, f64::INFINITY)), 33);
    }
}
