//! The Runge–Kutta steps of `integrator`: Dormand–Prince 5(4) with its error norm, and the
//! classical RK4 the tests use as a fixed-step reference. One step each, on the caller's
//! workspace; the driver (step control, events, exact linear phases) is the parent module.

use super::{Hybrid, Method, Stats};

/// One step of `method` of length `h` from `(y, dy)`: the new state, its derivative, and
/// Dormand–Prince's error norm (0 for the fixed-step RK4, which has none).
#[allow(clippy::too_many_arguments)]
pub(super) fn take_step<const N: usize, S: Hybrid<N>>(
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
pub(super) struct Workspace<const N: usize> {
    k: [[f64; N]; 7],
    y_new: [f64; N],
    tmp: [f64; N],
}

impl<const N: usize> Workspace<N> {
    pub(super) fn new() -> Self {
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
