//! The plant of one blow: a hammer or screw press on a billet (or a bare strike), as a
//! hybrid system for `integrator`.
//!
//! The machine is a chain of masses and springs (DESIGN.md §2.1–2.2) closed through the
//! billet. The billet is rigid-plastic (the papers' gamma): it pushes with the upsetting
//! load only while it is being compressed to a new minimum height. Between two masses
//! (hammer) the contact has three phases: `Plastic` (flowing, F = F_L), `Stuck` (the masses
//! move together, 0 < F < F_L) and `Free`. When the billet sits on a compliance (the
//! press's massless sensor/frame chain, or the `elastic_recovery` effect) the phases are
//! `Free`, `Elastic` and `Plastic`, and the plastic rate follows from the consistency
//! condition. `integrator` locates every switch.

mod base_hammer;
mod hybrid;

pub use base_hammer::{BaseHammer, GridPoint, NB};

use super::billet::{BilletLaw, STRAIN_RATE_FLOOR_PER_S};
use super::effects::{EffectSet, Foundation};
use super::integrator::{Crossing, Guards, Hybrid};
use super::machine::{DEFAULT_HAMMER_TOOL_CONTACT_N_PER_M, Machine, series};

/// Longest step as a fraction of the fastest local mode's period. A guard that oscillates
/// with that mode cannot cross zero twice within a quarter period; step control usually
/// keeps the steps shorter anyway.
const MAX_STEP_PERIODS: f64 = 0.25;

/// Relative margin of the yield load over the flow load for a billet at rest (1 ppm: far
/// below any physical scatter of a flow stress).
const YIELD_MARGIN: f64 = 1e-6;

/// Shortest time constant of the press's frame node that is integrated as a state, s.
/// Below it (c_frame under ~1.3e5 N s/m on the SPR 400) the node is folded into the series
/// springs: its damper then takes under 0.2 % of a copper blow's energy, and resolving it
/// would take steps of its time constant.
const NODE_MIN_TAU_S: f64 = 3e-6;

/// Length of the state vector.
pub const N: usize = 14;

// State layout. Positions and velocities point down (docs/interfaces.md, Conventions) and start
// at 0 at first contact.
const XU: usize = 0; // upper body: hammer ram m1 / press tool
pub(super) const VU: usize = 1;
const XR: usize = 2; // press ram behind the link
pub(super) const VR: usize = 3;
const XL: usize = 4; // hammer lower tool m2
pub(super) const VL: usize = 5;
const X3: usize = 6; // foundation mass (effect)
pub(super) const V3: usize = 7;
const XN: usize = 8; // press frame node (massless, first order when c_frame > 0)
const P: usize = 9; // plastic compression of the billet: h = h_start - p
pub(super) const Z: usize = 10; // low-pass state of the sensor high-pass (effect)
pub(super) const WP: usize = 11; // plastic work, J
pub(super) const WF: usize = 12; // friction work, J
pub(super) const WD: usize = 13; // damped work, J

/// Contact phase of the billet (or of the tools in a bare strike).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Contact {
    Free,
    Stuck,
    Elastic,
    Plastic,
}

/// The discrete state: contact phase, and whether the clearance in the hammer's support
/// path is closed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mode {
    pub contact: Contact,
    pub engaged: bool,
}

/// What sits under the billet.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Lower {
    /// Hammer: lower tool mass on the frame spring and damper (they carry the sensor load).
    /// Press with `clearance` and its die: the die on the sensor path in series.
    Mass { m_kg: f64, k_n_per_m: f64, c_ns_per_m: f64 },
    /// Press: massless sensor in series with the frame. With `c_frame > 0` the node between
    /// them is a first-order state; otherwise the frame is folded into the contact series.
    Chain { k_frame_n_per_m: f64, c_frame_ns_per_m: f64 },
}

