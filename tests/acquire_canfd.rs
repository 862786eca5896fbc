//! CAN FD acquisition at the file and socket boundary (issue 16): 50 kHz of the hammer's
//! three channels in 64-byte CAN FD frames, 8 samples a frame, in the block layout of
//! `config/hammer-canfd.dbc`. Logs written by the standard tools (cantools encoding with
//! the DBC, python-can writing `candump -L`: `tests/python/write_canfd.py`) and by
//! `forgemon simulate-device --can-fd` (which the standard tools also read back the same,
//! `tests/python/read_canfd.py`) are decoded with the committed DBC: samples on the
//! 20 µs grid with the values written, a lost frame a gap of exactly 8 samples, a
//! malformed line named by its number, and the blows found against the simulator's
//! ledger. The live FD socket test is ignored unless a vcan interface exists (`.ci/run`).

mod common;

use std::path::Path;
use std::process::Command;

use common::{read, root};

use forgemon::acquire::SourceEvent;
use forgemon::acquire::can::candump::BadLines;
use forgemon::acquire::can::{
    BLOCK_SAMPLES, CanDecoder, CanMapping, CanSourceConfig, CanTiming, CandumpReader, DbcNames, block_mapping_from_dbc,
    forgemon_fd_mapping, read_candump,
};
use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::EffectSet;
use forgemon::physics::machine::Machine;
use forgemon::physics::process::Process;
use forgemon::pipeline::{Pipeline, PipelineConfig};
use forgemon::signal::capture::CaptureRow;
use forgemon::synth::{CaptureSpec, idle_rows, synth_blows};
use serde_json::Value;

const MACHINE: &str = "config/hammer-lg1000.machine.toml";
const PROCESS: &str = "config/steel-16NiCrMo13.process.toml";
const DBC: &str = "config/hammer-canfd.dbc";
const FAULTS_LOG: &str = "fixtures/canfd/faults.log";
const FAULTS_ROWS: &str = "fixtures/canfd/faults.rows.csv";
const WRITER: &str = "tests/python/write_canfd.py";
const INSTALL: &str = "python3 -m pip install python-can cantools";
const RATE_HZ: f64 = 50_000.0;
const PERIOD_S: f64 = 20e-6;
/// Blow 1 of the paper at 3.9 m/s, then two at 5.3 m/s (seed 000 §3.1).
const V0S_MPS: [f64; 3] = [3.9, 5.3, 5.3];
const SEED: u64 = 1616;
/// Efficiency against the simulator's ledger, two-sided: issue 16's 0.02. This session is
/// rendered by the project's own simulator and point-sampled (no anti-alias filter), and at
/// 50 kHz the hammer's blows go to the model fit, which runs that same simulator: it reads
/// within 1e-5 here. What this test shows is the CAN FD path losing nothing; the estimator's
/// accuracy on independently rendered, filtered data is `tests/estimate_rates.rs`'s.
const EFFICIENCY_TOL: f64 = 0.02;

fn machine() -> Machine {
    parse_machine(MACHINE, &read(MACHINE)).expect("machine file").machine
}

fn process() -> Process {
    parse_process(PROCESS, &read(PROCESS)).expect("process file")
}

fn dbc_mapping() -> CanMapping {
    block_mapping_from_dbc(DBC, &read(DBC), &DbcNames::forgemon(), BLOCK_SAMPLES, true).expect("the example DBC")
}

fn decode(text: &str, origin: &str, bad: BadLines) -> (Vec<SourceEvent>, CanDecoder) {
    let mut dec = CanDecoder::new("can", dbc_mapping(), CanTiming::new(RATE_HZ, 0.01, true));
    let events = read_candump(&mut CandumpReader::new(origin, text.as_bytes()), &mut dec, bad).expect("decode");
    (events, dec)
}

