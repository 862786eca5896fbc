//! The base hammer's blow on a fixed eight-component state: the plant `Plant::new` builds
//! for a hammer on a billet with no machine-side effect (no clearance, no elastic recovery,
//! no foundation, no sensor high-pass; the load-side effects live in the billet law and are
//! kept), integrated without the six state components it never moves and without the
//! general plant's branches on parts it does not have.
//!
//! It is the general plant on fewer components, not an approximation of it: the vector
//! field evaluates the same contact law (`Plant::rigid_flow`, the billet's one law) with the
//! absent parts' zeros folded in and the masses' reciprocals taken once, the guards and the
//! sensor are the general plant's terms, the error norm sees the same components in the
//! same order, and the rare calls (events, initial state, energies, full outputs) expand the
//! state and ask the general plant. The results agree within roundoff, not to the bit.
//! `blow::run` selects it automatically; `blow`'s tests compare the two paths.
//!
//! With `with_exact_phases` (what `blow::simulate_blow_sensor`, the fits' blow, uses under
//! Dormand–Prince) it also advances the phases in which the billet does not flow by their
//! exact flow: there the plant is linear, the lower tool a damped oscillator (`oscillator`)
//! alone or carrying the ram, the ram in free flight or riding on it. Those phases (most of
//! the post window) then cost a 2×2 product per grid point instead of Runge–Kutta stages;
//! the results move by the general plant's integration error there, which `blow`'s tests
//! bound.

use std::cell::{Cell, RefCell};

use super::*;
use crate::physics::integrator::Grid;
use crate::physics::oscillator::{self, Oscillator, Propagator};

mod etd;
use etd::{Etd, EtdStep};

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

/// Angle of the fastest linear mode one exact step may cover, rad. The exact steps end on
/// the trace's samples, which are exact; between grid points the recorder reads the sensor
/// (its peak, a guard's bracket) on the cubic Hermite through exact ends, within
/// `(w h)^4 / 384` = 4.2e-6 of the ringing's amplitude (the interpolation's error bound),
/// less than a Dormand–Prince step of the same phase leaves at the fits' rtol 1e-6.
const EXACT_STEP_RAD: f64 = 0.2;

/// The exact flow of the phases without plastic flow.
#[derive(Debug, Clone, Copy)]
struct Exact {
    grid: Grid,
    /// The lower tool on its frame alone (tools apart) and carrying the ram (stuck).
    free: Oscillator,
    stuck: Oscillator,
    /// Their propagators over one grid step and over a step's span of grid points.
    free_step: Propagator,
    stuck_step: Propagator,
    free_span: Propagator,
    stuck_span: Propagator,
}

/// `with_exact_phases`' tables for one machine and grid step, on a grid from 0. A fit's
/// cost function simulates its five blows with the same machine, and the tables (eleven
/// exponential weights, four propagators) depend on nothing else: each thread keeps the
/// last machine's.
#[derive(Debug, Clone)]
struct Tables {
    /// The masses, the frame's stiffness and damping, the grid step (their bits), the points
    /// per step, and whether the law is rate-dependent.
    key: [u64; 7],
    exact: Exact,
    etd: Option<Etd>,
}

impl Tables {
    fn key(b: &BaseHammer, dt_s: f64, points: u32) -> [u64; 7] {
        let bits = [b.m1_kg, b.m2_kg, b.k_n_per_m, b.c_ns_per_m, dt_s].map(f64::to_bits);
        let rate = u64::from(b.law.is_rate_dependent());
        [bits[0], bits[1], bits[2], bits[3], bits[4], u64::from(points), rate]
    }
}

thread_local! {
    static TABLES: RefCell<Option<Tables>> = const { RefCell::new(None) };
}

/// The sensor at a grid point inside an exact step (`BaseHammer::grid_points`).
#[derive(Debug, Clone, Copy)]
pub struct GridPoint {
    pub t_s: f64,
    pub sensor_n: f64,
    /// The sensor's rate, N/s.
    pub rate: f64,
    /// The lower tool's position and velocity (`BaseHammer::grid_point_state`).
    lower_m: f64,
    lower_mps: f64,
}

