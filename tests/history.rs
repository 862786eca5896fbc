//! The quality record (issue 44) at the process boundary: the history database the service
//! writes as it runs, read back by Python's own `sqlite3` (`tests/python/dump_sqlite.py`),
//! against the recording it came from (MCAP is the source of truth):
//!
//! - a demo session with `--lot`, `--die` and a recipe fills it: a row per recorded result
//!   and per billet summary, each value the recording's (`forgemon export`), and
//!   `forgemon history rebuild` from the recording gives the same database, row for row;
//! - part ids given per billet (`Control::NewBilletAs`, what `POST /billet` sends) reach the
//!   blows' rows, the recording's `/billets` and a replay, and the rebuild;
//! - `POST /billet` with a JSON body is taken, and a bad one refused naming its key;
//! - die life: each die set's blows, hard blows and energy, its `die_life` alerts at the
//!   warning and the limit, and its count taken up again after a restart.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use forgemon::acquire::Backpressure;
use forgemon::acquire::serial::driver::{SerialConfig, SerialFormat, run_on_stream, system_clock_ns};
use forgemon::config::history::{DieLifeConfig, TraceUpdate};
use forgemon::config::service::ServiceConfig;
use forgemon::config::{parse_machine, parse_process};
use forgemon::daemon::{Control, Hooks, SOURCE_CHANNEL_CAPACITY, serve};
use forgemon::estimate::billet_book::Trace;
use forgemon::physics::effects::EffectSet;
use forgemon::record::{Payload, read_recording};
use forgemon::simdevice::{BilletPlan, SerialDeviceSpec, SimMachine, drive_serial};
use forgemon::synth::CaptureSpec;
use serde_json::Value;
use tokio::sync::{mpsc, watch};

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().expect("run forgemon")
}

