//! The sensing modes (issue 43): which channels a blow's estimate used, and the error model
//! of its efficiency in that mode.
//!
//! | mode | channels | impact speed | energies |
//! |---|---|---|---|
//! | full | load, acc, disp | encoder's approach | observer or model fit |
//! | no load | acc, disp | encoder's approach | model fit to the encoder and the ram's deceleration |
//! | no accelerometer | load, disp | encoder's approach, its own curvature | model fit to the encoder and the load |
//!
//! The efficiency's 1σ is the fit's own (`fit::ModelFit::efficiency_sd`: the parameters'
//! covariance from the residuals about the fit) with the part it cannot see added in
//! quadrature: a floor per mode (`efficiency_floor_sd`).

use crate::signal::sample::{Channels, Role};

/// The part of a mode's efficiency error the fit's covariance does not see: the start
/// height's quantisation carried down the encoder's chain, and the contact's placement
/// between samples. It is the root mean square error of the mode's efficiencies over the
/// tuning seeds' blows of `tests/degraded_sensing.rs` (seeds 11–14, 5, 20 and 100 kHz, the
/// hammer's 20 blows and the press's 40 at each), rounded up: in the full mode at most
/// 0.0013 (the press at 5 kHz), without the accelerometer 0.0013 (the press), without the
/// load 0.0010 (the press).
pub fn efficiency_floor_sd(channels: Channels) -> f64 {
    if channels.has(Role::Load) { 0.0015 } else { 0.0012 }
}

/// A blow's efficiency 1σ in its mode from the fit's own, `None` when the fit gave none.
pub fn efficiency_sd(channels: Channels, fit_sd: Option<f64>) -> Option<f64> {
    fit_sd.map(|sd| sd.hypot(efficiency_floor_sd(channels)))
}
