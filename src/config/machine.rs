//! `machine.toml` (CONTRACTS.md §3): the identified machine model, plus optional effect
//! parameters under `[effects.NAME]`. Other extra keys (uncertainties, provenance, fit
//! quality) are allowed and ignored here.

use std::collections::BTreeMap;

use super::{ConfigError, Keys, machine_kind, parse_table};
use crate::physics::effects::Effect;
use crate::physics::machine::{DEFAULT_HAMMER_TOOL_CONTACT_N_PER_M, Hammer, Machine, MachineKind, ScrewPress};

/// A machine file: the model and the effects it switches on by default.
#[derive(Debug, Clone, PartialEq)]
pub struct MachineFile {
    pub machine: Machine,
    pub effects: Vec<Effect>,
}

/// Parse and validate the text of a `machine.toml` named `origin`.
pub fn parse_machine(origin: &str, text: &str) -> Result<MachineFile, ConfigError> {
    let table = parse_table(origin, text)?;
    let keys = Keys::root(origin, &table);
    let machine = match machine_kind(&keys, "kind")? {
        MachineKind::Hammer => Machine::Hammer(Hammer {
            m1_kg: keys.positive("m1_kg")?,
            m2_kg: keys.positive("m2_kg")?,
            k_n_per_m: keys.positive("k_N_per_m")?,
            c_ns_per_m: keys.non_negative("c_Ns_per_m")?,
            k_tool_contact_n_per_m: match keys.opt_number("k_tool_contact_N_per_m")? {
                Some(_) => keys.positive("k_tool_contact_N_per_m")?,
                None => DEFAULT_HAMMER_TOOL_CONTACT_N_PER_M,
            },
        }),
        MachineKind::ScrewPress => Machine::ScrewPress(ScrewPress {
            m_tool_kg: keys.positive("m_tool_kg")?,
            m_ram_kg: keys.positive("m_ram_kg")?,
            k_link_n_per_m: keys.positive("k_link_N_per_m")?,
            c_link_ns_per_m: keys.non_negative("c_link_Ns_per_m")?,
            k_frame_n_per_m: keys.positive("k_frame_N_per_m")?,
            c_frame_ns_per_m: keys.non_negative("c_frame_Ns_per_m")?,
            k_sensor_n_per_m: keys.positive("k_sensor_N_per_m")?,
            k_tool_contact_n_per_m: match keys.opt_number("k_tool_contact_N_per_m")? {
                Some(_) => keys.positive("k_tool_contact_N_per_m")?,
                None => f64::INFINITY,
            },
        }),
    };
    let mut effects = Vec::new();
    if table.contains_key("effects") {
        let ek = keys.table("effects")?;
        for name in ek.table.keys() {
            let sub = ek.table(name)?;
            let mut params = BTreeMap::new();
            for k in sub.table.keys() {
                params.insert(k.clone(), sub.number(k)?);
            }
            let e = Effect::from_params(name, &params)
                .and_then(|e| e.check_machine(machine.kind()).map(|()| e))
                .map_err(|err| ek.invalid(name, err.to_string()))?;
            effects.push(e);
        }
    }
    Ok(MachineFile { machine, effects })
}

#[cfg(test)]
mod tests {
    use super::*;

    const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 732\nm2_kg = 19\nk_N_per_m = 3.15e9\nc_Ns_per_m = 18540\n";

    #[test]
    fn contract_hammer_example_parses() {
        let m = parse_machine("m.toml", HAMMER).unwrap();
        let Machine::Hammer(h) = m.machine else { panic!("not a hammer") };
        assert_eq!((h.m1_kg, h.m2_kg, h.k_n_per_m, h.c_ns_per_m), (732.0, 19.0, 3.15e9, 18540.0));
        assert!(m.effects.is_empty());
    }

    #[test]
    fn contract_press_example_parses() {
        let text = "kind = \"screw_press\"\nm_tool_kg = 3110\nm_ram_kg = 106000\nk_link_N_per_m = 1.72e9\n\
                    c_link_Ns_per_m = 3.61e5\nk_frame_N_per_m = 9.74e9\nc_frame_Ns_per_m = 0\nk_sensor_N_per_m = 3.39e10\n";
        let m = parse_machine("p.toml", text).unwrap();
        assert!(
            matches!(m.machine, Machine::ScrewPress(p) if p.m_tool_kg == 3110.0 && p.k_tool_contact_n_per_m.is_infinite())
        );
    }

    #[test]
    fn errors_name_file_and_key() {
        let e = parse_machine("m.toml", "kind = \"hammer\"\nm1_kg = 732\n").unwrap_err();
        assert_eq!(e.to_string(), "m.toml: missing key 'm2_kg'");
        let e = parse_machine("m.toml", &HAMMER.replace("m2_kg = 19", "m2_kg = -19")).unwrap_err();
        assert_eq!(e.to_string(), "m.toml: key 'm2_kg' must be finite and > 0, got -19");
        let e = parse_machine("m.toml", &HAMMER.replace("m2_kg = 19", "m2_kg = \"19\"")).unwrap_err();
        assert_eq!(e.to_string(), "m.toml: key 'm2_kg' must be a number, not string");
        let e = parse_machine("m.toml", "kind = \"anvil\"").unwrap_err();
        assert!(e.to_string().contains("key 'kind' must be \"hammer\" or \"screw_press\""), "{e}");
        let e = parse_machine("m.toml", "kind = \n").unwrap_err();
        assert!(e.to_string().starts_with("m.toml: not valid TOML") && e.to_string().contains("line 1"), "{e}");
    }

    #[test]
    fn effects_tables_are_read_and_checked() {
        let text = format!("{HAMMER}[effects.clearance]\ngap_m = 2e-4\n");
        let m = parse_machine("m.toml", &text).unwrap();
        assert_eq!(m.effects, vec![Effect::Clearance { gap_m: 2e-4, m_lower_kg: 0.0 }]);
        let e = parse_machine("m.toml", &format!("{HAMMER}[effects.clearance]\ngap = 2e-4\n")).unwrap_err();
        assert!(
            e.to_string().contains("key 'effects.clearance'") && e.to_string().contains("no parameter 'gap'"),
            "{e}"
        );
        // The lower die is the press's: a hammer's lower mass is its m2_kg.
        let die = "[effects.clearance]\ngap_m = 2e-4\nm_lower_kg = 800\n";
        let e = parse_machine("m.toml", &format!("{HAMMER}{die}")).unwrap_err();
        assert!(
            e.to_string().contains("key 'effects.clearance'") && e.to_string().contains("m_lower_kg does not apply"),
            "{e}"
        );
        let press = "kind = \"screw_press\"\nm_tool_kg = 3110\nm_ram_kg = 106000\nk_link_N_per_m = 1.72e9\n\
                     c_link_Ns_per_m = 3.61e5\nk_frame_N_per_m = 9.74e9\nc_frame_Ns_per_m = 0\nk_sensor_N_per_m = 3.39e10\n";
        let m = parse_machine("m.toml", &format!("{press}{die}")).unwrap();
        assert_eq!(m.effects, vec![Effect::Clearance { gap_m: 2e-4, m_lower_kg: 800.0 }]);
    }
}
