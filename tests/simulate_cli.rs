//! `forgemon simulate` at the process boundary: the built binary, real files, the JSON of
//! docs/interfaces.md §4, and clear errors with a non-zero exit on bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

const HAMMER: &str = "config/hammer-lg1000.machine.toml";
const PRESS: &str = "config/screw-press-spr400.machine.toml";
const STEEL: &str = "config/steel-16NiCrMo13.process.toml";
const COPPER: &str = "config/copper-cu99.process.toml";

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).current_dir(root()).args(args).output().expect("run forgemon")
}

fn json_of(args: &[&str]) -> Value {
    let out = forgemon(args);
    assert!(out.status.success(), "forgemon {args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("stdout is one JSON object")
}

/// A failing run: non-zero exit, no panic, and stderr naming every `needle`.
fn fails_naming(args: &[&str], needles: &[&str]) {
    let out = forgemon(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "forgemon {args:?} should fail");
    assert!(!err.contains("panicked"), "forgemon {args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr of {args:?} should name '{n}': {err}");
    }
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("forgemon-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn f(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or_else(|| panic!("{k} is not a number in {v}"))
}

#[test]
fn contract_json_has_every_field_and_the_ledger_closes() {
    let v = json_of(&["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9,5.3", "--json"]);
    let blows = v["blows"].as_array().unwrap();
    assert_eq!(blows.len(), 2);
    for (i, b) in blows.iter().enumerate() {
        assert_eq!(b["blow"].as_u64(), Some(i as u64 + 1));
        for k in [
            "v0_mps",
            "h_start_m",
            "h_end_m",
            "final_load_N",
            "peak_load_N",
            "forming_time_s",
            "spring_back_time_s",
            "efficiency",
        ] {
            assert!(b[k].is_number(), "{k} missing in {b}");
        }
        let e = &b["energy"];
        let sum: f64 = ["plastic_J", "friction_J", "damped_J", "elastic_J"].iter().map(|k| f(e, k)).sum();
        // docs/interfaces.md §4: the five terms add up to kinetic_in_J within 1 %.
        assert!((sum / f(e, "kinetic_in_J") - 1.0).abs() < 0.01, "{e}");
        assert!((f(b, "efficiency") - f(e, "plastic_J") / f(e, "kinetic_in_J")).abs() < 1e-12);
        assert!((0.0..=1.0).contains(&f(b, "efficiency")));
    }
    // docs/interfaces.md §4: the final height of blow i is the start height of blow i+1.
    assert_eq!(f(&blows[1], "h_start_m"), f(&blows[0], "h_end_m"));
    assert_eq!(f(&blows[0], "h_start_m"), 0.112);
    // Kinetic energy in is ½ (m1 + m2) v0² (DESIGN.md §2.4) with the Table 1 masses.
    assert!((f(&blows[0]["energy"], "kinetic_in_J") - 0.5 * 751.0 * 3.9 * 3.9).abs() < 1e-9);
    // The process sheet's measured height after blow 1 is echoed beside the simulated one.
    assert_eq!(f(&blows[0], "measured_h_end_m"), 0.089);
}

#[test]
fn table_output_has_a_line_per_blow() {
    let out = forgemon(&["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9,5.3,5.3"]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 4, "{text}");
    assert!(text.lines().next().unwrap().contains("efficiency"));
}

#[test]
fn bare_strike_reports_peak_and_contact_time() {
    let v = json_of(&["simulate", "--machine", PRESS, "--bare", "--v0", "0.363", "--json"]);
    let s = &v["strikes"][0];
    // Press paper §3.2: 4993 kN simulated; ±3 % (issue #2).
    assert!((f(s, "peak_load_N") / 4993e3 - 1.0).abs() < 0.03, "{s}");
    assert!(f(s, "contact_time_s") > 0.02 && f(s, "contact_time_s") < 0.035, "{s}");
}

#[test]
fn effects_on_the_command_line_change_the_blows_they_should() {
    let args = ["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9,3.9", "--json"];
    let base = json_of(&args);
    let mut with = args.to_vec();
    with.extend(["--effect", "thermal:q_dT=0.3"]);
    let cold = json_of(&with);
    assert_eq!(cold["effects"][0].as_str().unwrap().split(':').next(), Some("thermal"));
    // Thermal leaves blow 1 alone (exp(q_dT * 0)) and hardens blow 2.
    assert_eq!(base["blows"][0], cold["blows"][0]);
    assert!(f(&cold["blows"][1], "h_end_m") > f(&base["blows"][1], "h_end_m"));
}

#[test]
fn monte_carlo_is_deterministic_per_seed_and_brackets_the_nominal_blow() {
    let args = [
        "simulate",
        "--machine",
        HAMMER,
        "--process",
        STEEL,
        "--v0",
        "3.9",
        "--monte-carlo",
        "300",
        "--seed",
        "7",
        "--json",
    ];
    let a = json_of(&args);
    let b = json_of(&args);
    assert_eq!(a, b, "same seed, same bands");
    let mc = &a["monte_carlo"];
    assert_eq!(mc["runs"].as_u64(), Some(300));
    assert_eq!(mc["failed"].as_u64(), Some(0));
    let band = &mc["blows"][0]["final_load_N"];
    let nominal = f(&a["blows"][0], "final_load_N");
    assert!(f(band, "p2_5") < nominal && nominal < f(band, "p97_5"), "{band} vs {nominal}");
    // The load error alone is ±300 kN at 95 % (paper Table 2): the band is at least that wide.
    assert!(f(band, "p97_5") - f(band, "p2_5") > 2.0 * 300e3 * 0.8, "{band}");
    let mut other = args.to_vec();
    other[8] = "8";
    assert_ne!(json_of(&other)["monte_carlo"], a["monte_carlo"]);
}

#[test]
fn trace_csv_holds_the_blow() {
    let path = tmp("trace.csv");
    let p = path.to_str().unwrap();
    let v = json_of(&[
        "simulate",
        "--machine",
        HAMMER,
        "--process",
        STEEL,
        "--v0",
        "3.9,5.3",
        "--json",
        "--trace",
        p,
        "--trace-dt",
        "1e-6",
    ]);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("blow,t_s,load_N,billet_load_N,x_upper_m,x_lower_m,h_m"));
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    for blow in [1.0, 2.0] {
        let r: Vec<&Vec<f64>> = rows.iter().filter(|r| r[0] == blow).collect();
        assert!(r.windows(2).all(|w| w[1][1] > w[0][1]), "time increases within blow {blow}");
        // Sampled at 1 µs, the trace's largest load is within 0.5 % of the exact peak.
        let peak = r.iter().map(|r| r[2]).fold(f64::MIN, f64::max);
        let exact = f(&v["blows"][blow as usize - 1], "peak_load_N");
        assert!((peak / exact - 1.0).abs() < 0.005, "{peak} vs {exact}");
        // The smallest height in the trace is the blow's final height.
        let h_min = r.iter().map(|r| r[6]).fold(f64::MAX, f64::min);
        assert!((h_min - f(&v["blows"][blow as usize - 1], "h_end_m")).abs() < 1e-8);
    }
}

