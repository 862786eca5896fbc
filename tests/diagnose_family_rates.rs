//! The verdict's rates on the renderer family (issue 41): full diagnoses over renderers ×
//! machine kinds × effects × seeds, each case on its own drawn machine with a drawn effect
//! strength (`independent::drawn`), printed and written to `docs/diagnose-rates.md`. An
//! `#[ignore]`d harness, never a CI test.
//!
//! Seeds (`FORGEMON_FAMILY_SET`): `tune` (`drawn::TUNE`) to change the diagnosis on, `report`
//! (`drawn::REPORT`, the default) for the rates a change is judged by; a number runs the cases
//! from that seed on (to look at one case again).
//!
//! Run: `cargo test --release --test diagnose_family_rates -- --ignored --nocapture`, with
//! - `FORGEMON_FAMILY_SEEDS=20` seeds per cell (the default, `DEFAULT_SEEDS`);
//! - `FORGEMON_FAMILY_RENDERERS=rigid-eq3,elastic-siebel,hertz-tresca` (the default; any
//!   contact `rigid|elastic|hertz` with any friction `eq3|siebel|tresca`);
//! - `FORGEMON_FAMILY_KINDS=hammer,press`, `FORGEMON_FAMILY_EFFECTS=none,clearance,…`;
//! - `FORGEMON_FAMILY_OUT=file` appends one JSON line per case (with the diagnosis's report);
//! - `FORGEMON_FAMILY_FROM=file` diagnoses nothing and rebuilds the table from such a file;
//! - `FORGEMON_FAMILY_DOC=path` writes the table there; without it the table goes to
//!   `docs/diagnose-rates.md` only when nothing above selects a subset (set, renderers, kinds,
//!   effects and seeds at their defaults).

#[path = "independent/mod.rs"]
mod independent;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;

use forgemon::diagnose::{Diagnosis, diagnose};
use independent::Kind;
use independent::drawn::{self, EFFECTS};
use independent::family::{RENDERERS, Renderer};
use independent::verdict::{UNCERTAIN, names, own_shrink, strength, verdict_of};

/// Seeds per cell by default: 3 renderers × 2 kinds × 6 effects × 20 = 720 diagnoses, 40-50 min
/// one after the other on this 2-core machine. A cell's rate moves in steps of 5 %, so
/// that the goals (≤ 5 % false positives, ≥ 95 % found) can be told apart from a single case
/// (at 6 seeds a cell, one miss was 83 %).
const DEFAULT_SEEDS: u64 = 20;
/// A case counts as strong when its hidden effect's own error (`effect_strength`) is above this
/// over the noise (twice the verdict rule's `NOISE_FACTOR` of 2).
const STRONG: f64 = 4.0;
/// Issue 41's goal for a diagnosis's time on this machine, s.
const HAMMER_GOAL_S: f64 = 5.0;
const PRESS_GOAL_S: f64 = 30.0;
/// The columns of the confusion matrix beyond `EFFECTS` and the other effects named.
const ERROR: &str = "error";

/// One case's outcome.
#[derive(Debug, Clone)]
struct Outcome {
    renderer: String,
    kind: Kind,
    effect: &'static str,
    seed: u64,
    /// The verdict (`verdict_of`), or `error`.
    verdict: String,
    error: Option<String>,
    /// Baseline holdout nrmse over the noise; the hidden effect's own candidate's shrink.
    strength: f64,
    own_shrink: f64,
    /// The bootstrap's share of resamples with the case's verdict (`verdict.confidence`).
    agreement: f64,
    /// The case's time, its render and its diagnosis, s; the diagnosis's alone (what
    /// `forgemon diagnose` spends on its captures, the speed goal).
    secs: f64,
    diagnose_secs: f64,
    /// The hidden effect with its drawn parameters (`Debug`).
    hidden: String,
}

fn kind_name(kind: Kind) -> &'static str {
    match kind {
        Kind::Hammer => "hammer",
        Kind::Press => "press",
    }
}

