//! The PLC result image (docs/interfaces.md §8, issue 19 §2) at the process boundary: a real
//! `forgemon demo --plc ADDR` run in real time, read by an independent Modbus client
//! (`tests/python/plc_client.py`, pymodbus) as a PLC would. Every image it read must show
//! the blow results the demo recorded (read back from its MCAP recording, another path than
//! the image's encoder) within each register's unit; the heartbeat must advance once a
//! second; coil 0 must clear the alert-latched bit and coil 1 count one more billet; writes,
//! other addresses and another unit id are refused with Modbus exceptions, and a client that
//! sent garbage does not stop the server. CI installs pymodbus (`.ci/run`); elsewhere the
//! test fails saying how.
//!
//! The server's limits (issue 39), with raw TCP clients against `forgemon run`: an idle
//! connection is closed after `[plc_server] idle_timeout_s`; a connection past
//! `max_connections` takes the place of the oldest that has made no request, or is closed
//! when accepted if every open one has; a malformed request is answered with
//! exception 0x03 on a connection that goes on, and bytes that are not Modbus TCP close
//! the connection at once.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::free_port;

use forgemon::estimate::{BlowClass, BlowEstimate};
use forgemon::record::{Payload, read_recording};
use serde_json::Value;

const INSTALL: &str = "python3 -m pip install pymodbus";

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

/// Registers 6–21 against the blow's recorded result.
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
    // Issue 43: the demo's DAQ has all three channels, bits 0-2; the efficiency's 1σ.
    assert_eq!(w[20], 0b111, "blow {b}: channels");
    shows(w[21], r.efficiency_sd.unwrap_or(0.0), 1e-4, "efficiency sd", b);
}

#[test]
fn a_pymodbus_client_reads_the_demo_results_and_its_coils_act() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (plc, http) = (free_port(), free_port());
    let plc_addr = format!("127.0.0.1:{plc}");
    // Real time (the client reads each blow as a PLC would): 3 billets of 8 blows, 0.25 s
    // apart, about 7 s.
    let mut demo = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["demo", "--billets", "3", "--interval", "0.25", "--plc", &plc_addr])
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
    assert_eq!(results.len(), 24, "three billets of eight blows");

    // Refusals (Modbus exception codes): 1 illegal function, 2 illegal data address, 11
    // gateway target device failed to respond (unit 2 does not exist).
    let refused = &seen["refused"];
    for (what, code) in [
        ("write_register", 1),
        ("write_registers", 1),
        ("read_input", 1),
        ("read_coils", 1),
        ("read_past_end", 2),
        ("read_past_block", 2),
        ("write_coil_4", 2),
        ("other_unit", 11),
    ] {
        assert_eq!(refused[what], code, "{what}: {refused}");
    }

    // Every image read shows the result of the blow its counter names.
    let images: Vec<Vec<u32>> = seen["images"].as_array().expect("images").iter().map(words).collect();
    let ack = &seen["ack"];
    let part = &seen["part"];
    let part_at = part["images_before"].as_u64().expect("the part block step ran") as usize;
    let ack_at = ack["images_before"].as_u64().expect("the alert was latched and acknowledged") as usize;
    let acked_blows = u32_at(&words(&ack["before"]), 2);
    let mut blows_seen = Vec::new();
    for (i, w) in images.iter().enumerate() {
        assert_eq!(w.len(), 30);
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
        // Registers 22–29: the demo's one die set since the start (a fresh history), until
        // coil 3 changed it; no [die_life] limits: level 0, no share used.
        if i < part_at {
            let upto = || results.iter().filter(|x| x.blow <= u32_at(w, 2));
            assert_eq!(u32_at(w, 22), u32_at(w, 2), "blow {n}: die set blows");
            let hard = upto().filter(|x| x.class == BlowClass::Hard).count();
            assert_eq!(u32_at(w, 24) as usize, hard, "blow {n}: die set hard blows");
            let energy: f64 = upto().filter_map(|x| x.elastic_j.zip(x.damped_j)).map(|(e, d)| e + d).sum();
            shows(u32_at(w, 26), energy, 1e3, "die energy kJ", n);
            assert_eq!((w[28], w[29]), (0, 0), "blow {n}: no [die_life] limits");
        }
        blows_seen.push(n);
    }
    blows_seen.dedup();
    assert!(blows_seen.len() >= 8, "the client saw at least half the blows: {blows_seen:?}");
    assert_eq!(blows_seen.last(), Some(&24), "the last image shows the last blow");

    // Coil 0 cleared the latched alert; coil 1 counted a new billet.
    assert_eq!(ack["written"], true);
    let (before, after) = (words(&ack["before"]), words(&ack["after"]));
    assert_eq!(before[1] & 4, 4, "latched before");
    assert!(after[1] & 4 == 0 || u32_at(&after, 2) > u32_at(&before, 2), "coil 0 cleared the bit: {after:?}");
    let billet = &seen["billet"];
    assert_eq!(billet["written"], true);
    let (before, after) = (words(&billet["before"]), words(&billet["after"]));
    assert!(u32_at(&after, 4) > u32_at(&before, 4), "coil 1: billets {before:?} -> {after:?}");

    // The part block: written, read back as written, a control character refused (0x03);
    // coil 2 started a billet forged as it says, coil 3 a new life of die set 18.
    assert_eq!(
        (&part["wrote"], &part["coil_2"], &part["coil_3"]),
        (&Value::Bool(true), &Value::Bool(true), &Value::Bool(true)),
        "{part}"
    );
    assert_eq!(part["read_back"], part["written"]);
    assert_eq!(part["bad_write"], 3);
    let (before, as_block, die) = (words(&part["before"]), words(&part["after_billet"]), words(&part["after_die"]));
    // At least one more: the demo may start its own next billet meanwhile.
    assert!(u32_at(&as_block, 4) > u32_at(&before, 4), "coil 2 counted a billet: {before:?} -> {as_block:?}");
    let since_change = u32_at(&die, 2) - u32_at(&as_block, 2);
    assert!(u32_at(&die, 22) <= since_change, "coil 3 started the count again: {die:?} after {as_block:?}");
    // What the recording says the billets after coil 2 were forged as, and the die change.
    let messages = read_recording(&file).expect("the recording reads").messages;
    let forged: Vec<_> = messages
        .iter()
        .filter_map(|m| if let Payload::Billet(b) = &m.payload { Some(b.trace.clone()) } else { None })
        .collect();
    let want = forgemon::estimate::billet_book::Trace {
        part_id: Some("P-000418".into()),
        lot: Some("4711".into()),
        die_set: Some("18".into()),
    };
    assert!(forged.contains(&want), "a billet forged as the part block said: {forged:?}");
    assert!(forged.first().is_some_and(|t| *t != want), "not the first one: {forged:?}");

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

