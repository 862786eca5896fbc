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

    /// A new billet is in the dies: the height tracking and the alert memory start over.
    pub fn new_billet(&mut self) {
        self.estimator.new_billet();
        self.alerts.reset();
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

/// Feeds batches to a pipeline, ending the stream wherever a batch does not continue the
/// previous one (a new triggered capture, a gap, a reconnected link): one rule for every
/// kind of input, live or replayed, so a recording replays as it was processed live.
#[derive(Debug)]
pub struct Feeder {
    pipeline: Pipeline,
    /// Source, device time after the last sample (ns), period (ns).
    last: Option<(String, f64, f64)>,
    samples: u64,
}

impl Feeder {
    pub fn new(pipeline: Pipeline) -> Self {
        Feeder { pipeline, last: None, samples: 0 }
    }

    /// Feed a batch, closing the stream first if it does not continue the last one.
    pub fn push(&mut self, batch: &SampleBatch, out: &mut Vec<PipelineEvent>) {
        if let Some((source, next_ns, period_ns)) = &self.last {
            let jump = (batch.device_time_ns as f64 - next_ns).abs();
            if *source != batch.source || jump > 0.5 * period_ns {
                self.pipeline.end_of_stream(out);
            }
        }
        self.samples += batch.len() as u64;
        self.pipeline.push(batch, out);
        self.last = Some((
            batch.source.clone(),
            batch.device_time_ns as f64 + batch.period_ns * batch.len() as f64,
            batch.period_ns,
        ));
    }

    /// Samples fed so far.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    pub fn pipeline_mut(&mut self) -> &mut Pipeline {
        &mut self.pipeline
    }
}