fn list(var: &str) -> Option<Vec<String>> {
    std::env::var(var).ok().map(|s| s.split(',').map(|x| x.trim().to_string()).filter(|x| !x.is_empty()).collect())
}

/// Diagnose one case (`drawn::case`), with the machine file's own effects (its `[daq]`
/// filter) as `forgemon diagnose` takes them.
fn run_case(renderer: Renderer, kind: Kind, effect: &'static str, seed: u64) -> (Outcome, Option<Diagnosis>) {
    let t = std::time::Instant::now();
    let mut o = Outcome {
        renderer: renderer.name(),
        kind,
        effect,
        seed,
        verdict: ERROR.to_string(),
        error: None,
        strength: f64::NAN,
        own_shrink: f64::NAN,
        agreement: f64::NAN,
        secs: 0.0,
        diagnose_secs: f64::NAN,
        hidden: String::new(),
    };

    let run = std::panic::catch_unwind(|| {
        let c = drawn::case(renderer, kind, effect, seed)?;
        let td = std::time::Instant::now();
        let d = diagnose(
            &c.machine.file.machine,
            &c.machine.file.effect_set(),
            (c.calib.refs, c.calib.setting),
            (c.holdout.refs, c.holdout.setting),
            &|| {},
        )
        .ok_or_else(|| "no diagnosis (a simulation failed)".to_string())?;
        Ok::<_, String>((c.hidden, d, td.elapsed().as_secs_f64()))
    });
    let d = match run {
        Ok(Ok((hidden, d, secs))) => {
            o.diagnose_secs = secs;
            o.hidden = format!("{hidden:?}");
            o.verdict = verdict_of(&d);
            o.strength = strength(&d);
            o.own_shrink = own_shrink(&d, effect);
            o.agreement = d.confidence.agreement;
            Some(d)
        }
        Ok(Err(e)) => {
            o.error = Some(e);
            None
        }
        Err(p) => {
            o.error = Some(format!(
                "panic: {}",
                p.downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default()
            ));
            None
        }
    };
    o.secs = t.elapsed().as_secs_f64();
    (o, d)
}

/// The hidden effect's own share of the base model's holdout error, over the noise: the
/// case's strength less, in quadrature, the strength of the `none` case on the same renderer,
/// machine and noise (same seed; `drawn::case` draws the machine from the seed alone). On the
/// Siebel and Tresca renderers the base model misses the friction law even without an effect;
/// an effect whose case is no further from the base model than that is not a strong case,
/// however large the case's own strength. NaN without that none case.
fn effect_strength(all: &[Outcome], o: &Outcome) -> f64 {
    if o.effect == "none" {
        return o.strength;
    }
    let none = all.iter().find(|n| {
        n.effect == "none" && n.renderer == o.renderer && n.kind == o.kind && n.seed == o.seed && n.error.is_none()
    });
    none.map_or(f64::NAN, |n| (o.strength * o.strength - n.strength * n.strength).max(0.0).sqrt())
}

fn pct(a: usize, b: usize) -> String {
    if b == 0 { "–".to_string() } else { format!("{a}/{b} = {:.0} %", 100.0 * a as f64 / b as f64) }
}

fn range(v: &[f64]) -> (f64, f64) {
    v.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() { f64::NAN } else { v[v.len() / 2] }
}

/// The column of the confusion matrix `o` falls in.
fn column(o: &Outcome) -> String {
    if o.error.is_some() {
        return ERROR.to_string();
    }
    if o.verdict == UNCERTAIN || o.verdict == "none" {
        return o.verdict.clone();
    }
    if names(&o.verdict, o.effect) {
        return o.effect.to_string();
    }
    o.verdict.split('+').next().unwrap_or("").to_string()
}

/// Bands of effect strength for `by_strength`: from `STRONG` up.
const BANDS: [(f64, f64); 3] = [(STRONG, 10.0), (10.0, 30.0), (30.0, f64::INFINITY)];

