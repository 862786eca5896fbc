//! CAN acquisition at the file and socket boundary (issue #4): the committed candump log
//! of a simulated hammer session (`fixtures/can/`), decoded with the committed DBC file,
//! runs through the pipeline and finds every blow as the expected JSON beside it says and
//! as the simulated truth says; the log is what its generator writes; malformed lines
//! and lost frames are reported; the driver reports and retries an interface it cannot
//! open; the live SocketCAN test is ignored unless a vcan interface exists (`.ci/run`).
//!
//! Regenerate the fixtures with
//! `cargo test --test acquire_can -- --ignored regenerate_can_fixtures`.

mod common;

use std::path::Path;

use common::{read, root};

use forgemon::acquire::SourceEvent;
use forgemon::acquire::can::candump::BadLines;
use forgemon::acquire::can::{
    CanDecoder, CanDevice, CanMapping, CanSourceConfig, CanTiming, CandumpReader, DEFAULT_IFACE, DbcNames,
    forgemon_mapping, mapping_from_dbc, read_candump,
};
use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::EffectSet;
use forgemon::physics::machine::Machine;
use forgemon::physics::process::Process;
use forgemon::pipeline::{Pipeline, PipelineConfig};
use forgemon::signal::capture::CaptureRow;
use forgemon::synth::{CaptureSpec, idle_rows, synth_blows};
use serde_json::{Value, json};

const MACHINE: &str = "config/hammer-lg1000.machine.toml";
const PROCESS: &str = "config/steel-16NiCrMo13.process.toml";
const DBC: &str = "fixtures/can/hammer.dbc";
const LOG: &str = "fixtures/can/hammer_blows.log";
const EXPECTED: &str = "fixtures/can/hammer_blows.expected.json";
const REGENERATE: &str = "cargo test --test acquire_can -- --ignored regenerate_can_fixtures";

/// The session: blow 1 of the paper at 3.9 m/s, then two at 5.3 m/s (seed 000 §3.1), at
/// 5 kHz (the module docs: 68 % of a 1 Mbit/s bus), the machine idle between blows.
const V0S_MPS: [f64; 3] = [3.9, 5.3, 5.3];
const SAMPLE_RATE_HZ: f64 = 5000.0;
const IDLE_SAMPLES: usize = 750; // 0.15 s before each blow and after the last
const SEED: u64 = 4004;

fn machine() -> Machine {
    parse_machine(MACHINE, &read(MACHINE)).expect("machine file").machine
}

fn process() -> Process {
    parse_process(PROCESS, &read(PROCESS)).expect("process file")
}

fn spec() -> CaptureSpec {
    CaptureSpec { sample_rate_hz: SAMPLE_RATE_HZ, pre_s: 0.05, post_s: 0.03, ..CaptureSpec::hammer(SEED) }
}

/// The truth of one simulated blow, in the log's clock.
struct Truth {
    v0_mps: f64,
    efficiency: f64,
    t_contact_s: f64,
}

/// The session as one continuous stream of rows, and the truth of each blow.
fn session() -> (Vec<CaptureRow>, Vec<Truth>) {
    let spec = spec();
    let blows = synth_blows(&machine(), &EffectSet::NONE, &process(), &V0S_MPS, &spec).expect("simulate");
    let n_pre = (spec.pre_s * spec.sample_rate_hz).round() as usize;
    let mut rows = Vec::new();
    let mut contact_index = Vec::new();
    for (i, b) in blows.iter().enumerate() {
        rows.extend(idle_rows(IDLE_SAMPLES, 0.0, &spec, b.rows[0].disp_m, SEED + 1 + i as u64));
        contact_index.push(rows.len() + n_pre);
        rows.extend_from_slice(&b.rows);
    }
    let last = rows.last().map_or(0.0, |r| r.disp_m);
    rows.extend(idle_rows(IDLE_SAMPLES, 0.0, &spec, last, SEED + 99));
    // One clock for the whole stream.
    let dt = 1.0 / spec.sample_rate_hz;
    let t0 = spec.t_origin_s;
    for (k, r) in rows.iter_mut().enumerate() {
        r.t_s = t0 + k as f64 * dt;
    }
    let truth = blows
        .iter()
        .zip(contact_index)
        .map(|(b, k)| Truth {
            v0_mps: b.truth.v0_mps,
            efficiency: b.truth.efficiency(),
            t_contact_s: t0 + k as f64 * dt,
        })
        .collect();
    (rows, truth)
}