fn ok(out: Output) -> Output {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    out
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("forgemon-history-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The database as Python's sqlite3 reads it: `{user_version, tables: {name: [rows]}}`.
fn dump(db: &Path) -> Value {
    let script = common::root().join("tests/python/dump_sqlite.py");
    let out = Command::new("python3").arg(&script).arg(db).output().expect("python3 runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("JSON")
}

fn rows<'a>(d: &'a Value, table: &str) -> &'a Vec<Value> {
    d["tables"][table].as_array().unwrap_or_else(|| panic!("no table {table}: {d}"))
}

fn path_str(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A CSV export of `dir`'s recordings: its rows by column name.
fn exported(dir: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let out = ok(forgemon(&["export", path_str(dir), "--csv", "-"]));
    let mut r = csv::Reader::from_reader(out.stdout.as_slice());
    let header: Vec<String> = r.headers().unwrap().iter().map(str::to_string).collect();
    r.records().map(|rec| header.iter().cloned().zip(rec.unwrap().iter().map(str::to_string)).collect()).collect()
}

#[test]
fn a_demo_session_fills_the_history_and_its_rebuild_from_the_recording_equals_it() {
    let dir = temp("demo");
    let (_, recipe) = common::demo_and_teach(&dir, "reference", 3);
    let rec = dir.join("session");
    ok(forgemon(&[
        "demo",
        "--fast",
        "--billets",
        "4",
        "--lot",
        "4711",
        "--die",
        "17",
        "--recipe",
        path_str(&recipe),
        "--dir",
        path_str(&rec),
    ]));
    let live_db = rec.join("history.sqlite");
    let live = dump(&live_db);
    assert_eq!(live["user_version"], forgemon::history::schema::MIGRATIONS.len(), "schema version");

    // A row per recorded result, with the recording's values (the export reads the same
    // results): 4 billets of 8 blows.
    let blows = rows(&live, "blows");
    let export = exported(&rec);
    assert_eq!(blows.len(), export.len());
    assert_eq!(blows.len(), 32, "4 billets of 8 blows");
    for (b, e) in blows.iter().zip(&export) {
        let n = &e["blow"];
        assert_eq!(b["blow"].to_string(), *n);
        assert_eq!(b["billet"].to_string(), e["billet"], "blow {n}");
        assert_eq!(b["class"].as_str(), Some(e["class"].as_str()), "blow {n}");
        // The recorded value: the CSV prints the shortest round-trip form, and serde_json
        // reads Python's JSON to within an ulp (it does not round-trip without its
        // `float_roundtrip` feature).
        let eff: f64 = e["efficiency"].parse().unwrap();
        let got = b["efficiency"].as_f64().unwrap();
        assert!((got - eff).abs() <= 2.0 * f64::EPSILON * eff.abs(), "blow {n}: {got} against {eff}");
        let judged: Value = serde_json::from_str(&e["judgement"]).unwrap();
        let word = if judged["ok"] == true { "OK" } else { "NOK" };
        assert_eq!(b["judgement"].as_str(), Some(word), "blow {n}");
        assert_eq!(b["recipe"], judged["recipe"], "blow {n}");
        assert_eq!((b["lot"].as_str(), b["die_set"].as_str(), &b["part_id"]), (Some("4711"), Some("17"), &Value::Null));
    }
    let billets = rows(&live, "billets");
    assert_eq!(billets.len(), 4);
    for (i, b) in billets.iter().enumerate() {
        assert_eq!(b["billet"], i + 1);
        assert_eq!((b["blows"].as_u64(), b["finished"].as_i64()), (Some(8), Some(i64::from(i < 3))), "{b}");
        assert_eq!((b["lot"].as_str(), b["die_set"].as_str()), (Some("4711"), Some("17")), "{b}");
    }

    // MCAP is the source of truth: a rebuild from the recording is the live database.
    let rebuilt_db = dir.join("rebuilt.sqlite");
    let out = ok(forgemon(&["history", "rebuild", path_str(&rec), "--db", path_str(&rebuilt_db)]));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("32 blows and 4 billets added"), "{said}");
    assert_eq!(dump(&rebuilt_db), live, "rebuilt against live");
    // Into the live database it adds nothing: every row is there.
    let out = ok(forgemon(&["history", "rebuild", path_str(&rec), "--db", path_str(&live_db)]));
    assert!(String::from_utf8_lossy(&out.stderr).contains("0 blows and 0 billets added"));
    assert_eq!(dump(&live_db), live);

    // The export: pandas reads the CSV and pyarrow the Parquet file; both hold the database's
    // rows and columns, with `wall_time` for `wall_time_ns`.
    history_export_equals_the_rows(&dir, &live_db, blows);

    // The queries: by lot, by NOK, by billet table.
    let query = |extra: &[&str]| -> Vec<Value> {
        let args = [&["history", "query", "--db", path_str(&live_db), "--json"], extra].concat();
        let out = ok(forgemon(&args));
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    };
    assert_eq!(query(&["--lot", "4711"]).len(), 32);
    assert_eq!(query(&["--lot", "4712"]).len(), 0);
    let nok = blows.iter().filter(|b| b["judgement"] == "NOK").count();
    assert_eq!(query(&["--nok"]).len(), nok);
    let nok_billets: std::collections::BTreeSet<_> =
        blows.iter().filter(|b| b["judgement"] == "NOK").map(|b| b["billet"].as_u64()).collect();
    assert_eq!(query(&["--table", "billets", "--nok"]).len(), nok_billets.len());
    assert_eq!(query(&["--die", "17", "--limit", "5"]).len(), 5);
    eprintln!("history of the demo: 32 blows, {nok} NOK on {} billets", nok_billets.len());

    // The shift report from a minute before the first blow: its 32 blows and 4 billets, its
    // table and each blow's charts.
    let html = dir.join("shift.html");
    let day = chrono_day(&blows[0]);
    ok(forgemon(&[
        "history",
        "report",
        "--db",
        path_str(&live_db),
        "--recipe",
        path_str(&recipe),
        "--shift",
        &day,
        "--hours",
        "24",
        "-o",
        path_str(&html),
    ]));
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("Shift report: flange"), "the recipe's name in the title");
    assert!(
        page.contains("<td>32</td>") && page.contains("<td>4711</td>") && page.contains("<td>17</td>"),
        "the shift's table"
    );
    assert_eq!(page.matches("<svg").count(), 2 * 8, "an individuals and a moving-range chart per blow");

    // SPC per blow of the recipe, against Python's statistics on the same rows.
    let out = ok(forgemon(&["history", "spc", "--db", path_str(&live_db), "--recipe", path_str(&recipe), "--json"]));
    let spc: Vec<Value> =
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let recipe_file = forgemon::config::recipe::parse_recipe("r", &std::fs::read_to_string(&recipe).unwrap()).unwrap();
    let script = common::root().join("tests/python/spc_check.py");
    let py = Command::new("python3").arg(&script).arg(&live_db).arg(&recipe_file.name).output().expect("python3 runs");
    assert!(py.status.success(), "{}", String::from_utf8_lossy(&py.stderr));
    let want: Vec<Value> = serde_json::from_slice(&py.stdout).unwrap();
    // Every blow the recipe has and the demo forged, three quantities each.
    let blows_in_recipe = recipe_file.blows.iter().filter(|w| w.blow <= 8).count();
    assert_eq!(spc.len(), 3 * blows_in_recipe, "{spc:?}");
    for c in &spc {
        let w = want.iter().find(|w| w["blow"] == c["blow"] && w["quantity"] == c["quantity"]).expect("Python's row");
        let close = |k: &str| {
            let (a, b) = (c[k].as_f64().unwrap(), w[k].as_f64().unwrap());
            assert!((a - b).abs() <= 1e-9 * b.abs().max(1e-12), "{k}: {a} against Python's {b} ({c})");
        };
        assert_eq!(c["n"], w["n"], "{c}");
        for k in ["mean", "sd", "mr_bar"] {
            close(k);
        }
        // The limits are the recipe's window; Cp from them and Python's moving range.
        let window = recipe_file.blows.iter().find(|b| c["blow"] == b.blow).unwrap();
        let win = match c["quantity"].as_str().unwrap() {
            "efficiency" => window.efficiency,
            "plastic_J" => window.plastic_j,
            _ => window.peak_load_n,
        };
        assert_eq!((c["lsl"].as_f64(), c["usl"].as_f64()), (Some(win.min), Some(win.max)), "{c}");
        let cp = (win.max - win.min) / (6.0 * w["mr_bar"].as_f64().unwrap() / 1.128);
        assert!((c["cp"].as_f64().unwrap() - cp).abs() <= 1e-9 * cp, "{c}: Cp {cp}");
    }
}

