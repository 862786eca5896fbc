//! The lowest bins of a zero-padded real FFT without the others: a fit's cost function
//! compares about a tenth of a padded spectrum's bins (`identify::objective`'s band) and
//! takes one spectrum per simulated blow, and realfft splits the complex transform's
//! outputs into the real signal's bins over all of them (5 % of the hammer's fitted blow,
//! docs/validation.md "Diagnosis: location, basins, speed"). realfft has no call for a band, so this is
//! its `RealToComplexEven` (3.5) for the first bins alone: the same complex FFT of half the
//! length (rustfft's planner, as realfft plans it, on the even and odd samples as one
//! complex signal), realfft's twiddles, and its split's expressions in its order, so the
//! bins are realfft's to the bit (the tests below compare every bin).

use std::sync::Arc;

use realfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

use super::{SpectrumPlanner, checked_len};

impl SpectrumPlanner {
    /// Bins 1, 2, ... of [`SpectrumPlanner::spectrum`] up to the last at or below
    /// `f_max_hz`, to the bit, without the amplitudes above it (a fit's cost function
    /// compares about a tenth of a padded spectrum's bins, and takes one per simulated blow).
    /// A band below a quarter of the padded length (a fit's) is split out of the complex
    /// transform alone (`band`); a wider one takes the whole spectrum.
    pub fn amplitudes_up_to(
        &mut self,
        signal: &[f64],
        dt_s: f64,
        pad_factor: usize,
        min_len: usize,
        f_max_hz: f64,
    ) -> Vec<f64> {
        let Some(m) = checked_len(signal, dt_s, pad_factor, min_len) else { return Vec::new() };
        let scale = 2.0 / signal.len() as f64;
        let df_hz = 1.0 / (m as f64 * dt_s);
        let last = (1..=m / 2).take_while(|&k| k as f64 * df_hz <= f_max_hz).last().unwrap_or(0);
        if last <= Band::max_bin(m) {
            let band = match &mut self.band {
                Some(b) if b.len == m => b,
                slot => slot.insert(Band::new(&mut self.band_planner, m)),
            };
            return band.amplitudes(signal, last, scale);
        }
        match self.transform_to(signal, m) {
            Some(_) => self.output[1..=last].iter().map(|c| c.norm_sqr().sqrt() * scale).collect(),
            None => Vec::new(),
        }
    }
}

