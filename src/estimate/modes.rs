//! The sensing modes (issue 43): which channels a blow's estimate used, and the error model
//! of its efficiency in that mode.
//!
//! | mode | channels | impact speed | energies |
//! |---|---|---|---|
//! | full | load, acc, disp | encoder's approach | observer or model fit |
//! | no load | acc, disp | encoder's approach | model fit to the encoder and the ram's deceleration |
//! | no accelerometer | load, disp | encoder's approach, its own curvature | model fit to the encoder and the load |
//! | no encoder | load, acc | fitted with the model to the load and the accelerometer (`no_encoder`) | the same fit; heights the model's |
//!
//! The efficiency's 1σ is the fit's own (`fit::ModelFit::efficiency_sd`: the parameters'
//! covariance from the residuals about the fit) with the part it cannot see added in
//! quadrature: a floor per mode (`efficiency_floor_sd`).

use super::result::BlowEstimate;
use super::{EstimateError, Estimator};
use crate::signal::sample::{Channels, Role};
use crate::signal::segment::Blow;

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

/// The 1σ of a billet's height about its sheet's, as a fraction of it, that a blow without
/// an encoder carries into its efficiency's 1σ (`fit::efficiency_sd`: the height's 1σ
/// times the efficiency's slope along it, the fitted parameters taking up what they can):
/// billets sawn or sheared to length within ±2 %. The DAQ chain's test billets sit 1.5 %
/// off their sheets (`tests/common/rigs.rs`), and on its hammer that cost the fifth blow
/// 0.014 of efficiency (tuning seeds 11–14, `tests/degraded_sensing.rs`).
pub const SHEET_HEIGHT_SD_FRACTION: f64 = 0.01;

/// A blow's efficiency 1σ in its mode from the fit's own, `None` when the fit gave none.
pub fn efficiency_sd(channels: Channels, fit_sd: Option<f64>) -> Option<f64> {
    fit_sd.map(|sd| sd.hypot(efficiency_floor_sd(channels)))
}

impl Estimator {
    /// Without a load or an accelerometer the energies are the fitted model's or none: a
    /// blow the model could not be fitted to stays unestimated, and says why. Its end is not
    /// known.
    pub(super) fn unfitted(&mut self, e: &mut BlowEstimate) -> Option<f64> {
        let why = format!(
            "only the {} channels, and the model could not be fitted to them (the billet's height is not known, or the fit failed)",
            e.channels.names().join(" and ")
        );
        for field in ["plastic_J", "efficiency"] {
            e.unobserved.insert(field.to_string(), why.clone());
        }
        self.forget_end();
        None
    }

    /// The channels `blow` (which has an encoder: `no_encoder` takes one without) carries,
    /// or why it cannot be estimated with them: without a load the energies come from the
    /// model fitted to the encoder and the accelerometer, without an accelerometer from the
    /// model fitted to the load and the encoder, and either needs a process sheet.
    pub(super) fn channels_of(&self, blow: &Blow) -> Result<Channels, EstimateError> {
        let channels = blow.channels();
        let blow = self.blows;
        if !channels.has(Role::Load) && self.process.is_none() {
            return Err(EstimateError::Unobservable {
                blow,
                reason: "no load channel (load_N): the energies then come from the model fitted to the encoder and the accelerometer, which needs a process sheet (--process, or [process] in the service file)",
            });
        }
        if !channels.has(Role::Acc) && self.process.is_none() {
            return Err(EstimateError::Unobservable {
                blow,
                reason: "no accelerometer channel (acc_mps2): the energies then come from the model fitted to the load and the encoder, which needs a process sheet (--process, or [process] in the service file)",
            });
        }
        Ok(channels)
    }
}
