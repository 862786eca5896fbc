//! Issue 37: `identify` knows when the model does not fit. Billets rendered by the
//! independent renderer (its own integrator, contact and DAQ chain; `tests/independent`),
//! with and without a hidden effect, identified with the base model from the paper's prior:
//! the residual against the load's own pre-trigger noise, the verdict, and how often the
//! truth lies within the reported standard errors.

mod independent;

use std::process::Command;

use independent::captures::{Rendered, render, write_dir};
use independent::{HAMMER, Hidden, Kind, PRESS, speeds};

/// What `identify` made of one billet.
#[derive(Debug)]
struct Fit {
    /// (key, fitted / truth − 1, reported relative standard error, determined).
    params: Vec<(String, f64, f64, bool)>,
    rms_load_error: f64,
    over_noise: f64,
    /// `[identify] model_fits`.
    fits: bool,
    /// What identify printed.
    text: String,
}

fn num(v: &toml::Value) -> f64 {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64)).unwrap_or(f64::NAN)
}

fn identify(kind: Kind, hidden: Hidden, khz: f64, seed: u64) -> Fit {
    try_identify(kind, hidden, khz, seed).unwrap_or_else(|e| panic!("seed {seed}: {e}"))
}

/// `identify`, with its refusal returned (the harnesses list it and go on).
fn try_identify(kind: Kind, hidden: Hidden, khz: f64, seed: u64) -> Result<Fit, String> {
    let tmp = tempfile::tempdir().unwrap();
    let machine = if kind == Kind::Hammer { HAMMER } else { PRESS };
    let r: Rendered = render(kind, &hidden, &speeds(kind).0, 1.0, khz * 1e3, seed);
    write_dir(tmp.path(), &r, machine);
    if let Some(keep) = std::env::var_os("FORGEMON_FIT_KEEP") {
        write_dir(
            &std::path::PathBuf::from(keep).join(format!("{kind:?}-{khz}-{seed}-{}", hidden.library_name())),
            &r,
            machine,
        );
    }
    let out = tmp.path().join("fit.machine.toml");
    let kind_arg = if kind == Kind::Hammer { "hammer" } else { "screw_press" };
    let run = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["identify", "--kind", kind_arg, "--reference"])
        .arg(tmp.path())
        .args(["--fit-blows", "1,2", "--starts", "8", "--monte-carlo", "0"])
        .args(if std::env::var_os("FORGEMON_FIT_INITIAL").is_some() {
            vec!["--initial".into(), tmp.path().join("machine.toml")]
        } else {
            vec![]
        })
        .arg("-o")
        .arg(&out)
        .output()
        .expect("forgemon runs");
    if !run.status.success() {
        return Err(String::from_utf8_lossy(&run.stderr).into_owned());
    }
    let text = std::fs::read_to_string(&out).unwrap();
    let t: toml::Table = text.parse().unwrap();
    let truth: toml::Table = machine.parse().unwrap();
    let id = &t["identify"];
    let params = id["std_error"]
        .as_table()
        .unwrap()
        .iter()
        .filter_map(|(k, se)| {
            let v = num(&t[k]);
            let tv = num(truth.get(k)?);
            Some((k.clone(), v / tv - 1.0, num(se) / v, id["determined"][k].as_bool().unwrap_or(false)))
        })
        .collect();
    Ok(Fit {
        params,
        rms_load_error: num(&id["rms_load_error"]),
        over_noise: id.get("residual_over_noise").map_or(f64::NAN, num),
        fits: id["model_fits"].as_bool().unwrap_or(true),
        text: String::from_utf8_lossy(&run.stdout).into_owned(),
    })
}

/// The seeds `FORGEMON_FIT_SEEDS` lists (comma-separated), else `default`.
fn seeds_or(default: Vec<u64>) -> Vec<u64> {
    std::env::var("FORGEMON_FIT_SEEDS")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or(default)
}

#[test]
#[ignore = "the misfit table: cargo test --release --test identify_fit -- --ignored --nocapture table"]
fn table() {
    let seeds = seeds_or(vec![1]);
    let only = std::env::var("FORGEMON_FIT_CASES").unwrap_or_default();
    for (name, kind, hidden) in independent::cases() {
        if !only.split(',').any(|c| name.contains(c)) {
            continue;
        }
        let rates: &[f64] = if kind == Kind::Hammer { &[100.0, 10.0] } else { &[10.0] };
        for &khz in rates {
            for &seed in &seeds {
                let f = match try_identify(kind, hidden, khz, seed) {
                    Ok(f) => f,
                    Err(e) => {
                        println!("{name:<18} {khz:>4} kHz seed {seed}: refused: {}", e.trim());
                        continue;
                    }
                };
                let p: Vec<String> = f
                    .params
                    .iter()
                    .map(|(k, e, se, d)| {
                        format!(
                            "{k} {:+.3}%±{:.3}% z {:+.1}{}",
                            e * 100.0,
                            se * 100.0,
                            e.ln_1p() / se,
                            if *d { "" } else { "?" }
                        )
                    })
                    .collect();
                println!(
                    "{name:<18} {khz:>4} kHz seed {seed}: rms {:.4} over noise {:>6.1} | {}",
                    f.rms_load_error,
                    f.over_noise,
                    p.join(", ")
                );
            }
        }
    }
}

/// Seeds the misfit limit was set on (`identify::MISFIT_OVER_NOISE`): 1–3. The test below
/// reports on seed 7, the coverage harness on 11–22.
const REPORT_SEED: u64 = 7;