/// The log the simulated device writes for the session.
fn generate_log() -> (String, Vec<Truth>) {
    let (rows, truth) = session();
    let mut dev = CanDevice::new(forgemon_mapping());
    let mut log = Vec::new();
    dev.write_log(&mut log, DEFAULT_IFACE, &rows).expect("write to memory");
    assert_eq!(dev.saturated, 0, "every value fits its signal");
    (String::from_utf8(log).expect("ASCII"), truth)
}

fn fixture_mapping() -> CanMapping {
    mapping_from_dbc(DBC, &read(DBC), &DbcNames::forgemon()).expect("fixture DBC")
}

fn decoder() -> CanDecoder {
    CanDecoder::new("can", fixture_mapping(), CanTiming::new(SAMPLE_RATE_HZ, 0.05, true))
}

/// Decoded events through the pipeline (`common::blows_through`), each blow as its JSON.
fn run_pipeline(events: &[SourceEvent]) -> Vec<Value> {
    let m = machine();
    let p = Pipeline::new(m, Some(process()), PipelineConfig::for_machine(&m));
    common::blows_through(p, events).iter().map(|e| serde_json::to_value(e).expect("serialise")).collect()
}

fn decode(text: &str, origin: &str, bad: BadLines) -> (Vec<SourceEvent>, CanDecoder) {
    let mut dec = decoder();
    let events = read_candump(&mut CandumpReader::new(origin, text.as_bytes()), &mut dec, bad).expect("decode");
    (events, dec)
}

fn f(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"))
}

/// Numbers equal to 1e-9 relative (the same code on another CPU), the rest exactly.
fn assert_same(got: &Value, want: &Value, at: &str) {
    match (got, want) {
        (Value::Number(a), Value::Number(b)) => {
            let (a, b) = (a.as_f64().unwrap_or(f64::NAN), b.as_f64().unwrap_or(f64::NAN));
            // The estimator's fit ends at a relative cost change of 1e-5 on blows integrated
            // at rtol 1e-5 (`estimate::fit::{COST_RTOL, FIT_RTOL}`): a change of the physics
            // by roundoff moves its optimum within that, so a figure is held to 1e-4 of itself
            // (at least 1e-5, for shares near 0), and an instant to 1 µs (1/200 of a sample at
            // this log's 5 kHz). Folding the plant's laws into one moved them by at most 7.5e-4
            // of a 0.0045 residual share, 2.7e-6 of the final load and 5 ns.
            let tol = if at.ends_with("_s") { 1e-6 } else { (1e-4 * b.abs()).max(1e-5) };
            assert!((a - b).abs() <= tol, "{at}: {a} vs expected {b} (tolerance {tol:e})");
        }
        (Value::Object(a), Value::Object(b)) => {
            assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>(), "{at}: fields");
            for (k, v) in b {
                assert_same(&a[k], v, &format!("{at}.{k}"));
            }
        }
        (Value::Array(a), Value::Array(b)) => {
            assert_eq!(a.len(), b.len(), "{at}: length");
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert_same(x, y, &format!("{at}[{i}]"));
            }
        }
        _ => assert_eq!(got, want, "{at}"),
    }
}

fn expected_json(text: &str, truth: &[Truth]) -> Value {
    let (events, dec) = decode(text, LOG, BadLines::Fail);
    let blows = run_pipeline(&events);
    json!({
        "regenerate": REGENERATE,
        "log": {"lines": text.lines().count(), "frames": dec.counters().frames, "samples": dec.counters().samples,
                "gaps": dec.counters().gaps, "decode_errors": dec.counters().decode_errors,
                "unknown_frames": dec.stats().unknown_frames},
        "truth": truth.iter().enumerate().map(|(i, t)| json!({"blow": i + 1, "v0_mps": t.v0_mps,
                 "efficiency": t.efficiency, "t_contact_s": t.t_contact_s})).collect::<Vec<_>>(),
        "blows": blows,
    })
}

#[test]
#[ignore = "writes fixtures/can/; run to regenerate them"]
fn regenerate_can_fixtures() {
    let (text, truth) = generate_log();
    std::fs::write(root().join(LOG), &text).expect("write log");
    let expected = expected_json(&text, &truth);
    std::fs::write(root().join(EXPECTED), serde_json::to_string_pretty(&expected).expect("json") + "\n")
        .expect("write expected");
    eprintln!("wrote {LOG} ({} bytes) and {EXPECTED}", text.len());
}

