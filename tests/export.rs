//! `forgemon export` at the process boundary (issue 19 §4): the recordings of a demo run (a
//! directory, two billets) and of a replayed capture directory (a file) are exported to CSV
//! and to Parquet, and pandas/pyarrow (`tests/python/read_export.py`) read both back. Their
//! rows, columns and values must equal what `forgemon replay --json` prints for the same
//! recordings (another path: the replay estimates again, the export reads the recorded
//! results), in order across the files, with each row's billet, file and the wall-clock
//! time the result was recorded at. A file that is not a recording fails the export,
//! named. CI installs pandas and pyarrow (`.ci/run`); elsewhere the test fails saying how.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::EffectSet;
use forgemon::record::{Payload, read_recording};
use forgemon::signal::capture::write_capture;
use forgemon::synth::{CaptureSpec, synth_blows};
use serde_json::Value;

const HAMMER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/hammer-lg1000.machine.toml");
const STEEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/steel-16NiCrMo13.process.toml");
const INSTALL: &str = "python3 -m pip install pandas pyarrow";

/// docs/interfaces.md §5's fields, then the billet, the file and the time, then the additions.
const COLUMNS: [&str; 29] = [
    "file",
    "wall_time",
    "billet",
    "billet_blow",
    "blow",
    "t_contact_s",
    "v_impact_mps",
    "kinetic_in_J",
    "plastic_J",
    "friction_J",
    "damped_J",
    "elastic_J",
    "efficiency",
    "final_load_N",
    "h_end_m",
    "class",
    "gap_s",
    "sensor_check",
    "judgement",
    "alert",
    "alert_reason",
    "peak_load_N",
    "t_end_s",
    "h_start_m",
    "residual",
    "method",
    "part_id",
    "lot",
    "die_set",
];

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().expect("run forgemon")
}

fn ok(out: Output) -> Output {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    out
}

/// A capture directory of one billet, eight blows (noise seed 21).
fn capture_dir(dir: &Path) -> PathBuf {
    let d = dir.join("captures");
    std::fs::create_dir_all(&d).expect("dir");
    let m = parse_machine("m", &std::fs::read_to_string(HAMMER).expect("machine")).expect("machine").machine;
    let p = parse_process("p", &std::fs::read_to_string(STEEL).expect("process")).expect("process");
    let v0 = [3.9, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3];
    let blows = synth_blows(&m, &EffectSet::NONE, &p, &v0, &CaptureSpec::hammer(21)).expect("synthesised");
    for (i, b) in blows.iter().enumerate() {
        let mut f = std::fs::File::create(d.join(format!("blow_{:02}.csv", i + 1))).expect("create");
        write_capture(&mut f, &b.rows).expect("write");
    }
    std::fs::copy(STEEL, d.join("process.toml")).expect("copy");
    d
}

/// What `replay --json` prints for a recording, with each result's log time and the file.
fn replayed(file: &Path) -> Vec<(Value, i64)> {
    let out = ok(forgemon(&["replay", file.to_str().expect("utf-8"), "--json"]));
    let lines: Vec<Value> =
        String::from_utf8_lossy(&out.stdout).lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect();
    let times: Vec<i64> = read_recording(file)
        .expect("reads")
        .messages
        .iter()
        .filter(|m| matches!(m.payload, Payload::Result(_)))
        .map(|m| m.log_time_ns)
        .collect();
    assert_eq!(lines.len(), times.len(), "{}", file.display());
    lines.into_iter().zip(times).collect()
}

fn python_read(csv: &Path, parquet: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/read_export.py");
    let out = Command::new("python3")
        .arg(&script)
        .args([csv, parquet])
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e}): install Python 3, then `{INSTALL}`"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    match out.status.code() {
        Some(0) => {}
        Some(3) => panic!("pandas or pyarrow is missing: run `{INSTALL}`\n{stderr}"),
        _ => panic!("read_export.py failed ({}):\n{stderr}", out.status),
    }
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("read_export.py printed no JSON ({e}):\n{stderr}"))
}

/// Every column of `row` against the replayed result `want`, recorded in `file` at `t_ns`.
fn assert_row(row: &Value, want: &Value, file: &Path, t_ns: i64, wall_time: &Value) {
    let blow = &want["blow"];
    for key in [
        "blow",
        "t_contact_s",
        "v_impact_mps",
        "kinetic_in_J",
        "plastic_J",
        "friction_J",
        "damped_J",
        "elastic_J",
        "efficiency",
        "final_load_N",
        "h_end_m",
        "class",
        "gap_s",
        "sensor_check",
        "peak_load_N",
        "t_end_s",
        "h_start_m",
        "residual",
        "method",
        "billet",
        "billet_blow",
    ] {
        // Numbers compared as f64 (pandas may read a whole column of integers as floats).
        let same = match (row[key].as_f64(), want[key].as_f64()) {
            (Some(a), Some(b)) => a == b,
            _ => row[key] == want[key],
        };
        assert!(same, "blow {blow}: {key}: exported {}, replayed {}", row[key], want[key]);
    }
    assert_eq!(row["judgement"], Value::Null, "no recipe: no judgement");
    assert_eq!(row["alert"], want["alert"]["kind"], "blow {blow}: alert");
    assert_eq!(row["alert_reason"], want["alert"]["reason"], "blow {blow}: alert reason");
    assert_eq!(row["file"], file.to_str().expect("utf-8"));
    match wall_time {
        Value::Null => assert_eq!(row["wall_time"].as_i64(), Some(t_ns), "blow {blow}: wall time"),
        text => assert_eq!(&row["wall_time"], text, "blow {blow}: wall time"),
    }
}

