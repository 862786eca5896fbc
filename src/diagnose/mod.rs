//! The sim-to-real gap (issue #6, docs/interfaces.md §6, DESIGN.md §2.5): where the base model
//! and the measured blows part (`localise`), which library effect closes the gap on blows
//! it was not fitted on (`attribute`), and a verdict under an explicit rule.
//!
//! The verdict rule is `verdict.rs`'s (also written into the report); its error rates are
//! measured by `rates.rs`.

pub mod adopt;
pub mod attribute;
pub mod blowset;
pub mod confidence;
pub mod evidence;
pub mod indicators;
pub mod localise;
pub mod location;
pub mod phases;
#[cfg(test)]
mod rates;
mod scan;
pub mod verdict;
pub mod words;

use rayon::prelude::*;
use serde_json::{Value, json};

use crate::identify::objective::{Heights, Objective, Reference, Setting};
use crate::physics::effects::{Effect, EffectSet};
use crate::physics::machine::Machine;
use attribute::{Candidate, Fitted, library};
use blowset::{BlowSet, mean};
use confidence::Confidence;
use indicators::{Indicators, Summary, indicators, summarise};
use localise::{ByBand, ByPhase, Localised, localise};
use location::{Acts, Location, Split};

pub use verdict::{MIN_PAIR_SHRINK, MIN_SHRINK, NOISE_FACTOR};

/// The whole diagnosis.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    pub baseline_calib: f64,
    pub baseline_holdout: f64,
    pub baseline_holdout_per_blow: Vec<f64>,
    pub by_phase: ByPhase,
    pub by_band: ByBand,
    /// The error phase with phase, mean over the calibration blows (`location`).
    pub location: Location,
    /// The calibration blows' indicators, and over the blows.
    pub indicators: Vec<Indicators>,
    pub indicator_summary: Vec<Summary>,
    /// Every single effect and the pairs tried, best holdout first.
    pub candidates: Vec<Fitted>,
    pub verdict: Option<Fitted>,
    /// Effects the verdict's test cannot tell from it, with the physics reason if any.
    pub equivalent: Vec<(String, Option<String>)>,
    /// Sensor noise over the peak, mean over the holdout blows.
    pub noise_nrmse: f64,
    pub why: String,
    /// The verdict's bootstrap agreement, intervals and runner-up (`confidence`).
    pub confidence: Confidence,
    /// Where the verdict's effect acts: what it removes of the base model's error, phase
    /// with phase and band by band, on the holdout blows (None for "none").
    pub acts: Option<Acts>,
    pub calib: BlowSet,
    pub holdout: BlowSet,
}

fn blow_set(
    refs: Vec<Reference>,
    setting: Setting,
    machine: &Machine,
    effects: &EffectSet,
) -> Option<(BlowSet, Vec<Localised>, Vec<Indicators>)> {
    let n = refs.len();
    // Where the sheet has hand-measured heights, the start heights from the encoder's chain
    // (`Heights::Encoder`): the calipers' scatter (±0.2 mm) moved each holdout blow's error by
    // more than the noise and gave the independent hammer false positives (docs/validation.md, "Start
    // heights from the encoder").
    let obj = Objective::new(refs, vec![true; n], setting, machine.kind())
        .with_effects(*effects)
        .with_heights(Heights::Encoder);
    let mode2 = machine.second_mode_hz();
    let sims = obj.simulate(machine)?;
    let loc: Vec<Localised> = obj.refs.iter().zip(&sims).map(|(r, s)| localise(r, s, mode2)).collect();
    let ind = obj.refs.iter().zip(&sims).zip(&loc).map(|((r, s), l)| indicators(r, s, l, mode2)).collect();
    let windows = loc.iter().map(|l| l.window).collect();
    Some((BlowSet { obj, windows, mode2_hz: mode2 }, loc, ind))
}

/// How many fits `diagnose` runs (and tells `progress` of) on a machine of `kind` when one
/// single effect is best: every library effect alone, then the best one paired with each
/// other. Each further single that anchors pairs (`verdict::pair_anchors`) adds its own.
pub fn fit_count(kind: crate::physics::machine::MachineKind) -> usize {
    let n = library(kind).len();
    n + n.saturating_sub(1)
}