/// `forgemon run` serving the image on a free port with `limits` (TOML lines of
/// `[plc_server]`): the service and the image's address.
fn plc_service(dir: &Path, limits: &str) -> (Child, String) {
    let (http, plc) = (free_port(), free_port());
    let addr = format!("127.0.0.1:{plc}");
    let cfg = common::service_file(dir, http, &format!("[plc_server]\nlisten = \"{addr}\"\n{limits}"));
    let service = common::spawn_service(&cfg, http);
    // The image is a face started beside the status endpoint: wait until it accepts.
    let deadline = Instant::now() + Duration::from_secs(10);
    while TcpStream::connect(&addr).is_err() {
        assert!(Instant::now() < deadline, "the PLC image did not come up on {addr}");
        std::thread::sleep(Duration::from_millis(20));
    }
    (service, addr)
}

/// A connection to `addr` whose reads give up after `timeout`.
fn connect(addr: &str, timeout: Duration) -> TcpStream {
    let s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(timeout)).expect("read timeout");
    s
}

/// How a connection answered a read within its timeout.
#[derive(Debug, PartialEq)]
enum Seen {
    Bytes(Vec<u8>),
    /// End of stream or a reset: the server closed it.
    Closed,
    /// Nothing within the timeout: still open.
    Open,
}

fn wait_read(s: &mut TcpStream) -> Seen {
    let mut buf = [0u8; 300];
    match s.read(&mut buf) {
        Ok(0) => Seen::Closed,
        Ok(n) => Seen::Bytes(buf[..n].to_vec()),
        Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => Seen::Open,
        Err(_) => Seen::Closed,
    }
}

/// A request ADU: transaction `tid`, unit 1, `pdu`.
fn adu(tid: u16, pdu: &[u8]) -> Vec<u8> {
    let mut v = tid.to_be_bytes().to_vec();
    v.extend([0, 0]); // protocol 0
    v.extend(((pdu.len() + 1) as u16).to_be_bytes()); // length: unit + PDU
    v.push(1); // unit 1
    v.extend(pdu);
    v
}

/// Read holding registers 0..20, as the PLC does.
const READ_IMAGE: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x14];

fn stop(mut service: Child) {
    let _ = service.kill();
    let _ = service.wait();
}

/// Send the image read on `s` and wait for its answer: what came back.
fn poll(s: &mut TcpStream, tid: u16) -> Seen {
    s.write_all(&adu(tid, &READ_IMAGE)).expect("send");
    wait_read(s)
}

