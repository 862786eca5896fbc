//! `forgemon identify` from references without a load channel (issue 43): the accelerometer
//! and the encoder alone, with the ram's mass from the data sheet (`--ram-kg`) as the one
//! known quantity. Reference captures are made by `forgemon simulate --captures` (sensor
//! noise, a 10 µm encoder, the free-fall approach) from machines that are not the papers'
//! (the same as `tests/identify.rs`), and their `load_N` column is then removed, as a DAQ
//! without a load cell writes them.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const STEEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/steel-16NiCrMo13.process.toml");

/// A hammer unlike the paper's (Table 1: 732 kg, 19 kg, 3.15e9 N/m, 18540 N s/m).
const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n";
/// A press unlike the paper's Table 3.
const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
                     c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n";

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("forgemon-identify-noload-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn ok(out: &Output) -> String {
    assert!(out.status.success(), "{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `dir/captures` rendered by `simulate_args`, copied to `dir/no-load` without the `load_N`
/// column (wherever it stands in the header).
fn captures_without_load(dir: &Path, simulate_args: &[&str]) -> PathBuf {
    let caps = dir.join("captures");
    let mut args = simulate_args.to_vec();
    args.extend(["--captures", caps.to_str().unwrap()]);
    ok(&forgemon(&args));
    strip_load(&caps, &dir.join("no-load"))
}

/// The capture directory `from` copied to `to` without the `load_N` column (wherever it
/// stands in the header).
fn strip_load(from: &Path, to: &Path) -> PathBuf {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        if path.extension().is_some_and(|e| e == "csv") {
            let column = text.lines().next().unwrap().split(',').position(|c| c == "load_N").expect("a load column");
            let kept: Vec<String> = text
                .lines()
                .map(|l| {
                    l.split(',').enumerate().filter(|(i, _)| *i != column).map(|(_, c)| c).collect::<Vec<_>>().join(",")
                })
                .collect();
            std::fs::write(to.join(name), kept.join("\n") + "\n").unwrap();
        } else {
            std::fs::write(to.join(name), text).unwrap();
        }
    }
    to.to_path_buf()
}

fn table(text: &str) -> toml::Table {
    text.parse().unwrap()
}

fn number(t: &toml::Table, key: &str) -> f64 {
    t[key].as_float().or_else(|| t[key].as_integer().map(|i| i as f64)).unwrap()
}

/// The efficiencies `machine` gives the steel sheet's billet at `v0s`.
fn efficiencies(machine: &Path, sheet: &Path, v0s: &str) -> Vec<f64> {
    let out = ok(&forgemon(&[
        "simulate",
        "--machine",
        machine.to_str().unwrap(),
        "--process",
        sheet.to_str().unwrap(),
        "--v0",
        v0s,
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(out.lines().next().unwrap()).unwrap();
    v["blows"].as_array().unwrap().iter().map(|b| b["efficiency"].as_f64().unwrap()).collect()
}

#[test]
fn a_hammer_is_identified_from_its_accelerometer_and_encoder_with_the_ram_mass_held() {
    let dir = scratch("hammer");
    std::fs::write(dir.join("truth.machine.toml"), HAMMER).unwrap();
    let steel = std::fs::read_to_string(STEEL).unwrap();
    let sheet = dir.join("steel.process.toml");
    std::fs::write(&sheet, &steel[..steel.find("[[blows]]").unwrap_or(steel.len())]).unwrap();
    let truth = dir.join("truth.machine.toml");
    let caps = captures_without_load(
        &dir,
        &[
            "simulate",
            "--machine",
            truth.to_str().unwrap(),
            "--process",
            sheet.to_str().unwrap(),
            "--v0",
            "4.2,5.0,5.3",
        ],
    );
    // Without the data sheet's mass the captures are refused, naming the option.
    let out_path = dir.join("fitted.machine.toml");
    let refused = forgemon(&["identify", "--kind", "hammer", "--reference", caps.to_str().unwrap(), "-o", "/dev/null"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && stderr.contains("--ram-kg") && stderr.contains("load_N"), "{stderr}");
    let stdout = ok(&forgemon(&[
        "identify",
        "--kind",
        "hammer",
        "--reference",
        caps.to_str().unwrap(),
        "--ram-kg",
        "910",
        "-o",
        out_path.to_str().unwrap(),
    ]));
    eprintln!("{stdout}");
    let fitted_text = std::fs::read_to_string(&out_path).unwrap();
    let fitted = table(&fitted_text);
    // The anchor is held, and says so.
    assert_eq!(number(&fitted, "m1_kg"), 910.0);
    assert!(fitted_text.contains("m1_kg = 9.100000e2  # held at the data sheet's"), "{fitted_text}");
    assert!(stdout.contains("held at the data sheet's"), "{stdout}");
    // The lower tool is seen through the billet only: its mass and spring within the issue
    // 5 bound (5 %) all the same; the damper is reported with its own error.
    let truth_t = table(HAMMER);
    for key in ["m2_kg", "k_N_per_m"] {
        let (v, t) = (number(&fitted, key), number(&truth_t, key));
        assert!((v / t - 1.0).abs() < 0.05, "{key}: {v} vs {t}\n{fitted_text}");
    }
    // What the estimator takes from the model: the efficiencies it predicts, on the sheet's
    // billet at the references' speeds and one more blow, within issue 43's 0.03 of the true
    // machine's. (Measured: within 0.001.)
    let v0s = "4.2,5.0,5.3,5.3";
    let (ours, true_ones) = (efficiencies(&out_path, &sheet, v0s), efficiencies(&truth, &sheet, v0s));
    for (i, (a, b)) in ours.iter().zip(&true_ones).enumerate() {
        assert!((a - b).abs() <= 0.03, "blow {}: efficiency {a} against the true machine's {b}", i + 1);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_press_is_identified_from_bare_strikes_without_its_load_cell() {
    let dir = scratch("press");
    std::fs::write(dir.join("truth.machine.toml"), PRESS).unwrap();
    let truth = dir.join("truth.machine.toml");
    let caps = captures_without_load(
        &dir,
        &["simulate", "--machine", truth.to_str().unwrap(), "--bare", "--v0", "0.30,0.36,0.42"],
    );
    let out_path = dir.join("fitted.machine.toml");
    let stdout = ok(&forgemon(&[
        "identify",
        "--kind",
        "screw_press",
        "--bare",
        "--reference",
        caps.to_str().unwrap(),
        "--ram-kg",
        "90000",
        "-o",
        out_path.to_str().unwrap(),
    ]));
    eprintln!("{stdout}");
    let fitted_text = std::fs::read_to_string(&out_path).unwrap();
    let fitted = table(&fitted_text);
    let truth_t = table(PRESS);
    assert_eq!(number(&fitted, "m_ram_kg"), 90000.0);
    // As from the load (`tests/identify.rs`): the tool's mass, both springs and the link
    // damper within 5 % and called determined; the frame damper is not determined.
    for key in ["m_tool_kg", "k_link_N_per_m", "c_link_Ns_per_m", "k_frame_N_per_m"] {
        let (v, t) = (number(&fitted, key), number(&truth_t, key));
        assert!(fitted["identify"]["determined"][key].as_bool().unwrap(), "{key} determined\n{fitted_text}");
        assert!((v / t - 1.0).abs() < 0.05, "{key}: {v} vs {t}\n{fitted_text}");
    }
    assert!(!fitted["identify"]["determined"]["c_frame_Ns_per_m"].as_bool().unwrap(), "{fitted_text}");
    let _ = std::fs::remove_dir_all(&dir);
}

mod independent;

/// The independent renderer's hammer (`tests/independent`: its own integrator, an
/// elastic-plastic billet, a Butterworth DAQ chain) at 100 kHz, identified without its load
/// column: prints what identify made of it.
#[test]
#[ignore = "prints identify's table on the independent renderer; run with --ignored --nocapture"]
fn independent_hammer_without_load() {
    use independent::captures::{render, write_dir};
    use independent::{HAMMER as IND_HAMMER, Hidden, Kind, speeds};
    for seed in [1u64, 2] {
        let dir = scratch(&format!("independent-{seed}"));
        let r = render(Kind::Hammer, &Hidden::None, &speeds(Kind::Hammer).0, 1.0, 100e3, seed);
        let src = dir.join("with-load");
        write_dir(&src, &r, IND_HAMMER);
        let caps = strip_load(&src, &dir.join("no-load"));
        let out_path = dir.join("fitted.machine.toml");
        let out = forgemon(&[
            "identify",
            "--kind",
            "hammer",
            "--reference",
            caps.to_str().unwrap(),
            "--ram-kg",
            "910",
            "--fit-blows",
            "1,2",
            "--monte-carlo",
            "0",
            "-o",
            out_path.to_str().unwrap(),
        ]);
        eprintln!("seed {seed}:\n{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    }
}