/// Every decoded sample: device time, load, disp, acc.
fn samples(events: &[SourceEvent]) -> Vec<(f64, f64, f64, f64)> {
    let mut out = Vec::new();
    for e in events {
        if let SourceEvent::Batch(b) = e {
            assert_eq!(b.period_ns, 20_000.0);
            for i in 0..b.len() {
                out.push((b.time_s(i), b.values[3 * i], b.values[3 * i + 1], b.values[3 * i + 2]));
            }
        }
    }
    out
}

fn gaps(events: &[SourceEvent]) -> Vec<(f64, u64)> {
    events
        .iter()
        .filter_map(|e| if let SourceEvent::Gap(g) = e { Some((g.t_s, g.samples_lost)) } else { None })
        .collect()
}

/// Whether `t_s` lies on the 20 µs grid (to 1 ns).
fn on_grid(t_s: f64) -> bool {
    let k = (t_s / PERIOD_S).round();
    (t_s - k * PERIOD_S).abs() < 1e-9
}

/// Decoded events through the pipeline (`common::blows_through`), each blow as its JSON.
fn run_pipeline(events: &[SourceEvent]) -> Vec<Value> {
    let m = machine();
    let p = Pipeline::new(m, Some(process()), PipelineConfig::for_machine(&m));
    common::blows_through(p, events).iter().map(|e| serde_json::to_value(e).expect("serialise")).collect()
}

fn f(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"))
}

fn write_csv(path: &Path, rows: &[CaptureRow]) {
    let mut s = String::from("t_s,load_N,disp_m,acc_mps2\n");
    for r in rows {
        s.push_str(&format!("{:.7},{},{:.7},{}\n", r.t_s, r.load_n, r.disp_m, r.acc_mps2));
    }
    std::fs::write(path, s).expect("write rows");
}

fn python_write(rows: &Path, out: &Path, extra: &[&str]) {
    let script = root().join(WRITER);
    let res = Command::new("python3").arg(&script).arg(rows).arg(root().join(DBC)).arg(out).args(extra).output();
    let res = match res {
        Ok(r) => r,
        Err(e) => panic!("cannot run python3 ({e}): install Python 3, then `{INSTALL}`"),
    };
    assert!(res.status.success(), "{WRITER} failed (`{INSTALL}`?): {}", String::from_utf8_lossy(&res.stderr));
}

/// The session at 50 kHz as one stream, and each blow's truth (efficiency, impact speed)
/// from the simulator's own ledger.
fn session() -> (Vec<CaptureRow>, Vec<(f64, f64)>) {
    let spec = CaptureSpec { sample_rate_hz: RATE_HZ, pre_s: 0.05, post_s: 0.03, ..CaptureSpec::hammer(SEED) };
    let blows = synth_blows(&machine(), &EffectSet::NONE, &process(), &V0S_MPS, &spec).expect("simulate");
    let mut rows = Vec::new();
    for (i, b) in blows.iter().enumerate() {
        rows.extend(idle_rows(5000, 0.0, &spec, b.rows[0].disp_m, SEED + 1 + i as u64));
        rows.extend_from_slice(&b.rows);
    }
    let last = rows.last().map_or(0.0, |r| r.disp_m);
    rows.extend(idle_rows(5000, 0.0, &spec, last, SEED + 99));
    for (k, r) in rows.iter_mut().enumerate() {
        r.t_s = 100.0 + k as f64 * PERIOD_S;
    }
    (rows, blows.iter().map(|b| (b.truth.efficiency(), b.truth.v0_mps)).collect())
}

/// Check the blows against the ledger: every blow, impact speed within 1 %, efficiency
/// within `EFFICIENCY_TOL`; returns the efficiency errors.
fn check_blows(found: &[Value], truth: &[(f64, f64)], what: &str) -> Vec<f64> {
    assert_eq!(found.len(), truth.len(), "{what}: every blow, no extra: {found:?}");
    let mut errs = Vec::new();
    for (v, (eff, v0)) in found.iter().zip(truth) {
        assert!((f(v, "v_impact_mps") / v0 - 1.0).abs() < 0.01, "{what}: {v} vs v0 {v0}");
        errs.push(f(v, "efficiency") - eff);
    }
    eprintln!("{what}: efficiency - ledger per blow at 50 kHz: {errs:?}");
    for (e, (eff, _)) in errs.iter().zip(truth) {
        assert!(e.abs() <= EFFICIENCY_TOL, "{what}: efficiency off by {e} from the ledger's {eff}");
    }
    errs
}

