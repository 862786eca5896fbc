//! Integrator for hybrid (piecewise-smooth) mechanical systems, written for blows.
//!
//! A blow is a sequence of smooth phases (plastic forming, stuck, separated, ...) joined by
//! switching events. General adaptive solvers chatter at the rigid-plastic contact switch
//! (DESIGN.md §2.3); here the system names its phase (`Mode`), each phase is integrated with
//! Dormand–Prince 5(4) under step control, and every switch is located by root finding on
//! the step's cubic Hermite interpolant, then reached exactly with one more RK step before
//! the mode changes. A phase whose vector field is linear may instead be advanced by its
//! exact flow (`Hybrid::exact_grid`, `Hybrid::advance`) in steps that end on a fixed grid
//! (the trace's samples), its switches located on that flow. A mode with a linear part
//! and a slowly varying rest may take exponential steps from that grid's points, each
//! spanning several (`Hybrid::etd_grid`, `Hybrid::etd_step`); one whose error estimate
//! exceeds 1, or in which a guard fires, is not taken, and Dormand–Prince takes its span,
//! its steps ending on the grid. A fixed-step classical RK4 runs through the same driver as
//! the reference the tests compare against.

use std::fmt::Debug;

mod grid;
mod guards;
mod steppers;

pub use grid::Grid;
pub use guards::{Crossing, Guards};
use steppers::{Workspace, take_step};

/// Most guards (switching functions) a mode may arm at once.
pub const MAX_GUARDS: usize = 6;

/// Root-finding stops when the bracket is this fraction of the step.
const ROOT_REL_TOL: f64 = 1e-10;
/// Most root-finding iterations: bisection alone reaches `ROOT_REL_TOL` in 34, and at
/// worst every third iteration bisects.
const ROOT_MAX_ITERATIONS: usize = 120;
/// Regula falsi keeping the same end of the bracket this many times running bisects next.
const ROOT_STALL: u8 = 3;
/// Step-size controller: safety factor and growth limits (Hairer, Nørsett, Wanner §II.4).
const SAFETY: f64 = 0.9;
const MAX_GROWTH: f64 = 5.0;
const MIN_SHRINK: f64 = 0.2;

/// A piecewise-smooth autonomous ODE `y' = f(y, mode)` with switching guards.
pub trait Hybrid<const N: usize> {
    type Mode: Copy + PartialEq + Debug;
    /// The vector field of `mode`.
    fn rhs(&self, y: &[f64; N], mode: Self::Mode, dy: &mut [f64; N]);
    /// The guards armed in `mode`, evaluated at `y` (with `dy = rhs(y)`).
    fn guards(&self, y: &[f64; N], dy: &[f64; N], mode: Self::Mode, out: &mut Guards);
    /// A guard fired at `y`: return the next mode, projecting `y` onto it if needed.
    fn on_event(&self, y: &mut [f64; N], mode: Self::Mode, guard_id: u8) -> Self::Mode;
    /// Longest step that cannot jump over a double sign change of a guard
    /// (a fraction of the fastest mode's period).
    fn max_step(&self) -> f64;
    /// Where `mode`'s vector field is linear and `advance` gives its exact flow, the grid
    /// that flow's steps end on (short enough that no guard changes sign twice within one).
    /// `None` (the default): Dormand–Prince integrates the mode.
    fn exact_grid(&self, _mode: Self::Mode) -> Option<Grid> {
        None
    }
    /// The state `h_s` after `y` by the exact flow of `mode`; called only where `exact_grid`
    /// is `Some`.
    fn advance(&self, _y: &[f64; N], _mode: Self::Mode, _h_s: f64) -> [f64; N] {
        unreachable!("advance called in a mode without an exact_grid")
    }
    /// Where `mode` may take exponential steps (`etd_step`), the grid they start on and span
    /// `points` of. `None` (the default): Dormand–Prince alone.
    fn etd_grid(&self, _mode: Self::Mode) -> Option<Grid> {
        None
    }
    /// One exponential step of `h_s` (the grid's span) from the grid point `(t_s, y)`: the new
    /// state, its field, and an error estimate as Dormand–Prince's (≤ 1 accepts).
    #[allow(clippy::too_many_arguments)]
    fn etd_step(
        &self,
        _t_s: f64,
        _y: &[f64; N],
        _dy: &[f64; N],
        _h_s: f64,
        _scale: &[f64; N],
        _rtol: f64,
    ) -> Option<([f64; N], [f64; N], f64)> {
        None
    }
    /// The last exponential step was not taken (its error, or a guard in it).
    fn etd_discard(&self) {}
}