#[test]
fn copper_on_the_press_runs_through_the_cli() {
    let v = json_of(&["simulate", "--machine", PRESS, "--process", COPPER, "--v0", "0.346,0.346,0.346", "--json"]);
    let effs: Vec<f64> = v["blows"].as_array().unwrap().iter().map(|b| f(b, "efficiency")).collect();
    assert!(effs.windows(2).all(|w| w[1] < w[0]), "{effs:?}");
}

#[test]
fn bad_files_and_flags_name_the_file_and_key() {
    fails_naming(
        &["simulate", "--machine", "config/nope.toml", "--process", STEEL, "--v0", "3.9"],
        &["config/nope.toml", "cannot read"],
    );
    let bad = tmp("bad.machine.toml");
    std::fs::write(&bad, "kind = \"hammer\"\nm1_kg = 732\nm2_kg = 19\nk_N_per_m = 3.15e9\n").unwrap();
    let b = bad.to_str().unwrap();
    fails_naming(&["simulate", "--machine", b, "--process", STEEL, "--v0", "3.9"], &[b, "missing key 'c_Ns_per_m'"]);
    std::fs::write(&bad, "kind = \"hammer\"\nm1_kg = = 732\n").unwrap();
    fails_naming(&["simulate", "--machine", b, "--process", STEEL, "--v0", "3.9"], &[b, "not valid TOML", "line 2"]);
    std::fs::write(&bad, "kind = \"hammer\"\nm1_kg = 732\nm2_kg = 0\nk_N_per_m = 3.15e9\nc_Ns_per_m = 1\n").unwrap();
    fails_naming(
        &["simulate", "--machine", b, "--process", STEEL, "--v0", "3.9"],
        &[b, "'m2_kg' must be finite and > 0"],
    );
    fails_naming(&["simulate", "--machine", PRESS, "--process", STEEL, "--v0", "0.3"], &[STEEL, "'machine'", PRESS]);
    fails_naming(
        &["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9", "--effect", "gap:gap_m=1"],
        &["--effect gap:gap_m=1", "unknown effect 'gap'"],
    );
    let die = "clearance:gap_m=3e-4,m_lower_kg=800";
    fails_naming(
        &["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9", "--effect", die],
        &[die, "m_lower_kg does not apply to a hammer", "m2_kg"],
    );
    fails_naming(&["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "-3.9"], &["--v0", "-3.9"]);
    fails_naming(&["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "fast"], &["--v0", "fast"]);
    fails_naming(&["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9", "--rtol", "0"], &["--rtol"]);
    fails_naming(
        &["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9", "--monte-carlo", "1"],
        &["--monte-carlo", "at least 2"],
    );
    let sheet = tmp("bad.process.toml");
    std::fs::write(
        &sheet,
        std::fs::read_to_string(root().join(STEEL)).unwrap().replace("sigma0_Pa = 90e6", "sigma0_Pa = \"hot\""),
    )
    .unwrap();
    let s = sheet.to_str().unwrap();
    fails_naming(
        &["simulate", "--machine", HAMMER, "--process", s, "--v0", "3.9"],
        &[s, "material.sigma0_Pa", "must be a number"],
    );
    let empty = tmp("empty.process.toml");
    std::fs::write(&empty, "").unwrap();
    let e = empty.to_str().unwrap();
    fails_naming(&["simulate", "--machine", HAMMER, "--process", e, "--v0", "3.9"], &[e, "missing key 'machine'"]);
}
