//! Per-blow estimation with the identified model on measured signals (DESIGN.md §2.4):
//! impact speed from the approach, the model observer's energy terms, the split into
//! plastic and friction work along the billet's tracked height when a process sheet is
//! given, the efficiency class and the energy-balance residual. Pure code.

pub mod approach;
pub mod observer;
pub mod result;

pub use result::{BlowClass, BlowEstimate};

use crate::physics::billet::{BilletLaw, LoadEffects};
use crate::physics::machine::{Machine, MachineKind};
use crate::physics::process::Process;
use crate::signal::segment::Blow;
use approach::{ApproachError, fit_impact_speed};

/// A tracked billet height below this fraction of the sheet's is impossible for an upset
/// cylinder: the billets changed without a new-billet signal, so the height is no longer
/// known (until `new_billet`).
pub const MIN_TRACKED_HEIGHT_FRACTION: f64 = 0.02;

/// Thresholds of the estimator, with the defaults named.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorConfig {
    /// Efficiency at or above which a blow is `soft` (seed 000 §4.3: soft blows 80–90 %).
    pub soft_min: f64,
    /// At or above which it is `intermediate`; below, `hard` (seed 000 §4.3: 20–50 %).
    pub intermediate_min: f64,
    /// Length of the approach window of the impact-speed fit, s.
    pub fit_s: f64,
}

impl EstimatorConfig {
    pub const DEFAULT_SOFT_MIN: f64 = 0.75;
    pub const DEFAULT_INTERMEDIATE_MIN: f64 = 0.50;

    pub fn for_kind(kind: MachineKind) -> Self {
        EstimatorConfig {
            soft_min: Self::DEFAULT_SOFT_MIN,
            intermediate_min: Self::DEFAULT_INTERMEDIATE_MIN,
            // 10 ms of a 4 m/s free fall is 40 mm of travel; 50 ms at 0.35 m/s is 17 mm.
            fit_s: match kind {
                MachineKind::Hammer => 0.010,
                MachineKind::ScrewPress => 0.050,
            },
        }
    }

    pub fn classify(&self, efficiency: f64) -> BlowClass {
        if efficiency >= self.soft_min {
            BlowClass::Soft
        } else if efficiency >= self.intermediate_min {
            BlowClass::Intermediate
        } else {
            BlowClass::Hard
        }
    }
}

/// A blow the estimator could not evaluate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EstimateError {
    #[error("blow {blow}: {source}")]
    Approach {
        blow: u32,
        #[source]
        source: ApproachError,
    },
}

/// Estimates blow after blow, tracking the billet's height from the process sheet.
#[derive(Debug, Clone)]
pub struct Estimator {
    machine: Machine,
    process: Option<Process>,
    cfg: EstimatorConfig,
    /// Billet height before the next blow.
    h_m: Option<f64>,
    blows: u32,
}

impl Estimator {
    pub fn new(machine: Machine, process: Option<Process>, cfg: EstimatorConfig) -> Self {
        let h_m = process.as_ref().map(|p| p.billet.height_m);
        Estimator { machine, process, cfg, h_m, blows: 0 }
    }

    pub fn config(&self) -> &EstimatorConfig {
        &self.cfg
    }

    /// Whether the billet's height is being tracked (a process sheet, and not lost).
    pub fn tracking_height(&self) -> bool {
        self.h_m.is_some()
    }

    /// A new billet from the process sheet: its height starts again from the sheet's.
    pub fn new_billet(&mut self) {
        self.h_m = self.process.as_ref().map(|p| p.billet.height_m);
    }