/// `forgemon history export` of `db`'s blows as CSV and Parquet, read back by pandas and
/// pyarrow (`tests/python/read_export.py`): the columns and values of `blows`, the database's
/// rows as Python's sqlite3 read them.
fn history_export_equals_the_rows(dir: &Path, db: &Path, blows: &[Value]) {
    let (csv, parquet) = (dir.join("history.csv"), dir.join("history.parquet"));
    for (flag, out) in [("--csv", &csv), ("--parquet", &parquet)] {
        ok(forgemon(&["history", "export", "--db", path_str(db), flag, path_str(out)]));
    }
    let script = common::root().join("tests/python/read_export.py");
    let out = Command::new("python3").arg(&script).args([&csv, &parquet]).output().expect("python3 runs");
    assert!(out.status.success(), "read_export.py: {}", String::from_utf8_lossy(&out.stderr));
    let read: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let first = blows[0].as_object().unwrap();
    let want: Vec<&str> = std::iter::once("wall_time")
        .chain(first.keys().map(String::as_str).filter(|k| !["id", "wall_time_ns"].contains(k)))
        .collect();
    for form in ["csv", "parquet"] {
        let cols: Vec<&str> = read[form]["columns"].as_array().unwrap().iter().map(|c| c.as_str().unwrap()).collect();
        // In the table's order (dump_sqlite.py's objects keep it, as does serde_json here).
        assert_eq!(cols, want, "{form} columns");
        let got = read[form]["rows"].as_array().unwrap();
        assert_eq!(got.len(), blows.len(), "{form} rows");
        for (g, b) in got.iter().zip(blows) {
            for col in &want[1..] {
                let (x, y) = (&g[*col], &b[*col]);
                let same = match (x.as_f64(), y.as_f64(), y.as_str()) {
                    // Within an ulp or two: serde_json reads Python's JSON without
                    // `float_roundtrip` (as in the demo test above).
                    (Some(x), Some(y), _) => (x - y).abs() <= 2.0 * f64::EPSILON * y.abs(),
                    // pandas reads a CSV column of digits as numbers ("4711").
                    (Some(_), None, Some(y)) if form == "csv" => serde_json::to_string(x).ok().as_deref() == Some(y),
                    _ => x == y,
                };
                assert!(same, "{form} blow {}: {col} {x} against the database's {y}", b["blow"]);
            }
        }
    }
    let types = &read["parquet"]["arrow_types"];
    assert_eq!(types["wall_time"], "timestamp[ns, tz=UTC]");
    assert_eq!(
        (types["billet"].as_str(), types["efficiency"].as_str(), types["lot"].as_str()),
        (Some("int64"), Some("double"), Some("string"))
    );
    for (g, b) in read["parquet"]["rows"].as_array().unwrap().iter().zip(blows) {
        assert_eq!(g["wall_time"], b["wall_time_ns"], "Parquet wall_time is the row's log time");
    }
}

