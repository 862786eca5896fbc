//! The withheld-effect suite (issue #6): calibration and holdout billets made by
//! `forgemon simulate --effect … --captures` from a hammer that is not the example config
//! (sensor noise, load offset, 10 µm encoder steps and the free-fall approach of
//! `CaptureSpec::hammer`), diagnosed through the CLI without being told the effect.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

const STEEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/steel-16NiCrMo13.process.toml");
const COPPER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/copper-cu99.process.toml");
/// The "identified" machines: a hammer unlike the paper's Table 1, a press unlike the
/// press paper's Table 3.
const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n";
const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
                     c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n";

#[derive(Clone, Copy)]
enum Kind {
    Hammer,
    Press,
}

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().unwrap()
}

fn ok(out: &Output) -> String {
    assert!(out.status.success(), "{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Two billets (the sheet's height and 90 % of it; five blows each at different speeds)
/// forged with the hidden `effects`, and the machine file the diagnosis gets (without them).
fn make_case(name: &str, effects: &[&str]) -> (PathBuf, PathBuf) {
    make(Kind::Hammer, name, effects)
}

fn make(kind: Kind, name: &str, effects: &[&str]) -> (PathBuf, PathBuf) {
    let (machine_text, sheet_path, v0_calib, v0_hold) = match kind {
        Kind::Hammer => (HAMMER, STEEL, "4.0,4.5,5.0,5.3,5.3", "4.2,4.8,5.1,5.3,5.3"),
        // Copper on the press at the paper's speeds (0.346 m/s, §3.3).
        Kind::Press => (PRESS, COPPER, "0.30,0.33,0.36,0.36,0.36", "0.31,0.34,0.35,0.36,0.36"),
    };
    let dir = std::env::temp_dir().join(format!("forgemon-diagnose-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let machine = dir.join("machine.toml");
    std::fs::write(&machine, machine_text).unwrap();
    let text = std::fs::read_to_string(sheet_path).unwrap();
    let sheet: toml::Table = text[..text.find("[[blows]]").unwrap_or(text.len())].parse().unwrap();
    std::fs::write(dir.join("a.process.toml"), toml::to_string(&sheet).unwrap()).unwrap();
    let mut b = sheet.clone();
    let h = b["billet"]["height_m"].as_float().unwrap();
    b["billet"].as_table_mut().unwrap().insert("height_m".into(), toml::Value::Float(0.9 * h));
    std::fs::write(dir.join("b.process.toml"), toml::to_string(&b).unwrap()).unwrap();
    for (billet, sheet, v0, seed) in
        [("calib", "a.process.toml", v0_calib, "3"), ("holdout", "b.process.toml", v0_hold, "4")]
    {
        let (m, p, c) = (machine.to_str().unwrap(), dir.join(sheet), dir.join(billet));
        let mut args = vec!["simulate", "--machine", m, "--process", p.to_str().unwrap(), "--v0", v0];
        for e in effects {
            args.extend_from_slice(&["--effect", e]);
        }
        args.extend_from_slice(&["--captures", c.to_str().unwrap(), "--capture-seed", seed]);
        ok(&forgemon(&args));
    }
    (dir, machine)
}

fn diagnose(dir: &Path, machine: &Path) -> Value {
    let out = dir.join("out");
    let stdout = ok(&forgemon(&[
        "diagnose",
        "--machine",
        machine.to_str().unwrap(),
        "--calib",
        dir.join("calib").to_str().unwrap(),
        "--holdout",
        dir.join("holdout").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]));
    eprintln!("{stdout}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.matches("<svg").count() >= 4, "a report with plots");
    let r: Value = serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    // Each holdout blow's caption gives its error before and, with a verdict, after.
    let verdict = r["verdict"]["effect"].as_str().unwrap();
    // Issue #17: the effects the verdict's test cannot tell from it, never the verdict itself.
    let equivalent = r["verdict"]["equivalent"].as_array().expect("verdict.equivalent is a list");
    assert!(equivalent.iter().all(|e| e.as_str().is_some_and(|e| e != verdict)), "{r:#}");
    // Issue #17: the location phase with phase, its shares adding up to 1.
    let loc = &r["baseline"]["location"];
    let share = |p: &str| loc["share"][p].as_f64().unwrap();
    let sum: f64 = ["impact", "forming", "spring_back", "post"].iter().map(|p| share(p)).sum();
    assert!((sum - 1.0).abs() < 1e-9, "{r:#}");
    assert!(share(loc["phase"].as_str().unwrap()) >= 0.25, "{r:#}");
    assert!(loc["method"].as_str().is_some_and(|m| m.starts_with("phase_aligned")), "{r:#}");
    // Issue 41: the verdict's confidence, a bootstrap over the blows: an agreement in [0, 1]
    // that the resamples' verdict shares add up to, a runner-up told why it lost, and
    // "uncertain" exactly when the agreement is under the stated minimum.
    let c = &r["verdict"]["confidence"];
    let agreement = c["agreement"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&agreement), "{r:#}");
    let shares: f64 = c["verdicts"].as_object().unwrap().values().map(|v| v.as_f64().unwrap()).sum();
    assert!((shares - 1.0).abs() < 1e-9, "{r:#}");
    assert!(c["runner_up"]["why"].as_str().is_some_and(|w| !w.is_empty()), "{r:#}");
    assert_eq!(c["uncertain_between"].is_array(), agreement < c["min_agreement"].as_f64().unwrap(), "{r:#}");
    // The report opens with the verdict in words, before the statistics.
    let conclusion = html.split("Conclusion").nth(1).unwrap();
    let opening = if verdict == "none" { "No unmodelled effect is named" } else { "of the gap on the held-out blows" };
    assert!(conclusion.find(opening) < conclusion.find("The base model misses"), "{conclusion}");
    let after = html.matches(&format!(", with {verdict} ")).count();
    assert_eq!(after, if verdict == "none" { 0 } else { 5 }, "{verdict}");
    // Localisation by indicator (issue #6): every one named, with a value for every blow
    // or an explicit null.
    for name in [
        "peak_load",
        "final_load",
        "forming_time",
        "spring_back_time",
        "final_height",
        "mode2_frequency",
        "mode2_damping",
    ] {
        let i = &r["baseline"]["indicators"][name];
        assert_eq!(i["per_blow_rel_error"].as_array().map(Vec::len), Some(5), "{name}: {r:#}");
    }
    r
}

/// A single hidden effect: the verdict names it and the holdout shrink is ≥ 0.5 (issue
/// #6's bound). Returns the report.
fn single(name: &str, effect: &str) -> Value {
    single_on(Kind::Hammer, name, effect)
}

fn single_on(kind: Kind, name: &str, effect: &str) -> Value {
    let (dir, machine) = make(kind, name, &[effect]);
    let r = diagnose(&dir, &machine);
    let expected = effect.split(':').next().unwrap();
    assert_eq!(r["verdict"]["effect"], expected, "{r:#}");
    assert!(r["verdict"]["holdout_shrink"].as_f64().unwrap() >= 0.5, "{r:#}");
    recovers(&r, &[effect]);
    // A clear single effect on the project's renderer: the bootstrap agrees (issue 41's
    // 80 %), and the shrink's interval holds the shrink.
    let c = &r["verdict"]["confidence"];
    assert!(c["agreement"].as_f64().unwrap() >= 0.8, "{r:#}");
    let interval: Vec<f64> =
        c["holdout_shrink_interval"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    let shrink = r["verdict"]["holdout_shrink"].as_f64().unwrap();
    assert!(interval[0] <= shrink && shrink <= interval[1], "{r:#}");
    // Every library effect was tried, and the ranking is best first.
    let cands = r["candidates"].as_array().unwrap();
    for e in forgemon::physics::effects::EFFECT_NAMES {
        assert!(cands.iter().any(|c| c["effect"] == e), "{e} missing");
    }
    assert!(cands.windows(2).all(|w| w[0]["holdout"].as_f64() <= w[1]["holdout"].as_f64()));
    let _ = std::fs::remove_dir_all(&dir);
    r
}

/// The verdict's fitted parameters are the hidden ones: it measures the effect as well as
/// naming it. Within 3 %: over three pairs of capture seeds (3/4, 11/12, 21/22) the worst
/// value was 0.6 % off (the hammer's clearance gap), the rest within 0.3 %; held
/// parameters (a foundation damper of 0) must match exactly.
fn recovers(r: &Value, hidden: &[&str]) {
    let verdict = &r["verdict"]["effect"];
    let fitted = r["candidates"].as_array().unwrap().iter().find(|c| &c["effect"] == verdict).unwrap();
    for spec in hidden {
        let effect = forgemon::physics::effects::Effect::parse_spec(spec).unwrap();
        for (key, truth) in effect.params() {
            let got = fitted["params"][key].as_f64().unwrap();
            assert!((got - truth).abs() <= 0.03 * truth.abs(), "{key}: fitted {got}, hidden {truth}\n{r:#}");
        }
    }
}

/// Two hidden effects: the verdict names both, shrinks the holdout error by ≥ 0.5 and
/// measures both.
fn pair_on(kind: Kind, name: &str, effects: &[&str]) {
    let (dir, machine) = make(kind, name, effects);
    let r = diagnose(&dir, &machine);
    let mut names: Vec<&str> = r["verdict"]["effect"].as_str().unwrap().split('+').collect();
    names.sort();
    let mut hidden: Vec<&str> = effects.iter().map(|e| e.split(':').next().unwrap()).collect();
    hidden.sort();
    assert_eq!(names, hidden, "{r:#}");
    assert!(r["verdict"]["holdout_shrink"].as_f64().unwrap() >= 0.5, "{r:#}");
    recovers(&r, effects);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn clearance_is_named_and_located_at_impact() {
    let r = single("clearance", "clearance:gap_m=0.0003");
    assert_eq!(r["baseline"]["dominant_phase"], "impact", "{r:#}");
    acts_in(&r, "impact");
}

#[test]
fn elastic_recovery_is_named_and_located_in_the_spring_back() {
    let r = single("elastic", "elastic_recovery:k_contact_N_per_m=1.5e9");
    assert_eq!(r["baseline"]["dominant_phase"], "spring_back", "{r:#}");
    located_phase_with_phase(&r, "spring_back");
    acts_in(&r, "spring_back");
    // The papers' gap: the real spring-back lasts longer than the model's (beyond 5× the
    // ≤ 1 % of the blow a no-effect hammer shows; src/diagnose/mod.rs's tests).
    assert!(r["baseline"]["indicators"]["spring_back_time"]["mean_rel_error"].as_f64().unwrap() < -0.05, "{r:#}");
}

/// The largest mean relative error of forming time and final height on the no-effect
/// cases of either machine (0.9 % over capture seeds 3/4, 11/12 and 21/22), rounded up.
const NO_EFFECT_REL_ERROR: f64 = 0.01;

/// A flow stress the model lacks raises the real load, so the real forming ends sooner than
/// the model's: the gap is in the forming, the model's forming runs long, and it over-forms
/// the billet. Each beyond the ≤ 1 % (`NO_EFFECT_REL_ERROR`) a no-effect hammer or press
/// shows: the final height by 5×, the forming time by `forming_time_times` (5 too, but 3 for
/// the press's friction, which acts only late in the stroke, once the billet is flat: 4.0 %
/// to 4.2 % over capture seeds 3/4, 11/12 and 21/22).
fn located_in_the_forming(r: &Value, forming_time_times: f64) {
    assert_eq!(r["baseline"]["dominant_phase"], "forming", "{r:#}");
    located_phase_with_phase(r, "forming");
    let ind = |n: &str| r["baseline"]["indicators"][n]["mean_rel_error"].as_f64().unwrap();
    assert!(ind("forming_time") > forming_time_times * NO_EFFECT_REL_ERROR, "{r:#}");
    assert!(ind("final_height") < -5.0 * NO_EFFECT_REL_ERROR, "{r:#}");
}

/// Issue #17: `baseline.location`, phase with phase, names `phase` (src/diagnose/mod.rs's
/// tests chose the method on capture seed 5; these cases are seeds 3/4).
fn located_phase_with_phase(r: &Value, phase: &str) {
    assert_eq!(r["baseline"]["location"]["phase"], phase, "{r:#}");
}

/// Issue 41: where the verdict's effect acts, by counterfactual (`verdict.acts`), is `phase`
/// (the method was chosen on `tests/independent`'s seeds 3/4; these captures are the
/// project's renderer's, seeds 3/4).
fn acts_in(r: &Value, phase: &str) {
    assert_eq!(r["verdict"]["acts"]["phase"], phase, "{r:#}");
}

#[test]
fn friction_rise_is_named_and_located_in_the_forming() {
    let r = single("friction", "friction_rise:exponent=1.0");
    located_in_the_forming(&r, 5.0);
    acts_in(&r, "forming");
}

#[test]
fn strain_rate_is_named() {
    located_phase_with_phase(&single("rate", "strain_rate:m=0.1"), "forming");
}

#[test]
fn strain_hardening_is_named_and_located_in_the_forming() {
    located_in_the_forming(&single("hardening", "strain_hardening:n=0.2"), 5.0);
}

#[test]
fn thermal_is_named_and_located_in_the_forming() {
    located_in_the_forming(&single("thermal", "thermal:q_dT=0.15"), 5.0);
}

#[test]
fn foundation_is_named() {
    single("foundation", "foundation:m3_kg=2000,k3_N_per_m=5e9,c3_Ns_per_m=0");
}

#[test]
fn sensor_highpass_is_named() {
    single("highpass", "sensor_highpass:tau_s=0.005");
}

#[test]
fn no_effect_gives_none() {
    let (dir, machine) = make_case("none", &[]);
    let r = diagnose(&dir, &machine);
    assert_eq!(r["verdict"]["effect"], "none", "{r:#}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn two_effects_are_both_named() {
    pair_on(Kind::Hammer, "two", &["elastic_recovery:k_contact_N_per_m=1.5e9", "friction_rise:exponent=1.0"]);
}

// The press (copper, 20 kHz, constant-speed approach).

/// The library's clearance on a press: its lower die (800 kg) rests across a 0.3 mm gap from
/// the sensor path and has not been caught up (docs/interfaces.md §6, "the lower mass starts at
/// rest"). Struck by the billet, the die crosses the gap and bounces on the sensor path
/// while the billet forms: a rectified ring the base press, with no mass there, lacks.
#[test]
fn press_clearance_is_named_and_located_at_impact() {
    let r = single_on(Kind::Press, "p-clearance", "clearance:gap_m=0.0003,m_lower_kg=800");
    assert_eq!(r["baseline"]["dominant_phase"], "impact", "{r:#}");
    located_phase_with_phase(&r, "impact");
    acts_in(&r, "impact");
}

/// Issue #17's basin case: at the press's 20 kHz a clearance of a few tenths of a mm under a
/// light lower die (50 kg: struck at about twice the tool's 0.3 m/s it crosses 0.3 mm in
/// about 0.5 ms, ten samples) closes within a few samples. Before the fine scan of the gap
/// (src/diagnose/attribute.rs) it was fitted at 52 µm under the right die (capture seeds
/// 3/4, shrink 0.76 all the same).
///
/// The gap within 10 %: one sample of closure time (50 µs) at the die's ~0.6 m/s is 30 µm,
/// a tenth of the gap; the cost is flat below that (316 µm was fitted here). The die's mass
/// within `recovers`' 3 %.
#[test]
fn press_short_closure_finds_its_gap() {
    let (dir, machine) = make(Kind::Press, "p-short-closure", &["clearance:gap_m=0.0003,m_lower_kg=50"]);
    let r = diagnose(&dir, &machine);
    assert_eq!(r["verdict"]["effect"], "clearance", "{r:#}");
    assert!(r["verdict"]["holdout_shrink"].as_f64().unwrap() >= 0.5, "{r:#}");
    let params = &r["verdict"]["params"];
    let (gap, die) = (params["gap_m"].as_f64().unwrap(), params["m_lower_kg"].as_f64().unwrap());
    assert!((gap / 3e-4 - 1.0).abs() <= 0.10, "gap {gap}\n{r:#}");
    assert!((die / 50.0 - 1.0).abs() <= 0.03, "die {die}\n{r:#}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Without the die (`m_lower_kg` left out) a press's gap is dead travel in a massless sensor
/// path: the tool reaches the billet later, nothing else. At a constant-speed approach that
/// is a pure delay, which the alignment at 10 % of the peak removes, and a constant gap is
/// indistinguishable from the encoder's arbitrary offset: the load carries no trace of it.
/// So the honest answer is that there is no gap to explain, even with the press's
/// clearance candidate free to add a die. (Captures rendered at the default tolerance once
/// showed a 680 kN spike at the closure, an integration artefact a diagnosis could
/// "explain"; `synth::CAPTURE_RTOL`.)
#[test]
fn press_dead_travel_leaves_no_trace_in_the_load() {
    let (dir, machine) = make(Kind::Press, "p-dead-travel", &["clearance:gap_m=0.0003"]);
    let r = diagnose(&dir, &machine);
    assert_eq!(r["verdict"]["effect"], "none", "{r:#}");
    // Within the rule's noise band of a gap (2× the sensor noise), plus the base press's
    // own distance from noise-free captures, which the no-effect case measures (1.5×).
    let (base, noise) = (r["baseline"]["holdout"].as_f64().unwrap(), r["rule"]["noise_nrmse"].as_f64().unwrap());
    assert!(base < 3.0 * noise, "{r:#}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn press_elastic_recovery_is_named_and_located_in_the_spring_back() {
    let r = single_on(Kind::Press, "p-elastic", "elastic_recovery:k_contact_N_per_m=5e9");
    assert_eq!(r["baseline"]["dominant_phase"], "spring_back", "{r:#}");
    located_phase_with_phase(&r, "spring_back");
    acts_in(&r, "spring_back");
}

#[test]
fn press_friction_rise_is_named_and_located_in_the_forming() {
    located_in_the_forming(&single_on(Kind::Press, "p-friction", "friction_rise:exponent=1.0"), 3.0);
}

#[test]
fn press_strain_rate_is_named() {
    located_phase_with_phase(&single_on(Kind::Press, "p-rate", "strain_rate:m=0.1"), "forming");
}

#[test]
fn press_strain_hardening_is_named_and_located_in_the_forming() {
    located_in_the_forming(&single_on(Kind::Press, "p-hardening", "strain_hardening:n=0.2"), 5.0);
}

#[test]
fn press_thermal_is_named_and_located_in_the_forming() {
    located_in_the_forming(&single_on(Kind::Press, "p-thermal", "thermal:q_dT=0.15"), 5.0);
}

#[test]
fn press_foundation_is_named() {
    single_on(Kind::Press, "p-foundation", "foundation:m3_kg=20000,k3_N_per_m=5e9,c3_Ns_per_m=0");
}

#[test]
fn press_sensor_highpass_is_named() {
    single_on(Kind::Press, "p-highpass", "sensor_highpass:tau_s=0.02");
}

#[test]
fn press_no_effect_gives_none() {
    let (dir, machine) = make(Kind::Press, "p-none", &[]);
    let r = diagnose(&dir, &machine);
    assert_eq!(r["verdict"]["effect"], "none", "{r:#}");
    // The spring-back and the billet's final height are measured on every blow: the
    // comparison runs until the load is back at zero, past where the segmenter ends a press
    // blow (30 kN, above 2 % of the peak). With no effect they match the model's to 2 %:
    // the largest error over capture seeds 3/4 was 1.2 % (blow 1's final height, read
    // through a 10 µm encoder and 5 kN load noise).
    for name in ["spring_back_time", "final_height"] {
        let i = &r["baseline"]["indicators"][name];
        assert_eq!(i["blows"], 5, "{name}: {r:#}");
        for e in i["per_blow_rel_error"].as_array().unwrap() {
            assert!(e.as_f64().unwrap().abs() < 0.02, "{name}: {r:#}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn press_two_effects_are_both_named() {
    pair_on(Kind::Press, "p-two", &["elastic_recovery:k_contact_N_per_m=5e9", "friction_rise:exponent=1.0"]);
}

#[test]
fn bad_input_gives_a_clear_error() {
    let (dir, machine) = make_case("bad", &[]);
    let err = |args: &[&str]| {
        let o = forgemon(args);
        assert!(!o.status.success());
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!e.contains("panicked"), "{e}");
        e
    };
    let (m, c, h, o) = (
        machine.to_str().unwrap().to_string(),
        dir.join("calib").to_str().unwrap().to_string(),
        dir.join("holdout").to_str().unwrap().to_string(),
        dir.join("out").to_str().unwrap().to_string(),
    );
    // A missing process sheet.
    std::fs::remove_file(dir.join("holdout/process.toml")).unwrap();
    let e = err(&["diagnose", "--machine", &m, "--calib", &c, "--holdout", &h, "--out", &o]);
    assert!(e.contains("holdout") && e.contains("no process.toml"), "{e}");
    // A directory without blows.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::copy(dir.join("calib/process.toml"), empty.join("process.toml")).unwrap();
    let e = err(&["diagnose", "--machine", &m, "--calib", empty.to_str().unwrap(), "--holdout", &c, "--out", &o]);
    assert!(e.contains("no blow_NN.csv files"), "{e}");
    // A machine of the wrong kind.
    let press = dir.join("press.toml");
    std::fs::write(
        &press,
        "kind = \"screw_press\"\nm_tool_kg = 3110\nm_ram_kg = 106000\nk_link_N_per_m = 1.72e9\nc_link_Ns_per_m = 3.61e5\n\
         k_frame_N_per_m = 9.74e9\nc_frame_Ns_per_m = 0\nk_sensor_N_per_m = 3.39e10\n",
    )
    .unwrap();
    let e = err(&["diagnose", "--machine", press.to_str().unwrap(), "--calib", &c, "--holdout", &c, "--out", &o]);
    assert!(e.contains("key 'machine' is \"hammer\"") && e.contains("screw_press"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