/// Each effect found, per machine kind over the renderers, in bands of effect strength:
/// how the rate grows with the effect's size.
fn by_strength(all: &[Outcome]) -> String {
    let mut s = String::new();
    let band = |(lo, hi): (f64, f64)| if hi.is_finite() { format!("{lo}–{hi}") } else { format!("≥ {lo}") };
    let _ = writeln!(
        s,
        "## Found by effect strength\n\nEach effect found, over the renderers, in bands of its effect strength.\n\n\
         | kind | hidden | {} |\n|---|---|{}",
        BANDS.map(band).join(" | "),
        "---|".repeat(BANDS.len())
    );
    for kind in [Kind::Hammer, Kind::Press] {
        for e in &EFFECTS[1..] {
            let cells: Vec<String> = BANDS
                .iter()
                .map(|&(lo, hi)| {
                    let in_band: Vec<&Outcome> = all
                        .iter()
                        .filter(|o| o.kind == kind && o.effect == *e && o.error.is_none())
                        .filter(|o| (lo..hi).contains(&effect_strength(all, o)))
                        .collect();
                    pct(in_band.iter().filter(|o| names(&o.verdict, e)).count(), in_band.len())
                })
                .collect();
            let _ = writeln!(s, "| {} | {e} | {} |", kind_name(kind), cells.join(" | "));
        }
    }
    let _ = writeln!(s);
    s
}

