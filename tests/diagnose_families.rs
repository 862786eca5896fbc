//! Whole effect families (issue #17 item 5): blows rendered with an effect's hidden
//! parameters off the values the library once held (a damped foundation, a reference rate or
//! strain other than 10 /s or 0.2), and the diagnosis's fit must recover what the data
//! determine of it (`Effect::identifiable`: the exponent and the flow stress's level at the
//! default reference, a foundation's mass, spring and damping ratio) and the verdict must
//! name it.
//!
//! The data do not come from the fitted code path: `forgemon::daq` integrates the blows with
//! classical RK4 at a fixed 1 µs step (the fits use the adaptive Dormand–Prince of
//! `identify::objective`), passes the load through an anti-alias filter at 0.4 × the output
//! rate, decimates it and adds noise, an offset and encoder steps.
//!
//! Seeds: tolerances were set on the tuning seeds `TUNE` (calibration 31, holdout 32;
//! `cargo test --release --test diagnose_families -- --ignored --nocapture tuning_table`
//! prints them) and the CI tests assert on `ASSERT` (41/42), which were not looked at while
//! choosing them.
//!
//! The CI tests fit the hidden effect and its nearest rivals only (the flow effects for a
//! flow effect, the contact's and tools' elasticity for a foundation), to stay within a few
//! seconds each; the ignored `full_diagnosis_table` runs the whole library and its pairs on
//! every case and both seed sets and prints the verdicts.

use forgemon::config::{parse_machine, parse_process};
use forgemon::daq::{DaqSpec, daq_blows};
use forgemon::diagnose::attribute::{Fitted, fit_candidates, library};
use forgemon::diagnose::blowset::BlowSet;
use forgemon::diagnose::localise::{localise, reference};
use forgemon::diagnose::verdict::decide;
use forgemon::estimate::EstimatorConfig;
use forgemon::identify::objective::{Objective, Reference, Setting};
use forgemon::physics::effects::{Effect, EffectSet};
use forgemon::physics::machine::{Machine, MachineKind};
use forgemon::signal::segment::{SegmentConfig, Segmenter};
use forgemon::synth::{CaptureSpec, rows_batch};

/// The withheld-effect suite's machines (tests/diagnose.rs): a hammer unlike the paper's
/// Table 1, a press unlike the press paper's Table 3.
const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n";
const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
                     c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n";
const STEEL: &str = include_str!("../config/steel-16NiCrMo13.process.toml");
const COPPER: &str = include_str!("../config/copper-cu99.process.toml");

/// Capture seeds (calibration, holdout) the tolerances were set on.
const TUNE: (u64, u64) = (31, 32);
/// Capture seeds the CI tests assert on.
const ASSERT: (u64, u64) = (41, 42);

/// A damped foundation under the hammer's 26 kg lower tool: 2 t on 5 GN/m (a 250 Hz mode)
/// at a damping ratio of 0.2 (c3 = 0.2 · 2 √(k3 m3) = 1.26e6 N s/m).
const HAMMER_FOUNDATION: &str = "foundation:m3_kg=2000,k3_N_per_m=5e9,c3_Ns_per_m=1.26e6";
/// Rate sensitivity about a 2 /s reference: the flow stress at 10 /s is 5^0.1 = 1.17 times
/// the sheet's.
const HAMMER_RATE: &str = "strain_rate:m=0.1,rate_ref_per_s=2";
/// Hardening about a strain of 0.08: at 0.2 the flow stress is 2.5^0.2 = 1.20 times the
/// sheet's.
const HAMMER_HARDENING: &str = "strain_hardening:n=0.2,eps_ref=0.08";
/// The press's: 20 t on 5 GN/m under its 2.5 t tool at a damping ratio of 0.2 (c3 = 4e6).
const PRESS_FOUNDATION: &str = "foundation:m3_kg=20000,k3_N_per_m=5e9,c3_Ns_per_m=4e6";
const PRESS_RATE: &str = "strain_rate:m=0.1,rate_ref_per_s=2";

fn machine(kind: MachineKind) -> Machine {
    parse_machine("m", if kind == MachineKind::Hammer { HAMMER } else { PRESS }).unwrap().machine
}

