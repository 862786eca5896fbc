//! A DAQ chain for test data that does not share the estimator's code path (issue 16): the
//! simulator integrates each blow with classical RK4 at a fine fixed step (the `simulate
//! --rk4-dt` path, not the adaptive solver the model fit runs), the analogue channels
//! (load, accelerometer) pass a linear-phase anti-alias low-pass at 0.4 × the output rate
//! (a sigma-delta ADC's decimation filter: Blackman-windowed sinc, symmetric taps) and are
//! decimated, the encoder (a counter, latched at each sample instant) is read without a
//! filter, and then the DAQ's imperfections are added as in `synth`: load noise and a load
//! offset, encoder steps, accelerometer noise.
//!
//! Each output sample is stamped at its filter's centre tap: the DAQ removes its filter's
//! group delay from the timestamps, as DAQs that align channels of different filters do.
//! The DAQ's clock does not know the blow: first contact falls at a random point between
//! two samples (uniform over the fine steps of a sample period, drawn per blow from its own
//! stream so that the noise is the same whatever the phase), so a contact locator that
//! only finds sample instants shows its error.
//! The truth comes with every blow, as in `synth`.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use crate::physics::blow::SimOptions;
use crate::physics::effects::EffectSet;
use crate::physics::integrator::Method;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::physics::sequence::{SequenceError, simulate_sequence};
use crate::signal::capture::CaptureRow;
use crate::signal::fir::LowPass;
use crate::synth::{Approach, CaptureSpec, ENCODER_AT_LOWER_DIE_M, G_MPS2, SynthBlow};

/// The simulator's fixed step is at most this, s: 1 µs resolves the hammer's 2 kHz mode
/// with 500 steps a period, and every rate of issue 16 (5–100 kHz) divides 1 MHz.
pub const MAX_FINE_STEP_S: f64 = 1e-6;
/// Seeds the contact phases' stream, apart from the noise's.
const PHASE_STREAM: u64 = 0x9e37_79b9_7f4a_7c15;
/// The anti-alias filter's -6 dB point, a fraction of the output rate (issue 16).
pub const ANTI_ALIAS_CUTOFF: f64 = 0.4;
/// Its transition band, a fraction of the output rate: from 0.3 to 0.5, so that nothing
/// above the output's Nyquist frequency passes (stop band below -74 dB).
pub const ANTI_ALIAS_TRANSITION: f64 = 0.2;

/// The DAQ: what to capture around each blow and at which rate (`capture`), and how
/// finely the physics underneath is integrated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DaqSpec {
    pub capture: CaptureSpec,
    /// The fine step is the output period divided by this many (≥ 1).
    pub oversample: usize,
}

impl DaqSpec {
    /// `capture` with the fine step at most `MAX_FINE_STEP_S`.
    pub fn new(capture: CaptureSpec) -> Self {
        let oversample = (1.0 / (capture.sample_rate_hz * MAX_FINE_STEP_S)).ceil().max(1.0) as usize;
        DaqSpec { capture, oversample }
    }

    /// The simulator's fixed RK4 step, s.
    pub fn fine_step_s(&self) -> f64 {
        1.0 / (self.capture.sample_rate_hz * self.oversample as f64)
    }

    /// The anti-alias filter on the fine grid.
    pub fn anti_alias(&self) -> LowPass {
        let r = self.oversample as f64;
        LowPass::design(ANTI_ALIAS_CUTOFF / r, ANTI_ALIAS_TRANSITION / r)
    }
}

