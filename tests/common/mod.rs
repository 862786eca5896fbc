//! Helpers shared by the integration tests (each test file that uses them says `mod common;`).

#![allow(dead_code)]

use forgemon::acquire::SourceEvent;
use forgemon::estimate::BlowEstimate;
use forgemon::pipeline::{Pipeline, PipelineEvent};

/// Decoded source events through `p`, a gap ending the stream (the service instead bridges
/// short holes by device time, `pipeline::Feeder`, tested in `tests/service_faults.rs`):
/// the blows, every one of which must have been estimated.
pub fn blows_through(mut p: Pipeline, events: &[SourceEvent]) -> Vec<BlowEstimate> {
    let mut out = Vec::new();
    for e in events {
        match e {
            SourceEvent::Batch(b) => p.push(b, &mut out),
            SourceEvent::Gap(_) => p.end_of_stream(&mut out),
            SourceEvent::Status(_) => {}
        }
    }
    p.end_of_stream(&mut out);
    out.into_iter()
        .filter_map(|e| match e {
            PipelineEvent::Blow { estimate, .. } => Some(*estimate),
            PipelineEvent::Billet(_) => None,
            PipelineEvent::Rejected { cut, error } => panic!("blow at {} rejected: {error}", cut.t_contact_s),
        })
        .collect()
}