/// The machine, billet and effects of one blow, ready to integrate.
#[derive(Debug, Clone)]
pub struct Plant {
    m_upper_kg: f64,
    /// `1 / m_upper` and, under a lower mass, `1 / m`, kg⁻¹ (0 for the press's chain).
    inv_m: (f64, f64),
    /// Press ram: (mass, link stiffness, link damping).
    ram: Option<(f64, f64, f64)>,
    lower: Lower,
    /// Contact stiffness in series with the billet; infinite for the hammer's rigid contact.
    pub(super) k_contact_n_per_m: f64,
    node: bool,
    foundation: Option<Foundation>,
    /// Clearance in the support path of the lower mass (hammer, or press with its die).
    gap_support_m: f64,
    /// The lower mass starts at rest: it has not been caught up (`clearance`).
    lower_at_rest: bool,
    /// Clearance (dead travel) in the press's massless sensor path.
    gap_contact_m: f64,
    highpass_tau_s: f64,
    pub(super) billet: Option<BilletLaw>,
    pub(super) h_start_m: f64,
    rate_dependent: bool,
    max_step_s: f64,
    pub(super) f_max_hz: f64,
}

/// A rigid contact's force, its frictionless part, and the billet's plastic rate
/// (`Plant::rigid_flow`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Flow {
    pub contact_n: f64,
    pub frictionless_n: f64,
    pub p_rate_mps: f64,
}

impl Flow {
    /// The rates of the plastic and the friction work: the frictionless part's load and
    /// the rest, each times the compression rate.
    pub(super) fn work_rates(&self) -> (f64, f64) {
        (self.frictionless_n * self.p_rate_mps, (self.contact_n - self.frictionless_n) * self.p_rate_mps)
    }
}

/// The accelerations of the bodies either side of the billet (`inv_m`: their reciprocal
/// masses), from the forces on them: `upper_n` on the upper body besides the contact (the
/// press's link; 0 on a hammer), the contact's `contact_n` between them and the support's
/// `support_n` under the lower. Stuck bodies share one acceleration, bit for bit, so their
/// relative velocity stays exactly zero and the guards that leave the phase see a clean
/// start.
pub(super) fn two_bodies(inv_m: (f64, f64), upper_n: f64, contact_n: f64, support_n: f64, stuck: bool) -> (f64, f64) {
    let acc_upper = (upper_n - contact_n) * inv_m.0;
    let acc_lower = if stuck { acc_upper } else { (contact_n - support_n) * inv_m.1 };
    (acc_upper, acc_lower)
}

/// The force that keeps two stuck bodies together: the one that gives them one
/// acceleration under `upper_n` on the upper and `support_n` under the lower.
pub(super) fn stick_n(inv_m: (f64, f64), upper_n: f64, support_n: f64) -> f64 {
    (upper_n * inv_m.0 + support_n * inv_m.1) / (inv_m.0 + inv_m.1)
}

/// The frictionless part's share of an upsetting load (1 where the load is not finite and
/// positive: a bare strike, or a billet of no height).
fn frictionless_share(total_n: f64, frictionless_n: f64) -> f64 {
    if total_n.is_finite() && total_n > 0.0 { frictionless_n / total_n } else { 1.0 }
}

/// Forces and rates at one state, shared by the vector field, the guards and the outputs.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Eval {
    delta_m: f64,
    ddelta_mps: f64,
    h_m: f64,
    contact_n: f64,
    /// The part of `contact_n` that upsets a frictionless billet; the rest works against
    /// friction.
    frictionless_n: f64,
    p_rate_mps: f64,
    link_n: f64,
    support_n: f64,
    stick_n: f64,
    vn_mps: f64,
    sensor_raw_n: f64,
    acc_upper: f64,
    acc_lower: f64,
}

