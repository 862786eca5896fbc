//! Issue 37: the model-health alert fires when the model does not fit. Billets rendered by
//! the independent renderer with and without hidden effects, replayed with the base machine:
//! the flow-stress scale each blow's work needs (`flow_stress_scale`) stays put over a
//! billet while the model fits, and drifts when a load-side effect is missing; the load the
//! model fitted to each blow misses (`model_residual`) stays near the noise while the model
//! fits, and grows when an effect is missing.

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
    /// Largest `model_residual` over the billet.
    residual: f64,
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
    /// The model-health alert's residual and its phases (impact, forming, spring-back).
    by_phase: Option<(f64, [f64; 3])>,
    /// Whether a blow was implausible (its alert names the failed check instead).
    implausible: bool,
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
    let implausible = blows.iter().any(|b| b["class"] == "implausible");
    let first = |kind: &str| blows.iter().find(|b| b["alert"]["kind"] == kind).and_then(|b| b["blow"].as_u64());
    let watched = blows.iter().skip(1).all(|b| b["height_source"] == "encoder");
    let by_half = blows.iter().find(|b| b["alert"]["kind"] == "model_health").and_then(|b| {
        let f = &b["alert"]["figures"];
        let half = |k: &str| f[format!("flow_stress_scale_drift_{k}_half")].as_f64();
        Some((f["flow_stress_scale_drift"].as_f64()?, half("first")?, half("second")?))
    });
    let residual = blows.iter().filter_map(|b| b["model_residual"].as_f64()).fold(0.0, f64::max);
    let by_phase = blows.iter().find(|b| b["alert"]["kind"] == "model_health").and_then(|b| {
        let f = &b["alert"]["figures"];
        let p = |k: &str| f[format!("model_residual_{k}")].as_f64();
        Some((f["model_residual"].as_f64()?, [p("impact")?, p("forming")?, p("spring_back")?]))
    });
    Seen {
        drift,
        residual,
        err,
        health: first("model_health"),
        elastic: first("elastic_blow"),
        watched,
        by_half,
        by_phase,
        implausible,
    }
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
                    "{name:<20} {khz:>5} kHz seed {seed:>3}  drift {:.4}  residual {:.4}  eff err {:.3}  model_health {:?}  \
                     elastic {:?}",
                    s.drift, s.residual, s.err, s.health, s.elastic
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

/// No false alarm: billets without an effect, both machines, at 100, 20, 10 and 5 kHz, on
/// the report seeds (32 billets, 160 blows), raise no model-health alert. The largest
/// residual and drift are printed: the margin to the limits (`AlertConfig`).
#[test]
fn billets_the_model_fits_raise_no_model_health_alert() {
    let mut alarms = Vec::new();
    for kind in [Kind::Hammer, Kind::Press] {
        for khz in [100.0, 20.0, 10.0, 5.0] {
            for seed in REPORT_SEEDS {
                let s = billet(kind, Hidden::None, khz, seed);
                println!(
                    "{kind:?} {khz} kHz seed {seed}: drift {:.4}, residual {:.4}, model_health {:?}",
                    s.drift, s.residual, s.health
                );
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
/// (report seed 21; the hammer at 100 and 10 kHz, the press at 10 kHz), whether the heights
/// came from the encoder or, where the effect moved the base model's end height beyond the
/// continuity check's allowance (a foundation, a compliant contact), from the calipers. The
/// alert names where the model and the measurement part: the load's residual by phase of
/// the blow (impact, forming, spring-back), or the drift by half of the stroke, whose halves
/// bracket the blow's drift; an implausible blow's alert names the check it failed.
#[test]
fn every_effect_that_moves_an_efficiency_raises_the_model_health_alert() {
    let mut missed = Vec::new();
    let mut shown = 0;
    let mut from_calipers = Vec::new();
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
            if !first {
                missed.push(format!("{name} at {khz} kHz: {s:?}"));
                continue;
            }
            shown += 1;
            if !s.watched {
                from_calipers.push(name.clone());
            }
            match (s.by_phase, s.by_half) {
                (Some((r, [a, b, c])), _) => {
                    if !([r, a, b, c].iter().all(|x| x.is_finite()) && a.max(b).max(c) > 0.0) {
                        missed.push(format!("{name} at {khz} kHz: no residual by phase: {s:?}"));
                    }
                }
                (None, Some((d, a, b))) => {
                    if d < a.min(b) - 1e-9 || d > a.max(b) + 1e-9 {
                        missed.push(format!("{name} at {khz} kHz: drift {d} outside its halves' {a}, {b}"));
                    }
                }
                (None, None) if s.implausible => {}
                (None, None) => missed.push(format!("{name} at {khz} kHz: the alert names no phase: {s:?}")),
            }
        }
    }
    assert!(shown >= 11, "only {shown} cases that move an efficiency by more than 0.02 are seen");
    // The fitted model's residual sees where the drift cannot: the hammer's foundation at
    // 100 kHz, the press's foundation and compliant contact, whose heights the calipers gave.
    println!("seen with heights from the calipers: {from_calipers:?}");
    assert!(from_calipers.len() >= 3, "{from_calipers:?}");
    assert!(missed.is_empty(), "{missed:#?}");
}
