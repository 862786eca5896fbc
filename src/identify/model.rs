//! The parameters a fit moves, for each machine kind, and the bounded transform the
//! Levenberg–Marquardt search works in.
//!
//! Each parameter p lives in [lo, hi] (a decade or more either side of the prior) and is
//! searched as an unbounded u with ln p = ln lo + (ln hi − ln lo)·σ(u), σ the logistic
//! function: the search cannot leave the bounds, and steps are relative (a mass of 20 kg
//! and a spring of 3e9 N/m move alike). Uncertainties are reported on ln p, that is as
//! relative standard errors.

use crate::physics::machine::{Hammer, Machine, MachineKind, ScrewPress};

/// One fitted parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Param {
    /// Its `machine.toml` key.
    pub key: &'static str,
    pub lo: f64,
    pub hi: f64,
}

impl Param {
    /// u of value p (p clamped just inside the bounds).
    pub fn to_u(&self, p: f64) -> f64 {
        let (a, b) = (self.lo.ln(), self.hi.ln());
        let s = ((p.clamp(self.lo, self.hi).ln() - a) / (b - a)).clamp(1e-6, 1.0 - 1e-6);
        (s / (1.0 - s)).ln()
    }

    /// Value of u.
    pub fn from_u(&self, u: f64) -> f64 {
        let (a, b) = (self.lo.ln(), self.hi.ln());
        // exp(ln lo) may round below lo.
        (a + (b - a) * sigmoid(u)).exp().clamp(self.lo, self.hi)
    }

    /// d ln p / d u at u.
    pub fn dlnp_du(&self, u: f64) -> f64 {
        let s = sigmoid(u);
        (self.hi.ln() - self.lo.ln()) * s * (1.0 - s)
    }

    /// Whether p sits within 1 % (in ln p) of a bound: the data pushed it there.
    pub fn at_bound(&self, p: f64) -> bool {
        let span = self.hi.ln() - self.lo.ln();
        (p.ln() - self.lo.ln()) < 0.01 * span || (self.hi.ln() - p.ln()) < 0.01 * span
    }
}

fn sigmoid(u: f64) -> f64 {
    1.0 / (1.0 + (-u).exp())
}

/// Spread of the bounds around the prior, for masses and springs.
pub const STIFF_MASS_SPAN: f64 = 20.0;
/// Dampers are far less known beforehand: from 1/1000 to 100 times the prior.
pub const DAMPER_LO: f64 = 1e-3;
pub const DAMPER_HI: f64 = 100.0;
/// A prior damper of 0 (the paper's c1) is searched from this, N s/m.
pub const ZERO_DAMPER_PRIOR: f64 = 1e4;

/// What the fit moves and what it holds.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSet {
    pub kind: MachineKind,
    pub params: Vec<Param>,
    /// The prior machine: the values of the parameters not fitted (the press's sensor
    /// stiffness, from its data sheet) and the centre of the bounds.
    pub prior: Machine,
}

impl ParamSet {
    /// The parameters of `prior`'s kind. `bare`: a hammer's bare strike also needs the
    /// tool-on-tool contact stiffness. The press's `k_sensor_N_per_m` is held (the paper
    /// takes it from the sensor's data sheet, §2.3).
    pub fn new(prior: Machine, bare: bool) -> ParamSet {
        let around = |key, p: f64| Param { key, lo: p / STIFF_MASS_SPAN, hi: p * STIFF_MASS_SPAN };
        let damper = |key, c: f64| {
            let c = if c > 0.0 { c } else { ZERO_DAMPER_PRIOR };
            Param { key, lo: c * DAMPER_LO, hi: c * DAMPER_HI }
        };
        let params = match prior {
            Machine::Hammer(h) => {
                let mut v = vec![
                    around("m1_kg", h.m1_kg),
                    around("m2_kg", h.m2_kg),
                    around("k_N_per_m", h.k_n_per_m),
                    damper("c_Ns_per_m", h.c_ns_per_m),
                ];
                if bare {
                    v.push(around("k_tool_contact_N_per_m", h.k_tool_contact_n_per_m));
                }
                v
            }
            Machine::ScrewPress(p) => vec![
                around("m_tool_kg", p.m_tool_kg),
                around("m_ram_kg", p.m_ram_kg),
                around("k_link_N_per_m", p.k_link_n_per_m),
                damper("c_link_Ns_per_m", p.c_link_ns_per_m),
                around("k_frame_N_per_m", p.k_frame_n_per_m),
                damper("c_frame_Ns_per_m", p.c_frame_ns_per_m),
            ],
        };
        ParamSet { kind: prior.kind(), params, prior }
    }

    /// The same set with `key` held at the prior's value (not fitted).
    pub fn holding(mut self, key: &str) -> ParamSet {
        self.params.retain(|p| p.key != key);
        self
    }

    pub fn len(&self) -> usize {
        self.params.len()
    }

    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// Parameter values of a machine, in the set's order.
    pub fn values_of(&self, m: &Machine) -> Vec<f64> {
        self.params.iter().map(|p| get(m, p.key)).collect()
    }

    /// The machine with the set's parameters at `values`, the rest from the prior.
    pub fn machine(&self, values: &[f64]) -> Machine {
        let mut m = self.prior;
        for (p, v) in self.params.iter().zip(values) {
            set(&mut m, p.key, *v);
        }
        m
    }

    pub fn to_u(&self, values: &[f64]) -> Vec<f64> {
        self.params.iter().zip(values).map(|(p, v)| p.to_u(*v)).collect()
    }