/// The base model leaves more than twice the load's noise unexplained wherever a hidden
/// effect shapes the load, and `identify` then says so: `model_fits = false`, no parameter
/// determined, `diagnose` named. Where nothing is hidden it fits, at 100 kHz on the hammer
/// and at 10 kHz on the press. The hammer at 10 kHz does not: the renderer's anti-alias
/// filter (two Butterworths at 4 kHz) shapes a 1.5 ms pulse the model draws unfiltered, and
/// its parameters come out 8–20 % off (seeds 1–6), so the verdict is the right one there too.
/// Where it fits, every determined parameter lies within 3σ of the truth.
/// Not detectable and not asserted: a compliant contact on the press, which a softer frame
/// in series reproduces to the noise (residual 1.0–1.1 times it).
#[test]
fn a_model_that_leaves_more_than_twice_the_noise_unexplained_is_said_not_to_fit() {
    let fits = [(Kind::Hammer, Hidden::None, 100.0), (Kind::Press, Hidden::None, 10.0)];
    let named = |n: &'static str, khz: f64| {
        let (_, kind, hidden) = independent::cases().into_iter().find(|c| c.0 == n).expect("a case of the suite");
        (kind, hidden, khz, n)
    };
    let not = [
        (Kind::Hammer, Hidden::None, 10.0, "hammer-none"),
        named("hammer-foundation", 100.0),
        named("hammer-friction", 100.0),
        named("press-foundation", 10.0),
        named("press-friction", 10.0),
        named("press-rate", 10.0),
    ];
    let mut wrong = Vec::new();
    for (kind, hidden, khz) in fits {
        let f = identify(kind, hidden, khz, REPORT_SEED);
        println!("{kind:?} without an effect at {khz} kHz: residual {:.2} times the noise", f.over_noise);
        for (k, e, se, d) in &f.params {
            println!(
                "  {k}: error {:+.3} %, {:.3} % 1σ, z {:+.2}, determined {d}",
                e * 100.0,
                se * 100.0,
                e.ln_1p() / se
            );
        }
        let m1 = if kind == Kind::Hammer { "m1_kg" } else { "m_ram_kg" };
        let m1_determined = f.params.iter().any(|p| p.0 == m1 && p.3);
        // Standard errors that hold the model's error too (the jackknife over the blows,
        // `identify::fit::widen_by_blows`): every determined parameter within 3σ of the truth.
        // A right error leaves one out for 370; without the jackknife the hammer's m2 was
        // 3.7σ off on this seed (its 0.3 % bias), with it 2.5σ.
        for (k, e, se, _) in f.params.iter().filter(|p| p.3) {
            if e.ln_1p().abs() > 3.0 * se {
                wrong.push(format!("{kind:?} at {khz} kHz: {k} is {:.1}σ off", e.ln_1p() / se));
            }
        }
        if !(f.fits && f.over_noise <= 2.0 && m1_determined && f.text.contains("The model explains the blows")) {
            wrong.push(format!("{kind:?} at {khz} kHz without an effect: {f:?}"));
        }
    }
    for (kind, hidden, khz, name) in not {
        let f = identify(kind, hidden, khz, REPORT_SEED);
        println!("{name} at {khz} kHz: residual {:.2} times the noise", f.over_noise);
        let none_determined = f.params.iter().all(|p| !p.3);
        if f.fits || f.over_noise <= 2.0 || !none_determined || !f.text.contains("forgemon diagnose") {
            wrong.push(format!("{name} at {khz} kHz: {f:?}"));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// How often the truth lies within the reported 1σ on renders of a machine without a hidden
/// effect, seeds 11–22 (`FORGEMON_FIT_SEEDS` to change), over the parameters `identify`
/// marks determined, with each one's z. The jackknife's t factor (`fit::one_sigma_t`) is a
/// quantile, not tuned: both 11–22 and 31–42 report it (README, `identify`).
/// `FORGEMON_FIT_INITIAL=1` hands `identify` the machine file with its `[daq]` filter
/// (`--initial`), `FORGEMON_FIT_KEEP=DIR` keeps each rendered directory.
/// `cargo test --release --test identify_fit -- --ignored --nocapture coverage`
#[test]
#[ignore = "harness: 24 identifications; run by hand"]
fn coverage() {
    let seeds = seeds_or((11..=22).collect());
    for (kind, khz) in [(Kind::Hammer, 100.0), (Kind::Press, 10.0)] {
        // Each determined parameter's z = ln(fitted / truth) / relative standard error.
        let mut per_key: std::collections::BTreeMap<String, Vec<f64>> = Default::default();
        for &seed in &seeds {
            let Ok(f) = try_identify(kind, Hidden::None, khz, seed) else { continue };
            for (k, e, se, d) in &f.params {
                if *d {
                    per_key.entry(k.clone()).or_default().push(e.ln_1p() / se);
                }
            }
        }
        let inside = |z: &[f64]| z.iter().filter(|z| z.abs() <= 1.0).count();
        for (k, z) in &per_key {
            let zs: Vec<String> = z.iter().map(|z| format!("{z:+.1}")).collect();
            println!("{kind:?} {khz} kHz {k}: {} of {} within 1 sigma; z {}", inside(z), z.len(), zs.join(" "));
        }
        let (inside, n) = per_key.values().fold((0, 0), |a, z| (a.0 + inside(z), a.1 + z.len()));
        println!("{kind:?} {khz} kHz: {inside} of {n} determined parameters within 1 sigma");
    }
}