impl Plant {
    /// Build the blow of `machine` with `effects` on a billet of height `h_start_m`
    /// described by `billet` (`None`: a bare strike, tool on tool).
    pub fn new(machine: &Machine, effects: &EffectSet, billet: Option<BilletLaw>, h_start_m: f64) -> Plant {
        let kc_effect = effects.k_contact_n_per_m;
        let die = matches!(machine, Machine::ScrewPress(_)) && effects.clearance_lower_kg > 0.0;
        let (m_upper_kg, ram, lower, k_contact, node, gap_support_m, gap_contact_m) = match *machine {
            Machine::Hammer(h) => {
                let k_contact = if billet.is_some() { kc_effect } else { series(h.k_tool_contact_n_per_m, kc_effect) };
                let lower = Lower::Mass { m_kg: h.m2_kg, k_n_per_m: h.k_n_per_m, c_ns_per_m: h.c_ns_per_m };
                (h.m1_kg, None, lower, k_contact, false, effects.clearance_gap_m, 0.0)
            }
            // `clearance` with the press's lower die: a mass at rest across the gap from the
            // sensor path (sensor, any extra tool contact and frame in series). The frame damper
            // acts through the sensor spring; to first order in w c_frame / (k_sensor + k_frame)
            // (0.3 % at a 450 Hz die ring for c_frame = 5e4 N s/m) that is a damper
            // c_frame (k_sensor / (k_sensor + k_frame))^2 across the series spring.
            Machine::ScrewPress(p) if die => {
                let k_s = series(p.k_sensor_n_per_m, p.k_tool_contact_n_per_m);
                let share = k_s / (k_s + p.k_frame_n_per_m);
                let lower = Lower::Mass {
                    m_kg: effects.clearance_lower_kg,
                    k_n_per_m: series(k_s, p.k_frame_n_per_m),
                    c_ns_per_m: p.c_frame_ns_per_m * share * share,
                };
                let kc = series(kc_effect, effects.clearance_die_k_n_per_m);
                let k_contact = if billet.is_some() { kc } else { series(DEFAULT_HAMMER_TOOL_CONTACT_N_PER_M, kc) };
                let ram = Some((p.m_ram_kg, p.k_link_n_per_m, p.c_link_ns_per_m));
                (p.m_tool_kg, ram, lower, k_contact, false, effects.clearance_gap_m, 0.0)
            }
            Machine::ScrewPress(p) => {
                // A frame damper so weak that the node relaxes faster than NODE_MIN_TAU_S is
                // folded into the series (its damping is negligible; resolving it would take
                // steps of its time constant).
                let tau_node = p.c_frame_ns_per_m / (p.k_frame_n_per_m + p.k_sensor_n_per_m);
                let node = p.c_frame_ns_per_m > 0.0 && tau_node >= NODE_MIN_TAU_S;
                let mut k = series(series(p.k_sensor_n_per_m, p.k_tool_contact_n_per_m), kc_effect);
                if !node {
                    k = series(k, p.k_frame_n_per_m);
                }
                let lower = Lower::Chain { k_frame_n_per_m: p.k_frame_n_per_m, c_frame_ns_per_m: p.c_frame_ns_per_m };
                let ram = Some((p.m_ram_kg, p.k_link_n_per_m, p.c_link_ns_per_m));
                (p.m_tool_kg, ram, lower, k, node, 0.0, effects.clearance_gap_m)
            }
        };
        let rate_dependent = billet.as_ref().is_some_and(|b| b.is_rate_dependent());
        // Fastest local mode: each body against everything that holds it.
        let mut f2: f64 = 0.0;
        let kc_fin = if k_contact.is_finite() { k_contact } else { 0.0 };
        if let Some((m_r, k_l, _)) = ram {
            f2 = f2.max(k_l / m_r);
            f2 = f2.max((k_l + kc_fin) / m_upper_kg);
        } else {
            f2 = f2.max(kc_fin / m_upper_kg);
        }
        if let Lower::Mass { m_kg, k_n_per_m, .. } = lower {
            f2 = f2.max((k_n_per_m + kc_fin) / m_kg);
        }
        if let Some(f) = effects.foundation {
            let k_above = match lower {
                Lower::Mass { k_n_per_m, .. } => k_n_per_m,
                Lower::Chain { k_frame_n_per_m, .. } => k_frame_n_per_m,
            };
            f2 = f2.max((f.k3_n_per_m + k_above) / f.m3_kg);
        }
        let f_max_hz = f2.sqrt() / (2.0 * std::f64::consts::PI);
        let inv_m_lower = match lower {
            Lower::Mass { m_kg, .. } => 1.0 / m_kg,
            Lower::Chain { .. } => 0.0,
        };
        Plant {
            m_upper_kg,
            inv_m: (1.0 / m_upper_kg, inv_m_lower),
            ram,
            lower,
            k_contact_n_per_m: k_contact,
            node,
            foundation: effects.foundation,
            gap_support_m,
            lower_at_rest: gap_support_m > 0.0 || die,
            gap_contact_m,
            highpass_tau_s: effects.highpass_tau_s,
            billet,
            h_start_m,
            rate_dependent,
            max_step_s: MAX_STEP_PERIODS / f_max_hz,
            f_max_hz,
        }
    }

