//! The blow advisor (issue 20) against the simulator as the plant: the advised blows are
//! struck on a plant integrated by fixed-step RK4 at 1/200 of its fastest mode's period (the
//! advisor plans with the adaptive Dormand–Prince of `physics::blow`), from several start
//! heights on the hammer paper's machine (LG1000, steel 16NiCrMo13) and the press paper's
//! (SPR 400, copper). Then the advisor plans with a machine model whose stiffness is 10 %
//! off the plant's and replans after each measured blow (the height read to the encoder's
//! 10 µm), as the service does.
//!
//! Tolerances are issue 20's: the final height within ±0.5 mm of the target, in the number of
//! blows advised, and no hard blow where the advisor said none would be.

use forgemon::advise::{Advisor, Plan, PlanRequest, Speeds, TARGET_TOLERANCE_M};
use forgemon::config::{parse_machine, parse_process};
use forgemon::estimate::EstimatorConfig;
use forgemon::physics::EffectSet;
use forgemon::physics::blow::{SimOptions, simulate_blow};
use forgemon::physics::integrator::Method;
use forgemon::physics::machine::Machine;
use forgemon::physics::process::Process;
use forgemon::physics::sequence::blow_plant;

const HAMMER: &str = include_str!("../config/hammer-lg1000.machine.toml");
const STEEL: &str = include_str!("../config/steel-16NiCrMo13.process.toml");
const PRESS: &str = include_str!("../config/screw-press-spr400.machine.toml");
const COPPER: &str = include_str!("../config/copper-cu99.process.toml");
/// The plant's step: 1 µs on the LG1000 (2.05 kHz mode: 490 steps a period), 10 µs on the
/// SPR 400 (275 Hz: 360 steps).
fn plant_dt_s(m: &Machine) -> f64 {
    match m {
        Machine::Hammer(_) => 1e-6,
        Machine::ScrewPress(_) => 1e-5,
    }
}
/// The encoder's step: the height the service measures after a blow.
const ENCODER_M: f64 = 10e-6;

struct Rig {
    machine: Machine,
    process: Process,
    starts_m: [f64; 3],
    target_m: f64,
    speeds: Speeds,
}

/// Hammer: drop heights for 2.5–5.3 m/s (5.3 m/s is the paper's full blow, §3.1), the
/// paper's 112 mm billet and heights it passes on the way, to 40 mm (the LG1000 plan's end).
fn hammer() -> Rig {
    Rig {
        machine: parse_machine("hammer", HAMMER).expect("machine").machine,
        process: parse_process("steel", STEEL).expect("sheet"),
        starts_m: [0.112, 0.095, 0.080],
        target_m: 0.040,
        speeds: Speeds::Settings(vec![2.5, 3.2, 3.9, 4.6, 5.3]),
    }
}

/// Press: any speed up to 0.45 m/s (the paper's blows are 0.346 m/s at 25 % energy, Table 1),
/// the 30 mm copper billet to 12 mm.
fn press() -> Rig {
    Rig {
        machine: parse_machine("press", PRESS).expect("machine").machine,
        process: parse_process("copper", COPPER).expect("sheet"),
        starts_m: [0.030, 0.025, 0.020],
        target_m: 0.012,
        speeds: Speeds::UpTo(0.45),
    }
}

/// One blow on the plant: fixed-step RK4, another integration than the advisor's.
/// Returns the height after it and its efficiency.
fn strike_plant(m: &Machine, p: &Process, index: usize, h_m: f64, v0_mps: f64) -> (f64, f64) {
    let plant = blow_plant(m, &EffectSet::NONE, p, index, h_m);
    let opts = SimOptions { method: Method::Rk4 { dt_s: plant_dt_s(m) }, ..SimOptions::default() };
    let r = simulate_blow(&plant, v0_mps, &opts).expect("the plant strikes");
    (r.forming.expect("a billet").h_end_m, r.efficiency())
}

fn plan(m: &Machine, rig: &Rig, h_now_m: f64, blows_done: usize) -> Plan {
    let req = PlanRequest { h_now_m, target_m: rig.target_m, blows_done, speeds: rig.speeds.clone() };
    Advisor::new(m, &EffectSet::NONE, &rig.process).plan(&req).expect("a plan")
}

