//! The base hammer's plastic flow by an exponential integrator (ETDRK4, Cox and Matthews
//! 2002), for the fits' plant (`BaseHammer::with_exact_phases`) on a rate-independent law.
//!
//! While the billet flows, the lower tool rings on its frame at a few kHz, driven by the
//! billet's load, which changes on the blow's millisecond scale. Dormand–Prince has to
//! follow the ringing (250 steps over the suite's hammer's 11.7 ms of flow); this integrator
//! advances the lower tool's oscillator exactly for a load that is quadratic in time over the
//! step, so its steps are set by the load: `ETD_STEP_RAD` of the ringing, 100 µs on the
//! suite's hammer (`benches/plastic_integrators.py` and docs/validation.md's "fifth pass": 3.3× fewer
//! evaluations, each bound of `blow::tests` met with room).
//!
//! - The linear part is the lower tool's oscillator, and the compression's share of its
//!   speed: `P + x_l` moves only with the ram, so the compression is the ram's share,
//!   integrated as the other components are, less the lower tool's travel.
//! - Every other component (the ram, the works) has no linear part, and the scheme is then
//!   the classical RK4.
//! - Steps start on the trace's grid and span `Etd::points` of its points, so the samples
//!   inside take tabulated weights (`Etd::inside`) on the scheme's own continuous extension.
//! - The error estimate is the defect of the quadratic at the step's end (the load there
//!   against the quadratic through the stages), carried through the step's `phi_3`. A step
//!   whose estimate exceeds 1, or in which a guard fires, is not taken: Dormand–Prince
//!   takes that span (`integrator::integrate`), as it takes a rate-dependent law (whose
//!   damping near the end of flow, `m F / h'`, is not in the linear part) and every step
//!   that does not start on the grid. The estimate is an indicator, not a bound: it flags a
//!   load that stops being smooth over a step (it caught the rate term's end of flow in the
//!   study), and at the fits' tolerance `blow::tests` hold the results to what a capture
//!   cannot see; at 1e-9 it lets some spans through that leave 8e-11 m on the final height
//!   where Dormand–Prince alone leaves 2e-12 m
//!   (`blow::tests::the_fits_plastic_flow_takes_exponential_steps_where_they_hold`).

use std::rc::Rc;

use super::{BL, BP, BVL, BaseHammer, NB};
use crate::physics::integrator::Grid;
use crate::physics::oscillator::{self, Oscillator, Phi};

/// Angle of the lower tool's ringing one exponential step covers at most, rad. At 1.0 (100 µs
/// on the suite's hammer, 70 µs on the paper's) `benches/plastic_integrators.py` measured
/// compressions within 2e-10 m of the reference (bound 1e-8 m), the sensor at the samples
/// within 3.2 N (bound 200 N) and the plastic work within 6.3e-6 of the kinetic energy
/// (ledger 1e-5); its error estimate stayed below 0.05 there.
const ETD_STEP_RAD: f64 = 1.0;

/// `1/3`, the quadratic term's integral over a step.
const THIRD: f64 = 1.0 / 3.0;

/// The plastic steps of one blow: the grid they start and end on, and their weights.
#[derive(Debug, Clone)]
pub(super) struct Etd {
    /// The grid the steps start and end on (the exact phases' points, `points` per step).
    pub(super) grid: Grid,
    w: Rc<Weights>,
}

/// The weights of a step of `points` grid steps, which depend on the lower tool and the
/// step alone: shared by every blow of a machine (`BaseHammer::with_exact_phases`' cache).
#[derive(Debug)]
struct Weights {
    full: Phi,
    half: Phi,
    /// At each grid point inside a step, `j / points` of it, j = 1 .. points - 1.
    inside: Vec<Phi>,
    /// `j / points`, j = 0 ..= points, divided once (`fraction`).
    fractions: Vec<f64>,
}

