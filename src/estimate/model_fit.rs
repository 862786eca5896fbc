//! The model fit of one blow, as the estimator runs it (`fit::fit_blow` on a copy decimated
//! to the fit's rate, `decimate`): for its energies where the observer cannot resolve the
//! machine's second mode, and beside the observer as the model check everywhere else. Either
//! way the fit leaves the load it could not explain (`fit::ModelResidual`), the blow's
//! `model_residual`. A method of `Estimator`, after `estimate` has found the impact.

use super::approach::ApproachFit;
use super::{Estimator, decimate, fit};
use crate::signal::sample::Role;
use crate::signal::segment::Blow;

/// Where a blow's model fit starts: the start height, the flow-stress scale, the contact in
/// samples after the segmenter's contact sample, and whether the contact is searched from the
/// encoder's optimum as well (`fit::fit_blow`); and the blow's 1-based index on its billet
/// (the fits before the blow is counted on its billet and after it).
#[derive(Debug, Clone, Copy)]
pub(super) struct FitStart {
    pub h0_m: f64,
    pub scale0: f64,
    pub delta0: f64,
    pub search_contact: bool,
    pub blow_index: usize,
}

impl FitStart {
    pub(super) fn at(h0_m: f64, scale0: f64, delta0: f64, search_contact: bool, blow_index: usize) -> FitStart {
        FitStart { h0_m, scale0, delta0, search_contact, blow_index }
    }
}

impl Estimator {
    /// The model fitted to `blow` from start height `h0_m` (`None`: it could not be, or
    /// its residuals say it did not fit, `fit::MAX_GOOD_RMS`, and the observer takes the
    /// blow). A fit that ran, good or not, leaves its residual in `check`.
    pub(super) fn fit(
        &self,
        blow: &Blow,
        approach: ApproachFit,
        start: FitStart,
        check: &mut Option<fit::ModelResidual>,
    ) -> Option<fit::ModelFit> {
        let FitStart { h0_m, scale0, delta0, search_contact, blow_index } = start;
        let process = self.billet_process.as_ref()?;
        // Above the fit's rate, a decimated copy: contact counts in its coarser samples.
        let f = decimate::factor(blow.period_s);
        let coarse = decimate::decimate(blow, f);
        let effects = self.model_effects();
        let problem = fit::FitProblem {
            machine: &self.machine,
            effects: &effects,
            process,
            blow_index,
            h_start_m: h0_m,
            blow: &coarse,
            daq_period_s: blow.period_s,
            approach,
            channels: blow.channels(),
            // Without an encoder the start height is the sheet's, carried down by the model.
            height_sd_m: (!blow.channels().has(Role::Disp))
                .then_some(super::modes::SHEET_HEIGHT_SD_FRACTION * process.billet.height_m),
        };
        // Above the fit's rate the locator's contact, found in the finer samples, is already
        // within a fraction of a coarse sample: no second start is needed to find the basin
        // (it halved the hammer's 100 kHz latency, 10.8 to 6.4 ms, with the same results on
        // the tuning seeds of `tests/estimate_rates.rs`).
        let search = search_contact && f == 1;
        let mut m = fit::fit_blow(&problem, self.cfg.encoder_resolution_m, scale0, delta0 / f as f64, search).ok()?;
        // The check is the load's own best fit: where the fit to all three channels leaves
        // more than `fit::CONFIRM_RESIDUAL`, the model is fitted to the load and the
        // acceleration alone, and the smaller residual is the blow's.
        let mut residual = m.residual;
        if residual.load > fit::CONFIRM_RESIDUAL
            && problem.channels.has(Role::Disp)
            && let Ok(r) = fit::analogue_residual(&problem, self.cfg.encoder_resolution_m, m.scale, m.contact_samples)
            && r.load < residual.load
        {
            residual = r;
        }
        *check = Some(residual);
        m.contact_samples *= f as f64;
        (m.rms <= fit::MAX_GOOD_RMS).then_some(m)
    }
}
