//! A stop (SIGTERM) anywhere between a blow's contact and the end of its ring-down: the blow
//! it cut is `incomplete`, with no energies and no alert, never a whole blow. The stream is a
//! simulated billet (`SimMachine`, the hammer of paper Table 1) fed to the session core as the
//! service feeds it, cut at 60 instants across the third blow, including the instants where
//! the lower tool's ring at impact carries the load under the end level and below zero.

mod common;

use forgemon::physics::EffectSet;
use forgemon::pipeline::{Pipeline, PipelineConfig};
use forgemon::session::{End, Outcome, Session, Stamp};
use forgemon::signal::capture::CaptureRow;
use forgemon::signal::sample::{Role, SampleBatch};
use forgemon::simdevice::{BilletPlan, SimMachine};
use forgemon::synth::CaptureSpec;

const PERIOD_NS: i64 = 10_000;

fn rows() -> Vec<CaptureRow> {
    let plan = BilletPlan { process: common::process("steel-16NiCrMo13.process.toml"), v0s_mps: vec![3.9, 5.3, 5.3] };
    let machine = common::machine("hammer-lg1000.machine.toml");
    let mut sim = SimMachine::new(machine, EffectSet::NONE, vec![plan], CaptureSpec::hammer(41), 0.25);
    let mut rows = Vec::new();
    while !sim.finished() {
        rows.extend(sim.next_rows(25_000).unwrap());
    }
    rows
}

/// The blows a session reports for `rows`, fed in 10 ms batches, then stopped.
fn through_a_session(rows: &[CaptureRow]) -> Vec<forgemon::estimate::BlowEstimate> {
    let machine = common::machine("hammer-lg1000.machine.toml");
    let process = common::process("steel-16NiCrMo13.process.toml");
    let pipeline = Pipeline::new(machine, Some(process), PipelineConfig::for_machine(&machine));
    let mut session = Session::new(pipeline, None, Stamp::DeviceEnd);
    let mut out = Vec::new();
    for (k, chunk) in rows.chunks(1000).enumerate() {
        let t0 = k as i64 * 1000 * PERIOD_NS;
        let batch = SampleBatch {
            source: "daq".into(),
            seq: k as u64,
            device_time_ns: t0,
            host_time_ns: t0,
            period_ns: PERIOD_NS as f64,
            roles: vec![Role::Load, Role::Disp, Role::Acc],
            values: chunk.iter().flat_map(|r| [r.load_n, r.disp_m, r.acc_mps2]).collect(),
        };
        session.batch(&batch, &mut out);
    }
    let _ = session.finish(End::Stopped, rows.len() as i64 * PERIOD_NS, &mut out);
    out.into_iter()
        .filter_map(|o| match o {
            Outcome::Blow { estimate, .. } => Some(*estimate),
            _ => None,
        })
        .collect()
}

#[test]
fn a_stop_anywhere_from_contact_to_the_end_of_the_ring_down_leaves_the_blow_incomplete() {
    let rows = rows();
    let whole = through_a_session(&rows);
    assert_eq!(whole.len(), 3);
    assert!(whole.iter().all(|b| b.efficiency.is_some()), "the uncut billet's blows are whole");
    let third = &whole[2];
    let at = |t: f64| (t / (PERIOD_NS as f64 * 1e-9)).round() as usize;
    let (contact, end) = (at(third.t_contact_s), at(third.t_end_s));
    // The segmenter closes a blow on its own once the load has stayed quiet for its hold
    // time from `t_end_s` on, at sample `end + hold - 1`: the end of the ring-down (hammer:
    // `SegmentConfig::for_kind`). Cuts run from the first sample after contact to the one
    // before that.
    let hold = at(forgemon::signal::segment::SegmentConfig::for_kind(forgemon::physics::MachineKind::Hammer).hold_s);
    let last = end + hold - 2;
    let mut cuts: Vec<usize> = (0..50).map(|i| contact + 1 + (last - contact - 1) * i / 49).collect();
    // Every sample where the impact's ring carries the load below zero, up to ten of them.
    let below_zero: Vec<usize> = (contact..end).filter(|&i| rows[i].load_n < 0.0).take(10).collect();
    assert!(!below_zero.is_empty(), "the impact's ring never carries the load below zero: nothing to cut there");
    cuts.extend(below_zero);
    let mut complete = Vec::new();
    for &cut in &cuts {
        let blows = through_a_session(&rows[..=cut]);
        assert_eq!(blows.len(), 3, "cut at sample {cut}");
        let b = &blows[2];
        if b.class.as_str() != "incomplete" || b.efficiency.is_some() || b.plastic_j.is_some() || b.alert.is_some() {
            complete.push((cut, (cut - contact) as f64 * 1e-2, b.class.as_str()));
        }
    }
    assert!(complete.is_empty(), "cuts (sample, ms after contact, class) reported as whole: {complete:?}");
}