#[test]
fn idle_plc_connections_are_closed_after_the_idle_timeout_and_the_cap_is_counted_at_accept() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (service, addr) = plc_service(dir.path(), "idle_timeout_s = 3.0\nmax_connections = 3\n");
    let timeout = Duration::from_millis(1500);
    // A PLC polls; two clients connect and say nothing.
    let mut plc = connect(&addr, timeout);
    let plc_first = poll(&mut plc, 1);
    let (mut quiet_1, mut quiet_2) = (connect(&addr, timeout), connect(&addr, timeout));
    // A fourth, at the cap: it takes the place of the oldest that made no request, which
    // is closed at once (well before the 3 s idle timeout), and is served.
    let mut fourth = connect(&addr, timeout);
    let evicted = wait_read(&mut quiet_1);
    let (fourth_served, quiet_2_polled) = (poll(&mut fourth, 2), poll(&mut quiet_2, 3));
    // Now every open connection has made a request: a fifth is closed when accepted.
    let mut fifth = connect(&addr, timeout);
    let fifth_seen = wait_read(&mut fifth);
    // Then nobody asks anything: each is closed 3 s after its last request, not before.
    let last_request = Instant::now();
    let mut closed_after = Vec::new();
    for s in [&mut plc, &mut fourth, &mut quiet_2] {
        s.set_read_timeout(Some(Duration::from_secs(8))).expect("read timeout");
        closed_after.push((wait_read(s), last_request.elapsed()));
    }
    // Their places are free again: a new client is served.
    let mut after = connect(&addr, Duration::from_secs(3));
    let served = poll(&mut after, 9);
    stop(service);
    for (what, seen) in [("the PLC", &plc_first), ("the fourth", &fourth_served), ("the second quiet", &quiet_2_polled)]
    {
        assert!(matches!(seen, Seen::Bytes(r) if r.len() == 49 && r[7] == 0x03), "{what}: {seen:?}");
    }
    assert_eq!(evicted, Seen::Closed, "the oldest quiet connection kept its place past max_connections = 3");
    assert_eq!(fifth_seen, Seen::Closed, "the connection past max_connections = 3 was not closed");
    for (seen, t) in &closed_after {
        assert_eq!(*seen, Seen::Closed, "an idle connection was not closed after {t:?}");
        assert!(*t >= Duration::from_millis(2900), "closed after {t:?}, before the 3 s idle timeout");
    }
    let Seen::Bytes(reply) = served else { panic!("a client after the idle ones was not served: {served:?}") };
    // transaction 9, protocol 0, length 43, unit 1, function 3, 40 bytes
    assert_eq!(reply[..9], [0, 9, 0, 0, 0, 43, 1, 0x03, 40], "{reply:02x?}");
}

#[test]
fn a_malformed_pdu_is_answered_with_exception_3_and_the_connection_stays_usable() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (service, addr) = plc_service(dir.path(), "");
    let mut s = connect(&addr, Duration::from_secs(3));
    let mut ask = |tid: u16, pdu: &[u8]| {
        s.write_all(&adu(tid, pdu)).expect("send");
        wait_read(&mut s)
    };
    let answers = [
        ask(1, &[0x03, 0x00, 0x00, 0x00, 0x00]),                // a read of 0 registers
        ask(2, &[0x03, 0x00, 0x00, 0x00, 0x7E]),                // a read of 126 (max 125)
        ask(3, &[0x03, 0x00, 0x00, 0x00]),                      // truncated: no quantity's low byte
        ask(4, &[0x10, 0x00, 0x00, 0x00, 0x02, 0x03, 0, 1, 0]), // 2 registers, 3 bytes
        ask(5, &[0x05, 0x00, 0x00, 0x12, 0x34]),                // a coil value other than on or off
    ];
    let read = ask(6, &READ_IMAGE);
    stop(service);
    for (k, (seen, function)) in answers.iter().zip([0x83u8, 0x83, 0x83, 0x90, 0x85]).enumerate() {
        let tid = k as u8 + 1;
        // transaction, protocol 0, length 3, unit 1, function | 0x80, 0x03 illegal data value
        assert_eq!(*seen, Seen::Bytes(vec![0, tid, 0, 0, 0, 3, 1, function, 0x03]), "request {tid}");
    }
    let Seen::Bytes(reply) = read else { panic!("the connection did not go on: {read:?}") };
    assert_eq!(reply[..9], [0, 6, 0, 0, 0, 43, 1, 0x03, 40], "{reply:02x?}");
}

#[test]
fn random_bytes_get_the_connection_closed_at_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    // An idle timeout far longer than the test waits: the close is the gate's.
    let (service, addr) = plc_service(dir.path(), "idle_timeout_s = 60.0\n");
    let garbage: [&[u8]; 3] = [
        b"GET / HTTP/1.1\r\nhost: plc\r\n\r\n",
        &[0x16, 0x03, 0x01, 0x02, 0x00, 0x01, 0x00, 0x01, 0xfc, 0x03, 0x03], // a TLS hello
        &[0x00, 0x01, 0x00, 0x00, 0xff, 0xff, 0x01, 0x03],                   // protocol 0, length 65535
    ];
    let seen: Vec<Seen> = garbage
        .iter()
        .map(|g| {
            let mut s = connect(&addr, Duration::from_secs(5));
            s.write_all(g).expect("send");
            wait_read(&mut s)
        })
        .collect();
    // The server still serves a PLC.
    let served = poll(&mut connect(&addr, Duration::from_secs(3)), 7);
    stop(service);
    assert_eq!(seen, [Seen::Closed, Seen::Closed, Seen::Closed]);
    assert!(matches!(served, Seen::Bytes(ref r) if r[7] == 0x03), "{served:?}");
}