impl Etd {
    /// The weights for steps of whole points of `grid` (the exact phases'), none where the
    /// step would cover fewer than two points or the lower tool is not underdamped.
    pub(super) fn new(free: &Oscillator, w0_per_s: f64, grid: Grid) -> Option<Etd> {
        let points = ((ETD_STEP_RAD / (w0_per_s * grid.dt_s)).floor().min(f64::from(grid.points))) as u32;
        if points < 2 {
            return None;
        }
        let grid = Grid { points, ..grid };
        let h = grid.span_s();
        let inside = (1..points).map(|j| free.phi(h * f64::from(j) / f64::from(points))).collect::<Option<_>>()?;
        let fractions = (0..=points).map(|j| f64::from(j) / f64::from(points)).collect();
        let w = Weights { full: free.phi(h)?, half: free.phi(0.5 * h)?, inside, fractions };
        Some(Etd { grid, w: Rc::new(w) })
    }

    /// The same weights on the grid from `t0_s`.
    pub(super) fn starting_at(&self, t0_s: f64) -> Etd {
        Etd { grid: Grid { t0_s, ..self.grid }, w: Rc::clone(&self.w) }
    }

    /// `j / points` of a step.
    pub(super) fn fraction(&self, j: u32) -> f64 {
        self.w.fractions.get(j as usize).copied().unwrap_or(1.0)
    }
}

/// An exponential step's stages, kept for the samples inside it (`BaseHammer::grid_points`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct EtdStep {
    pub(super) t0_s: f64,
    pub(super) h_s: f64,
    y0: [f64; NB],
    /// The nonlinear part along the step, `n0 + d1 s/h + d2 (s/h)^2`.
    n0: [f64; NB],
    d1: [f64; NB],
    d2: [f64; NB],
    pub(super) y1: [f64; NB],
}

