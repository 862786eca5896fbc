//! The Foxglove live view against an independent client (issue 19 §3): `forgemon demo
//! --foxglove` runs the service on a simulated hammer, and `tests/python/foxglove_client.py`
//! (the `websockets` and `protobuf` packages, nothing of ours) speaks
//! `foxglove.websocket.v1` to it: it subscribes to `/results` and the samples, and decodes
//! them with the schema the server advertised. What it decodes must be what the demo printed
//! and recorded, exactly. CI installs the packages (`.ci/run`); elsewhere the test fails
//! saying how.

use std::path::Path;
use std::process::{Command, Stdio};

use forgemon::record::{Payload, Recorded, read_recording};
use serde_json::Value;

const INSTALL: &str = "python3 -m pip install websockets protobuf";

fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind a free port");
    l.local_addr().expect("address").port()
}

/// Every message of every file the demo recorded in `dir`.
fn recorded(dir: &Path) -> Vec<Recorded> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .expect("the demo's recording directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    files.sort();
    files.iter().flat_map(|f| read_recording(f).expect("the demo's recording reads").messages).collect()
}

/// A double the client printed as its shortest round-trip text (`repr`), parsed exactly.
fn num(v: &Value, key: &str) -> f64 {
    v[key].as_str().and_then(|s| s.parse().ok()).unwrap_or_else(|| panic!("{key}: not a number in {v}"))
}

#[test]
fn a_python_foxglove_client_decodes_the_demos_blows_as_printed_and_recorded() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec");
    let addr = format!("127.0.0.1:{}", free_port());
    let demo = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["demo", "--billets", "1", "--interval", "0.4", "--foxglove", &addr, "--dir"])
        .arg(&rec)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the demo");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/foxglove_client.py");
    // Two results: the demo forges 8 blows, one every 0.4 s, so the client has until the
    // 7th (about 2.8 s) to start, connect and subscribe.
    let client = Command::new("python3").arg(&script).arg(format!("ws://{addr}")).args(["2", "60"]).output();
    let demo = demo.wait_with_output().expect("the demo runs");
    let stdout = String::from_utf8_lossy(&demo.stdout);
    assert!(demo.status.success(), "the demo failed:\n{stdout}\n{}", String::from_utf8_lossy(&demo.stderr));
    let client = client.unwrap_or_else(|e| panic!("cannot run python3 ({e}): install Python 3, then `{INSTALL}`"));
    let stderr = String::from_utf8_lossy(&client.stderr);
    match client.status.code() {
        Some(0) => {}
        Some(3) => panic!("the Python packages are missing: run `{INSTALL}`\n{stderr}"),
        _ => panic!("foxglove_client.py failed ({}):\n{stderr}\ndemo:\n{stdout}", client.status),
    }
    let got: Value = serde_json::from_slice(&client.stdout).expect("foxglove_client.py prints JSON");
    assert_eq!(got["subprotocol"], "foxglove.websocket.v1");
    assert!(got["server_info"]["name"].as_str().is_some_and(|n| n.starts_with("forgemon")), "{}", got["server_info"]);

    // The recording's channels, each with its protobuf schema.
    let channels = &got["channels"];
    for (topic, schema) in [
        ("/results", "forgemon.BlowResult"),
        ("/blows", "forgemon.BlowBoundary"),
        ("/alerts", "forgemon.Alert"),
        ("/billets", "forgemon.BilletSummary"),
        ("/samples/daq", "forgemon.SampleBatch"),
    ] {
        assert_eq!(channels[topic]["schemaName"], schema, "{topic}: {channels}");
        assert_eq!(channels[topic]["encoding"], "protobuf");
        assert_eq!(channels[topic]["schemaEncoding"], "protobuf");
    }

    let messages = recorded(&rec);
    let results = got["results"].as_array().cloned().unwrap_or_default();
    assert_eq!(results.len(), 2);
    for r in &results {
        let m = &r["message"];
        let blow = m["blow"].as_u64().expect("a blow number") as u32;
        // Exactly the recorded result of the same blow, logged at the same time.
        let (log_time_ns, e) = messages
            .iter()
            .find_map(|rm| match &rm.payload {
                Payload::Result(e) if e.blow == blow => Some((rm.log_time_ns, e)),
                _ => None,
            })
            .unwrap_or_else(|| panic!("blow {blow} is not in the recording"));
        assert_eq!(r["log_time_ns"].as_i64(), Some(log_time_ns), "blow {blow}");
        assert_eq!(num(m, "t_contact_s"), e.t_contact_s, "blow {blow}");
        assert_eq!(num(m, "v_impact_mps"), e.v_impact_mps, "blow {blow}");
        assert_eq!(Some(num(m, "kinetic_in_J")), e.kinetic_in_j, "blow {blow}");
        assert_eq!(Some(num(m, "plastic_J")), e.plastic_j, "blow {blow}");
        assert_eq!(Some(num(m, "efficiency")), e.efficiency, "blow {blow}");
        assert_eq!(num(m, "peak_load_N"), e.peak_load_n, "blow {blow}");
        assert_eq!(m["class"], e.class.as_str(), "blow {blow}");
        assert_eq!(m["billet"].as_u64(), Some(u64::from(e.billet.billet)), "blow {blow}");
        // And what the demo printed for it: blow, billet, impact m/s, plastic J, ..., class.
        let line = stdout
            .lines()
            .map(|l| l.split_whitespace().collect::<Vec<_>>())
            .find(|w| w.len() >= 7 && w[0] == blow.to_string())
            .unwrap_or_else(|| panic!("blow {blow} not printed:\n{stdout}"));
        let shown = [
            format!("{}", m["billet"]),
            format!("{:.2}", num(m, "v_impact_mps")),
            format!("{:.0}", num(m, "plastic_J")),
        ];
        assert_eq!(line[1..4], shown, "blow {blow}: {line:?}");
        assert_eq!(line[line.len() - 2..], [format!("{:.2}", num(m, "efficiency")), e.class.as_str().to_string()]);
    }

    // The raw curves: a sample batch decodes to the recorded one with the same sequence number.
    let samples = got["samples"].as_array().cloned().unwrap_or_default();
    assert!(!samples.is_empty());
    for s in &samples {
        let m = &s["message"];
        let seq: u64 = m["seq"].as_str().and_then(|x| x.parse().ok()).expect("seq (an int64 as a string)");
        let b = messages
            .iter()
            .find_map(|rm| match &rm.payload {
                Payload::Samples(b) if b.seq == seq => Some(b),
                _ => None,
            })
            .unwrap_or_else(|| panic!("batch {seq} is not in the recording"));
        assert_eq!(m["roles"], serde_json::json!(["ROLE_LOAD_N", "ROLE_DISP_M", "ROLE_ACC_MPS2"]));
        assert_eq!(num(m, "period_ns"), b.period_ns);
        assert_eq!(m["values_len"].as_u64(), Some(b.values.len() as u64));
        let ends: Vec<f64> = m["values_first_last"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|x| x.as_str().and_then(|s| s.parse().ok()))
            .collect();
        assert_eq!(ends, [b.values[0], b.values[b.values.len() - 1]], "batch {seq}");
    }
    assert!(got["status"].as_array().is_some_and(Vec::is_empty), "no warnings or errors: {}", got["status"]);
}
