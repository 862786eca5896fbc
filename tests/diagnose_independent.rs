//! The diagnosis on data it was not fitted with (issue #17): blows rendered by
//! `independent/` (its own contact law, integrator, DAQ chain and hand-measured heights),
//! read and diagnosed by the project as real captures would be.
//!
//! Seeds: the location method and the verdict rule were chosen on the project's own renderer
//! (capture seed 5, and the rates' `tune` set, `src/diagnose/rates.rs`). On this renderer,
//! seed 3 (calibration; 4 the holdout) is where the renderer's faults and the hammer's
//! measured end of forming were found and fixed; the tests that assert on what was seen
//! there say so and assert on seeds 7/8 (`OTHER_SEED`). The harness
//! (`tests/diagnose_independent_table.rs`) reports seeds 3/4.
//!
//! CI tests here only render and localise (no fits: a few seconds each). The full diagnosis
//! of every case, on both renderers, is the `#[ignore]`d harness in
//! `tests/diagnose_independent_table.rs`.

#[path = "independent/mod.rs"]
mod independent;

use forgemon::diagnose::blowset::BlowSet;
use forgemon::diagnose::localise::localise;
use forgemon::diagnose::location::Location;
use forgemon::identify::objective::{Heights, Objective};
use independent::{Hidden, Kind, billet, cases, machine, speeds};

/// Assert seeds (module docs).
const CALIB_SEED: u64 = 3;
/// Seed for the assertions whose bounds were set on `CALIB_SEED` after the renderer was
/// corrected (its hammer die at the impact speed, eq. 3, no ram weight in contact).
const OTHER_SEED: u64 = 7;

/// The base model's location on the calibration billet of a case, as `diagnose` reports it
/// in `baseline.location`, and the mean lead of the ram's contact over the load's, samples.
fn baseline_location(kind: Kind, hidden: &Hidden, seed: u64) -> (Location, f64) {
    let m = machine(kind);
    let b = billet(kind, hidden, &speeds(kind).0, 1.0, seed);
    let lead = b
        .refs
        .iter()
        .map(|r| match (r.t_ram_contact_s, r.measured) {
            (Some(ram), Some(mi)) => (mi.contact_s - ram) / r.dt_s,
            _ => 0.0,
        })
        .sum::<f64>()
        / b.refs.len() as f64;
    let n = b.refs.len();
    let obj = Objective::new(b.refs, vec![true; n], b.setting, m.kind());
    let sims = obj.simulate(&m).expect("the base model simulates the independent blows");
    let loc: Vec<Location> =
        obj.refs.iter().zip(&sims).map(|(r, s)| localise(r, s, m.second_mode_hz()).location).collect();
    (Location::mean(&loc), lead)
}

/// The caliper noise is there, and the heights need not fall monotonically as measured.
#[test]
fn hand_measured_heights_carry_caliper_noise() {
    let b = billet(Kind::Hammer, &Hidden::None, &speeds(Kind::Hammer).0, 1.0, CALIB_SEED);
    let forgemon::identify::objective::Setting::Billet(p) = &b.setting else { panic!("a billet") };
    assert_eq!(p.measured_final_heights_m.len(), 5);
    for (m, t) in p.measured_final_heights_m.iter().zip(&b.heights_m) {
        // ±0.2 mm (independent/mod.rs, CALIPER_M), and not exactly the truth.
        assert!((m - t).abs() <= 0.2e-3 && m != t, "{m} {t}");
    }
    // The billet is upset on every blow (true heights fall).
    assert!(b.heights_m.windows(2).all(|w| w[1] < w[0]), "{:?}", b.heights_m);
}

/// The ram's contact (its accelerometer) leads the load's by the clearance's closure on
/// independently rendered blows too, and not without one. Bounds as in
/// `diagnose::tests::the_ram_touches_before_the_load_rises_by_the_closure`: 0.25 mm at the
/// hammer die's ~4 m/s is over 60 µs (6 samples at 100 kHz); the press's 600 kg die at under
/// twice the tool's 0.36 m/s takes over 0.35 ms (7 samples at 20 kHz). Without a clearance
/// the two agree within the sample the load's contact is rounded to, plus one for the
/// anti-alias filter's delay, which the accelerometer and the load share.
#[test]
fn the_ram_leads_the_load_by_the_closure_on_independent_blows() {
    for (kind, hidden, lo, hi) in [
        (Kind::Hammer, Hidden::None, -2.0, 2.0),
        (Kind::Hammer, Hidden::Clearance { gap_m: 0.25e-3, die_kg: 0.0 }, 6.0, f64::INFINITY),
        (Kind::Press, Hidden::Clearance { gap_m: 0.25e-3, die_kg: 600.0 }, 7.0, f64::INFINITY),
    ] {
        let (_, lead) = baseline_location(kind, &hidden, CALIB_SEED);
        assert!((lo..=hi).contains(&lead), "{kind:?} {hidden:?}: {lead}");
    }
}

