//! The base hammer's blow on a fixed eight-component state: the plant `Plant::new` builds
//! for a hammer on a billet with no machine-side effect (no clearance, no elastic recovery,
//! no foundation, no sensor high-pass; the load-side effects live in the billet law and are
//! kept), integrated without the six state components it never moves and without the
//! general plant's branches on parts it does not have.
//!
//! It is the general plant to the bit, not an approximation of it: the hot functions (the
//! vector field, the guards, the sensor and its rate) evaluate the same expressions in the
//! same order with the absent parts' zeros folded in exactly (`x - 0.0` is `x`), the error
//! norm sees the same components in the same order, and the rare calls (events, initial
//! state, energies, full outputs) expand the state and ask the general plant.
//! `blow::run` selects it automatically; `blow`'s tests compare the two paths.

use super::*;

/// Length of the reduced state.
pub const NB: usize = 8;

/// The general state's component held at each reduced index, in increasing order (so the
/// error norm sums the same terms in the same order as on the general state).
const FULL_INDEX: [usize; NB] = [XU, VU, XL, VL, P, WP, WF, WD];
// Reduced indices.
const BU: usize = 0;
const BVU: usize = 1;
const BL: usize = 2;
const BVL: usize = 3;
const BP: usize = 4;
const BWP: usize = 5;
const BWF: usize = 6;
const BWD: usize = 7;

/// A hammer on a billet with no machine-side effect, borrowed from its general plant.
#[derive(Debug, Clone, Copy)]
pub struct BaseHammer<'a> {
    plant: &'a Plant,
    law: &'a BilletLaw,
    m1_kg: f64,
    m2_kg: f64,
    k_n_per_m: f64,
    c_ns_per_m: f64,
}

impl<'a> BaseHammer<'a> {
    /// The specialised plant of `plant`, when it is a base hammer on a billet.
    pub fn of(plant: &'a Plant) -> Option<BaseHammer<'a>> {
        let Lower::Mass { m_kg, k_n_per_m, c_ns_per_m } = plant.lower else { return None };
        let base = plant.ram.is_none()
            && plant.rigid()
            && !plant.node
            && plant.foundation.is_none()
            && plant.gap_support_m == 0.0
            && !plant.lower_at_rest
            && plant.gap_contact_m == 0.0
            && !plant.highpass_tau_s.is_finite();
        let law = plant.billet.as_ref()?;
        base.then_some(BaseHammer { plant, law, m1_kg: plant.m_upper_kg, m2_kg: m_kg, k_n_per_m, c_ns_per_m })
    }

    /// The reduced state of a general one.
    pub fn reduce(&self, y: &[f64; N]) -> [f64; NB] {
        FULL_INDEX.map(|i| y[i])
    }

    /// The general state of a reduced one (the components a base hammer never moves are 0
    /// there too: its vector field keeps them at their initial 0).
    pub fn expand(&self, y: &[f64; NB]) -> [f64; N] {
        let mut full = [0.0; N];
        for (b, &i) in FULL_INDEX.iter().enumerate() {
            full[i] = y[b];
        }
        full
    }

    /// The lower tool's frame force, which the sensor reads: `Plant::kinematics`' support
    /// force with the foundation's and the clearance's zeros folded in. The support path is
    /// always engaged (no clearance).
    fn support_n(&self, y: &[f64; NB]) -> f64 {
        self.k_n_per_m * y[BL] + self.c_ns_per_m * y[BVL]
    }

    /// The force that keeps the tools together while stuck (`Plant::kinematics`, no ram).
    fn stick_n(&self, support_n: f64) -> f64 {
        (0.0 / self.m1_kg + support_n / self.m2_kg) / (1.0 / self.m1_kg + 1.0 / self.m2_kg)
    }

    /// Sensor output (`Plant::sensor_at`).
    pub fn sensor_at(&self, y: &[f64; NB]) -> f64 {
        self.support_n(y)
    }

    /// The sensor on a step's cubic Hermite interpolant at `theta`: `integrator::hermite`'s
    /// terms for the two components it reads, the others left out.
    pub fn sensor_within(
        &self,
        y0: &[f64; NB],
        dy0: &[f64; NB],
        y1: &[f64; NB],
        dy1: &[f64; NB],
        h: f64,
        theta: f64,
    ) -> f64 {
        let pick = |y: &[f64; NB]| [y[BL], y[BVL]];
        let [x, v] = crate::physics::integrator::hermite(&pick(y0), &pick(dy0), &pick(y1), &pick(dy1), h, theta);
        self.k_n_per_m * x + self.c_ns_per_m * v
    }

    /// Rate of the sensor output (`Plant::sensor_rate`).
    pub fn sensor_rate(&self, y: &[f64; NB], dy: &[f64; NB]) -> f64 {
        self.k_n_per_m * y[BVL] + self.c_ns_per_m * dy[BVL]
    }
}

impl Hybrid<NB> for BaseHammer<'_> {
    type Mode = Mode;

