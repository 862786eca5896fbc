//! The lowest bins of a zero-padded real FFT without the others: a fit's cost function
//! compares about a tenth of a padded spectrum's bins (`identify::objective`'s band) and
//! takes one spectrum per simulated blow, and realfft splits the complex transform's
//! outputs into the real signal's bins over all of them (5 % of the hammer's fitted blow,
//! README "Diagnosis: location, basins, speed"). realfft has no call for a band, so this is
//! its `RealToComplexEven` (3.5) for the first bins alone: the same complex FFT of half the
//! length (rustfft's planner, as realfft plans it, on the even and odd samples as one
//! complex signal), realfft's twiddles, and its split's expressions in its order, so the
//! bins are realfft's to the bit (`spectrum`'s tests compare every bin).

use std::sync::Arc;

use realfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

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
    /// The plan for a real transform of `len` points (even, ≥ 4).
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

    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// The highest bin `amplitudes` can give: below a quarter of the length, where realfft's
    /// split pairs each bin with one from the top half.
    pub(super) fn max_bin(&self) -> usize {
        self.twiddles.len()
    }

    /// `|X_k| * scale` for k = 1 ..= `last` (at most `max_bin`) of `signal` (at most `len`
    /// samples) zero-padded to `len`, into `out`.
    pub(super) fn amplitudes(&mut self, signal: &[f64], last: usize, scale: f64, out: &mut Vec<f64>) {
        debug_assert!(signal.len() <= self.len && last <= self.max_bin());
        // realfft reads its real input as complex pairs (even sample, odd sample).
        let pairs = signal.chunks_exact(2);
        let odd = pairs.remainder().first().copied();
        let mut filled = 0;
        for (c, p) in self.input.iter_mut().zip(pairs) {
            *c = Complex { re: p[0], im: p[1] };
            filled += 1;
        }
        if let Some(x) = odd {
            self.input[filled] = Complex { re: x, im: 0.0 };
            filled += 1;
        }
        // The transform uses its input as scratch: the padding is written every time.
        self.input[filled..].fill(Complex::default());
        self.fft.process_outofplace_with_scratch(&mut self.input, &mut self.output, &mut self.scratch);
        let half = self.len / 2;
        out.clear();
        out.extend((1..=last).map(|k| {
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
        }));
    }
}