/// Each case's verdict and the bootstrap's agreement with it, a row per renderer, kind and
/// hidden effect, a column per seed.
fn agreements(all: &[Outcome]) -> String {
    let mut seeds: Vec<u64> = all.iter().map(|o| o.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let mut s = format!(
        "\n## Bootstrap agreement per case\n\nEach case's verdict and the share of the bootstrap's resamples that reach it \
         (`verdict.confidence.agreement`; under 80 % the report says uncertain).\n\n\
         | renderer | kind | hidden | {} |\n|---|---|---|{}\n",
        seeds.iter().map(|k| format!("seed {k}")).collect::<Vec<_>>().join(" | "),
        "---|".repeat(seeds.len())
    );
    let mut rows: Vec<(&str, Kind, &str)> = Vec::new();
    for o in all {
        if !rows.contains(&(o.renderer.as_str(), o.kind, o.effect)) {
            rows.push((o.renderer.as_str(), o.kind, o.effect));
        }
    }
    for (renderer, kind, effect) in rows {
        let cells: Vec<String> = seeds
            .iter()
            .map(|k| {
                all.iter()
                    .find(|o| o.renderer == renderer && o.kind == kind && o.effect == effect && o.seed == *k)
                    .map_or("–".to_string(), |o| match &o.error {
                        Some(_) => ERROR.to_string(),
                        None => format!("{} {:.2}", o.verdict, o.agreement),
                    })
            })
            .collect();
        let _ = writeln!(s, "| {renderer} | {} | {effect} | {} |", kind_name(kind), cells.join(" | "));
    }
    s
}

/// The document: header, rates per renderer and kind, confusion matrices, times, misses.
fn document(all: &[Outcome], set: &str, seeds: u64, renderer_names: &[String]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Diagnosis rates on the renderer family\n\n\
         Regenerate: `cargo test --release --test diagnose_family_rates -- --ignored --nocapture` \
         (`FORGEMON_FAMILY_FROM=cases.jsonl` rebuilds it from the JSON lines `FORGEMON_FAMILY_OUT` wrote)\n\n\
         - Method: `forgemon::diagnose` (the machine file's `[daq]` filter as its effects, as `forgemon diagnose`) \
         on blows of the `tests/independent/` renderers {}: contact rigid-plastic, elastic-plastic or Hertz in series; \
         yield load by eq. 3, Siebel or Tresca (m = √3 μ). Each case is a machine drawn from its seed (hammer m1 \
         200 kg–5 t, die 0.01–0.2 × m1; press ram 5–150 t, tool 0.01–0.1 × ram; springs and damping ratios ×0.3–3 of \
         the fixed rigs', no press frame damper; `tests/independent/drawn.rs`), the sheet's billet scaled to the \
         machine (five blows leave about half its height), one hidden effect at a strength drawn log-uniform, and a \
         calibration and a holdout billet of five blows each.\n\
         - Strength: the base model's holdout nrmse over the sensor noise (`baseline_holdout / noise_nrmse`). \
         Effect strength: the hidden effect's own share of it, the case's strength less, in quadrature, that of \
         the none case on the same machine and noise (same seed); it sets which cases are strong, since on the \
         Siebel and Tresca renderers the none case is already off the base model.\n\
         - Seeds: set `{set}`, {seeds} per cell (renderer × kind × effect): a cell's rate moves in steps of {:.1} %.\n\
         - Goals: false positives on `none` ≤ 5 %; each effect found in ≥ 95 % of its cases with effect strength ≥ {STRONG}.\n\
         - A pair verdict `a+b` counts as finding a and b; `uncertain` is a verdict the report marks uncertain \
         and settles on no effect. A verdict uncertain only in what goes with an effect that ≥ 80 % of the \
         bootstrap resamples name (`verdict.confidence.settled`) counts as that effect.\n\
         - Siebel and Tresca (m = √3 μ makes them one law) part from the library's eq. 3 at second order in \
         μ d/h, up to 1 % of the load on the steel hammer's flattest billets: a real gap of the base model, which \
         no library effect is, and which shows as the none cases' strength on those renderers.\n\
         - False positives count a named effect; an `uncertain` verdict (the bootstrap's agreement under 80 %) names \
         none and is counted beside them.\n",
        renderer_names.join(", "),
        100.0 / seeds as f64
    );
    let _ = writeln!(
        s,
        "## Summary\n\nFalse positives on none (a named effect), and each effect found in its cases of effect strength ≥ {STRONG}.\n"
    );
    let _ = writeln!(s, "| renderer | kind | none: false positives | {} |", EFFECTS[1..].join(" | "));
    let _ = writeln!(s, "|---|---|---|{}", "---|".repeat(EFFECTS.len() - 1));
    for r in renderer_names {
        for kind in [Kind::Hammer, Kind::Press] {
            let ok = |e: &str| -> Vec<&Outcome> {
                all.iter()
                    .filter(|o| &o.renderer == r && o.kind == kind && o.effect == e && o.error.is_none())
                    .collect()
            };
            if all.iter().all(|o| &o.renderer != r || o.kind != kind) {
                continue;
            }
            let none = ok("none");
            let fp = none.iter().filter(|o| o.verdict != "none" && o.verdict != UNCERTAIN).count();
            let unsure = none.iter().filter(|o| o.verdict == UNCERTAIN).count();
            let found: Vec<String> = EFFECTS[1..]
                .iter()
                .map(|e| {
                    let strong: Vec<&Outcome> =
                        ok(e).into_iter().filter(|o| effect_strength(all, o) >= STRONG).collect();
                    pct(strong.iter().filter(|o| names(&o.verdict, e)).count(), strong.len())
                })
                .collect();
            let _ = writeln!(
                s,
                "| {r} | {} | {} (uncertain {unsure}) | {} |",
                kind_name(kind),
                pct(fp, none.len()),
                found.join(" | ")
            );
        }
    }
    let _ = writeln!(s);
    s.push_str(&by_strength(all));
    for r in renderer_names {
        for kind in [Kind::Hammer, Kind::Press] {
            let cell: Vec<&Outcome> = all.iter().filter(|o| &o.renderer == r && o.kind == kind).collect();
            if cell.is_empty() {
                continue;
            }
            let _ = writeln!(s, "## {r}, {}\n", kind_name(kind));
            let _ = writeln!(
                s,
                "| hidden | cases | errors | found (all) | found (effect strength ≥ {STRONG}) | strength median (min–max) | effect strength median (min–max) |"
            );
            let _ = writeln!(s, "|---|---|---|---|---|---|---|");
            for e in EFFECTS {
                let rows: Vec<&&Outcome> = cell.iter().filter(|o| o.effect == e).collect();
                if rows.is_empty() {
                    continue;
                }
                let ok: Vec<&&&Outcome> = rows.iter().filter(|o| o.error.is_none()).collect();
                let hit = |o: &&&&Outcome| if e == "none" { o.verdict == "none" } else { names(&o.verdict, e) };
                let strong: Vec<&&&Outcome> =
                    ok.iter().filter(|o| effect_strength(all, o) >= STRONG).copied().collect();
                let st: Vec<f64> = ok.iter().map(|o| o.strength).collect();
                let own: Vec<f64> = ok.iter().map(|o| effect_strength(all, o)).filter(|x| x.is_finite()).collect();
                let (lo, hi) = range(&st);
                let (own_lo, own_hi) = range(&own);
                let label = if e == "none" { "none (verdict none)".to_string() } else { e.to_string() };
                let _ = writeln!(
                    s,
                    "| {label} | {} | {} | {} | {} | {:.1} ({lo:.1}–{hi:.1}) | {:.1} ({own_lo:.1}–{own_hi:.1}) |",
                    rows.len(),
                    rows.len() - ok.len(),
                    pct(ok.iter().filter(|o| hit(o)).count(), ok.len()),
                    if e == "none" {
                        "–".to_string()
                    } else {
                        pct(strong.iter().filter(|o| hit(o)).count(), strong.len())
                    },
                    median(st.clone()),
                    median(own.clone()),
                );
            }
            let none: Vec<&&Outcome> = cell.iter().filter(|o| o.effect == "none" && o.error.is_none()).collect();
            let fp = none.iter().filter(|o| o.verdict != "none" && o.verdict != UNCERTAIN).count();
            let unsure = none.iter().filter(|o| o.verdict == UNCERTAIN).count();
            let _ = writeln!(s, "\nFalse positives on none: {}; uncertain: {unsure}.\n", pct(fp, none.len()));
            // Confusion matrix.
            let mut others: Vec<String> = cell
                .iter()
                .map(|o| column(o))
                .filter(|c| !EFFECTS.contains(&c.as_str()) && c != UNCERTAIN && c != ERROR)
                .collect();
            others.sort();
            others.dedup();
            let cols: Vec<&str> =
                EFFECTS.iter().copied().chain(others.iter().map(String::as_str)).chain([UNCERTAIN, ERROR]).collect();
            let _ = writeln!(s, "| hidden \\ verdict | {} |", cols.join(" | "));
            let _ = writeln!(s, "|---|{}", "---|".repeat(cols.len()));
            for e in EFFECTS {
                let rows: Vec<&&Outcome> = cell.iter().filter(|o| o.effect == e).collect();
                if rows.is_empty() {
                    continue;
                }
                let mut counts = BTreeMap::<String, usize>::new();
                for o in &rows {
                    *counts.entry(column(o)).or_default() += 1;
                }
                let line: Vec<String> = cols.iter().map(|c| counts.get(*c).copied().unwrap_or(0).to_string()).collect();
                let _ = writeln!(s, "| {e} | {} |", line.join(" | "));
            }
            let _ = writeln!(s);
        }
    }
    let total: f64 = all.iter().map(|o| o.secs).sum();
    let _ = writeln!(
        s,
        "## Time per case, s\n\nAll {} cases: {:.0} min, one after the other. Diagnosis: `diagnose` on the rendered captures, what `forgemon diagnose` spends (goal: under {HAMMER_GOAL_S} s on the hammer, {PRESS_GOAL_S} s on the press); case: the render of its blows at the fine step and the diagnosis.\n\n| kind | cases | diagnosis median | diagnosis max | over the goal | case median | case max |\n|---|---|---|---|---|---|---|",
        all.len(),
        total / 60.0
    );
    for kind in [Kind::Hammer, Kind::Press] {
        let of = |f: fn(&Outcome) -> f64| -> Vec<f64> { all.iter().filter(|o| o.kind == kind).map(f).collect() };
        let (t, d) = (of(|o| o.secs), of(|o| o.diagnose_secs));
        if !t.is_empty() {
            let max = |v: &[f64]| v.iter().copied().filter(|x| !x.is_nan()).fold(f64::NAN, f64::max);
            let goal = if kind == Kind::Hammer { HAMMER_GOAL_S } else { PRESS_GOAL_S };
            let over = d.iter().filter(|x| **x > goal).count();
            let _ = writeln!(
                s,
                "| {} | {} | {:.1} | {:.1} | {over} | {:.1} | {:.1} |",
                kind_name(kind),
                t.len(),
                median(d.iter().copied().filter(|x| !x.is_nan()).collect()),
                max(&d),
                median(t.clone()),
                max(&t)
            );
        }
    }
    s.push_str(&agreements(all));
    let _ = writeln!(
        s,
        "\n## Misses\n\nEach case whose verdict is not its hidden effect (`none` for none), or that failed.\n"
    );
    let _ = writeln!(
        s,
        "| renderer | kind | hidden | seed | verdict | own shrink | strength | effect strength | hidden parameters |\n|---|---|---|---|---|---|---|---|---|"
    );
    for o in all {
        let hit = if o.effect == "none" { o.verdict == "none" } else { names(&o.verdict, o.effect) };
        if !hit || o.error.is_some() {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {:.2} | {:.1} | {:.1} | {} |",
                o.renderer,
                kind_name(o.kind),
                o.effect,
                o.seed,
                o.error.as_deref().map_or(o.verdict.clone(), |e| format!("error: {e}")),
                o.own_shrink,
                o.strength,
                effect_strength(all, o),
                o.hidden.replace('|', "/")
            );
        }
    }
    s
}

