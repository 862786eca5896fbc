//! `forgemon identify` end to end (issue #5), as a user runs it: reference captures made by
//! `forgemon simulate --captures` from machines that are not the papers' (sensor noise,
//! load offset, 10 µm encoder and the approach included), identified back.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const STEEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/steel-16NiCrMo13.process.toml");

/// A hammer unlike the paper's (Table 1: 732 kg, 19 kg, 3.15e9 N/m, 18540 N s/m).
const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n";
/// A press unlike the paper's Table 3.
const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
                     c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n";

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("forgemon-identify-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn ok(out: &Output) -> String {
    assert!(out.status.success(), "{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Three steel blows of the hammer (4.2, 5.0, 5.3 m/s) on a sheet without measured
/// heights, so each blow starts where the simulated one before it ended.
fn hammer_captures(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("truth.machine.toml"), HAMMER).unwrap();
    let steel = std::fs::read_to_string(STEEL).unwrap();
    let sheet = &steel[..steel.find("[[blows]]").unwrap_or(steel.len())];
    std::fs::write(dir.join("steel.process.toml"), sheet).unwrap();
    let caps = dir.join("captures");
    ok(&forgemon(&[
        "simulate",
        "--machine",
        dir.join("truth.machine.toml").to_str().unwrap(),
        "--process",
        dir.join("steel.process.toml").to_str().unwrap(),
        "--v0",
        "4.2,5.0,5.3",
        "--captures",
        caps.to_str().unwrap(),
    ]));
    caps
}

fn value(toml_text: &str, key: &str) -> f64 {
    let t: toml::Table = toml_text.parse().unwrap();
    t[key].as_float().or_else(|| t[key].as_integer().map(|i| i as f64)).unwrap()
}

fn determined(toml_text: &str, key: &str) -> bool {
    let t: toml::Table = toml_text.parse().unwrap();
    t["identify"]["determined"][key].as_bool().unwrap()
}

fn identify(caps: &Path, out: &Path, extra: &[&str]) -> (String, String) {
    let mut args = vec!["identify", "--reference", caps.to_str().unwrap(), "-o", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let stdout = ok(&forgemon(&args));
    (stdout, std::fs::read_to_string(out).unwrap())
}

#[test]
fn a_hammer_is_identified_from_one_billet_blow_and_predicts_the_others() {
    let dir = scratch("hammer");
    let caps = hammer_captures(&dir);
    let out = dir.join("fitted.machine.toml");
    let (stdout, fitted) = identify(&caps, &out, &["--kind", "hammer", "--fit-blows", "1"]);
    eprintln!("{stdout}");
    // The bound: within 5 % for every parameter the data determines. One blow on a
    // billet determines all four: the ram mass carries the blow's momentum (the load's
    // impulse against the impact speed), the lower tool's mass and spring set the ~2 kHz
    // ring's frequency and its share of the load, and the damper its decay; so all four must
    // be called determined and be within the bound.
    let truth: toml::Table = HAMMER.parse().unwrap();
    for key in ["m1_kg", "m2_kg", "k_N_per_m", "c_Ns_per_m"] {
        let t = truth[key].as_float().or_else(|| truth[key].as_integer().map(|i| i as f64)).unwrap();
        let v = value(&fitted, key);
        assert!(determined(&fitted, key), "{key} should be determined\n{fitted}");
        assert!((v / t - 1.0).abs() < 0.05, "{key}: {v} vs {t}\n{fitted}");
    }
    // The fitted file is a machine file every other command reads.
    ok(&forgemon(&["simulate", "--machine", out.to_str().unwrap(), "--process", STEEL, "--v0", "3.9"]));
    // Blows 2 and 3 (faster, on a shorter billet) are predicted no worse than blow 1 is
    // fitted plus the sensor noise (2 kN sd, CaptureSpec::hammer, over a ~1 MN peak).
    let t: toml::Table = fitted.parse().unwrap();
    let fit = t["identify"]["rms_load_error"].as_float().unwrap();
    let held = t["identify"]["rms_load_error_held_out"].as_float().unwrap();
    assert!(held <= fit + 2e3 / 1e6, "held out {held} vs fit {fit}");
    // The report is written next to it.
    let html = std::fs::read_to_string(out.with_extension("html")).unwrap();
    assert!(html.contains("m1_kg") && html.contains("<svg"), "a report with plots");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_press_is_identified_from_three_bare_strikes() {
    let dir = scratch("press");
    std::fs::write(dir.join("truth.machine.toml"), PRESS).unwrap();
    let caps = dir.join("bare");
    ok(&forgemon(&[
        "simulate",
        "--machine",
        dir.join("truth.machine.toml").to_str().unwrap(),
        "--bare",
        "--v0",
        "0.30,0.36,0.42",
        "--captures",
        caps.to_str().unwrap(),
    ]));
    let out = dir.join("fitted.machine.toml");
    let (stdout, fitted) = identify(&caps, &out, &["--kind", "screw_press", "--bare"]);
    eprintln!("{stdout}");
    let truth: toml::Table = PRESS.parse().unwrap();
    // Both masses, both springs and the link damper are determined: the three strikes' peaks
    // and the ~300 Hz ring's frequency, share and decay each depend on them, and the press
    // paper identifies all of them from bare strikes. Each must be within the 5 %.
    for key in ["m_tool_kg", "m_ram_kg", "k_link_N_per_m", "c_link_Ns_per_m", "k_frame_N_per_m"] {
        let t = truth[key].as_float().or_else(|| truth[key].as_integer().map(|i| i as f64)).unwrap();
        let v = value(&fitted, key);
        assert!(determined(&fitted, key), "{key} should be determined\n{fitted}");
        assert!((v / t - 1.0).abs() < 0.05, "{key}: {v} vs {t}\n{fitted}");
    }
    // The frame damper is built not to be: its time constant c / (k_frame + k_sensor) is
    // 1.2 µs, under the 3 µs below which the plant folds the frame node into the series
    // springs (`physics::plant::NODE_MIN_TAU_S`), so no load the model makes depends on it.
    // The tool must say so, and the verdict must be right: the load is independent of it.
    assert!(!determined(&fitted, "c_frame_Ns_per_m"), "c_frame cannot be determined\n{fitted}");
    not_determined_is_flat(&dir, &fitted, "c_frame_Ns_per_m", &[0.0, 1e5], "c_link_Ns_per_m");
    // The sensor stiffness is held at its data-sheet value (press paper §2.3).
    assert_eq!(value(&fitted, "k_sensor_N_per_m"), 3.39e10);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The fitted press's bare strikes with one key replaced, as `simulate --trace` samples them.
/// Each sample: (whether it belongs to the first strike, load in N).
fn bare_trace(dir: &Path, fitted: &str, key: &str, v: f64) -> Vec<(bool, f64)> {
    let machine = dir.join(format!("{key}-{v}.machine.toml"));
    let text: String = fitted
        .lines()
        .take_while(|l| !l.starts_with("[identify"))
        .map(|l| if l.starts_with(&format!("{key} =")) { format!("{key} = {v:e}\n") } else { format!("{l}\n") })
        .collect();
    std::fs::write(&machine, text).unwrap();
    let csv = dir.join(format!("{key}-{v}.csv"));
    let (m, c) = (machine.to_str().unwrap(), csv.to_str().unwrap());
    ok(&forgemon(&[
        "simulate",
        "--machine",
        m,
        "--bare",
        "--v0",
        "0.30,0.36,0.42",
        "--trace",
        c,
        "--trace-dt",
        "5e-5",
    ]));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let col = lines.next().unwrap().split(',').position(|h| h == "load_N").unwrap();
    lines.map(|l| (l.starts_with("1,"), l.split(',').nth(col).unwrap().parse().unwrap())).collect()
}

/// The check of a "not determined" verdict from another path than identify's Jacobian:
/// the simulator's load with `key` at each of `values` is the same as with the fitted value
/// to 1 N, far below the captures' 5 kN noise, so no data of this kind could determine it;
/// whereas `control`, a determined parameter, moved by the 5 % that separates the verdicts,
/// moves the load by more than the noise.
fn not_determined_is_flat(dir: &Path, fitted: &str, key: &str, values: &[f64], control: &str) {
    let base = bare_trace(dir, fitted, key, value(fitted, key));
    for &v in values {
        let other = bare_trace(dir, fitted, key, v);
        assert_eq!(other.len(), base.len(), "{key} = {v} changes the strikes' length");
        let worst = base.iter().zip(&other).map(|(a, b)| (a.1 - b.1).abs()).fold(0.0, f64::max);
        assert!(worst < 1.0, "{key} = {v} moves the load by {worst} N: the data could see it");
    }
    // The first strike only: the control may change the strikes' lengths.
    let moved = bare_trace(dir, fitted, control, value(fitted, control) * 1.05);
    let first = |t: &[(bool, f64)]| t.iter().take_while(|p| p.0).map(|p| p.1).collect::<Vec<f64>>();
    let worst = first(&base).iter().zip(&first(&moved)).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(worst > 5e3, "{control} × 1.05 moves the load by only {worst} N");
}

#[test]
fn five_starting_guesses_give_the_same_parameters() {
    let dir = scratch("starts");
    let caps = hammer_captures(&dir);
    // Priors from half to twice the paper's machine, each parameter its own way.
    let guesses = [
        (732.0, 19.0, 3.15e9, 18540.0),
        (400.0, 35.0, 1.8e9, 9000.0),
        (1400.0, 10.0, 6.0e9, 40000.0),
        (600.0, 12.0, 5.0e9, 30000.0),
        (1200.0, 30.0, 2.0e9, 10000.0),
    ];
    let mut results: Vec<[f64; 4]> = Vec::new();
    for (i, (m1, m2, k, c)) in guesses.iter().enumerate() {
        let prior = dir.join(format!("prior{i}.machine.toml"));
        std::fs::write(
            &prior,
            format!("kind = \"hammer\"\nm1_kg = {m1}\nm2_kg = {m2}\nk_N_per_m = {k}\nc_Ns_per_m = {c}\n"),
        )
        .unwrap();
        let out = dir.join(format!("fit{i}.machine.toml"));
        let seed = (i + 11).to_string();
        // One start: the guess itself, so that each fit is one local search from it.
        let (_, fitted) = identify(
            &caps,
            &out,
            &[
                "--kind",
                "hammer",
                "--fit-blows",
                "1",
                "--initial",
                prior.to_str().unwrap(),
                "--seed",
                &seed,
                "--starts",
                "1",
            ],
        );
        results.push(["m1_kg", "m2_kg", "k_N_per_m", "c_Ns_per_m"].map(|k| value(&fitted, k)));
    }
    // The bound: the same parameters within 1 %.
    for r in &results[1..] {
        for (j, (a, b)) in r.iter().zip(&results[0]).enumerate() {
            assert!((a / b - 1.0).abs() < 0.01, "parameter {j}: {a} vs {b}; all: {results:?}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_reference_data_gives_a_clear_error() {
    let dir = scratch("bad");
    let caps = hammer_captures(&dir);
    let out = dir.join("x.machine.toml");
    let err = |args: &[&str]| {
        let o = forgemon(args);
        assert!(!o.status.success());
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!e.contains("panicked"), "{e}");
        e
    };
    let (c, o) = (caps.to_str().unwrap(), out.to_str().unwrap());
    // Wrong kind: the process sheet is a hammer's.
    let e = err(&["identify", "--kind", "screw_press", "--reference", c, "-o", o]);
    assert!(e.contains("key 'machine' is \"hammer\"") && e.contains("--kind is screw_press"), "{e}");
    // A billet reference without its sheet.
    let e = err(&["identify", "--kind", "hammer", "--reference", c, "--process", "/nonexistent.toml", "-o", o]);
    assert!(e.contains("no process sheet"), "{e}");
    // No blow: the ram standing still.
    let idle = dir.join("idle");
    std::fs::create_dir_all(&idle).unwrap();
    let mut csv = String::from("t_s,load_N,disp_m,acc_mps2\n");
    for i in 0..20000 {
        csv.push_str(&format!("{:.6},{},0.4,{}\n", i as f64 * 1e-5, (i % 7) as f64 * 300.0, (i % 5) as f64 * 0.3));
    }
    std::fs::write(idle.join("blow_01.csv"), csv).unwrap();
    std::fs::copy(caps.join("process.toml"), idle.join("process.toml")).unwrap();
    let e = err(&["identify", "--kind", "hammer", "--reference", idle.to_str().unwrap(), "-o", o]);
    assert!(e.contains("no blow found"), "{e}");
    // A clipped load sensor: full scale at 600 kN.
    let clipped = dir.join("clipped");
    std::fs::create_dir_all(&clipped).unwrap();
    let text = std::fs::read_to_string(caps.join("blow_01.csv")).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let col = header.split(',').position(|h| h == "load_N").unwrap();
    let mut out_csv = format!("{header}\n");
    for line in lines {
        let mut f: Vec<String> = line.split(',').map(String::from).collect();
        let v: f64 = f[col].parse().unwrap();
        f[col] = format!("{}", v.min(600e3));
        out_csv.push_str(&f.join(","));
        out_csv.push('\n');
    }
    std::fs::write(clipped.join("blow_01.csv"), out_csv).unwrap();
    std::fs::copy(caps.join("process.toml"), clipped.join("process.toml")).unwrap();
    let e = err(&["identify", "--kind", "hammer", "--reference", clipped.to_str().unwrap(), "-o", o]);
    assert!(e.contains("blow_01.csv") && e.contains("clipped at 600"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Refits of the hammer (`hammer_captures`' machine and blows, blow 1 fitted, one local
/// search from the default prior) on captures differing only in their noise `seed`s: for
/// each parameter, z = ln(fitted / truth) / (the reported relative standard error), since
/// the fit's parameters and covariance are in ln p (`identify::fit::uncertainty`).
fn refit_z(seeds: std::ops::RangeInclusive<u64>) -> Vec<[f64; 4]> {
    let dir = scratch(&format!("se-{}", seeds.start()));
    std::fs::write(dir.join("truth.machine.toml"), HAMMER).unwrap();
    let steel = std::fs::read_to_string(STEEL).unwrap();
    std::fs::write(dir.join("steel.process.toml"), &steel[..steel.find("[[blows]]").unwrap_or(steel.len())]).unwrap();
    let truth: toml::Table = HAMMER.parse().unwrap();
    let keys = ["m1_kg", "m2_kg", "k_N_per_m", "c_Ns_per_m"];
    let mut out = Vec::new();
    for seed in seeds {
        let caps = dir.join(format!("captures-{seed}"));
        let (m, p, c) = (dir.join("truth.machine.toml"), dir.join("steel.process.toml"), caps.to_str().unwrap());
        let (m, p, s) = (m.to_str().unwrap(), p.to_str().unwrap(), seed.to_string());
        ok(&forgemon(&[
            "simulate",
            "--machine",
            m,
            "--process",
            p,
            "--v0",
            "4.2,5.0,5.3",
            "--captures",
            c,
            "--capture-seed",
            &s,
        ]));
        let out_file = dir.join(format!("fit-{seed}.machine.toml"));
        let (_, fitted) = identify(
            &caps,
            &out_file,
            &["--kind", "hammer", "--fit-blows", "1", "--starts", "1", "--monte-carlo", "0"],
        );
        let t: toml::Table = fitted.parse().unwrap();
        out.push(keys.map(|k| {
            let v = value(&fitted, k);
            let se = t["identify"]["std_error"][k].as_float().unwrap() / v;
            let truth_v = truth[k].as_float().or_else(|| truth[k].as_integer().map(|i| i as f64)).unwrap();
            (v / truth_v).ln() / se
        }));
    }
    let _ = std::fs::remove_dir_all(&dir);
    out
}

/// The fast CI version: 8 refits (seeds 201–208, not looked at before the bound was set).
/// With standard errors that are right, z is standard normal and Σz² over 8 refits is χ²
/// with 8 degrees of freedom; its 0.5 % and 99.5 % points (1.34, 21.95) bound the RMS of z
/// to 0.41–1.66. A standard error half the true spread (RMS z ≈ 2) fails it.
///
/// The ram mass m1 once failed it (RMS z 2.0, coverage 6 of 24 in the harness below): the
/// fit took each blow's impact speed as exact, while m1 follows the momentum, impulse over
/// speed, and the approach's speed is off by about 0.3 mm/s in 4.2 m/s (the accelerometer's
/// 2 m/s² noise in the parabola's curvature, `identify::speed`). The speed's own standard
/// error now enters the covariance, and m1 is checked with the others.
#[test]
fn standard_errors_match_the_spread_over_noise_seeds() {
    let z = refit_z(201..=208);
    for (j, key) in ["m1_kg", "m2_kg", "k_N_per_m", "c_Ns_per_m"].iter().enumerate() {
        let col: Vec<f64> = z.iter().map(|r| r[j]).collect();
        let rms = (col.iter().map(|z| z * z).sum::<f64>() / col.len() as f64).sqrt();
        eprintln!("{key}: RMS z {rms:.2} over {} refits: {col:.2?}", col.len());
        assert!((0.41..=1.66).contains(&rms), "{key}: RMS z {rms:.2}: {col:?}");
    }
}

/// The check: 24 refits (seeds 101–124); the 1-sigma interval should hold 68.3 %
/// of them. The count is binomial(24, 0.683); 11–21 holds it with 98.6 % (each tail under
/// 1 %), so a right standard error fails this test for one parameter in 70. It failed on m1
/// (6 of 24) while the impact speed was taken as exact; with the speed's standard error
/// propagated, m1 holds 17 (see the CI version above; the README gives every parameter).
/// `cargo nextest run --release --test identify --run-ignored only -E 'test(/cover/)' --no-capture`
#[test]
#[ignore = "harness: 24 refits; run by hand"]
fn one_sigma_intervals_cover_68_percent_of_24_refits() {
    let z = refit_z(101..=124);
    let mut failed = Vec::new();
    for (j, key) in ["m1_kg", "m2_kg", "k_N_per_m", "c_Ns_per_m"].iter().enumerate() {
        let inside = z.iter().filter(|r| r[j].abs() <= 1.0).count();
        let rms = (z.iter().map(|r| r[j] * r[j]).sum::<f64>() / z.len() as f64).sqrt();
        eprintln!(
            "{key}: {inside} of {} inside 1 sigma ({:.0} %), RMS z {rms:.2}",
            z.len(),
            100.0 * inside as f64 / z.len() as f64
        );
        if !(11..=21).contains(&inside) {
            failed.push(format!("{key}: {inside} of {}", z.len()));
        }
    }
    assert!(failed.is_empty(), "coverage outside 11-21 of 24: {failed:?}");
}