    fn rigid(&self) -> bool {
        self.k_contact_n_per_m.is_infinite()
    }

    /// The load at which a resting billet starts to flow: the upsetting load raised by
    /// `YIELD_MARGIN`. Leaving plastic flow puts the yield guard at zero to within roundoff;
    /// the margin puts it strictly on its armed side, so the next yield cannot be missed.
    fn yield_load(&self, h: f64, ddelta: f64) -> f64 {
        self.upset(h, ddelta).0 * (1.0 + YIELD_MARGIN)
    }

    /// Upsetting load (total, frictionless) at height `h` and approach rate `ddelta`.
    fn upset(&self, h: f64, ddelta: f64) -> (f64, f64) {
        match &self.billet {
            Some(b) => {
                let l = b.load_closing(h, ddelta);
                (l.total_n, l.frictionless_n)
            }
            None => (f64::INFINITY, f64::INFINITY),
        }
    }

    /// The billet at a rigid contact in phase `contact`, at height `h_m` with the tools
    /// closing at `ddelta_mps`: stuck tools press on it with `stick_n`; flowing, it pushes
    /// back with the upsetting load and is compressed at the approach rate. The general
    /// plant and the base hammer's (`BaseHammer`) both evaluate it.
    pub(super) fn rigid_flow(law: &BilletLaw, contact: Contact, h_m: f64, ddelta_mps: f64, stick_n: f64) -> Flow {
        match contact {
            Contact::Free | Contact::Elastic => Flow { contact_n: 0.0, frictionless_n: 0.0, p_rate_mps: 0.0 },
            Contact::Stuck => Flow { contact_n: stick_n, frictionless_n: stick_n, p_rate_mps: 0.0 },
            Contact::Plastic => {
                let l = law.load_closing(h_m, ddelta_mps);
                Flow { contact_n: l.total_n, frictionless_n: l.frictionless_n, p_rate_mps: ddelta_mps }
            }
        }
    }

    /// The geometry and the forces that follow from positions and velocities alone: all of
    /// `eval` but the upsetting load and what depends on it (a rigid contact's force while
    /// flowing, the accelerations, the plastic rate, the frictionless share). The guards
    /// and the hammer's or a compliant contact's sensor need no more, and the billet law is
    /// the costly part of `eval` (its `expm1`, and `pow`s with Hansel–Spittel). The values it
    /// sets are those `eval` computes, bit for bit: `eval` starts from them.
    pub(super) fn kinematics(&self, y: &[f64; N], mode: Mode) -> Eval {
        let mut e = Eval::default();
        let (x3, v3) = if self.foundation.is_some() { (y[X3], y[V3]) } else { (0.0, 0.0) };
        e.link_n = match self.ram {
            Some((_, k, c)) => k * (y[XR] - y[XU]) + c * (y[VR] - y[VU]),
            None => 0.0,
        };
        e.h_m = self.h_start_m - y[P];
        match self.lower {
            Lower::Mass { k_n_per_m, c_ns_per_m, .. } => {
                e.delta_m = y[XU] - y[XL];
                e.ddelta_mps = y[VU] - y[VL];
                e.support_n = if mode.engaged {
                    k_n_per_m * (y[XL] - x3 - self.gap_support_m) + c_ns_per_m * (y[VL] - v3)
                } else {
                    0.0
                };
                e.stick_n = stick_n(self.inv_m, e.link_n, e.support_n);
            }
            Lower::Chain { .. } => e.delta_m = y[XU] - if self.node { y[XN] } else { x3 },
        }
        // A compliant contact's force follows from positions alone.
        if !self.rigid() && mode.contact != Contact::Free {
            e.contact_n = self.k_contact_n_per_m * (e.delta_m - y[P] - self.gap_contact_m).max(0.0);
        }
        // The press's frame node moves by its force balance; the billet is squeezed at the
        // tool's velocity relative to it.
        if let Lower::Chain { k_frame_n_per_m, c_frame_ns_per_m } = self.lower {
            let v_lower = if self.node {
                e.vn_mps = v3 + (e.contact_n - k_frame_n_per_m * (y[XN] - x3)) / c_frame_ns_per_m;
                e.vn_mps
            } else {
                v3
            };
            e.ddelta_mps = y[VU] - v_lower;
        }
        e.sensor_raw_n = match self.lower {
            Lower::Mass { .. } => e.support_n,
            Lower::Chain { .. } => e.contact_n,
        };
        e
    }