#[test]
#[ignore = "full diagnoses over renderers × kinds × effects × seeds: regenerates docs/diagnose-rates.md"]
fn family_verdict_rates() {
    if let Ok(from) = std::env::var("FORGEMON_FAMILY_FROM") {
        return from_file(&from);
    }
    let set = std::env::var("FORGEMON_FAMILY_SET").unwrap_or_else(|_| "report".into());
    let first = drawn::first_seed(&set).unwrap_or_else(|| panic!("FORGEMON_FAMILY_SET={set}: tune, report or a seed"));
    let seeds_env = std::env::var("FORGEMON_FAMILY_SEEDS").ok();
    let seeds: u64 = seeds_env.as_deref().map_or(DEFAULT_SEEDS, |s| s.parse().expect("FORGEMON_FAMILY_SEEDS: a count"));
    let renderer_names = list("FORGEMON_FAMILY_RENDERERS");
    let renderers: Vec<Renderer> = match &renderer_names {
        Some(n) => n.iter().map(|x| Renderer::parse(x).unwrap_or_else(|| panic!("{x}: not a renderer"))).collect(),
        None => RENDERERS.to_vec(),
    };
    let kind_names = list("FORGEMON_FAMILY_KINDS");
    let kinds: Vec<Kind> = match &kind_names {
        Some(n) => n
            .iter()
            .map(|k| match k.as_str() {
                "hammer" => Kind::Hammer,
                "press" => Kind::Press,
                other => panic!("{other}: hammer or press"),
            })
            .collect(),
        None => vec![Kind::Hammer, Kind::Press],
    };
    let effect_names = list("FORGEMON_FAMILY_EFFECTS");
    let effects: Vec<&'static str> = match &effect_names {
        Some(n) => n
            .iter()
            .map(|e| *EFFECTS.iter().find(|x| *x == e).unwrap_or_else(|| panic!("{e}: not in {EFFECTS:?}")))
            .collect(),
        None => EFFECTS.to_vec(),
    };
    let subset = set != "report"
        || seeds != DEFAULT_SEEDS
        || renderer_names.is_some()
        || kind_names.is_some()
        || effect_names.is_some();
    let doc = std::env::var("FORGEMON_FAMILY_DOC")
        .ok()
        .or_else(|| (!subset).then(|| concat!(env!("CARGO_MANIFEST_DIR"), "/docs/diagnose-rates.md").to_string()));
    let mut out = std::env::var("FORGEMON_FAMILY_OUT")
        .ok()
        .map(|p| std::fs::OpenOptions::new().create(true).append(true).open(&p).unwrap_or_else(|e| panic!("{p}: {e}")));
    let mut all = Vec::new();
    for r in &renderers {
        for &kind in &kinds {
            for &effect in &effects {
                for k in 0..seeds {
                    let seed = first + k;
                    let (o, d) = run_case(*r, kind, effect, seed);
                    println!(
                        "CASE {} {} {effect} seed {seed}: verdict {}, strength {:.1}, own shrink {:.2}, {:.1} s{}",
                        o.renderer,
                        kind_name(kind),
                        o.verdict,
                        o.strength,
                        o.own_shrink,
                        o.secs,
                        o.error.as_deref().map_or(String::new(), |e| format!(" ERROR {e}"))
                    );
                    if let Some(f) = out.as_mut() {
                        let line = serde_json::json!({
                            "renderer": o.renderer, "kind": kind_name(kind), "effect": effect, "seed": seed, "set": set,
                            "hidden": o.hidden, "verdict": o.verdict, "error": o.error,
                            "strength": o.strength, "own_shrink": o.own_shrink, "secs": o.secs, "diagnose_secs": o.diagnose_secs,
                            "report": d.as_ref().map(|d| d.to_json()),
                        });
                        writeln!(f, "{line}").unwrap_or_else(|e| panic!("FORGEMON_FAMILY_OUT: {e}"));
                    }
                    all.push(o);
                }
            }
        }
    }
    let text = document(&all, &set, seeds, &renderers.iter().map(|r| r.name()).collect::<Vec<_>>());
    println!("{text}");
    if let Some(path) = doc {
        std::fs::write(&path, &text).unwrap_or_else(|e| panic!("{path}: {e}"));
        println!("written to {path}");
    }
}

