//! No false blows (issue #3): ten minutes of samples in which nothing strikes (sensor noise
//! alone, and a ram that moves, reverses and is even braked hard without touching anything)
//! give zero blows. Fed straight through the live pipeline in memory: at 100 kHz a CSV of
//! ten minutes would be 2 GB.

use forgemon::config::parse_machine;
use forgemon::pipeline::{Pipeline, PipelineConfig, PipelineEvent};
use forgemon::signal::sample::{Role, SampleBatch};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

const TEN_MINUTES_S: f64 = 600.0;

/// Run `seconds` of samples at `rate_hz` through the pipeline; `motion(t)` gives the ram's
/// (position m, acceleration m/s²) without noise. Returns the events and the pipeline.
fn run(
    machine_toml: &str,
    rate_hz: f64,
    load_sd: f64,
    acc_sd: f64,
    motion: impl Fn(f64) -> (f64, f64),
) -> (Vec<PipelineEvent>, Pipeline) {
    let machine = parse_machine("machine.toml", machine_toml).unwrap().machine;
    let mut p = Pipeline::new(machine, None, PipelineConfig::for_machine(&machine));
    let mut rng = StdRng::seed_from_u64(5);
    let (ln, an) = (Normal::new(0.0, load_sd).unwrap(), Normal::new(0.0, acc_sd).unwrap());
    let batch_n = (rate_hz * 0.05) as usize;
    let period_ns = 1e9 / rate_hz;
    let mut events = Vec::new();
    let total = (TEN_MINUTES_S * rate_hz) as usize;
    let mut values = Vec::with_capacity(batch_n * 3);
    for (seq, start) in (0..total).step_by(batch_n).enumerate() {
        values.clear();
        for k in start..start + batch_n {
            let t = k as f64 / rate_hz;
            let (x, a) = motion(t);
            values.extend_from_slice(&[ln.sample(&mut rng), (x / 10e-6).round() * 10e-6, a + an.sample(&mut rng)]);
        }
        let b = SampleBatch {
            source: "daq".into(),
            seq: seq as u64,
            device_time_ns: (start as f64 * period_ns) as i64,
            host_time_ns: (start as f64 * period_ns) as i64,
            period_ns,
            roles: vec![Role::Load, Role::Disp, Role::Acc],
            values: values.clone(),
        };
        p.push(&b, &mut events);
    }
    p.end_of_stream(&mut events);
    (events, p)
}

#[test]
fn ten_minutes_of_a_hammer_that_never_strikes() {
    let hammer = include_str!("../config/hammer-lg1000.machine.toml");
    // Noise alone: 2 kN load, 2 m/s² accelerometer (the synthetic capture's levels).
    let (events, p) = run(hammer, 100e3, 2e3, 2.0, |_| (0.5, 0.0));
    assert!(events.is_empty(), "{} blows from noise", events.len());
    assert_eq!(p.segment_stats().samples, 60_000_000);
    // A ram lifted and dropped every 6 s, caught by its brake at 300 m/s² for 5 ms (above
    // the 100 m/s² trigger), never touching the billet: the load never confirms a contact.
    let motion = |t: f64| {
        let phase = t % 6.0;
        let a = if phase < 1.0 {
            -3.0
        } else if phase < 2.0 {
            9.81
        } else if (2.0..2.005).contains(&phase) {
            -300.0
        } else {
            0.0
        };
        (0.5 + 0.3 * (phase / 6.0), a)
    };
    let (events, p) = run(hammer, 100e3, 2e3, 2.0, motion);
    assert!(events.is_empty(), "{} blows from a ram that never struck", events.len());
    let s = p.segment_stats();
    assert_eq!(s.blows, 0);
    assert_eq!(s.triggers_without_contact, 100, "every brake event triggered and was dropped: {s:?}");
}

#[test]
fn ten_minutes_of_a_press_that_never_strikes() {
    let press = include_str!("../config/screw-press-spr400.machine.toml");
    // 5 kN load noise, 0.05 m/s² accelerometer; the ram strokes down and up at 0.35 m/s,
    // reversing at 3.5 m/s² (above the 1 m/s² trigger) without reaching the billet.
    let motion = |t: f64| {
        let phase = t % 4.0;
        let a = if (1.9..2.1).contains(&phase) { -3.5 } else { 0.0 };
        let x = if phase < 2.0 { 0.35 * phase } else { 0.35 * (4.0 - phase) };
        (x, a)
    };
    let (events, p) = run(press, 20e3, 5e3, 0.05, motion);
    assert!(events.is_empty(), "{} blows from a press that never struck", events.len());
    assert_eq!(p.segment_stats().triggers_without_contact, 150);
}
