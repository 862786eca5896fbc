//! `forgemon run` as a process (issue #4): it opens a real pty by path, like a serial DAQ,
//! while the test drives a simulated hammer into the other end in real time. Alerts reach a
//! webhook (a test HTTP server on 127.0.0.1), `/status` and `/metrics` tell the state,
//! SIGTERM finishes the recording cleanly, and after `kill -9` the file left behind is
//! recovered, losing at most the last second.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use common::{free_port, http_get, spawn_service};

use forgemon::acquire::ChannelSpec;
use forgemon::config::parse_process;
use forgemon::physics::EffectSet;
use forgemon::record::{Payload, RecordReader};
use forgemon::signal::sample::Role;
use forgemon::simdevice::{BilletPlan, SerialDeviceSpec, SimMachine, drive_serial};
use forgemon::synth::CaptureSpec;
use tokio_serial::SerialPort;

const HAMMER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/hammer-lg1000.machine.toml");
const STEEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/steel-16NiCrMo13.process.toml");
const RATE_HZ: f64 = 100e3;

fn channels() -> Vec<ChannelSpec> {
    vec![
        ChannelSpec { role: Role::Load, gain: 1.0, offset: 0.0 },
        ChannelSpec { role: Role::Disp, gain: 1e-6, offset: 0.0 },
        ChannelSpec { role: Role::Acc, gain: 1e-3, offset: 0.0 },
    ]
}

/// A one-request-at-a-time HTTP server that hands each request body to the test.
fn webhook_server() -> (u16, mpsc::Receiver<String>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let mut r = BufReader::new(stream.try_clone().unwrap());
            let mut len = 0usize;
            let mut line = String::new();
            while r.read_line(&mut line).unwrap_or(0) > 2 {
                if let Some(v) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                    len = v.trim().parse().unwrap_or(0);
                }
                line.clear();
            }
            let mut body = vec![0; len];
            let _ = r.read_exact(&mut body);
            let _ = (&stream).write_all(b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\nconnection: close\r\n\r\n");
            let _ = tx.send(String::from_utf8_lossy(&body).into_owned());
        }
    });
    (port, rx)
}

struct Service {
    child: Child,
    dir: PathBuf,
    http: u16,
}

fn start_service(name: &str, tty: &str, webhook_port: u16) -> Service {
    start_service_with(name, tty, webhook_port, "")
}

fn start_service_with(name: &str, tty: &str, webhook_port: u16, extra_alerts: &str) -> Service {
    start_service_on(name, tty, webhook_port, extra_alerts, None)
}

