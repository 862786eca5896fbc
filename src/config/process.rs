//! `process.toml` (CONTRACTS.md §2): the billet, its material and interface, and the
//! measured heights after each blow.

use super::{ConfigError, Keys, machine_kind, parse_table};
use crate::physics::billet::{BilletGeometry, FlowStress};
use crate::physics::process::Process;

/// Parse and validate the text of a `process.toml` named `origin`.
pub fn parse_process(origin: &str, text: &str) -> Result<Process, ConfigError> {
    let table = parse_table(origin, text)?;
    let keys = Keys::root(origin, &table);
    let machine = machine_kind(&keys, "machine")?;
    let b = keys.table("billet")?;
    let billet = BilletGeometry { diameter_m: b.positive("diameter_m")?, height_m: b.positive("height_m")? };
    let m = keys.table("material")?;
    let material = match m.string("model")? {
        "constant" => FlowStress::Constant { sigma0_pa: m.positive("sigma0_Pa")? },
        "hansel_spittel" => FlowStress::HanselSpittel {
            a_pa: m.positive("A_Pa")?,
            m1: m.finite("m1")?,
            m2: m.finite("m2")?,
            m3: m.finite("m3")?,
            m4: m.finite("m4")?,
            temperature_c: m.finite("temperature_C")?,
        },
        other => {
            return Err(m.invalid("model", format!("must be \"constant\" or \"hansel_spittel\", got \"{other}\"")));
        }
    };
    let friction = keys.table("interface")?.non_negative("friction")?;
    let mut measured = Vec::new();
    match table.get("blows") {
        None => {}
        Some(toml::Value::Array(blows)) => {
            for (i, blow) in blows.iter().enumerate() {
                let key = format!("blows[{}]", i + 1);
                let toml::Value::Table(t) = blow else {
                    return Err(keys.invalid(&key, "must be a table"));
                };
                let bk = Keys { origin, prefix: key, table: t };
                let h = bk.positive("final_height_m")?;
                let previous = measured.last().copied().unwrap_or(billet.height_m);
                if h > previous {
                    return Err(bk.invalid(
                        "final_height_m",
                        format!("{h} m is above the height before that blow ({previous} m)"),
                    ));
                }
                measured.push(h);
            }
        }
        Some(_) => return Err(keys.invalid("blows", "must be an array of tables ([[blows]])")),
    }
    Ok(Process { machine, billet, material, friction, measured_final_heights_m: measured })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::machine::MachineKind;

    const STEEL: &str = "machine = \"hammer\"\n[billet]\ndiameter_m = 0.060\nheight_m = 0.112\n\
                         [material]\nmodel = \"constant\"\nsigma0_Pa = 90e6\n[interface]\nfriction = 0.2\n";

    #[test]
    fn contract_example_parses() {
        let text = format!("{STEEL}[[blows]]\nfinal_height_m = 0.0889\n");
        let p = parse_process("p.toml", &text).unwrap();
        assert_eq!(p.machine, MachineKind::Hammer);
        assert_eq!(p.billet, BilletGeometry { diameter_m: 0.060, height_m: 0.112 });
        assert_eq!(p.material, FlowStress::Constant { sigma0_pa: 90e6 });
        assert_eq!(p.friction, 0.2);
        assert_eq!(p.measured_final_heights_m, vec![0.0889]);
    }

    #[test]
    fn errors_name_file_and_key() {
        let e = parse_process("p.toml", &STEEL.replace("height_m = 0.112\n", "")).unwrap_err();
        assert_eq!(e.to_string(), "p.toml: missing key 'billet.height_m'");
        let e = parse_process("p.toml", &STEEL.replace("\"constant\"", "\"johnson_cook\"")).unwrap_err();
        assert!(e.to_string().contains("key 'material.model'"), "{e}");
        let e = parse_process("p.toml", &STEEL.replace("sigma0_Pa", "sigma_Pa")).unwrap_err();
        assert_eq!(e.to_string(), "p.toml: missing key 'material.sigma0_Pa'");
        let e = parse_process("p.toml", &format!("{STEEL}[[blows]]\nfinal_height_m = 0.2\n")).unwrap_err();
        assert!(e.to_string().contains("key 'blows[1].final_height_m'"), "{e}");
        let e = parse_process("p.toml", &STEEL.replace("friction = 0.2", "friction = -0.2")).unwrap_err();
        assert!(e.to_string().contains("key 'interface.friction' must be finite and >= 0"), "{e}");
    }
}
