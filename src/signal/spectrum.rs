//! Amplitude spectra of blow signals and the vibration modes they show: the FFT step of
//! both papers' identification (hammer paper §2.2, press paper §2.3 and §3.1), where the
//! peaks of the sensor load's spectrum give the machine model's degrees of freedom.
//!
//! **The carrier wave.** A blow's load is one pulse, half-sine-like: a few ms on the hammer
//! (blow 1 of the model: 9.6 ms of forming, then a sub-ms unloading) and tens of ms on the
//! press (a 27 ms bare strike). Its spectrum is a lobe at 0 Hz about 1/(contact time) wide,
//! with sidelobes 1/(contact time) apart, and it dominates the low bins. The record lasts
//! little more than the contact, so the pulse is about half a period of the machine's slow
//! mode (the ram against the frame, 18 Hz in the press model), which the record cannot give
//! a frequency: its peak sits in bin 0 or 1 (hammer paper §2.2: "a vibratory mode in which
//! the oscillation frequency is lower than the resolution of the FFT"; press paper §3.1:
//! 0 Hz and 36.4 Hz are "the same vibration mode", of which only half a period is recorded).
//! [`Mode::below_resolution`] flags such a peak: a degree of freedom, not a machine mode
//! with a frequency. The machine's second mode (the lower tools on their support, ≈ 2 kHz
//! on the hammer, ≈ 290 Hz on the press) rings during and after the pulse and shows as a
//! peak on top of the pulse's spectrum.
//!
//! **Zero padding** (hammer paper §2.2) interpolates between the record's bins, 1/T apart
//! for a record of length T; it makes peaks easier to place but separates nothing closer
//! than 1/T.
//!
//! **Finding a blow's modes.** The pulse's sidelobes are peaks too, and in the load spectrum
//! they can outrank a machine mode: the hammer model's pulse ends with a 0.7 ms unloading,
//! an edge whose sidelobes fall only as 1/f (the first, at 140 Hz, has 18 % of the maximum's
//! prominence, the 2 kHz mode 31 %), and the press's 290 Hz mode has 11 % against the
//! pulse's lobe. The load-rate spectrum (× 2πf) lifts the modes but also the sidelobes of a
//! smooth pulse (28 % for a half-sine). [`blow_modes`] therefore looks for peaks in the
//! spectrum weighted by √(2πf), the geometric mean of the two, where the sidelobes of all
//! three stay below 16 % and the modes above 34 %, with [`BLOW_REL_PROMINENCE`] between.
//! The numbers are those of the tests below.

use std::fmt;
use std::sync::Arc;

use realfft::num_complex::Complex;
use realfft::{RealFftPlanner, RealToComplex};

/// Longest FFT computed, points (128 MiB of input). A longer request gives an empty spectrum.
pub const MAX_FFT_LEN: usize = 1 << 24;

/// One-sided amplitude spectrum: bin k is at k·df_hz, from 0 Hz to the Nyquist frequency.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Spectrum {
    /// Bin spacing, Hz: 1 / (padded length · dt).
    pub df_hz: f64,
    /// Resolution of the record, Hz: 1 / (unpadded length · dt). Zero padding interpolates
    /// between the record's bins but does not separate anything closer than this.
    pub resolution_hz: f64,
    /// Amplitude per bin, in the signal's unit (see [`SpectrumPlanner::spectrum`]).
    pub amplitude: Vec<f64>,
}

impl Spectrum {
    /// Frequency of bin `k`, Hz.
    pub fn frequency_hz(&self, k: usize) -> f64 {
        k as f64 * self.df_hz
    }

    pub fn len(&self) -> usize {
        self.amplitude.len()
    }

    pub fn is_empty(&self) -> bool {
        self.amplitude.is_empty()
    }

    /// The spectrum of the signal's `order`-th time derivative: each bin times
    /// (2π f)^`order`, with fractional orders (0.5: the geometric mean of the signal's and
    /// its rate's spectra, see [`blow_modes`]). Bin 0 becomes 0 for `order` > 0, and
    /// infinite for `order` < 0.
    pub fn derivative(&self, order: f64) -> Spectrum {
        let amplitude = self
            .amplitude
            .iter()
            .enumerate()
            .map(|(k, a)| a * (2.0 * std::f64::consts::PI * self.frequency_hz(k)).powf(order))
            .collect();
        Spectrum { amplitude, ..*self }
    }