/// The diagnosis takes each blow's start height from the encoder's chain
/// (`Heights::Encoder`) where the sheet has hand-measured heights (±0.2 mm here). The chain
/// goes from the model's first contact placed on the encoder, so a fresh copper billet's
/// late load-level contact on the press (118 µm late on this seed, which the chain from the
/// contact sample carried to every later blow) does not offset it. A chained blow still
/// starts from its own load-level contact (its model contact is not known before it is
/// simulated), so each start carries that contact's uncertainty: a sample's travel at the
/// fastest impact plus two 10 µm steps (`tol`), shared offset included.
#[test]
fn the_encoder_chain_gives_the_start_heights() {
    for kind in [Kind::Hammer, Kind::Press] {
        let m = machine(kind);
        let b = billet(kind, &Hidden::None, &speeds(kind).0, 1.0, CALIB_SEED);
        let tol = b.refs.iter().map(|r| r.v0_mps * r.dt_s).fold(0.0, f64::max) + 20e-6;
        let n = b.refs.len();
        let obj = Objective::new(b.refs, vec![true; n], b.setting, m.kind()).with_heights(Heights::Encoder);
        let sims = obj.simulate(&m).expect("the base model simulates the independent blows");
        let err: Vec<f64> =
            sims[1..].iter().zip(&b.heights_m).map(|(s, t)| s.h_start_m.expect("a billet blow") - t).collect();
        eprintln!("HEIGHTS {kind:?}: errors {:?} µm", err.iter().map(|e| (e * 1e6).round()).collect::<Vec<_>>());
        assert!(err.iter().all(|e| e.abs() <= tol), "{kind:?}: {err:?} (±{tol})");
    }
}

/// Issue #17 item 3: the clearance's fit starts from the gap the measured closure shows
/// (`BlowSet::closure_gap_m`: what the lower tool crosses while the ram's contact leads the
/// load's), at `attribute::CLOSURE_SHARES` of it, 0.25–2 (see there). The hidden gap must lie
/// in that range on both machines' independent blows.
///
/// The range's lower end was set on `CALIB_SEED` at 0.25 mm, on the hammer's closure as the
/// ram's travel over the lead. That read the hammer's 0.1 and 0.5 mm gaps on `OTHER_SEED` as
/// 0.577 and 1.178 mm (the 0.1 mm below the range): its 26 kg die starts at rest under the
/// gap and the billet's load pushes it across, so the closure is now what the die crosses,
/// `F T² / (2 m2)` (the press's stays the ram's travel). Measured with it, seeds 3 and 7: the
/// hammer shows 0.258, 0.279, 0.121 and 0.519 mm for 0.25, 0.25, 0.1 and 0.5 mm, the press
/// 0.280, 0.270, 0.108 and 0.525 mm. Seed 11 (0.15 and 0.35 mm) was added after the change,
/// and not looked at before it was asserted: hammer 0.159 and 0.358 mm, press 0.165 and
/// 0.390 mm.
#[test]
fn the_measured_closure_brackets_the_hidden_gap() {
    let unseen = OTHER_SEED + 4;
    for (seed, gap) in [
        (CALIB_SEED, 0.25e-3),
        (OTHER_SEED, 0.25e-3),
        (OTHER_SEED, 0.1e-3),
        (OTHER_SEED, 0.5e-3),
        (unseen, 0.15e-3),
        (unseen, 0.35e-3),
    ] {
        for (kind, hidden) in [
            (Kind::Hammer, Hidden::Clearance { gap_m: gap, die_kg: 0.0 }),
            (Kind::Press, Hidden::Clearance { gap_m: gap, die_kg: 600.0 }),
        ] {
            let m = machine(kind);
            let b = billet(kind, &hidden, &speeds(kind).0, 1.0, seed);
            let n = b.refs.len();
            let set = BlowSet {
                obj: Objective::new(b.refs, vec![true; n], b.setting, m.kind()),
                windows: Vec::new(),
                mode2_hz: m.second_mode_hz(),
            };
            let shown = set.closure_gap_m(&m).unwrap_or_else(|| panic!("{kind:?} seed {seed}: no closure measured"));
            eprintln!("CLOSURE {kind:?} seed {seed}: {:.3} mm shown, {:.3} mm hidden", shown * 1e3, gap * 1e3);
            assert!((0.25 * shown..=2.0 * shown).contains(&gap), "{kind:?} seed {seed}: {shown} against {gap}");
        }
    }
}

