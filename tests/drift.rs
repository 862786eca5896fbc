//! Drift alarms (issue 44) on rendered sessions: billets forged by the simulator with their
//! own scatter (flow stress ±3 %, friction ±10 %, one sd, drawn per billet), through the
//! live pipeline at 20 kHz, into the drift detector with its defaults (100 reference
//! billets, k = 0.5, h = 11; chosen on synthetic scores in `alert::drift`'s tests, not on
//! these sessions, seeds 4400–4402):
//!
//! - no drift, 100 + 300 billets: no alarm;
//! - friction rising from the sheet's μ to twice it over 200 billets (lubrication drying);
//! - flow stress rising by 25 % over 200 billets (billets coming in about 60 K colder).
//!
//! Each ramp is found, and the test prints after how many billets of it and what the alarm
//! says (when written: friction after 40 ramp billets, travel −0.07 mm a blow; flow stress
//! after 44, plastic energy +43 J a blow, travel −0.25 mm after 51); both name colder
//! billets or lubrication drying, which less travel at the same energy cannot tell apart.

mod common;

use forgemon::alert::drift::{Direction, Drift, DriftAlarm, DriftConfig, Quantity};
use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::EffectSet;
use forgemon::pipeline::{Feeder, Pipeline, PipelineConfig, PipelineEvent};
use forgemon::simdevice::{BilletPlan, SimMachine};
use forgemon::synth::{CaptureSpec, rows_batch};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

const REFERENCE: usize = 100;
const V0S: [f64; 5] = [3.9, 5.3, 5.3, 5.3, 5.3];

/// The session's billets: `billets` after the reference's, `ramp(i)` the (friction, flow
/// stress) factors of the i-th of them (0 before the ramp), each billet with its own scatter.
fn plans(seed: u64, billets: usize, ramp: impl Fn(f64) -> (f64, f64)) -> Vec<BilletPlan> {
    let steel = parse_process("p", &common::read("config/steel-16NiCrMo13.process.toml")).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    (0..REFERENCE + billets)
        .map(|i| {
            let along = i.saturating_sub(REFERENCE) as f64 / billets as f64;
            let (mu, sigma) = if i < REFERENCE { (1.0, 1.0) } else { ramp(along) };
            let mut p = common::with_flow_stress(steel.clone(), sigma * (1.0 + 0.03 * normal.sample(&mut rng)));
            p.friction *= mu * (1.0 + 0.10 * normal.sample(&mut rng));
            BilletPlan { process: p, v0s_mps: V0S.to_vec() }
        })
        .collect()
}

/// The alarms of a session, each with the billet it came on (from 1).
fn session(seed: u64, plans: Vec<BilletPlan>) -> Vec<DriftAlarm> {
    let machine = parse_machine("m", &common::read("config/hammer-lg1000.machine.toml")).unwrap().machine;
    let steel = parse_process("p", &common::read("config/steel-16NiCrMo13.process.toml")).unwrap();
    let capture = CaptureSpec { sample_rate_hz: 20e3, ..CaptureSpec::hammer(seed) };
    let mut sim = SimMachine::new(machine, EffectSet::NONE, plans, capture, 0.25);
    let mut feeder = Feeder::new(Pipeline::new(machine, Some(steel), PipelineConfig::for_machine(&machine)));
    let mut drift = Drift::new(DriftConfig::default());
    let (mut events, mut alarms, mut n, mut billets) = (Vec::new(), Vec::new(), 0i64, 0i64);
    let mut take = |events: &mut Vec<PipelineEvent>, drift: &mut Drift, alarms: &mut Vec<DriftAlarm>| {
        for e in events.drain(..) {
            match e {
                PipelineEvent::Blow { estimate, .. } => drift.on_blow(&estimate),
                PipelineEvent::Billet(b) => {
                    billets += 1;
                    alarms.extend(drift.on_billet(&b, billets * 60_000_000_000));
                }
                PipelineEvent::Rejected { .. } => {}
            }
        }
    };
    while !sim.finished() {
        let billet = sim.billet_of_emitted();
        let rows = sim.next_rows(100).unwrap();
        if billet > 0 && sim.billet_of_emitted() > billet {
            feeder.pipeline_mut().new_billet(&mut events);
        }
        let batch = rows_batch("daq", 0, n * 50_000, 50_000.0, &rows);
        n += rows.len() as i64;
        feeder.push(&batch, &mut events);
        take(&mut events, &mut drift, &mut alarms);
    }
    feeder.pipeline_mut().end_of_stream(&mut events);
    feeder.pipeline_mut().close_billet(&mut events);
    take(&mut events, &mut drift, &mut alarms);
    assert!(drift.watching(), "the reference was learnt");
    alarms
}

fn show(what: &str, alarms: &[DriftAlarm]) {
    for a in alarms {
        eprintln!(
            "{what}: billet {} (ramp billet {}): {}",
            a.at_billet,
            a.at_billet as i64 - REFERENCE as i64,
            a.reason
        );
    }
}

#[test]
fn a_session_without_drift_raises_no_alarm() {
    let alarms = session(4400, plans(4400, 300, |_| (1.0, 1.0)));
    show("no drift", &alarms);
    assert!(alarms.is_empty(), "{alarms:?}");
}

#[test]
fn lubrication_drying_over_200_billets_is_found() {
    let alarms = session(4401, plans(4401, 200, |x| (1.0 + x, 1.0)));
    show("friction x1 -> x2", &alarms);
    let first = alarms.first().expect("an alarm");
    assert!(first.at_billet as usize > REFERENCE, "not before the ramp: {first:?}");
    assert!(first.since_billet as usize >= REFERENCE - 10, "its start on the ramp, not long before: {first:?}");
    assert!(first.reason.contains("lubrication drying"), "{}", first.reason);
}

#[test]
fn colder_billets_over_200_billets_are_found_and_named() {
    let alarms = session(4402, plans(4402, 200, |x| (1.0, 1.0 + 0.25 * x)));
    show("flow stress x1 -> x1.25", &alarms);
    let first = alarms.first().expect("an alarm");
    assert!(first.at_billet as usize > REFERENCE, "not before the ramp: {first:?}");
    let travel = alarms.iter().find(|a| a.quantity == Quantity::Travel).expect("travel drifts");
    assert_eq!(travel.direction, Direction::Down, "{travel:?}");
    assert!(travel.reason.contains("colder billets"), "{}", travel.reason);
}
