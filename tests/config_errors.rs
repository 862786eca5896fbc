//! Configuration mistakes through the built binary (issue 15): a misspelt key, an extreme
//! value and a noisy process sheet. A mistake stops the verb with exit status 1 and a
//! message naming the file, line, column and key before anything is opened or simulated;
//! a measured height that rises by caliper noise is kept, with a warning naming the blows.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const HAMMER: &str = "config/hammer-lg1000.machine.toml";
const STEEL: &str = "config/steel-16NiCrMo13.process.toml";

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).current_dir(root()).args(args).output().expect("run forgemon")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("forgemon-config-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

/// Exit status 1, and every needle in stderr.
fn fails_naming(out: &Output, needles: &[&str]) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "stderr: {err}");
    for n in needles {
        assert!(err.contains(n), "'{n}' not in: {err}");
    }
    err
}

#[test]
fn a_misspelt_alert_key_stops_run_before_anything_is_opened() {
    let dir = tmp("run-typo");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let machine = root().join(HAMMER);
    // A device that does not exist and a recording directory that must not be created:
    // the configuration is refused before either is touched.
    let cfg = format!(
        "machine = \"{}\"\n[recording]\ndir = \"rec\"\n[alerts]\nhard_blwo = false\n[[sources]]\nname = \"daq\"\n\
         kind = \"serial\"\npath = \"/dev/forgemon-no-such-tty\"\n[[sources.channels]]\nrole = \"load_N\"\ngain = 1.0\n",
        machine.display()
    );
    let config = dir.join("service.toml");
    std::fs::write(&config, cfg).unwrap();
    let c = config.to_str().unwrap();
    let out = forgemon(&["run", "--config", c]);
    let at = format!("{c}:5:1:");
    fails_naming(&out, &[&at, "unknown key 'hard_blwo' in [alerts]", "did you mean 'hard_blow'?"]);
    assert!(!dir.join("rec").exists(), "the recording directory was created");
}

#[test]
fn extreme_machine_and_billet_values_are_refused_before_simulating() {
    let hammer = std::fs::read_to_string(root().join(HAMMER)).unwrap();
    let steel = std::fs::read_to_string(root().join(STEEL)).unwrap();
    for (name, text, key) in [
        ("heavy.machine.toml", hammer.replace("m1_kg = 732", "m1_kg = 1e308"), "'m1_kg'"),
        ("soft.machine.toml", hammer.replace("k_N_per_m = 3.15e9", "k_N_per_m = 1e-300"), "'k_N_per_m'"),
    ] {
        let path = tmp(name);
        std::fs::write(&path, text).unwrap();
        let p = path.to_str().unwrap();
        let out = forgemon(&["simulate", "--machine", p, "--process", STEEL, "--v0", "3.9"]);
        let err = fails_naming(&out, &[p, key, "physically sensible range"]);
        assert!(!err.contains("step size"), "{err}");
    }
    let thin = tmp("thin.process.toml");
    std::fs::write(&thin, steel.replace("diameter_m = 0.060", "diameter_m = 1e-300")).unwrap();
    let t = thin.to_str().unwrap();
    let out = forgemon(&["simulate", "--machine", HAMMER, "--process", t, "--v0", "3.9"]);
    fails_naming(&out, &[&format!("{t}:6:1:"), "'billet.diameter_m'", "within 1e-3..2 m"]);
}

#[test]
fn a_sheet_whose_heights_rise_by_caliper_noise_is_kept_with_a_warning() {
    let steel = std::fs::read_to_string(root().join(STEEL)).unwrap();
    let sheet = &steel[..steel.find("[[blows]]").unwrap_or(steel.len())];
    // Blow 4 measures 0.1 mm taller than blow 3.
    let noisy = format!(
        "{sheet}[[blows]]\nfinal_height_m = 0.0929\n[[blows]]\nfinal_height_m = 0.0750\n\
         [[blows]]\nfinal_height_m = 0.0620\n[[blows]]\nfinal_height_m = 0.0621\n"
    );
    let path = tmp("noisy.process.toml");
    std::fs::write(&path, noisy).unwrap();
    let p = path.to_str().unwrap();
    let caps = tmp("noisy-captures");
    let _ = std::fs::remove_dir_all(&caps);
    let c = caps.to_str().unwrap();
    let v0 = "3.9,4.5,5.0,5.3";
    let out = forgemon(&["simulate", "--machine", HAMMER, "--process", p, "--v0", v0, "--json", "--captures", c]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let warning =
        "measured heights rise between blow 3 (62.00 mm) and blow 4 (62.10 mm): caliper noise? kept as measured";
    assert!(err.contains("forgemon: warning: ") && err.contains(warning) && err.contains(p), "{err}");
    // replay reads the same sheet (the capture directory's own holds the simulated heights).
    let out = forgemon(&["replay", c, "--machine", HAMMER, "--process", p, "--json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains(warning), "{err}");
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 4, "one JSON line per blow");
    // identify reads it too (and cross-checks it against the encoder). Few starts keep it
    // cheap.
    let out_machine = tmp("noisy.machine.toml");
    let o = out_machine.to_str().unwrap();
    let args = [
        "identify",
        "--kind",
        "hammer",
        "--reference",
        c,
        "--process",
        p,
        "-o",
        o,
        "--starts",
        "2",
        "--monte-carlo",
        "10",
    ];
    let out = forgemon(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains(warning), "{err}");
    // What identify wrote loads as a machine file.
    let out = forgemon(&["simulate", "--machine", o, "--process", p, "--v0", "3.9"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Issue 36: a measured height 500 mm on a 112 mm billet was kept as "caliper noise?" by
/// `replay` and `simulate`, with exit 0. A rise beyond `[caliper] tolerance_m` (1 mm) is no
/// caliper's scatter: both verbs refuse the sheet, naming its file, line and key.
#[test]
fn a_measured_height_far_above_the_billet_is_refused_by_replay_and_simulate() {
    let steel = std::fs::read_to_string(root().join(STEEL)).unwrap();
    let sheet = &steel[..steel.find("[[blows]]").unwrap_or(steel.len())];
    let tall = format!("{sheet}[[blows]]\nfinal_height_m = 0.5\n");
    let path = tmp("tall.process.toml");
    std::fs::write(&path, tall).unwrap();
    let p = path.to_str().unwrap();
    let line = 1 + sheet.lines().count() + 1;
    let at = format!("{p}:{line}:1: key 'blows[1].final_height_m' is 500.00 mm, 388.00 mm above the billet's height_m");
    let out = forgemon(&["simulate", "--machine", HAMMER, "--process", p, "--v0", "3.9"]);
    fails_naming(&out, &[&at, "[caliper] tolerance_m = 1.00 mm"]);
    let caps = tmp("tall-captures");
    let _ = std::fs::remove_dir_all(&caps);
    let c = caps.to_str().unwrap();
    let out = forgemon(&["simulate", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9", "--captures", c]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = forgemon(&["replay", c, "--machine", HAMMER, "--process", p, "--json"]);
    fails_naming(&out, &[&at]);
    assert!(out.stdout.is_empty(), "nothing replayed on a refused sheet");
}
