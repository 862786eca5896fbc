//! Sensor health per blow (issue 16, docs/interfaces.md §5 `sensor_check`): the load sensor and
//! the ram's accelerometer measure the same blow, so the momentum the machine lost, as the
//! accelerometer and the model's masses see it, must equal the impulse the load sensor
//! carried. Their relative disagreement is reported per blow; a wrong gain, a drifting
//! charge amplifier or a loose accelerometer shows as a disagreement that persists.
//!
//! Impulses, not peaks: a DAQ's anti-alias filter and a low sample rate smear a peak but
//! keep the area under the force, and the noise of each channel averages out in the
//! integral (2 kN per sample at 100 kHz over a 10 ms blow is 0.6 N s of the blow's
//! 3000–4000 N s). Both integrals run over the same samples, from the last sample before
//! contact to the blow's end (trapezoids), so a contact found a sample late costs nothing.
//!
//! **Hammer** (DESIGN.md §2.1, no gravity in the model): `m1 x1'' = -F` and
//! `m2 x2'' = F - F_s`. Added up and integrated over the blow,
//! `∫F_s dt = -m1 Δv1 - m2 Δv2`. The lower tool enters at the impact speed (the model's
//! catch-up assumption) and is at rest on its spring once the load has stayed quiet (the
//! blow's end: a 10 kN ring left on the LG1000's 2 kHz mode is 0.04 m/s, 0.8 N s), so
//! `Δv2 = -v0` and the accelerometer's side is `-m1 ∫a dt + m2 v0`.
//!
//! **Screw press** (DESIGN.md §2.2): the load sensor carries the billet's force on the tool
//! directly (the support has no mass), the link force `-m_ram a_ram` acts on the tool from
//! behind: `m_tool x_tool'' = F_link - F_s`, so `∫F_s dt = -m_ram Δv_ram - m_tool Δv_tool`.
//! The tool lags the ram by the link's stretch `s`, from `c s' + k s = F_link` (the
//! observer's filter): `v_tool = v_ram - s'`. Both start at the impact speed with the link
//! relaxed, so the accelerometer's side is `-(m_ram + m_tool) ∫a dt + m_tool s'_end`. The
//! tool still rings on the link after the load has gone (118 Hz, decaying over 17 ms on
//! the SPR 400), which is why `s'_end` is kept: without it the check would carry up to 5 %
//! of the blow's impulse.
//!
//! `sensor_check = load impulse / accelerometer momentum − 1`: positive when the load
//! sensor reads high (a gain 10 % high gives +0.10). Pure code.

use crate::physics::machine::{Machine, ScrewPress};
use crate::signal::segment::Blow;

use super::observer::first_order_step;

/// Why a blow has no sensor check (`sensor_check` is `null`).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum NoCheck {
    #[error("the blow holds no interval between contact and its end")]
    Empty,
    /// Every accelerometer sample of the blow is the same: the channel is dead, stuck or
    /// missing (filled with a constant), so the ram's side of the check does not exist.
    #[error("the accelerometer is flat over the blow ({acc_mps2} m/s² throughout)")]
    FlatAccelerometer { acc_mps2: f64 },
    /// The model's machine lost no momentum by the accelerometer while the load sensor
    /// carried a blow: no relative error can be formed (a reversed or dead accelerometer).
    #[error("the accelerometer shows no momentum lost ({momentum_ns:.1} N s)")]
    NoMomentumLost { momentum_ns: f64 },
}

/// The two sides of the check, N s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impulses {
    /// `∫F_s dt` of the zeroed load over the blow.
    pub load_ns: f64,
    /// The momentum the machine lost, from the accelerometer and the model's masses.
    pub momentum_ns: f64,
}

impl Impulses {
    /// The relative disagreement, `load / momentum - 1`.
    pub fn relative(&self) -> Result<f64, NoCheck> {
        if self.momentum_ns > 0.0 && self.momentum_ns.is_finite() && self.load_ns.is_finite() {
            Ok(self.load_ns / self.momentum_ns - 1.0)
        } else {
            Err(NoCheck::NoMomentumLost { momentum_ns: self.momentum_ns })
        }
    }
}

/// The blow's `sensor_check`: the load sensor's impulse against the momentum the
/// accelerometer and the model say the machine lost, with impact speed `v0_mps`.
pub fn sensor_check(machine: &Machine, blow: &Blow, v0_mps: f64) -> Result<f64, NoCheck> {
    impulses(machine, blow, v0_mps)?.relative()
}

/// Both sides of the check over the blow (module doc).
pub fn impulses(machine: &Machine, blow: &Blow, v0_mps: f64) -> Result<Impulses, NoCheck> {
    let from = blow.i_contact.saturating_sub(1);
    let to = blow.i_end.min(blow.samples.len().saturating_sub(1));
    if to <= from {
        return Err(NoCheck::Empty);
    }
    let s = &blow.samples[from..=to];
    let acc0 = s[0].acc_mps2;
    if s.iter().all(|x| x.acc_mps2 == acc0) {
        return Err(NoCheck::FlatAccelerometer { acc_mps2: acc0 });
    }
    let dt = blow.period_s;
    let load_ns = trapezoid(s.iter().map(|x| x.load_n - blow.load_zero_n), dt);
    let dv_ram_mps = trapezoid(s.iter().map(|x| x.acc_mps2), dt);
    let momentum_ns = match machine {
        Machine::Hammer(h) => -h.m1_kg * dv_ram_mps + h.m2_kg * v0_mps,
        Machine::ScrewPress(p) => {
            let link_rate_end = link_stretch_rate_end(p, s.iter().map(|x| -p.m_ram_kg * x.acc_mps2), dt);
            -(p.m_ram_kg + p.m_tool_kg) * dv_ram_mps + p.m_tool_kg * link_rate_end
        }
    };
    Ok(Impulses { load_ns, momentum_ns })
}