/// A hammer on a billet with no machine-side effect, borrowed from its general plant.
#[derive(Debug, Clone)]
pub struct BaseHammer<'a> {
    plant: &'a Plant,
    law: &'a BilletLaw,
    m1_kg: f64,
    m2_kg: f64,
    k_n_per_m: f64,
    c_ns_per_m: f64,
    exact: Option<Exact>,
    /// The plastic flow's exponential steps (`etd`), with the exact phases on a
    /// rate-independent law, and the last one's stages.
    etd: Option<Etd>,
    last_etd: Cell<Option<EtdStep>>,
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
        base.then_some(BaseHammer {
            plant,
            law,
            m1_kg: plant.m_upper_kg,
            m2_kg: m_kg,
            k_n_per_m,
            c_ns_per_m,
            exact: None,
            etd: None,
            last_etd: Cell::new(None),
        })
    }

    /// The same plant advancing the phases without plastic flow by their exact flow, on the
    /// grid `t0_s + k dt`: `dt` is the trace's `sample_dt_s` (or a whole fraction of it)
    /// within `EXACT_STEP_RAD` of the fastest mode, so every sample is a grid point, and a
    /// step spans as many grid points as fit in the plant's `max_step` (a guard cannot
    /// change sign twice within it; `grid_points` gives the sensor at those inside).
    /// Unchanged if no finite step follows from the parameters.
    pub fn with_exact_phases(self, t0_s: f64, sample_dt_s: Option<f64>) -> Self {
        let free = Oscillator::new(self.m2_kg, self.k_n_per_m, self.c_ns_per_m);
        let stuck = Oscillator::new(self.m1_kg + self.m2_kg, self.k_n_per_m, self.c_ns_per_m);
        let h_max = EXACT_STEP_RAD / free.fastest_rate_per_s().max(stuck.fastest_rate_per_s());
        let dt_s = match sample_dt_s {
            // The ceiling's slack keeps a sample step equal to h_max (to roundoff) whole.
            Some(d) if d > 0.0 && d.is_finite() => d / (d / h_max * (1.0 - 1e-9)).ceil().max(1.0),
            _ => h_max,
        };
        if !(dt_s > 0.0 && dt_s.is_finite() && t0_s.is_finite()) {
            return self;
        }
        // At most u32::MAX points: a float-to-int cast saturates.
        let points = ((self.plant.max_step() / dt_s).floor() as u32).max(1);
        let key = Tables::key(&self, dt_s, points);
        let tables = TABLES.with_borrow_mut(|last| match last {
            Some(t) if t.key == key => t.clone(),
            _ => last.insert(self.tables(free, stuck, Grid { t0_s: 0.0, dt_s, points }, key)).clone(),
        });
        let exact = Exact { grid: Grid { t0_s, ..tables.exact.grid }, ..tables.exact };
        let etd = tables.etd.map(|e| e.starting_at(t0_s));
        BaseHammer { exact: Some(exact), etd, ..self }
    }

    /// The exact phases' propagators and the plastic steps' weights on `grid`.
    fn tables(&self, free: Oscillator, stuck: Oscillator, grid: Grid, key: [u64; 7]) -> Tables {
        let exact = Exact {
            grid,
            free,
            stuck,
            free_step: free.propagator(grid.dt_s),
            stuck_step: stuck.propagator(grid.dt_s),
            free_span: free.propagator(grid.span_s()),
            stuck_span: stuck.propagator(grid.span_s()),
        };
        // The exponential plastic steps: not on a rate-dependent law (`etd`).
        let w0 = (self.k_n_per_m / self.m2_kg).sqrt();
        let etd = (!self.law.is_rate_dependent()).then(|| Etd::new(&free, w0, grid)).flatten();
        Tables { key, exact, etd }
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
        stick_n(self.plant.inv_m, 0.0, support_n)
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

    /// In an exact phase, the grid points after `t0_s` within a step of `h_s` from a grid
    /// point `(t0_s, y0)`: `f` at each in turn, the lower tool advanced
    /// by the one-point propagator (a 2×2 product per point). False, and no call, where the
    /// step is not such a step.
    pub fn grid_points<F: FnMut(&GridPoint)>(&self, t0_s: f64, y0: &[f64; NB], mode: Mode, h_s: f64, mut f: F) -> bool {
        if mode.contact == Contact::Plastic {
            return self.etd_points(t0_s, h_s, f);
        }
        let Some(e) = self.exact.as_ref() else { return false };
        let Some(k0) = e.grid.on_grid(t0_s) else { return false };
        // A step of whole points is their multiple to roundoff; the slack keeps the last.
        let n = (h_s / e.grid.dt_s * (1.0 + 1e-9)).floor();
        if n < 1.0 {
            return false;
        }
        let (step, inv_m) = if mode.contact == Contact::Stuck {
            (&e.stuck_step, 1.0 / (self.m1_kg + self.m2_kg))
        } else {
            (&e.free_step, self.plant.inv_m.1)
        };
        let (mut x, mut v) = (y0[BL], y0[BVL]);
        let mut j = 1.0;
        while j <= n {
            (x, v) = oscillator::apply(step, x, v);
            let sensor_n = self.k_n_per_m * x + self.c_ns_per_m * v;
            // The lower tool's acceleration: the frame's force over the mass it carries.
            let rate = self.k_n_per_m * v - self.c_ns_per_m * sensor_n * inv_m;
            f(&GridPoint { t_s: e.grid.t0_s + (k0 + j) * e.grid.dt_s, sensor_n, rate, lower_m: x, lower_mps: v });
            j += 1.0;
        }
        true
    }

    /// In an exponential plastic step (the last one taken, from `t0_s` over `h_s`), `f` at
    /// each grid point within it, on the scheme's continuous extension; false, and no call,
    /// where the step is not that one.
    fn etd_points<F: FnMut(&GridPoint)>(&self, t0_s: f64, h_s: f64, mut f: F) -> bool {
        let (Some(etd), Some(_), Some(s)) = (self.etd.as_ref(), self.exact.as_ref(), self.last_etd.get()) else {
            return false;
        };
        let inv_m2 = self.plant.inv_m.1;
        // The observer's step is `t1 - t0`, the span to roundoff.
        if !(s.t0_s == t0_s && (h_s - s.h_s).abs() <= 1e-9 * s.h_s) {
            return false;
        }
        let Some(k0) = etd.grid.on_grid(t0_s) else { return false };
        let mut k = k0;
        self.etd_lower_points(&s, |x, v, force| {
            let sensor_n = self.k_n_per_m * x + self.c_ns_per_m * v;
            let acc = force - sensor_n * inv_m2;
            let rate = self.k_n_per_m * v + self.c_ns_per_m * acc;
            k += 1.0;
            f(&GridPoint { t_s: etd.grid.t0_s + k * etd.grid.dt_s, sensor_n, rate, lower_m: x, lower_mps: v });
        })
    }

    /// The whole state at a grid point of an exact step from `(t0_s, y0)` (or of an
    /// exponential plastic step).
    pub fn grid_point_state(&self, t0_s: f64, y0: &[f64; NB], mode: Mode, p: &GridPoint) -> [f64; NB] {
        if mode.contact == Contact::Plastic
            && let (Some(etd), Some(s)) = (self.etd.as_ref(), self.last_etd.get())
        {
            let j = ((p.t_s - t0_s) / etd.grid.dt_s).round() as u32;
            if let Some(y) = self.etd_point(&s, j.max(1)) {
                return y;
            }
        }
        self.phase_state(y0, mode, p.t_s - t0_s, p.lower_m, p.lower_mps)
    }

    /// The state `tau_s` after `y` in a linear phase, given the lower tool's position and
    /// velocity then: the ram in free flight, or riding on the tool when stuck; the damped
    /// work as the oscillator's energy loss; the plastic state unchanged.
    fn phase_state(&self, y: &[f64; NB], mode: Mode, tau_s: f64, xl: f64, vl: f64) -> [f64; NB] {
        let stuck = mode.contact == Contact::Stuck;
        let m_kg = if stuck { self.m1_kg + self.m2_kg } else { self.m2_kg };
        let mut out = *y;
        out[BL] = xl;
        out[BVL] = vl;
        if stuck {
            // Stuck tools share one velocity exactly (`Plant::common_velocity` at entry).
            out[BU] = y[BU] + (xl - y[BL]);
            out[BVU] = vl;
        } else {
            out[BU] = y[BU] + tau_s * y[BVU];
        }
        // The damper takes what the oscillator loses, d/dt (½ m v² + ½ k x²) = -c v²: the
        // energy ledger closes to roundoff over these phases.
        out[BWD] =
            y[BWD] + 0.5 * m_kg * (y[BVL] - vl) * (y[BVL] + vl) + 0.5 * self.k_n_per_m * (y[BL] - xl) * (y[BL] + xl);
        out
    }
}