    /// Amplitude at `f_hz` by linear interpolation between bins; 0 outside the spectrum
    /// (below 0 Hz, above the last bin, a non-finite `f_hz`, an empty spectrum).
    pub fn at(&self, f_hz: f64) -> f64 {
        let x = f_hz / self.df_hz;
        let last = self.amplitude.len().saturating_sub(1);
        if self.amplitude.is_empty() || !(x >= 0.0 && x <= last as f64) {
            return 0.0;
        }
        let i = (x.floor() as usize).min(last);
        if i == last {
            return self.amplitude[last];
        }
        let w = x - i as f64;
        self.amplitude[i] * (1.0 - w) + self.amplitude[i + 1] * w
    }
}

/// A peak of a spectrum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Peak frequency, Hz, refined between bins.
    pub frequency_hz: f64,
    /// Peak amplitude, refined between bins, in the spectrum's unit.
    pub amplitude: f64,
    /// Height of the peak above the higher of its two bases (see [`find_modes`]), as a
    /// fraction of the spectrum's maximum.
    pub rel_prominence: f64,
    /// The peak is in bin 0 or 1 of the unpadded record, below 1.5 × the resolution 1/T
    /// (1.5 bins when the spectrum gives no resolution): a mode slower than the record can
    /// resolve, or the blow's load pulse itself (the papers' carrier wave), not a machine
    /// mode that can be given a frequency.
    pub below_resolution: bool,
}

/// Zero-padded FFTs with the plan and the buffers kept from one call to the next, for
/// callers that take thousands of spectra of the same length (the identification).
pub struct SpectrumPlanner {
    planner: RealFftPlanner<f64>,
    fft: Option<Arc<dyn RealToComplex<f64>>>,
    input: Vec<f64>,
    output: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl fmt::Debug for SpectrumPlanner {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SpectrumPlanner").field("fft_len", &self.fft.as_ref().map(|p| p.len())).finish()
    }
}

impl Default for SpectrumPlanner {
    fn default() -> Self {
        Self::new()
    }
}

