//! Every number a blow reports in its physical range, or the blow flagged (issue 36,
//! DESIGN.md §3: plausibility is a stage). One place holds every check: the impact speed
//! within what the machine can reach, the start height within the billet, the end height
//! below the start, each energy term non-negative, the efficiency in [0, 1] and the energy
//! terms summing to the kinetic energy in.
//!
//! A value outside its range by no more than the estimator's own accuracy
//! (`NOISE_FRACTION_OF_KINETIC` of the energy in) is the measurement's scatter about the
//! bound: it is reported at the bound, and its value as computed is kept beside it in
//! `at_bound`, so nothing is clamped silently. A value beyond that makes the blow
//! `implausible`: its energies, efficiency and end height are withheld (`null`), and its
//! `reason` names the value and its range. A value is never clamped into range and passed
//! off. Pure code.

pub use super::result::{AtBound, Check, Implausible};
use super::result::{BlowClass, BlowEstimate};
use crate::physics::machine::MachineKind;

/// The fastest impact a gravity drop hammer reaches, m/s: free fall from 2.5 m (the tallest
/// gravity hammers' stroke) is 7.0 m/s, and power-drop hammers accelerated by steam or air
/// reach about 9 m/s (Lange, Handbook of Metal Forming, ch. 16: blow speeds of hammers 5–9
/// m/s). A faster impact is an encoder or a clock the estimator misread.
pub const HAMMER_V_MAX_MPS: f64 = 10.0;
/// The fastest impact of a screw press, m/s: screw presses strike at 0.5–1.5 m/s at full
/// energy (Lange, ch. 15; the SPR 400 of seed 001 at 0.346 m/s is 25 % of its energy, so
/// 0.69 m/s at full). Twice the top of that range.
pub const PRESS_V_MAX_MPS: f64 = 3.0;

/// The estimator's accuracy on a blow's energy, as a fraction of the energy in: issue 16's
/// efficiency target (0.02, met at every DAQ rate on both machines, `tests/estimate_rates.rs`).
/// An energy term or an efficiency outside its range by no more than this is the scatter
/// about the bound.
pub const NOISE_FRACTION_OF_KINETIC: f64 = 0.02;

/// How far the energy terms may sum from the kinetic energy in, as a fraction of it, before
/// the blow is implausible: the width of the intermediate class (efficiency 0.50–0.75,
/// `EstimatorConfig`). A blow that leaves that much energy unaccounted for could lie in any
/// class, so its efficiency says nothing. (The model-health alert warns from 10 %,
/// `AlertConfig::residual_limit`; the healthy blows of `tests/capture_freedoms.rs` stay
/// within 2.3 %.)
pub const LEDGER_TOLERANCE: f64 = 0.25;

/// A billet more than this fraction higher than the sheet's is not the sheet's billet: the
/// billet detector's new-billet rise (`billet::NEW_BILLET_RISE_FRACTION`).
pub const BILLET_OFF_SHEET_FRACTION: f64 = super::billet::NEW_BILLET_RISE_FRACTION;

/// The fastest impact `kind` can reach, m/s.
pub fn v_max_mps(kind: MachineKind) -> f64 {
    match kind {
        MachineKind::Hammer => HAMMER_V_MAX_MPS,
        MachineKind::ScrewPress => PRESS_V_MAX_MPS,
    }
}

/// The ranges a blow is checked against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ranges {
    /// The fastest impact the machine reaches, m/s.
    pub v_max_mps: f64,
    /// The sheet's billet height, m (`None` without a sheet).
    pub sheet_height_m: Option<f64>,
    /// The height of the billet before its first blow, m, when known.
    pub billet_height_m: Option<f64>,
    /// How far a height may sit above its bound and be the measurement's scatter, m (the
    /// encoder's and caliper's resolutions and one sample's travel).
    pub height_tolerance_m: f64,
}

/// Check `e` against `r`. On success the values within the scatter of a bound are set to it
/// (their values as computed in `e.at_bound`) and the blow is classified by `classify`; on
/// failure the blow becomes `implausible` with the reason, and its energies, efficiency,
/// residual and end height are withheld (and the start height, if it is the one out of
/// range). An incomplete blow is left as it is: it reports nothing to check.
pub fn settle(e: &mut BlowEstimate, r: &Ranges, classify: impl Fn(f64) -> BlowClass) {
    if e.class == BlowClass::Incomplete {
        return;
    }
    match check(e, r) {
        Ok(bounded) => {
            for (field, raw, bound) in bounded {
                e.at_bound.insert(field.to_string(), raw);
                set(e, field, bound);
            }
            if let Some(eff) = e.efficiency {
                e.class = classify(eff);
            }
        }
        Err(why) => {
            if why.check == Check::StartHeight {
                e.h_start_m = None;
            }
            e.kinetic_in_j = None;
            e.plastic_j = None;
            e.friction_j = None;
            e.damped_j = None;
            e.elastic_j = None;
            e.efficiency = None;
            e.residual = None;
            e.h_end_m = None;
            e.at_bound.clear();
            e.class = BlowClass::Implausible;
            e.implausible = Some(why);
        }
    }
}