    /// Whether the sensor's load follows from `kinematics` alone: it does unless it is the
    /// force of a rigid contact (a press without compliance, which `new` never builds).
    pub(super) fn sensor_is_kinematic(&self) -> bool {
        matches!(self.lower, Lower::Mass { .. }) || !self.rigid()
    }

    /// Sensor output at a state, without the billet law where it is not needed.
    pub(super) fn sensor_at(&self, y: &[f64; N], mode: Mode) -> f64 {
        let e = if self.sensor_is_kinematic() { self.kinematics(y, mode) } else { self.eval(y, mode) };
        self.sensor(y, &e)
    }

    /// Forces and rates at a state: `kinematics`, then the billet law and the dynamics.
    pub(super) fn eval(&self, y: &[f64; N], mode: Mode) -> Eval {
        let mut e = self.kinematics(y, mode);
        if self.rigid()
            && let Some(law) = &self.billet
        {
            let f = Plant::rigid_flow(law, mode.contact, e.h_m, e.ddelta_mps, e.stick_n);
            (e.contact_n, e.frictionless_n, e.p_rate_mps) = (f.contact_n, f.frictionless_n, f.p_rate_mps);
        } else {
            e.frictionless_n = e.contact_n;
        }
        // Accelerations of the bodies either side of the billet.
        let stuck = mode.contact == Contact::Stuck;
        (e.acc_upper, e.acc_lower) = two_bodies(self.inv_m, e.link_n, e.contact_n, e.support_n, stuck);
        if let (Lower::Chain { .. }, false) = (self.lower, stuck) {
            e.acc_lower = self.foundation_acc(y, e.contact_n);
        }
        if !self.rigid() && mode.contact == Contact::Plastic {
            // The upsetting load is needed only while the billet flows.
            let (total, frictionless) = self.upset(e.h_m, e.ddelta_mps);
            e.p_rate_mps = self.consistency(&e, total);
            e.frictionless_n = e.contact_n * frictionless_share(total, frictionless);
        }
        e.sensor_raw_n = match self.lower {
            Lower::Mass { .. } => e.support_n,
            Lower::Chain { .. } => e.contact_n,
        };
        e
    }

    fn foundation_acc(&self, y: &[f64; N], down_n: f64) -> f64 {
        match self.foundation {
            Some(f) => (down_n - f.k3_n_per_m * y[X3] - f.c3_ns_per_m * y[V3]) / f.m3_kg,
            None => 0.0,
        }
    }

