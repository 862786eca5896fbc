//! The chain after the sample source, the same live and in replay (DESIGN.md §3): samples
//! in, segmented blows estimated with the machine model and judged by the alert rules out.
//! It neither knows nor cares whether the samples come from a port or a file; replaying a
//! recording through it reproduces the live results exactly. Pure code.

use crate::alert::{AlertConfig, AlertRules};
use crate::estimate::{BlowEstimate, EstimateError, Estimator, EstimatorConfig};
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::signal::sample::SampleBatch;
use crate::signal::segment::{Blow, SegmentConfig, SegmentStats, Segmenter};

/// Where the segmenter cut a blow, device times in s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cut {
    pub t_trigger_s: f64,
    pub t_contact_s: f64,
    pub t_end_s: f64,
}

/// What the pipeline reports.
#[derive(Debug, Clone, PartialEq)]
pub enum PipelineEvent {
    /// A blow, estimated; `estimate.alert` holds the alert it raised, if any.
    Blow { cut: Cut, estimate: Box<BlowEstimate> },
    /// A blow was cut but could not be estimated (for example too short an approach).
    Rejected { cut: Cut, error: EstimateError },
}

/// Thresholds of every stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipelineConfig {
    pub segment: SegmentConfig,
    pub estimate: EstimatorConfig,
    pub alerts: AlertConfig,
}

impl PipelineConfig {
    /// Defaults for the machine's kind.
    pub fn for_machine(machine: &Machine) -> Self {
        let kind = machine.kind();
        PipelineConfig {
            segment: SegmentConfig::for_kind(kind),
            estimate: EstimatorConfig::for_kind(kind),
            alerts: AlertConfig::default(),
        }
    }
}

/// Segmenter, estimator and alert rules in a row.
#[derive(Debug)]
pub struct Pipeline {
    segmenter: Segmenter,
    estimator: Estimator,
    alerts: AlertRules,
    cut: Vec<Blow>,
}

impl Pipeline {
    pub fn new(machine: Machine, process: Option<Process>, cfg: PipelineConfig) -> Self {
        Pipeline {
            segmenter: Segmenter::new(cfg.segment),
            estimator: Estimator::new(machine, process, cfg.estimate),
            alerts: AlertRules::new(cfg.alerts),
            cut: Vec::new(),
        }
    }

    /// Feed one batch of samples.
    pub fn push(&mut self, batch: &SampleBatch, out: &mut Vec<PipelineEvent>) {
        self.segmenter.push(batch, &mut self.cut);
        self.drain(out);
    }

    /// The samples stop (end of a triggered capture, end of a file, link lost): a blow in
    /// progress is closed as it stands and the trigger re-arms for the next capture.
    pub fn end_of_stream(&mut self, out: &mut Vec<PipelineEvent>) {
        self.segmenter.finish(&mut self.cut);
        self.drain(out);
    }

    /// New alert thresholds (SIGHUP).
    pub fn set_alert_config(&mut self, cfg: AlertConfig) {
        self.alerts.set_config(cfg);
    }

    pub fn segment_stats(&self) -> SegmentStats {
        self.segmenter.stats()
    }

    fn drain(&mut self, out: &mut Vec<PipelineEvent>) {
        for blow in self.cut.drain(..) {
            let cut = Cut {
                t_trigger_s: blow.samples[blow.i_trigger].t_s,
                t_contact_s: blow.samples[blow.i_contact].t_s,
                t_end_s: blow.samples[blow.i_end].t_s,
            };
            match self.estimator.estimate(&blow) {
                Ok(mut estimate) => {
                    estimate.alert = self.alerts.on_blow(&estimate);
                    out.push(PipelineEvent::Blow { cut, estimate: Box::new(estimate) });
                }
                Err(error) => out.push(PipelineEvent::Rejected { cut, error }),
            }
        }
    }
}