/// `ns` since the epoch as RFC 3339 UTC with nanoseconds, by the civil calendar (Howard
/// Hinnant's days-to-date), for the CSV's `wall_time`.
fn rfc3339(ns: i64) -> String {
    let (secs, frac) = (ns.div_euclid(1_000_000_000), ns.rem_euclid(1_000_000_000));
    let (days, sod) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{frac:09}Z", sod / 3600, sod % 3600 / 60, sod % 60)
}

#[test]
fn pandas_and_pyarrow_read_back_the_replayed_results_of_every_file_and_billet() {
    let tmp = tempfile::tempdir().expect("temp dir");
    // A demo run: a directory holding one recording of two billets.
    let demo_dir = tmp.path().join("demo");
    ok(forgemon(&[
        "demo",
        "--fast",
        "--billets",
        "2",
        "--interval",
        "0.3",
        "--lot",
        "L4711",
        "--die",
        "D17",
        "--dir",
        demo_dir.to_str().expect("utf-8"),
    ]));
    let demo_file = std::fs::read_dir(&demo_dir)
        .expect("the demo's directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .expect("a recording");
    // A capture directory replayed into a recording: a file.
    let rec = tmp.path().join("captures.mcap");
    let captures = capture_dir(tmp.path());
    ok(forgemon(&[
        "replay",
        captures.to_str().expect("utf-8"),
        "--machine",
        HAMMER,
        "--out",
        rec.to_str().expect("utf-8"),
    ]));

    let (csv, parquet) = (tmp.path().join("blows.csv"), tmp.path().join("blows.parquet"));
    let inputs = [demo_dir.to_str().expect("utf-8"), rec.to_str().expect("utf-8")];
    for (flag, out) in [("--csv", &csv), ("--parquet", &parquet)] {
        let done = ok(forgemon(&["export", inputs[0], inputs[1], flag, out.to_str().expect("utf-8")]));
        let said = String::from_utf8_lossy(&done.stderr);
        assert!(said.contains("exported 24 blows from 2 recordings"), "{said}");
    }
    // `--parquet -` into a pipe: the same bytes as the file.
    let piped = ok(forgemon(&["export", inputs[0], inputs[1], "--parquet", "-"]));
    assert!(piped.stdout == std::fs::read(&parquet).expect("the parquet file"), "--parquet - wrote other bytes");
    let read = python_read(&csv, &parquet);

    let want: Vec<(Value, i64, &Path)> = replayed(&demo_file)
        .into_iter()
        .map(|(v, t)| (v, t, demo_file.as_path()))
        .chain(replayed(&rec).into_iter().map(|(v, t)| (v, t, rec.as_path())))
        .collect();
    assert_eq!(want.len(), 24, "16 demo blows and 8 replayed ones");
    let billets: Vec<u64> = want.iter().filter_map(|(v, _, _)| v["billet"].as_u64()).collect();
    assert_eq!(billets.iter().filter(|&&b| b == 2).count(), 8, "the demo's second billet is exported");
    for format in ["csv", "parquet"] {
        let table = &read[format];
        let columns: Vec<&str> =
            table["columns"].as_array().expect("columns").iter().filter_map(Value::as_str).collect();
        assert_eq!(columns, COLUMNS, "{format}");
        let rows = table["rows"].as_array().expect("rows");
        assert_eq!(rows.len(), want.len(), "{format}");
        for (row, (w, t_ns, file)) in rows.iter().zip(&want) {
            let wall = if format == "csv" { Value::String(rfc3339(*t_ns)) } else { Value::Null };
            assert_row(row, w, file, *t_ns, &wall);
            // The demo forged lot L4711 on die set D17 (`--lot`, `--die`); the replayed
            // captures were forged as nothing recorded.
            let demo = *file == demo_file.as_path();
            let (lot, die) = if demo { (Value::from("L4711"), Value::from("D17")) } else { (Value::Null, Value::Null) };
            assert_eq!((&row["lot"], &row["die_set"], &row["part_id"]), (&lot, &die, &Value::Null), "{format}");
        }
    }
    // The Parquet columns are typed: a UTC timestamp, unsigned counts, nullable doubles.
    let types = &read["parquet"]["arrow_types"];
    assert_eq!(types["wall_time"], "timestamp[ns, tz=UTC]");
    assert_eq!(types["billet"], "uint32");
    assert_eq!(types["efficiency"], "double");
    assert_eq!(types["class"], "string");
}

#[test]
fn a_file_that_is_not_a_recording_fails_the_export_and_is_named() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let out = tmp.path().join("never.csv");
    let done = forgemon(&["export", STEEL, "--csv", out.to_str().expect("utf-8")]);
    let err = String::from_utf8_lossy(&done.stderr);
    assert!(!done.status.success() && err.contains(STEEL) && err.contains("not an MCAP"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.exists(), "nothing is written");
    // A directory with no recordings says so.
    let done = forgemon(&["export", tmp.path().to_str().expect("utf-8"), "--csv", out.to_str().expect("utf-8")]);
    let err = String::from_utf8_lossy(&done.stderr);
    assert!(!done.status.success() && err.contains("no recordings"), "{err}");
}