/// An outcome back from its JSON line.
fn outcome_from_json(v: &serde_json::Value) -> Outcome {
    let num = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    let text = |k: &str| v[k].as_str().unwrap_or_default().to_string();
    let effect =
        *EFFECTS.iter().find(|e| **e == v["effect"].as_str().unwrap_or_default()).expect("an effect of EFFECTS");
    Outcome {
        renderer: text("renderer"),
        kind: if v["kind"] == "press" { Kind::Press } else { Kind::Hammer },
        effect,
        seed: v["seed"].as_u64().unwrap_or_default(),
        verdict: text("verdict"),
        error: v["error"].as_str().map(str::to_string),
        strength: num("strength"),
        own_shrink: num("own_shrink"),
        agreement: v["report"]["verdict"]["confidence"]["agreement"].as_f64().unwrap_or(f64::NAN),
        secs: num("secs"),
        diagnose_secs: num("diagnose_secs"),
        hidden: text("hidden"),
    }
}

/// The document rebuilt from the JSON lines of a run (`FORGEMON_FAMILY_OUT`), written where
/// `FORGEMON_FAMILY_DOC` says or to `docs/diagnose-rates.md`.
fn from_file(path: &str) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let lines: Vec<serde_json::Value> =
        text.lines().filter(|l| !l.trim().is_empty()).map(|l| serde_json::from_str(l).expect("a JSON line")).collect();
    let all: Vec<Outcome> = lines.iter().map(outcome_from_json).collect();
    let set = lines.first().and_then(|v| v["set"].as_str()).unwrap_or("report").to_string();
    let mut renderers: Vec<String> = Vec::new();
    let mut per_cell = BTreeMap::<(String, &str, &str), u64>::new();
    for o in &all {
        if !renderers.contains(&o.renderer) {
            renderers.push(o.renderer.clone());
        }
        *per_cell.entry((o.renderer.clone(), kind_name(o.kind), o.effect)).or_default() += 1;
    }
    let seeds = per_cell.values().copied().max().unwrap_or(0);
    let doc = document(&all, &set, seeds, &renderers);
    println!("{doc}");
    let out = std::env::var("FORGEMON_FAMILY_DOC")
        .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/docs/diagnose-rates.md").to_string());
    std::fs::write(&out, doc).unwrap_or_else(|e| panic!("{out}: {e}"));
    println!("written to {out}");
}