/// The strongest check that the DBC and the decoder agree with the standard tools: a log
/// cantools and python-can wrote from the DBC decodes to the samples written, on the grid,
/// and the blows come out as the simulator's ledger says.
#[test]
fn a_log_written_by_cantools_and_python_can_decodes_to_its_samples_and_blows() {
    let (rows, truth) = session();
    let dir = tempfile::tempdir().expect("temp dir");
    let csv = dir.path().join("rows.csv");
    let log = dir.path().join("bus.log");
    write_csv(&csv, &rows);
    python_write(&csv, &log, &[]);
    let text = std::fs::read_to_string(&log).expect("log");
    assert!(text.lines().all(|l| l.contains(" 121##1")), "every line a CAN FD frame");
    let (events, dec) = decode(&text, "bus.log", BadLines::Fail);
    assert_eq!(gaps(&events), vec![]);
    assert_eq!((dec.counters().decode_errors, dec.stats().unsupported_frames), (0, 0));
    let got = samples(&events);
    assert_eq!(got.len(), rows.len() / BLOCK_SAMPLES * BLOCK_SAMPLES);
    for (k, ((t, load, disp, acc), r)) in got.iter().zip(&rows).enumerate() {
        // Device time 0 is the first sample's time; the frame's stamp was its last sample's.
        assert!(on_grid(*t) && (t - (r.t_s - rows[0].t_s)).abs() < 1e-9, "sample {k}: t {t}");
        // Within half a step of each signal's resolution (100 N, 1 µm, 0.25 m/s²).
        assert!((load - r.load_n).abs() <= 50.0 + 1e-6, "sample {k}: load {load} vs {}", r.load_n);
        assert!((disp - r.disp_m).abs() <= 0.5e-6 + 1e-9, "sample {k}: disp {disp} vs {}", r.disp_m);
        assert!((acc - r.acc_mps2).abs() <= 0.125 + 1e-9, "sample {k}: acc {acc} vs {}", r.acc_mps2);
    }
    let via_can = check_blows(&run_pipeline(&events), &truth, "cantools log");
    // The same rows without the bus (no quantisation, one batch per 10 ms): the CAN FD
    // path moves no efficiency by more than 0.002, so what is left is the estimator's.
    let direct: Vec<SourceEvent> = rows
        .chunks(500)
        .enumerate()
        .map(|(i, c)| {
            SourceEvent::Batch(forgemon::signal::sample::SampleBatch {
                source: "direct".into(),
                seq: i as u64,
                device_time_ns: (i * 500) as i64 * 20_000,
                host_time_ns: (i * 500) as i64 * 20_000,
                period_ns: 20_000.0,
                roles: vec![
                    forgemon::signal::sample::Role::Load,
                    forgemon::signal::sample::Role::Disp,
                    forgemon::signal::sample::Role::Acc,
                ],
                values: c.iter().flat_map(|r| [r.load_n, r.disp_m, r.acc_mps2]).collect(),
            })
        })
        .collect();
    let direct = check_blows(&run_pipeline(&direct), &truth, "same rows without CAN");
    for (a, b) in via_can.iter().zip(&direct) {
        assert!((a - b).abs() < 0.002, "CAN FD {a} vs direct {b}");
    }
}