impl SpectrumPlanner {
    pub fn new() -> Self {
        SpectrumPlanner {
            planner: RealFftPlanner::new(),
            fft: None,
            input: Vec::new(),
            output: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// Bins 1, 2, ... of [`SpectrumPlanner::spectrum`] up to the last at or below
    /// `f_max_hz` (a fit's cost function compares about a tenth of a padded spectrum's
    /// bins, and takes one per simulated blow): realfft's whole transform, cut.
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
        match self.transform_to(signal, m) {
            Some(_) => self.output[1..=last].iter().map(|c| c.norm_sqr().sqrt() * scale).collect(),
            None => Vec::new(),
        }
    }

    /// One-sided amplitude spectrum of `signal`, sampled every `dt_s`, zero-padded to the
    /// next power of two ≥ max(`min_len`, `pad_factor` · `signal.len()`) (`pad_factor` 0
    /// counts as 1).
    ///
    /// Scaling: every bin is |X_k| · 2/N, with N = `signal.len()` (the unpadded length). A
    /// sine of amplitude A sampled over whole periods reads A at its frequency whatever
    /// the padding (padding adds zeros, not energy). Bins 0 and Nyquist get the same
    /// factor, so a constant c reads 2c at 0 Hz: the usual one-sided convention halves bin
    /// 0, which would put a dip at 0 Hz in the spectrum of a pulse and move the carrier's
    /// peak to bin 1. There is no window: a blow's load starts and ends at zero, so the
    /// record is its own window.
    ///
    /// The mean is not removed: a blow's load pulse is the carrier wave of the papers and
    /// is part of what the spectrum shows (module doc).
    ///
    /// Bad input gives an empty spectrum, never a panic: an empty signal, a non-finite
    /// sample, `dt_s` not finite and > 0, or a padded length over [`MAX_FFT_LEN`].
    pub fn spectrum(&mut self, signal: &[f64], dt_s: f64, pad_factor: usize, min_len: usize) -> Spectrum {
        let Some(m) = self.transform(signal, dt_s, pad_factor, min_len) else { return Spectrum::default() };
        let n = signal.len();
        let scale = 2.0 / n as f64;
        // |X| stays far below the 1e154 at which norm_sqr overflows for any signal of
        // physical size, and is half the cost of the hypot in `norm`.
        let amplitude = self.output.iter().map(|c| c.norm_sqr().sqrt() * scale).collect();
        Spectrum { df_hz: 1.0 / (m as f64 * dt_s), resolution_hz: 1.0 / (n as f64 * dt_s), amplitude }
    }

    /// The zero-padded FFT of `signal` into `self.output`; its padded length, or `None` (and
    /// nothing computed) on bad input (`spectrum`'s doc).
    fn transform(&mut self, signal: &[f64], dt_s: f64, pad_factor: usize, min_len: usize) -> Option<usize> {
        let m = checked_len(signal, dt_s, pad_factor, min_len)?;
        self.transform_to(signal, m)
    }

    /// `transform` of a signal `checked_len` passed, to its length `m`.
    fn transform_to(&mut self, signal: &[f64], m: usize) -> Option<usize> {
        let n = signal.len();
        let fft = match &self.fft {
            Some(f) if f.len() == m => Arc::clone(f),
            _ => {
                let f = self.planner.plan_fft_forward(m);
                self.input = f.make_input_vec();
                self.output = f.make_output_vec();
                self.scratch = f.make_scratch_vec();
                self.fft = Some(Arc::clone(&f));
                f
            }
        };
        self.input[..n].copy_from_slice(signal);
        self.input[n..].fill(0.0);
        // Only fails on buffers of the wrong length, which the plan made itself.
        fft.process_with_scratch(&mut self.input, &mut self.output, &mut self.scratch).ok().map(|()| m)
    }
}

/// `padded_len` of a signal that can be transformed: `None` for bad input (`spectrum`'s doc).
fn checked_len(signal: &[f64], dt_s: f64, pad_factor: usize, min_len: usize) -> Option<usize> {
    let good = !signal.is_empty() && dt_s.is_finite() && dt_s > 0.0 && signal.iter().all(|x| x.is_finite());
    good.then(|| padded_len(signal.len(), pad_factor, min_len)).flatten()
}

/// FFT length for `n` samples: the next power of two ≥ max(`min_len`, `pad_factor` · `n`, 2),
/// `None` above [`MAX_FFT_LEN`].
fn padded_len(n: usize, pad_factor: usize, min_len: usize) -> Option<usize> {
    let target = n.checked_mul(pad_factor.max(1))?.max(min_len).max(2);
    target.checked_next_power_of_two().filter(|&m| m <= MAX_FFT_LEN)
}

/// [`SpectrumPlanner::spectrum`] with a planner of its own, for one-off spectra.
pub fn amplitude_spectrum(signal: &[f64], dt_s: f64, pad_factor: usize, min_len: usize) -> Spectrum {
    SpectrumPlanner::new().spectrum(signal, dt_s, pad_factor, min_len)
}

/// Vibration modes of `s`: its local maxima whose prominence is at least `rel_prominence`
/// × the spectrum's maximum, the `max_modes` most prominent, sorted by frequency.
///
/// Prominence is the topographic one (as scipy's `peak_prominences`): from the peak, walk
/// each way until a higher bin or the end of the spectrum and take the lowest bin on the
/// way; the prominence is the height above the higher of these two minima. A one-sided
/// spectrum of a real signal is mirror-symmetric about 0 Hz and about the Nyquist
/// frequency, so a walk that reaches either end goes on along the mirror image: a peak at
/// 0 Hz (the carrier) is a peak, and measured against the valley on its right.
///
/// Each peak is refined by a parabola through the logarithm of its bin and its two
/// neighbours (exact for a Gaussian peak; within 0.05 bin on the main lobe of a sine's
/// record padded 8×). A plateau of equal bins counts as one peak at its middle. A
/// non-finite amplitude counts as 0. Nothing is found in a spectrum of fewer than two bins,
/// without a positive maximum, with `rel_prominence` not ≥ 0 or `max_modes` 0.
pub fn find_modes(s: &Spectrum, rel_prominence: f64, max_modes: usize) -> Vec<Mode> {
    let v: Vec<f64> = s.amplitude.iter().map(|&a| if a.is_finite() { a } else { 0.0 }).collect();
    let n = v.len();
    let a_max = v.iter().copied().fold(0.0, f64::max);
    if n < 2 || rel_prominence.is_nan() || rel_prominence < 0.0 || max_modes == 0 || a_max <= 0.0 {
        return Vec::new();
    }
    let threshold = rel_prominence * a_max;
    let resolution_hz = if s.resolution_hz > 0.0 { s.resolution_hz } else { s.df_hz };
    let prominence = prominences(&v);
    let mut modes: Vec<Mode> = local_maxima(&v)
        .into_iter()
        .filter_map(|p| {
            let prominence = prominence[p];
            (prominence >= threshold && prominence > 0.0).then(|| {
                let (offset, amplitude) = refine(&v, p);
                let frequency_hz = (p as f64 + offset) * s.df_hz;
                Mode {
                    frequency_hz,
                    amplitude,
                    rel_prominence: prominence / a_max,
                    below_resolution: frequency_hz < 1.5 * resolution_hz,
                }
            })
        })
        .collect();
    modes.sort_by(|a, b| b.rel_prominence.total_cmp(&a.rel_prominence));
    modes.truncate(max_modes);
    modes.sort_by(|a, b| a.frequency_hz.total_cmp(&b.frequency_hz));
    modes
}

/// Spectral weight of [`blow_modes`]: the half derivative, amplitude × √(2πf).
pub const BLOW_WEIGHT_ORDER: f64 = 0.5;

/// Relative prominence of [`blow_modes`]: above the pulse sidelobes of the blows in the
/// tests (≤ 0.16: the hammer model's blow 1, the press model's bare strike, a half-sine)
/// and below their carrier and mode peaks (≥ 0.34), with room both ways.
pub const BLOW_REL_PROMINENCE: f64 = 0.25;

/// The modes of a blow's load spectrum `load` (module doc, "Finding a blow's modes"): the
/// peaks of `load.derivative(BLOW_WEIGHT_ORDER)` with a relative prominence of at least
/// [`BLOW_REL_PROMINENCE`], at most `max_modes`, sorted by frequency. Each mode's amplitude
/// is read back from `load` at its frequency, in the load's unit; its relative prominence
/// is the weighted spectrum's. The carrier's peak lands in the first bins of the weighted
/// spectrum (it is 0 at 0 Hz) and is flagged [`Mode::below_resolution`] as long as the
/// record is not much longer than the contact, as a segmented blow is; in a much longer
/// record it would show as a low-frequency mode near 1/(2 · contact time).
pub fn blow_modes(load: &Spectrum, max_modes: usize) -> Vec<Mode> {
    let mut modes = find_modes(&load.derivative(BLOW_WEIGHT_ORDER), BLOW_REL_PROMINENCE, max_modes);
    for m in &mut modes {
        m.amplitude = load.at(m.frequency_hz);
    }
    modes
}

/// Indices of the local maxima of `v` (n ≥ 2), mirrored at both ends; a plateau gives its
/// middle.
fn local_maxima(v: &[f64]) -> Vec<usize> {
    let n = v.len();
    let mut peaks = Vec::new();
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j + 1 < n && v[j + 1] == v[i] {
            j += 1;
        }
        // Neighbours of the plateau i..=j; past an end, the mirror image continues the
        // plateau and then shows the neighbour on the other side.
        let left = if i > 0 { Some(v[i - 1]) } else { v.get(j + 1).copied() };
        let right = if j + 1 < n { Some(v[j + 1]) } else { i.checked_sub(1).map(|k| v[k]) };
        if let (Some(l), Some(r)) = (left, right)
            && v[i] > l
            && v[i] > r
        {
            peaks.push(if i == 0 {
                0
            } else if j == n - 1 {
                n - 1
            } else {
                (i + j) / 2
            });
        }
        i = j + 1;
    }
    peaks
}