/// `start_service_with` on a copy of the LG1000's machine file in the service's directory
/// (`machine.toml`), when `own_machine`: a file the test may rewrite.
fn start_service_on(name: &str, tty: &str, webhook_port: u16, extra_alerts: &str, own_machine: Option<()>) -> Service {
    let dir = std::env::temp_dir().join(format!("forgemon-run-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let machine = match own_machine {
        Some(()) => {
            std::fs::copy(HAMMER, dir.join("machine.toml")).unwrap();
            dir.join("machine.toml").display().to_string()
        }
        None => HAMMER.to_string(),
    };
    let http = free_port();
    let cfg = format!(
        r#"machine = "{machine}"
process = "{STEEL}"
[recording]
dir = "rec"
[http]
listen = "127.0.0.1:{http}"
[alerts]
webhook = "http://127.0.0.1:{webhook_port}/alerts"
{extra_alerts}
[[sources]]
name = "daq"
kind = "serial"
path = "{tty}"
[[sources.channels]]
role = "load_N"
gain = 1.0
[[sources.channels]]
role = "disp_m"
gain = 1e-6
[[sources.channels]]
role = "acc_mps2"
gain = 1e-3
"#
    );
    std::fs::write(dir.join("service.toml"), cfg).unwrap();
    let child = spawn_service(&dir.join("service.toml"), http);
    Service { child, dir, http }
}

/// Wait until the service on `port` has reported `n` blows (15 s at most).
fn wait_for_blows(port: u16, n: u64) {
    let deadline = Instant::now() + Duration::from_secs(15);
    while status(port)["blows"].as_u64() < Some(n) {
        assert!(Instant::now() < deadline, "blows seen: {}", status(port));
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn status(port: u16) -> serde_json::Value {
    serde_json::from_str(&http_get(port, "/status").unwrap()).unwrap()
}

fn recordings(dir: &Path) -> Vec<PathBuf> {
    common::recordings_in(&dir.join("rec"))
}

/// Drive `billets` billets of eight blows, `interval_s` apart, into the pty master in real
/// time; `written` counts the samples sent. Stops when `stop` turns true.
fn drive(
    master: tokio_serial::SerialStream,
    billets: usize,
    interval_s: f64,
    written: Arc<AtomicU64>,
    stop: tokio::sync::watch::Receiver<bool>,
) {
    let plan = BilletPlan { process: steel(), v0s_mps: vec![3.9, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3] };
    drive_plans(master, vec![plan; billets], interval_s, written, stop);
}

fn steel() -> forgemon::physics::process::Process {
    parse_process("steel", &std::fs::read_to_string(STEEL).unwrap()).unwrap()
}

fn hammer() -> forgemon::physics::machine::Machine {
    forgemon::config::parse_machine("hammer", &std::fs::read_to_string(HAMMER).unwrap()).unwrap().machine
}

/// Drive `plans` into the pty master in real time, `interval_s` between blows.
fn drive_plans(
    master: tokio_serial::SerialStream,
    plans: Vec<BilletPlan>,
    interval_s: f64,
    written: Arc<AtomicU64>,
    stop: tokio::sync::watch::Receiver<bool>,
) {
    let sim = SimMachine::new(hammer(), EffectSet::NONE, plans, CaptureSpec::hammer(5), interval_s);
    let spec =
        SerialDeviceSpec { channels: channels(), frame_samples: 1000, realtime: true, faults: Default::default() };
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async move {
        let counting = CountingWriter { inner: master, written };
        drive_serial(sim, &spec, counting, stop, |_, _| {}).await.unwrap();
    });
}

/// Counts the samples that reach the pty (3 channels of i32 per sample, COBS-framed).
struct CountingWriter {
    inner: tokio_serial::SerialStream,
    written: Arc<AtomicU64>,
}

impl tokio::io::AsyncWrite for CountingWriter {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        let r = std::pin::Pin::new(&mut self.inner).poll_write(cx, buf);
        if let std::task::Poll::Ready(Ok(n)) = &r {
            // A 1000-sample frame is ~12 kB; count bytes here and samples via bytes/12.
            self.written.fetch_add(*n as u64, Ordering::Relaxed);
        }
        r
    }
    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

fn pty() -> (tokio_serial::SerialStream, tokio_serial::SerialStream, String) {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let _g = rt.enter();
    let (master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let name = slave.name().expect("the pty slave has a path");
    std::mem::forget(rt);
    (master, slave, name)
}

#[test]
fn alerts_reach_the_webhook_and_the_status_endpoint_tells_the_state() {
    let (master, slave, tty) = pty();
    let (hook_port, hooks) = webhook_server();
    let mut svc = start_service("webhook", &tty, hook_port);
    let written = Arc::new(AtomicU64::new(0));
    let (_stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    drive(master, 1, 0.3, written, stop_rx);
    // The blows of the billet are all found and the hard ones raised an alert.
    let deadline = Instant::now() + Duration::from_secs(10);
    while status(svc.http)["blows"].as_u64() < Some(8) {
        assert!(Instant::now() < deadline, "blows seen: {}", status(svc.http));
        std::thread::sleep(Duration::from_millis(50));
    }
    let st = status(svc.http);
    assert_eq!(st["blows"], 8);
    assert_eq!(st["last_class"], "hard");
    assert_eq!(st["sources"]["daq"]["state"], "connected");
    assert_eq!(st["sources"]["daq"]["crc_errors"], 0);
    // The device and the service share this machine's clock, so the true drift is 0 ppm.
    // The estimate is clamped to ±MAX_DRIFT_PPM (500); over this ~3 s run the pty's delivery
    // jitter moved it by 16 and 33 ppm in two runs on the 2-core machine. Half the clamp
    // leaves 7x margin and still fails an estimate that runs away to the clamp.
    let drift = st["sources"]["daq"]["clock_drift_ppm"].as_f64().expect("a clock estimate");
    assert!(drift.abs() < 0.5 * forgemon::signal::align::MAX_DRIFT_PPM, "drift {drift} ppm");
    // Reported once a blow has a result (its value is a benchmark figure, not asserted).
    let latency = st["last_result_latency_ms"].as_f64().expect("the last result's latency");
    eprintln!("last result latency: {latency:.3} ms, clock drift estimate {drift:.1} ppm");
    let alert: serde_json::Value =
        serde_json::from_str(&hooks.recv_timeout(Duration::from_secs(5)).expect("the webhook was called")).unwrap();
    assert_eq!(alert["kind"], "elastic_blow");
    // The simulator's efficiencies of blows 7 and 8 are 0.502 and 0.371 (`forgemon simulate`
    // of this plan): blow 8 is the first hard one, and blow 7 sits within issue 16's 0.02
    // of the 0.5 line, so either may be the first the estimator calls hard.
    let first_hard = alert["blow"].as_u64();
    assert!(matches!(first_hard, Some(7 | 8)), "{alert}");
    assert!(alert["reason"].as_str().unwrap().contains("hard"));
    // The status shows when the webhook answered, counted from the samples that ended the
    // blow (a figure for the note, not a timed assertion; the webhook task runs after the
    // handler replied, so poll briefly).
    let deadline = Instant::now() + Duration::from_secs(2);
    let hook_ms = loop {
        if let Some(ms) = status(svc.http)["last_webhook_latency_ms"].as_f64() {
            break ms;
        }
        assert!(Instant::now() < deadline, "no webhook latency in {}", status(svc.http));
        std::thread::sleep(Duration::from_millis(20));
    };
    eprintln!("end of blow to webhook answered: {hook_ms:.3} ms");
    let metrics = http_get(svc.http, "/metrics").unwrap();
    assert!(metrics.contains("forgemon_blows_total 8"), "{metrics}");
    assert!(metrics.contains("forgemon_source_up{source=\"daq\"} 1"), "{metrics}");
    // SIGTERM finishes the recording: a renamed .mcap that holds the eight results.
    let kill = Command::new("kill").args(["-TERM", &svc.child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let code = svc.child.wait().unwrap();
    assert!(code.success(), "{code:?}");
    drop(slave);
    let files = recordings(&svc.dir);
    assert!(files.iter().all(|f| f.extension().is_some_and(|x| x == "mcap")), "{files:?}");
    let results = files
        .iter()
        .flat_map(|f| {
            RecordReader::open(f)
                .unwrap()
                .filter_map(|m| m.ok())
                .filter(|m| matches!(m.payload, Payload::Result(_)))
                .collect::<Vec<_>>()
        })
        .count();
    assert_eq!(results, 8);
}

#[test]
fn kill_9_loses_at_most_the_last_second() {
    let (master, slave, tty) = pty();
    let (hook_port, _hooks) = webhook_server();
    let mut svc = start_service("kill9", &tty, hook_port);
    let written = Arc::new(AtomicU64::new(0));
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let w = written.clone();
    let device = std::thread::spawn(move || drive(master, 3, 0.3, w, stop_rx));
    std::thread::sleep(Duration::from_millis(3500));
    let at_kill = written.load(Ordering::Relaxed);
    svc.child.kill().unwrap(); // SIGKILL
    svc.child.wait().unwrap();
    let _ = stop_tx.send(true);
    let _ = device.join();
    drop(slave);
    let files = recordings(&svc.dir);
    let part = files.iter().find(|f| f.to_string_lossy().ends_with(".mcap.part")).expect("an unfinished .mcap.part");
    let mut reader = RecordReader::open(part).unwrap();
    let mut samples = 0u64;
    for m in reader.by_ref() {
        if let Payload::Samples(b) = m.unwrap().payload {
            samples += b.len() as u64;
        }
    }
    assert!(!reader.report().complete);
    // Bytes on the wire per sample: 3 x i32 plus framing (~12.1 bytes at 1000 per frame).
    let sent_samples = at_kill as f64 / 12.1;
    // DESIGN.md §3: synced at least every second, so at most the last second (100 kHz) is
    // lost; 0.2 s more for what sat in the pty and the service's queue.
    let lost = sent_samples - samples as f64;
    assert!(lost <= 1.2 * RATE_HZ, "sent ~{sent_samples:.0}, recovered {samples}: lost {lost:.0} samples");
    assert!(samples > 0);
}

#[test]
fn alerts_set_the_plc_coil() {
    use forgemon::acquire::modbus::server::{BankService, TcpServer, lock, shared_bank};
    let rt = tokio::runtime::Runtime::new().unwrap();
    let bank = shared_bank();
    let service = BankService { bank: bank.clone(), faults: Default::default(), unit: None };
    let server = rt.block_on(TcpServer::start("127.0.0.1:0".parse().unwrap(), service)).unwrap();
    let plc = format!("[alerts.plc_coil]\naddress = \"{}\"\nunit = 1\ncoil = 12", server.addr());
    let (master, slave, tty) = pty();
    let (hook_port, _hooks) = webhook_server();
    let mut svc = start_service_with("coil", &tty, hook_port, &plc);
    assert!(!lock(&bank).coils[12]);
    let (_stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    drive(master, 1, 0.3, Arc::new(AtomicU64::new(0)), stop_rx);
    // The hard blows of the billet raise the alert; the coil is set on the PLC.
    let deadline = Instant::now() + Duration::from_secs(10);
    while !lock(&bank).coils[12] {
        assert!(Instant::now() < deadline, "the coil was not set: {}", status(svc.http));
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(!lock(&bank).coils[11] && !lock(&bank).coils[13], "only coil 12");
    svc.child.kill().unwrap();
    svc.child.wait().unwrap();
    drop(slave);
    drop(server);
}

#[test]
fn a_candump_log_with_its_dbc_feeds_the_service() {
    let fixtures = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/can");
    // The committed fixture holds three blows (fixtures/can/README.md).
    service_finds_blows_in_candump(&format!("{fixtures}/hammer_blows.log"), "can", 3);
}

#[test]
fn simulate_device_writes_a_candump_log_the_service_reads() {
    let dir = std::env::temp_dir().join(format!("forgemon-simdev-{}-can", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("session.log");
    let out = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["simulate-device", "--machine", HAMMER, "--process", STEEL, "--v0", "3.9,5.3,5.3,5.3", "--billets", "1"])
        .args(["--interval", "0.3", "--rate", "5000", "--transport", "candump", "--out", log.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    service_finds_blows_in_candump(log.to_str().unwrap(), "simdev", 4);
}

/// Run the service on a candump log with the fixture DBC until it has found `blows`.
fn service_finds_blows_in_candump(log: &str, name: &str, blows: u64) {
    let fixtures = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/can");
    let dir = std::env::temp_dir().join(format!("forgemon-run-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let http = free_port();
    let cfg = format!(
        r#"machine = "{HAMMER}"
process = "{STEEL}"
[recording]
dir = "rec"
[http]
listen = "127.0.0.1:{http}"
[[sources]]
name = "bus"
kind = "can"
log = "{log}"
sample_rate_hz = 5000
dbc = "{fixtures}/hammer.dbc"
[sources.signals]
load_N = "Load"
disp_m = "Disp"
acc_mps2 = "Acc"
sequence = "Seq"
"#
    );
    std::fs::write(dir.join("service.toml"), cfg).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["run", "--config", dir.join("service.toml").to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("service.err")).unwrap())
        .spawn()
        .unwrap();
    // The log is replayed in real time (about 0.3 s a blow).
    let deadline = Instant::now() + Duration::from_secs(15);
    loop {
        if let Some(st) = http_get(http, "/status").and_then(|b| serde_json::from_str::<serde_json::Value>(&b).ok())
            && st["blows"] == blows
        {
            assert_eq!(st["sources"]["bus"]["gaps"], 0);
            break;
        }
        assert!(
            Instant::now() < deadline,
            "{blows} blows were not found in {log}: {:?} {}",
            http_get(http, "/status"),
            std::fs::read_to_string(dir.join("service.err")).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    child.kill().unwrap();
    child.wait().unwrap();
}

/// Issue 22: ten billets of heights up to 8 % off the sheet's (the first on it), forged over
/// a real pty with no new-billet signal at all. The service counts ten billets from the
/// encoder, and every blow's height after it is within 0.1 mm (the issue's figure) of the
/// simulator's.
#[test]
fn ten_billets_are_counted_over_a_pty_without_a_billet_signal() {
    let (master, slave, tty) = pty();
    let (hook_port, _hooks) = webhook_server();
    let mut svc = start_service("billets", &tty, hook_port);
    let base = BilletPlan { process: steel(), v0s_mps: vec![3.9, 5.3, 5.3] };
    let plans = forgemon::simdevice::spread_plans(&base, 10, 0.08, 11);
    // The simulator's truth, forged once more off the line (the physics is deterministic).
    let mut truth_sim = SimMachine::new(hammer(), EffectSet::NONE, plans.clone(), CaptureSpec::hammer(5), 0.3);
    while !truth_sim.finished() {
        truth_sim.next_rows(100_000).unwrap();
    }
    let truth = truth_sim.h_end_truth_m().to_vec();
    let (_stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    drive_plans(master, plans.clone(), 0.3, Arc::new(AtomicU64::new(0)), stop_rx);
    let deadline = Instant::now() + Duration::from_secs(10);
    while status(svc.http)["blows"].as_u64() < Some(30) {
        assert!(Instant::now() < deadline, "blows seen: {}", status(svc.http));
        std::thread::sleep(Duration::from_millis(50));
    }
    let st = status(svc.http);
    assert_eq!((st["billets"].as_u64(), st["billets_finished"].as_u64()), (Some(10), Some(9)), "{st}");
    assert_eq!((st["billet_blows"].as_u64(), st["last_billet_blows"].as_u64()), (Some(3), Some(3)), "{st}");
    let metrics = http_get(svc.http, "/metrics").unwrap();
    assert!(metrics.contains("forgemon_billets_total 10"), "{metrics}");
    assert!(metrics.contains("forgemon_billets_finished_total 9"), "{metrics}");
    assert!(metrics.contains("forgemon_last_billet_blows 3"), "{metrics}");
    let kill = Command::new("kill").args(["-TERM", &svc.child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    assert!(svc.child.wait().unwrap().success());
    drop(slave);
    let messages: Vec<_> = recordings(&svc.dir)
        .iter()
        .flat_map(|f| RecordReader::open(f).unwrap().filter_map(|m| m.ok()).collect::<Vec<_>>())
        .collect();
    let results: Vec<_> = messages
        .iter()
        .filter_map(|m| match &m.payload {
            Payload::Result(r) => Some(r),
            _ => None,
        })
        .collect();
    assert_eq!(results.len(), 30);
    for (i, (r, h)) in results.iter().zip(&truth).enumerate() {
        assert_eq!(r.billet.billet, i as u32 / 3 + 1, "blow {}", r.blow);
        assert_eq!(r.billet.billet_check, None, "blow {}", r.blow);
        let e = r.h_end_m.expect("a tracked height");
        assert!((e - h).abs() < 1e-4, "blow {}: h_end {e} vs simulated {h}", r.blow);
    }
    // The recording's `/billets`: one summary per billet, the last closed unfinished when
    // the service stopped; heights from the saw cut and to the simulator's end, 0.1 mm.
    let billets: Vec<_> = messages
        .iter()
        .filter_map(|m| match &m.payload {
            Payload::Billet(b) => Some(b),
            _ => None,
        })
        .collect();
    assert_eq!(billets.len(), 10);
    for (i, b) in billets.iter().enumerate() {
        assert_eq!((b.billet, b.blows, b.finished), (i as u32 + 1, 3, i < 9), "{b}");
        let h0 = b.h_start_m.expect("a start height");
        assert!((h0 - plans[i].process.billet.height_m).abs() < 1e-4, "{b}");
        assert!((b.h_end_m.expect("an end height") - truth[3 * i + 2]).abs() < 1e-4, "{b}");
    }
    // `inspect` counts them from the file.
    let rec = recordings(&svc.dir);
    let out = Command::new(env!("CARGO_BIN_EXE_forgemon")).args(["inspect", "--json"]).arg(&rec[0]).output().unwrap();
    let inspected: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((inspected["billets"].as_u64(), inspected["billets_finished"].as_u64()), (Some(10), Some(9)));
}

/// SIGHUP reloads the alert rules, and the recording keeps the new file where it took
/// effect, so a replay judges each blow by the rules the live run had at that blow. The
/// first billet is forged with hard-blow alerts off, the second after turning them on.
#[test]
fn a_sighup_reload_is_recorded_and_replayed_where_it_happened() {
    let (master, slave, tty) = pty();
    let (hook_port, _hooks) = webhook_server();
    let mut svc = start_service_with("sighup", &tty, hook_port, "hard_blow = false");
    let (_stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let device = std::thread::spawn(move || drive(master, 2, 0.3, Arc::new(AtomicU64::new(0)), stop_rx));
    let wait_blows = |n: u64| wait_for_blows(svc.http, n);
    wait_blows(8);
    let cfg = svc.dir.join("service.toml");
    let text = std::fs::read_to_string(&cfg).unwrap().replace("hard_blow = false", "hard_blow = true");
    std::fs::write(&cfg, text).unwrap();
    assert!(Command::new("kill").args(["-HUP", &svc.child.id().to_string()]).status().unwrap().success());
    wait_blows(16);
    device.join().unwrap();
    assert!(Command::new("kill").args(["-TERM", &svc.child.id().to_string()]).status().unwrap().success());
    assert!(svc.child.wait().unwrap().success());
    drop(slave);
    let rec = recordings(&svc.dir);
    assert_eq!(rec.len(), 1, "{rec:?}");
    let live: Vec<_> = RecordReader::open(&rec[0])
        .unwrap()
        .filter_map(|m| match m.ok()?.payload {
            Payload::Result(r) => Some(r),
            _ => None,
        })
        .collect();
    assert_eq!(live.len(), 16);
    let live_alerts: Vec<bool> = live.iter().map(|r| r.alert.is_some()).collect();
    // Billet 1's hard blows did not alert; billet 2's did.
    assert!(live[..8].iter().all(|r| r.alert.is_none()), "{live_alerts:?}");
    assert!(live[8..].iter().any(|r| r.alert.is_some()), "{live_alerts:?}");
    let replay = |extra: &[&str]| -> Vec<bool> {
        let out = Command::new(env!("CARGO_BIN_EXE_forgemon"))
            .args(["replay", rec[0].to_str().unwrap(), "--machine", HAMMER, "--json"])
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let lines = String::from_utf8(out.stdout).unwrap();
        lines.lines().map(|l| !serde_json::from_str::<serde_json::Value>(l).unwrap()["alert"].is_null()).collect()
    };
    assert_eq!(replay(&[]), live_alerts, "the replay follows the recorded reload");
    // The reloaded file applied from the start judges billet 1's hard blows too.
    let from_start = replay(&["--service", cfg.to_str().unwrap()]);
    assert!(from_start[..8].iter().any(|a| *a), "{from_start:?}");
}

/// Issue 37: `run` takes an adopted machine file on SIGHUP. After billet 1 the machine file
/// gains an effect (friction that rises as the part flattens, which this simulated hammer
/// does not have, so billet 2's blows, struck as billet 1's, come out otherwise: more of
/// their work is friction); the recording holds the
/// model where it changed, and its replay gives the live results to the bit.
#[test]
fn a_sighup_takes_the_adopted_machine_file_and_the_replay_follows() {
    let (master, slave, tty) = pty();
    let (hook_port, _hooks) = webhook_server();
    let mut svc = start_service_on("sighup-model", &tty, hook_port, "", Some(()));
    let (_stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let device = std::thread::spawn(move || drive(master, 2, 0.3, Arc::new(AtomicU64::new(0)), stop_rx));
    let wait_blows = |n: u64| wait_for_blows(svc.http, n);
    wait_blows(8);
    let machine = svc.dir.join("machine.toml");
    let adopted = format!("{}\n[effects.friction_rise]\nexponent = 0.8\n", std::fs::read_to_string(&machine).unwrap());
    std::fs::write(&machine, adopted).unwrap();
    assert!(Command::new("kill").args(["-HUP", &svc.child.id().to_string()]).status().unwrap().success());
    wait_blows(16);
    device.join().unwrap();
    assert!(Command::new("kill").args(["-TERM", &svc.child.id().to_string()]).status().unwrap().success());
    assert!(svc.child.wait().unwrap().success());
    drop(slave);
    let rec = recordings(&svc.dir);
    assert_eq!(rec.len(), 1, "{rec:?}");
    let (mut live, mut machines) = (Vec::new(), 0);
    for m in RecordReader::open(&rec[0]).unwrap() {
        match m.unwrap().payload {
            Payload::Result(r) => live.push(r.efficiency),
            Payload::Config(c) if c.name == "machine.toml" => machines += 1,
            _ => {}
        }
    }
    assert_eq!((live.len(), machines), (16, 2), "the model at the start and where SIGHUP changed it");
    // Billet 2 was estimated with the rising friction: its efficiencies are lower.
    let moved = (0..8).map(|i| (live[8 + i].unwrap_or(0.0) - live[i].unwrap_or(0.0)).abs()).fold(0.0, f64::max);
    assert!(moved > 0.02, "billet 2 against billet 1: {live:?}");
    let out = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["replay", rec[0].to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let replayed: Vec<Option<f64>> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["efficiency"].as_f64())
        .collect();
    // Equal but for serde_json's parse of the printed number (not correctly rounded without
    // its float_roundtrip feature: an ulp at most).
    assert_eq!(replayed.len(), live.len());
    for (r, l) in replayed.iter().zip(&live) {
        assert!(
            r.zip(*l).is_some_and(|(r, l)| (r - l).abs() <= 1e-15),
            "the replay follows the recorded model: {replayed:?} {live:?}"
        );
    }
}
