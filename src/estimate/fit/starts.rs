//! Where a fit without an encoder starts: the impact speed the accelerometer's integral
//! gives through the model, and the best contacts of a grid (`fit_blow`).

use super::{CONTACT_BOUNDS_SAMPLES, CONTACT_BOUNDS_WITHOUT_LOAD_SAMPLES, Params, Residuals, Setup, clamp_u, cost};
use crate::signal::sample::Role;

/// Without an encoder the fit also starts from the best of a grid of contact instants, a
/// sample apart over the contact's bounds, this many of them by their cost at the start's
/// scale and speed. The load's cost has a local minimum per period of the ring: at 5 kHz
/// the hammer's 2 kHz ring spans 2.5 samples, and on the DAQ chain's tuning seed 11 the
/// linear-phase filter's precursors put the segmenter's contact sample 4.5 samples early;
/// from the locator's contact alone the fit ended 2 samples short with a residual of 16
/// (`MAX_GOOD_RMS` is 5).
pub const NO_ENCODER_GRID_STARTS: usize = 2;

/// Rounds of `speed_start`.
const SPEED_START_ROUNDS: usize = 2;

/// Without an encoder, the start's impact speed: the one whose modelled change of the ram's
/// speed over the window matches the accelerometer's, at `u0`'s scale and contact. The
/// impulse alone (`no_encoder::impulse_approach`) also counts the rebound, which on a
/// nearly elastic press blow doubles it: from there the fit found a wrong minimum (the DAQ
/// chain's press, tuning seed 11, 20 and 100 kHz, the last blows: efficiency 0.06 and 0.14
/// off). The model's ratio of the change to the speed carries its rebound.
pub(super) fn speed_start(setup: &Setup<'_>, mut u: Params) -> Params {
    let tau_s = u[1] * setup.p.blow.period_s;
    for _ in 0..SPEED_START_ROUNDS {
        let Ok(e) = setup.eval(u, Residuals::Analogue) else { break };
        let (v0, _) = setup.contact_state(tau_s, u[2]);
        let modelled = e.ram_end_mps - v0;
        let measured = setup.measured_ram_end_mps(tau_s, u[2]) - v0;
        let v1 = measured / modelled * v0;
        if !(v1 > 0.0 && modelled < 0.0) {
            break;
        }
        u = clamp_u([u[0], u[1], u[2] + (v1 / v0).ln(), u[3]], setup.p.channels);
    }
    u
}

/// The `NO_ENCODER_GRID_STARTS` best contacts, a sample apart over the bounds, at `u0`'s
/// scale and speed.
pub(super) fn contact_grid(setup: &Setup<'_>, u0: Params) -> Vec<Params> {
    let (lo, hi) =
        if setup.p.channels.has(Role::Load) { CONTACT_BOUNDS_SAMPLES } else { CONTACT_BOUNDS_WITHOUT_LOAD_SAMPLES };
    let mut graded: Vec<(f64, Params)> = (lo as i64..=hi as i64)
        .map(|d| [u0[0], d as f64, u0[2], u0[3]])
        .filter_map(|u| setup.eval(u, Residuals::Analogue).ok().map(|e| (cost(&e.r), u)))
        .collect();
    graded.sort_by(|a, b| a.0.total_cmp(&b.0));
    graded.into_iter().take(NO_ENCODER_GRID_STARTS).map(|(_, u)| u).collect()
}
