//! The third reduced mode (issue 43): a blow without a ram encoder, from the load and the
//! accelerometer.
//!
//! Without an encoder there is no approach parabola, so the impact speed is fitted with the
//! model: the fit (`fit`) takes ln(speed) as a third parameter beside the flow-stress scale
//! and the contact instant, on the load's and the acceleration's residuals alone. Its first
//! guess is the accelerometer's impulse over the blow, `−∫a dt` from contact to the blow's
//! end (`impulse_approach`), which counts the rebound too; the fit's start then takes the
//! rebound through the model (`fit::starts`). The accelerometer's integral fixes the ram's
//! change of speed, and the load's level and duration the flow stress and the speed it
//! stopped from: a rigid-plastic billet under a hammer ram stops it in `m v₀ / F`.
//!
//! Heights come from the model's chain: a billet's first blow starts at the sheet's height,
//! each later blow at the fitted end of the one before (`HeightSource::Model`). A new billet
//! is known by its signal, or by an idle gap longer than `EstimatorConfig::idle_new_billet_s`
//! (there is no contact position to show a taller billet). The end height is the model's,
//! not a measurement, so it is not reported (`h_end_m` is `null`, `unobserved` says why);
//! the next blow on an encoder takes the billet up again from the sheet or the model, its
//! offset unknown.

use super::approach::{ACC_GUARD_SAMPLES, ApproachError, ApproachFit, MIN_FIT_SAMPLES};
use super::billet::BilletCheck;
use super::model_fit::FitStart;
use super::result::{BilletTag, BlowEstimate, HeightSource};
use super::{EstimateError, Estimator, Placed, modes, sensor, started};
use crate::signal::sample::Role;
use crate::signal::segment::Blow;
use std::collections::BTreeMap;

/// Why a whole blow without an encoder is not estimated when the model could not be fitted.
pub const UNFITTED: &str = "no ram encoder channel (disp_m), and the model could not be fitted to the load and the accelerometer (the billet's height is not known since a blow before failed, or the fit failed): the impact speed is not observed";

/// Why a blow without an encoder reports no end height.
pub const END_HEIGHT_UNOBSERVED: &str = "no encoder: the billet's height is the sheet's carried down by the model, not measured (a billet off its sheet's height stays off by as much)";

impl Estimator {
    /// Estimate `blow`, which has no encoder (none configured, or left out: `excluded`).
    pub(super) fn estimate_without_encoder(
        &mut self,
        blow: &Blow,
        excluded: BTreeMap<String, String>,
    ) -> Result<BlowEstimate, EstimateError> {
        let channels = blow.channels();
        let n = self.blows;
        if !channels.has(Role::Load) || !channels.has(Role::Acc) {
            return Err(EstimateError::Unobservable {
                blow: n,
                reason: "no ram encoder channel (disp_m) and only one other: without the encoder the impact speed is fitted to the load and the accelerometer together",
            });
        }
        if self.process.is_none() {
            return Err(EstimateError::Unobservable {
                blow: n,
                reason: "no ram encoder channel (disp_m): the impact speed and the energies then come from the model fitted to the load and the accelerometer, which needs a process sheet (--process, or [process] in the service file)",
            });
        }
        let approach =
            impulse_approach(blow, self.cfg.fit_s).map_err(|source| EstimateError::Approach { blow: n, source })?;
        let placed = self.place_by_time(blow.samples[blow.i_contact].t_s);
        let h_start_m = placed.h_start_m;
        let delta0 = self.locate_contact(blow, approach.v_impact_mps, h_start_m);
        let gap_s = self.gap_s(blow);
        let complete = blow.lost_s == 0.0 && gap_s <= self.max_bridged_s();
        let mut check = None;
        let fitted = match h_start_m {
            Some(h) if complete => {
                self.fit(blow, approach, FitStart::at(h, self.scale, delta0, true, self.billet_blows), &mut check)
            }
            _ => None,
        };
        let delta = fitted.as_ref().map_or(delta0, |f| f.contact_samples);
        let t_contact_s = blow.samples[blow.i_contact].t_s + delta * blow.period_s;
        let v_mps = fitted.as_ref().map_or(approach.at(delta * blow.period_s).v_impact_mps, |f| f.v0_mps);
        let mut e = started(n, blow, (t_contact_s, v_mps), gap_s, &placed);
        e.channels = channels;
        e.excluded = excluded;
        // The encoder's offset is not known to the next blow that has one.
        self.chain = None;
        self.unverified = true;
        if !complete {
            // The impulse of a blow cut short is not the speed it struck at.
            e.v_impact_mps = f64::NAN;
            e.unobserved.insert("v_impact_mps".into(), "no encoder, and the blow is incomplete".into());
            self.h_m = None;
            return Ok(e);
        }
        let tolerance_m = self.contact_tolerance_m(v_mps * blow.period_s);
        let h_end_m = match &fitted {
            Some(f) => {
                self.scale = f.scale;
                e.efficiency_sd = modes::efficiency_sd(channels, f.efficiency_sd);
                let h_end_m = self.fill_from_fit(&mut e, blow, f);
                // The billet's own height is not measured: the model carries the sheet's.
                e.h_end_m = None;
                e.unobserved.insert("h_end_m".into(), END_HEIGHT_UNOBSERVED.into());
                h_end_m
            }
            None => {
                self.forget_end();
                return Err(EstimateError::Unobservable { blow: n, reason: UNFITTED });
            }
        };
        e.model_residual = check.map(|c| c.load);
        e.model_residual_by_phase = check.map(|c| c.load_by_phase);
        e.sensor_check = sensor::sensor_check(&self.machine, blow, e.v_impact_mps).ok();
        self.settle(&mut e, blow, placed.first, tolerance_m, (0.0, h_start_m, h_end_m));
        Ok(e)
    }

