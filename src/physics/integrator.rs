//! Integrator for hybrid (piecewise-smooth) mechanical systems, written for blows.
//!
//! A blow is a sequence of smooth phases (plastic forming, stuck, separated, ...) joined by
//! switching events. General adaptive solvers chatter at the rigid-plastic contact switch
//! (DESIGN.md §2.3); here the system names its phase (`Mode`), each phase is integrated with
//! Dormand–Prince 5(4) under step control, and every switch is located by root finding on
//! the step's cubic Hermite interpolant, then reached exactly with one more RK step before
//! the mode changes. A fixed-step classical RK4 runs through the same driver as the
//! reference the tests compare against.

use std::fmt::Debug;

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

/// Which sign change of a guard counts as its event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Crossing {
    /// From non-positive to strictly positive.
    Rising,
    /// From non-negative to strictly negative.
    Falling,
}

/// The switching functions armed in one mode.
#[derive(Debug, Clone, Copy)]
pub struct Guards {
    pub value: [f64; MAX_GUARDS],
    pub crossing: [Crossing; MAX_GUARDS],
    /// Caller-defined identity of each guard, handed back in `on_event`.
    pub id: [u8; MAX_GUARDS],
    pub len: usize,
}

impl Guards {
    pub fn new() -> Self {
        Guards { value: [0.0; MAX_GUARDS], crossing: [Crossing::Rising; MAX_GUARDS], id: [0; MAX_GUARDS], len: 0 }
    }

    pub fn push(&mut self, id: u8, value: f64, crossing: Crossing) {
        debug_assert!(self.len < MAX_GUARDS);
        self.value[self.len] = value;
        self.crossing[self.len] = crossing;
        self.id[self.len] = id;
        self.len += 1;
    }

    /// A guard fires when the step ends strictly on its triggering side having started on
    /// the other side or exactly at zero. A mode entered at a switch often starts with a
    /// guard at exactly zero (entering `Plastic` from `Stuck`, the relative velocity is 0):
    /// if it then moves the wrong way at once, the mode must end at once.
    fn fired(&self, i: usize, start: f64) -> bool {
        let end = self.value[i];
        match self.crossing[i] {
            Crossing::Rising => start <= 0.0 && end > 0.0,
            Crossing::Falling => start >= 0.0 && end < 0.0,
        }
    }
}

