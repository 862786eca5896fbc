//! The PLC result image (CONTRACTS.md §8, issue 19 §2) at the process boundary: a real
//! `forgemon demo --plc ADDR` run in real time, read by an independent Modbus client
//! (`tests/python/plc_client.py`, pymodbus) as a PLC would. Every image it read must show
//! the blow results the demo recorded (read back from its MCAP recording, another path than
//! the image's encoder) within each register's unit; the heartbeat must advance once a
//! second; coil 0 must clear the alert-latched bit and coil 1 count one more billet; writes,
//! other addresses and another unit id are refused with Modbus exceptions, and a client that
//! sent garbage does not stop the server. CI installs pymodbus (`.ci/run`); elsewhere the
//! test fails saying how.

use std::io::{BufRead, BufReader};
use std::net::TcpListener;
use std::path::Path;
use std::process::{Command, Stdio};

use forgemon::estimate::{BlowClass, BlowEstimate};
use forgemon::record::{Payload, read_recording};
use serde_json::Value;

const INSTALL: &str = "python3 -m pip install pymodbus";

/// A free loopback port (closed again, for the demo to take).
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).expect("a free port").port()
}

fn words(v: &Value) -> Vec<u32> {
    v.as_array().expect("registers").iter().map(|w| w.as_u64().expect("a word") as u32).collect()
}

fn u32_at(w: &[u32], at: usize) -> u32 {
    (w[at] << 16) | w[at + 1]
}

/// `register` shows `value` in units of `unit`: within half a unit of it (the rounding),
/// with 1e-6 of a unit for the float arithmetic.
fn shows(register: u32, value: f64, unit: f64, what: &str, blow: u32) {
    let scaled = value / unit;
    assert!(
        (f64::from(register) - scaled).abs() <= 0.5 + 1e-6,
        "blow {blow}: {what} register {register}, result {scaled}"
    );
}

fn class_code(c: BlowClass) -> u32 {
    match c {
        BlowClass::Soft => 1,
        BlowClass::Intermediate => 2,
        BlowClass::Hard => 3,
        BlowClass::Incomplete => 4,
        BlowClass::Implausible => 5,
    }
}

/// Registers 6–19 against the blow's recorded result.
fn assert_image_shows(w: &[u32], r: &BlowEstimate) {
    let b = r.blow;
    assert_eq!(w[6], class_code(r.class), "blow {b}: class");
    shows(w[7], r.efficiency.unwrap_or(0.0), 1e-4, "efficiency", b);
    shows(u32_at(w, 8), r.plastic_j.unwrap_or(0.0), 1.0, "plastic J", b);
    shows(u32_at(w, 10), r.kinetic_in_j.unwrap_or(0.0), 1.0, "kinetic J", b);
    shows(w[12], r.v_impact_mps, 1e-3, "impact mm/s", b);
    shows(u32_at(w, 13), r.peak_load_n, 100.0, "peak load 100 N", b);
    shows(w[15], r.h_end_m.unwrap_or(0.0), 1e-5, "height 0.01 mm", b);
    assert_eq!(w[1] & (1 << 4) != 0, r.class == BlowClass::Incomplete, "blow {b}: incomplete bit");
    // No recipe, no advisor yet (issue 20): "no recipe", "unknown", "none", and never NOK.
    assert_eq!((w[16], w[17], u32_at(w, 18)), (0, 0xFFFF, 0), "blow {b}: judgement and advisor");
    assert_eq!(w[1] & (1 << 3), 0, "blow {b}: NOK without a recipe");
}