#[test]
fn the_fixture_dbc_describes_the_simulated_daq_frame() {
    assert_eq!(fixture_mapping(), forgemon_mapping());
}

#[test]
fn every_blow_of_the_candump_fixture_is_found_as_expected_and_as_simulated() {
    let text = read(LOG);
    assert!(text.len() < 5_000_000);
    let expected: Value = serde_json::from_str(&read(EXPECTED)).expect("expected JSON");
    let (events, dec) = decode(&text, LOG, BadLines::Fail);
    assert_eq!(dec.counters().samples, expected["log"]["samples"].as_u64().unwrap());
    assert_eq!(dec.counters().gaps, 0);
    assert_eq!(dec.counters().decode_errors, 0);
    let found = run_pipeline(&events);
    let at = format!("blows (after an intended change to the pipeline: {REGENERATE})");
    assert_same(&Value::Array(found.clone()), &expected["blows"], &at);
    // Against the simulated truth, with issue #3's tolerances: every blow, impact speed
    // within 1 %, contact within 1 ms; and issue 16's: efficiency within 0.02 of the
    // simulator's ledger, both sides (at the 5 kHz a classic CAN bus carries the estimator
    // fits the machine model; the observer read 0.69 / 0.67 / 0.64 against the true
    // 0.93 / 0.91 / 0.87). This log is point-sampled, without an anti-alias filter.
    let truth = expected["truth"].as_array().unwrap();
    assert_eq!(found.len(), V0S_MPS.len(), "every blow, no extra");
    // The truth is in the log's clock; device time counts from the log's first frame.
    let t_first_s = first_frame_ns(&text) as f64 * 1e-9;
    for (v, t) in found.iter().zip(truth) {
        let b = v["blow"].clone();
        assert!((f(v, "v_impact_mps") / f(t, "v0_mps") - 1.0).abs() < 0.01, "blow {b}: {v} vs {t}");
        assert!((f(v, "t_contact_s") + t_first_s - f(t, "t_contact_s")).abs() < 1e-3, "blow {b}: {v} vs {t}");
        assert!((f(v, "efficiency") - f(t, "efficiency")).abs() <= 0.02, "blow {b}: {v} vs {t}");
    }
}

/// The receive time of a log's first frame, ns.
fn first_frame_ns(text: &str) -> i64 {
    CandumpReader::new(LOG, text.as_bytes()).next_frame().expect("a frame").expect("not empty").t_ns
}

/// The fixture log replayed by the service's CAN log source (`run_log`), at the log's pace
/// or as fast as possible: every event, and the pipeline's blows as JSON text.
async fn replay_log_source(path: &Path, realtime: bool) -> (Vec<SourceEvent>, String) {
    let cfg = CanSourceConfig {
        name: "can".into(),
        iface: LOG.into(),
        mapping: fixture_mapping(),
        timing: CanTiming::new(SAMPLE_RATE_HZ, 0.05, true),
    };
    let (tx, mut rx) = tokio::sync::mpsc::channel(100_000);
    let (_stop, stop_rx) = tokio::sync::watch::channel(false);
    forgemon::acquire::can::run_log(cfg, path.to_path_buf(), realtime, tx, stop_rx).await.expect("log reads");
    let mut events = Vec::new();
    while let Some(e) = rx.recv().await {
        if !matches!(e, SourceEvent::Status(_)) {
            events.push(e);
        }
    }
    let blows = serde_json::to_string(&run_pipeline(&events)).expect("json");
    (events, blows)
}

