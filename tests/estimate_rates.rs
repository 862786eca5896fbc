//! Per-blow energy at every DAQ rate (issue 16): the hammer paper's machine (LG1000, steel,
//! the Table 3 series of blow 1 at 3.9 m/s then 5.3 m/s) and the press paper's (SPR 400,
//! copper, ten blows at 0.346 m/s), rendered by the DAQ chain of `forgemon::daq` (RK4 at a
//! fine fixed step, a linear-phase anti-alias low-pass at 0.4 × the sample rate, decimation,
//! 3 kN load noise, 10 µm encoder steps, the accelerometer's noise, a load offset) and read
//! through the whole pipeline. The truth is off the sheet the estimator is given: the flow
//! stress scaled by a factor it is not told, the billet a little higher or lower.
//!
//! Tolerances (issue 16): efficiency within 0.02 absolute and impact speed within 1 % of
//! the simulator's ledger, both sides, every blow. The end height, with the encoder
//! referenced to the lower die as `daq` renders it (`Encoder::DieReferenced`): its bias
//! (the mean error over a session's blows) within `HEIGHT_BIAS_TOL_M`, every blow within
//! `HEIGHT_BLOW_TOL_M`, and the growth from the first blow to the last within
//! `HEIGHT_GROWTH_TOL_M` (the bias that grew blow by blow).
//!
//! Seeds: the estimator's thresholds (`OBSERVER_MIN_SAMPLES_PER_MODE`, the fit's scales)
//! were tuned on `TUNING_SEEDS` (run `cargo test --release --test estimate_rates -- --ignored
//! --nocapture` for their table); the tests assert on `ASSERT_SEEDS`, never used in tuning.

#[path = "common/rigs.rs"]
mod rigs;

use forgemon::physics::blow::BlowResult;
use forgemon::physics::process::Process;
use forgemon::pipeline::{Pipeline, PipelineConfig, PipelineEvent};
use forgemon::synth::rows_batch;
use rigs::{Rig, machine, render, sheet, truth_process};

/// Issue 16's accuracy target.
const EFFICIENCY_TOL: f64 = 0.02;
const SPEED_REL_TOL: f64 = 0.01;
/// Issue 16: the end height's bias below the encoder's resolution, 10 µm. Measured on the
/// twelve tuning seeds (`tuning_table`, every blow; the DAQ puts first contact at a random
/// point between samples), the bias is within 1.7 µm at every rate on both machines with
/// the die reference (before it, and without it: the hammer at 5 kHz -6.9 µm, the press
/// fitted at 5–10 kHz +9.4 and +10.3 µm; README "The end height").
const HEIGHT_BIAS_TOL_M: f64 = 10e-6;
/// Every blow's end height. With the encoder referenced to the die, a blow's end height
/// rests on two encoder readings: where the ram met the billet (or, for a fitted blow, where
/// it sat in the spring-back) and where the die is. Each reading is quantised to a step
/// q = 10 µm, an error uniform over ±q/2 with sd q/√12 = 2.9 µm that averaging over samples
/// does not remove when the ram moves less than a step between them; two of them give an sd
/// of q/√6 = 4.1 µm, and three sd of it 12.2 µm. (The tuning seeds' blows scatter by
/// 0.9–3.2 µm sd about their bias; the largest error, 10.3 µm, is the press's fifth blow at
/// 5–10 kHz, a systematic miss of the fit's set on that blow, README "The end height".)
const HEIGHT_BLOW_TOL_M: f64 = 3.0 * 10e-6 / 2.449_489_742_783_178;
/// The growth of that error from the first blow to the last. Before the encoder chain the
/// press's end heights grew by 60–100 µm over ten blows, and the hammer's by up to 17 µm
/// over five before the spring-back's set (`estimate::fit`); on the tuning seeds they now
/// move by a few µm, within the encoder's step.
const HEIGHT_GROWTH_TOL_M: f64 = 10e-6;

/// 1601 was the assert seed until the spring-back's set, the accelerometer's guard and the
/// contact's random phase were tuned with it in view; it is a tuning seed since, and 2411
/// asserts. 2411's first run failed the hammer at 5 kHz (34 µm, an accelerometer mean
/// 0.8 m/s² high); that led to the approach's curvature from both sensors
/// (`estimate::approach`), which has no constant to tune, and nothing was tuned on 2411.
/// Seeds 13–21 were added to measure the end height's bias apart from its scatter (issue 16).
const TUNING_SEEDS: [u64; 12] = [11, 12, 1601, 13, 14, 15, 16, 17, 18, 19, 20, 21];
const ASSERT_SEEDS: [u64; 1] = [2411];

