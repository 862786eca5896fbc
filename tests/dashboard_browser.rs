//! The dashboard in a real browser (issue 19, face 1): `forgemon demo --http` serves it, and
//! headless Chromium (Debian's `chromium`, driven over the DevTools protocol by
//! `tests/python/dashboard_cdp.py`) loads it while the demo forges. The page must show blow
//! 1's row with the number, efficiency and class the demo printed for it (its console line, a
//! code path apart from the page's JSON and script), take a row live (a blow after the page
//! loaded, without a reload), draw the blow's measured and model curves, show the latched
//! alert and, after its Acknowledge button, the acknowledged state, which `/status` confirms.
//! The alert's whole reason, which the panel's three lines cut, is the reason's title and
//! opens over the page on a click. Each source's rate is the one measured, on every render from
//! the first. The time column is the time of day in the browser's zone (the plant PC's), run
//! here in Asia/Kathmandu (UTC+5:45). It saves `target/dashboard.png`, the README's screenshot
//! (`docs/dashboard.png`). A second test stops the service under an open page and starts
//! another: the header and the sources table agree the link is gone (not "reconnecting…" over
//! "connected"), and the page reconnects by itself.
//! CI installs Chromium and `websockets` (`.ci/run`); elsewhere the test fails saying how.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use serde_json::Value;

const INSTALL: &str = "apt-get install chromium; python3 -m pip install websockets";

fn chromium() -> String {
    ["chromium", "chromium-browser"]
        .into_iter()
        .find(|c| Command::new(c).arg("--version").output().is_ok_and(|o| o.status.success()))
        .unwrap_or_else(|| panic!("no chromium or chromium-browser on PATH ({INSTALL})"))
        .to_string()
}