    pub fn from_u(&self, u: &[f64]) -> Vec<f64> {
        self.params.iter().zip(u).map(|(p, u)| p.from_u(*u)).collect()
    }
}

/// A parameter of a machine by its `machine.toml` key (NaN for a key of the other kind).
pub fn get(m: &Machine, key: &str) -> f64 {
    match (m, key) {
        (Machine::Hammer(h), "m1_kg") => h.m1_kg,
        (Machine::Hammer(h), "m2_kg") => h.m2_kg,
        (Machine::Hammer(h), "k_N_per_m") => h.k_n_per_m,
        (Machine::Hammer(h), "c_Ns_per_m") => h.c_ns_per_m,
        (Machine::Hammer(h), "k_tool_contact_N_per_m") => h.k_tool_contact_n_per_m,
        (Machine::ScrewPress(p), "m_tool_kg") => p.m_tool_kg,
        (Machine::ScrewPress(p), "m_ram_kg") => p.m_ram_kg,
        (Machine::ScrewPress(p), "k_link_N_per_m") => p.k_link_n_per_m,
        (Machine::ScrewPress(p), "c_link_Ns_per_m") => p.c_link_ns_per_m,
        (Machine::ScrewPress(p), "k_frame_N_per_m") => p.k_frame_n_per_m,
        (Machine::ScrewPress(p), "c_frame_Ns_per_m") => p.c_frame_ns_per_m,
        (Machine::ScrewPress(p), "k_sensor_N_per_m") => p.k_sensor_n_per_m,
        (Machine::ScrewPress(p), "k_tool_contact_N_per_m") => p.k_tool_contact_n_per_m,
        _ => f64::NAN,
    }
}

pub fn set(m: &mut Machine, key: &str, v: f64) {
    match (m, key) {
        (Machine::Hammer(Hammer { m1_kg, .. }), "m1_kg") => *m1_kg = v,
        (Machine::Hammer(Hammer { m2_kg, .. }), "m2_kg") => *m2_kg = v,
        (Machine::Hammer(Hammer { k_n_per_m, .. }), "k_N_per_m") => *k_n_per_m = v,
        (Machine::Hammer(Hammer { c_ns_per_m, .. }), "c_Ns_per_m") => *c_ns_per_m = v,
        (Machine::Hammer(Hammer { k_tool_contact_n_per_m, .. }), "k_tool_contact_N_per_m") => {
            *k_tool_contact_n_per_m = v
        }
        (Machine::ScrewPress(ScrewPress { m_tool_kg, .. }), "m_tool_kg") => *m_tool_kg = v,
        (Machine::ScrewPress(ScrewPress { m_ram_kg, .. }), "m_ram_kg") => *m_ram_kg = v,
        (Machine::ScrewPress(ScrewPress { k_link_n_per_m, .. }), "k_link_N_per_m") => *k_link_n_per_m = v,
        (Machine::ScrewPress(ScrewPress { c_link_ns_per_m, .. }), "c_link_Ns_per_m") => *c_link_ns_per_m = v,
        (Machine::ScrewPress(ScrewPress { k_frame_n_per_m, .. }), "k_frame_N_per_m") => *k_frame_n_per_m = v,
        (Machine::ScrewPress(ScrewPress { c_frame_ns_per_m, .. }), "c_frame_Ns_per_m") => *c_frame_ns_per_m = v,
        _ => {}
    }
}

/// The built-in prior of a kind when the user gives none: the papers' identified machines
/// (hammer paper Table 1, press paper Table 3). Only the centre of generous bounds.
pub fn default_prior(kind: MachineKind) -> Machine {
    match kind {
        MachineKind::Hammer => Machine::Hammer(Hammer {
            m1_kg: 732.0,
            m2_kg: 19.0,
            k_n_per_m: 3.15e9,
            c_ns_per_m: 18540.0,
            k_tool_contact_n_per_m: crate::physics::machine::DEFAULT_HAMMER_TOOL_CONTACT_N_PER_M,
        }),
        MachineKind::ScrewPress => Machine::ScrewPress(ScrewPress {
            m_tool_kg: 3110.0,
            m_ram_kg: 106000.0,
            k_link_n_per_m: 1.72e9,
            c_link_ns_per_m: 3.61e5,
            k_frame_n_per_m: 9.74e9,
            c_frame_ns_per_m: 0.0,
            k_sensor_n_per_m: 3.39e10,
            k_tool_contact_n_per_m: f64::INFINITY,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_transform_round_trips_and_stays_in_bounds() {
        let p = Param { key: "m1_kg", lo: 36.6, hi: 14640.0 };
        for v in [40.0, 732.0, 14000.0] {
            assert!((p.from_u(p.to_u(v)) / v - 1.0).abs() < 1e-9);
        }
        assert!(p.from_u(-1e3) >= p.lo && p.from_u(1e3) <= p.hi);
        // The derivative against a finite difference.
        let u = 0.3;
        let fd = (p.from_u(u + 1e-6).ln() - p.from_u(u - 1e-6).ln()) / 2e-6;
        assert!((fd / p.dlnp_du(u) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn a_set_writes_back_only_its_parameters() {
        let prior = default_prior(MachineKind::ScrewPress);
        let set = ParamSet::new(prior, true);
        assert_eq!(set.len(), 6, "the sensor stiffness is held");
        let mut v = set.values_of(&prior);
        v[0] = 2000.0;
        let m = set.machine(&v);
        assert_eq!(get(&m, "m_tool_kg"), 2000.0);
        assert_eq!(get(&m, "k_sensor_N_per_m"), 3.39e10);
    }
}