impl Hybrid<NB> for BaseHammer<'_> {
    type Mode = Mode;

    /// `Plant::rhs` on the components this plant moves, from the general plant's own terms:
    /// its support force with the absent parts' zeros folded in, its contact law
    /// (`Plant::rigid_flow`), its accelerations (`two_bodies`) and work rates
    /// (`Flow::work_rates`).
    fn rhs(&self, y: &[f64; NB], mode: Mode, dy: &mut [f64; NB]) {
        let support_n = self.support_n(y);
        let stuck = mode.contact == Contact::Stuck;
        let stick_n = if stuck { self.stick_n(support_n) } else { 0.0 };
        let f = Plant::rigid_flow(self.law, mode.contact, self.plant.h_start_m - y[BP], y[BVU] - y[BVL], stick_n);
        (dy[BVU], dy[BVL]) = two_bodies(self.plant.inv_m, 0.0, f.contact_n, support_n, stuck);
        dy[BU] = y[BVU];
        dy[BL] = y[BVL];
        dy[BP] = f.p_rate_mps;
        (dy[BWP], dy[BWF]) = f.work_rates();
        dy[BWD] = self.c_ns_per_m * y[BVL] * y[BVL];
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

    /// The tools apart or stuck: a linear phase, advanced exactly with `with_exact_phases`.
    fn exact_grid(&self, mode: Mode) -> Option<Grid> {
        self.exact.filter(|_| mode.contact != Contact::Plastic).map(|e| e.grid)
    }

    /// Plastic flow on a rate-independent law, with the exact phases (`etd`).
    fn etd_grid(&self, mode: Mode) -> Option<Grid> {
        self.etd.as_ref().filter(|_| mode.contact == Contact::Plastic).map(|e| e.grid)
    }

    fn etd_step(
        &self,
        t_s: f64,
        y: &[f64; NB],
        dy: &[f64; NB],
        h_s: f64,
        scale: &[f64; NB],
        rtol: f64,
    ) -> Option<([f64; NB], [f64; NB], f64)> {
        self.etd_step_from(t_s, y, dy, h_s, scale, rtol)
    }

    fn etd_discard(&self) {
        self.last_etd.set(None);
    }

    /// The lower tool (alone, or with the ram when stuck) by its oscillator's propagator;
    /// the ram in free flight, or riding on it; the plastic state unchanged.
    fn advance(&self, y: &[f64; NB], mode: Mode, h_s: f64) -> [f64; NB] {
        let Some(e) = self.exact.as_ref() else { unreachable!("advance without exact phases") };
        let stuck = mode.contact == Contact::Stuck;
        let (osc, step) = if stuck { (&e.stuck, &e.stuck_step) } else { (&e.free, &e.free_step) };
        let span = if stuck { &e.stuck_span } else { &e.free_span };
        let phi = if h_s == e.grid.span_s() {
            *span
        } else if h_s == e.grid.dt_s {
            *step
        } else {
            osc.propagator(h_s)
        };
        let (xl, vl) = oscillator::apply(&phi, y[BL], y[BVL]);
        self.phase_state(y, mode, h_s, xl, vl)
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{parse_machine, parse_process};
    use crate::physics::blow::{SimOptions, simulate_blow_sensor};
    use crate::physics::effects::{Effect, EffectSet};
    use crate::physics::integrator::Method;
    use crate::physics::sequence::blow_plant;

    #[test]
    fn a_machine_never_gets_the_tables_of_the_one_before() {
        // The fits' options; the paper's hammer and the suite's light one (another mass,
        // frame and damper), and the paper's with a rate-dependent law (no exponential steps).
        let fits =
            SimOptions { method: Method::Dopri5 { rtol: 1e-6 }, trace_dt_s: Some(1e-5), ..SimOptions::default() };
        let machine = |text: &str| parse_machine("m", text).unwrap().machine;
        let paper = machine(include_str!("../../../config/hammer-lg1000.machine.toml"));
        let small = machine("kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n");
        let steel = parse_process("steel", include_str!("../../../config/steel-16NiCrMo13.process.toml")).unwrap();
        let rate = EffectSet::from_effects(&[Effect::parse_spec("strain_rate:m=0.15").unwrap()]);
        let cases = [(&paper, EffectSet::NONE), (&small, EffectSet::NONE), (&paper, rate)];
        let blow = |i: usize| {
            let (m, e) = &cases[i];
            simulate_blow_sensor(&blow_plant(m, e, &steel, 1, 0.112), 4.0, &fits).unwrap()
        };
        // Each case on a thread of its own (no tables kept), then in turn on one thread, each
        // finding the one before's: the same machine with another law, another machine, and
        // back.
        let fresh: Vec<_> =
            (0..cases.len()).map(|i| std::thread::scope(|s| s.spawn(|| blow(i)).join().unwrap())).collect();
        for i in [0, 2, 1, 0, 2] {
            let (res, sensor) = blow(i);
            assert_eq!(sensor, fresh[i].1, "case {i}");
            assert_eq!(res, fresh[i].0, "case {i}");
        }
        // The rate-dependent law takes no exponential steps, the others do.
        assert_eq!(fresh[2].0.stats.etd_steps, 0);
        assert!(fresh[0].0.stats.etd_steps > 0 && fresh[1].0.stats.etd_steps > 0);
    }
}
