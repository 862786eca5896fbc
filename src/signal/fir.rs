//! Linear-phase FIR low-pass filters (windowed sinc, symmetric taps): the anti-alias filter
//! a sigma-delta DAQ applies before decimating (issue 16 renders test data through one,
//! `daq`), and the analysis low-pass the model fit puts both the measured and the modelled
//! signals through (`estimate::fit`). Pure code.

use std::f64::consts::PI;

/// A symmetric (linear-phase) FIR low-pass on a uniform grid. Applied centred, so it delays
/// nothing: a sample stands for the instant of the centre tap.
#[derive(Debug, Clone, PartialEq)]
pub struct LowPass {
    /// `2 half + 1` taps summing to 1 (unit gain at DC).
    taps: Vec<f64>,
    half: usize,
}

impl LowPass {
    /// Blackman-windowed sinc with its -6 dB point at `cutoff` (a fraction of the grid's
    /// sample rate, in (0, 0.5)) and a transition band `transition` wide (same units): the
    /// Blackman window's main lobe makes the transition about 5.5 / taps, and its side lobes
    /// stay below -74 dB.
    pub fn design(cutoff: f64, transition: f64) -> LowPass {
        let cutoff = cutoff.clamp(1e-6, 0.5);
        let half = ((5.5 / transition.max(1e-6)) / 2.0).ceil().max(1.0) as usize;
        let n = 2 * half + 1;
        let mut taps: Vec<f64> = (0..n)
            .map(|i| {
                let m = i as f64 - half as f64;
                let sinc = if m == 0.0 { 2.0 * cutoff } else { (2.0 * PI * cutoff * m).sin() / (PI * m) };
                let w = 0.42 - 0.5 * (2.0 * PI * i as f64 / (n - 1) as f64).cos()
                    + 0.08 * (4.0 * PI * i as f64 / (n - 1) as f64).cos();
                sinc * w
            })
            .collect();
        let sum: f64 = taps.iter().sum();
        for t in &mut taps {
            *t /= sum;
        }
        LowPass { taps, half }
    }

    /// Taps either side of the centre.
    pub fn half(&self) -> usize {
        self.half
    }

    pub fn taps(&self) -> &[f64] {
        &self.taps
    }

    /// The filtered value centred on `signal[i]`, the signal held at its first and last
    /// values beyond its ends.
    pub fn at(&self, signal: &[f64], i: usize) -> f64 {
        let n = signal.len();
        if n == 0 {
            return 0.0;
        }
        let start = i as i64 - self.half as i64;
        // Inside the signal, the same sum in the same order without the holding.
        if let Ok(first) = usize::try_from(start)
            && let Some(window) = signal.get(first..first + self.taps.len())
        {
            return self.taps.iter().zip(window).fold(0.0, |acc, (t, x)| acc + t * x);
        }
        let mut acc = 0.0;
        for (j, t) in self.taps.iter().enumerate() {
            let k = (start + j as i64).clamp(0, n as i64 - 1) as usize;
            acc += t * signal[k];
        }
        acc
    }

    /// The whole signal filtered (held at its ends).
    pub fn apply(&self, signal: &[f64]) -> Vec<f64> {
        (0..signal.len()).map(|i| self.at(signal, i)).collect()
    }

    /// Gain at frequency `f` (a fraction of the grid's rate).
    pub fn gain(&self, f: f64) -> f64 {
        self.taps.iter().enumerate().map(|(i, t)| t * (2.0 * PI * f * (i as f64 - self.half as f64)).cos()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_the_band_and_stops_beyond_the_transition() {
        let lp = LowPass::design(0.4 / 8.0, 0.2 / 8.0);
        assert!((lp.gain(0.0) - 1.0).abs() < 1e-12);
        // Flat to within 0.1 % up to 0.25 of the output rate (1/32 of the grid's).
        assert!((lp.gain(0.25 / 8.0) - 1.0).abs() < 1e-3, "{}", lp.gain(0.25 / 8.0));
        // -6 dB at the cutoff, and below -70 dB past the transition.
        assert!((lp.gain(0.4 / 8.0) - 0.5).abs() < 0.02, "{}", lp.gain(0.4 / 8.0));
        assert!(lp.gain(0.55 / 8.0).abs() < 3e-4, "{}", lp.gain(0.55 / 8.0));
    }

    #[test]
    fn a_ramp_passes_unchanged_away_from_the_ends() {
        let lp = LowPass::design(0.2, 0.1);
        let ramp: Vec<f64> = (0..200).map(|i| 3.0 * i as f64).collect();
        let out = lp.apply(&ramp);
        assert!((out[100] - 300.0).abs() < 1e-9, "{}", out[100]);
    }
}
