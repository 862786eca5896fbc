//! How the family's tests read a diagnosis (issue 41): the verdict as one name, whether it
//! names a hidden effect, and the case's strength. One place, so that the CI tests and the
//! rates harness count alike.

use forgemon::diagnose::Diagnosis;

/// A verdict the report marks uncertain.
pub const UNCERTAIN: &str = "uncertain";

/// The verdict as counted: when the report says it is uncertain between effects
/// (`verdict.confidence.uncertain_between` not empty), the effects it is settled on
/// (`verdict.confidence.settled`, `a+b` for two) or else `uncertain`; otherwise the effect's
/// name (`a+b` for a pair), `none` without one.
pub fn verdict_of(d: &Diagnosis) -> String {
    let json = d.to_json();
    let c = &json["verdict"]["confidence"];
    let uncertain = c["uncertain_between"].as_array().is_some_and(|a| !a.is_empty());
    if uncertain {
        let settled: Vec<&str> =
            c["settled"].as_array().map_or(Vec::new(), |a| a.iter().filter_map(|v| v.as_str()).collect());
        return if settled.is_empty() { UNCERTAIN.to_string() } else { settled.join("+") };
    }
    d.verdict.as_ref().map_or("none".to_string(), |f| f.name.clone())
}

/// Whether `verdict` names `effect`, alone or in a pair `a+b`; `none` names none.
pub fn names(verdict: &str, effect: &str) -> bool {
    verdict.split('+').any(|v| v == effect)
}

/// The case's strength: the base model's holdout nrmse over the sensor noise.
pub fn strength(d: &Diagnosis) -> f64 {
    d.baseline_holdout / d.noise_nrmse
}

/// The holdout shrink of `effect`'s own single candidate (NaN without one).
pub fn own_shrink(d: &Diagnosis, effect: &str) -> f64 {
    d.candidates.iter().find(|f| f.name == effect).map_or(f64::NAN, |f| 1.0 - f.holdout / d.baseline_holdout)
}