/// Follow each start's plan on the plant: the final height in the window, in the advised
/// number of blows, and no hard blow.
fn follow(rig: Rig) {
    let hard_min = EstimatorConfig::DEFAULT_INTERMEDIATE_MIN;
    for &h0 in &rig.starts_m {
        let p = plan(&rig.machine, &rig, h0, 0);
        assert!(p.reachable && p.hard_blows == 0, "from {h0}: {p:?}");
        let n = p.blows_to_target.expect("a count");
        assert_eq!(n, p.plan.len());
        let mut h = h0;
        for (i, b) in p.plan.iter().enumerate() {
            let (h1, eff) = strike_plant(&rig.machine, &rig.process, i + 1, h, b.v0_mps);
            assert!(eff >= hard_min, "from {h0}, blow {}: the plant's blow is hard ({eff:.3}); advised {b:?}", i + 1);
            h = h1;
        }
        eprintln!("from {:.1} mm: {n} blows, ends at {:.3} mm (target {:.1})", h0 * 1e3, h * 1e3, rig.target_m * 1e3);
        assert!((h - rig.target_m).abs() <= TARGET_TOLERANCE_M, "from {h0}: ends at {h} after {n} blows: {p:?}");
    }
}

#[test]
fn the_hammers_plans_land_in_the_window_on_the_plant() {
    follow(hammer());
}

#[test]
fn the_presss_plans_land_in_the_window_on_the_plant() {
    follow(press());
}

/// The model's stiffnesses times `f`.
fn stiffer(m: &Machine, f: f64) -> Machine {
    match *m {
        Machine::Hammer(mut h) => {
            h.k_n_per_m *= f;
            Machine::Hammer(h)
        }
        Machine::ScrewPress(mut s) => {
            s.k_link_n_per_m *= f;
            s.k_frame_n_per_m *= f;
            s.k_sensor_n_per_m *= f;
            Machine::ScrewPress(s)
        }
    }
}

/// Plan with a model 10 % too stiff (and 10 % too soft), strike the next advised blow on
/// the plant, measure, replan: the billet ends in the window. Prints, per start, the first
/// plan's count against the blows struck.
fn replan_with_an_off_model(rig: Rig) {
    for f in [0.9, 1.1] {
        let model = stiffer(&rig.machine, f);
        for &h0 in &rig.starts_m {
            let first = plan(&model, &rig, h0, 0).blows_to_target.expect("reachable");
            let mut h = h0;
            let mut struck = 0;
            loop {
                let p = plan(&model, &rig, h, struck);
                let Some(next) = p.plan.first() else {
                    assert!(p.reachable, "stiffness x{f} from {h0}: after {struck} blows at {h}: {p:?}");
                    break;
                };
                struck += 1;
                let (h1, _) = strike_plant(&rig.machine, &rig.process, struck, h, next.v0_mps);
                h = (h1 / ENCODER_M).round() * ENCODER_M;
                assert!(struck <= first + 2, "stiffness x{f} from {h0}: {struck} blows and not there ({h})");
            }
            eprintln!(
                "stiffness x{f} from {:.1} mm: first plan {first} blows, struck {struck}, ends at {:.3} mm",
                h0 * 1e3,
                h * 1e3
            );
            assert!((h - rig.target_m).abs() <= TARGET_TOLERANCE_M);
        }
    }
}

#[test]
fn replanning_absorbs_a_stiffness_10_percent_off_on_the_hammer() {
    replan_with_an_off_model(hammer());
}

#[test]
fn replanning_absorbs_a_stiffness_10_percent_off_on_the_press() {
    replan_with_an_off_model(press());
}

/// The fewest blows without a hard one, by trying every sequence of the settings (with the
/// advisor's own model: this checks the search, not the model).
fn exhaustive_fewest(rig: &Rig, settings: &[f64], h0: f64, max_depth: usize) -> Option<usize> {
    let adv = Advisor::new(&rig.machine, &EffectSet::NONE, &rig.process);
    let opts = adv.opts;
    let lo = rig.target_m - TARGET_TOLERANCE_M;
    let hi = rig.target_m + TARGET_TOLERANCE_M;
    let mut level = vec![h0];
    for depth in 1..=max_depth {
        let mut next = Vec::new();
        for &h in &level {
            for &v in settings {
                let r = simulate_blow(&blow_plant(&rig.machine, &EffectSet::NONE, &rig.process, depth, h), v, &opts)
                    .expect("simulates");
                let h1 = r.forming.expect("a billet").h_end_m;
                if r.efficiency() < EstimatorConfig::DEFAULT_INTERMEDIATE_MIN || h1 < lo {
                    continue;
                }
                if h1 <= hi {
                    return Some(depth);
                }
                next.push(h1);
            }
        }
        level = next;
    }
    None
}

