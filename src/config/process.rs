//! `process.toml` (docs/interfaces.md §2): the billet, its material and interface, and the
//! measured heights after each blow. Every table denies unknown keys.
//!
//! Measured heights are hand-measured and noisy: a height that rises from one blow to the
//! next, or after blow 1 stands above the billet's, by no more than `[caliper] tolerance_m`
//! is kept as measured, with a warning naming the blows ([`parse_process_sheet`]); a larger
//! rise is no caliper's scatter, and the sheet is refused at that key (issue 36).

use serde::Deserialize;
use serde::de::IgnoredAny;

use super::document::Document;
use super::limits::{
    BILLET_DIMENSION_M, CALIPER_TOLERANCE_M, FLOW_STRESS_PA, FRICTION, HANSEL_SPITTEL_A_PA, HANSEL_SPITTEL_EXPONENT,
    HANSEL_SPITTEL_M1_PER_C, MEASURED_HEIGHT_M, TEMPERATURE_C,
};
use super::{ConfigError, Parsed};
use crate::physics::billet::{BilletGeometry, FlowStress};
use crate::physics::machine::MachineKind;
use crate::physics::process::Process;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSheet {
    #[allow(dead_code)]
    machine: String,
    billet: RawBillet,
    /// Read by its `model` (`RawConstant` or `RawHanselSpittel`).
    #[allow(dead_code)]
    material: IgnoredAny,
    interface: RawInterface,
    #[serde(default)]
    blows: Vec<RawBlow>,
    caliper: Option<RawCaliper>,
}

/// `[caliper]`: how the measured heights were taken.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCaliper {
    tolerance_m: f64,
}