/// Regression (issue 15, finding 8): the log path kept epoch time (1.7e9 s) in f64, 0.24 µs
/// resolution, and batches were cut at the pace of the replay, so two runs of the same log
/// differed in the 5th digit of the impact speed.
#[tokio::test]
async fn two_replays_of_the_same_candump_log_are_byte_identical() {
    // The fixture's clock starts at 79.96 s; shift it to an epoch time like a real capture.
    let text = read(LOG);
    let shift_us = 1_700_000_000_000_000i64;
    let mut shifted = String::with_capacity(text.len() + 8 * 4400);
    for line in text.lines() {
        let (stamp, rest) = line.split_once(") ").expect("candump -L line");
        let (s, us) = stamp.trim_start_matches('(').split_once('.').expect("sec.usec");
        let t_us = s.parse::<i64>().expect("seconds") * 1_000_000 + us.parse::<i64>().expect("µs") + shift_us;
        shifted.push_str(&format!("({}.{:06}) {rest}\n", t_us / 1_000_000, t_us % 1_000_000));
    }
    assert!(shifted.starts_with("(1700000079.962098) can0 120#"), "{}", &shifted[..40]);
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("epoch.log");
    std::fs::write(&path, &shifted).expect("write log");
    let (events_a, blows_a) = replay_log_source(&path, true).await;
    let (events_b, blows_b) = replay_log_source(&path, true).await;
    let (events_c, blows_c) = replay_log_source(&path, false).await;
    assert_eq!(events_a, events_b, "two paced replays give the same batches");
    assert_eq!(events_a, events_c, "paced or not, the same batches");
    assert_eq!(blows_a, blows_b);
    assert_eq!(blows_a, blows_c);
    // Device time counts from the first frame in integer ns: µs stamps stay exact.
    let SourceEvent::Batch(first) = &events_a[0] else { panic!("{:?}", events_a[0]) };
    assert_eq!((first.device_time_ns, first.host_time_ns), (0, 1_700_000_079_962_098_000));
    // Against the unshifted log: the same blows to the last digit.
    let unshifted = run_pipeline(&decode(&text, LOG, BadLines::Fail).0);
    assert_eq!(blows_a, serde_json::to_string(&unshifted).expect("json"), "the epoch does not change a digit");
    assert_eq!(unshifted.len(), V0S_MPS.len());
}

#[test]
fn the_committed_log_is_what_the_generator_writes() {
    let (text, truth) = generate_log();
    assert!(text == read(LOG), "{LOG} differs from the simulated device's output: regenerate with `{REGENERATE}`");
    let expected: Value = serde_json::from_str(&read(EXPECTED)).expect("expected JSON");
    assert_same(&expected["truth"], &expected_json(&text, &truth)["truth"], "truth");
}

#[test]
fn a_malformed_line_names_the_file_and_line_or_is_counted() {
    let text = read(LOG);
    let mut lines: Vec<&str> = text.lines().collect();
    // Line 100 lies in the idle stretch before the first blow.
    lines[99] = "(79.981800) can0 120#00F";
    let bad = lines.join("\n");
    let mut dec = decoder();
    let err = read_candump(&mut CandumpReader::new(LOG, bad.as_bytes()), &mut dec, BadLines::Fail).unwrap_err();
    let msg = err.to_string();
    assert!(msg.starts_with(&format!("{LOG}:100:")), "{msg}");

    let mut lines: Vec<&str> = text.lines().collect();
    lines[99] = "this is not candump";
    lines[199] = "(79.9818) can0 120#00";
    let bad = lines.join("\n");
    let (events, dec) = decode(&bad, LOG, BadLines::Count);
    assert_eq!(dec.counters().decode_errors, 2);
    // Each lost line is a one-sample gap the counter reveals.
    let lost: Vec<u64> =
        events.iter().filter_map(|e| if let SourceEvent::Gap(g) = e { Some(g.samples_lost) } else { None }).collect();
    assert_eq!(lost, vec![1, 1]);
    assert_eq!(run_pipeline(&events).len(), V0S_MPS.len(), "no blow lost");
}

#[test]
fn frames_lost_from_the_log_are_gaps_of_that_many_samples_and_other_traffic_is_ignored() {
    let text = read(LOG);
    let mut out = String::new();
    for (i, l) in text.lines().enumerate() {
        if (300..303).contains(&i) || (400..700).contains(&i) {
            continue; // 3 lost, then 300 (more than the 8-bit counter's wrap)
        }
        out.push_str(l);
        out.push('\n');
        if i % 50 == 0 {
            out.push_str("(79.000000) can0 7DF#0201000000000000\n(79.000000) can0 120##1AABB\n");
        }
    }
    let (events, dec) = decode(&out, "edited.log", BadLines::Fail);
    let lost: Vec<u64> =
        events.iter().filter_map(|e| if let SourceEvent::Gap(g) = e { Some(g.samples_lost) } else { None }).collect();
    // Past the counter's wrap, the first frame after the outage is only believed once the
    // next one confirms it (a lone frame claiming wraps may be a wild stamp); it is dropped,
    // so the gap counts it too: 300 + 1 samples not delivered.
    assert_eq!(lost, vec![3, 301]);
    assert_eq!(dec.stats().unknown_frames, dec.stats().unsupported_frames);
    assert!(dec.stats().unknown_frames > 0);
    assert_eq!(run_pipeline(&events).len(), V0S_MPS.len(), "the gaps lie before the first blow");
}