/// One billet's blows rendered through the DAQ with the hidden `effect`, read as `diagnose`
/// reads a capture directory. `holdout`: the second billet (90 % of the sheet's height,
/// other speeds), as in tests/diagnose.rs.
fn billet(m: &Machine, effect: &str, holdout: bool, seed: u64) -> (Vec<Reference>, Setting) {
    let kind = m.kind();
    let (sheet, v0s, capture) = match (kind, holdout) {
        (MachineKind::Hammer, false) => (STEEL, [4.0, 4.5, 5.0, 5.3, 5.3], CaptureSpec::hammer(seed)),
        (MachineKind::Hammer, true) => (STEEL, [4.2, 4.8, 5.1, 5.3, 5.3], CaptureSpec::hammer(seed)),
        (MachineKind::ScrewPress, false) => (COPPER, [0.30, 0.33, 0.36, 0.36, 0.36], CaptureSpec::press(seed)),
        (MachineKind::ScrewPress, true) => (COPPER, [0.31, 0.34, 0.35, 0.36, 0.36], CaptureSpec::press(seed)),
    };
    let mut p = parse_process("p", sheet).unwrap();
    p.measured_final_heights_m.clear();
    if holdout {
        p.billet.height_m *= 0.9;
    }
    let hidden = match effect {
        "none" => EffectSet::NONE,
        e => EffectSet::from_effects(&[Effect::parse_spec(e).unwrap()]),
    };
    let spec = DaqSpec::new(capture);
    let fit_s = EstimatorConfig::for_kind(kind).fit_s;
    let refs = daq_blows(m, &hidden, &p, &v0s, &spec)
        .unwrap()
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let batch = rows_batch("c", 0, 0, 1e9 / capture.sample_rate_hz, &b.rows);
            let cut = Segmenter::cut_all(SegmentConfig::for_kind(kind), [&batch]);
            reference("b", &cut[0], Some(i + 1), fit_s, m).unwrap()
        })
        .collect();
    (refs, Setting::Billet(p))
}

/// A billet's blows as the diagnosis scores them, the base model's nrmse per blow, and the
/// sensor noise over the peak.
fn blow_set(m: &Machine, (refs, setting): (Vec<Reference>, Setting)) -> (BlowSet, Vec<f64>, f64) {
    let n = refs.len();
    let obj = Objective::new(refs, vec![true; n], setting, m.kind());
    let mode2 = m.second_mode_hz();
    let sims = obj.simulate(m).unwrap();
    let loc: Vec<_> = obj.refs.iter().zip(&sims).map(|(r, s)| localise(r, s, mode2)).collect();
    let base = loc.iter().map(|l| l.nrmse).collect();
    let windows = loc.iter().map(|l| l.window).collect();
    let set = BlowSet { obj, windows, mode2_hz: mode2 };
    let noise = set.noise_nrmse();
    (set, base, noise)
}

/// The effect `name` and its `rivals` fitted on the calibration billet, scored on the
/// holdout one, and the verdict rule applied to them (single effects, no pairs).
fn fit_case(kind: MachineKind, effect: &str, rivals: &[&str], seeds: (u64, u64)) -> (Fitted, Option<String>) {
    let m = machine(kind);
    let (calib, _, _) = blow_set(&m, billet(&m, effect, false, seeds.0));
    let (holdout, base_hold, noise) = blow_set(&m, billet(&m, effect, true, seeds.1));
    let lib = library(kind);
    let name = effect.split(':').next().unwrap();
    let fits: Vec<Fitted> = lib
        .iter()
        .filter(|c| c.name == name || rivals.contains(&c.name))
        .map(|c| fit_candidates(&m, &EffectSet::NONE, &[c], &[], &calib, &holdout).unwrap())
        .collect();
    let verdict = decide(&m, &base_hold, noise, &fits, &[]).chosen.map(|f| f.name);
    (fits.into_iter().find(|f| f.name == name).unwrap(), verdict)
}

/// Relative errors of the fitted identifiable combination against the hidden one, by name
/// (a damping ratio's too: 0.2 fitted as 0.22 is 0.1).
fn errors(fitted: &Fitted, hidden: &str) -> Vec<(&'static str, f64)> {
    let truth = Effect::parse_spec(hidden).unwrap().identifiable();
    let got = fitted.effects[0].identifiable();
    truth.iter().zip(&got).map(|((k, t), (_, g))| (*k, g / t - 1.0)).collect()
}

/// The CI check of one case on the `ASSERT` seeds: the verdict names the effect and each
/// identifiable quantity is within its tolerance.
fn check(kind: MachineKind, effect: &str, rivals: &[&str], tolerance: &[(&str, f64)]) {
    let (fitted, verdict) = fit_case(kind, effect, rivals, ASSERT);
    let errs = errors(&fitted, effect);
    eprintln!("{kind:?} {effect}: verdict {verdict:?}, fitted {:?}, errors {errs:?}", fitted.effects);
    assert_eq!(verdict.as_deref(), Some(effect.split(':').next().unwrap()), "{fitted:?}");
    for (key, tol) in tolerance {
        let (_, e) = errs.iter().find(|(k, _)| k == key).unwrap();
        assert!(e.abs() <= *tol, "{key}: relative error {e:.4} beyond {tol}\n{fitted:?}");
    }
}

/// The flow effects a flow effect competes with.
const FLOW: [&str; 4] = ["friction_rise", "strain_rate", "strain_hardening", "thermal"];
/// The elastic effects a foundation competes with (a light foundation is a series spring).
const ELASTIC: [&str; 2] = ["elastic_recovery", "foundation"];

// Tolerances: about twice the largest error on the tuning seeds 31/32 (`tuning_table`,
// quoted with each), and at least 1 %.

#[test]
fn hammer_damped_foundation_is_fitted_with_its_damper() {
    // Tuning: m3 −3.3 %, k3 −1.6 %, ζ3 +2.0 % (the mass is low by about as much on the assert
    // seeds: the renderer's RK4 and anti-alias filter against the fit's model, not noise).
    check(MachineKind::Hammer, HAMMER_FOUNDATION, &ELASTIC, &[("m3_kg", 0.07), ("k3_N_per_m", 0.04), ("zeta3", 0.04)]);
}

