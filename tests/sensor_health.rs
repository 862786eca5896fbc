//! Sensor health through the live pipeline (issue 16): the per-blow `sensor_check` (the load
//! sensor's impulse against the momentum the accelerometer and the model say the machine
//! lost) and the `sensor` alert, on simulated sessions of the paper hammer (LG1000, steel)
//! and the paper press (SPR 400, copper) rendered by `forgemon::simdevice` with the DAQ
//! model of `forgemon::synth`, at 5, 20 and 100 kHz. Faults are put into the rendered
//! samples as a DAQ would show them: a load gain 10 % high, a charge amplifier whose offset
//! drifts faster and faster.

mod common;

use forgemon::alert::AlertKind;
use forgemon::estimate::BlowEstimate;
use forgemon::physics::{EffectSet, Machine, Process};
use forgemon::pipeline::{Feeder, Pipeline, PipelineConfig};
use forgemon::signal::capture::CaptureRow;
use forgemon::simdevice::{BilletPlan, SimMachine};
use forgemon::synth::{CaptureSpec, rows_batch};

/// The noise seeds the default bound was tuned on (`AlertConfig::DEFAULT_SENSOR_LIMIT`);
/// the tests below run on other seeds.
const TUNING_SEEDS: [u64; 3] = [101, 102, 103];

/// The rates of issue 16's table that the bound covers, Hz.
const RATES_HZ: [f64; 3] = [5e3, 20e3, 100e3];

fn hammer() -> Machine {
    common::machine("hammer-lg1000.machine.toml")
}
fn press() -> Machine {
    common::machine("screw-press-spr400.machine.toml")
}
fn steel() -> Process {
    common::process("steel-16NiCrMo13.process.toml")
}
fn copper() -> Process {
    common::process("copper-cu99.process.toml")
}

/// A session and its machine: the hammer forges four steel billets with two blows each
/// (3.9 then 5.3 m/s: soft blows, so no elastic-blow alert hides a sensor alert); the press
/// forges the paper's copper billet, ten blows at 0.346 m/s (seed 001 §3.2).
struct Session {
    machine: Machine,
    plans: Vec<BilletPlan>,
    spec: CaptureSpec,
    interval_s: f64,
}

fn hammer_session(rate_hz: f64, seed: u64, billets: usize) -> Session {
    let plan = BilletPlan { process: steel(), v0s_mps: vec![3.9, 5.3] };
    let spec = CaptureSpec { sample_rate_hz: rate_hz, ..CaptureSpec::hammer(seed) };
    Session { machine: hammer(), plans: vec![plan; billets], spec, interval_s: 0.4 }
}

fn press_session(rate_hz: f64, seed: u64) -> Session {
    let plan = BilletPlan { process: copper(), v0s_mps: vec![0.346; 10] };
    let spec = CaptureSpec { sample_rate_hz: rate_hz, ..CaptureSpec::press(seed) };
    Session { machine: press(), plans: vec![plan], spec, interval_s: 0.6 }
}

/// The session's samples, on one clock from 0.
fn render(s: &Session) -> Vec<CaptureRow> {
    let mut sim = SimMachine::new(s.machine, EffectSet::NONE, s.plans.clone(), s.spec, s.interval_s);
    let mut rows = Vec::new();
    loop {
        let chunk = sim.next_rows(50_000).expect("simulates");
        if chunk.is_empty() {
            break;
        }
        rows.extend(chunk);
    }
    rows
}

/// Run `rows` through the live pipeline in 1 ms batches (with the process sheet); every
/// blow's estimate.
fn run(machine: &Machine, process: &Process, rate_hz: f64, rows: &[CaptureRow]) -> Vec<BlowEstimate> {
    let period_ns = 1e9 / rate_hz;
    let per_batch = ((rate_hz * 1e-3).round() as usize).max(1);
    let mut feeder = Feeder::new(Pipeline::new(*machine, Some(process.clone()), PipelineConfig::for_machine(machine)));
    let mut events = Vec::new();
    for (i, chunk) in rows.chunks(per_batch).enumerate() {
        let t0_ns = (i as f64 * per_batch as f64 * period_ns).round() as i64;
        feeder.push(&rows_batch("daq", i as u64, t0_ns, period_ns, chunk), &mut events);
    }
    feeder.pipeline_mut().end_of_stream(&mut events);
    common::estimates(&events)
}

fn checks(blows: &[BlowEstimate]) -> Vec<f64> {
    blows.iter().map(|b| b.sensor_check.expect("a complete blow has a sensor check")).collect()
}