/// The committed fixture (written by cantools/python-can, two faults; fixtures/canfd/README.md).
#[test]
fn the_fault_fixture_names_its_bad_line_and_loses_exactly_one_block_per_fault() {
    let text = read(FAULTS_LOG);
    let err = read_candump(
        &mut CandumpReader::new(FAULTS_LOG, text.as_bytes()),
        &mut CanDecoder::new("can", dbc_mapping(), CanTiming::new(RATE_HZ, 0.01, true)),
        BadLines::Fail,
    )
    .unwrap_err()
    .to_string();
    assert!(err.starts_with(&format!("{FAULTS_LOG}:7: not a candump -L line")), "{err}");
    assert!(err.contains("odd number of hex digits"), "{err}");

    let (events, dec) = decode(&text, FAULTS_LOG, BadLines::Count);
    assert_eq!(dec.counters().decode_errors, 1);
    // The lost frame (samples 32..40) and the malformed line's (56..64): 8 samples each.
    let g = gaps(&events);
    assert_eq!(g.iter().map(|g| g.1).collect::<Vec<_>>(), vec![8, 8]);
    assert!((g[0].0 - 32.0 * PERIOD_S).abs() < 1e-9 && (g[1].0 - 56.0 * PERIOD_S).abs() < 1e-9, "{g:?}");
    assert_eq!(dec.counters().gaps, 2);
    // Nothing else is lost: the other 80 samples, each at its index's time with its value.
    let got = samples(&events);
    assert_eq!(got.len(), 80);
    let kept: Vec<usize> = (0..96).filter(|k| !(32..40).contains(k) && !(56..64).contains(k)).collect();
    let rows: Vec<Vec<f64>> = read(FAULTS_ROWS)
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse::<f64>().expect("number")).collect())
        .collect();
    for ((t, load, disp, acc), k) in got.iter().zip(kept) {
        assert!(on_grid(*t) && (t - k as f64 * PERIOD_S).abs() < 1e-9, "sample {k}: {t}");
        assert_eq!((*load, *acc), (rows[k][1], rows[k][3]), "sample {k}");
        assert!((disp - rows[k][2]).abs() < 1e-9, "sample {k}");
    }
}