#[test]
fn the_search_finds_the_fewest_blows_an_exhaustive_search_finds() {
    let rig = hammer();
    let Speeds::Settings(settings) = rig.speeds.clone() else { unreachable!() };
    for &h0 in &rig.starts_m {
        let best = exhaustive_fewest(&rig, &settings, h0, 5);
        let advised = plan(&rig.machine, &rig, h0, 0).blows_to_target;
        assert_eq!(advised, best, "from {h0}");
    }
}

#[test]
fn it_says_when_the_target_cannot_be_reached_or_needs_hard_blows() {
    let rig = hammer();
    // Already below the window: a billet only gets flatter.
    let p = plan(&rig.machine, &rig, 0.039, 0);
    assert!(!p.reachable && p.why.as_deref().is_some_and(|w| w.contains("below")), "{p:?}");
    // Already in it: nothing to do.
    let p = plan(&rig.machine, &rig, 0.0402, 0);
    assert!(p.reachable && p.blows_to_target == Some(0), "{p:?}");
    // A weakest setting that takes the billet past the window in one blow.
    let strong = Rig { speeds: Speeds::Settings(vec![5.3]), target_m: 0.105, ..hammer() };
    let p = plan(&strong.machine, &strong, 0.112, 0);
    assert!(!p.reachable && p.why.as_deref().is_some_and(|w| w.contains("below the target")), "{p:?}");
    // Flat: from 40 mm to 15 mm the steel's last blows are hard at every setting (the paper's
    // later blows turn elastic, §4.3): the plan says so and counts them.
    let flat = Rig { target_m: 0.015, ..hammer() };
    let p = plan(&flat.machine, &flat, 0.040, 0);
    assert!(p.reachable && p.hard_blows > 0 && p.why.as_deref().is_some_and(|w| w.contains("hard")), "{p:?}");
    assert_eq!(p.plan.iter().filter(|b| b.class == "hard").count(), p.hard_blows);
}

#[test]
fn bad_requests_are_refused() {
    let rig = hammer();
    let adv = Advisor::new(&rig.machine, &EffectSet::NONE, &rig.process);
    let req = |h: f64, speeds: Speeds| PlanRequest { h_now_m: h, target_m: 0.04, blows_done: 0, speeds };
    let e = adv.plan(&req(f64::NAN, Speeds::UpTo(5.0))).unwrap_err().to_string();
    assert!(e.contains("--h-now"), "{e}");
    let e = adv.plan(&req(0.1, Speeds::Settings(vec![]))).unwrap_err().to_string();
    assert!(e.contains("impact speeds"), "{e}");
}

#[test]
#[ignore = "prints the search against the exhaustive one; run with --ignored --nocapture"]
fn search_table() {
    let rig = hammer();
    let Speeds::Settings(settings) = rig.speeds.clone() else { unreachable!() };
    let cases: Vec<(f64, f64)> = [0.112, 0.104, 0.096, 0.088, 0.080, 0.072, 0.064]
        .iter()
        .flat_map(|&h| [0.050, 0.040, 0.030].map(|t| (h, t)))
        .filter(|(h, t)| h - t > 0.01)
        .collect();
    let mut wrong = 0;
    for &(h0, target) in &cases {
        let r = Rig { target_m: target, ..hammer() };
        let best = exhaustive_fewest(&r, &settings, h0, 5);
        let t0 = std::time::Instant::now();
        let p = plan(&r.machine, &r, h0, 0);
        let dt = t0.elapsed();
        wrong += usize::from(best.is_some() && p.blows_to_target != best);
        eprintln!("{h0} -> {target}: advised {:?}, exhaustive {best:?}, {dt:?}", p.blows_to_target);
    }
    eprintln!("{wrong} of {} cases not the fewest", cases.len());
}