    /// The blow's place on its billet without an encoder: a new billet on its signal, or
    /// after an idle gap, else the next blow on the present one, starting at the height the
    /// blow before left (`h_m`). Counts the blow on its billet.
    fn place_by_time(&mut self, t_contact_s: f64) -> Placed {
        let signalled = std::mem::take(&mut self.signalled);
        let idle = self.last_end.is_some_and(|end| t_contact_s - end.t_s > self.cfg.idle_new_billet_s);
        if !signalled && (self.billet == 0 || idle) {
            self.start_billet();
        }
        let mut billet_check = None;
        if self.billet_blows == 0 && self.prev_billet_blows == 1 && self.billet > 1 {
            billet_check = Some(BilletCheck::PreviousBilletOneBlow);
        }
        self.billet_blows += 1;
        let first = self.billet_blows == 1;
        let (h_start_m, height_source) = match self.h_m {
            Some(h) => (Some(h), if first { HeightSource::Sheet } else { self.h_source }),
            None => (None, HeightSource::Unknown),
        };
        let billet = BilletTag {
            billet: self.billet,
            billet_blow: self.billet_blows as u32,
            billet_check,
            h_start_off_sheet_m: None,
        };
        Placed { billet, first, measured: false, taught: false, h_start_m, height_check: None, height_source }
    }
}

/// The approach without an encoder: the accelerometer's mean over the window `fit_s` before
/// contact (less `ACC_GUARD_SAMPLES`, the anti-alias filter's reach), and as the impact
/// speed the impulse `−∫a dt` from the contact sample to the blow's end: the fit's first
/// guess, high by up to the rebound's speed (`fit::LN_SPEED_BOUNDS`). No position:
/// `x_contact_m` is 0.
pub fn impulse_approach(blow: &Blow, fit_s: f64) -> Result<ApproachFit, ApproachError> {
    let end = blow.i_contact.saturating_sub(ACC_GUARD_SAMPLES);
    let start = end.saturating_sub((fit_s / blow.period_s).round() as usize);
    let pre = &blow.samples[start..end];
    if pre.len() < MIN_FIT_SAMPLES {
        return Err(ApproachError::TooShort { found: pre.len(), needed: MIN_FIT_SAMPLES });
    }
    let acc_mps2 = pre.iter().map(|s| s.acc_mps2).sum::<f64>() / pre.len() as f64;
    let blow_samples = &blow.samples[blow.i_contact..=blow.i_end];
    let dv: f64 = blow_samples.windows(2).map(|w| 0.5 * (w[0].acc_mps2 + w[1].acc_mps2)).sum::<f64>() * blow.period_s;
    let v_mps = -dv;
    if v_mps.is_nan() || v_mps <= 0.0 {
        return Err(ApproachError::NotApproaching { v_mps });
    }
    Ok(ApproachFit { v_impact_mps: v_mps, acc_mps2, x_contact_m: 0.0, v_sd_mps: f64::NAN })
}