/// Diagnose `machine` (with its own `effects`) on calibration and holdout blows.
/// `progress` is told of each fitted candidate.
pub fn diagnose(
    machine: &Machine,
    effects: &EffectSet,
    calib: (Vec<Reference>, Setting),
    holdout: (Vec<Reference>, Setting),
    progress: &(dyn Fn() + Sync),
) -> Option<Diagnosis> {
    let (calib, calib_loc, calib_ind) = blow_set(calib.0, calib.1, machine, effects)?;
    let (holdout, hold_loc, _) = blow_set(holdout.0, holdout.1, machine, effects)?;
    let by_phase = ByPhase::mean(&calib_loc.iter().map(|l| l.by_phase).collect::<Vec<_>>());
    let by_band = ByBand::mean(&calib_loc.iter().map(|l| l.by_band).collect::<Vec<_>>());
    let location = Location::mean(&calib_loc.iter().map(|l| l.location).collect::<Vec<_>>());
    let base_hold: Vec<f64> = hold_loc.iter().map(|l| l.nrmse).collect();
    let base_calib = mean(&calib_loc.iter().map(|l| l.nrmse).collect::<Vec<_>>());
    let lib = library(machine.kind());
    let singles: Vec<(usize, Fitted)> = lib
        .par_iter()
        .enumerate()
        .filter_map(|(i, c)| {
            let f = attribute::fit_candidates(machine, effects, &[c], &[], &calib, &holdout);
            progress();
            f.map(|f| (i, f))
        })
        .collect();
    let mut ranked = singles.clone();
    ranked.sort_by(|a, b| a.1.holdout.total_cmp(&b.1.holdout));
    let singles: Vec<Fitted> = ranked.iter().map(|(_, f)| f.clone()).collect();
    let anchor_names = verdict::pair_anchors(&base_hold, &singles);
    let anchors: Vec<&(usize, Fitted)> = ranked.iter().filter(|r| anchor_names.contains(&r.1.name)).collect();
    let pairs = fit_pairs(machine, effects, &anchors, &ranked, &calib, &holdout, progress);
    let mut candidates: Vec<Fitted> = singles.iter().chain(&pairs).cloned().collect();
    candidates.sort_by(|a, b| a.holdout.total_cmp(&b.holdout));
    let noise_nrmse = holdout.noise_nrmse();
    let baseline_holdout = mean(&base_hold);
    let v = verdict::decide(machine, &base_hold, noise_nrmse, &singles, &pairs);
    let scores = confidence::Scores { machine, base_hold: &base_hold, noise_nrmse, singles: &singles, pairs: &pairs };
    let inputs = confidence::Inputs { scores, base: effects, calib: &calib, holdout: &holdout };
    let confidence = confidence::confidence(&inputs, v.chosen.as_ref(), &v.equivalent);
    let acts = v.chosen.as_ref().and_then(|f| acts(machine, effects, &f.effects, &holdout));
    Some(Diagnosis {
        baseline_calib: base_calib,
        baseline_holdout,
        baseline_holdout_per_blow: base_hold,
        by_phase,
        by_band,
        location,
        indicator_summary: summarise(&calib_ind),
        indicators: calib_ind,
        candidates,
        verdict: v.chosen,
        equivalent: v.equivalent,
        noise_nrmse,
        why: v.why,
        confidence,
        acts,
        calib,
        holdout,
    })
}

/// Where `chosen` acts on the holdout blows: the base model's residual there against the
/// model's with `chosen`'s effects, on the measured blows' phases.
fn acts(machine: &Machine, effects: &EffectSet, chosen: &[Effect], holdout: &BlowSet) -> Option<Acts> {
    let mut set = *effects;
    for e in chosen {
        set.apply(e);
    }
    let split = |set: EffectSet| -> Option<Vec<Split>> {
        let sims = holdout.obj.with_effects(set).simulate(machine)?;
        Some(
            holdout
                .obj
                .refs
                .iter()
                .zip(&sims)
                .map(|(r, s)| {
                    let l = localise(r, s, holdout.mode2_hz);
                    let bands = [l.by_band.low, l.by_band.mode2, l.by_band.high];
                    let ring = ((1.0 / (holdout.mode2_hz * r.dt_s)).round() as usize).max(1);
                    Split::of(&r.load_n, &s.load_n, &l.measured, &l.model, l.window, r.peak_n, ring, bands)
                })
                .collect(),
        )
    };
    Some(Acts::of(&split(*effects)?, &split(set)?))
}