impl BaseHammer<'_> {
    /// The vector field less its linear part, from the field `dy` at `y`: the billet's load
    /// on the lower tool per its mass, and the ram's speed in the compression's rate.
    fn nonlinear(&self, inv_m2: f64, y: &[f64; NB], dy: &[f64; NB]) -> [f64; NB] {
        let mut n = *dy;
        n[BL] = 0.0;
        n[BVL] = dy[BVL] + self.support_n(y) * inv_m2;
        n[BP] = dy[BP] + y[BVL];
        n
    }

    /// The state `h` after `from` under the forcing `f0 + f1 s/h + f2 (s/h)^2`: the lower
    /// tool by `phi`'s weights, the components without a linear part by the forcing's
    /// integral, the compression by the ram's share less the lower tool's travel.
    fn forced(phi: &Phi, from: &[f64; NB], h: f64, f0: &[f64; NB], f1: &[f64; NB], f2: &[f64; NB]) -> [f64; NB] {
        let mut out = [0.0; NB];
        for i in 0..NB {
            out[i] = from[i] + h * (f0[i] + 0.5 * f1[i] + THIRD * f2[i]);
        }
        let (x, v) = oscillator::apply(&phi.e, from[BL], from[BVL]);
        let [p1, p2, p3] = phi.p;
        let force = |k: usize| h * (p1[k] * f0[BVL] + p2[k] * f1[BVL] + 2.0 * p3[k] * f2[BVL]);
        out[BL] = x + force(0);
        out[BVL] = v + force(1);
        out[BP] -= out[BL] - from[BL];
        out
    }

    /// `forced` under a constant forcing (the stages).
    fn forced_const(phi: &Phi, from: &[f64; NB], h: f64, f0: &[f64; NB]) -> [f64; NB] {
        let mut out = [0.0; NB];
        for i in 0..NB {
            out[i] = from[i] + h * f0[i];
        }
        let (x, v) = oscillator::apply(&phi.e, from[BL], from[BVL]);
        let p1 = phi.p[0];
        out[BL] = x + h * (p1[0] * f0[BVL]);
        out[BVL] = v + h * (p1[1] * f0[BVL]);
        out[BP] -= out[BL] - from[BL];
        out
    }

    /// One exponential step of a whole span from a grid point: the new state, its field and
    /// the error estimate (≤ 1 accepts, as Dormand–Prince's). `None` where the plant has no
    /// exponential steps or `h` is not the span. The stages are kept for `grid_points`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn etd_step_from(
        &self,
        t_s: f64,
        y: &[f64; NB],
        dy: &[f64; NB],
        h: f64,
        scale: &[f64; NB],
        rtol: f64,
    ) -> Option<([f64; NB], [f64; NB], f64)> {
        let etd = self.etd.as_ref()?;
        let inv_m2 = self.plant.inv_m.1;
        if h != etd.grid.span_s() {
            return None;
        }
        let mode = super::Mode { contact: super::Contact::Plastic, engaged: true };
        let field = |y: &[f64; NB]| {
            let mut dy = [0.0; NB];
            super::Hybrid::rhs(self, y, mode, &mut dy);
            (dy, self.nonlinear(inv_m2, y, &dy))
        };
        let n0 = self.nonlinear(inv_m2, y, dy);
        let a = Self::forced_const(&etd.w.half, y, 0.5 * h, &n0);
        let (_, na) = field(&a);
        let b = Self::forced_const(&etd.w.half, y, 0.5 * h, &na);
        let (_, nb) = field(&b);
        let twice_b = std::array::from_fn(|i| 2.0 * nb[i] - n0[i]);
        let c = Self::forced_const(&etd.w.half, &a, 0.5 * h, &twice_b);
        let (_, nc) = field(&c);
        let d1: [f64; NB] = std::array::from_fn(|i| -3.0 * n0[i] + 2.0 * (na[i] + nb[i]) - nc[i]);
        let d2: [f64; NB] = std::array::from_fn(|i| 2.0 * (n0[i] - (na[i] + nb[i]) + nc[i]));
        let y1 = Self::forced(&etd.w.full, y, h, &n0, &d1, &d2);
        let (dy1, n1) = field(&y1);
        // The defect at the end, carried as a constant forcing through phi_3 (a sixth of the
        // step on the components without a linear part).
        let defect = |i: usize| n1[i] - (n0[i] + d1[i] + d2[i]);
        let lower_x = h * etd.w.full.p[2][0] * defect(BVL);
        let mut sum = 0.0;
        for i in 0..NB {
            let e = match i {
                BL => lower_x,
                BVL => h * etd.w.full.p[2][1] * defect(BVL),
                BP => h * defect(BP) / 6.0 - lower_x,
                _ => h * defect(i) / 6.0,
            };
            let sc = rtol * (scale[i] + y[i].abs().max(y1[i].abs()));
            sum += (e / sc) * (e / sc);
        }
        self.last_etd.set(Some(EtdStep { t0_s: t_s, h_s: h, y0: *y, n0, d1, d2, y1 }));
        Some((y1, dy1, (sum / NB as f64).sqrt()))
    }

    /// The state at grid point `j` (of `Etd::points`) of the kept step, on the scheme's
    /// continuous extension (the step's own end at the last).
    pub(super) fn etd_point(&self, s: &EtdStep, j: u32) -> Option<[f64; NB]> {
        let etd = self.etd.as_ref()?;
        if j >= etd.grid.points {
            return Some(s.y1);
        }
        let th = etd.fraction(j);
        let d1 = s.d1.map(|d| th * d);
        let d2 = s.d2.map(|d| th * th * d);
        Some(Self::forced(etd.w.inside.get(j as usize - 1)?, &s.y0, th * s.h_s, &s.n0, &d1, &d2))
    }

    /// The lower tool's position and speed, and the load on it per its mass, at each grid
    /// point of the kept step after its start, in turn (the step's own end at the last):
    /// `etd_point`'s, without the other components (all the samples need). False, and no
    /// call, where the plant has no exponential steps.
    pub(super) fn etd_lower_points(&self, s: &EtdStep, mut f: impl FnMut(f64, f64, f64)) -> bool {
        let Some(etd) = self.etd.as_ref() else { return false };
        let w = &*etd.w;
        let (x0, v0) = (s.y0[BL], s.y0[BVL]);
        let (f0, d1, d2) = (s.n0[BVL], s.d1[BVL], s.d2[BVL]);
        for (phi, &th) in w.inside.iter().zip(&w.fractions[1..]) {
            let (x, v) = oscillator::apply(&phi.e, x0, v0);
            let h = th * s.h_s;
            let [p1, p2, p3] = phi.p;
            let (g1, g2) = (th * d1, th * th * d2);
            let force = |k: usize| h * (p1[k] * f0 + p2[k] * g1 + 2.0 * p3[k] * g2);
            f(x + force(0), v + force(1), f0 + th * (d1 + th * d2));
        }
        f(s.y1[BL], s.y1[BVL], f0 + (d1 + d2));
        true
    }
}