/// A minute before a row's time, RFC 3339, for `--shift`.
fn chrono_day(row: &Value) -> String {
    let secs = row["wall_time_ns"].as_i64().unwrap() / 1_000_000_000 - 60;
    let out = Command::new("date").args(["-u", "-d", &format!("@{secs}"), "+%Y-%m-%dT%H:%M:%SZ"]).output().unwrap();
    String::from_utf8(out.stdout).unwrap().trim().to_string()
}

#[test]
fn a_query_names_a_missing_database_and_a_bad_time() {
    let dir = temp("errors");
    let missing = dir.join("none.sqlite");
    let out = forgemon(&["history", "query", "--db", path_str(&missing)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("none.sqlite") && err.contains("no history database"), "{err}");
    assert!(!missing.exists(), "a query creates nothing");
    let db = dir.join("h.sqlite");
    drop(forgemon::history::History::open(&db, None).unwrap());
    let out = forgemon(&["history", "query", "--db", path_str(&db), "--since", "yesterday"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--since yesterday") && err.contains("RFC 3339"), "{err}");
}

/// `billets` billets of three blows over a real pty into a service recording to `rec`,
/// forged as `part` at the start; at each later billet's start `change` says what it is
/// forged as (as `POST /billet` would, at the billet's first sample).
fn forge(rec: &Path, part: Trace, die_life: DieLifeConfig, billets: usize, change: fn(usize) -> TraceUpdate) {
    forge_with(rec, |c| ServiceConfig { part, die_life, ..c }, billets, change)
}

/// As `forge`, the service's configuration `config` of the minimal one.
fn forge_with(
    rec: &Path,
    config: impl FnOnce(ServiceConfig) -> ServiceConfig,
    billets: usize,
    change: fn(usize) -> TraceUpdate,
) {
    let machine_text = common::read("config/hammer-lg1000.machine.toml");
    let steel = common::read("config/steel-16NiCrMo13.process.toml");
    let machine = parse_machine("m", &machine_text).unwrap().machine;
    let plan = BilletPlan { process: parse_process("p", &steel).unwrap(), v0s_mps: vec![3.9, 5.3, 5.3] };
    let sim = SimMachine::new(machine, EffectSet::NONE, vec![plan; billets], CaptureSpec::hammer(5), 0.3);
    let config =
        config(ServiceConfig::minimal(common::root().join("config/hammer-lg1000.machine.toml"), rec.to_path_buf()));
    let parts = common::demo_hammer_parts(rec, config);
    let channels = forgemon::cli::demo::demo_channels();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async move {
        let (master, slave) = tokio_serial::SerialStream::pair().expect("a pty pair");
        let (tx, rx) = mpsc::channel(SOURCE_CHANNEL_CAPACITY);
        let (shutdown_tx, shutdown_rx) = watch::channel(false);
        let (_stop_tx, stop_rx) = watch::channel(false);
        let (control_tx, control_rx) = mpsc::channel(16);
        let billet_tx = control_tx.clone();
        let spec = SerialDeviceSpec {
            channels: channels.clone(),
            frame_samples: 1000,
            realtime: false,
            faults: Default::default(),
        };
        let device_stop = shutdown_rx.clone();
        let device = tokio::spawn(async move {
            let mut master = master;
            let stats = drive_serial(sim, &spec, &mut master, device_stop, move |billet, at| {
                let c = Control::NewBilletAs { at_device_ns: Some(at as i64), change: Box::new(change(billet)) };
                billet_tx.try_send(c).expect("room for the signal");
            })
            .await;
            // A pty drops what its reader has not taken when the master closes: stay open
            // until the service has read the last frame (as `forgemon demo` does).
            tokio::time::sleep(std::time::Duration::from_secs(1)).await;
            stats
        });
        let cfg = SerialConfig {
            backpressure: Backpressure::Wait,
            ..SerialConfig::new("daq", "pty", 0, SerialFormat::Binary, channels)
        };
        tokio::spawn(run_on_stream(cfg, slave, system_clock_ns, tx, shutdown_rx));
        serve(parts, rx, shutdown_tx, stop_rx, Hooks::default(), Some((control_tx, control_rx))).await.unwrap();
        device.await.unwrap().unwrap();
    });
}

/// The `die_life` alerts of the recordings in `rec` from `first` on: (blow, reason).
fn die_alerts(files: &[PathBuf]) -> Vec<(u32, String)> {
    files
        .iter()
        .flat_map(|f| read_recording(f).unwrap().messages)
        .filter_map(|m| match m.payload {
            Payload::Alert(a) if a.kind == forgemon::alert::AlertKind::DieLife => Some((a.blow, a.reason)),
            _ => None,
        })
        .collect()
}

/// Three billets, the first forged as `[part]` says, the next two each given its part id at
/// its start (as `POST /billet` would), the third on another die set. `[die_life]` warns at
/// 3 blows and stops at 5: die set D-1 (6 blows) reaches both, D-2 (3 blows) its warning.
#[test]
fn part_ids_and_die_sets_reach_the_rows_the_recording_a_replay_the_rebuild_and_die_life() {
    let dir = temp("parts");
    let rec = dir.join("rec");
    let first = Trace { part_id: Some("P-0001".into()), lot: Some("L-9".into()), die_set: Some("D-1".into()) };
    let life = DieLifeConfig { warn_blows: Some(3), limit_blows: Some(5), ..DieLifeConfig::default() };
    forge(&rec, first.clone(), life, 3, |billet| TraceUpdate {
        part_id: Some(Some(format!("P-{billet:04}"))),
        die_set: (billet == 3).then(|| Some("D-2".to_string())),
        ..TraceUpdate::default()
    });

    let expect = |billet: u64| -> (String, String, String) {
        let part = format!("P-{billet:04}");
        (part, "L-9".into(), if billet == 3 { "D-2" } else { "D-1" }.into())
    };
    let as_triple = |r: &Value| {
        let s = |k: &str| r[k].as_str().unwrap_or("-").to_string();
        (s("part_id"), s("lot"), s("die_set"))
    };
    let live = dump(&rec.join("history.sqlite"));
    let blows = rows(&live, "blows");
    assert_eq!(blows.len(), 9, "3 billets of 3 blows");
    for b in blows {
        assert_eq!(as_triple(b), expect(b["billet"].as_u64().unwrap()), "{b}");
    }
    let billets = rows(&live, "billets");
    assert_eq!(billets.len(), 3);
    for b in billets {
        assert_eq!(as_triple(b), expect(b["billet"].as_u64().unwrap()), "{b}");
    }
    // The recording's `/billets` carry the same (the history took them from there).
    let recording = common::first_recording(&rec);
    let summaries: Vec<Trace> = read_recording(&recording)
        .unwrap()
        .messages
        .into_iter()
        .filter_map(|m| match m.payload {
            Payload::Billet(b) => Some(b.trace),
            _ => None,
        })
        .collect();
    let want: Vec<Trace> = (1..=3)
        .map(|n| {
            let (p, l, d) = expect(n);
            Trace { part_id: Some(p), lot: Some(l), die_set: Some(d) }
        })
        .collect();
    assert_eq!(summaries, want);
    assert_eq!(summaries[0], first);
    // A replay takes the recorded traces where the live run took them.
    let out = ok(forgemon(&["replay", path_str(&recording)]));
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with("billet ")).collect();
    assert_eq!(lines.len(), 3, "a summary line per billet: {text}");
    for (n, line) in (1..=3).zip(&lines) {
        let (p, l, d) = expect(n);
        assert!(line.starts_with(&format!("billet {n} part {p} lot {l} die set {d}")), "{line}");
    }
    // And the rebuild is the live database, die sets included.
    let rebuilt = dir.join("rebuilt.sqlite");
    ok(forgemon(&["history", "rebuild", path_str(&rec), "--db", path_str(&rebuilt)]));
    assert_eq!(dump(&rebuilt), live);

    // Die life: each die set's blows, hard blows and the energy its dies took (elastic plus
    // damped of its blows' rows).
    let dies = rows(&live, "die_sets");
    assert_eq!(dies.len(), 2, "{dies:?}");
    for d in dies {
        let name = d["die_set"].as_str().unwrap();
        let on: Vec<&Value> = blows.iter().filter(|b| b["die_set"] == name).collect();
        let energy: f64 = on.iter().filter_map(|b| Some(b["elastic_J"].as_f64()? + b["damped_J"].as_f64()?)).sum();
        let without = on.iter().filter(|b| b["elastic_J"].is_null()).count();
        let hard = on.iter().filter(|b| b["class"] == "hard").count();
        assert_eq!(d["blows"].as_u64(), Some(on.len() as u64), "{d}");
        assert_eq!(d["blows_without_energy"].as_u64(), Some(without as u64), "{d}");
        assert_eq!(d["hard_blows"].as_u64(), Some(hard as u64), "{d}");
        assert!((d["energy_J"].as_f64().unwrap() - energy).abs() < 1e-9 * energy, "{d}: {energy}");
    }
    // The alerts: D-1's warning at its 3rd blow and limit at its 5th, D-2's warning at its
    // 3rd (the run's 9th).
    let alerts = die_alerts(std::slice::from_ref(&recording));
    let at: Vec<u32> = alerts.iter().map(|a| a.0).collect();
    assert_eq!(at, [3, 5, 9], "{alerts:?}");
    assert!(alerts[0].1.starts_with("die set D-1 has reached its warning"), "{}", alerts[0].1);
    assert!(alerts[1].1.starts_with("die set D-1 has reached its limit"), "{}", alerts[1].1);
    assert!(alerts[2].1.starts_with("die set D-2 has reached its warning"), "{}", alerts[2].1);

    // A restart takes D-2 up where the database left it: 3 blows more reach its limit (5)
    // at the new run's 2nd blow, where a count from zero would not.
    let before: std::collections::BTreeSet<PathBuf> = common::files_in(&rec).into_iter().collect();
    let d2 = Trace { die_set: Some("D-2".into()), ..Trace::default() };
    forge(&rec, d2, life, 1, |_| TraceUpdate::default());
    let new: Vec<PathBuf> = common::files_in(&rec)
        .into_iter()
        .filter(|f| !before.contains(f) && f.extension().is_some_and(|x| x == "mcap"))
        .collect();
    let alerts = die_alerts(&new);
    assert_eq!(alerts.len(), 1, "{alerts:?}");
    assert_eq!(alerts[0].0, 2, "{alerts:?}");
    let words = &alerts[0].1;
    assert!(words.starts_with("die set D-2 has reached its limit") && words.contains("(5 blows taken"), "{words}");
    let after = dump(&rec.join("history.sqlite"));
    let d2: Vec<&Value> = rows(&after, "die_sets").iter().filter(|d| d["die_set"] == "D-2").collect();
    assert_eq!(d2.len(), 1, "one installation of D-2: no die change");
    assert_eq!(d2[0]["blows"].as_u64(), Some(6));
}

#[test]
fn post_billet_takes_a_json_body_and_refuses_a_bad_one_naming_its_key() {
    let dir = temp("post");
    let http = common::free_port();
    let cfg = common::service_toml(&dir, http, "", "[part]\nlot = \"4711\"\n");
    let _svc = common::KillOnDrop(common::spawn_service(&cfg, http));
    let status = || -> Value { serde_json::from_str(&common::http_get(http, "/status").unwrap()).unwrap() };
    let wait = |what: &str, done: &dyn Fn(&Value) -> bool| {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
        while !done(&status()) {
            assert!(std::time::Instant::now() < deadline, "{what}: {}", status());
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    };
    wait("[part] in force", &|s| s["part"] == serde_json::json!({"lot": "4711"}));
    let (code, body) = common::http_send(http, "POST", "/billet", br#"{"part_id": "P-0042", "die_set": "17"}"#);
    assert_eq!(code, 202, "{body}");
    wait("the new billet's", &|s| {
        s["part"] == serde_json::json!({"part_id": "P-0042", "lot": "4711", "die_set": "17"})
    });
    for (bad, key) in [(&br#"{"lot": 4711}"#[..], "lot"), (br#"{"die": "17"}"#, "die"), (b"part 7", "not JSON")] {
        let (code, body) = common::http_send(http, "POST", "/billet", bad);
        assert_eq!(code, 400, "{body}");
        assert!(body.contains(key), "{body}");
    }
    // An empty body is the plain signal, as before.
    assert_eq!(common::http_send(http, "POST", "/billet", b"").0, 202);
    // A die change: the new set from zero, under its name.
    let (code, body) = common::http_send(http, "POST", "/die", br#"{"die_set": "18"}"#);
    assert_eq!(code, 202, "{body}");
    wait("the new die set", &|s| s["die_life"]["die_set"] == "18" && s["part"]["die_set"] == "18");
    assert_eq!(status()["die_life"]["blows"], 0);
    assert_eq!(common::http_send(http, "POST", "/die", br#"{"die": "18"}"#).0, 400);
    wait("the history's counters", &|s| s["history"].is_object());
    let st = status();
    assert_eq!(st["history"]["path"].as_str(), Some(path_str(&dir.join("rec/history.sqlite"))), "{st}");
    assert_eq!(st["history"]["dropped"], 0, "{st}");
}

/// The drift alarms' reference survives a restart (issue 44): a first run learns it from 10
/// good billets and records it; the history keeps it; a second run resumes it at its start
/// (recorded again, the same text) instead of learning anew, and learns nothing itself.
#[test]
fn the_drift_reference_learnt_in_one_run_is_resumed_by_the_next() {
    let dir = temp("drift");
    let rec = dir.join("rec");
    let drift = forgemon::config::history::DriftConfig { learn_billets: 10, ..Default::default() };
    let with_drift = move |c: ServiceConfig| ServiceConfig { drift: Some(drift), ..c };
    forge_with(&rec, with_drift, 12, |_| TraceUpdate::default());
    let references = |files: &[PathBuf]| -> Vec<(i64, String)> {
        files
            .iter()
            .flat_map(|f| read_recording(f).unwrap().messages)
            .filter_map(|m| match m.payload {
                Payload::Config(c) if c.name == forgemon::alert::drift::REFERENCE_CONFIG_NAME => {
                    Some((m.log_time_ns, c.text))
                }
                _ => None,
            })
            .collect()
    };
    let first_run = common::recordings_in(&rec);
    let learnt = references(&first_run);
    assert_eq!(learnt.len(), 1, "learnt once, after the tenth good billet");
    let reference: forgemon::alert::drift::Reference = serde_json::from_str(&learnt[0].1).expect("a reference");
    assert_eq!(reference.learn_billets, 10);
    assert!(!reference.blows.is_empty());
    let kept = dump(&rec.join("history.sqlite"));
    assert_eq!(rows(&kept, "drift_references").len(), 1, "the history keeps it");

    forge_with(&rec, with_drift, 2, |_| TraceUpdate::default());
    let second_run: Vec<PathBuf> = common::recordings_in(&rec).into_iter().filter(|f| !first_run.contains(f)).collect();
    assert!(!second_run.is_empty());
    let resumed = references(&second_run);
    assert_eq!(resumed.len(), 1, "recorded once, at the start: {resumed:?}");
    assert_eq!(resumed[0].1, learnt[0].1, "the same reference");
    assert_eq!(rows(&dump(&rec.join("history.sqlite")), "drift_references").len(), 1, "still one reference");
}