/// The pairs worth fitting, fitted: each of `anchors` (`verdict::pair_anchors`) with each
/// other single of `ranked` (a second effect that only shows once the first is in place
/// need not rank high alone).
fn fit_pairs(
    machine: &Machine,
    effects: &EffectSet,
    anchors: &[&(usize, Fitted)],
    ranked: &[(usize, Fitted)],
    calib: &BlowSet,
    holdout: &BlowSet,
    progress: &(dyn Fn() + Sync),
) -> Vec<Fitted> {
    type Ranked<'a> = &'a (usize, Fitted);
    let lib = library(machine.kind());
    let is_anchor = |i: usize| anchors.iter().position(|a| a.0 == i);
    let pairs_in: Vec<(Ranked, Ranked)> = anchors
        .iter()
        .enumerate()
        .flat_map(|(k, a)| {
            // A pair of two anchors is fitted once, from the better-ranked one.
            ranked.iter().filter(move |o| o.0 != a.0 && is_anchor(o.0).is_none_or(|j| j > k)).map(move |o| (*a, o))
        })
        .collect();
    pairs_in
        .par_iter()
        .filter_map(|((ia, fa), (ib, _))| {
            let cands: Vec<&Candidate> = vec![&lib[*ia], &lib[*ib]];
            // The best single effect starts where its own fit ended.
            let held = lib[*ia].values_of(&fa.effects[0]);
            let f = attribute::fit_candidates(machine, effects, &cands, &held, calib, holdout);
            progress();
            f
        })
        .collect()
}