impl Default for Guards {
    fn default() -> Self {
        Self::new()
    }
}

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
        let h_try = h.min(t_stop - t);
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
        if y1.iter().any(|v| !v.is_finite()) {
            return Err(IntegrationError::NonFinite { t_s: t + h_try, mode: format!("{mode:?}") });
        }

        // Did a guard fire inside this step?
        let mut g1 = Guards::new();
        sys.guards(&y1, &dy1, mode, &mut g1);
        let mut earliest: Option<(f64, u8)> = None;
        for i in 0..guards.len.min(g1.len) {
            if g1.fired(i, guards.value[i]) {
                let theta = locate(sys, mode, &y, &dy, &y1, &dy1, h_try, i, guards.value[i], g1.value[i], &mut stats);
                if earliest.is_none_or(|(th, _)| theta < th) {
                    earliest = Some((theta, g1.id[i]));
                }
            }
        }

        match earliest {
            None => {
                stats.steps += 1;
                t_stop =
                    obs.on_step(t, &y, &dy, t + h_try, &y1, &dy1, mode).map_or(limits.t_max_s, |ts| ts.max(t + h_try));
                t += h_try;
                y = y1;
                dy = dy1;
                guards = g1;
            }
            Some((theta, id)) => {
                // Reach the event exactly with one RK step of the located length.
                let h_ev = theta * h_try;
                let (ye, dye) = if h_ev > 0.0 {
                    let (ye, dye, _) = take_step(sys, method, mode, &y, &dy, h_ev, &mut ws, scale, &mut stats);
                    (ye, dye)
                } else {
                    (y, dy)
                };
                stats.steps += 1;
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

/// One step of `method` of length `h` from `(y, dy)`: the new state, its derivative, and
/// Dormand–Prince's error norm (0 for the fixed-step RK4, which has none).
#[allow(clippy::too_many_arguments)]
fn take_step<const N: usize, S: Hybrid<N>>(
    sys: &S,
    method: Method,
    mode: S::Mode,
    y: &[f64; N],
    dy: &[f64; N],
    h: f64,
    ws: &mut Workspace<N>,
    scale: &[f64; N],
    stats: &mut Stats,
) -> ([f64; N], [f64; N], f64) {
    match method {
        Method::Dopri5 { rtol } => {
            let err = dopri5_step(sys, mode, y, dy, h, ws, scale, rtol);
            stats.rhs_evals += 6;
            (ws.y_new, ws.k[6], err)
        }
        Method::Rk4 { .. } => {
            rk4_step(sys, mode, y, dy, h, ws);
            let mut dy1 = [0.0; N];
            sys.rhs(&ws.y_new, mode, &mut dy1);
            stats.rhs_evals += 5;
            (ws.y_new, dy1, 0.0)
        }
    }
}

/// Scratch space of the RK stages.
struct Workspace<const N: usize> {
    k: [[f64; N]; 7],
    y_new: [f64; N],
    tmp: [f64; N],
}

impl<const N: usize> Workspace<N> {
    fn new() -> Self {
        Workspace { k: [[0.0; N]; 7], y_new: [0.0; N], tmp: [0.0; N] }
    }
}

// Dormand–Prince 5(4) tableau (Hairer, Nørsett, Wanner, Table II.5.2).
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const B1: f64 = 35.0 / 384.0;
const B3: f64 = 500.0 / 1113.0;
const B4: f64 = 125.0 / 192.0;
const B5: f64 = -2187.0 / 6784.0;
const B6: f64 = 11.0 / 84.0;
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

// The stage loops index several arrays in step; iterators would hide the tableau.
#[allow(clippy::needless_range_loop)]
/// One Dormand–Prince step of length `h`; leaves the new state in `ws.y_new` and its
/// derivative (FSAL) in `ws.k[6]`. Returns the RMS error norm (≤ 1 accepts).
#[allow(clippy::too_many_arguments)]
fn dopri5_step<const N: usize, S: Hybrid<N>>(
    sys: &S,
    mode: S::Mode,
    y: &[f64; N],
    dy: &[f64; N],
    h: f64,
    ws: &mut Workspace<N>,
    scale: &[f64; N],
    rtol: f64,
) -> f64 {
    ws.k[0] = *dy;
    macro_rules! stage {
        ($dst:expr, $($a:expr => $ki:expr),+) => {{
            for i in 0..N {
                ws.tmp[i] = y[i] + h * (0.0 $(+ $a * ws.k[$ki][i])+);
            }
            let (tmp, k) = (&ws.tmp, &mut ws.k);
            sys.rhs(tmp, mode, &mut k[$dst]);
        }};
    }
    stage!(1, A21 => 0);
    stage!(2, A31 => 0, A32 => 1);
    stage!(3, A41 => 0, A42 => 1, A43 => 2);
    stage!(4, A51 => 0, A52 => 1, A53 => 2, A54 => 3);
    stage!(5, A61 => 0, A62 => 1, A63 => 2, A64 => 3, A65 => 4);
    for i in 0..N {
        ws.y_new[i] =
            y[i] + h * (B1 * ws.k[0][i] + B3 * ws.k[2][i] + B4 * ws.k[3][i] + B5 * ws.k[4][i] + B6 * ws.k[5][i]);
    }
    let (y_new, k) = (&ws.y_new, &mut ws.k);
    sys.rhs(y_new, mode, &mut k[6]);
    let mut sum = 0.0;
    let mut active = 0usize;
    for i in 0..N {
        let e = h
            * (E1 * ws.k[0][i]
                + E3 * ws.k[2][i]
                + E4 * ws.k[3][i]
                + E5 * ws.k[4][i]
                + E6 * ws.k[5][i]
                + E7 * ws.k[6][i]);
        if scale[i].is_finite() {
            let sc = rtol * (scale[i] + y[i].abs().max(ws.y_new[i].abs()));
            sum += (e / sc) * (e / sc);
            active += 1;
        }
    }
    (sum / active.max(1) as f64).sqrt()
}

#[allow(clippy::needless_range_loop)]
/// One classical RK4 step of length `h` into `ws.y_new`.
fn rk4_step<const N: usize, S: Hybrid<N>>(
    sys: &S,
    mode: S::Mode,
    y: &[f64; N],
    dy: &[f64; N],
    h: f64,
    ws: &mut Workspace<N>,
) {
    ws.k[0] = *dy;
    for (stage, c) in [(1usize, 0.5), (2, 0.5), (3, 1.0)] {
        for i in 0..N {
            ws.tmp[i] = y[i] + c * h * ws.k[stage - 1][i];
        }
        let (tmp, k) = (&ws.tmp, &mut ws.k);
        sys.rhs(tmp, mode, &mut k[stage]);
    }
    for i in 0..N {
        ws.y_new[i] = y[i] + h / 6.0 * (ws.k[0][i] + 2.0 * ws.k[1][i] + 2.0 * ws.k[2][i] + ws.k[3][i]);
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

/// Locate where guard `i` crosses zero within the step (Illinois regula falsi on the
/// Hermite interpolant). Returns the fraction of the step.
#[allow(clippy::too_many_arguments)]
fn locate<const N: usize, S: Hybrid<N>>(
    sys: &S,
    mode: S::Mode,
    y0: &[f64; N],
    dy0: &[f64; N],
    y1: &[f64; N],
    dy1: &[f64; N],
    h: f64,
    i: usize,
    g_start: f64,
    g_end: f64,
    stats: &mut Stats,
) -> f64 {
    let eval = |theta: f64, stats: &mut Stats| {
        let y = hermite(y0, dy0, y1, dy1, h, theta);
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