    /// Plastic rate of a billet on a compliance `k`: the elastic force `k (delta - p)` must
    /// follow the flow load `F_L(h, epsdot)` with `epsdot = delta'/h`, so
    /// `k (delta' - p') = -dF/dh p' + dF/depsdot (delta''/h + delta' p'/h^2)`.
    /// The strain rate uses the approach rate (the elastic part of it is neglected: the
    /// compliance deflects by tens of µm against mm of flow), which keeps this explicit.
    fn consistency(&self, e: &Eval, total: f64) -> f64 {
        let k = self.k_contact_n_per_m;
        let h = e.h_m;
        let dh = 1e-7 * h;
        let (up, _) = self.upset(h + dh, e.ddelta_mps);
        let (dn, _) = self.upset(h - dh, e.ddelta_mps);
        let f_h = (up - dn) / (2.0 * dh);
        let rate = e.ddelta_mps.max(0.0) / h;
        let f_r = if self.rate_dependent && rate > STRAIN_RATE_FLOOR_PER_S {
            let dr = 1e-6 * rate;
            let (fr, _) = self.upset(h, (rate + dr) * h);
            (fr - total) / dr
        } else {
            0.0
        };
        let dd = e.acc_upper - e.acc_lower;
        let num = k * e.ddelta_mps - f_r * dd / h;
        let den = k - f_h + f_r * e.ddelta_mps.max(0.0) / (h * h);
        // Integration error lets the elastic force drift off the flow load; this term makes
        // the drift decay with the time constant of the step cap (Baumgarte stabilisation).
        let drift = (e.contact_n - total) / self.max_step_s;
        (num + drift) / den
    }

    /// Sensor output: the raw load, or the high-passed one with `sensor_highpass`.
    pub(super) fn sensor(&self, y: &[f64; N], e: &Eval) -> f64 {
        if self.highpass_tau_s.is_finite() { e.sensor_raw_n - y[Z] } else { e.sensor_raw_n }
    }

    /// Mechanical energy in the machine (kinetic plus spring), J.
    pub fn mechanical_energy(&self, y: &[f64; N], mode: Mode) -> f64 {
        let (x3, v3) = if self.foundation.is_some() { (y[X3], y[V3]) } else { (0.0, 0.0) };
        let mut e = 0.5 * self.m_upper_kg * y[VU] * y[VU];
        if let Some((m, k, _)) = self.ram {
            e += 0.5 * m * y[VR] * y[VR] + 0.5 * k * (y[XR] - y[XU]).powi(2);
        }
        match self.lower {
            Lower::Mass { m_kg, k_n_per_m, .. } => {
                e += 0.5 * m_kg * y[VL] * y[VL];
                if mode.engaged {
                    e += 0.5 * k_n_per_m * (y[XL] - x3 - self.gap_support_m).powi(2);
                }
            }
            Lower::Chain { k_frame_n_per_m, .. } => {
                if self.node {
                    e += 0.5 * k_frame_n_per_m * (y[XN] - x3).powi(2);
                }
            }
        }
        if !self.rigid() && mode.contact != Contact::Free {
            let xl = match self.lower {
                Lower::Mass { .. } => y[XL],
                Lower::Chain { .. } if self.node => y[XN],
                Lower::Chain { .. } => x3,
            };
            let c = (y[XU] - xl - y[P] - self.gap_contact_m).max(0.0);
            e += 0.5 * self.k_contact_n_per_m * c * c;
        }
        if let Some(f) = self.foundation {
            e += 0.5 * f.m3_kg * v3 * v3 + 0.5 * f.k3_n_per_m * x3 * x3;
        }
        e
    }

    /// State at first contact: every moving body at the impact speed, springs unloaded.
    /// With `clearance` the lower mass (the hammer's, or the press's die) starts at rest (it
    /// has not been caught up).
    pub fn initial_state(&self, v0_mps: f64) -> ([f64; N], Mode) {
        let mut y = [0.0; N];
        y[VU] = v0_mps;
        if self.ram.is_some() {
            y[VR] = v0_mps;
        }
        if matches!(self.lower, Lower::Mass { .. }) && !self.lower_at_rest {
            y[VL] = v0_mps;
        }
        let engaged = self.gap_support_m == 0.0;
        let mut mode = Mode { contact: Contact::Elastic, engaged };
        // Dead travel in the press's sensor path: the tool first crosses the gap, and the
        // touch guard locates the closure, where the step restarts (the force switching on
        // inside a step is a kink that step control would only see through its error).
        if !self.rigid() && self.gap_contact_m > 0.0 {
            mode.contact = Contact::Free;
        }
        if self.rigid() {
            mode.contact = Contact::Free;
            mode = self.on_event(&mut y, mode, hybrid::G_TOUCH);
        }
        (y, mode)
    }

