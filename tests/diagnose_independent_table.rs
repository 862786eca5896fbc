//! The per-case, per-renderer table of issue #17 (an `#[ignore]`d harness, minutes per
//! case): for each case of `independent::cases`, the verdict, the holdout shrink and the
//! location of `forgemon::diagnose` on
//! - `own`: the project's renderer (`synth::synth_blows`, the library's effect at the same
//!   parameters where it has them, its fixed values where it does not), and
//! - `independent`: `tests/independent/` (its own contact law, integrator, DAQ chain and
//!   hand-measured heights).
//!
//! Run: `cargo test --release --test diagnose_independent_table -- --ignored --nocapture`
//! (`FORGEMON_TABLE_CASES=hammer-none,press-rate` for some cases, `FORGEMON_TABLE_SEEDS=1`
//! for the seed pair 1/2 instead of 3/4, `FORGEMON_TABLE_RENDERERS=independent` for one
//! renderer.)

#[path = "independent/mod.rs"]
mod independent;

use forgemon::config::parse_process;
use forgemon::diagnose::diagnose;
use forgemon::identify::objective::{Reference, Setting};
use forgemon::physics::effects::{Effect, EffectSet};
use forgemon::signal::segment::{SegmentConfig, Segmenter};
use forgemon::synth::{CaptureSpec, rows_batch, synth_blows};
use independent::{Hidden, Kind, billet, cases, machine, speeds};

/// The library's effect for a hidden one (its fixed values where it holds some).
fn library_spec(kind: Kind, hidden: &Hidden) -> Option<String> {
    Some(match *hidden {
        Hidden::None => return None,
        Hidden::Clearance { gap_m, die_kg } if kind == Kind::Press => {
            format!("clearance:gap_m={gap_m},m_lower_kg={die_kg}")
        }
        Hidden::Clearance { gap_m, .. } => format!("clearance:gap_m={gap_m}"),
        Hidden::Compliant { k_n_per_m } => format!("elastic_recovery:k_contact_N_per_m={k_n_per_m}"),
        Hidden::FrictionRise { p } => format!("friction_rise:exponent={p}"),
        Hidden::StrainRate { m, .. } => format!("strain_rate:m={m}"),
        Hidden::Foundation { m_kg, k_n_per_m, .. } => {
            format!("foundation:m3_kg={m_kg},k3_N_per_m={k_n_per_m},c3_Ns_per_m=0")
        }
        Hidden::Hardening { n, eps_ref } => format!("strain_hardening:n={n},eps_ref={eps_ref}"),
        Hidden::Thermal { q } => format!("thermal:q_dT={q}"),
        Hidden::Highpass { tau_s } => format!("sensor_highpass:tau_s={tau_s}"),
    })
}

/// The project's renderer: one billet as `tests/diagnose.rs` makes it.
fn own_billet(kind: Kind, hidden: &Hidden, v0s: &[f64], scale: f64, seed: u64) -> (Vec<Reference>, Setting) {
    let m = machine(kind);
    let sheet = match kind {
        Kind::Hammer => include_str!("../config/steel-16NiCrMo13.process.toml"),
        Kind::Press => include_str!("../config/copper-cu99.process.toml"),
    };
    let mut p = parse_process("p", sheet).unwrap();
    p.measured_final_heights_m.clear();
    p.billet.height_m *= scale;
    let effects = library_spec(kind, hidden)
        .map_or(EffectSet::NONE, |s| EffectSet::from_effects(&[Effect::parse_spec(&s).unwrap()]));
    let spec = if kind == Kind::Hammer { CaptureSpec::hammer(seed) } else { CaptureSpec::press(seed) };
    let fit_s = forgemon::estimate::EstimatorConfig::for_kind(m.kind()).fit_s;
    let refs = synth_blows(&m, &effects, &p, v0s, &spec)
        .unwrap()
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let batch = rows_batch("c", 0, 0, 1e9 / spec.sample_rate_hz, &b.rows);
            let cut = Segmenter::cut_all(SegmentConfig::for_kind(m.kind()), [&batch]);
            forgemon::diagnose::localise::reference("b", &cut[0], Some(i + 1), fit_s, &m).unwrap()
        })
        .collect();
    (refs, Setting::Billet(p))
}

#[test]
#[ignore = "minutes per case: prints the per-case, per-renderer verdict table"]
fn independent_table() {
    let only = std::env::var("FORGEMON_TABLE_CASES").ok();
    let seed: u64 = std::env::var("FORGEMON_TABLE_SEEDS").ok().and_then(|s| s.parse().ok()).unwrap_or(3);
    let renderers = std::env::var("FORGEMON_TABLE_RENDERERS").unwrap_or_else(|_| "own,independent".into());
    println!(
        "| case | renderer | seeds | verdict | shrink | baseline holdout | location | impact | forming | spring_back | post |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, kind, hidden) in cases() {
        if only.as_ref().is_some_and(|o| !o.split(',').any(|c| c == name)) {
            continue;
        }
        let m = machine(kind);
        let (v_cal, v_hold) = speeds(kind);
        for renderer in renderers.split(',') {
            let (calib, holdout) = match renderer {
                "own" => {
                    (own_billet(kind, &hidden, &v_cal, 1.0, seed), own_billet(kind, &hidden, &v_hold, 0.9, seed + 1))
                }
                _ => {
                    let (c, h) =
                        (billet(kind, &hidden, &v_cal, 1.0, seed), billet(kind, &hidden, &v_hold, 0.9, seed + 1));
                    ((c.refs, c.setting), (h.refs, h.setting))
                }
            };
            let t = std::time::Instant::now();
            let Some(d) = diagnose(&m, &EffectSet::NONE, calib, holdout, &|| {}) else {
                println!("| {name} | {renderer} | {seed}/{} | (no diagnosis: a simulation failed) |", seed + 1);
                continue;
            };
            let (verdict, shrink) = d
                .verdict
                .as_ref()
                .map_or(("none".to_string(), 0.0), |f| (f.name.clone(), 1.0 - f.holdout / d.baseline_holdout));
            let s = d.location.share();
            let c = &d.confidence;
            println!(
                "| {name} | {renderer} | {seed}/{} | {verdict} (hidden {}) | {shrink:.2} | {:.4} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} s | agreement {:.2} runner-up {} | acts {} |",
                seed + 1,
                hidden.library_name(),
                d.baseline_holdout,
                d.location.phase(),
                s.impact,
                s.forming,
                s.spring_back,
                s.post,
                t.elapsed().as_secs_f64(),
                c.agreement,
                c.runner_up.as_ref().map_or("-".to_string(), |r| format!("{} ({:.2}): {}", r.name, r.share, r.why)),
                d.acts.map_or("-".to_string(), |a| format!("{} {} {:?}", a.phase(), a.band(), a.removed_by_phase)),
            );
            println!("  {}", forgemon::diagnose::words::opening(&d));
        }
    }
}