/// What the driver tells the observer, and what the observer answers.
pub trait Observer<const N: usize, M> {
    /// An accepted step from `(t0, y0)` to `(t1, y1)` in `mode`. Return the time at which to
    /// stop (the driver ends exactly there), or `None` for no planned stop (run to `t_max`).
    #[allow(clippy::too_many_arguments)]
    fn on_step(
        &mut self,
        t0: f64,
        y0: &[f64; N],
        dy0: &[f64; N],
        t1: f64,
        y1: &[f64; N],
        dy1: &[f64; N],
        mode: M,
    ) -> Option<f64>;
    /// A located event: the mode changes from `from` to `to` at `(t, y)`.
    fn on_event(&mut self, t: f64, y: &[f64; N], from: M, to: M, guard_id: u8);
}

/// The integration method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Dormand–Prince 5(4) with step control; `atol[i] = rtol * scale[i]`. The error norm is
    /// the RMS over the components with a finite scale: an infinite scale marks a component
    /// the system does not use, which must not dilute the norm.
    Dopri5 { rtol: f64 },
    /// Classical RK4 at a fixed step, s (the tests' reference).
    Rk4 { dt_s: f64 },
}

/// Counts of the work done, for benchmarks and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    pub steps: u32,
    pub rejected: u32,
    pub rhs_evals: u32,
    pub events: u32,
    /// Of `steps`, those taken by a linear phase's exact flow.
    pub exact_steps: u32,
    /// Of `steps`, the exponential ones (`Hybrid::etd_step`).
    pub etd_steps: u32,
}

/// Why integration stopped early.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IntegrationError {
    #[error("step size fell below {min_step_s:e} s at t = {t_s:e} s (mode {mode})")]
    StepTooSmall { t_s: f64, min_step_s: f64, mode: String },
    #[error("more than {max_events} switching events by t = {t_s:e} s (the contact chatters; mode {mode})")]
    Chatter { t_s: f64, max_events: u32, mode: String },
    #[error("the state became non-finite at t = {t_s:e} s (mode {mode})")]
    NonFinite { t_s: f64, mode: String },
    #[error("no end within {t_max_s} s of simulated time")]
    NoEnd { t_max_s: f64 },
    #[error(
        "more than {max_steps} steps by t = {t_s:e} s (a mode far faster than the blow: check the masses and stiffnesses)"
    )]
    TooManySteps { t_s: f64, max_steps: u64 },
}

/// Limits of one integration run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub t_max_s: f64,
    pub max_events: u32,
    pub initial_step_s: f64,
    /// Most steps (accepted and rejected) before giving up.
    pub max_steps: u64,
}

