//! `machine.toml` (docs/interfaces.md §3): the identified machine model, plus optional effect
//! parameters under `[effects.NAME]`.
//!
//! Which keys are read: the kind's parameters, `k_tool_contact_N_per_m`, `[effects.NAME]`,
//! `[daq]` (the load channel's anti-alias filter, `physics::load_filter`, which `diagnose`
//! reads the model through), and the `[identify]` table that `forgemon identify` writes (ignored here). The contract
//! allows other extra keys (uncertainties, provenance), so any other key is accepted and
//! ignored, unless it looks like a typing error: a near miss of a known key ("did you
//! mean"), or a parameter of the other machine kind. A known key with a suffix
//! (`k_N_per_m_std_error`) is an annotation, not a near miss. Effect parameters are checked by
//! `Effect::from_params`, which knows each effect's names.

use std::collections::BTreeMap;

use serde::Deserialize;
use serde::de::IgnoredAny;

use super::ConfigError;
use super::document::{Document, suggest};
use super::limits::{DAMPING_NS_PER_M, MASS_KG, STIFFNESS_N_PER_M};
use crate::physics::effects::{Effect, EffectSet};
use crate::physics::load_filter::LoadFilter;
use crate::physics::machine::{DEFAULT_HAMMER_TOOL_CONTACT_N_PER_M, Hammer, Machine, ScrewPress};

/// A machine file: the model and the effects it switches on by default.
#[derive(Debug, Clone, PartialEq)]
pub struct MachineFile {
    pub machine: Machine,
    pub effects: Vec<Effect>,
    /// The DAQ's anti-alias filter on the load channel (`[daq]`), none when not declared.
    pub load_filter: LoadFilter,
}

impl MachineFile {
    /// The model's effects with the DAQ's filter: what the estimator, the fits and the
    /// simulator take from the file.
    pub fn effect_set(&self) -> EffectSet {
        EffectSet { load_filter: self.load_filter, ..EffectSet::from_effects(&self.effects) }
    }
}

/// `[daq]`: the load channel's anti-alias filter, from the DAQ's data sheet. Cut-off as a
/// fraction of the sample rate; `cascade` identical filters in series.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDaq {
    load_filter: String,
    cutoff: Option<f64>,
    order: Option<u32>,
    cascade: Option<u32>,
}