/// The band's plan for one padded length, and its buffers.
pub(super) struct Band {
    /// The real transform's length, even.
    len: usize,
    fft: Arc<dyn Fft<f64>>,
    /// realfft's: `e^{-2πik/len} / 2` for bin k = 1, 2, ..., below `len / 4`.
    twiddles: Vec<Complex<f64>>,
    input: Vec<Complex<f64>>,
    output: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl Band {
    /// The plan for a real transform of `len` points (even).
    pub(super) fn new(planner: &mut FftPlanner<f64>, len: usize) -> Band {
        let half = len / 2;
        let fft = planner.plan_fft_forward(half);
        // realfft's `compute_twiddle(i, len) * 0.5`.
        let twiddles = (1..len / 4)
            .map(|i| {
                let angle = -2f64 * std::f64::consts::PI / len as f64 * i as f64;
                Complex { re: angle.cos(), im: angle.sin() } * 0.5
            })
            .collect();
        let scratch = vec![Complex::default(); fft.get_outofplace_scratch_len()];
        Band {
            len,
            fft,
            twiddles,
            input: vec![Complex::default(); half],
            output: vec![Complex::default(); half],
            scratch,
        }
    }

    /// The highest bin `amplitudes` gives for a transform of `len` points: below a quarter
    /// of the length, where realfft's split pairs each bin with one from the top half.
    fn max_bin(len: usize) -> usize {
        (len / 4).saturating_sub(1)
    }

    /// `|X_k| * scale` for k = 1 ..= `last` (at most `max_bin`) of `signal` (at most `len`
    /// samples) zero-padded to `len`.
    pub(super) fn amplitudes(&mut self, signal: &[f64], last: usize, scale: f64) -> Vec<f64> {
        debug_assert!(signal.len() <= self.len && last <= Band::max_bin(self.len));
        // realfft reads its real input as complex pairs (even sample, odd sample).
        // An odd last sample is paired with the padding's first zero.
        let filled = signal.len().div_ceil(2);
        for (c, p) in self.input.iter_mut().zip(signal.chunks(2)) {
            *c = Complex { re: p[0], im: p.get(1).copied().unwrap_or(0.0) };
        }
        // The transform uses its input as scratch: the padding is written every time.
        self.input[filled..].fill(Complex::default());
        self.fft.process_outofplace_with_scratch(&mut self.input, &mut self.output, &mut self.scratch);
        let half = self.len / 2;
        (1..=last)
            .map(|k| {
                // realfft's split of bin k (and of bin half - k, not kept), term for term.
                let (x, x_rev, tw) = (self.output[k], self.output[half - k], self.twiddles[k - 1]);
                let sum = x + x_rev;
                let diff = x - x_rev;
                let twiddled_re_sum = sum * tw.re;
                let twiddled_im_sum = sum * tw.im;
                let twiddled_re_diff = diff * tw.re;
                let twiddled_im_diff = diff * tw.im;
                let half_sum_re = 0.5 * sum.re;
                let half_diff_im = 0.5 * diff.im;
                let re = half_sum_re + (twiddled_re_sum.im + twiddled_im_diff.re);
                let im = half_diff_im + (twiddled_im_sum.im - twiddled_re_diff.re);
                Complex { re, im }.norm_sqr().sqrt() * scale
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{half_sine, sine};
    use super::super::{SpectrumPlanner, amplitude_spectrum};

    #[test]
    fn the_band_up_to_a_frequency_is_the_spectrums_bins_to_the_bit() {
        // A 9.6 ms half-sine pulse with a 2 kHz ring, 1715 samples at 100 kHz (a fitted
        // hammer blow's window), padded 4×: the bins a fit compares, from both methods.
        let dt = 1e-5;
        let x: Vec<f64> =
            half_sine(9.6e-3, dt, 1715).iter().zip(sine(2050.0, 0.05, dt, 1715)).map(|(a, b)| a + b).collect();
        let mut planner = SpectrumPlanner::new();
        let s = planner.spectrum(&x, dt, 4, 0);
        // A band edge between bins, one exactly on a bin's frequency, and past Nyquist.
        for f_max in [5000.0, 40.0 * s.df_hz, 1e9] {
            let want: Vec<f64> =
                (1..s.len()).take_while(|&k| s.frequency_hz(k) <= f_max).map(|k| s.amplitude[k]).collect();
            assert!(!want.is_empty());
            assert_eq!(planner.amplitudes_up_to(&x, dt, 4, 0, f_max), want, "f_max {f_max}");
        }
        assert!(planner.amplitudes_up_to(&[1.0, f64::NAN], dt, 4, 0, 5000.0).is_empty());
    }

    #[test]
    fn the_band_split_alone_is_realffts_split_to_the_bit() {
        // A half-sine pulse with a 2 kHz ring and an offset, at odd and even lengths (an odd
        // one leaves its last sample unpaired); paddings that leave from 7 % (301 of 4096) to all
        // of the transform filled; band edges from the first bin to either side of a quarter of
        // the padded length, where the band split stops and the whole spectrum is taken,
        // with the planner's length changing in between.
        let dt = 1e-5;
        let mut planner = SpectrumPlanner::new();
        for n in [1715, 1716, 301, 4] {
            let x: Vec<f64> = half_sine(n as f64 * 0.6 * dt, dt, n)
                .iter()
                .zip(sine(2050.0, 0.05, dt, n))
                .map(|(a, b)| a + b + 1e-3)
                .collect();
            for (pad, min_len) in [(4, 0), (1, 0), (2, 4096)] {
                let s = amplitude_spectrum(&x, dt, pad, min_len);
                let quarter = (s.len() - 1) / 2;
                for last in [1, 2, quarter / 3, quarter - 1, quarter, quarter + 1, s.len() - 1] {
                    let last = last.clamp(1, s.len() - 1);
                    // Half a bin above `last`: the band's edge falls between bins.
                    let f_max = (last as f64 + 0.5) * s.df_hz;
                    let got = planner.amplitudes_up_to(&x, dt, pad, min_len, f_max);
                    assert_eq!(got, s.amplitude[1..=last], "n {n}, pad {pad}, min_len {min_len}, last bin {last}");
                }
            }
        }
    }
}