/// How the default bound was measured: `sensor_check` of every healthy blow on the tuning
/// seeds, per machine and rate. Run with
/// `cargo nextest run --release --run-ignored only sensor_check_spread --no-capture`.
#[test]
#[ignore = "measurement for the default bound, prints a table"]
fn sensor_check_spread_on_the_tuning_seeds() {
    for kind in ["hammer", "press"] {
        for rate in RATES_HZ {
            let mut all = Vec::new();
            for seed in TUNING_SEEDS {
                let s = if kind == "hammer" { hammer_session(rate, seed, 4) } else { press_session(rate, seed) };
                let process = s.plans[0].process.clone();
                let blows = run(&s.machine, &process, rate, &render(&s));
                all.extend(checks(&blows));
            }
            let n = all.len() as f64;
            let mean = all.iter().sum::<f64>() / n;
            let sd = (all.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let max = all.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            println!("{kind} {:>6.0} Hz: n {n} mean {mean:+.4} sd {sd:.4} max|x| {max:.4}", rate);
        }
    }
}

/// Seeds of the tests: not the tuning seeds.
const TEST_SEEDS: [u64; 2] = [7, 8];

fn sensor_alerts(blows: &[BlowEstimate]) -> Vec<u32> {
    blows.iter().filter(|b| b.alert.as_ref().is_some_and(|a| a.kind == AlertKind::Sensor)).map(|b| b.blow).collect()
}

/// (a) Healthy blows on seeds the bound was not tuned on, at every rate and on both
/// machines: every |sensor_check| within the default bound, and no `sensor` alert.
#[test]
fn healthy_blows_pass_the_sensor_check_at_every_rate() {
    let limit = forgemon::alert::AlertConfig::DEFAULT_SENSOR_LIMIT;
    for rate in RATES_HZ {
        for seed in TEST_SEEDS {
            for s in [hammer_session(rate, seed, 2), press_session(rate, seed)] {
                let process = s.plans[0].process.clone();
                let blows = run(&s.machine, &process, rate, &render(&s));
                let n_planned: usize = s.plans.iter().map(|p| p.v0s_mps.len()).sum();
                assert_eq!(blows.len(), n_planned, "{rate} Hz seed {seed}");
                for (b, x) in blows.iter().zip(checks(&blows)) {
                    assert!(x.abs() < limit, "{rate} Hz seed {seed} blow {}: sensor_check {x}", b.blow);
                }
                let ex: Vec<_> = blows.iter().map(|b| (b.blow, b.sensor_check, b.acc_check, &b.excluded)).collect();
                assert_eq!(sensor_alerts(&blows), Vec::<u32>::new(), "{rate} Hz seed {seed}: {ex:?}");
            }
        }
    }
}

/// (b) The load channel's gain 10 % high in the config (every load sample, its offset too,
/// scaled by 1.1): `sensor_check` = 1.1 (1 + healthy) − 1, so 0.10 within 1.1 × the healthy
/// spread at the rate; at 20 kHz the tuning seeds' largest |sensor_check| was 0.0014
/// (`DEFAULT_SENSOR_LIMIT`'s doc), doubled for other seeds: 0.1 ± 0.003. The accelerometer
/// and the encoder agree, so the load is left out from the first blow on (issue 43), and
/// that blow raises the one sensor alert, naming it; each blow's efficiency is then within
/// issue 43's 0.03 of the healthy run's.
#[test]
fn a_load_gain_ten_percent_high_reads_plus_ten_percent_and_is_left_out() {
    let rate = 20e3;
    let s = hammer_session(rate, TEST_SEEDS[0], 4);
    let healthy_rows = render(&s);
    let mut rows = healthy_rows.clone();
    for r in &mut rows {
        r.load_n *= 1.1;
    }
    let blows = run(&s.machine, &s.plans[0].process, rate, &rows);
    let healthy = run(&s.machine, &s.plans[0].process, rate, &healthy_rows);
    assert_eq!(blows.len(), 8);
    for ((b, x), h) in blows.iter().zip(checks(&blows)).zip(&healthy) {
        assert!((x - 0.1).abs() < 0.003, "blow {}: sensor_check {x}", b.blow);
        assert_eq!(b.excluded.keys().collect::<Vec<_>>(), ["load"], "blow {}", b.blow);
        let (e, want) = (b.efficiency.expect("efficiency"), h.efficiency.expect("healthy efficiency"));
        assert!((e - want).abs() < 0.03, "blow {}: efficiency {e} against {want} healthy", b.blow);
    }
    assert_eq!(sensor_alerts(&blows), vec![1]);
    let a = blows[0].alert.as_ref().expect("alert");
    assert!(a.reason.contains("the load channel") && a.reason.contains("+10."), "{}", a.reason);
}

/// The charge amplifier's offset drifting ever faster (`offset = q t² / 2`, t from the
/// session's start): each blow's zero (the pre-trigger mean) removes the offset's level,
/// not its rise during the blow, which grows with t blow by blow.
const DRIFT_Q_N_PER_S2: f64 = 1e5;

fn drift_n(t_s: f64) -> f64 {
    0.5 * DRIFT_Q_N_PER_S2 * t_s * t_s
}

/// (c) A slowly drifting load offset: the check's shift from the healthy run (same seed)
/// grows blow by blow and is what the added drift predicts (its area over the blow above
/// its level in the pre-trigger window, over the healthy load's area, both summed from the
/// rendered samples, not by the estimator). From the first blow whose check passes
/// `faults::LOAD_LIMIT` (2 %) the load is left out, the accelerometer and the encoder
/// agreeing (issue 43): that blow raises the one sensor alert, naming the load, and none
/// comes before it.
#[test]
fn a_drifting_load_offset_alerts_once_it_passes_the_bound_and_not_before() {
    let rate = 20e3;
    let dt = 1.0 / rate;
    let s = hammer_session(rate, TEST_SEEDS[1], 8);
    let healthy_rows = render(&s);
    let mut rows = healthy_rows.clone();
    for (i, r) in rows.iter_mut().enumerate() {
        r.load_n += drift_n(i as f64 * dt);
    }
    let healthy = run(&s.machine, &s.plans[0].process, rate, &healthy_rows);
    let drifted = run(&s.machine, &s.plans[0].process, rate, &rows);
    assert_eq!(drifted.len(), healthy.len());
    let pre = forgemon::signal::segment::SegmentConfig::HAMMER.pre_trigger_s;
    let limit = forgemon::estimate::faults::LOAD_LIMIT;
    let mut predicted = Vec::new();
    for (h, d) in healthy.iter().zip(&drifted) {
        if !d.is_complete() {
            // The last blow: the recording ends while the drift holds the load above the
            // end level, so the blow is cut short, incomplete, and has no check.
            assert_eq!((d.blow as usize, d.sensor_check), (drifted.len(), None));
            predicted.push(f64::NAN);
            continue;
        }
        let (xh, xd) = (h.sensor_check.expect("healthy check"), d.sensor_check.expect("complete blow's check"));
        let shift = xd - xh;
        // Sample indices of the blow's window (device time counts samples from 0).
        let i0 = (d.t_contact_s / dt).round() as usize - 1;
        let i1 = (d.t_end_s / dt).round() as usize;
        // The segmenter's zero: the mean over the first half of the pre-trigger window (the
        // trigger is within a sample or two of contact on the hammer).
        let zero_window = i0.saturating_sub((pre / dt) as usize)..i0.saturating_sub((pre / dt / 2.0) as usize);
        let mean = |f: &dyn Fn(usize) -> f64| zero_window.clone().map(f).sum::<f64>() / zero_window.len() as f64;
        let zero = mean(&|i| drift_n(i as f64 * dt));
        let load_zero = mean(&|i| healthy_rows[i].load_n);
        let area = |f: &dyn Fn(usize) -> f64| (i0..i1).map(|i| 0.5 * (f(i) + f(i + 1)) * dt).sum::<f64>();
        let extra = area(&|i| drift_n(i as f64 * dt) - zero);
        let load = area(&|i| healthy_rows[i].load_n - load_zero);
        let want = extra / load;
        // 5 % while the blow ends on its own: the trigger is a sample or two off the
        // contact this window is placed by, which moves the zero's window along the drift
        // by that much. 20 % once the drift holds the zeroed load above the segmenter's
        // 10 kN end level (`SegmentConfig::HAMMER`) so that the blow runs to its 0.1 s
        // maximum: then the drift also moves the walk-back to contact (at 5 kN).
        let ran_to_max = d.t_end_s - d.t_contact_s > 0.9 * forgemon::signal::segment::SegmentConfig::HAMMER.max_blow_s;
        let tol = if ran_to_max { 0.20 } else { 0.05 };
        assert!(shift > 0.0 && (shift - want).abs() < tol * want, "blow {}: shift {shift}, predicted {want}", d.blow);
        predicted.push(xh + want);
    }
    let first_over = predicted.iter().position(|x| x.abs() > limit).expect("the drift passes the bound") as u32 + 1;
    let checked: Vec<_> =
        drifted.iter().map(|d| (d.blow, d.sensor_check, d.excluded.keys().collect::<Vec<_>>())).collect();
    assert_eq!(sensor_alerts(&drifted), vec![first_over], "checks and exclusions: {checked:?}");
    let alert = drifted[first_over as usize - 1].alert.as_ref().expect("the alert");
    assert!(alert.reason.contains("the load channel"), "{}", alert.reason);
    for d in drifted.iter().filter(|d| d.is_complete()) {
        assert_eq!(d.excluded.contains_key("load"), d.blow >= first_over, "blow {}: {checked:?}", d.blow);
    }
    // On this session the drift passes the limit on blow 5; the test means something only
    // if the first blows are below it.
    assert!(first_over > 2, "the drift passes the limit on blow {first_over}");
}

/// (d) A dead accelerometer (a flat channel): the hammer's blows are triggered by the ram's
/// deceleration, so no blow is cut and nothing is estimated or alerted: the dead channel
/// shows in the source's health, not in `sensor_check`. (Within a blow that was cut, a flat
/// accelerometer gives `sensor_check` null, which the alert counts as a failed check:
/// `estimate::sensor` and `alert` unit tests.)
#[test]
fn a_flat_accelerometer_cuts_no_blows() {
    let rate = 20e3;
    let s = hammer_session(rate, TEST_SEEDS[0], 1);
    let mut rows = render(&s);
    for r in &mut rows {
        r.acc_mps2 = 0.0;
    }
    let blows = run(&s.machine, &s.plans[0].process, rate, &rows);
    assert!(blows.is_empty(), "{} blows", blows.len());
}