/// JSON has no NaN: a missing number is null.
fn finite(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

impl Diagnosis {
    /// `report.json` (docs/interfaces.md §6), with the indicators added to `baseline`.
    pub fn to_json(&self) -> Value {
        let params = |f: &Fitted| -> Value {
            let mut m = serde_json::Map::new();
            for e in &f.effects {
                for (k, v) in e.params() {
                    m.insert(k.to_string(), json!(v));
                }
            }
            Value::Object(m)
        };
        let shrink = |after: f64| 1.0 - after / self.baseline_holdout;
        json!({
            "metric": "nrmse_load",
            "baseline": {
                "calib": self.baseline_calib,
                "holdout": self.baseline_holdout,
                "holdout_per_blow": self.baseline_holdout_per_blow.iter().copied().map(finite).collect::<Vec<_>>(),
                "by_phase": self.by_phase,
                "dominant_phase": self.by_phase.dominant(),
                "by_band": self.by_band,
                "location": {"phase": self.location.phase(), "share": self.location.share(), "method": location::METHOD},
                "indicators": self.indicator_summary.iter().map(|s| (s.name.to_string(), json!({
                    "mean_rel_error": finite(s.mean_rel_error), "blows": s.blows,
                    "per_blow_rel_error": s.per_blow_rel_error.iter().map(|x| x.map(finite)).collect::<Vec<_>>(),
                }))).collect::<serde_json::Map<_, _>>(),
                "dominant_indicator": indicators::dominant(&self.indicator_summary).map(|s| s.name),
                "indicators_per_blow": self.indicators,
            },
            "candidates": self.candidates.iter().map(|f| json!({
                "effect": f.name, "params": params(f), "calib": f.calib, "holdout": f.holdout,
                "holdout_shrink": shrink(f.holdout),
                "holdout_per_blow": f.holdout_per_blow.iter().copied().map(finite).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
            "verdict": match &self.verdict {
                Some(f) => json!({"effect": f.name, "holdout_before": self.baseline_holdout, "holdout_after": f.holdout,
                                  "confidence": self.confidence.to_json(),
                                  "acts": self.acts.map(|a| json!({
                                      "phase": a.phase(), "band": a.band(), "method": location::ACTS_METHOD,
                                      "removed_by_phase": location::PHASE_NAMES.iter().zip(a.removed_by_phase).map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
                                      "removed_by_band": location::BAND_NAMES.iter().zip(a.removed_by_band).map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
                                  })),
                                  "holdout_shrink": shrink(f.holdout), "params": params(f),
                                  "equivalent": self.equivalent.iter().map(|(n, _)| n).collect::<Vec<_>>(),
                                  "equivalent_why": self.equivalent.iter().filter_map(|(n, w)| w.as_ref().map(|w| (n.clone(), json!(w))))
                                      .collect::<serde_json::Map<_, _>>()}),
                None => json!({"effect": "none", "holdout_before": self.baseline_holdout, "holdout_after": self.baseline_holdout,
                               "confidence": self.confidence.to_json(),
                               "holdout_shrink": 0.0, "equivalent": [], "equivalent_why": {}}),
            },
            "rule": {
                "noise_nrmse": self.noise_nrmse, "noise_factor": NOISE_FACTOR, "min_shrink": MIN_SHRINK,
                "min_pair_shrink": MIN_PAIR_SHRINK, "parsimony_window": verdict::PARSIMONY_WINDOW,
                "test": evidence::TESTS,
                "test_level": evidence::ALPHA,
                "explanation": self.why,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{parse_machine, parse_process};
    use crate::identify::objective::{Objective, Reference, Setting};
    use crate::physics::effects::{Effect, EffectSet};
    use crate::physics::machine::Machine;
    use crate::physics::machine::MachineKind;
    use crate::physics::process::Process;
    use crate::signal::segment::{SegmentConfig, Segmenter};
    use crate::synth::{CaptureSpec, rows_batch, synth_blows};

    use super::indicators::{Summary, indicators, summarise};
    use super::localise::{ByPhase, localise};
    use super::location::Location;

    /// The withheld-effect suite's machines (tests/diagnose.rs): a hammer unlike the
    /// paper's Table 1, a press unlike the press paper's Table 3.
    const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n";
    const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
        c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n";

    /// Blows made with a hidden effect, seen through the base model as `diagnose` sees them
    /// (phases located on the measured signals): the residual by phase over the blows, and
    /// the indicators.
    /// The hammer is the withheld-effect suite's (not the paper's), the billet the steel
    /// sheet's without its measured heights, so the model carries its own heights.
    fn baseline(effect: &str) -> (ByPhase, Vec<Summary>) {
        let (phase, _, summary, _) = baseline_on(MachineKind::Hammer, effect);
        (phase, summary)
    }

    /// `baseline` on either machine (the press on the copper sheet at the paper's speeds),
    /// with the location phase with phase and how many samples the ram's contact came before
    /// the load's (`Reference::t_ram_contact_s`), mean over the blows.
    fn baseline_on(kind: MachineKind, effect: &str) -> (ByPhase, Location, Vec<Summary>, f64) {
        let (m, refs, p) = measured(kind, effect);
        // How long the ram was in contact before the load rose, samples, mean over the blows.
        let lead = refs
            .iter()
            .map(|r| match (r.t_ram_contact_s, r.measured) {
                (Some(ram), Some(m)) => (m.contact_s - ram) / r.dt_s,
                _ => 0.0,
            })
            .sum::<f64>()
            / refs.len() as f64;
        let n = refs.len();
        let obj = Objective::new(refs, vec![true; n], Setting::Billet(p), kind);
        let sims = obj.simulate(&m).unwrap();
        let loc: Vec<_> = obj.refs.iter().zip(&sims).map(|(r, s)| localise(r, s, m.second_mode_hz())).collect();
        let ind: Vec<_> =
            obj.refs.iter().zip(&sims).zip(&loc).map(|((r, s), l)| indicators(r, s, l, m.second_mode_hz())).collect();
        // Over the blows, as the report's baseline gives them.
        let mean = ByPhase::mean(&loc.iter().map(|l| l.by_phase).collect::<Vec<_>>());
        let location = Location::mean(&loc.iter().map(|l| l.location).collect::<Vec<_>>());
        let summary = summarise(&ind);
        eprintln!("{effect}: {mean:?}\n  location {} {:?}", location.phase(), location.share());
        for s in &summary {
            eprintln!("  {}: {:+.3}", s.name, s.mean_rel_error);
        }
        (mean, location, summary, lead)
    }

    /// Five blows of the suite's machine of `kind` with `effect` hidden, on a billet of its
    /// sheet without measured heights, as references: the machine, the references, the sheet.
    fn measured(kind: MachineKind, effect: &str) -> (Machine, Vec<Reference>, Process) {
        let (text, sheet, v0s, spec) = match kind {
            MachineKind::Hammer => (
                HAMMER,
                include_str!("../../config/steel-16NiCrMo13.process.toml"),
                vec![4.0, 4.5, 5.0, 5.3, 5.3],
                CaptureSpec::hammer(5),
            ),
            MachineKind::ScrewPress => (
                PRESS,
                include_str!("../../config/copper-cu99.process.toml"),
                vec![0.30, 0.33, 0.36, 0.36, 0.36],
                CaptureSpec::press(5),
            ),
        };
        let m = parse_machine("m", text).unwrap().machine;
        let mut p = parse_process("p", sheet).unwrap();
        p.measured_final_heights_m.clear();
        let hidden = match effect {
            "none" => EffectSet::NONE,
            e => EffectSet::from_effects(&[Effect::parse_spec(e).unwrap()]),
        };
        let blows = synth_blows(&m, &hidden, &p, &v0s, &spec).unwrap();
        let fit_s = crate::estimate::EstimatorConfig::for_kind(kind).fit_s;
        let refs: Vec<Reference> = blows
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let batch = rows_batch("c", 0, 0, 1e9 / spec.sample_rate_hz, &b.rows);
                let cut = Segmenter::cut_all(SegmentConfig::for_kind(kind), [&batch]);
                super::localise::reference("b", &cut[0], Some(i + 1), fit_s, &m).unwrap()
            })
            .collect();
        (m, refs, p)
    }

    // `attribute`'s global stage leaves out a grid point whose first blow alone costs more
    // than the best points' whole cost: exact only while that part bounds the whole.
    #[test]
    fn the_first_blows_cost_bounds_the_sets_cost() {
        for (kind, hidden) in [
            (MachineKind::Hammer, "clearance:gap_m=0.0003"),
            (MachineKind::ScrewPress, "clearance:gap_m=0.0003,m_lower_kg=300"),
            (MachineKind::ScrewPress, "elastic_recovery:k_contact_N_per_m=5e9"),
        ] {
            let (m, refs, p) = measured(kind, hidden);
            let (set, _, _) = super::blow_set(refs, Setting::Billet(p), &m, &EffectSet::NONE).unwrap();
            let mut bounded = 0;
            for e in
                ["", "clearance:gap_m=0.0001", "elastic_recovery:k_contact_N_per_m=2e9", "friction_rise:exponent=0.5"]
            {
                let effects = if e.is_empty() {
                    EffectSet::NONE
                } else {
                    EffectSet::from_effects(&[Effect::parse_spec(e).unwrap()])
                };
                let cost: f64 = set.residuals(&m, &effects).unwrap().iter().map(|x| x * x).sum();
                let bound = set.first_blow_cost(&m, &effects);
                assert!(bound <= cost, "{hidden}, model {e:?}: bound {bound} over the cost {cost}");
                // A bound of nothing prunes nothing: the first blow carries its share.
                if bound > 0.05 * cost {
                    bounded += 1;
                }
            }
            assert!(
                bounded >= 3,
                "{hidden}: the first blow's part is at least 5 % of the cost in {bounded} of 4 models"
            );
        }
    }

    fn rel(summary: &[Summary], name: &str) -> f64 {
        summary.iter().find(|s| s.name == name).unwrap().mean_rel_error
    }

    // docs/interfaces.md §6 / issue #6: where an effect has a clear location, the base model's
    // dominant phase says so.
    #[test]
    fn elastic_recovery_shows_in_the_spring_back() {
        let (phase, ind) = baseline("elastic_recovery:k_contact_N_per_m=1.5e9");
        assert_eq!(phase.dominant(), "spring_back");
        // The papers' gap: the real spring-back lasts longer than the model's (hammer paper
        // §4.2: 3.7 ms against 0.8 ms), and the compliant contact softens the impact, so the
        // rigid model rings higher. Each beyond 5× what the no-effect case shows (≤ 0.01).
        assert!(rel(&ind, "spring_back_time") < -0.05);
        assert!(rel(&ind, "peak_load") > 0.05);
    }

    #[test]
    fn clearance_shows_at_impact() {
        assert_eq!(baseline("clearance:gap_m=0.0003").0.dominant(), "impact");
    }

    // A flow stress the model lacks (friction rising as the billet flattens, a cooling
    // billet, strain hardening) raises the real load, so the real forming ends sooner: the
    // model forms too long and ends below the measured final load. Its largest load error
    // is the model still forming, then unloading, after the real billet has stopped, which
    // `localise` charges to the forming that ran long.
    #[test]
    fn a_missing_flow_stress_shows_in_the_forming() {
        for effect in ["friction_rise:exponent=1.0", "thermal:q_dT=0.15", "strain_hardening:n=0.2"] {
            let (phase, ind) = baseline(effect);
            assert_eq!(phase.dominant(), "forming", "{effect}: {phase:?}");
            // The model forms too long and over-forms the billet, each beyond 5× what the
            // no-effect case shows (≤ 0.01 of its scale), and ends below the real final load,
            // beyond the no-effect bound (0.02; thermal's first blow is unchanged, by its
            // definition, which halves its mean).
            assert!(rel(&ind, "forming_time") > 0.05, "{effect}");
            assert!(rel(&ind, "final_load") < -0.02, "{effect}");
            assert!(rel(&ind, "final_height") < -0.05, "{effect}");
        }
    }

    /// Issue #17: located phase with phase (`location`), an effect that changes only the
    /// billet's flow lands in the forming on both machines, a compliant contact in the
    /// spring-back, a clearance at impact. The named phase holds the largest share, and over
    /// half of the error where that held when the method was chosen; the compliant hammer
    /// contact (0.42 against the forming's 0.33), the press's clearance (0.48 against 0.33)
    /// and the hammer's (0.52 against 0.46) by less, so over 0.4 there.
    ///
    /// Tuning: the method (a phase's share of the blow's squared error, not its density as
    /// `by_phase` has it; the impact's start at the ram's own contact; the forming's ring
    /// amplitude charged to the impact that set it up) was chosen on these capture seeds (5);
    /// the withheld-effect suite (tests/diagnose.rs, seeds 3/4) and the independent renderer
    /// (tests/diagnose_independent.rs) report on others. The hammer's clearance came to the
    /// impact (from the forming's 0.53) when the measured end of forming was anchored at the
    /// ram's speed at the load's contact (`localise::ram_speed_at_load_contact`), a cause found
    /// on the independent renderer's seed 3; its row here was added after, unchanged.
    #[test]
    fn location_names_the_phase_the_effect_acts_in() {
        for (kind, effect, phase, at_least) in [
            (MachineKind::Hammer, "friction_rise:exponent=1.0", "forming", 0.5),
            (MachineKind::Hammer, "strain_rate:m=0.1", "forming", 0.5),
            (MachineKind::Hammer, "strain_hardening:n=0.2", "forming", 0.5),
            (MachineKind::Hammer, "thermal:q_dT=0.15", "forming", 0.5),
            (MachineKind::Hammer, "elastic_recovery:k_contact_N_per_m=1.5e9", "spring_back", 0.4),
            (MachineKind::Hammer, "clearance:gap_m=0.0003", "impact", 0.4),
            (MachineKind::ScrewPress, "friction_rise:exponent=1.0", "forming", 0.5),
            (MachineKind::ScrewPress, "strain_rate:m=0.1", "forming", 0.5),
            (MachineKind::ScrewPress, "strain_hardening:n=0.2", "forming", 0.5),
            (MachineKind::ScrewPress, "elastic_recovery:k_contact_N_per_m=5e9", "spring_back", 0.5),
            (MachineKind::ScrewPress, "clearance:gap_m=0.0003,m_lower_kg=800", "impact", 0.4),
        ] {
            let (_, location, _, _) = baseline_on(kind, effect);
            let share = location.share();
            assert_eq!(location.phase(), phase, "{kind:?} {effect}: {share:?}");
            let named = match phase {
                "forming" => share.forming,
                "impact" => share.impact,
                _ => share.spring_back,
            };
            assert!(named > at_least, "{kind:?} {effect}: {share:?}");
            let sum = share.impact + share.forming + share.spring_back + share.post;
            assert!((sum - 1.0).abs() < 1e-12, "{share:?}");
        }
    }

    /// The ram's own contact (`Reference::t_ram_contact_s`, its accelerometer leaving the
    /// approach) comes before the load's by the clearance's closure, and with no effect
    /// within the sample the load's contact is rounded to. Closure (`synth` truth is not
    /// sampled at it, so bounded by the physics): the hammer's 26 kg die, struck at ~4 m/s,
    /// crosses 0.3 mm in ~75 µs or more (7.5 samples at 100 kHz); the press's 800 kg die at
    /// under twice the ram's 0.33 m/s takes over 0.45 ms (9 samples at 20 kHz).
    #[test]
    fn the_ram_touches_before_the_load_rises_by_the_closure() {
        let (.., none) = baseline_on(MachineKind::Hammer, "none");
        assert!((0.0..=1.5).contains(&none), "{none}");
        let (.., hammer) = baseline_on(MachineKind::Hammer, "clearance:gap_m=0.0003");
        assert!(hammer > 7.5, "{hammer}");
        let (.., press) = baseline_on(MachineKind::ScrewPress, "clearance:gap_m=0.0003,m_lower_kg=800");
        assert!(press > 9.0, "{press}");
    }

    #[test]
    fn no_effect_leaves_the_indicators_within_the_sensors() {
        // 2 kN load noise and 10 µm encoder steps (CaptureSpec::hammer) on a ~1 MN blow of
        // several ms: every indicator within 2 % of its scale.
        let (_, ind) = baseline("none");
        for s in &ind {
            assert!(s.mean_rel_error.abs() < 0.02, "{}: {}", s.name, s.mean_rel_error);
        }
    }
}