/// `∫ y dt` by trapezoids over samples `dt` apart.
fn trapezoid(y: impl Iterator<Item = f64>, dt: f64) -> f64 {
    let mut sum = 0.0;
    let mut prev: Option<f64> = None;
    for v in y {
        if let Some(p) = prev {
            sum += 0.5 * (p + v) * dt;
        }
        prev = Some(v);
    }
    sum
}

/// The press link's stretch rate at the last sample, m/s, from `c s' + k s = F_link` run
/// from a relaxed link: the exact step for a force linear between samples (as the
/// observer's), then `s' = (F_link - k s) / c`; without a damper, the stretch's slope.
fn link_stretch_rate_end(p: &ScrewPress, link_n: impl Iterator<Item = f64>, dt: f64) -> f64 {
    let (k, c) = (p.k_link_n_per_m, p.c_link_ns_per_m);
    let tau = c / k;
    let (mut st, mut st_prev, mut f_prev) = (0.0, 0.0, None::<f64>);
    let mut f_last = 0.0;
    for f in link_n {
        if let Some(f0) = f_prev {
            st_prev = st;
            st = first_order_step(st, f0 / k, f / k, dt, tau);
        }
        f_prev = Some(f);
        f_last = f;
    }
    if c > 0.0 { (f_last - k * st) / c } else { (st - st_prev) / dt }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::machine::Hammer;
    use crate::signal::segment::Sample;

    const DT: f64 = 1e-5;

    /// The paper hammer (seed 000 Table 1).
    fn hammer() -> Machine {
        Machine::Hammer(Hammer {
            m1_kg: 732.0,
            m2_kg: 19.0,
            k_n_per_m: 3.15e9,
            c_ns_per_m: 18540.0,
            k_tool_contact_n_per_m: 6e10,
        })
    }

    /// A blow in the model's own terms: a half-sine billet force of `peak_n` over 10 ms
    /// decelerates the ram (`a = -F / m1`), and the load sensor carries it with the lower
    /// tool's momentum `m2 v0` added as a short 0.5 ms pulse at impact (how the lower tool is
    /// brought to rest on its spring).
    fn blow(peak_n: f64, v0: f64, gain: f64) -> Blow {
        let (m1, m2) = (732.0, 19.0);
        let (t_blow, t_pulse) = (0.01, 0.0005);
        let pulse_peak = m2 * v0 * std::f64::consts::PI / (2.0 * t_pulse);
        let n = 1500;
        let samples = (0..n)
            .map(|i| {
                let t = (i as f64 - 100.0) * DT;
                let half_sine = |len: f64, peak: f64| {
                    if (0.0..=len).contains(&t) { peak * (std::f64::consts::PI * t / len).sin() } else { 0.0 }
                };
                let f = half_sine(t_blow, peak_n);
                Sample {
                    t_s: t,
                    load_n: 1000.0 + gain * (f + half_sine(t_pulse, pulse_peak)),
                    disp_m: 0.0,
                    acc_mps2: -f / m1,
                    filled: false,
                }
            })
            .collect();
        Blow {
            samples,
            i_trigger: 95,
            i_contact: 101,
            i_end: n - 1,
            load_zero_n: 1000.0,
            period_s: DT,
            lost_s: 0.0,
            open_end_n: None,
            ram_cut: None,
        }
    }

    #[test]
    fn the_model_s_own_blow_checks_to_zero_and_a_gain_shows_as_itself() {
        // Trapezoids of half-sines at 100 samples per 1 ms: their error is below 1e-4.
        let x = sensor_check(&hammer(), &blow(400e3, 3.9, 1.0), 3.9).unwrap();
        assert!(x.abs() < 1e-4, "{x}");
        let x = sensor_check(&hammer(), &blow(400e3, 3.9, 1.1), 3.9).unwrap();
        assert!((x - 0.1).abs() < 2e-4, "{x}");
        let i = impulses(&hammer(), &blow(400e3, 3.9, 0.9), 3.9).unwrap();
        // ∫ half-sine = peak · 2 T / π, plus m2 v0.
        let want = 400e3 * 2.0 * 0.01 / std::f64::consts::PI + 19.0 * 3.9;
        assert!((i.momentum_ns - want).abs() < 1e-3 * want, "{i:?} vs {want}");
        assert!((i.load_ns - 0.9 * want).abs() < 1e-3 * want, "{i:?}");
    }

    #[test]
    fn a_flat_accelerometer_has_no_check() {
        let mut b = blow(400e3, 3.9, 1.0);
        for s in &mut b.samples {
            s.acc_mps2 = 9.81;
        }
        assert_eq!(sensor_check(&hammer(), &b, 3.9), Err(NoCheck::FlatAccelerometer { acc_mps2: 9.81 }));
    }

    #[test]
    fn an_accelerometer_mounted_upside_down_has_no_check() {
        // A reversed accelerometer makes the ram gain momentum in the blow.
        let mut b = blow(400e3, 3.9, 1.0);
        for s in &mut b.samples {
            s.acc_mps2 = -s.acc_mps2;
        }
        assert!(matches!(sensor_check(&hammer(), &b, 3.9), Err(NoCheck::NoMomentumLost { .. })));
    }

    #[test]
    fn a_blow_without_samples_after_contact_has_no_check() {
        let mut b = blow(400e3, 3.9, 1.0);
        b.i_contact = 0;
        b.i_end = 0;
        assert_eq!(sensor_check(&hammer(), &b, 3.9), Err(NoCheck::Empty));
    }
}