/// Issue #17: the location on independent blows. A clearance at `impact`, a compliant contact
/// in `spring_back`, the flow effects (friction rise, strain rate) in `forming`, on both
/// machines. The no-effect cases have no location to hold; the damped foundation is not
/// prescribed one by the issue (it shows in the forming on both renderers, 0.52–0.80).
///
/// Seeds: the causes were found and fixed on seed 3 (the renderer's press sensors rode on the
/// tool instead of the ram, which split every press case 0.5/0.5 between forming and
/// spring-back; the hammer's measured end of forming crept to the load's zero with a
/// clearance, `localise::ram_speed_at_load_contact`). Asserted on seeds 7 and 8, first seen
/// when this was written. Margins there: the hammer's clearance is the narrowest (impact
/// 0.51 against the forming's 0.46), then the press's compliant contact (spring-back 0.47
/// against 0.42 on seed 7).
#[test]
fn location_on_independent_blows() {
    let mut wrong = Vec::new();
    for seed in [OTHER_SEED, OTHER_SEED + 1] {
        for (name, kind, hidden) in cases() {
            let expected = match hidden {
                Hidden::Clearance { .. } => "impact",
                Hidden::Compliant { .. } => "spring_back",
                Hidden::FrictionRise { .. } | Hidden::StrainRate { .. } | Hidden::Hardening { .. } => "forming",
                // Not among `cases()`: rendered for `tests/diagnose_adopt.rs` only.
                Hidden::None | Hidden::Foundation { .. } | Hidden::Thermal { .. } | Hidden::Highpass { .. } => continue,
            };
            let (loc, lead) = baseline_location(kind, &hidden, seed);
            eprintln!("LOCATION {name} seed {seed}: {} {:?} (ram lead {lead:.1} samples)", loc.phase(), loc.share());
            if loc.phase() != expected {
                wrong.push(format!("{name} seed {seed}: {} not {expected}, {:?}", loc.phase(), loc.share()));
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// The base model and the independent renderer describe the same machine (issue #17): on
/// blows without an effect, the library's model with the machine file's parameters follows
/// the renderer's elastic-plastic billet to about the noise. This failed on the hammer while
/// the renderer's die started at rest (first peak 1.23 MN modelled against 0.50 MN rendered,
/// seed 3, baseline holdout 0.20 of the peak): the hammer paper assigns the impact speed to
/// both masses (§2.3.1), which the renderer now does.
///
/// Bounds set on seed 3 (largest nrmse per blow: hammer 0.0061, press 0.0134; first peaks
/// within 0.4 % and 1 %), asserted on seed `OTHER_SEED`: nrmse ≤ 0.025 of the peak (about twice
/// seed 3's worst, and still 8× under the 0.20 a die at rest gave), peaks within 3 %.
#[test]
fn the_base_model_matches_independent_blows_without_an_effect() {
    for kind in [Kind::Hammer, Kind::Press] {
        let m = machine(kind);
        let b = billet(kind, &Hidden::None, &speeds(kind).0, 1.0, OTHER_SEED);
        let n = b.refs.len();
        let obj = Objective::new(b.refs, vec![true; n], b.setting, m.kind());
        let sims = obj.simulate(&m).expect("the base model simulates the independent blows");
        for (r, s) in obj.refs.iter().zip(&sims) {
            let peak_model = s.load_n.iter().fold(0.0f64, |a, &v| a.max(v));
            let e = forgemon::diagnose::localise::nrmse(r, s);
            let what = format!(
                "{kind:?} blow {:?}: nrmse {e:.4}, peak {:.3} MN rendered, {:.3} MN modelled",
                r.blow_index,
                r.peak_n / 1e6,
                peak_model / 1e6
            );
            eprintln!("BASE {what}");
            assert!(e <= 0.025, "{what}");
            assert!((peak_model / r.peak_n - 1.0).abs() <= 0.03, "{what}");
        }
    }
}