#[test]
fn the_page_shows_the_first_blow_live_and_the_acknowledged_alert() {
    let browser = chromium();
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let dir = std::env::temp_dir().join(format!("forgemon-dashboard-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    // Real time, blows 0.5 s apart: the page opens (about 2 s for Chromium) before blow 8,
    // whose alert stays latched for 4 s, until blow 16 raises the next.
    let mut demo = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["demo", "--billets", "2", "--interval", "0.5", "--http", &format!("127.0.0.1:{port}")])
        .args(["--target", "0.03"])
        .args(["--dir", dir.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let (tx, rx) = mpsc::channel();
    let stdout = demo.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let url = loop {
        let line = rx.recv_timeout(Duration::from_secs(20)).expect("the demo prints its dashboard's URL");
        if let Some(u) = line.trim().strip_prefix("dashboard on ") {
            break u.to_string();
        }
    };
    assert_eq!(url, format!("http://127.0.0.1:{port}/"));
    let shot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/dashboard.png");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/dashboard_cdp.py");
    let out = Command::new("python3").args([script, &browser, &url, shot.to_str().unwrap()]).output().unwrap();
    let demo_lines: Vec<String> = rx.try_iter().collect();
    let _ = demo.kill();
    let _ = demo.wait();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        out.status.success(),
        "the browser session failed ({INSTALL}):\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value = serde_json::from_slice(&out.stdout).unwrap();

    // Blow 1 as the demo printed it: "   1       1        3.90       5319  [###..] 0.93  soft".
    let printed: Vec<&str> = demo_lines
        .iter()
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .find(|w| w.first() == Some(&"1") && w.get(1) == Some(&"1"))
        .map(|w| vec![w[0], w[w.len() - 2], w[w.len() - 1]])
        .expect("the demo printed blow 1");
    let row: Vec<&str> = seen["first_row"].as_array().unwrap().iter().map(|c| c.as_str().unwrap()).collect();
    // Columns: billet, blow, ..., efficiency (10th), ..., class (13th), recipe (empty: the
    // demo runs without one), alert.
    assert_eq!(row.len(), 15, "{row:?}");
    assert_eq!(row[13], "", "no recipe, no judgement");
    assert_eq!(row[1], printed[0], "blow number");
    let (page_eff, demo_eff): (f64, f64) = (row[9].parse().unwrap(), printed[1].parse().unwrap());
    // The page shows 3 decimals, the demo 2: they agree within the demo's rounding.
    assert!((page_eff - demo_eff).abs() <= 0.005 + 1e-9, "efficiency {page_eff} on the page, {demo_eff} printed");
    assert_eq!(row[12], printed[2], "class");

    // The die set in the hammer (issue 44): the demo gives none, so "–", with its blows as
    // /status counts them (the page may have moved on by a blow since).
    let dies = &seen["dies"];
    let shown = dies["shown"].as_str().unwrap();
    let counted: u64 = shown.strip_prefix("– · ").and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("{dies}"));
    let at_status = dies["status_blows"].as_u64().unwrap();
    assert!(counted == at_status || counted == at_status + 1, "{dies}");
    assert_eq!(at_status, dies["blows"].as_u64().unwrap(), "one die set since the start: {dies}");

    // The page opened before the blows it then showed arrived (the live feed did it).
    assert!(seen["blows_at_load"].as_u64().unwrap() < 8, "{seen}");
    // The curve of the alerting blow: measured and fitted model (the demo's hammer at
    // 100 kHz is fitted, `estimate::OBSERVER_MIN_SAMPLES_PER_MODE`), each decimated to at
    // most 2 points a bucket (`estimate::curve::CURVE_BUCKETS` = 300).
    let c: Vec<u64> = seen["curve"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    assert!(c[1] > 100 && c[1] <= 600 && c[2] > 100 && c[2] <= 600, "curve points {c:?}");

    // The alert the first billet's hard blow raised, then acknowledged with the button.
    let before = &seen["alert_before"];
    assert!(before["cls"].as_str().unwrap().contains("latched"), "{before}");
    assert!(before["kind"].as_str().unwrap().starts_with("elastic_blow"), "{before}");
    assert_eq!(before["button_hidden"], false);
    // The live advisor (`--target 0.03`) shows its plan, or why there is none, for 30 mm.
    let advice = &seen["advice"];
    assert_eq!(advice["hidden"], false, "{advice}");
    assert!(advice["text"].as_str().unwrap().contains("30.0 mm"), "{advice}");
    // The last blow's sensing mode (issue 43): the demo's DAQ has all three channels; its
    // efficiency carries its 1σ in the title.
    let sensors = &seen["sensors"];
    assert_eq!(sensors["text"], "load + acc + disp", "{sensors}");
    assert!(sensors["sd"].as_str().unwrap().starts_with("± "), "{sensors}");
    let after = &seen["alert_after"];
    assert!(after["cls"].as_str().unwrap().contains("acked"), "{after}");
    assert!(after["kind"].as_str().unwrap().starts_with("acknowledged: elastic_blow"), "{after}");
    assert_eq!(after["button_hidden"], true);
    assert!(seen["status_latched_alert"].is_null(), "/status still latches {}", seen["status_latched_alert"]);

    // The alert's reason: cut by the panel, whole in its title and, clicked, over the page.
    let (cut, open) = (&seen["reason_before"], &seen["reason_open"]);
    let reason = seen["latched_reason"].as_str().unwrap();
    assert_eq!(cut["text"], reason, "{cut}");
    assert_eq!(cut["title"], reason, "{cut}");
    assert_eq!(cut["cut"], true, "the demo's elastic_blow reason is longer than the panel: {cut}");
    assert_eq!(
        (&open["cut"], &open["on_top"], &open["inside"]),
        (&Value::Bool(false), &Value::Bool(true), &Value::Bool(true)),
        "{open}"
    );
    assert_eq!(open["expanded"], "true");

    // The rate: a measured figure on every render from the first, within a factor of 2 of the
    // rate /status's sample count grew at over the same 2 s. Not closer: the page's figure is
    // the service's over its last 3 s, and on a loaded machine the simulated device delivers
    // in bursts (seen while the whole suite ran: 82 kHz on the page, 130 kHz from /status).
    let status_hz = seen["rate_status_hz"].as_f64().unwrap();
    let rates: Vec<&str> = seen["rates"].as_array().unwrap().iter().map(|r| r.as_str().unwrap()).collect();
    assert!(rates.len() >= 10, "{rates:?}");
    for r in &rates {
        let hz = match r.split_whitespace().collect::<Vec<_>>()[..] {
            [x, "kHz"] => x.parse::<f64>().unwrap() * 1e3,
            [x, "Hz"] => x.parse::<f64>().unwrap(),
            _ => panic!("rate {r:?} is not a measured rate; all: {rates:?}"),
        };
        assert!((0.5..=2.0).contains(&(hz / status_hz)), "rate {r} on the page, {status_hz:.0} Hz from /status");
    }

    // The time column: the time of day in the page's zone, of first contact, so a little
    // before the row arrived (the blow's post window, the estimate, the fetch): within 10 s,
    // for a loaded machine.
    let row = &seen["live_row"];
    let shown = seen["live_row_time_s"].as_f64().unwrap_or_else(|| panic!("not a time of day: {row}"));
    let arrived = seen["arrived_time_s"].as_f64().unwrap();
    // Seconds the row arrived after the time it shows, across midnight too.
    let before_s = (arrived - shown + 43_200.0).rem_euclid(86_400.0) - 43_200.0;
    assert!((-0.5..10.0).contains(&before_s), "shown {shown} s of the day, arrived at {arrived}: {row}");
    // ICU names the zone by its older spelling, Asia/Katmandu.
    assert!(row["title"].as_str().unwrap().contains("Asia/Kat"), "{row}");
    assert!(std::fs::metadata(&shot).unwrap().len() > 10_000, "a screenshot was saved");
}

/// The page follows a service restart by itself: the demo it opened on stops (the page says
/// so), another starts on the same port, and the page shows the new run's blows (fewer than
/// the first run had: a table fetched again, not kept) without a reload.
#[test]
fn the_page_reconnects_by_itself_after_the_service_restarts() {
    let browser = chromium();
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let dir = tempfile::tempdir().unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/dashboard_cdp.py");
    let out = Command::new("python3")
        .args([script, "--restart", &browser, env!("CARGO_BIN_EXE_forgemon"), &port.to_string()])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "the browser session failed ({INSTALL}):\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value = serde_json::from_slice(&out.stdout).unwrap();
    let before = seen["max_blow_before"].as_u64().unwrap();
    let after = seen["after"]["max_blow"].as_u64().unwrap();
    assert!(before >= 6, "{seen}");
    // The second run (blows 1 s apart) had reached only a few blows when the page came back.
    assert!(after >= 1 && after < before, "{seen}");
    // While the service is gone the header and the sources table say so together: no source
    // shown "connected" under a header that says "reconnecting…"; once back, both say live.
    let (gone, back) = (&seen["gone"], &seen["back"]);
    assert_eq!(gone["conn"], "reconnecting…", "{gone}");
    let states =
        |v: &Value| v["states"].as_array().unwrap().iter().map(|s| s.as_str().unwrap().to_string()).collect::<Vec<_>>();
    assert!(!states(gone).is_empty() && states(gone).iter().all(|s| s == "unknown"), "{gone}");
    assert!(gone["rates"].as_array().unwrap().iter().all(|r| r == "–"), "{gone}");
    assert_eq!(back["conn"], "live", "{back}");
    assert!(!states(back).is_empty() && states(back).iter().all(|s| s == "connected"), "{back}");
    let header: u64 = seen["after"]["header_blows"].as_str().unwrap().parse().unwrap();
    let status = seen["status_blows"].as_u64().unwrap();
    assert!(header == status || header + 1 == status, "header {header} blows, /status {status}");
}

/// The history page (issue 44) with 100 000 blows: a demo makes the database, Python's
/// sqlite3 adds 100 000 synthetic blows on four die sets and twenty lots
/// (`tests/python/fill_history.py`, another code path than the service's writer), and a demo
/// serving it is opened in Chromium. Every die set's and lot's row must show Python's counts
/// and mean efficiency; the die-set filter must narrow it; the I-MR chart of blow 3 must
/// count its blows. The time from navigation to drawn is printed (a figure for the note,
/// not a pass mark: times are for benchmarks). It saves `target/history.png`.
#[test]
fn the_history_page_draws_100000_blows_by_die_set_and_lot() {
    let browser = chromium();
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let dir = std::env::temp_dir().join(format!("forgemon-history-page-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let forgemon = env!("CARGO_BIN_EXE_forgemon");
    let made =
        Command::new(forgemon).args(["demo", "--fast", "--billets", "1", "--dir", dir.to_str().unwrap()]).output();
    assert!(made.unwrap().status.success(), "the first demo makes the database");
    let db = dir.join("history.sqlite");
    let fill = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/fill_history.py");
    let out = Command::new("python3").args([fill, db.to_str().unwrap(), "100000", "7"]).output().unwrap();
    assert!(out.status.success(), "fill_history.py: {}", String::from_utf8_lossy(&out.stderr));
    let want: Value = serde_json::from_slice(&out.stdout).unwrap();

    let mut demo = Command::new(forgemon)
        .args(["demo", "--billets", "6", "--interval", "0.5", "--http", &format!("127.0.0.1:{port}")])
        .args(["--dir", dir.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Its stdout read to the end: a closed pipe would stop the demo.
    let (tx, rx) = mpsc::channel();
    let stdout = demo.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(u) = line.trim().strip_prefix("dashboard on ") {
                let _ = tx.send(u.to_string());
            }
        }
    });
    let url = rx.recv_timeout(Duration::from_secs(20)).expect("the demo prints its dashboard's URL");
    let shot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/history.png");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/dashboard_cdp.py");
    let page = format!("{url}history");
    let out = Command::new("python3").args([script, "--history", &browser, &page, shot.to_str().unwrap()]).output();
    let _ = demo.kill();
    let _ = demo.wait();
    let _ = std::fs::remove_dir_all(&dir);
    let out = out.unwrap();
    assert!(
        out.status.success(),
        "the browser session failed ({INSTALL}):\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((&seen["ready"], &seen["error"]), (&Value::from("1"), &Value::from("")), "{seen}");
    let blows: u64 = seen["blows"].as_str().unwrap().parse().unwrap();
    assert!(blows >= 100_008, "the synthetic blows and the first demo's 8: {blows}");

    // Each die set's and lot's row: name, blows, billets, hard, NOK, mean efficiency (3
    // decimals: within half of the last digit of Python's mean).
    for (table, key) in [("by_die", "die"), ("by_lot", "lot")] {
        let rows = seen[table].as_array().unwrap();
        let groups = want[key].as_object().unwrap();
        for (name, w) in groups {
            let row = rows.iter().find(|r| r[0] == name.as_str()).unwrap_or_else(|| panic!("{table}: no {name}"));
            for (col, field) in [(1, "blows"), (2, "billets"), (3, "hard"), (4, "nok")] {
                assert_eq!(row[col].as_str().unwrap().parse::<u64>().ok(), w[field].as_u64(), "{table} {name} {field}");
            }
            let shown: f64 = row[5].as_str().unwrap().parse().unwrap();
            let mean = w["mean_efficiency"].as_f64().unwrap();
            assert!((shown - mean).abs() <= 0.0005 + 1e-9, "{table} {name}: mean {shown} against {mean}");
        }
        assert_eq!(rows.len(), groups.len() + 1, "{table}: the demo's blows without a die set or lot are one more row");
    }
    assert_eq!(seen["filtered"]["blows"], "20000", "die set D2 only: {}", seen["filtered"]);
    assert_eq!(seen["filtered"]["by_die"].as_array().map(Vec::len), Some(1));
    // Blow 3 of the 12 500 synthetic billets and of the demos' billets.
    let imr = seen["imr_blow_3"].as_str().unwrap();
    let n: u64 = imr.strip_prefix("n ").and_then(|s| s.split(' ').next()).and_then(|s| s.parse().ok()).unwrap();
    assert!((12_501..12_510).contains(&n), "{imr}");
    eprintln!(
        "history page: {blows} blows drawn {:.0} ms after navigation (this load {:.0} ms)",
        seen["load_ms"].as_f64().unwrap_or(f64::NAN),
        seen["drawn"]["ms"].as_f64().unwrap_or(f64::NAN)
    );
}