/// Topographic prominence (see [`find_modes`]) of every bin of `v` taken as a peak, in
/// one pass each way.
fn prominences(v: &[f64]) -> Vec<f64> {
    let left = bases(v.iter().copied());
    let mut right = bases(v.iter().rev().copied());
    right.reverse();
    v.iter()
        .zip(left)
        .zip(right)
        .map(|((&h, (left, left_end)), (right, right_end))| {
            // A walk past an end comes back along the mirror image, over the peak's twin
            // and on along the other side's walk.
            let left_ref = if left_end { left.min(right) } else { left };
            let right_ref = if right_end { right.min(left) } else { right };
            let base = left_ref.max(right_ref);
            if base.is_finite() { h - base } else { 0.0 }
        })
        .collect()
}

/// For each bin in the order given: the lowest bin on the walk back to the nearest higher
/// bin, and whether the walk reached the start instead (the lowest bin is then over the
/// whole way, +∞ for the first bin). The stack holds the bins no higher bin has passed
/// yet, each with the lowest bin between it and the next on the stack (or the current
/// bin); the walks of all bins cost one pass.
fn bases(v: impl Iterator<Item = f64>) -> Vec<(f64, bool)> {
    let mut out = Vec::with_capacity(v.size_hint().0);
    let mut stack: Vec<(f64, f64)> = Vec::new();
    let mut below_bottom = f64::INFINITY;
    for h in v {
        let mut low = f64::INFINITY;
        while let Some(&(top_h, top_low)) = stack.last()
            && top_h <= h
        {
            low = low.min(top_h).min(top_low);
            stack.pop();
        }
        match stack.last_mut() {
            Some((_, gap)) => {
                *gap = gap.min(low);
                out.push((*gap, false));
            }
            None => {
                below_bottom = below_bottom.min(low);
                out.push((below_bottom, true));
            }
        }
        stack.push((h, f64::INFINITY));
    }
    out
}

