//! Measured error rates of the verdict rule (issue #17, item 2): an `#[ignore]`d test that
//! prints them, never a CI test (it fits the whole library, minutes per case).
//!
//! The full diagnosis is too slow to repeat over many seeds, so the rates are measured on
//! the decision rule (`verdict::decide`, single effects only, no pairs) applied to per-blow
//! holdout errors from real fits: for each case the whole library is fitted on one
//! calibration billet per calibration seed, then every fitted candidate and the baseline
//! are scored on a holdout billet rendered with each holdout noise seed. So the holdout
//! noise varies over all the seeds and the fit's noise over the calibration seeds.
//!
//! Seeds: the rule was tuned on the set `tune` (calibration seed 101, holdout seeds
//! 1001..=1020) and its rates are reported on the set `report` (calibration seeds 201 and
//! 202, holdout seeds 2001..=2012: 24 seed pairs per case), which was not looked at while
//! choosing the rule. Run:
//!
//! `FORGEMON_RATES_SET=report cargo test --release --lib rates -- --ignored --nocapture`
//!
//! (`FORGEMON_RATES_CASES=hammer-none,press-clearance` runs some cases only.)

use crate::config::{parse_machine, parse_process};
use crate::estimate::EstimatorConfig;
use crate::identify::objective::{Reference, Setting};
use crate::physics::effects::{Effect, EffectSet};
use crate::physics::machine::Machine;
use crate::signal::segment::{SegmentConfig, Segmenter};
use crate::synth::{CaptureSpec, rows_batch, synth_blows};

use super::attribute::{Fitted, fit_candidates, library};
use super::blow_set;
use super::blowset::mean;
use super::verdict::decide;

const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n";
const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
                     c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n";
const STEEL: &str = include_str!("../../config/steel-16NiCrMo13.process.toml");
const COPPER: &str = include_str!("../../config/copper-cu99.process.toml");

/// The shrink a single effect must reach to count in the power (issue #17: "a single effect
/// that shrinks the holdout error by ≥ 0.3 is found in ≥ 95 %").
const POWER_SHRINK: f64 = 0.3;

/// The cases: the withheld-effect suite's machines and billets, with its hidden effects
/// (which shrink the holdout error by 0.9 or more) and weaker ones, down to where the shrink
/// is near the 0.3 (the power is counted only on seed pairs whose true effect
/// shrinks the error by at least `POWER_SHRINK`).
const CASES: [(&str, bool, Option<&str>); 22] = [
    ("hammer-none", false, None),
    ("hammer-clearance", false, Some("clearance:gap_m=0.0001")),
    ("hammer-clearance-20um", false, Some("clearance:gap_m=0.00002")),
    ("hammer-clearance-5um", false, Some("clearance:gap_m=0.000005")),
    ("hammer-elastic", false, Some("elastic_recovery:k_contact_N_per_m=4e9")),
    ("hammer-elastic-2e10", false, Some("elastic_recovery:k_contact_N_per_m=2e10")),
    ("hammer-elastic-6e10", false, Some("elastic_recovery:k_contact_N_per_m=6e10")),
    ("hammer-thermal", false, Some("thermal:q_dT=0.05")),
    ("hammer-thermal-0.01", false, Some("thermal:q_dT=0.01")),
    ("hammer-thermal-0.003", false, Some("thermal:q_dT=0.003")),
    ("hammer-friction-0.1", false, Some("friction_rise:exponent=0.1")),
    ("hammer-friction-0.03", false, Some("friction_rise:exponent=0.03")),
    ("hammer-foundation", false, Some("foundation:m3_kg=2000,k3_N_per_m=5e9,c3_Ns_per_m=0")),
    ("hammer-foundation-5e10", false, Some("foundation:m3_kg=2000,k3_N_per_m=5e10,c3_Ns_per_m=0")),
    ("press-none", true, None),
    ("press-clearance", true, Some("clearance:gap_m=0.0003,m_lower_kg=800")),
    ("press-clearance-30um", true, Some("clearance:gap_m=0.00003,m_lower_kg=800")),
    ("press-elastic-5e10", true, Some("elastic_recovery:k_contact_N_per_m=5e10")),
    ("press-elastic-2e11", true, Some("elastic_recovery:k_contact_N_per_m=2e11")),
    ("press-foundation", true, Some("foundation:m3_kg=20000,k3_N_per_m=5e9,c3_Ns_per_m=0")),
    ("press-foundation-5e10", true, Some("foundation:m3_kg=20000,k3_N_per_m=5e10,c3_Ns_per_m=0")),
    ("press-friction-0.1", true, Some("friction_rise:exponent=0.1")),
];