/// Simulate the blows `v0s_mps` on `process` (the truth: its flow stress and height may
/// differ from what the estimator is told) and render each through the DAQ.
pub fn daq_blows(
    machine: &Machine,
    effects: &EffectSet,
    process: &Process,
    v0s_mps: &[f64],
    spec: &DaqSpec,
) -> Result<Vec<SynthBlow>, SequenceError> {
    let aa = spec.anti_alias();
    let dt_f = spec.fine_step_s();
    let c = spec.capture;
    // The trace must outlast the last output sample by the filter's half width.
    let opts = SimOptions {
        method: Method::Rk4 { dt_s: dt_f },
        post_s: c.post_s + (aa.half() + 2) as f64 * dt_f + 1.0 / c.sample_rate_hz,
        trace_dt_s: Some(dt_f),
    };
    let results = simulate_sequence(machine, effects, process, v0s_mps, &opts)?;
    let s = c.sensors;
    let mut rng = StdRng::seed_from_u64(c.seed);
    let load_noise = Normal::new(0.0, s.load_sd_n).expect("finite sd");
    let acc_noise = Normal::new(0.0, s.acc_sd_mps2).expect("finite sd");
    let offset = rand_distr::Uniform::new_inclusive(-s.load_offset_n, s.load_offset_n).expect("finite bounds");
    let r = spec.oversample as i64;
    let dt = 1.0 / c.sample_rate_hz;
    let mut phase_rng = StdRng::seed_from_u64(c.seed ^ PHASE_STREAM);
    let phase = rand_distr::Uniform::new(0, r.max(1)).expect("r ≥ 1");
    let mut out = Vec::with_capacity(results.len());
    for (i, mut truth) in results.into_iter().enumerate() {
        let encoder_zero_m = ENCODER_AT_LOWER_DIE_M - truth.h_start_m;
        let t_contact = c.t_origin_s + c.pre_s + i as f64 * c.blow_interval_s;
        // Sample k sits `p` fine steps after k sample periods from contact.
        let p = phase.sample(&mut phase_rng);
        let load_offset = offset.sample(&mut rng);
        let v0 = truth.v0_mps;
        let n_pre = (c.pre_s * c.sample_rate_hz).round() as i64;
        let n_post = ((truth.contact_time_s + c.post_s) * c.sample_rate_hz).floor() as i64;
        // The fine grid from j0 (before contact) on: load, ram position, ram acceleration.
        let j0 = -n_pre * r - aa.half() as i64;
        let j1 = n_post * r + p + aa.half() as i64;
        let mut load = Vec::with_capacity((j1 - j0 + 1) as usize);
        let mut x = Vec::with_capacity(load.capacity());
        let mut acc = Vec::with_capacity(load.capacity());
        for j in j0..=j1 {
            if j < 0 {
                let t = j as f64 * dt_f;
                let (xj, aj) = match c.approach {
                    Approach::FreeFall => (v0 * t + 0.5 * G_MPS2 * t * t, G_MPS2),
                    Approach::ConstantSpeed => (v0 * t, 0.0),
                };
                load.push(0.0);
                x.push(xj);
                acc.push(aj);
            } else if let Some(p) = truth.trace.get(j as usize).or(truth.trace.last()) {
                load.push(p.out.sensor_n);
                x.push(p.out.ram_m);
                acc.push(p.out.ram_acc_mps2);
            }
        }
        let mut rows = Vec::with_capacity((n_pre + n_post) as usize);
        for k in -n_pre..n_post {
            let centre = (k * r + p - j0) as usize;
            let q = s.encoder_step_m;
            let xk = encoder_zero_m + x[centre];
            let disp = if q > 0.0 { (xk / q).round() * q } else { xk };
            rows.push(CaptureRow {
                t_s: t_contact + k as f64 * dt + p as f64 * dt_f,
                load_n: aa.at(&load, centre) + load_offset + load_noise.sample(&mut rng),
                disp_m: disp,
                acc_mps2: aa.at(&acc, centre) + acc_noise.sample(&mut rng),
            });
        }
        // The fine trace is megabytes; the truth is the ledger and the indicators.
        truth.trace = Vec::new();
        out.push(SynthBlow { rows, truth, t_contact_s: t_contact });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{parse_machine, parse_process};

    /// The rendered blow keeps the simulated physics: the load's peak within the noise and
    /// the filter's smoothing of the 2 kHz ring, the encoder on its steps, and the time of
    /// contact where the truth puts it.
    #[test]
    fn a_hammer_blow_through_the_daq_at_5_khz() {
        let m = parse_machine("m", include_str!("../config/hammer-lg1000.machine.toml")).unwrap().machine;
        let p = parse_process("p", include_str!("../config/steel-16NiCrMo13.process.toml")).unwrap();
        let spec = DaqSpec::new(CaptureSpec { sample_rate_hz: 5e3, ..CaptureSpec::hammer(3) });
        assert_eq!(spec.oversample, 200);
        let b = daq_blows(&m, &EffectSet::NONE, &p, &[3.9], &spec).unwrap().remove(0);
        let n_pre = (spec.capture.pre_s * 5e3).round() as usize;
        // Contact falls between the sample before and the sample `n_pre`.
        let after = b.rows[n_pre].t_s - b.t_contact_s;
        assert!((-1e-9..2e-4).contains(&after), "{after}");
        // Before contact: the load is its offset and noise only.
        let before: f64 = b.rows[..n_pre - 5].iter().map(|r| r.load_n).sum::<f64>() / (n_pre - 5) as f64;
        assert!(before.abs() <= spec.capture.sensors.load_offset_n + 2e3, "{before}");
        // The forming load (≈ 325 kN at the end of forming, DESIGN.md §2.1) is seen at 5 kHz.
        let peak = b.rows.iter().map(|r| r.load_n - before).fold(f64::MIN, f64::max);
        assert!(peak > 250e3 && peak < 1.2 * b.truth.peak_load_n, "{peak} vs {}", b.truth.peak_load_n);
        for r in &b.rows {
            let steps = r.disp_m / 10e-6;
            assert!((steps - steps.round()).abs() < 1e-6);
        }
    }
}