/// The keys of a hammer's model.
const HAMMER_KEYS: &[&str] = &["m1_kg", "m2_kg", "k_N_per_m", "c_Ns_per_m"];
/// The keys of a screw press's model.
const PRESS_KEYS: &[&str] = &[
    "m_tool_kg",
    "m_ram_kg",
    "k_link_N_per_m",
    "c_link_Ns_per_m",
    "k_frame_N_per_m",
    "c_frame_Ns_per_m",
    "k_sensor_N_per_m",
];
/// The keys both kinds read.
const COMMON_KEYS: &[&str] = &["kind", "k_tool_contact_N_per_m", "effects", "identify", "daq"];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHammer {
    #[allow(dead_code)]
    kind: String,
    m1_kg: f64,
    m2_kg: f64,
    #[serde(rename = "k_N_per_m")]
    k_n_per_m: f64,
    #[serde(rename = "c_Ns_per_m")]
    c_ns_per_m: f64,
    #[serde(rename = "k_tool_contact_N_per_m")]
    k_tool_contact_n_per_m: Option<f64>,
    #[serde(default)]
    effects: BTreeMap<String, BTreeMap<String, f64>>,
    #[allow(dead_code)]
    identify: Option<IgnoredAny>,
    daq: Option<RawDaq>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPress {
    #[allow(dead_code)]
    kind: String,
    m_tool_kg: f64,
    m_ram_kg: f64,
    #[serde(rename = "k_link_N_per_m")]
    k_link_n_per_m: f64,
    #[serde(rename = "c_link_Ns_per_m")]
    c_link_ns_per_m: f64,
    #[serde(rename = "k_frame_N_per_m")]
    k_frame_n_per_m: f64,
    #[serde(rename = "c_frame_Ns_per_m")]
    c_frame_ns_per_m: f64,
    #[serde(rename = "k_sensor_N_per_m")]
    k_sensor_n_per_m: f64,
    #[serde(rename = "k_tool_contact_N_per_m")]
    k_tool_contact_n_per_m: Option<f64>,
    #[serde(default)]
    effects: BTreeMap<String, BTreeMap<String, f64>>,
    #[allow(dead_code)]
    identify: Option<IgnoredAny>,
    daq: Option<RawDaq>,
}

/// Parse and validate the text of a `machine.toml` named `origin`.
pub fn parse_machine(origin: &str, text: &str) -> Result<MachineFile, ConfigError> {
    let doc = Document::parse(origin, text)?;
    let kind = doc.choice("kind", &["hammer", "screw_press"])?;
    let (own, other, other_kind) =
        if kind == "hammer" { (HAMMER_KEYS, PRESS_KEYS, "screw_press") } else { (PRESS_KEYS, HAMMER_KEYS, "hammer") };
    let known: Vec<&str> = own.iter().chain(COMMON_KEYS).copied().collect();
    let mut table = doc.table().clone();
    for key in doc.table().keys() {
        let key = key.get_ref().as_ref();
        if known.contains(&key) {
            continue;
        }
        if other.contains(&key) {
            return Err(doc.invalid(key, format!("is a {other_kind} parameter, but kind = \"{kind}\"")));
        }
        // A known key with a suffix (`k_N_per_m_std_error`) annotates it: an extra.
        let annotates = known.iter().any(|k| key.strip_prefix(k).is_some_and(|rest| rest.starts_with('_')));
        if !annotates && let Some(s) = suggest(key, &known) {
            return Err(ConfigError::UnknownKey {
                place: doc.place(key),
                key: key.to_string(),
                table: String::new(),
                suggestion: Some(s.to_string()),
            });
        }
        // An extra key the contract allows (provenance, uncertainty): not ours to read.
        table.remove(key);
    }
    let (machine, effects, daq) = if kind == "hammer" {
        let raw: RawHammer = doc.read_table(table)?;
        let machine = Machine::Hammer(Hammer {
            m1_kg: doc.in_range("m1_kg", raw.m1_kg, &MASS_KG)?,
            m2_kg: doc.in_range("m2_kg", raw.m2_kg, &MASS_KG)?,
            k_n_per_m: doc.in_range("k_N_per_m", raw.k_n_per_m, &STIFFNESS_N_PER_M)?,
            c_ns_per_m: doc.in_range("c_Ns_per_m", raw.c_ns_per_m, &DAMPING_NS_PER_M)?,
            k_tool_contact_n_per_m: match raw.k_tool_contact_n_per_m {
                Some(k) => doc.in_range("k_tool_contact_N_per_m", k, &STIFFNESS_N_PER_M)?,
                None => DEFAULT_HAMMER_TOOL_CONTACT_N_PER_M,
            },
        });
        (machine, raw.effects, raw.daq)
    } else {
        let raw: RawPress = doc.read_table(table)?;
        let machine = Machine::ScrewPress(ScrewPress {
            m_tool_kg: doc.in_range("m_tool_kg", raw.m_tool_kg, &MASS_KG)?,
            m_ram_kg: doc.in_range("m_ram_kg", raw.m_ram_kg, &MASS_KG)?,
            k_link_n_per_m: doc.in_range("k_link_N_per_m", raw.k_link_n_per_m, &STIFFNESS_N_PER_M)?,
            c_link_ns_per_m: doc.in_range("c_link_Ns_per_m", raw.c_link_ns_per_m, &DAMPING_NS_PER_M)?,
            k_frame_n_per_m: doc.in_range("k_frame_N_per_m", raw.k_frame_n_per_m, &STIFFNESS_N_PER_M)?,
            c_frame_ns_per_m: doc.in_range("c_frame_Ns_per_m", raw.c_frame_ns_per_m, &DAMPING_NS_PER_M)?,
            k_sensor_n_per_m: doc.in_range("k_sensor_N_per_m", raw.k_sensor_n_per_m, &STIFFNESS_N_PER_M)?,
            k_tool_contact_n_per_m: match raw.k_tool_contact_n_per_m {
                Some(k) => doc.in_range("k_tool_contact_N_per_m", k, &STIFFNESS_N_PER_M)?,
                None => f64::INFINITY,
            },
        });
        (machine, raw.effects, raw.daq)
    };
    let mut out = Vec::new();
    for (name, params) in &effects {
        let e = Effect::from_params(name, params)
            .and_then(|e| e.check_machine(machine.kind()).map(|()| e))
            .map_err(|err| doc.invalid(&format!("effects.{name}"), err.to_string()))?;
        out.push(e);
    }
    let load_filter = match daq {
        Some(d) => load_filter(&doc, d)?,
        None => LoadFilter::None,
    };
    Ok(MachineFile { machine, effects: out, load_filter })
}

/// `[daq]`'s filter, each key checked against what a DAQ can have.
fn load_filter(doc: &Document, d: RawDaq) -> Result<LoadFilter, ConfigError> {
    match d.load_filter.as_str() {
        "none" => Ok(LoadFilter::None),
        "butterworth" => {
            let cutoff = d.cutoff.ok_or_else(|| doc.invalid("daq.cutoff", "is needed for a butterworth filter"))?;
            if !(cutoff > 0.0 && cutoff < 0.5) {
                return Err(
                    doc.invalid("daq.cutoff", format!("{cutoff} is not a fraction of the sample rate in (0, 0.5)"))
                );
            }
            let order = d.order.unwrap_or(2);
            if !(1..=8).contains(&order) {
                return Err(doc.invalid("daq.order", format!("{order} is not an order from 1 to 8")));
            }
            let cascade = d.cascade.unwrap_or(1);
            if !(1..=4).contains(&cascade) {
                return Err(doc.invalid("daq.cascade", format!("{cascade} is not 1 to 4 filters in series")));
            }
            Ok(LoadFilter::Butterworth { order, cascade, cutoff })
        }
        other => Err(doc.invalid("daq.load_filter", format!("\"{other}\" is not \"none\" or \"butterworth\""))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 732\nm2_kg = 19\nk_N_per_m = 3.15e9\nc_Ns_per_m = 18540\n";
    const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 3110\nm_ram_kg = 106000\nk_link_N_per_m = 1.72e9\n\
                         c_link_Ns_per_m = 3.61e5\nk_frame_N_per_m = 9.74e9\nc_frame_Ns_per_m = 0\nk_sensor_N_per_m = 3.39e10\n";

    fn err(text: &str) -> String {
        parse_machine("m.toml", text).unwrap_err().to_string()
    }

    #[test]
    fn a_daq_table_declares_the_load_filter_and_a_wrong_key_is_named() {
        let m =
            parse_machine("m.toml", &format!("{HAMMER}[daq]\nload_filter = \"butterworth\"\ncutoff = 0.4\n")).unwrap();
        assert_eq!(m.load_filter, LoadFilter::Butterworth { order: 2, cascade: 1, cutoff: 0.4 });
        assert_eq!(parse_machine("m.toml", HAMMER).unwrap().load_filter, LoadFilter::None);
        // What identify writes on reads back.
        let f = LoadFilter::Butterworth { order: 4, cascade: 2, cutoff: 0.35 };
        assert_eq!(parse_machine("m.toml", &format!("{HAMMER}{}", f.to_toml())).unwrap().load_filter, f);
        for (daq, key) in [
            ("load_filter = \"bessel\"\ncutoff = 0.4", "daq.load_filter"),
            ("load_filter = \"butterworth\"", "daq.cutoff"),
            ("load_filter = \"butterworth\"\ncutoff = 0.6", "daq.cutoff"),
            ("load_filter = \"butterworth\"\ncutoff = 0.4\norder = 0", "daq.order"),
        ] {
            let e = err(&format!("{HAMMER}[daq]\n{daq}\n"));
            assert!(e.contains(key) && e.contains("m.toml"), "{daq}: {e}");
        }
        assert!(err(&format!("{HAMMER}[daq]\nload_filter = \"none\"\ncutof = 0.4\n")).contains("cutof"));
    }

    #[test]
    fn contract_hammer_example_parses() {
        let m = parse_machine("m.toml", HAMMER).unwrap();
        let Machine::Hammer(h) = m.machine else { panic!("not a hammer") };
        assert_eq!((h.m1_kg, h.m2_kg, h.k_n_per_m, h.c_ns_per_m), (732.0, 19.0, 3.15e9, 18540.0));
        assert!(m.effects.is_empty());
    }

    #[test]
    fn contract_press_example_parses() {
        let m = parse_machine("p.toml", PRESS).unwrap();
        assert!(
            matches!(m.machine, Machine::ScrewPress(p) if p.m_tool_kg == 3110.0 && p.k_tool_contact_n_per_m.is_infinite())
        );
    }

    #[test]
    fn the_example_machine_files_parse() {
        for text in [
            include_str!("../../config/hammer-lg1000.machine.toml"),
            include_str!("../../config/screw-press-spr400.machine.toml"),
        ] {
            parse_machine("example", text).unwrap();
        }
    }

    #[test]
    fn errors_name_file_line_and_key() {
        assert_eq!(err("kind = \"hammer\"\nm1_kg = 732\n"), "m.toml: missing key 'm2_kg'");
        assert_eq!(
            err(&HAMMER.replace("m2_kg = 19", "m2_kg = -19")),
            "m.toml:3:1: key 'm2_kg' must be finite and > 0, got -19"
        );
        assert_eq!(
            err(&HAMMER.replace("m2_kg = 19", "m2_kg = \"19\"")),
            "m.toml:3:9: key 'm2_kg' must be a number, not string \"19\""
        );
        let e = err("kind = \"anvil\"");
        assert!(e.starts_with("m.toml:1:1: key 'kind' must be \"hammer\" or \"screw_press\", got \"anvil\""), "{e}");
        let e = err("kind = \n");
        assert!(e.starts_with("m.toml:1:") && e.contains("not valid TOML") && e.contains("line 1"), "{e}");
    }

    #[test]
    fn extreme_values_are_refused_before_any_simulation() {
        let e = err(&HAMMER.replace("m1_kg = 732", "m1_kg = 1e308"));
        assert_eq!(e, "m.toml:2:1: key 'm1_kg' must be within 0.1..1e7 kg (a physically sensible range), got 1e308");
        let e = err(&HAMMER.replace("k_N_per_m = 3.15e9", "k_N_per_m = 1e-300"));
        assert!(e.starts_with("m.toml:4:1: key 'k_N_per_m' must be within 1e5..1e13 N/m"), "{e}");
        let e = err(&PRESS.replace("c_frame_Ns_per_m = 0", "c_frame_Ns_per_m = inf"));
        assert!(e.contains("key 'c_frame_Ns_per_m' must be finite and >= 0, got inf"), "{e}");
        let e = err(&format!("{HAMMER}k_tool_contact_N_per_m = 1e20\n"));
        assert!(e.contains("key 'k_tool_contact_N_per_m' must be within"), "{e}");
    }

    #[test]
    fn a_misspelt_key_is_refused_and_other_extra_keys_are_kept_out_of_the_way() {
        let e = err(&HAMMER.replace("c_Ns_per_m", "c_Ns_per_n"));
        assert_eq!(e, "m.toml:5:1: unknown key 'c_Ns_per_n' at the top level; did you mean 'c_Ns_per_m'?");
        let e = err(&format!("{HAMMER}m1_kgs = 700\n"));
        assert!(e.contains("unknown key 'm1_kgs'") && e.contains("did you mean 'm1_kg'?"), "{e}");
        let e = err(&format!("{HAMMER}[efects.clearance]\ngap_m = 2e-4\n"));
        assert!(e.contains("unknown key 'efects'") && e.contains("did you mean 'effects'?"), "{e}");
        // A press parameter in a hammer file is a mistake, not an extra.
        let e = err(&format!("{HAMMER}m_ram_kg = 1000\n"));
        assert_eq!(e, "m.toml:6:1: key 'm_ram_kg' is a screw_press parameter, but kind = \"hammer\"");
        // Provenance and uncertainties are allowed (docs/interfaces.md §3).
        let extra = "operator = \"jd\"\nm1_kg_std_error = 12.5\nk_N_per_m_se = 1e7\n[provenance]\nfrom = \"bench\"\n";
        assert_eq!(
            parse_machine("m.toml", &format!("{HAMMER}{extra}")).unwrap().machine,
            parse_machine("m.toml", HAMMER).unwrap().machine
        );
    }

    #[test]
    fn what_identify_writes_reads_back() {
        let text = "# Identified by `forgemon identify` from caps.\nkind = \"hammer\"\nm1_kg = 9.1e2  # ± 0.1 %\n\
                    m2_kg = 2.6e1\nk_N_per_m = 2.6e9\nc_Ns_per_m = 2.4e4\nk_tool_contact_N_per_m = 6e10\n\n[identify]\n\
                    source = \"caps\"\nobjective_eq4 = 0.01\nstarts = 8\n\n[identify.std_error]\nm1_kg = 1.0e0\n\n\
                    [identify.determined]\nm1_kg = true\n\n[identify.correlation]\n\"m1_kg:m2_kg\" = 0.71\n";
        let m = parse_machine("m.toml", text).unwrap();
        assert!(matches!(m.machine, Machine::Hammer(h) if h.m1_kg == 910.0 && h.k_tool_contact_n_per_m == 6e10));
    }

    #[test]
    fn effects_tables_are_read_and_checked() {
        let text = format!("{HAMMER}[effects.clearance]\ngap_m = 2e-4\n");
        let m = parse_machine("m.toml", &text).unwrap();
        assert_eq!(m.effects, vec![Effect::Clearance { gap_m: 2e-4, m_lower_kg: 0.0, k_die_n_per_m: f64::INFINITY }]);
        let e = err(&format!("{HAMMER}[effects.clearance]\ngap = 2e-4\n"));
        assert!(
            e.starts_with("m.toml:6:") && e.contains("key 'effects.clearance'") && e.contains("no parameter 'gap'"),
            "{e}"
        );
        let e = err(&format!("{HAMMER}[effects.clearance]\ngap_m = \"wide\"\n"));
        assert!(e.contains("key 'effects.clearance.gap_m' must be a number"), "{e}");
        // The lower die is the press's: a hammer's lower mass is its m2_kg.
        let die = "[effects.clearance]\ngap_m = 2e-4\nm_lower_kg = 800\n";
        let e = err(&format!("{HAMMER}{die}"));
        assert!(e.contains("key 'effects.clearance'") && e.contains("m_lower_kg does not apply"), "{e}");
        let m = parse_machine("m.toml", &format!("{PRESS}{die}")).unwrap();
        assert_eq!(m.effects, vec![Effect::Clearance { gap_m: 2e-4, m_lower_kg: 800.0, k_die_n_per_m: f64::INFINITY }]);
    }
}