/// One blow: the estimate against the truth.
#[derive(Debug)]
struct Row {
    blow: usize,
    efficiency: f64,
    true_efficiency: f64,
    v_rel_err: f64,
    /// End height less the simulated one, less the sheet's start height less the true one.
    h_err_m: Option<f64>,
    /// The located contact less the true one, in ram travel at impact (m): time × speed.
    contact_err_m: f64,
    method: Option<forgemon::estimate::Method>,
}

/// Render the session through the DAQ, run it through the pipeline, compare every blow.
fn run(rig: Rig, rate_hz: f64, seed: u64) -> Vec<Row> {
    run_on(rig, rate_hz, seed, &truth_process(rig), Encoder::DieReferenced)
}

/// What the estimator knows of the encoder's zero.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Encoder {
    /// Nothing: the first billet is taken at its sheet's height, and the end heights are
    /// compared less the sheet's error in it.
    Relative,
    /// Its reading on the lower die (`daq` renders an encoder referenced to the die):
    /// the end heights are compared as they are.
    DieReferenced,
}

/// `run` with the billet and flow stress of `truth`.
fn run_on(rig: Rig, rate_hz: f64, seed: u64, truth_p: &Process, encoder: Encoder) -> Vec<Row> {
    let m = machine(rig);
    let session = render(rig, rate_hz, seed, truth_p);
    let (rows, t_contact_s) = (&session.rows, &session.t_contact_s);
    let period_ns = 1e9 / rate_hz;
    let per_batch = (rate_hz * 0.01) as usize;
    let mut cfg = PipelineConfig::for_machine(&m);
    if encoder == Encoder::DieReferenced {
        cfg.estimate.encoder_at_die_m = Some(forgemon::synth::ENCODER_AT_LOWER_DIE_M);
    }
    let mut p = Pipeline::new(m, Some(sheet(rig)), cfg);
    let mut events = Vec::new();
    for (k, chunk) in rows.chunks(per_batch).enumerate() {
        let t0 = (k * per_batch) as f64 * period_ns;
        p.push(&rows_batch("daq", k as u64, t0 as i64, period_ns, chunk), &mut events);
    }
    p.end_of_stream(&mut events);
    let truth: Vec<&BlowResult> = session.truth.iter().collect();
    // The estimator starts from the sheet's height, which is off the truth's by a height it
    // cannot know; what it must get right is every blow's set after that.
    let start_off_m = match encoder {
        Encoder::Relative => sheet(rig).billet.height_m - truth_p.billet.height_m,
        Encoder::DieReferenced => 0.0,
    };
    assert_eq!(events.len(), truth.len(), "{rig:?} at {rate_hz} Hz: one result per blow");
    events
        .iter()
        .zip(truth)
        .enumerate()
        .map(|(i, (e, t))| {
            let PipelineEvent::Blow { estimate, .. } = e else { panic!("{rig:?} {rate_hz} Hz blow {}: {e:?}", i + 1) };
            Row {
                blow: i + 1,
                efficiency: estimate.efficiency.unwrap_or(f64::NAN),
                true_efficiency: t.efficiency(),
                v_rel_err: estimate.v_impact_mps / t.v0_mps - 1.0,
                h_err_m: estimate.h_end_m.zip(t.forming.map(|f| f.h_end_m)).map(|(a, b)| a - b - start_off_m),
                contact_err_m: (estimate.t_contact_s - t_contact_s[i]) * t.v0_mps,
                method: estimate.method,
            }
        })
        .collect()
}

/// The largest errors over a session's blows: efficiency (absolute), impact speed
/// (relative) and end height (m).
fn worst(rows: &[Row]) -> (f64, f64, f64) {
    let de = rows.iter().map(|r| (r.efficiency - r.true_efficiency).abs()).fold(0.0, f64::max);
    let dv = rows.iter().map(|r| r.v_rel_err.abs()).fold(0.0, f64::max);
    let dh = rows.iter().filter_map(|r| r.h_err_m.map(f64::abs)).fold(0.0, f64::max);
    (de, dv, dh)
}

/// The largest end-height error less the first blow's contact error (m): what an
/// unreferenced encoder's chain adds to the error it carries from the first contact.
fn carried_worst_m(rows: &[Row]) -> f64 {
    let first = rows.first().map_or(f64::NAN, |r| r.contact_err_m);
    rows.iter().filter_map(|r| r.h_err_m.map(|h| (h - first).abs())).fold(0.0, f64::max)
}

