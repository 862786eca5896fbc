//! The recipe file (docs/interfaces.md §9, `PART.recipe.toml`): read and validated like every other
//! file (errors name the file, line and key), and written by `forgemon teach` in the same
//! form, readable and editable by hand.

use serde::{Deserialize, Serialize};

use super::document::Document;
use super::limits::{
    EFFICIENCY, ENERGY_J, ENVELOPE_POINTS, LOAD_N, Limits, PEAK_LOAD_N, RECIPE_BYTES, RECIPE_NAME_CHARS, TRAVEL_M,
};
use super::{ConfigError, Place};
use crate::recipe::{BlowWindows, Recipe, Tolerances, Window};

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRecipe {
    name: String,
    machine: String,
    billets: u32,
    taught_from: Vec<String>,
    tolerances: RawTolerances,
    blows: Vec<RawBlow>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTolerances {
    k: f64,
    efficiency: f64,
    plastic_fraction: f64,
    peak_load_fraction: f64,
    load_fraction: f64,
    compression_m: f64,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBlow {
    blow: u32,
    efficiency: [f64; 2],
    #[serde(rename = "plastic_J")]
    plastic_j: [f64; 2],
    #[serde(rename = "peak_load_N")]
    peak_load_n: [f64; 2],
    travel_m: [f64; 2],
    compression_m: Vec<f64>,
    #[serde(rename = "load_lower_N")]
    load_lower_n: Vec<f64>,
    #[serde(rename = "load_upper_N")]
    load_upper_n: Vec<f64>,
}

/// The header `write_recipe` puts above the tables.
const HEADER: &str = "# forgemon recipe (docs/interfaces.md §9), taught by `forgemon teach`. Per blow: windows [min, max]\n\
# on efficiency, plastic energy, peak load and travel, and the load's envelope against the\n\
# compression (the ram's travel since first contact). Each is the good billets' mean\n\
# ± max(k·sd, tolerance); edit by hand if you like, the service checks the file on load.\n";

/// The recipe as TOML text.
pub fn write_recipe(r: &Recipe) -> Result<String, toml::ser::Error> {
    let t = r.tolerances;
    let raw = RawRecipe {
        name: r.name.clone(),
        machine: r.machine.clone(),
        billets: r.billets,
        taught_from: r.taught_from.clone(),
        tolerances: RawTolerances {
            k: t.k,
            efficiency: t.efficiency,
            plastic_fraction: t.plastic_fraction,
            peak_load_fraction: t.peak_load_fraction,
            load_fraction: t.load_fraction,
            compression_m: t.compression_m,
        },
        blows: r
            .blows
            .iter()
            .map(|b| RawBlow {
                blow: b.blow,
                efficiency: [b.efficiency.min, b.efficiency.max],
                plastic_j: [b.plastic_j.min, b.plastic_j.max],
                peak_load_n: [b.peak_load_n.min, b.peak_load_n.max],
                travel_m: [b.travel_m.min, b.travel_m.max],
                compression_m: b.compression_m.clone(),
                load_lower_n: b.load_lower_n.clone(),
                load_upper_n: b.load_upper_n.clone(),
            })
            .collect(),
    };
    Ok(format!("{HEADER}{}", toml::to_string(&raw)?))
}

/// Parse the recipe file `origin` and check it as `forgemon teach` writes it: the one check
/// of every recipe, from a file at the start, `replay --recipe`, a recording or `POST
/// /recipe`. The text is at most `RECIPE_BYTES` long; the name short printable text
/// (`check_name`); every window bound and envelope point finite and inside its physical
/// range (`limits.rs`: efficiency 0..1, energies and peak loads from 0, travel and
/// compression 0..2 m, loads within ±1e11 N); an envelope has `ENVELOPE_POINTS` points.
pub fn parse_recipe(origin: &str, text: &str) -> Result<Recipe, ConfigError> {
    if text.len() as u64 > RECIPE_BYTES.max {
        return Err(ConfigError::TooLarge {
            place: Place::file(origin),
            bytes: text.len() as u64,
            max: RECIPE_BYTES.max,
        });
    }
    let doc = Document::parse(origin, text)?;
    let raw: RawRecipe = doc.read()?;
    check_name(&raw.name).map_err(|why| doc.invalid("name", why))?;
    if !matches!(raw.machine.as_str(), "hammer" | "screw_press") {
        return Err(doc.invalid("machine", format!("{} is not \"hammer\" or \"screw_press\"", shown(&raw.machine))));
    }
    if let Some(i) =
        raw.taught_from.iter().position(|t| t.chars().count() > TAUGHT_FROM_CHARS || t.chars().any(char::is_control))
    {
        return Err(doc.invalid(
            &format!("taught_from[{}]", i + 1),
            format!("must be a path of at most {TAUGHT_FROM_CHARS} characters without control characters"),
        ));
    }
    let t = &raw.tolerances;
    for (key, x) in [
        ("k", t.k),
        ("efficiency", t.efficiency),
        ("plastic_fraction", t.plastic_fraction),
        ("peak_load_fraction", t.peak_load_fraction),
        ("load_fraction", t.load_fraction),
        ("compression_m", t.compression_m),
    ] {
        if !(x.is_finite() && x >= 0.0) {
            return Err(doc.invalid(&format!("tolerances.{key}"), format!("must be a finite number >= 0, got {x}")));
        }
    }
    if raw.blows.is_empty() {
        return Err(doc.invalid("blows", "must hold at least one [[blows]] table"));
    }
    let blows = raw.blows.iter().enumerate().map(|(i, b)| blow_windows(&doc, i, b)).collect::<Result<_, _>>()?;
    Ok(Recipe {
        name: raw.name,
        machine: raw.machine,
        tolerances: Tolerances {
            k: t.k,
            efficiency: t.efficiency,
            plastic_fraction: t.plastic_fraction,
            peak_load_fraction: t.peak_load_fraction,
            load_fraction: t.load_fraction,
            compression_m: t.compression_m,
        },
        billets: raw.billets,
        taught_from: raw.taught_from,
        blows,
    })
}

/// The longest `taught_from` entry, characters: Linux's `PATH_MAX`.
const TAUGHT_FROM_CHARS: usize = 4096;

/// Whether `name` may name a recipe: 1 to `RECIPE_NAME_CHARS` characters of printable text,
/// no control character (a newline, an ANSI escape) and no bidirectional override, which
/// would rewrite the `/status`, log and dashboard lines it is shown in.
pub fn check_name(name: &str) -> Result<(), String> {
    let n = name.chars().count() as u64;
    let bidi = |c: char| matches!(c, '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}');
    if name.trim().is_empty() {
        Err("must not be empty".into())
    } else if n > RECIPE_NAME_CHARS.max {
        Err(format!("must be at most {} characters, got {n}", RECIPE_NAME_CHARS.max))
    } else if let Some(c) = name.chars().find(|&c| c.is_control() || bidi(c)) {
        Err(format!("must be printable text, but holds the control character {}", c.escape_unicode()))
    } else {
        Ok(())
    }
}

/// `s` as an error message may quote it: escaped, and cut after 64 characters.
fn shown(s: &str) -> String {
    let cut: String = s.chars().take(64).collect();
    let more = if cut.len() < s.len() { "..." } else { "" };
    format!("\"{}{more}\"", cut.escape_debug())
}

/// The `i`-th (from 0) `[[blows]]` table, checked.
fn blow_windows(doc: &Document<'_>, i: usize, b: &RawBlow) -> Result<BlowWindows, ConfigError> {
    let at = |key: &str| format!("blows[{}].{key}", i + 1);
    if b.blow != i as u32 + 1 {
        return Err(
            doc.invalid(&at("blow"), format!("is {} but the tables must number the blows 1, 2, ... in order", b.blow))
        );
    }
    let window = |key: &str, w: [f64; 2], limits: &Limits| {
        if w.iter().all(|&x| limits.check(x).is_ok()) && w[0] <= w[1] {
            Ok(Window { min: w[0], max: w[1] })
        } else {
            Err(doc.invalid(
                &at(key),
                format!(
                    "must be [min, max] with min <= max, each finite and within {} (its physical range), got [{}, {}]",
                    limits.range(),
                    w[0],
                    w[1]
                ),
            ))
        }
    };
    let n = b.compression_m.len();
    if b.load_lower_n.len() != n || b.load_upper_n.len() != n || ENVELOPE_POINTS.check(n as u64).is_err() {
        return Err(doc.invalid(
            &at("compression_m"),
            format!(
                "the envelope needs {}..={} points and as many bounds: {n} points, {} lower, {} upper",
                ENVELOPE_POINTS.min,
                ENVELOPE_POINTS.max,
                b.load_lower_n.len(),
                b.load_upper_n.len()
            ),
        ));
    }
    if !b.compression_m.iter().all(|&x| TRAVEL_M.check(x).is_ok()) || !b.compression_m.windows(2).all(|w| w[0] < w[1]) {
        let why =
            format!("must be strictly increasing, each finite and within {} (its physical range)", TRAVEL_M.range());
        return Err(doc.invalid(&at("compression_m"), why));
    }
    for (key, bounds) in [("load_lower_N", &b.load_lower_n), ("load_upper_N", &b.load_upper_n)] {
        if let Some(j) = bounds.iter().position(|&x| LOAD_N.check(x).is_err()) {
            let why = format!(
                "point {} is {}, not finite and within {} (its physical range)",
                j + 1,
                bounds[j],
                LOAD_N.range()
            );
            return Err(doc.invalid(&at(key), why));
        }
    }
    if let Some(j) = (0..n).find(|&j| b.load_lower_n[j] > b.load_upper_n[j]) {
        return Err(doc.invalid(&at("load_lower_N"), format!("point {} is above its upper bound", j + 1)));
    }
    Ok(BlowWindows {
        blow: b.blow,
        efficiency: window("efficiency", b.efficiency, &EFFICIENCY)?,
        plastic_j: window("plastic_J", b.plastic_j, &ENERGY_J)?,
        peak_load_n: window("peak_load_N", b.peak_load_n, &PEAK_LOAD_N)?,
        travel_m: window("travel_m", b.travel_m, &TRAVEL_M)?,
        compression_m: b.compression_m.clone(),
        load_lower_n: b.load_lower_n.clone(),
        load_upper_n: b.load_upper_n.clone(),
    })
}

/// `r`'s windows and envelope bounds brought inside their physical ranges, as `teach`
/// writes them: a window learnt as mean ± max(k·sd, tolerance) may reach past a bound (an
/// efficiency window up to 1.02, a plastic energy from below 0) where no plausible blow can
/// be (`estimate::plausibility` reports every value inside its range). Cut there, it judges
/// every plausible blow as before.
pub fn within_limits(r: &mut Recipe) {
    let clamp = |w: &mut Window, l: &Limits| {
        w.min = w.min.clamp(l.min, l.max);
        w.max = w.max.clamp(l.min, l.max);
    };
    for b in &mut r.blows {
        clamp(&mut b.efficiency, &EFFICIENCY);
        clamp(&mut b.plastic_j, &ENERGY_J);
        clamp(&mut b.peak_load_n, &PEAK_LOAD_N);
        clamp(&mut b.travel_m, &TRAVEL_M);
        for x in b.load_lower_n.iter_mut().chain(b.load_upper_n.iter_mut()) {
            *x = x.clamp(LOAD_N.min, LOAD_N.max);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recipe() -> Recipe {
        Recipe {
            name: "flange".into(),
            machine: "hammer".into(),
            tolerances: Tolerances::default(),
            billets: 3,
            taught_from: vec!["a.mcap".into()],
            blows: vec![BlowWindows {
                blow: 1,
                efficiency: Window { min: 0.9, max: 0.95 },
                plastic_j: Window { min: 6000.0, max: 7000.0 },
                peak_load_n: Window { min: 1e6, max: 1.2e6 },
                travel_m: Window { min: 0.018, max: 0.020 },
                compression_m: vec![0.0, 1e-3, 2e-3],
                load_lower_n: vec![-1e4, 2e5, 4e5],
                load_upper_n: vec![1e4, 3e5, 6e5],
            }],
        }
    }

    #[test]
    fn a_written_recipe_reads_back_the_same() {
        let text = write_recipe(&recipe()).unwrap();
        assert_eq!(parse_recipe("r.toml", &text).unwrap(), recipe());
    }

    #[test]
    fn errors_name_the_file_line_and_key() {
        let text = write_recipe(&recipe()).unwrap();
        let e = |t: &str| parse_recipe("part.recipe.toml", t).unwrap_err().to_string();
        let bad = e(&text.replace("efficiency = [0.9, 0.95]", "efficiency = [0.95, 0.9]"));
        // file:line:column, then the key.
        let at = bad.split(' ').next().unwrap_or("");
        assert!(at.starts_with("part.recipe.toml:") && at.matches(':').count() == 3, "{bad}");
        assert!(bad.contains("key 'blows[1].efficiency'"), "{bad}");
        let bad = e(&text.replace("blow = 1", "blow = 2"));
        assert!(bad.contains("blows[1].blow"), "{bad}");
        let bad = e(&text.replace("load_fraction", "load_fractoin"));
        assert!(bad.contains("load_fractoin") && bad.contains("did you mean"), "{bad}");
        let bad = e(&text.replace("machine = \"hammer\"", "machine = \"anvil\""));
        assert!(bad.contains("key 'machine'"), "{bad}");
        // A quoted value comes back escaped and cut.
        let bad = e(&text.replace("machine = \"hammer\"", &format!("machine = \"\\u001b[2J{}\"", "x".repeat(500))));
        assert!(!bad.contains('\u{1b}') && bad.contains("\\u{1b}[2J") && bad.len() < 300, "{bad}");
    }

    #[test]
    fn windows_outside_their_physical_range_are_refused_with_the_range() {
        let text = write_recipe(&recipe()).unwrap();
        let e = |from: &str, to: &str| parse_recipe("r.toml", &text.replace(from, to)).unwrap_err().to_string();
        let bad = e("efficiency = [0.9, 0.95]", "efficiency = [-1e308, 1e308]");
        assert!(bad.contains("key 'blows[1].efficiency'") && bad.contains("within 0..1"), "{bad}");
        let bad = e("efficiency = [0.9, 0.95]", "efficiency = [0.9, 1.01]");
        assert!(bad.contains("blows[1].efficiency"), "{bad}");
        let bad = e("plastic_J = [6000.0,", "plastic_J = [-1.0,");
        assert!(bad.contains("blows[1].plastic_J") && bad.contains("0..4.5e9 J"), "{bad}");
        let bad = e("peak_load_N = [1000000.0,", "peak_load_N = [nan,");
        assert!(bad.contains("blows[1].peak_load_N") && bad.contains("0..1e11 N"), "{bad}");
        let bad = e("load_upper_N = [10000.0,", "load_upper_N = [inf,");
        assert!(
            bad.contains("blows[1].load_upper_N") && bad.contains("point 1") && bad.contains("-1e11..1e11 N"),
            "{bad}"
        );
        let bad = e("compression_m = [0.0,", "compression_m = [-0.001,");
        assert!(bad.contains("blows[1].compression_m") && bad.contains("0..2 m"), "{bad}");
        let bad = e("travel_m = [0.018, 0.02]", "travel_m = [0.018, 3.0]");
        assert!(bad.contains("blows[1].travel_m"), "{bad}");
    }

    #[test]
    fn names_are_short_printable_text() {
        assert!(check_name("flange 2 (Ø60)").is_ok());
        assert!(check_name(&"n".repeat(64)).is_ok());
        assert!(check_name(&"n".repeat(65)).unwrap_err().contains("at most 64"));
        for bad in ["a\nb", "a\u{1b}[31mred", "tab\there", "\u{202e}txt.exe", "del\u{7f}", " "] {
            assert!(check_name(bad).is_err(), "{bad:?}");
        }
        let text = write_recipe(&recipe()).unwrap().replace("name = \"flange\"", "name = \"a\\nb\"");
        let bad = parse_recipe("r.toml", &text).unwrap_err().to_string();
        assert!(bad.contains("key 'name'") && bad.contains("\\u{a}") && !bad.contains("a\nb"), "{bad}");
    }

    #[test]
    fn envelopes_and_files_have_a_bounded_size() {
        let mut r = recipe();
        let n = ENVELOPE_POINTS.max as usize + 1;
        r.blows[0].compression_m = (0..n).map(|j| j as f64 * 1e-5).collect();
        r.blows[0].load_lower_n = vec![0.0; n];
        r.blows[0].load_upper_n = vec![1.0; n];
        let bad = parse_recipe("r.toml", &write_recipe(&r).unwrap()).unwrap_err().to_string();
        assert!(bad.contains("blows[1].compression_m") && bad.contains("2..=200 points"), "{bad}");
        let big = format!("{}\n#{}", write_recipe(&recipe()).unwrap(), "x".repeat(RECIPE_BYTES.max as usize));
        let bad = parse_recipe("r.toml", &big).unwrap_err();
        assert!(matches!(bad, ConfigError::TooLarge { max: 1_048_576, .. }), "{bad}");
        assert!(bad.to_string().starts_with("r.toml: "), "{bad}");
    }

    #[test]
    fn a_window_learnt_past_its_range_is_cut_there_and_then_passes() {
        let mut r = recipe();
        r.blows[0].efficiency = Window { min: 0.97, max: 1.03 };
        r.blows[0].plastic_j = Window { min: -50.0, max: 70.0 };
        within_limits(&mut r);
        assert_eq!(r.blows[0].efficiency, Window { min: 0.97, max: 1.0 });
        assert_eq!(r.blows[0].plastic_j, Window { min: 0.0, max: 70.0 });
        assert_eq!(parse_recipe("r.toml", &write_recipe(&r).unwrap()).unwrap(), r);
    }
}
