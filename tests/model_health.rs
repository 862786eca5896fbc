//! Issue 37: the model-health alert fires when the model does not fit. Billets rendered by
//! the independent renderer with and without hidden effects, replayed with the base machine:
//! the flow-stress scale each blow's work needs (`flow_stress_scale`) stays put over a
//! billet while the model fits, and drifts when a load-side effect is missing.

mod independent;

use std::path::Path;
use std::process::Command;

use independent::captures::{Rendered, render, write_dir};
use independent::{HAMMER, Hidden, Kind, PRESS, speeds};
use serde_json::Value;

/// The replay's JSON lines for `dir` with its own machine file.
fn replay(dir: &Path) -> Vec<Value> {
    let out = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["replay", dir.to_str().unwrap(), "--json"])
        .output()
        .expect("forgemon runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// What the base machine made of a billet.
#[derive(Debug)]
struct Seen {
    /// Largest |scale / first scale − 1| over the billet.
    drift: f64,
    /// Worst |efficiency − truth| (infinite for a blow without one).
    err: f64,
    /// The blow of the first model_health alert, and of the first efficiency alert.
    health: Option<u64>,
    elastic: Option<u64>,
    /// Whether every blow after the first had its start height from the encoder, where the
    /// drift is watched.
    watched: bool,
    /// The model-health alert's drift, and over the first and the second half of the
    /// stroke.
    by_half: Option<(f64, f64, f64)>,
}

fn billet(kind: Kind, hidden: Hidden, khz: f64, seed: u64) -> Seen {
    let tmp = tempfile::tempdir().unwrap();
    let r: Rendered = render(kind, &hidden, &speeds(kind).0, 1.0, khz * 1e3, seed);
    write_dir(tmp.path(), &r, if kind == Kind::Hammer { HAMMER } else { PRESS });
    let blows = replay(tmp.path());
    let scales: Vec<f64> = blows.iter().filter_map(|b| b["flow_stress_scale"].as_f64()).collect();
    let drift = scales.iter().map(|s| (s / scales[0] - 1.0).abs()).fold(0.0, f64::max);
    let err = blows
        .iter()
        .zip(&r.truth)
        .map(|(b, t)| b["efficiency"].as_f64().map_or(f64::INFINITY, |e| (e - t.efficiency()).abs()))
        .fold(0.0, f64::max);
    let first = |kind: &str| blows.iter().find(|b| b["alert"]["kind"] == kind).and_then(|b| b["blow"].as_u64());
    let watched = blows.iter().skip(1).all(|b| b["height_source"] == "encoder");
    let by_half = blows.iter().find(|b| b["alert"]["kind"] == "model_health").and_then(|b| {
        let f = &b["alert"]["figures"];
        let half = |k: &str| f[format!("flow_stress_scale_drift_{k}_half")].as_f64();
        Some((f["flow_stress_scale_drift"].as_f64()?, half("first")?, half("second")?))
    });
    Seen { drift, err, health: first("model_health"), elastic: first("elastic_blow"), watched, by_half }
}

#[test]
#[ignore = "the drift's table: cargo test --release --test model_health -- --ignored --nocapture"]
fn drift_table() {
    let seeds: Vec<u64> = std::env::var("FORGEMON_HEALTH_SEEDS")
        .map(|s| s.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or_else(|_| vec![1, 2, 3]);
    let mut cases = independent::cases();
    for (kind, k) in [(Kind::Hammer, "hammer"), (Kind::Press, "press")] {
        cases.push((
            if k == "hammer" { "hammer-hardening" } else { "press-hardening" },
            kind,
            Hidden::Hardening { n: 0.2, eps_ref: 0.1 },
        ));
        cases.push((if k == "hammer" { "hammer-thermal" } else { "press-thermal" }, kind, Hidden::Thermal { q: 0.06 }));
        cases.push((
            if k == "hammer" { "hammer-highpass" } else { "press-highpass" },
            kind,
            Hidden::Highpass { tau_s: 0.03 },
        ));
    }
    for (name, kind, hidden) in cases {
        for khz in [100.0, 10.0] {
            for &seed in &seeds {
                let s = billet(kind, hidden, khz, seed);
                println!(
                    "{name:<20} {khz:>5} kHz seed {seed:>3}  drift {:.4}  eff err {:.3}  model_health {:?}  elastic {:?}",
                    s.drift, s.err, s.health, s.elastic
                );
            }
        }
    }
}

/// The cases: the independent renderer's, and the effects it renders for issue 37 only.
fn all_cases() -> Vec<(String, Kind, Hidden)> {
    let mut cases: Vec<(String, Kind, Hidden)> =
        independent::cases().into_iter().map(|(n, k, h)| (n.to_string(), k, h)).collect();
    for (kind, k) in [(Kind::Hammer, "hammer"), (Kind::Press, "press")] {
        cases.push((format!("{k}-hardening"), kind, Hidden::Hardening { n: 0.2, eps_ref: 0.1 }));
        cases.push((format!("{k}-thermal"), kind, Hidden::Thermal { q: 0.06 }));
        cases.push((format!("{k}-highpass"), kind, Hidden::Highpass { tau_s: 0.03 }));
    }
    cases
}

/// Seeds the rule is reported on: nothing was tuned on them (the limit's seeds are 1–3).
const REPORT_SEEDS: [u64; 4] = [21, 22, 23, 24];

/// No false alarm: billets without an effect, both machines, 100 and 10 kHz, on the report
/// seeds (16 billets, 80 blows), raise no model-health alert.
#[test]
fn billets_the_model_fits_raise_no_model_health_alert() {
    let mut alarms = Vec::new();
    for kind in [Kind::Hammer, Kind::Press] {
        for khz in [100.0, 10.0] {
            for seed in REPORT_SEEDS {
                let s = billet(kind, Hidden::None, khz, seed);
                println!("{kind:?} {khz} kHz seed {seed}: drift {:.4}, model_health {:?}", s.drift, s.health);
                if s.health.is_some() {
                    alarms.push(format!("{kind:?} at {khz} kHz, seed {seed}: {s:?}"));
                }
            }
        }
    }
    assert!(alarms.is_empty(), "false alarms: {alarms:#?}");
}

/// Every hidden effect that moves a blow's efficiency by more than 0.02 under the base
/// model raises the model-health alert, on or before the blow of any efficiency alert
/// (report seed 21; the hammer at 100 and 10 kHz, the press at 10 kHz), where the drift is
/// watched: on blows whose start height the encoder measured. Where the effect also moves
/// the base model's end height beyond the continuity check's allowance (a foundation, a
/// compliant contact: the next capture's contact is not where the model left the billet),
/// the heights come from the calipers and the drift is not watched; those of them the alert
/// misses are listed, and their number bounded, not hidden. An alert from the observer
/// gives the residual by phase of the stroke, whose halves bracket the blow's drift.
#[test]
fn every_effect_that_moves_an_efficiency_raises_the_model_health_alert() {
    let mut missed = Vec::new();
    let mut unwatched = Vec::new();
    let mut shown = 0;
    let mut split = 0;
    for (name, kind, hidden) in all_cases() {
        let rates: &[f64] = if kind == Kind::Hammer { &[100.0, 10.0] } else { &[10.0] };
        for &khz in rates {
            let s = billet(kind, hidden, khz, REPORT_SEEDS[0]);
            println!("{name:<20} {khz:>5} kHz: {s:?}");
            if s.err <= 0.02 {
                continue;
            }
            let first = match (s.health, s.elastic) {
                (Some(h), Some(e)) => h <= e,
                (Some(_), None) => true,
                (None, _) => false,
            };
            if first {
                shown += 1;
                // The residual by phase: the blow's scale is the law-weighted mean of its two
                // halves' scales, so its drift lies between theirs.
                if let Some((d, a, b)) = s.by_half {
                    split += 1;
                    if d < a.min(b) - 1e-9 || d > a.max(b) + 1e-9 {
                        missed.push(format!("{name} at {khz} kHz: drift {d} outside its halves' {a}, {b}"));
                    }
                }
            } else if !s.watched {
                unwatched.push(format!("{name} at {khz} kHz: {s:?}"));
            } else {
                missed.push(format!("{name} at {khz} kHz: {s:?}"));
            }
        }
    }
    println!("not watched and not seen (heights from the calipers): {unwatched:#?}");
    assert!(shown >= 8, "only {shown} cases that move an efficiency by more than 0.02 are seen");
    // The observer's alerts name the residual by phase (the fit's, at low rates, do not).
    assert!(split >= 5, "only {split} alerts give the drift by phase of the stroke");
    assert!(unwatched.len() <= 3, "{unwatched:#?}");
    assert!(missed.is_empty(), "{missed:#?}");
}