    /// Whether the lower mass moves away from its support (the clearance opening).
    pub(super) fn support_opening(&self, y: &[f64; N]) -> bool {
        let v3 = if self.foundation.is_some() { y[V3] } else { 0.0 };
        matches!(self.lower, Lower::Mass { .. }) && y[VL] - v3 < 0.0
    }

    /// Energy the moving bodies bring to the blow, J.
    pub fn kinetic_in(&self, y0: &[f64; N]) -> f64 {
        self.mechanical_energy(y0, Mode { contact: Contact::Free, engaged: false })
    }

    /// Which state components this plant uses (the others stay zero).
    pub(super) fn used_states(&self) -> [bool; N] {
        let mut u = [true; N];
        if self.ram.is_none() {
            u[XR] = false;
            u[VR] = false;
        }
        if matches!(self.lower, Lower::Chain { .. }) {
            u[XL] = false;
            u[VL] = false;
        }
        if self.foundation.is_none() {
            u[X3] = false;
            u[V3] = false;
        }
        if !self.node {
            u[XN] = false;
        }
        if !self.highpass_tau_s.is_finite() {
            u[Z] = false;
        }
        u
    }

    /// Outputs at a state: (sensor load, billet force, upper position, lower position, height).
    pub fn outputs(&self, y: &[f64; N], mode: Mode) -> Outputs {
        let e = self.eval(y, mode);
        let lower_m = match self.lower {
            Lower::Mass { .. } => y[XL],
            Lower::Chain { .. } if self.node => y[XN],
            Lower::Chain { .. } => y[X3],
        };
        let (ram_m, ram_mps, ram_acc_mps2) = match self.ram {
            Some((m, _, _)) => (y[XR], y[VR], -e.link_n / m),
            None => (y[XU], y[VU], e.acc_upper),
        };
        Outputs {
            sensor_n: self.sensor(y, &e),
            billet_n: e.contact_n,
            upper_m: y[XU],
            lower_m,
            h_m: e.h_m,
            ram_m,
            ram_mps,
            ram_acc_mps2,
        }
    }

    /// Rate of the sensor output, for peak interpolation within a step.
    pub(super) fn sensor_rate(&self, y: &[f64; N], dy: &[f64; N], mode: Mode) -> f64 {
        let raw = match self.lower {
            Lower::Mass { k_n_per_m, c_ns_per_m, .. } => {
                if mode.engaged {
                    let (v3, a3) = if self.foundation.is_some() { (y[V3], dy[V3]) } else { (0.0, 0.0) };
                    k_n_per_m * (y[VL] - v3) + c_ns_per_m * (dy[VL] - a3)
                } else {
                    0.0
                }
            }
            Lower::Chain { .. } => {
                if mode.contact == Contact::Free {
                    0.0
                } else {
                    let vl = if self.node {
                        dy[XN]
                    } else if self.foundation.is_some() {
                        y[V3]
                    } else {
                        0.0
                    };
                    self.k_contact_n_per_m * (y[VU] - vl - dy[P])
                }
            }
        };
        if self.highpass_tau_s.is_finite() { raw - dy[Z] } else { raw }
    }
}

/// Signals a person or the diagnosis looks at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outputs {
    pub sensor_n: f64,
    pub billet_n: f64,
    pub upper_m: f64,
    pub lower_m: f64,
    pub h_m: f64,
    /// The ram, which carries the encoder and the accelerometer: the upper mass of a hammer,
    /// the heavy mass behind the link of a press. Position m, velocity m/s, acceleration m/s².
    pub ram_m: f64,
    pub ram_mps: f64,
    pub ram_acc_mps2: f64,
}