    /// `Plant::eval` and `Plant::rhs` for this plant, term for term.
    fn rhs(&self, y: &[f64; NB], mode: Mode, dy: &mut [f64; NB]) {
        let h_m = self.plant.h_start_m - y[BP];
        let ddelta_mps = y[BVU] - y[BVL];
        let support_n = self.support_n(y);
        let (mut contact_n, mut p_rate_mps, mut frictionless_share) = (0.0, 0.0, 1.0);
        match mode.contact {
            Contact::Free | Contact::Elastic => {}
            Contact::Stuck => contact_n = self.stick_n(support_n),
            Contact::Plastic => {
                let l = self.law.load(h_m, ddelta_mps.max(0.0) / h_m);
                if l.total_n.is_finite() && l.total_n > 0.0 {
                    frictionless_share = l.frictionless_n / l.total_n;
                }
                contact_n = l.total_n;
                p_rate_mps = ddelta_mps;
            }
        }
        let acc_upper = (0.0 - contact_n) / self.m1_kg;
        let acc_lower = if mode.contact == Contact::Stuck { acc_upper } else { (contact_n - support_n) / self.m2_kg };
        dy[BU] = y[BVU];
        dy[BVU] = acc_upper;
        dy[BL] = y[BVL];
        dy[BVL] = acc_lower;
        dy[BP] = p_rate_mps;
        let work = contact_n * p_rate_mps;
        dy[BWP] = work * frictionless_share;
        dy[BWF] = work * (1.0 - frictionless_share);
        dy[BWD] = 0.0 + self.c_ns_per_m * y[BVL].powi(2);
    }

    /// `Plant::guards` for a rigid contact with an engaged support and a raw sensor.
    fn guards(&self, y: &[f64; NB], _dy: &[f64; NB], mode: Mode, out: &mut Guards) {
        let support_n = self.support_n(y);
        match mode.contact {
            Contact::Free | Contact::Elastic => {
                out.push(hybrid::G_TOUCH, (y[BU] - y[BL]) - y[BP], Crossing::Rising);
            }
            Contact::Plastic => out.push(hybrid::G_REL_VEL_ZERO, y[BVU] - y[BVL], Crossing::Falling),
            Contact::Stuck => {
                let stick_n = self.stick_n(support_n);
                let f_l = self.plant.yield_load(self.plant.h_start_m - y[BP], 0.0);
                out.push(hybrid::G_STICK_ZERO, stick_n, Crossing::Falling);
                out.push(hybrid::G_STICK_YIELD, stick_n - f_l, Crossing::Rising);
            }
        }
        if mode.contact != Contact::Plastic {
            out.push(hybrid::G_SENSOR_ZERO, support_n, Crossing::Falling);
        }
    }

    fn on_event(&self, y: &mut [f64; NB], mode: Mode, guard_id: u8) -> Mode {
        let mut full = self.expand(y);
        let next = self.plant.on_event(&mut full, mode, guard_id);
        *y = self.reduce(&full);
        next
    }

    fn max_step(&self) -> f64 {
        self.plant.max_step()
    }
}