/// A value bounded: its name, its value as computed, and the bound it is reported at.
type Bounded = (&'static str, f64, f64);

/// The values to report at a bound (field, value as computed, bound), or the first check
/// the blow fails.
fn check(e: &BlowEstimate, r: &Ranges) -> Result<Vec<Bounded>, Implausible> {
    check_inputs(e, r)?;
    let mut bounded = Vec::new();
    check_final_load(e, &mut bounded)?;
    if let Some(kinetic_j) = e.kinetic_in_j {
        check_energies(e, kinetic_j, &mut bounded)?;
    }
    Ok(bounded)
}

/// The impact speed within the machine's reach, the start height within the billet and
/// the end height below it.
fn check_inputs(e: &BlowEstimate, r: &Ranges) -> Result<(), Implausible> {
    let v = e.v_impact_mps;
    if !(v > 0.0 && v <= r.v_max_mps) {
        return Err(Implausible::new(
            Check::ImpactSpeed,
            format!("impact speed {v:.3} m/s outside (0, {:.1}] m/s, the fastest this machine strikes", r.v_max_mps),
        ));
    }
    let tol = r.height_tolerance_m;
    if let Some(h0) = e.h_start_m {
        let cap = r.sheet_height_m.map(|s| s * (1.0 + BILLET_OFF_SHEET_FRACTION));
        let max = match (r.billet_height_m, cap) {
            (Some(b), Some(c)) => Some((b + tol).min(c)),
            (b, c) => b.map(|b| b + tol).or(c),
        };
        if !(h0 > 0.0 && max.is_none_or(|m| h0 <= m)) {
            return Err(Implausible::new(
                Check::StartHeight,
                format!(
                    "start height {:.2} mm outside (0, {}] mm, the billet's height",
                    h0 * 1e3,
                    max.map_or("-".to_string(), |m| format!("{:.2}", m * 1e3))
                ),
            ));
        }
        if let Some(h1) = e.h_end_m
            && !(h1 > 0.0 && h1 <= h0 + tol)
        {
            return Err(Implausible::new(
                Check::EndHeight,
                format!("end height {:.2} mm outside (0, {:.2}] mm, the start height", h1 * 1e3, h0 * 1e3),
            ));
        }
    }
    Ok(())
}

/// The load at the end of forming, not below zero beyond the estimate's accuracy.
fn check_final_load(e: &BlowEstimate, bounded: &mut Vec<Bounded>) -> Result<(), Implausible> {
    // The load at the end of forming is the sensor's, and a billet in compression cannot
    // pull on the tools: a reading below zero by more than the estimate's accuracy of the
    // peak is a sensor's zero or lost low frequencies (a piezo's high-pass), or an end of
    // forming placed in the spring-back's ringing (issue 37: -986 kN on a moving
    // foundation). Within it, it is reported at zero.
    let load_noise_n = NOISE_FRACTION_OF_KINETIC * e.peak_load_n.abs();
    if e.final_load_n.is_nan() || e.final_load_n < -load_noise_n {
        return Err(Implausible::new(
            Check::FinalLoad,
            format!(
                "load at the end of forming {:.1} kN below zero by more than the estimate's accuracy ({:.1} kN, {:.0} % \
                 of the {:.0} kN peak): the billet cannot pull; the sensor's zero or its low frequencies are off",
                e.final_load_n * 1e-3,
                load_noise_n * 1e-3,
                100.0 * NOISE_FRACTION_OF_KINETIC,
                e.peak_load_n * 1e-3
            ),
        ));
    }
    if e.final_load_n < 0.0 {
        bounded.push(("final_load_N", e.final_load_n, 0.0));
    }
    Ok(())
}

/// Each energy term non-negative, the efficiency in [0, 1] and the terms summing to the
/// `kinetic_j` in, each within the estimate's accuracy.
fn check_energies(e: &BlowEstimate, kinetic_j: f64, bounded: &mut Vec<Bounded>) -> Result<(), Implausible> {
    let noise_j = NOISE_FRACTION_OF_KINETIC * kinetic_j;
    let terms = [
        ("plastic_J", e.plastic_j),
        ("friction_J", e.friction_j),
        ("damped_J", e.damped_j),
        ("elastic_J", e.elastic_j),
    ];
    for (name, value) in terms {
        match value {
            Some(j) if j < -noise_j || !j.is_finite() => {
                return Err(Implausible::new(
                    Check::Energy,
                    format!(
                        "{name} {j:.0} J below zero by more than the estimate's accuracy ({:.0} J, {:.0} % of the {kinetic_j:.0} J in)",
                        noise_j,
                        100.0 * NOISE_FRACTION_OF_KINETIC
                    ),
                ));
            }
            Some(j) if j < 0.0 => bounded.push((name, j, 0.0)),
            _ => {}
        }
    }
    if let Some(eff) = e.efficiency {
        let noise = NOISE_FRACTION_OF_KINETIC;
        if !(-noise..=1.0 + noise).contains(&eff) {
            return Err(Implausible::new(
                Check::Efficiency,
                format!(
                    "efficiency {eff:.3} outside [0, 1] by more than the estimate's accuracy ({noise}): the plastic work \
                     cannot exceed the kinetic energy in, nor be negative"
                ),
            ));
        }
        if eff < 0.0 {
            bounded.push(("efficiency", eff, 0.0));
        } else if eff > 1.0 {
            bounded.push(("efficiency", eff, 1.0));
            // The plastic work is the efficiency's numerator: at most the energy in.
            if let Some(p) = e.plastic_j.filter(|p| *p > kinetic_j) {
                bounded.push(("plastic_J", p, kinetic_j));
            }
        }
    }
    let balanced = e.residual.is_none_or(|res| res.abs() <= LEDGER_TOLERANCE);
    if let (false, Some(res)) = (balanced, e.residual) {
        return Err(Implausible::new(
            Check::Balance,
            format!(
                "the energy terms miss the {kinetic_j:.0} J in by {:.0} % (beyond {:.0} %): the blow's energies do not add up",
                100.0 * res,
                100.0 * LEDGER_TOLERANCE
            ),
        ));
    }
    Ok(())
}

/// Set the field named `field` to `x`.
fn set(e: &mut BlowEstimate, field: &str, x: f64) {
    match field {
        "plastic_J" => e.plastic_j = Some(x),
        "friction_J" => e.friction_j = Some(x),
        "damped_J" => e.damped_j = Some(x),
        "elastic_J" => e.elastic_j = Some(x),
        "efficiency" => e.efficiency = Some(x),
        "final_load_N" => e.final_load_n = x,
        _ => unreachable!("settle bounds only the fields of `check`"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::config::EstimatorConfig;
    use crate::estimate::result::examples;

    fn ranges() -> Ranges {
        Ranges {
            v_max_mps: HAMMER_V_MAX_MPS,
            sheet_height_m: Some(0.112),
            billet_height_m: Some(0.112),
            height_tolerance_m: 60e-6,
        }
    }

    /// A healthy soft blow with the heights set: 112 mm to 92.9 mm.
    fn blow() -> BlowEstimate {
        let mut e = examples::soft(1);
        e.h_start_m = Some(0.112);
        e.h_end_m = Some(0.0929);
        e.friction_j = Some(226.0);
        // The example's terms sum to 5711 - 5320 - 226 - 150 - 15 = 0 J.
        e.residual = Some(0.0);
        e
    }

    fn settled(mut e: BlowEstimate) -> BlowEstimate {
        let cfg = EstimatorConfig::for_kind(MachineKind::Hammer);
        settle(&mut e, &ranges(), |x| cfg.classify(x));
        e
    }

    fn failed(e: BlowEstimate) -> Implausible {
        let e = settled(e);
        assert_eq!(e.class, BlowClass::Implausible);
        assert_eq!((e.efficiency, e.plastic_j, e.kinetic_in_j, e.h_end_m), (None, None, None, None));
        e.implausible.expect("a reason")
    }

    #[test]
    fn a_healthy_blow_passes_unchanged() {
        let e = settled(blow());
        assert_eq!(e, BlowEstimate { class: BlowClass::Soft, ..blow() });
        assert!(e.at_bound.is_empty());
    }

    #[test]
    fn each_check_fails_on_its_own_value() {
        type Breaker = Box<dyn Fn(&mut BlowEstimate)>;
        let cases: [(Check, Breaker); 10] = [
            (Check::ImpactSpeed, Box::new(|e| e.v_impact_mps = 12.0)),
            (Check::ImpactSpeed, Box::new(|e| e.v_impact_mps = -0.5)),
            (Check::StartHeight, Box::new(|e| e.h_start_m = Some(-0.0068))),
            (Check::StartHeight, Box::new(|e| e.h_start_m = Some(0.389))),
            (Check::EndHeight, Box::new(|e| e.h_end_m = Some(0.113))),
            (Check::Energy, Box::new(|e| e.plastic_j = Some(-2431.0))),
            (Check::Energy, Box::new(|e| e.damped_j = Some(f64::NAN))),
            (Check::Efficiency, Box::new(|e| e.efficiency = Some(1.2))),
            (Check::Balance, Box::new(|e| e.residual = Some(-0.3))),
            (Check::FinalLoad, Box::new(|e| e.final_load_n = -986e3)),
        ];
        for (check, break_it) in cases {
            let mut e = blow();
            break_it(&mut e);
            let why = failed(e);
            assert_eq!(why.check, check, "{why:?}");
        }
        // The start height out of range is withheld too; in range it stays.
        let mut e = blow();
        e.h_start_m = Some(0.389);
        assert_eq!(settled(e).h_start_m, None);
        let mut e = blow();
        e.efficiency = Some(-0.5);
        assert_eq!(settled(e).h_start_m, Some(0.112));
    }

    #[test]
    fn the_reason_names_the_value_and_its_range() {
        let mut e = blow();
        e.h_start_m = Some(-0.00676);
        assert_eq!(failed(e).reason, "start height -6.76 mm outside (0, 112.06] mm, the billet's height");
        let mut e = blow();
        e.efficiency = Some(-0.142);
        assert!(failed(e).reason.starts_with("efficiency -0.142 outside [0, 1]"));
    }

    /// Within the estimator's accuracy of a bound the blow is the bound's, with its value as
    /// computed kept beside it; just past that it is implausible.
    #[test]
    fn the_scatter_about_a_bound_is_reported_at_the_bound_and_kept() {
        let mut e = blow();
        e.efficiency = Some(1.012);
        e.plastic_j = Some(5780.0);
        let s = settled(e);
        assert_eq!((s.efficiency, s.plastic_j, s.class), (Some(1.0), Some(5711.0), BlowClass::Soft));
        assert_eq!(s.at_bound.get("efficiency"), Some(&1.012));
        assert_eq!(s.at_bound.get("plastic_J"), Some(&5780.0));
        let mut e = blow();
        e.efficiency = Some(-0.015);
        e.plastic_j = Some(-85.0);
        let s = settled(e);
        assert_eq!((s.efficiency, s.plastic_j, s.class), (Some(0.0), Some(0.0), BlowClass::Hard));
        let mut e = blow();
        e.efficiency = Some(1.0 + NOISE_FRACTION_OF_KINETIC + 1e-9);
        assert_eq!(failed(e).check, Check::Efficiency);
        // The example's peak is 1.16 MN: 23.2 kN of scatter below zero at the end of forming.
        let mut e = blow();
        e.final_load_n = -20e3;
        let s = settled(e);
        assert_eq!((s.final_load_n, s.class, s.at_bound.get("final_load_N")), (0.0, BlowClass::Soft, Some(&-20e3)));
        let mut e = blow();
        e.final_load_n = -24e3;
        assert_eq!(failed(e).check, Check::FinalLoad);
    }

    /// A start height above the billet's within the measurement is its scatter; a billet
    /// more than a tenth taller than the sheet's is not this sheet's, whatever its first
    /// blow said.
    #[test]
    fn the_start_height_is_bounded_by_the_billet_and_by_the_sheet() {
        let mut e = blow();
        e.h_start_m = Some(0.112 + 50e-6);
        assert_eq!(settled(e).class, BlowClass::Soft);
        let r = Ranges { billet_height_m: Some(0.5), ..ranges() };
        let mut e = blow();
        e.h_start_m = Some(0.489);
        let cfg = EstimatorConfig::for_kind(MachineKind::Hammer);
        settle(&mut e, &r, |x| cfg.classify(x));
        assert_eq!(e.implausible.map(|i| i.check), Some(Check::StartHeight));
    }

    #[test]
    fn an_incomplete_blow_is_left_as_it_is() {
        let mut e = blow();
        e.class = BlowClass::Incomplete;
        e.v_impact_mps = 50.0;
        assert_eq!(settled(e.clone()), e);
    }
}