/// `forgemon simulate-device --can-fd` writes a 50 kHz FD log that the service's log
/// source replays into the blows of the simulator's ledger (`forgemon simulate`).
#[tokio::test]
async fn simulate_device_writes_a_50_khz_fd_log_the_service_reads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let log = dir.path().join("fd.log");
    let bin = env!("CARGO_BIN_EXE_forgemon");
    let v0 = "3.9,5.3,5.3";
    let out = Command::new(bin)
        .args(["simulate-device", "--machine", MACHINE, "--process", PROCESS, "--v0", v0, "--billets", "1"])
        .args(["--interval", "0.3", "--rate", "50000", "--transport", "candump", "--can-fd", "--out"])
        .arg(&log)
        .current_dir(root())
        .output()
        .expect("run forgemon");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let said = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(said.contains("CAN FD frames of 8 samples"), "{said}");
    let text = std::fs::read_to_string(&log).expect("log");
    assert!(text.lines().all(|l| l.contains(" can0 121##1") && l.len() == l.find("##").unwrap_or(0) + 3 + 128));

    // Through the service's CAN log source, as `forgemon run` with a `log =` source does.
    let cfg = CanSourceConfig {
        name: "bus".into(),
        iface: "fd.log".into(),
        mapping: dbc_mapping(),
        timing: CanTiming::new(RATE_HZ, 0.01, true),
    };
    let (tx, mut rx) = tokio::sync::mpsc::channel(1_000_000);
    let (_stop, stop_rx) = tokio::sync::watch::channel(false);
    forgemon::acquire::can::run_log(cfg, log.clone(), false, tx, stop_rx).await.expect("log reads");
    let mut events = Vec::new();
    let mut last = None;
    while let Some(e) = rx.recv().await {
        match e {
            SourceEvent::Status(s) => last = Some(s),
            e => events.push(e),
        }
    }
    let s = last.expect("a status");
    assert_eq!((s.state.as_str(), s.decode_errors, s.gaps), ("finished", 0, 0), "{s:?}");
    let got = samples(&events);
    assert_eq!(got.len() as u64, s.samples);
    assert_eq!(got.len(), text.lines().count() * BLOCK_SAMPLES);
    assert!(got.iter().enumerate().all(|(k, (t, ..))| on_grid(*t) && (t - k as f64 * PERIOD_S).abs() < 1e-9));

    // The standard tools read forgemon's log as forgemon does: python-can and cantools
    // with the same DBC give the same counter (+8 a frame) and the same values.
    let py = Command::new("python3")
        .arg(root().join("tests/python/read_canfd.py"))
        .arg(&log)
        .arg(root().join(DBC))
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e}): `{INSTALL}`"));
    assert!(py.status.success(), "read_canfd.py (`{INSTALL}`?): {}", String::from_utf8_lossy(&py.stderr));
    let theirs: Value = serde_json::from_slice(&py.stdout).expect("read_canfd.py JSON");
    let seq: Vec<u64> = theirs["seq"].as_array().expect("seq").iter().filter_map(Value::as_u64).collect();
    assert_eq!(seq, (0..seq.len() as u64).map(|k| 8 * k).collect::<Vec<_>>());
    let theirs = theirs["samples"].as_array().expect("samples");
    assert_eq!(theirs.len(), got.len());
    for (k, (t, ours)) in theirs.iter().zip(&got).enumerate() {
        let v: Vec<f64> = t.as_array().expect("a sample").iter().filter_map(Value::as_f64).collect();
        let o = [ours.1, ours.2, ours.3];
        assert!(
            v.len() == 3 && v.iter().zip(o).all(|(a, b)| (a - b).abs() <= 1e-9 * b.abs().max(1.0)),
            "sample {k}: {v:?} vs {o:?}"
        );
    }

    // The ledger: `forgemon simulate` of the same blows on the same billet.
    let sim = Command::new(bin)
        .args(["simulate", "--machine", MACHINE, "--process", PROCESS, "--v0", v0, "--json"])
        .current_dir(root())
        .output()
        .expect("run forgemon simulate");
    assert!(sim.status.success(), "{}", String::from_utf8_lossy(&sim.stderr));
    let ledger: Value = serde_json::from_slice(&sim.stdout).expect("simulate JSON");
    let truth: Vec<(f64, f64)> =
        ledger["blows"].as_array().expect("blows").iter().map(|b| (f(b, "efficiency"), f(b, "v0_mps"))).collect();
    check_blows(&run_pipeline(&events), &truth, "simulate-device log");
}

/// The live test's configuration on `FORGEMON_VCAN` (default vcan0).
fn live_config() -> (String, CanSourceConfig) {
    let iface = std::env::var("FORGEMON_VCAN").unwrap_or_else(|_| "vcan0".to_string());
    let cfg = CanSourceConfig {
        name: "can".into(),
        iface: iface.clone(),
        mapping: forgemon_fd_mapping(),
        timing: CanTiming::new(RATE_HZ, 0.001, true),
    };
    (iface, cfg)
}

/// Where the interface cannot be opened (here: a kernel without AF_CAN), the driver says
/// so in its status and retries, until told to stop.
#[tokio::test]
async fn an_fd_interface_that_cannot_be_opened_is_reported_and_retried() {
    use std::time::Duration;
    let (_, mut cfg) = live_config();
    cfg.iface = "forgemon-none0".into();
    let (tx, mut rx) = tokio::sync::mpsc::channel(1024);
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let task = tokio::spawn(forgemon::acquire::can::run(cfg, tx, stop_rx));
    let first = tokio::time::timeout(Duration::from_secs(5), rx.recv()).await.expect("a status").expect("open");
    let SourceEvent::Status(s) = first else { panic!("{first:?}") };
    assert_eq!(s.state, "reconnecting");
    assert!(s.detail.contains("forgemon-none0"), "{}", s.detail);
    stop_tx.send(true).expect("driver alive");
    tokio::time::timeout(Duration::from_secs(5), task).await.expect("stops when told").expect("no panic");
}

