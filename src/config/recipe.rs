//! The recipe file (CONTRACTS §9, `PART.recipe.toml`): read and validated like every other
//! file (errors name the file, line and key), and written by `forgemon teach` in the same
//! form, readable and editable by hand.

use serde::{Deserialize, Serialize};

use super::ConfigError;
use super::document::Document;
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
const HEADER: &str = "# forgemon recipe (CONTRACTS §9), taught by `forgemon teach`. Per blow: windows [min, max]\n\
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

/// Parse the recipe file `origin`.
pub fn parse_recipe(origin: &str, text: &str) -> Result<Recipe, ConfigError> {
    let doc = Document::parse(origin, text)?;
    let raw: RawRecipe = doc.read()?;
    if raw.name.trim().is_empty() {
        return Err(doc.invalid("name", "must not be empty"));
    }
    if !matches!(raw.machine.as_str(), "hammer" | "screw_press") {
        return Err(doc.invalid("machine", format!("'{}' is not \"hammer\" or \"screw_press\"", raw.machine)));
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
    let mut blows = Vec::with_capacity(raw.blows.len());
    for (i, b) in raw.blows.iter().enumerate() {
        let at = |key: &str| format!("blows[{}].{key}", i + 1);
        if b.blow != i as u32 + 1 {
            return Err(doc.invalid(
                &at("blow"),
                format!("is {} but the tables must number the blows 1, 2, ... in order", b.blow),
            ));
        }
        let window = |key: &str, w: [f64; 2]| {
            if w.iter().all(|x| x.is_finite()) && w[0] <= w[1] {
                Ok(Window { min: w[0], max: w[1] })
            } else {
                Err(doc.invalid(&at(key), format!("must be [min, max] with min <= max, got [{}, {}]", w[0], w[1])))
            }
        };
        let n = b.compression_m.len();
        if n < 2 || b.load_lower_n.len() != n || b.load_upper_n.len() != n {
            return Err(doc.invalid(
                &at("compression_m"),
                format!(
                    "the envelope needs at least 2 points and as many bounds: {n} points, {} lower, {} upper",
                    b.load_lower_n.len(),
                    b.load_upper_n.len()
                ),
            ));
        }
        if !b.compression_m.windows(2).all(|w| w[0] < w[1]) || !b.compression_m.iter().all(|x| x.is_finite()) {
            return Err(doc.invalid(&at("compression_m"), "must be finite and strictly increasing"));
        }
        if let Some(j) = (0..n).find(|&j| !(b.load_lower_n[j].is_finite() && b.load_lower_n[j] <= b.load_upper_n[j])) {
            return Err(
                doc.invalid(&at("load_lower_N"), format!("point {} is above its upper bound or not finite", j + 1))
            );
        }
        blows.push(BlowWindows {
            blow: b.blow,
            efficiency: window("efficiency", b.efficiency)?,
            plastic_j: window("plastic_J", b.plastic_j)?,
            peak_load_n: window("peak_load_N", b.peak_load_n)?,
            travel_m: window("travel_m", b.travel_m)?,
            compression_m: b.compression_m.clone(),
            load_lower_n: b.load_lower_n.clone(),
            load_upper_n: b.load_upper_n.clone(),
        });
    }
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
    }
}