/// `[caliper] tolerance_m` when the sheet does not set it (`process::CALIPER_TOLERANCE_M`).
pub const DEFAULT_CALIPER_TOLERANCE_M: f64 = crate::physics::process::CALIPER_TOLERANCE_M;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBillet {
    diameter_m: f64,
    height_m: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInterface {
    friction: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBlow {
    final_height_m: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConstant {
    #[allow(dead_code)]
    model: String,
    #[serde(rename = "sigma0_Pa")]
    sigma0_pa: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHanselSpittel {
    #[allow(dead_code)]
    model: String,
    #[serde(rename = "A_Pa")]
    a_pa: f64,
    m1: f64,
    m2: f64,
    m3: f64,
    m4: f64,
    #[serde(rename = "temperature_C")]
    temperature_c: f64,
}

/// Parse and validate the text of a `process.toml` named `origin`; warnings are dropped
/// (the command-line verbs use [`parse_process_sheet`] and print them).
pub fn parse_process(origin: &str, text: &str) -> Result<Process, ConfigError> {
    parse_process_sheet(origin, text).map(|p| p.value)
}

/// Parse and validate the text of a `process.toml` named `origin`, with a warning for each
/// measured height that rises above the one before it (kept as measured).
pub fn parse_process_sheet(origin: &str, text: &str) -> Result<Parsed<Process>, ConfigError> {
    let doc = Document::parse(origin, text)?;
    let machine = match doc.choice("machine", &["hammer", "screw_press"])? {
        "hammer" => MachineKind::Hammer,
        _ => MachineKind::ScrewPress,
    };
    let raw: RawSheet = doc.read()?;
    let billet = BilletGeometry {
        diameter_m: doc.in_range("billet.diameter_m", raw.billet.diameter_m, &BILLET_DIMENSION_M)?,
        height_m: doc.in_range("billet.height_m", raw.billet.height_m, &BILLET_DIMENSION_M)?,
    };
    let material_value = doc.get("material").cloned().ok_or_else(|| doc.missing("material"))?;
    let material = match doc.choice("material.model", &["constant", "hansel_spittel"])? {
        "constant" => {
            let m: RawConstant = doc.read_value(material_value, "material")?;
            FlowStress::Constant { sigma0_pa: doc.in_range("material.sigma0_Pa", m.sigma0_pa, &FLOW_STRESS_PA)? }
        }
        _ => {
            let m: RawHanselSpittel = doc.read_value(material_value, "material")?;
            FlowStress::HanselSpittel {
                a_pa: doc.in_range("material.A_Pa", m.a_pa, &HANSEL_SPITTEL_A_PA)?,
                m1: doc.in_range("material.m1", m.m1, &HANSEL_SPITTEL_M1_PER_C)?,
                m2: doc.in_range("material.m2", m.m2, &HANSEL_SPITTEL_EXPONENT)?,
                m3: doc.in_range("material.m3", m.m3, &HANSEL_SPITTEL_EXPONENT)?,
                m4: doc.in_range("material.m4", m.m4, &HANSEL_SPITTEL_EXPONENT)?,
                temperature_c: doc.in_range("material.temperature_C", m.temperature_c, &TEMPERATURE_C)?,
            }
        }
    };
    let friction = doc.in_range("interface.friction", raw.interface.friction, &FRICTION)?;
    let tolerance_m = match &raw.caliper {
        Some(c) => doc.in_range("caliper.tolerance_m", c.tolerance_m, &CALIPER_TOLERANCE_M)?,
        None => DEFAULT_CALIPER_TOLERANCE_M,
    };
    let mut measured = Vec::with_capacity(raw.blows.len());
    let mut warnings = Vec::new();
    for (i, blow) in raw.blows.iter().enumerate() {
        let key = format!("blows[{}].final_height_m", i + 1);
        let h = doc.in_range(&key, blow.final_height_m, &MEASURED_HEIGHT_M)?;
        let place = doc.place(&key);
        // What it rises above, in words: the billet's height after blow 1, the blow before's
        // measured height after that. A billet only gets flatter.
        let (above_m, what) = match measured.last().copied() {
            None => (billet.height_m, "the billet's height_m".to_string()),
            Some(previous) => (previous, format!("blow {i}'s")),
        };
        let rise_m = h - above_m;
        if rise_m > tolerance_m {
            return Err(doc.invalid(
                &key,
                format!(
                    "is {:.2} mm, {:.2} mm above {what} ({:.2} mm): a billet only gets flatter, and that is more \
                     than a caliper's scatter ([caliper] tolerance_m = {:.2} mm)",
                    h * 1e3,
                    rise_m * 1e3,
                    above_m * 1e3,
                    tolerance_m * 1e3
                ),
            ));
        }
        if rise_m > 0.0 {
            warnings.push(match i {
                0 => format!(
                    "{place}: the measured height after blow 1 ({:.2} mm) is above the billet's height_m ({:.2} mm): \
                     caliper noise? kept as measured",
                    h * 1e3,
                    billet.height_m * 1e3
                ),
                _ => format!(
                    "{place}: measured heights rise between blow {i} ({:.2} mm) and blow {} ({:.2} mm): caliper noise? \
                     kept as measured",
                    above_m * 1e3,
                    i + 1,
                    h * 1e3
                ),
            });
        }
        measured.push(h);
    }
    let value = Process { machine, billet, material, friction, measured_final_heights_m: measured };
    Ok(Parsed { value, warnings })
}

#[cfg(test)]
mod tests {
    use super::*;

    const STEEL: &str = "machine = \"hammer\"\n[billet]\ndiameter_m = 0.060\nheight_m = 0.112\n\
                         [material]\nmodel = \"constant\"\nsigma0_Pa = 90e6\n[interface]\nfriction = 0.2\n";

    fn err(text: &str) -> String {
        parse_process("p.toml", text).unwrap_err().to_string()
    }

    #[test]
    fn contract_example_parses() {
        let text = format!("{STEEL}[[blows]]\nfinal_height_m = 0.0889\n");
        let p = parse_process_sheet("p.toml", &text).unwrap();
        assert!(p.warnings.is_empty());
        let p = p.value;
        assert_eq!(p.machine, MachineKind::Hammer);
        assert_eq!(p.billet, BilletGeometry { diameter_m: 0.060, height_m: 0.112 });
        assert_eq!(p.material, FlowStress::Constant { sigma0_pa: 90e6 });
        assert_eq!(p.friction, 0.2);
        assert_eq!(p.measured_final_heights_m, vec![0.0889]);
    }

    #[test]
    fn the_example_process_sheets_parse_without_warnings() {
        for text in [
            include_str!("../../config/steel-16NiCrMo13.process.toml"),
            include_str!("../../config/copper-cu99.process.toml"),
            include_str!("../../config/aluminium-7175.process.toml"),
        ] {
            assert!(parse_process_sheet("example", text).unwrap().warnings.is_empty());
        }
    }

    #[test]
    fn errors_name_file_line_and_key() {
        assert_eq!(err(&STEEL.replace("height_m = 0.112\n", "")), "p.toml:2:2: missing key 'billet.height_m'");
        let e = err(&STEEL.replace("\"constant\"", "\"johnson_cook\""));
        assert_eq!(
            e,
            "p.toml:6:1: key 'material.model' must be \"constant\" or \"hansel_spittel\", got \"johnson_cook\""
        );
        let e = err(&STEEL.replace("friction = 0.2", "friction = -0.2"));
        assert_eq!(e, "p.toml:9:1: key 'interface.friction' must be finite and >= 0, got -0.2");
        assert_eq!(err(""), "p.toml: missing key 'machine'");
        let e = err(&STEEL.replace("sigma0_Pa = 90e6", "sigma0_Pa = \"hot\""));
        assert!(e.contains("key 'material.sigma0_Pa' must be a number"), "{e}");
    }

    #[test]
    fn misspelt_keys_are_refused_with_a_suggestion() {
        let e = err(&STEEL.replace("sigma0_Pa", "sigma_Pa"));
        assert_eq!(e, "p.toml:7:1: unknown key 'sigma_Pa' in [material]; did you mean 'sigma0_Pa'?");
        let e = err(&STEEL.replace("friction = 0.2", "friction = 0.2\nfriction_model = \"tresca\""));
        assert!(e.starts_with("p.toml:10:1: unknown key 'friction_model' in [interface]"), "{e}");
        let e = err(&format!("{STEEL}[[blows]]\nfinal_heigth_m = 0.08\n"));
        assert!(e.contains("unknown key 'final_heigth_m' in [blows[1]]; did you mean 'final_height_m'?"), "{e}");
        let e = err(&STEEL.replace("[interface]", "[interfase]"));
        assert!(e.contains("unknown key 'interfase' at the top level; did you mean 'interface'?"), "{e}");
    }

    #[test]
    fn extreme_values_are_refused() {
        let e = err(&STEEL.replace("diameter_m = 0.060", "diameter_m = 1e-300"));
        assert_eq!(
            e,
            "p.toml:3:1: key 'billet.diameter_m' must be within 1e-3..2 m (a physically sensible range), got 1e-300"
        );
        let e = err(&STEEL.replace("sigma0_Pa = 90e6", "sigma0_Pa = 9e99"));
        assert!(e.contains("key 'material.sigma0_Pa' must be within"), "{e}");
        let e = err(&STEEL.replace("friction = 0.2", "friction = 20"));
        assert!(e.contains("key 'interface.friction' must be within 0..1"), "{e}");
        let hs = "machine = \"screw_press\"\n[billet]\ndiameter_m = 0.05\nheight_m = 0.03\n[material]\n\
                  model = \"hansel_spittel\"\nA_Pa = 411e6\nm1 = -0.0012\nm2 = 0.2\nm3 = 0.01\nm4 = -0.01\n\
                  temperature_C = 20\n[interface]\nfriction = 0.05\n";
        assert!(parse_process("p.toml", hs).is_ok());
        let e = err(&hs.replace("m1 = -0.0012", "m1 = 5"));
        assert!(e.contains("key 'material.m1' must be within"), "{e}");
        let e = err(&hs.replace("temperature_C = 20", "temperature_C = nan"));
        assert!(e.contains("key 'material.temperature_C' must be finite"), "{e}");
    }

    #[test]
    fn rising_measured_heights_are_kept_with_a_warning_naming_the_blows() {
        let text = format!(
            "{STEEL}[[blows]]\nfinal_height_m = 0.0889\n[[blows]]\nfinal_height_m = 0.01562\n\
             [[blows]]\nfinal_height_m = 0.01572\n"
        );
        let p = parse_process_sheet("process.toml", &text).unwrap();
        assert_eq!(p.value.measured_final_heights_m, vec![0.0889, 0.01562, 0.01572]);
        assert_eq!(
            p.warnings,
            vec![
                "process.toml:15:1: measured heights rise between blow 2 (15.62 mm) and blow 3 (15.72 mm): \
                 caliper noise? kept as measured"
                    .to_string()
            ]
        );
        let e = parse_process_sheet("p.toml", &format!("{STEEL}[[blows]]\nfinal_height_m = 0.1123\n")).unwrap();
        assert_eq!(e.value.measured_final_heights_m, vec![0.1123]);
        assert!(e.warnings[0].contains("after blow 1 (112.30 mm) is above the billet's height_m (112.00 mm)"), "{e:?}");
    }

    /// Issue 36: a measured height of 500 mm on a 112 mm billet was kept as "caliper noise".
    /// A rise beyond `[caliper] tolerance_m` (1 mm unless set) is refused at its key.
    #[test]
    fn a_rise_beyond_the_calipers_tolerance_is_refused_at_its_key() {
        let e = err(&format!("{STEEL}[[blows]]\nfinal_height_m = 0.5\n"));
        assert_eq!(
            e,
            "p.toml:11:1: key 'blows[1].final_height_m' is 500.00 mm, 388.00 mm above the billet's height_m \
             (112.00 mm): a billet only gets flatter, and that is more than a caliper's scatter ([caliper] \
             tolerance_m = 1.00 mm)"
        );
        let three = format!(
            "{STEEL}[[blows]]\nfinal_height_m = 0.0889\n[[blows]]\nfinal_height_m = 0.0612\n\
             [[blows]]\nfinal_height_m = 0.0625\n"
        );
        let e = err(&three);
        assert!(e.starts_with("p.toml:15:1: key 'blows[3].final_height_m' is 62.50 mm, 1.30 mm above blow 2's"), "{e}");
        // A wider tolerance, set: kept with its warning; a narrower one refuses 0.3 mm.
        let wide = format!("{three}[caliper]\ntolerance_m = 0.002\n");
        let p = parse_process_sheet("p.toml", &wide).unwrap();
        assert_eq!(p.value.measured_final_heights_m, vec![0.0889, 0.0612, 0.0625]);
        assert_eq!(p.warnings.len(), 1);
        let tight = format!("{STEEL}[[blows]]\nfinal_height_m = 0.1123\n[caliper]\ntolerance_m = 0.0002\n");
        assert!(err(&tight).contains("key 'blows[1].final_height_m' is 112.30 mm"), "{}", err(&tight));
        let e = err(&format!("{STEEL}[caliper]\ntolerance_m = 0.5\n"));
        assert!(e.contains("key 'caliper.tolerance_m' must be within 0..0.01 m"), "{e}");
    }
}