/// Integrate from `(0, y0)` in `mode0` until the observer asks to stop.
pub fn integrate<const N: usize, S, O>(
    sys: &S,
    method: Method,
    scale: &[f64; N],
    y0: [f64; N],
    mode0: S::Mode,
    limits: Limits,
    obs: &mut O,
) -> Result<Stats, IntegrationError>
where
    S: Hybrid<N>,
    O: Observer<N, S::Mode>,
{
    let mut stats = Stats::default();
    let mut t = 0.0;
    let mut y = y0;
    let mut mode = mode0;
    let mut dy = [0.0; N];
    sys.rhs(&y, mode, &mut dy);
    stats.rhs_evals += 1;
    let mut guards = Guards::new();
    sys.guards(&y, &dy, mode, &mut guards);

    let h_max = sys.max_step();
    let mut h = match method {
        Method::Dopri5 { .. } => limits.initial_step_s.min(h_max),
        Method::Rk4 { dt_s } => dt_s,
    };
    let min_step = match method {
        Method::Dopri5 { .. } => limits.t_max_s * 1e-14,
        Method::Rk4 { dt_s } => dt_s,
    };
    let mut t_stop = limits.t_max_s;
    let mut ws = Workspace::<N>::new();
    // The end of a span an exponential step left to Dormand–Prince.
    let mut etd_left_until = f64::NEG_INFINITY;

    loop {
        if u64::from(stats.steps) + u64::from(stats.rejected) > limits.max_steps {
            return Err(IntegrationError::TooManySteps { t_s: t, max_steps: limits.max_steps });
        }
        if t >= t_stop {
            return if t_stop < limits.t_max_s {
                Ok(stats)
            } else {
                Err(IntegrationError::NoEnd { t_max_s: limits.t_max_s })
            };
        }
        // A linear phase steps by its exact flow to the next grid point (and leaves the
        // step-size controller's proposal `h` for the next nonlinear phase); the RK4
        // reference integrates every phase.
        let grid = match method {
            Method::Dopri5 { .. } => sys.exact_grid(mode),
            Method::Rk4 { .. } => None,
        };
        // Where the mode has exponential steps: one from a grid point, unless its span was
        // left to Dormand–Prince; Dormand–Prince's steps end on that grid.
        let etd = match (method, grid) {
            (Method::Dopri5 { rtol }, None) => sys.etd_grid(mode).map(|g| (g, rtol)),
            _ => None,
        };
        let mut etd_taken = None;
        if let Some((g, rtol)) = etd
            && t >= etd_left_until
            && g.on_grid(t).is_some()
            && let (h_g, t_g) = g.next_step(t)
            && t_g <= t_stop
            && let Some((y1, dy1, err)) = sys.etd_step(t, &y, &dy, h_g, scale, rtol)
        {
            stats.rhs_evals += 4;
            if err <= 1.0 && y1.iter().all(|v| v.is_finite()) {
                etd_taken = Some((h_g, t_g, y1, dy1));
            } else {
                stats.rejected += 1;
                sys.etd_discard();
                etd_left_until = t_g;
            }
        }
        let (h_try, t1, y1, dy1) = if let Some(taken) = etd_taken {
            taken
        } else if let Some(g) = grid {
            let (h_grid, t_grid) = g.next_step(t);
            let (h_try, t1) = if t_grid < t_stop { (h_grid, t_grid) } else { (t_stop - t, t_stop) };
            let y1 = sys.advance(&y, mode, h_try);
            let mut dy1 = [0.0; N];
            sys.rhs(&y1, mode, &mut dy1);
            stats.rhs_evals += 1;
            (h_try, t1, y1, dy1)
        } else {
            let h_try = match etd {
                Some(_) if t < etd_left_until => h.min(etd_left_until - t),
                Some((g, _)) => h.min(g.next_step(t).1 - t),
                None => h,
            }
            .min(t_stop - t);
            // One trial step; only Dormand–Prince's is checked and its next length chosen.
            let (y1, dy1, err) = take_step(sys, method, mode, &y, &dy, h_try, &mut ws, scale, &mut stats);
            if let Method::Dopri5 { .. } = method {
                if !err.is_finite() || err > 1.0 {
                    stats.rejected += 1;
                    let shrink = if err.is_finite() { (SAFETY * err.powf(-0.2)).max(MIN_SHRINK) } else { MIN_SHRINK };
                    h = h_try * shrink;
                    if h < min_step {
                        return Err(IntegrationError::StepTooSmall {
                            t_s: t,
                            min_step_s: min_step,
                            mode: format!("{mode:?}"),
                        });
                    }
                    continue;
                }
                let grow = if err > 0.0 { (SAFETY * err.powf(-0.2)).min(MAX_GROWTH) } else { MAX_GROWTH };
                h = (h_try * grow).min(h_max);
            }
            (h_try, t + h_try, y1, dy1)
        };
        if y1.iter().any(|v| !v.is_finite()) {
            return Err(IntegrationError::NonFinite { t_s: t + h_try, mode: format!("{mode:?}") });
        }

        // Did a guard fire inside this step?
        let mut g1 = Guards::new();
        sys.guards(&y1, &dy1, mode, &mut g1);
        let mut earliest: Option<(f64, u8)> = None;
        let mut fired_in_etd = false;
        for i in 0..guards.len.min(g1.len) {
            if g1.fired(i, guards.value[i]) {
                if etd_taken.is_some() {
                    // Dormand–Prince takes the span and locates the event in it.
                    fired_in_etd = true;
                    break;
                }
                // On the step's Hermite cubic, or on the exact flow of a linear phase.
                let at = |theta: f64| match grid {
                    Some(_) => sys.advance(&y, mode, theta * h_try),
                    None => hermite(&y, &dy, &y1, &dy1, h_try, theta),
                };
                let theta = locate(sys, mode, at, i, guards.value[i], g1.value[i], &mut stats);
                if earliest.is_none_or(|(th, _)| theta < th) {
                    earliest = Some((theta, g1.id[i]));
                }
            }
        }

        if fired_in_etd {
            stats.rejected += 1;
            sys.etd_discard();
            etd_left_until = t1;
            continue;
        }
        match earliest {
            None => {
                stats.steps += 1;
                stats.exact_steps += u32::from(grid.is_some());
                stats.etd_steps += u32::from(etd_taken.is_some());
                t_stop = obs.on_step(t, &y, &dy, t1, &y1, &dy1, mode).map_or(limits.t_max_s, |ts| ts.max(t1));
                t = t1;
                y = y1;
                dy = dy1;
                guards = g1;
            }
            Some((theta, id)) => {
                // Reach the event exactly with one RK step of the located length.
                let h_ev = theta * h_try;
                let (ye, dye) = if h_ev <= 0.0 {
                    (y, dy)
                } else if grid.is_some() {
                    let ye = sys.advance(&y, mode, h_ev);
                    let mut dye = [0.0; N];
                    sys.rhs(&ye, mode, &mut dye);
                    stats.rhs_evals += 1;
                    (ye, dye)
                } else {
                    let (ye, dye, _) = take_step(sys, method, mode, &y, &dy, h_ev, &mut ws, scale, &mut stats);
                    (ye, dye)
                };
                stats.steps += 1;
                stats.exact_steps += u32::from(grid.is_some());
                t_stop =
                    obs.on_step(t, &y, &dy, t + h_ev, &ye, &dye, mode).map_or(limits.t_max_s, |ts| ts.max(t + h_ev));
                t += h_ev;
                y = ye;
                let from = mode;
                mode = sys.on_event(&mut y, mode, id);
                stats.events += 1;
                if stats.events > limits.max_events {
                    return Err(IntegrationError::Chatter {
                        t_s: t,
                        max_events: limits.max_events,
                        mode: format!("{mode:?}"),
                    });
                }
                sys.rhs(&y, mode, &mut dy);
                stats.rhs_evals += 1;
                obs.on_event(t, &y, from, mode, id);
                guards = Guards::new();
                sys.guards(&y, &dy, mode, &mut guards);
            }
        }
    }
}