fn check(rig: Rig, rate_hz: f64) {
    // The stated rule, blow by blow: the observer where a second-mode period spans at least
    // OBSERVER_MIN_SAMPLES_PER_MODE samples, the model fit below (there is a sheet here).
    use forgemon::estimate::{Method, OBSERVER_MIN_SAMPLES_PER_MODE};
    let per_mode = rate_hz / machine(rig).second_mode_hz();
    let method = if per_mode >= OBSERVER_MIN_SAMPLES_PER_MODE { Method::Observer } else { Method::ModelFit };
    for seed in ASSERT_SEEDS {
        let rows = run(rig, rate_hz, seed);
        let (de, dv, dh) = worst(&rows);
        eprintln!(
            "{rig:?} {} kHz seed {seed}: max |Δeff| {de:.4}, max |Δv|/v {dv:.4}, max |Δh| {:.1} µm",
            rate_hz / 1e3,
            dh * 1e6
        );
        for r in &rows {
            let at = format!("{rig:?} at {} kHz, seed {seed}, blow {}: {r:?}", rate_hz / 1e3, r.blow);
            assert!((r.efficiency - r.true_efficiency).abs() <= EFFICIENCY_TOL, "efficiency: {at}");
            assert!(r.v_rel_err.abs() <= SPEED_REL_TOL, "impact speed: {at}");
            assert_eq!(r.method, Some(method), "method: {at}");
            assert!(r.h_err_m.is_some_and(|h| h.abs() <= HEIGHT_BLOW_TOL_M), "end height: {at}");
        }
        let errs: Vec<f64> = rows.iter().filter_map(|r| r.h_err_m).collect();
        let bias = errs.iter().sum::<f64>() / errs.len().max(1) as f64;
        assert!(bias.abs() <= HEIGHT_BIAS_TOL_M, "{rig:?} {rate_hz} Hz seed {seed}: end-height bias {bias}");
        let first = rows.first().and_then(|r| r.h_err_m).unwrap_or(f64::NAN);
        let last = rows.last().and_then(|r| r.h_err_m).unwrap_or(f64::NAN);
        assert!((last - first).abs() <= HEIGHT_GROWTH_TOL_M, "{rig:?} {rate_hz} Hz: height grew {first} -> {last}");
    }
}

macro_rules! rate_tests {
    ($($name:ident: $rig:expr, $rate:expr;)*) => {$(
        #[test]
        fn $name() {
            check($rig, $rate);
        }
    )*};
}

rate_tests! {
    hammer_at_5_khz: Rig::Hammer, 5e3;
    hammer_at_10_khz: Rig::Hammer, 10e3;
    hammer_at_20_khz: Rig::Hammer, 20e3;
    hammer_at_50_khz: Rig::Hammer, 50e3;
    hammer_at_100_khz: Rig::Hammer, 100e3;
    press_at_5_khz: Rig::Press, 5e3;
    press_at_10_khz: Rig::Press, 10e3;
    press_at_20_khz: Rig::Press, 20e3;
    press_at_50_khz: Rig::Press, 50e3;
    press_at_100_khz: Rig::Press, 100e3;
}

/// The press's fit at 5 and 10 kHz with the billet at its sheet's height (the flow stress
/// still off the sheet's): the end height within the encoder's 10 µm step, every blow.
/// This is what separates the fit's own error from the unestimated billet height of the
/// unreferenced encoder (README "The end height").
#[test]
fn press_fit_on_a_billet_of_its_sheets_height() {
    let mut truth = truth_process(Rig::Press);
    truth.billet.height_m = sheet(Rig::Press).billet.height_m;
    for rate_hz in [5e3, 10e3] {
        for seed in ASSERT_SEEDS {
            for r in run_on(Rig::Press, rate_hz, seed, &truth, Encoder::Relative) {
                assert!(r.h_err_m.is_some_and(|h| h.abs() <= 10e-6), "{} kHz seed {seed}: {r:?}", rate_hz / 1e3);
            }
        }
    }
}

/// Without the die reference (the service's default) the first billet is taken at its
/// sheet's height, and every blow's end height is that less the ram's travel since the
/// first contact: every blow carries the first contact's error (8 µm sd on the hammer at
/// 5 kHz, +10 µm on the press fitted at 5–10 kHz from the billet's unknown height; README
/// "The end height"), and adds no more than its own readings' quantisation,
/// `HEIGHT_BLOW_TOL_M` (tuning seeds: at most 8.3 µm at any rate). Checked where the first
/// contact is hardest: the hammer at 5 kHz, the press fitted at 5 kHz and observed at 20.
#[test]
fn an_unreferenced_encoder_carries_only_the_first_contacts_error() {
    for (rig, rate_hz) in [(Rig::Hammer, 5e3), (Rig::Press, 5e3), (Rig::Press, 20e3)] {
        for seed in ASSERT_SEEDS {
            let rows = run_on(rig, rate_hz, seed, &truth_process(rig), Encoder::Relative);
            let at = format!("{rig:?} at {} kHz, seed {seed}: {rows:?}", rate_hz / 1e3);
            assert!(rows.iter().all(|r| (r.efficiency - r.true_efficiency).abs() <= EFFICIENCY_TOL), "{at}");
            assert!(rows.iter().all(|r| r.v_rel_err.abs() <= SPEED_REL_TOL), "{at}");
            assert!(rows.iter().all(|r| r.h_err_m.is_some()), "{at}");
            assert!(carried_worst_m(&rows) <= HEIGHT_BLOW_TOL_M, "{at}");
        }
    }
}