#[test]
fn a_pymodbus_client_reads_the_demo_results_and_its_coils_act() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (plc, http) = (free_port(), free_port());
    let plc_addr = format!("127.0.0.1:{plc}");
    // Real time (the client reads each blow as a PLC would): 2 billets of 8 blows, 0.25 s
    // apart, about 5 s.
    let mut demo = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["demo", "--billets", "2", "--interval", "0.25", "--plc", &plc_addr])
        .args(["--http", &format!("127.0.0.1:{http}"), "--dir"])
        .arg(dir.path().join("rec"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the demo");
    let mut stdout = BufReader::new(demo.stdout.take().expect("stdout"));
    let mut banner = String::new();
    while !banner.contains("PLC result image") {
        let mut line = String::new();
        if stdout.read_line(&mut line).expect("the demo's stdout") == 0 {
            panic!("the demo stopped before serving the PLC image:\n{banner}");
        }
        banner.push_str(&line);
    }
    assert!(banner.contains(&format!("PLC result image (Modbus TCP, unit 1) on {plc_addr}")), "{banner}");

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/plc_client.py");
    let client = Command::new("python3")
        .arg(&script)
        .args([plc_addr.as_str(), "30"])
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e}): install Python 3, then `{INSTALL}`"));
    let demo_out = demo.wait_with_output().expect("the demo ends");
    let stderr = String::from_utf8_lossy(&client.stderr);
    match client.status.code() {
        Some(0) => {}
        Some(3) => panic!("pymodbus is missing: run `{INSTALL}`\n{stderr}"),
        _ => panic!("plc_client.py failed ({}):\n{stderr}", client.status),
    }
    assert!(demo_out.status.success(), "demo: {}", String::from_utf8_lossy(&demo_out.stderr));
    let seen: Value = serde_json::from_slice(&client.stdout).expect("the client's JSON");

    // The demo's results as it recorded them.
    let file = std::fs::read_dir(dir.path().join("rec"))
        .expect("the recording directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .expect("a finished recording");
    let results: Vec<BlowEstimate> = read_recording(&file)
        .expect("the recording reads")
        .messages
        .into_iter()
        .filter_map(|m| if let Payload::Result(r) = m.payload { Some(*r) } else { None })
        .collect();
    assert_eq!(results.len(), 16, "two billets of eight blows");

    // Refusals (Modbus exception codes): 1 illegal function, 2 illegal data address, 11
    // gateway target device failed to respond (unit 2 does not exist).
    let refused = &seen["refused"];
    for (what, code) in [
        ("write_register", 1),
        ("write_registers", 1),
        ("read_input", 1),
        ("read_coils", 1),
        ("read_past_end", 2),
        ("write_coil_2", 2),
        ("other_unit", 11),
    ] {
        assert_eq!(refused[what], code, "{what}: {refused}");
    }

    // Every image read shows the result of the blow its counter names.
    let images: Vec<Vec<u32>> = seen["images"].as_array().expect("images").iter().map(words).collect();
    let ack = &seen["ack"];
    let ack_at = ack["images_before"].as_u64().expect("the alert was latched and acknowledged") as usize;
    let acked_blows = u32_at(&words(&ack["before"]), 2);
    let mut blows_seen = Vec::new();
    for (i, w) in images.iter().enumerate() {
        assert_eq!(w.len(), 20);
        assert_eq!(w[1] & 1, 1, "running");
        let n = u32_at(w, 2);
        if n == 0 {
            assert_eq!(w[6], 0, "no blow yet: class 0");
            continue;
        }
        let r = results.iter().find(|r| r.blow == n).unwrap_or_else(|| panic!("no result for blow {n}"));
        assert_image_shows(w, r);
        assert_eq!(w[1] & 2, 2, "blow {n}: the demo's one source is connected");
        // Billets: the blow's own billet until coil 1 added one.
        let billets = u32_at(w, 4);
        assert!(billets == r.billet.billet || billets == r.billet.billet + 1, "blow {n}: billets {billets}");
        // Latched: an alert at or before this blow, after the acknowledgement if this image
        // was read after it.
        let since = if i >= ack_at { acked_blows } else { 0 };
        let alerted = |kind: Option<&str>| {
            results.iter().any(|x| {
                x.blow > since
                    && x.blow <= n
                    && x.alert.as_ref().is_some_and(|a| kind.is_none_or(|k| a.kind.as_str() == k))
            })
        };
        assert_eq!(w[1] & 4 != 0, alerted(None), "blow {n}: alert latched bit");
        assert_eq!(w[1] & 32 != 0, alerted(Some("model_health")), "blow {n}: model health bit");
        assert_eq!(w[1] & 64 != 0, alerted(Some("sensor")), "blow {n}: sensor bit");
        blows_seen.push(n);
    }
    blows_seen.dedup();
    assert!(blows_seen.len() >= 8, "the client saw at least half the blows: {blows_seen:?}");
    assert_eq!(blows_seen.last(), Some(&16), "the last image shows the last blow");

    // Coil 0 cleared the latched alert; coil 1 counted a new billet.
    assert_eq!(ack["written"], true);
    let (before, after) = (words(&ack["before"]), words(&ack["after"]));
    assert_eq!(before[1] & 4, 4, "latched before");
    assert!(after[1] & 4 == 0 || u32_at(&after, 2) > u32_at(&before, 2), "coil 0 cleared the bit: {after:?}");
    let billet = &seen["billet"];
    assert_eq!(billet["written"], true);
    let (before, after) = (words(&billet["before"]), words(&billet["after"]));
    assert!(u32_at(&after, 4) > u32_at(&before, 4), "coil 1: billets {before:?} -> {after:?}");

    // The heartbeat counts seconds: over the run it advanced by the seconds elapsed, within
    // one count at each end (the client reads at any phase of the 1 s tick) and 0.5 s of
    // scheduling on a loaded machine.
    let hb = seen["heartbeats"].as_array().expect("heartbeats");
    let (first, last) = (&hb[0], &hb[hb.len() - 1]);
    let elapsed_s = last[0].as_f64().unwrap_or(0.0) - first[0].as_f64().unwrap_or(0.0);
    let counted = f64::from((last[1].as_u64().unwrap_or(0) as u16).wrapping_sub(first[1].as_u64().unwrap_or(0) as u16));
    assert!(elapsed_s >= 2.0, "the client read for {elapsed_s} s");
    assert!((counted - elapsed_s).abs() <= 1.5, "heartbeat +{counted} over {elapsed_s:.2} s");
}