#[test]
fn hammer_strain_rate_off_its_reference_is_fitted_as_its_level() {
    // Tuning: m −0.23 %, level +0.02 % (the reference itself 2 /s fitted at 1.99).
    check(MachineKind::Hammer, HAMMER_RATE, &FLOW, &[("m", 0.01), ("level_at_ref", 0.01)]);
}

#[test]
fn hammer_strain_hardening_off_its_reference_is_fitted_as_its_level() {
    // Tuning: n +0.07 %, level +0.02 %.
    check(MachineKind::Hammer, HAMMER_HARDENING, &FLOW, &[("n", 0.01), ("level_at_ref", 0.01)]);
}

#[test]
fn press_damped_foundation_is_fitted_with_its_damper() {
    // Tuning: m3 −0.35 %, k3 −0.29 %, ζ3 +0.57 %.
    check(
        MachineKind::ScrewPress,
        PRESS_FOUNDATION,
        &ELASTIC,
        &[("m3_kg", 0.01), ("k3_N_per_m", 0.01), ("zeta3", 0.015)],
    );
}

#[test]
fn press_strain_rate_off_its_reference_is_fitted_as_its_level() {
    // Tuning: m +0.13 %, level −0.10 %.
    check(MachineKind::ScrewPress, PRESS_RATE, &FLOW, &[("m", 0.01), ("level_at_ref", 0.01)]);
}

/// A free flow-stress level must not turn a billet without any effect into one: the flow
/// effects (two with a free level now) and the elastic ones fitted on a no-effect hammer
/// billet leave the verdict at "none".
#[test]
fn hammer_no_effect_stays_none_with_free_levels() {
    let m = machine(MachineKind::Hammer);
    let (calib, _, _) = blow_set(&m, billet(&m, "none", false, ASSERT.0));
    let (holdout, base_hold, noise) = blow_set(&m, billet(&m, "none", true, ASSERT.1));
    let fits: Vec<Fitted> = library(MachineKind::Hammer)
        .iter()
        .filter(|c| FLOW.contains(&c.name) || ELASTIC.contains(&c.name))
        .map(|c| fit_candidates(&m, &EffectSet::NONE, &[c], &[], &calib, &holdout).unwrap())
        .collect();
    let v = decide(&m, &base_hold, noise, &fits, &[]);
    assert!(v.chosen.is_none(), "{}\n{fits:#?}", v.why);
}

/// The cases of the tables: machine, effect, rivals.
fn cases() -> Vec<(MachineKind, &'static str, &'static [&'static str])> {
    vec![
        (MachineKind::Hammer, HAMMER_FOUNDATION, &ELASTIC),
        (MachineKind::Hammer, HAMMER_RATE, &FLOW),
        (MachineKind::Hammer, HAMMER_HARDENING, &FLOW),
        (MachineKind::ScrewPress, PRESS_FOUNDATION, &ELASTIC),
        (MachineKind::ScrewPress, PRESS_RATE, &FLOW),
    ]
}

/// Prints each case's fitted identifiable combination and its errors on the tuning seeds,
/// from which the CI tests' tolerances were set.
#[test]
#[ignore = "tuning harness: a minute or more; prints the errors the tolerances were set from"]
fn tuning_table() {
    for (kind, effect, rivals) in cases() {
        let (fitted, verdict) = fit_case(kind, effect, rivals, TUNE);
        println!("{kind:?} {effect}: verdict {verdict:?}; {:?}; errors {:?}", fitted.effects, errors(&fitted, effect));
    }
}

/// The whole library and its pairs (`forgemon::diagnose::diagnose`, as the CLI runs it) on
/// each case and both seed sets: the verdict, the holdout shrink and the location.
#[test]
#[ignore = "the full diagnosis per case, minutes in all; prints the verdict table"]
fn full_diagnosis_table() {
    for (kind, effect, _) in cases() {
        let m = machine(kind);
        for (set, seeds) in [("tune", TUNE), ("assert", ASSERT)] {
            let calib = billet(&m, effect, false, seeds.0);
            let holdout = billet(&m, effect, true, seeds.1);
            // Elapsed time is printed, not asserted (benches/diagnose.rs measures speed).
            let t0 = std::time::Instant::now();
            let d = forgemon::diagnose::diagnose(&m, &EffectSet::NONE, calib, holdout, &|| {}).unwrap();
            let elapsed_s = t0.elapsed().as_secs_f64();
            let v = d.verdict.as_ref();
            let shrink = v.map_or(0.0, |f| 1.0 - f.holdout / d.baseline_holdout);
            let errs = v.filter(|f| f.effects.len() == 1).map(|f| errors(f, effect));
            println!(
                "{kind:?} {effect} [{set}] {elapsed_s:.1} s: verdict {} shrink {shrink:.3} equivalent {:?} location {}; {:?} errors {errs:?}",
                v.map_or("none", |f| f.name.as_str()),
                d.equivalent.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(),
                d.location.phase(),
                v.map(|f| &f.effects),
            );
        }
    }
}