/// The tuning table: every rate, both machines, on the tuning seeds. `TUNING_ONLY=Press:5`
/// (a machine, and a rate in kHz) prints one row of it; `TUNING_BLOWS=1` every blow;
/// `TUNING_RELATIVE=1` runs without the die reference.
/// Per machine and rate it separates the end height's bias (the mean error over every
/// blow of every seed) from its scatter: between sessions (the sd of the sessions' mean
/// errors: the first contact, which the encoder chain carries to every later blow) and
/// within a session (the blows' sd about their session's mean).
#[test]
#[ignore = "prints the tuning table; run with --ignored --nocapture"]
fn tuning_table() {
    let only = std::env::var("TUNING_ONLY").unwrap_or_default();
    let verbose = std::env::var("TUNING_BLOWS").is_ok();
    let encoder = if std::env::var("TUNING_RELATIVE").is_ok() { Encoder::Relative } else { Encoder::DieReferenced };
    for rig in [Rig::Hammer, Rig::Press] {
        for rate in [5e3, 10e3, 20e3, 50e3, 100e3] {
            if !only.is_empty() && only != format!("{rig:?}:{}", rate / 1e3) {
                continue;
            }
            let mut sessions = Vec::new();
            for seed in TUNING_SEEDS {
                let rows = run_on(rig, rate, seed, &truth_process(rig), encoder);
                let (de, dv, dh) = worst(&rows);
                eprintln!(
                    "{rig:?} {:>5} kHz seed {seed}: max |Δeff| {de:.4}, max |Δv|/v {dv:.4}, max |Δh| {:.1} µm, first contact {:+.1} µm",
                    rate / 1e3,
                    dh * 1e6,
                    rows.first().map_or(f64::NAN, |r| r.contact_err_m * 1e6),
                );
                eprintln!("    max |Δh - first contact| {:.1} µm", carried_worst_m(&rows) * 1e6);
                if verbose {
                    for r in &rows {
                        eprintln!(
                            "    blow {:>2}: eff {:.4} vs {:.4}  Δv/v {:+.4}  Δh {:?}  contact {:+.1} µm",
                            r.blow,
                            r.efficiency,
                            r.true_efficiency,
                            r.v_rel_err,
                            r.h_err_m.map(|h| (h * 1e7).round() / 10.0),
                            r.contact_err_m * 1e6,
                        );
                    }
                }
                sessions.push(rows.iter().filter_map(|r| r.h_err_m).collect::<Vec<f64>>());
            }
            let s = HeightStats::of(&sessions);
            eprintln!(
                "{rig:?} {:>5} kHz over {} seeds: bias {:+.1} µm, between sessions sd {:.1} µm, within sd {:.1} µm, max |Δh| {:.1} µm",
                rate / 1e3,
                sessions.len(),
                s.bias_m * 1e6,
                s.between_sd_m * 1e6,
                s.within_sd_m * 1e6,
                s.max_abs_m * 1e6
            );
        }
    }
}

/// The end height's errors over sessions: bias and scatter (`tuning_table`).
struct HeightStats {
    bias_m: f64,
    between_sd_m: f64,
    within_sd_m: f64,
    max_abs_m: f64,
}

impl HeightStats {
    fn of(sessions: &[Vec<f64>]) -> Self {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let sd = |v: &[f64]| {
            let m = mean(v);
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len().max(2) - 1) as f64).sqrt()
        };
        let all: Vec<f64> = sessions.iter().flatten().copied().collect();
        let means: Vec<f64> = sessions.iter().map(|s| mean(s)).collect();
        let within: Vec<f64> = sessions.iter().flat_map(|s| s.iter().map(move |x| x - mean(s))).collect();
        HeightStats {
            bias_m: mean(&all),
            between_sd_m: sd(&means),
            within_sd_m: sd(&within),
            max_abs_m: all.iter().map(|x| x.abs()).fold(0.0, f64::max),
        }
    }
}
