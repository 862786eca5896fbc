//! `forgemon import` and `forgemon inspect` at the process boundary: a capture directory
//! becomes a recording that replays like the directory, and `inspect` tells what a
//! recording holds, in forging terms, for whole and cut-off files alike.

use std::path::PathBuf;
use std::process::{Command, Output};

use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::EffectSet;
use forgemon::signal::capture::write_capture;
use forgemon::synth::{CaptureSpec, synth_blows};
use serde_json::Value;

const HAMMER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/hammer-lg1000.machine.toml");
const STEEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/steel-16NiCrMo13.process.toml");

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().expect("run forgemon")
}

fn capture_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("forgemon-import-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let m = parse_machine("m", &std::fs::read_to_string(HAMMER).unwrap()).unwrap().machine;
    let p = parse_process("p", &std::fs::read_to_string(STEEL).unwrap()).unwrap();
    let blows =
        synth_blows(&m, &EffectSet::NONE, &p, &[3.9, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3], &CaptureSpec::hammer(21))
            .unwrap();
    for (i, b) in blows.iter().enumerate() {
        write_capture(&mut std::fs::File::create(dir.join(format!("blow_{:02}.csv", i + 1))).unwrap(), &b.rows)
            .unwrap();
    }
    std::fs::copy(STEEL, dir.join("process.toml")).unwrap();
    dir
}

fn inspect(path: &str) -> Value {
    let out = forgemon(&["inspect", path, "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn an_imported_directory_replays_like_the_directory() {
    let dir = capture_dir("replay");
    let rec = dir.join("imported.mcap");
    let (d, r) = (dir.to_str().unwrap(), rec.to_str().unwrap());
    let out = forgemon(&["import", d, "-o", r, "--machine", HAMMER]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let from_dir = forgemon(&["replay", d, "--machine", HAMMER, "--json"]);
    let from_rec = forgemon(&["replay", r, "--machine", HAMMER, "--json"]);
    assert!(from_rec.status.success(), "{}", String::from_utf8_lossy(&from_rec.stderr));
    assert_eq!(from_dir.stdout, from_rec.stdout);
    assert_eq!(String::from_utf8_lossy(&from_rec.stdout).lines().count(), 8);
    // The import holds samples and configuration, no results yet.
    let v = inspect(r);
    assert_eq!(v["complete"], true);
    assert_eq!(v["blows"], 0);
    assert_eq!(v["sources"][0]["channels"], "load_N,disp_m,acc_mps2");
    assert!((v["sources"][0]["rate_hz"].as_f64().unwrap() - 100e3).abs() < 1.0);
    assert_eq!(v["config_files"], serde_json::json!(["machine.toml", "process.toml"]));
}

#[test]
fn inspect_counts_blows_classes_and_alerts_of_a_replay() {
    let dir = capture_dir("inspect");
    let rec = dir.join("replay.mcap");
    let replay =
        forgemon(&["replay", dir.to_str().unwrap(), "--machine", HAMMER, "--json", "--out", rec.to_str().unwrap()]);
    assert!(replay.status.success());
    let results: Vec<Value> =
        String::from_utf8_lossy(&replay.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let v = inspect(rec.to_str().unwrap());
    assert_eq!(v["blows"].as_u64(), Some(results.len() as u64));
    let hard = results.iter().filter(|r| r["class"] == "hard").count() as u64;
    assert_eq!(v["results_by_class"]["hard"].as_u64().unwrap_or(0), hard);
    let alerts = results.iter().filter(|r| !r["alert"].is_null()).count() as u64;
    assert_eq!(v["alerts"]["elastic_blow"].as_u64().unwrap_or(0), alerts);
    let mean = results.iter().map(|r| r["efficiency"].as_f64().unwrap()).sum::<f64>() / results.len() as f64;
    assert!((v["mean_efficiency"].as_f64().unwrap() - mean).abs() < 1e-12);
    // Per-billet statistics, from the replayed results here: one billet, its efficiencies'
    // mean and sample standard deviation, and the billet blow of its first hard blow, which
    // the billet's own summary also names.
    let stats = &v["billet_stats"][0];
    assert_eq!(v["billet_stats"].as_array().map(Vec::len), Some(1));
    assert_eq!(stats["blows"].as_u64(), Some(results.len() as u64));
    let effs: Vec<f64> = results.iter().map(|r| r["efficiency"].as_f64().unwrap()).collect();
    let sd = (effs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (effs.len() - 1) as f64).sqrt();
    assert!((stats["efficiency_mean"].as_f64().unwrap() - mean).abs() < 1e-12);
    assert!((stats["efficiency_sd"].as_f64().unwrap() - sd).abs() < 1e-12);
    let plastic: Vec<f64> = results.iter().map(|r| r["plastic_J"].as_f64().unwrap()).collect();
    let plastic_mean = plastic.iter().sum::<f64>() / plastic.len() as f64;
    assert!((stats["plastic_J_mean"].as_f64().unwrap() - plastic_mean).abs() < 1e-9 * plastic_mean);
    let first_hard = results.iter().find(|r| r["class"] == "hard").map(|r| r["billet_blow"].as_u64().unwrap());
    assert_eq!(stats["first_hard_blow"].as_u64(), first_hard);
    assert_eq!(v["billet_summaries"][0]["first_hard_blow"].as_u64(), first_hard);
    // The text form says the same for people.
    let text = String::from_utf8(forgemon(&["inspect", rec.to_str().unwrap()]).stdout).unwrap();
    assert!(text.contains("finished properly") && text.contains(&format!("blows: {}", results.len())), "{text}");
    // A copy cut in the middle is reported as cut off, with what was recovered.
    let bytes = std::fs::read(&rec).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let c = inspect(cut.to_str().unwrap());
    assert_eq!(c["complete"], false);
    assert!(c["recovered_messages"].as_u64().unwrap() > 0);
    let text = String::from_utf8(forgemon(&["inspect", cut.to_str().unwrap()]).stdout).unwrap();
    assert!(text.contains("CUT OFF"), "{text}");
}

#[test]
fn import_and_inspect_refuse_what_they_cannot_read() {
    let dir = capture_dir("bad");
    let out = forgemon(&["inspect", STEEL]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains(STEEL) && err.contains("not an MCAP"), "{err}");
    let bad = dir.join("blow_01.csv");
    std::fs::write(&bad, "t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,x,2,3\n").unwrap();
    let rec = dir.join("never.mcap");
    let out = forgemon(&["import", dir.to_str().unwrap(), "-o", rec.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("blow_01.csv:3") && err.contains("load_N"), "{err}");
    assert!(!err.contains("panicked"));
}