/// The live tests' configuration on `FORGEMON_VCAN` (default vcan0).
fn live_config(iface: &str) -> CanSourceConfig {
    CanSourceConfig {
        name: "can".into(),
        iface: iface.to_string(),
        mapping: forgemon_mapping(),
        timing: CanTiming::new(SAMPLE_RATE_HZ, 0.01, true),
    }
}

/// Where the interface cannot be opened (here: a kernel without AF_CAN), the driver says
/// so in its status and keeps retrying with backoff, and stops when told.
#[tokio::test]
async fn an_interface_that_cannot_be_opened_is_reported_and_retried() {
    use std::time::Duration;
    let (tx, mut rx) = tokio::sync::mpsc::channel(1024);
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let task = tokio::spawn(forgemon::acquire::can::run(live_config("forgemon-none0"), tx, stop_rx));
    let first = tokio::time::timeout(Duration::from_secs(5), rx.recv()).await.expect("a status").expect("open");
    let SourceEvent::Status(s) = first else { panic!("{first:?}") };
    assert_eq!(s.state, "reconnecting");
    assert!(s.detail.contains("forgemon-none0"), "{}", s.detail);
    let second = tokio::time::timeout(Duration::from_secs(5), rx.recv()).await.expect("a retry").expect("open");
    assert!(matches!(second, SourceEvent::Status(ref s) if s.state == "reconnecting"), "{second:?}");
    stop_tx.send(true).expect("driver alive");
    tokio::time::timeout(Duration::from_secs(5), task).await.expect("stops when told").expect("no panic");
}

/// Frames sent on a real (virtual) CAN bus arrive as samples. Needs a kernel with AF_CAN
/// and a `vcan0` (or `FORGEMON_VCAN`) interface: ignored by default, so nextest counts it
/// as skipped; `.ci/run` runs it where the interface exists.
#[tokio::test]
#[ignore = "needs AF_CAN and a vcan0 interface (.ci/run runs it where there is one)"]
async fn live_socketcan_reads_frames() {
    use socketcan::{EmbeddedFrame, Socket, StandardId};
    use std::time::Duration;
    let iface = std::env::var("FORGEMON_VCAN").unwrap_or_else(|_| "vcan0".to_string());
    let (tx, mut rx) = tokio::sync::mpsc::channel(1024);
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let sender = socketcan::CanSocket::open(&iface).expect("the vcan interface opens");
    let task = tokio::spawn(forgemon::acquire::can::run(live_config(&iface), tx, stop_rx));
    // Wait for the driver to connect, then send 100 samples.
    loop {
        let e = tokio::time::timeout(Duration::from_secs(5), rx.recv()).await.expect("status").expect("open");
        if matches!(e, SourceEvent::Status(ref s) if s.state == "connected") {
            break;
        }
    }
    let mut dev = CanDevice::new(forgemon_mapping());
    for k in 0..100 {
        for (f, d) in dev.encode(|_| k as f64) {
            let id = StandardId::new(f.id as u16).expect("11 bits");
            let frame = socketcan::CanFrame::new(id, &d).expect("8 bytes");
            sender.write_frame(&frame).expect("send on the bus");
        }
    }
    let mut samples = 0;
    while samples < 100 {
        match tokio::time::timeout(Duration::from_secs(5), rx.recv()).await.expect("samples").expect("open") {
            SourceEvent::Batch(b) => samples += b.len(),
            SourceEvent::Gap(g) => panic!("no gap on a local bus: {g:?}"),
            SourceEvent::Status(_) => {}
        }
    }
    assert_eq!(samples, 100);
    stop_tx.send(true).expect("driver alive");
    tokio::time::timeout(Duration::from_secs(5), task).await.expect("stops").expect("no panic");
}

#[test]
fn fixture_paths_exist() {
    for p in [DBC, LOG, EXPECTED, "fixtures/can/README.md"] {
        assert!(Path::new(&root().join(p)).exists(), "{p}");
    }
}