/// Blocks sent on a real (virtual) CAN FD bus arrive as samples. Needs a kernel with AF_CAN
/// and a `vcan0` (or `FORGEMON_VCAN`) interface: ignored by default, so nextest counts it
/// as skipped; `.ci/run` runs it where the interface exists.
#[tokio::test]
#[ignore = "needs AF_CAN and a vcan0 interface (.ci/run runs it where there is one)"]
async fn live_canfd_socket_reads_blocks() {
    use socketcan::Socket;
    use socketcan::{CanFdFrame, EmbeddedFrame, StandardId};
    use std::time::Duration;
    let (iface, cfg) = live_config();
    let (tx, mut rx) = tokio::sync::mpsc::channel(1024);
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let sender = socketcan::CanFdSocket::open(&iface).expect("the vcan interface opens in FD mode");
    let task = tokio::spawn(forgemon::acquire::can::run(cfg, tx, stop_rx));
    loop {
        let e = tokio::time::timeout(Duration::from_secs(5), rx.recv()).await.expect("status").expect("open");
        if matches!(e, SourceEvent::Status(ref s) if s.state == "connected") {
            break;
        }
    }
    let mut dev = forgemon::acquire::can::CanDevice::new(forgemon_fd_mapping());
    for b in 0..20 {
        let rows: Vec<CaptureRow> = (0..BLOCK_SAMPLES)
            .map(|k| CaptureRow { t_s: 0.0, load_n: (b * 8 + k) as f64 * 100.0, disp_m: 0.1, acc_mps2: 0.0 })
            .collect();
        let (f, d) = dev.encode_block(&rows);
        let id = StandardId::new(f.id as u16).expect("11 bits");
        let frame = CanFdFrame::new(id, &d).expect("64 bytes");
        sender.write_frame(&frame).expect("send on the bus");
    }
    let mut n = 0;
    while n < 160 {
        match tokio::time::timeout(Duration::from_secs(5), rx.recv()).await.expect("samples").expect("open") {
            SourceEvent::Batch(b) => n += b.len(),
            SourceEvent::Gap(g) => panic!("no gap on a local bus: {g:?}"),
            SourceEvent::Status(_) => {}
        }
    }
    assert_eq!(n, 160);
    stop_tx.send(true).expect("driver alive");
    tokio::time::timeout(Duration::from_secs(5), task).await.expect("stops").expect("no panic");
}

/// Throughput of the log path (parse + decode), not a pass/fail check: run with
/// `cargo nextest run --release --test acquire_canfd --run-ignored only --no-capture`.
#[test]
#[ignore = "a measurement; prints samples/s"]
fn decode_throughput_of_a_10_s_50_khz_fd_log() {
    let rows: Vec<CaptureRow> = (0..500_000)
        .map(|k| CaptureRow {
            t_s: 1.7e9 + k as f64 * PERIOD_S,
            load_n: (k % 1000) as f64 * 100.0,
            disp_m: 0.4,
            acc_mps2: 9.75,
        })
        .collect();
    let mut log = Vec::new();
    forgemon::acquire::can::CanDevice::new(forgemon_fd_mapping()).write_log(&mut log, "can0", &rows).expect("write");
    let text = String::from_utf8(log).expect("ASCII");
    let start = std::time::Instant::now();
    let (events, dec) = decode(&text, "mem", BadLines::Fail);
    let dt = start.elapsed().as_secs_f64();
    assert_eq!(dec.counters().samples, 500_000);
    assert!(!events.is_empty());
    eprintln!(
        "decoded {} FD frames ({} samples, {} MB of candump text) in {dt:.3} s: {:.0} samples/s, {:.1}x real time at 50 kHz",
        dec.counters().frames,
        dec.counters().samples,
        text.len() / 1_000_000,
        500_000.0 / dt,
        10.0 / dt
    );
}