/// One billet's blows with the hidden effect, read as `diagnose` reads a capture directory
/// (as `benches/diagnose.rs` does).
fn billet(m: &Machine, press: bool, hidden: &EffectSet, seed: u64) -> (Vec<Reference>, Setting) {
    let kind = m.kind();
    let (sheet, v0s, height) = match (press, seed % 2 == 1) {
        (false, true) => (STEEL, [4.0, 4.5, 5.0, 5.3, 5.3], 1.0),
        (false, false) => (STEEL, [4.2, 4.8, 5.1, 5.3, 5.3], 0.9),
        (true, true) => (COPPER, [0.30, 0.33, 0.36, 0.36, 0.36], 1.0),
        (true, false) => (COPPER, [0.31, 0.34, 0.35, 0.36, 0.36], 0.9),
    };
    let mut p = parse_process("p", sheet).unwrap();
    p.measured_final_heights_m.clear();
    p.billet.height_m *= height;
    let spec = if press { CaptureSpec::press(seed) } else { CaptureSpec::hammer(seed) };
    let refs = synth_blows(m, hidden, &p, &v0s, &spec)
        .unwrap()
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let batch = rows_batch("c", 0, 0, 1e9 / spec.sample_rate_hz, &b.rows);
            let cut = Segmenter::cut_all(SegmentConfig::for_kind(kind), [&batch]);
            let fit_s = EstimatorConfig::for_kind(kind).fit_s;
            super::localise::reference("b", &cut[0], Some(i + 1), fit_s, m).unwrap()
        })
        .collect();
    (refs, Setting::Billet(p))
}

/// The seed set: (calibration seeds, holdout seeds). Calibration seeds are odd (the taller
/// billet), holdout seeds even (the shorter one), as in the suite.
fn seeds(set: &str) -> (Vec<u64>, Vec<u64>) {
    match set {
        "tune" => (vec![101], (1001..=1020).map(|s| s * 2).collect()),
        _ => (vec![201, 203], (2001..=2012).map(|s| s * 2).collect()),
    }
}

#[derive(Default, Debug)]
struct Tally {
    runs: usize,
    verdict_not_none: usize,
    eligible: usize,
    found: usize,
    found_or_equivalent: usize,
    verdicts: std::collections::BTreeMap<String, usize>,
    shrinks: Vec<f64>,
}

