//! Issue 37: the loop closed. Billets rendered with a hidden effect by the independent
//! renderer; `forgemon diagnose` on a calibration billet writes the machine with its
//! verdict adopted; the holdout billet replayed with that machine gives every blow's
//! efficiency within 0.02 of the truth, where the base machine misses.

mod independent;

use std::path::Path;
use std::process::Command;

use independent::captures::{Rendered, render, write_dir};
use independent::{HAMMER, Hidden, Kind, PRESS, speeds};
use serde_json::Value;

fn forgemon(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().expect("forgemon runs")
}

/// The efficiencies `forgemon replay DIR --machine M --json` gives.
fn efficiencies(dir: &Path, machine: &Path) -> Vec<Option<f64>> {
    let out = forgemon(&["replay", dir.to_str().unwrap(), "--machine", machine.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap()["efficiency"].as_f64())
        .collect()
}

fn worst(got: &[Option<f64>], r: &Rendered) -> f64 {
    if got.len() != r.truth.len() {
        return f64::NAN;
    }
    got.iter().zip(&r.truth).map(|(e, t)| e.map_or(f64::INFINITY, |e| (e - t.efficiency()).abs())).fold(0.0, f64::max)
}

/// One case: (verdict, base error, adopted error).
fn case(kind: Kind, hidden: Hidden, khz: f64, seed: u64) -> (String, f64, f64) {
    let tmp = tempfile::tempdir().unwrap();
    // FORGEMON_ADOPT_KEEP=DIR keeps each case's directories under DIR, to look into.
    let root = match std::env::var("FORGEMON_ADOPT_KEEP") {
        Ok(dir) => {
            let d = Path::new(&dir).join(format!(
                "{}-{}-{khz}",
                if kind == Kind::Hammer { "hammer" } else { "press" },
                hidden.library_name()
            ));
            let _ = std::fs::remove_dir_all(&d);
            std::fs::create_dir_all(&d).unwrap();
            d
        }
        Err(_) => tmp.path().to_path_buf(),
    };
    let (v_cal, v_hold) = speeds(kind);
    let machine = if kind == Kind::Hammer { HAMMER } else { PRESS };
    let cal = render(kind, &hidden, &v_cal, 1.0, khz * 1e3, seed);
    let hold = render(kind, &hidden, &v_hold, 0.97, khz * 1e3, seed + 1);
    let (c, h, o) = (root.join("calib"), root.join("holdout"), root.join("out"));
    write_dir(&c, &cal, machine);
    write_dir(&h, &hold, machine);
    let base = c.join("machine.toml");
    let out = forgemon(&[
        "diagnose",
        "--machine",
        base.to_str().unwrap(),
        "--calib",
        c.to_str().unwrap(),
        "--holdout",
        h.to_str().unwrap(),
        "--out",
        o.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let verdict =
        stdout.lines().find_map(|l| l.strip_prefix("verdict: ")).unwrap_or("?").split(' ').next().unwrap().to_string();
    let base_err = worst(&efficiencies(&h, &base), &hold);
    let adopted = o.join("machine.toml");
    let adopted_err = if adopted.exists() { worst(&efficiencies(&h, &adopted), &hold) } else { base_err };
    (verdict, base_err, adopted_err)
}

/// The independent renderer's cases, and the effects it renders for this test only.
fn all_cases() -> Vec<(&'static str, Kind, Hidden)> {
    let mut cases = independent::cases();
    for (kind, k) in [(Kind::Hammer, "hammer"), (Kind::Press, "press")] {
        let more = [
            ("hardening", Hidden::Hardening { n: 0.2, eps_ref: 0.1 }),
            ("thermal", Hidden::Thermal { q: 0.06 }),
            ("highpass", Hidden::Highpass { tau_s: 0.03 }),
        ];
        for (name, h) in more {
            cases.push((Box::leak(format!("{k}-{name}").into_boxed_str()), kind, h));
        }
    }
    cases
}

#[test]
#[ignore = "a table for the note: cargo test --release --test diagnose_adopt -- --ignored --nocapture"]
fn table() {
    let only = std::env::var("FORGEMON_ADOPT_CASES").unwrap_or_default();
    for (name, kind, hidden) in
        all_cases().into_iter().filter(|(n, _, _)| only.is_empty() || only.split(',').any(|o| n.contains(o)))
    {
        for khz in [100.0, 10.0] {
            let (v, b, a) = case(kind, hidden, khz, 36);
            println!("{name:<20} {khz:>5} kHz  verdict {v:<32} base {b:.3}  adopted {a:.3}");
        }
    }
}

/// The loop on the cases CI runs: every effect of the library and none, on the hammer at
/// 100 kHz (its observer's rate) and 10 kHz (fitted), and on the press at 10 kHz; among them
/// the four (a moving foundation, a piezo's high-pass, rising friction on either
/// machine). The verdict names the hidden effect (any verdict where none is hidden), and the
/// holdout billet replayed with the adopted machine has every blow within
/// `EFFICIENCY_TOL` of the truth. The whole table, the press at 100 kHz and the press
/// without an effect too (15 min on 2 cores), is `table` above. The machine files declare
/// the renderer's anti-alias filter (`independent::HAMMER`): without it the hammer's
/// foundation at 10 kHz got verdict none (shrink 0.28). The closest to the goal is the
/// hammer's rising friction at 10 kHz: 0.019 against a base error of 0.216 (its exponent
/// fitted at 0.76 there, 0.80 at 100 kHz, hidden 0.8; 0.020–0.021 before the estimator
/// read `[daq]`).
#[test]
fn an_adopted_verdict_brings_every_holdout_blow_within_0_02_of_the_truth() {
    let mut failures = Vec::new();
    for (name, kind, hidden) in all_cases() {
        let rates: &[f64] = match (kind, hidden) {
            (Kind::Hammer, _) => &[100.0, 10.0],
            // The press without an effect costs a diagnosis of 8 min (no candidate is
            // pruned); `table` runs it.
            (Kind::Press, Hidden::None) => &[],
            (Kind::Press, _) => &[10.0],
        };
        for &khz in rates {
            let (verdict, base, adopted) = case(kind, hidden, khz, 36);
            println!("{name:<20} {khz:>5} kHz  verdict {verdict:<20} base {base:.3}  adopted {adopted:.3}");
            let named = hidden == Hidden::None || verdict == hidden.library_name();
            if !named || adopted > EFFICIENCY_TOL {
                failures.push(format!(
                    "{name} at {khz} kHz: verdict {verdict}, adopted error {adopted:.3} (base {base:.3})"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Issue 16's accuracy target for a blow's efficiency (`tests/estimate_rates.rs`), which
/// issue 37 asks of the adopted model.
const EFFICIENCY_TOL: f64 = 0.02;