#[allow(clippy::needless_range_loop)]
/// Cubic Hermite interpolation of a step at `theta` in [0, 1].
pub fn hermite<const N: usize>(
    y0: &[f64; N],
    dy0: &[f64; N],
    y1: &[f64; N],
    dy1: &[f64; N],
    h: f64,
    theta: f64,
) -> [f64; N] {
    let t2 = theta * theta;
    let t3 = t2 * theta;
    let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
    let h10 = t3 - 2.0 * t2 + theta;
    let h01 = -2.0 * t3 + 3.0 * t2;
    let h11 = t3 - t2;
    let mut out = [0.0; N];
    for i in 0..N {
        out[i] = h00 * y0[i] + h10 * h * dy0[i] + h01 * y1[i] + h11 * h * dy1[i];
    }
    out
}

/// Locate where guard `i` crosses zero within the step (Illinois regula falsi on the state
/// `at` a fraction of the step: the Hermite interpolant, or a linear phase's exact flow).
/// Returns the fraction of the step.
fn locate<const N: usize, S: Hybrid<N>>(
    sys: &S,
    mode: S::Mode,
    at: impl Fn(f64) -> [f64; N],
    i: usize,
    g_start: f64,
    g_end: f64,
    stats: &mut Stats,
) -> f64 {
    let eval = |theta: f64, stats: &mut Stats| {
        let y = at(theta);
        let mut dy = [0.0; N];
        sys.rhs(&y, mode, &mut dy);
        stats.rhs_evals += 1;
        let mut g = Guards::new();
        sys.guards(&y, &dy, mode, &mut g);
        g.value[i]
    };
    let (mut a, mut fa) = (0.0, g_start);
    let (mut b, mut fb) = (1.0, g_end);
    let mut side = 0i8;
    let mut run = 0u8;
    for _ in 0..ROOT_MAX_ITERATIONS {
        if b - a <= ROOT_REL_TOL {
            break;
        }
        let mut c = (a * fb - b * fa) / (fb - fa);
        // A guard flat on one side of its root (a contact force held at zero until a gap
        // closes, then rising at the contact stiffness) keeps the secant on the flat side,
        // and the Illinois halving needs ~100 rounds to undo a 1e40 ratio of the ends:
        // bisect when the same end has been kept `ROOT_STALL` times running.
        if !(c > a && c < b) || run >= ROOT_STALL {
            c = 0.5 * (a + b);
            run = 0;
        }
        let fc = eval(c, stats);
        if fc == 0.0 {
            return c;
        }
        let kept_a = (fc > 0.0) == (fb > 0.0);
        let now = if kept_a { 1 } else { -1 };
        run = if now == side { run + 1 } else { 1 };
        if kept_a {
            b = c;
            fb = fc;
            if side == 1 {
                fa *= 0.5;
            }
        } else {
            a = c;
            fa = fc;
            if side == -1 {
                fb *= 0.5;
            }
        }
        side = now;
    }
    // The far end of the bracket, so that the guard has crossed when the mode switches.
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bouncing-free test system: x'' = -x (harmonic), with a guard on x falling through 0.
    struct Oscillator;

    #[derive(Debug, Clone, Copy, PartialEq)]
    enum M {
        Swing,
        Done,
    }

    impl Hybrid<2> for Oscillator {
        type Mode = M;
        fn rhs(&self, y: &[f64; 2], mode: M, dy: &mut [f64; 2]) {
            if mode == M::Done {
                *dy = [0.0, 0.0];
            } else {
                *dy = [y[1], -y[0]];
            }
        }
        fn guards(&self, y: &[f64; 2], _dy: &[f64; 2], mode: M, out: &mut Guards) {
            if mode == M::Swing {
                out.push(0, y[0], Crossing::Falling);
            }
        }
        fn on_event(&self, _y: &mut [f64; 2], _mode: M, _id: u8) -> M {
            M::Done
        }
        fn max_step(&self) -> f64 {
            0.5
        }
    }

    struct Record(Option<f64>);
    impl Observer<2, M> for Record {
        fn on_step(
            &mut self,
            _: f64,
            _: &[f64; 2],
            _: &[f64; 2],
            t1: f64,
            _: &[f64; 2],
            _: &[f64; 2],
            _: M,
        ) -> Option<f64> {
            let _ = t1;
            self.0.map(|te| te + 1.0)
        }
        fn on_event(&mut self, t: f64, _: &[f64; 2], _: M, _: M, _: u8) {
            self.0 = Some(t);
        }
    }

    fn run(method: Method) -> f64 {
        let mut rec = Record(None);
        let limits = Limits { t_max_s: 10.0, max_events: 10, initial_step_s: 1e-3, max_steps: 1_000_000 };
        // x = cos t starts positive and first falls through zero at t = pi/2.
        integrate(&Oscillator, method, &[1.0, 1.0], [1.0, 0.0], M::Swing, limits, &mut rec).unwrap();
        rec.0.unwrap()
    }

    #[test]
    fn dopri5_locates_the_event_of_a_harmonic_oscillator() {
        let t = run(Method::Dopri5 { rtol: 1e-9 });
        assert!((t - std::f64::consts::FRAC_PI_2).abs() < 1e-8, "{t}");
    }

    /// The same oscillator advanced by its exact flow (a rotation) in steps of 0.3 s (two
    /// grid points of 0.15 s) from 0.1 s, so that no step ends on the event.
    struct ExactOscillator;

    impl Hybrid<2> for ExactOscillator {
        type Mode = M;
        fn rhs(&self, y: &[f64; 2], mode: M, dy: &mut [f64; 2]) {
            Oscillator.rhs(y, mode, dy)
        }
        fn guards(&self, y: &[f64; 2], dy: &[f64; 2], mode: M, out: &mut Guards) {
            Oscillator.guards(y, dy, mode, out)
        }
        fn on_event(&self, y: &mut [f64; 2], mode: M, id: u8) -> M {
            Oscillator.on_event(y, mode, id)
        }
        fn max_step(&self) -> f64 {
            0.5
        }
        fn exact_grid(&self, mode: M) -> Option<Grid> {
            (mode == M::Swing).then_some(Grid { t0_s: 0.1, dt_s: 0.15, points: 2 })
        }
        fn advance(&self, y: &[f64; 2], _mode: M, h: f64) -> [f64; 2] {
            let (s, c) = h.sin_cos();
            [c * y[0] + s * y[1], -s * y[0] + c * y[1]]
        }
    }

    #[test]
    fn the_exact_flow_locates_the_event_on_its_grid() {
        let mut rec = Record(None);
        let limits = Limits { t_max_s: 10.0, max_events: 10, initial_step_s: 1e-3, max_steps: 1_000_000 };
        let stats = integrate(
            &ExactOscillator,
            Method::Dopri5 { rtol: 1e-9 },
            &[1.0, 1.0],
            [1.0, 0.0],
            M::Swing,
            limits,
            &mut rec,
        )
        .unwrap();
        // The root finder's ROOT_REL_TOL of the 0.3 s step on the exact flow: 3e-11 s.
        let t = rec.0.unwrap();
        assert!((t - std::f64::consts::FRAC_PI_2).abs() < 1e-10, "{t}");
        // 0 -> 0.1 -> ... -> 1.3 -> the event at 1.5708: six exact steps, the last to the
        // event; then `Done` is integrated by Dormand–Prince.
        assert_eq!(stats.exact_steps, 6, "{stats:?}");
        assert_eq!(stats.rejected, 0);
    }

    #[test]
    fn a_grid_step_ends_on_the_next_point() {
        let g = Grid { t0_s: 0.1, dt_s: 0.3, points: 2 };
        let (h, t) = g.next_step(0.0);
        assert!((h - 0.1).abs() < 1e-15 && (t - 0.1).abs() < 1e-15, "{h} {t}");
        // On a grid point (as computed, t0 + k dt): a whole step, its length exactly the span.
        assert_eq!(g.next_step(0.1 + 3.0 * 0.3), (g.span_s(), 0.1 + 5.0 * 0.3));
        let (h, t) = g.next_step(0.5);
        assert!((h - 0.2).abs() < 1e-15 && (t - 0.7).abs() < 1e-15, "{h} {t}");
    }

    #[test]
    fn rk4_locates_the_event_of_a_harmonic_oscillator() {
        let t = run(Method::Rk4 { dt_s: 1e-3 });
        assert!((t - std::f64::consts::FRAC_PI_2).abs() < 1e-10, "{t}");
    }

    /// x' = 1 with a guard flat until x = 0.3, then steep: a contact force that switches on
    /// when a gap closes, less a flow load of 1e-30 (a fresh billet's). Regula falsi alone
    /// stays on the flat side; the located instant must be the closure.
    struct Closure;

    impl Hybrid<1> for Closure {
        type Mode = M;
        fn rhs(&self, _y: &[f64; 1], mode: M, dy: &mut [f64; 1]) {
            dy[0] = if mode == M::Swing { 1.0 } else { 0.0 };
        }
        fn guards(&self, y: &[f64; 1], _dy: &[f64; 1], mode: M, out: &mut Guards) {
            if mode == M::Swing {
                out.push(0, 1e9 * (y[0] - 0.3).max(0.0) - 1e-30, Crossing::Rising);
            }
        }
        fn on_event(&self, _y: &mut [f64; 1], _mode: M, _id: u8) -> M {
            M::Done
        }
        fn max_step(&self) -> f64 {
            1.0
        }
    }

    struct At(Option<f64>);
    impl Observer<1, M> for At {
        fn on_step(
            &mut self,
            _: f64,
            _: &[f64; 1],
            _: &[f64; 1],
            _: f64,
            _: &[f64; 1],
            _: &[f64; 1],
            _: M,
        ) -> Option<f64> {
            self.0.map(|te| te + 0.1)
        }
        fn on_event(&mut self, t: f64, _: &[f64; 1], _: M, _: M, _: u8) {
            self.0 = Some(t);
        }
    }

    #[test]
    fn a_guard_flat_on_one_side_is_located_at_its_kink() {
        // One step of 1 s covers the closure at t = 0.3.
        let limits = Limits { t_max_s: 10.0, max_events: 10, initial_step_s: 1.0, max_steps: 1000 };
        let mut at = At(None);
        integrate(&Closure, Method::Dopri5 { rtol: 1e-6 }, &[1.0], [0.0], M::Swing, limits, &mut at).unwrap();
        let t = at.0.unwrap();
        // ROOT_REL_TOL of the 1 s step, and the 1e-30 / 1e9 offset of the root, far below it.
        assert!((t - 0.3).abs() < 1e-9, "{t}");
    }

    #[test]
    fn hermite_reproduces_a_cubic_exactly() {
        // y = t^3 on [1, 2]: y0 = 1, y1 = 8, y'0 = 3, y'1 = 12.
        let y = hermite(&[1.0], &[3.0], &[8.0], &[12.0], 1.0, 0.5);
        assert!((y[0] - 1.5f64.powi(3)).abs() < 1e-14);
    }
}