/// Offset from bin `p` (within ±0.5) and height of the parabola through the log-amplitude
/// of bins p-1, p, p+1 (mirrored at the ends); no refinement where a bin is 0.
fn refine(v: &[f64], p: usize) -> (f64, f64) {
    let n = v.len();
    let lo = if p > 0 { v[p - 1] } else { v[1] };
    let hi = if p + 1 < n { v[p + 1] } else { v[n - 2] };
    let (a, b, c) = (lo, v[p], hi);
    if !(a > 0.0 && b > 0.0 && c > 0.0) {
        return (0.0, b);
    }
    let (a, b, c) = (a.ln(), b.ln(), c.ln());
    let curvature = a - 2.0 * b + c;
    // Finite: the logarithms of finite positive numbers.
    if curvature >= 0.0 {
        return (0.0, v[p]);
    }
    let offset = (0.5 * (a - c) / curvature).clamp(-0.5, 0.5);
    (offset, (b - 0.25 * (a - c) * offset).exp())
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;
    use crate::config::{parse_machine, parse_process};
    use crate::physics::{BlowResult, EffectSet, Machine, SimOptions, simulate_bare, simulate_sequence};

    pub(super) fn sine(f_hz: f64, amplitude: f64, dt_s: f64, n: usize) -> impl Iterator<Item = f64> {
        (0..n).map(move |i| amplitude * (2.0 * PI * f_hz * i as f64 * dt_s).sin())
    }

    /// A half-sine pulse of `pulse_s` at the start of a record of `n` samples.
    pub(super) fn half_sine(pulse_s: f64, dt_s: f64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let t = i as f64 * dt_s;
                if t < pulse_s { (PI * t / pulse_s).sin() } else { 0.0 }
            })
            .collect()
    }

    fn machine(name: &str, toml: &str) -> Machine {
        parse_machine(name, toml).unwrap().machine
    }

    /// Sensor load of a simulated blow, sampled every `TRACE_DT_S`.
    const TRACE_DT_S: f64 = 1e-5;

    fn sensor_load(b: &BlowResult) -> Vec<f64> {
        b.trace.iter().map(|p| p.out.sensor_n).collect()
    }

    fn opts() -> SimOptions {
        SimOptions { trace_dt_s: Some(TRACE_DT_S), ..SimOptions::default() }
    }

    #[test]
    fn two_sines_give_two_modes_at_their_frequencies_and_amplitudes() {
        // 0.1 s at 20 kHz: 30 and 200 whole periods.
        let dt = 1.0 / 20_000.0;
        let n = 2000;
        let x: Vec<f64> = sine(300.0, 2.0, dt, n).zip(sine(2000.0, 0.5, dt, n)).map(|(a, b)| a + b).collect();
        let s = amplitude_spectrum(&x, dt, 8, 0);
        assert_eq!(s.len(), 16384 / 2 + 1);
        assert!((s.df_hz - 20_000.0 / 16384.0).abs() < 1e-12);
        assert!((s.resolution_hz - 10.0).abs() < 1e-9);
        // Without a window the zero-padded record shows the sinc's sidelobes: the 300 Hz
        // sine's first has 21.7 % of its peak, a prominence of 0.217 of the maximum, below
        // the 2000 Hz sine's 0.25; the two most prominent peaks are the two sines.
        let modes = find_modes(&s, 0.1, 2);
        assert_eq!(modes.len(), 2, "{modes:?}");
        for (m, (f, a)) in modes.iter().zip([(300.0, 2.0), (2000.0, 0.5)]) {
            // The peak bin is within half a bin of the true frequency and the parabola
            // only moves it within ±half a bin, towards the top: under one bin.
            assert!((m.frequency_hz - f).abs() < s.df_hz, "{m:?}");
            // Over whole periods each sine's spectrum is a sinc-like lobe of height A
            // centred on its frequency, so the errors are the nearest padded bin's offset
            // from the top (≤ 1/16 of the resolution: sinc(1/16) = 0.994 before refinement)
            // and the other sine's leakage (170 resolutions away: ≤ A_other / (π · 170),
            // 0.004 from the 300 Hz sine, 0.75 % of 0.5); 5 % bounds both with room.
            assert!((m.amplitude - a).abs() < 0.05 * a, "{m:?}");
            assert!(!m.below_resolution);
        }
    }

    #[test]
    fn sine_amplitude_does_not_depend_on_padding() {
        // 64 whole periods in 1024 samples, padded 1× to 16×: A = 3 on the sine's bin.
        let dt = 1e-3;
        let x: Vec<f64> = sine(62.5, 3.0, dt, 1024).collect();
        let mut planner = SpectrumPlanner::new();
        for pad in [1, 2, 16] {
            let s = planner.spectrum(&x, dt, pad, 0);
            assert_eq!(s.len(), 1024 * pad / 2 + 1);
            // Exact up to rounding: the FFT of whole periods.
            assert!((s.amplitude[64 * pad] - 3.0).abs() < 1e-9, "pad {pad}: {}", s.amplitude[64 * pad]);
            assert!((s.at(62.5) - 3.0).abs() < 1e-9);
        }
        // A constant reads twice itself at 0 Hz (uniform 2/N scaling, see `spectrum`).
        let s = planner.spectrum(&[1.5; 100], dt, 1, 0);
        assert!((s.amplitude[0] - 3.0).abs() < 1e-12);
    }

    #[test]
    fn planner_reused_across_lengths_matches_a_fresh_one() {
        let dt = 1e-4;
        let a: Vec<f64> = sine(440.0, 1.0, dt, 700).collect();
        let b = half_sine(0.01, dt, 300);
        let mut planner = SpectrumPlanner::new();
        for x in [&a, &b, &a, &b] {
            assert_eq!(planner.spectrum(x, dt, 4, 1024), amplitude_spectrum(x, dt, 4, 1024));
        }
    }

    #[test]
    fn at_interpolates_between_bins_and_is_zero_outside() {
        let s = Spectrum { df_hz: 10.0, resolution_hz: 10.0, amplitude: vec![1.0, 3.0, 2.0] };
        assert_eq!(s.at(0.0), 1.0);
        assert_eq!(s.at(5.0), 2.0);
        assert_eq!(s.at(17.5), 2.25);
        assert_eq!(s.at(20.0), 2.0);
        for f in [-1.0, 20.5, f64::NAN, f64::INFINITY] {
            assert_eq!(s.at(f), 0.0, "{f}");
        }
        assert_eq!(Spectrum::default().at(0.0), 0.0);
    }

    #[test]
    fn half_sine_pulse_alone_is_only_the_carrier() {
        // A 10 ms pulse in a 15 ms record at 100 kHz (the hammer's blow and record, module
        // doc). The half-sine's spectrum, |cos(π f T)| / |1 − 4 f² T²|, peaks at 0 Hz and its
        // sidelobes have at most 1/(4 · 2.5² − 1) = 4.2 % of it: the carrier alone.
        let dt = 1e-5;
        let s = amplitude_spectrum(&half_sine(0.01, dt, 1500), dt, 8, 0);
        let modes = find_modes(&s, 0.1, 10);
        assert_eq!(modes.len(), 1, "{modes:?}");
        assert_eq!(modes[0].frequency_hz, 0.0);
        assert!(modes[0].below_resolution);
        // Weighted by √(2πf) the pulse's lobe moves off 0 Hz, still within the record's
        // first bin (66.7 Hz); the sidelobes stay under BLOW_REL_PROMINENCE (the first has
        // 0.15).
        let modes = blow_modes(&s, 10);
        assert_eq!(modes.len(), 1, "{modes:?}");
        assert!(modes[0].below_resolution && modes[0].frequency_hz > 0.0, "{modes:?}");
    }

    #[test]
    fn hammer_model_blow_1_shows_the_two_kilohertz_mode() {
        // Hammer paper §3.1.2: blow 1 on the steel billet at 3.9 m/s, machine of Table 1.
        let hammer = machine("hammer", include_str!("../../config/hammer-lg1000.machine.toml"));
        let steel = parse_process("steel", include_str!("../../config/steel-16NiCrMo13.process.toml")).unwrap();
        let b = simulate_sequence(&hammer, &EffectSet::NONE, &steel, &[3.9], &opts()).unwrap().remove(0);
        let s = amplitude_spectrum(&sensor_load(&b), TRACE_DT_S, 8, 0);

        // In the load spectrum itself the pulse's sidelobes (140, 240, ... Hz) are peaks
        // between the carrier and the mode at 10 % prominence: why blow_modes weights.
        let raw = find_modes(&s, 0.1, 10);
        assert!(raw.iter().any(|m| !m.below_resolution && m.frequency_hz < 1000.0), "{raw:?}");

        // The paper's two degrees of freedom (§2.2): the carrier below the resolution, and
        // one machine mode.
        let modes = blow_modes(&s, 10);
        assert!(modes.first().is_some_and(|m| m.below_resolution), "{modes:?}");
        let machine_modes: Vec<&Mode> = modes.iter().filter(|m| !m.below_resolution).collect();
        assert_eq!(machine_modes.len(), 1, "{modes:?}");
        let f = machine_modes[0].frequency_hz;
        // 1.6–2.5 kHz: the paper measured "about 1.8 kHz" (§2.2, Fig. 3) and the model's
        // lower tool rings at sqrt(k/m2)/2π = 2.05 kHz (Table 1); the band takes in both
        // with 10 % below the one and 20 % above the other.
        assert!((1600.0..=2500.0).contains(&f), "{f} Hz");
        // And the model's own frequency within the record's resolution 1/T (65 Hz): the
        // ringing lasts the record, so the peak is placed no better than that.
        assert!((f - hammer.second_mode_hz()).abs() < s.resolution_hz, "{f} Hz vs {}", hammer.second_mode_hz());
    }

    #[test]
    fn press_model_bare_strike_shows_the_three_hundred_hertz_mode() {
        // Press paper §3.2: bare strike at 0.363 m/s, machine of Table 3.
        let press = machine("press", include_str!("../../config/screw-press-spr400.machine.toml"));
        let b = simulate_bare(&press, &EffectSet::NONE, 0.363, &opts()).unwrap();
        let s = amplitude_spectrum(&sensor_load(&b), TRACE_DT_S, 8, 0);
        // Press paper §3.1: two modes, one near 0 Hz (the carrier) and one at about 292 Hz.
        let modes = blow_modes(&s, 10);
        assert!(modes.first().is_some_and(|m| m.below_resolution), "{modes:?}");
        let machine_modes: Vec<&Mode> = modes.iter().filter(|m| !m.below_resolution).collect();
        assert_eq!(machine_modes.len(), 1, "{modes:?}");
        let f = machine_modes[0].frequency_hz;
        // 292 Hz read from the paper's FFT with bins δf = 36.4 Hz apart (§3.1): the true
        // peak is within a bin of it.
        assert!((f - 292.0).abs() < 36.4, "{f} Hz");
        // The model's tool mode, sqrt((k_link + k_sensor ⊕ k_frame) / m_tool) / 2π =
        // 276 Hz, within the record's resolution 1/T (31 Hz).
        assert!((f - press.second_mode_hz()).abs() < s.resolution_hz, "{f} Hz vs {}", press.second_mode_hz());
    }

    /// The walks of `find_modes`'s doc, bin by bin: the reference for `prominences`.
    fn naive_prominence(v: &[f64], p: usize) -> f64 {
        let h = v[p];
        // Lowest bin on the walk to the first higher bin, and whether the walk hit the end.
        let walk = |range: &mut dyn Iterator<Item = usize>| {
            let mut low = f64::INFINITY;
            for i in range {
                if v[i] > h {
                    return (low, false);
                }
                low = low.min(v[i]);
            }
            (low, true)
        };
        let (left, left_end) = walk(&mut (0..p).rev());
        let (right, right_end) = walk(&mut (p + 1..v.len()));
        // A walk past an end comes back along the mirror image, over the peak's twin and
        // on along the other side's walk.
        let left_ref = if left_end { left.min(right) } else { left };
        let right_ref = if right_end { right.min(left) } else { right };
        let base = left_ref.max(right_ref);
        if base.is_finite() { h - base } else { 0.0 }
    }

    #[test]
    fn prominences_match_the_walks_bin_by_bin() {
        // A pulse's spectrum (a long falling run of small ripples, where every walk to the
        // right runs to the end), noise with plateaus, and small hand-made cases.
        let dt = 1e-5;
        let pulse = amplitude_spectrum(&half_sine(0.01, dt, 1500), dt, 4, 0).amplitude;
        let mut seed = 12345u64;
        let noise: Vec<f64> = (0..3000)
            .map(|_| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((seed >> 33) % 16) as f64
            })
            .collect();
        let cases = [pulse, noise, vec![1.0, 2.0], vec![2.0, 1.0], vec![1.0, 1.0, 1.0], vec![3.0, 1.0, 2.0, 1.0, 3.0]];
        for v in &cases {
            let fast = prominences(v);
            for (p, &f) in fast.iter().enumerate() {
                assert_eq!(f, naive_prominence(v, p), "bin {p} of {} bins", v.len());
            }
        }
    }

    #[test]
    fn bad_input_gives_empty_results() {
        let x = [0.0, 1.0, 0.5, -0.2];
        for (signal, dt) in [
            (&[][..], 1e-3),
            (&[0.0, f64::NAN, 1.0][..], 1e-3),
            (&[0.0, f64::INFINITY][..], 1e-3),
            (&x[..], 0.0),
            (&x[..], -1e-3),
            (&x[..], f64::NAN),
            (&x[..], f64::INFINITY),
        ] {
            let s = amplitude_spectrum(signal, dt, 4, 64);
            assert!(s.is_empty(), "{signal:?} {dt}");
            assert!(find_modes(&s, 0.1, 10).is_empty());
            assert!(blow_modes(&s, 10).is_empty());
        }
        // Lengths that overflow or exceed MAX_FFT_LEN.
        assert!(amplitude_spectrum(&x, 1e-3, usize::MAX, 0).is_empty());
        assert!(amplitude_spectrum(&x, 1e-3, 1, usize::MAX).is_empty());
        assert!(amplitude_spectrum(&x, 1e-3, 1, MAX_FFT_LEN + 1).is_empty());
        // A pad factor of 0 counts as 1.
        assert_eq!(amplitude_spectrum(&x, 1e-3, 0, 0).len(), 3);

        // Spectra find_modes cannot use.
        let good = amplitude_spectrum(&half_sine(0.01, 1e-4, 150), 1e-4, 4, 0);
        assert!(find_modes(&good, f64::NAN, 10).is_empty());
        assert!(find_modes(&good, -0.1, 10).is_empty());
        assert!(find_modes(&good, 0.1, 0).is_empty());
        let flat = Spectrum { df_hz: 1.0, resolution_hz: 1.0, amplitude: vec![2.0; 16] };
        assert!(find_modes(&flat, 0.0, 10).is_empty());
        let zero = Spectrum { amplitude: vec![0.0; 16], ..flat.clone() };
        assert!(find_modes(&zero, 0.0, 10).is_empty());
        // A non-finite bin counts as 0: a valley, not a peak (so 0 Hz and the last bin are
        // peaks, by the mirror at both ends).
        let nan = Spectrum { amplitude: vec![1.0, f64::NAN, 3.0, 1.0, f64::INFINITY, 0.5], ..flat };
        let modes = find_modes(&nan, 0.0, 10);
        assert_eq!(modes.iter().map(|m| m.frequency_hz).collect::<Vec<_>>(), [0.0, 2.0, 5.0], "{modes:?}");
        assert_eq!(modes.iter().map(|m| m.amplitude).collect::<Vec<_>>(), [1.0, 3.0, 0.5]);
    }
}