    /// Estimate the next blow.
    pub fn estimate(&mut self, blow: &Blow) -> Result<BlowEstimate, EstimateError> {
        self.blows += 1;
        let n = self.blows;
        let fit = fit_impact_speed(&blow.samples, blow.i_contact, self.cfg.fit_s, blow.period_s)
            .map_err(|source| EstimateError::Approach { blow: n, source })?;
        let v0 = fit.v_impact_mps;
        let o = observer::observe(&self.machine, blow, v0);
        let max_comp = o.compression_m.iter().copied().fold(0.0, f64::max);
        let (plastic_j, friction_j, h_end_m) = match (&self.process, self.h_m) {
            (Some(p), Some(h0)) => {
                let law =
                    BilletLaw::new(p.billet.clone(), p.material.clone(), p.friction, LoadEffects::NEUTRAL, n as usize);
                let (mut plastic, mut friction) = (0.0, 0.0);
                let mut h_min = h0;
                for (comp, dw) in o.compression_m.iter().zip(&o.work_j) {
                    // The billet only gets flatter: its height is the running minimum.
                    h_min = h_min.min(h0 - comp);
                    let l = law.load(h_min.max(1e-6), 0.0);
                    let share = if l.total_n > 0.0 { l.frictionless_n / l.total_n } else { 1.0 };
                    plastic += dw * share;
                    friction += dw * (1.0 - share);
                }
                let h_end = h0 - max_comp;
                if h_end < MIN_TRACKED_HEIGHT_FRACTION * p.billet.height_m {
                    // Lost track of the billet: report the work unsplit and no height.
                    self.h_m = None;
                    (o.deform_j, None, None)
                } else {
                    self.h_m = Some(h_end);
                    (plastic, Some(friction), Some(h_end))
                }
            }
            _ => (o.deform_j, None, None),
        };
        let efficiency = plastic_j / o.kinetic_in_j;
        let residual = (o.kinetic_in_j - o.deform_j - o.damped_j - o.elastic_j) / o.kinetic_in_j;
        let t_contact_s = blow.samples[blow.i_contact].t_s;
        Ok(BlowEstimate {
            blow: n,
            t_contact_s,
            v_impact_mps: v0,
            kinetic_in_j: o.kinetic_in_j,
            plastic_j,
            friction_j,
            damped_j: o.damped_j,
            elastic_j: o.elastic_j,
            efficiency,
            final_load_n: o.final_load_n,
            h_end_m,
            class: self.cfg.classify(efficiency),
            alert: None,
            t_end_s: blow.samples[blow.i_end].t_s,
            peak_load_n: o.peak_load_n,
            residual,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{parse_machine, parse_process};
    use crate::physics::effects::EffectSet;
    use crate::signal::capture::CaptureReader;
    use crate::signal::segment::{SegmentConfig, Segmenter};
    use crate::synth::{CaptureSpec, synth_blows};

    /// Billets changed without a new-billet signal: the tracked height would go negative.
    /// Past 2 % of the sheet's height the estimator stops reporting one (and the split that
    /// needs it) until `new_billet`, which restores it.
    #[test]
    fn an_impossible_billet_height_is_reported_as_unknown() {
        let m = parse_machine("m", include_str!("../../config/hammer-lg1000.machine.toml")).unwrap().machine;
        let p = parse_process("p", include_str!("../../config/steel-16NiCrMo13.process.toml")).unwrap();
        // Four blows on one billet, estimated as if the sheet were 20 mm high: the tracked
        // height runs out after the first blows.
        let blows = synth_blows(&m, &EffectSet::NONE, &p, &[5.3; 4], &CaptureSpec::hammer(9)).unwrap();
        let mut short = p.clone();
        short.billet.height_m = 0.020;
        let mut est = Estimator::new(m, Some(short), EstimatorConfig::for_kind(m.kind()));
        let mut heights = Vec::new();
        for b in &blows {
            let mut text = Vec::new();
            crate::signal::capture::write_capture(&mut text, &b.rows).unwrap();
            let batches = CaptureReader::new("x", text.as_slice(), 0.05).unwrap().read_all().unwrap();
            let cut = Segmenter::cut_all(SegmentConfig::HAMMER, &batches);
            let e = est.estimate(&cut[0]).unwrap();
            assert!(e.h_end_m.is_none_or(|h| h > 0.0), "{:?}", e.h_end_m);
            heights.push(e.h_end_m);
        }
        assert!(heights.iter().any(|h| h.is_none()), "{heights:?}");
        assert!(!est.tracking_height());
        est.new_billet();
        assert!(est.tracking_height());
    }
}