#[test]
#[ignore = "minutes per case; prints the verdict rule's measured error rates"]
fn verdict_error_rates() {
    let set = std::env::var("FORGEMON_RATES_SET").unwrap_or_else(|_| "tune".into());
    let only = std::env::var("FORGEMON_RATES_CASES").ok();
    let (calib_seeds, hold_seeds) = seeds(&set);
    let mut lines = Vec::new();
    for (name, press, effect) in CASES {
        if only.as_ref().is_some_and(|o| !o.split(',').any(|c| c == name)) {
            continue;
        }
        let m = parse_machine("m", if press { PRESS } else { HAMMER }).unwrap().machine;
        let hidden = effect.map_or(EffectSet::NONE, |e| EffectSet::from_effects(&[Effect::parse_spec(e).unwrap()]));
        let truth = effect.map(|e| e.split(':').next().unwrap());
        let lib = library(m.kind());
        let mut t = Tally::default();
        for &cs in &calib_seeds {
            let (cal, setting) = billet(&m, press, &hidden, cs);
            let (calib, calib_loc, _) = blow_set(cal, setting, &m, &EffectSet::NONE).unwrap();
            let base_calib = mean(&calib_loc.iter().map(|l| l.nrmse).collect::<Vec<_>>());
            let (h0, hs0) = billet(&m, press, &hidden, hold_seeds[0]);
            let (hold0, _, _) = blow_set(h0, hs0, &m, &EffectSet::NONE).unwrap();
            let fits: Vec<Fitted> =
                lib.iter().filter_map(|c| fit_candidates(&m, &EffectSet::NONE, &[c], &[], &calib, &hold0)).collect();
            for &hs in &hold_seeds {
                let (h, setting) = billet(&m, press, &hidden, hs);
                let (hold, hold_loc, _) = blow_set(h, setting, &m, &EffectSet::NONE).unwrap();
                let base: Vec<f64> = hold_loc.iter().map(|l| l.nrmse).collect();
                let singles: Vec<Fitted> = fits
                    .iter()
                    .filter_map(|f| {
                        let per_blow = hold.nrmse(&m, &EffectSet::from_effects(&f.effects))?;
                        Some(Fitted { holdout: mean(&per_blow), holdout_per_blow: per_blow, ..f.clone() })
                    })
                    .collect();
                let v = decide(&m, &base, hold.noise_nrmse(), &singles, &[]);
                let chosen = v.chosen.as_ref().map_or("none".to_string(), |f| f.name.clone());
                t.runs += 1;
                t.verdict_not_none += usize::from(v.chosen.is_some());
                *t.verdicts.entry(chosen.clone()).or_default() += 1;
                if let Some(truth) = truth {
                    let f = singles.iter().find(|f| f.name == truth).unwrap();
                    let shrink = 1.0 - f.holdout / mean(&base);
                    t.shrinks.push(shrink);
                    if shrink >= POWER_SHRINK {
                        t.eligible += 1;
                        t.found += usize::from(chosen == truth);
                        t.found_or_equivalent +=
                            usize::from(chosen == truth || v.equivalent.iter().any(|(n, _)| n == truth));
                    }
                }
                lines.push(format!(
                    "{{\"case\":\"{name}\",\"calib_seed\":{cs},\"hold_seed\":{hs},\"noise\":{},\"base\":{:?},\"cands\":{{{}}},\"base_calib\":{base_calib},\"calib\":{{{}}},\"verdict\":\"{chosen}\"}}",
                    hold.noise_nrmse(),
                    base,
                    singles.iter().map(|f| format!("\"{}\":{:?}", f.name, f.holdout_per_blow)).collect::<Vec<_>>().join(","),
                    singles.iter().map(|f| format!("\"{}\":{}", f.name, f.calib)).collect::<Vec<_>>().join(",")
                ));
            }
        }
        let pct = |a: usize, b: usize| if b == 0 { f64::NAN } else { 100.0 * a as f64 / b as f64 };
        match truth {
            None => println!(
                "RATES set={set} {name}: false positives {}/{} = {:.1} % (verdicts {:?})",
                t.verdict_not_none,
                t.runs,
                pct(t.verdict_not_none, t.runs),
                t.verdicts
            ),
            Some(truth) => println!(
                "RATES set={set} {name}: {truth} found {}/{} = {:.1} % of runs with its shrink ≥ {POWER_SHRINK} (named or equivalent: {}); shrink min {:.2} median {:.2}; verdicts {:?}",
                t.found,
                t.eligible,
                pct(t.found, t.eligible),
                t.found_or_equivalent,
                t.shrinks.iter().copied().fold(f64::INFINITY, f64::min),
                {
                    let mut s = t.shrinks.clone();
                    s.sort_by(f64::total_cmp);
                    s.get(s.len() / 2).copied().unwrap_or(f64::NAN)
                },
                t.verdicts
            ),
        }
    }
    if let Ok(path) = std::env::var("FORGEMON_RATES_OUT") {
        std::fs::write(path, lines.join("\n")).unwrap();
    }
}
