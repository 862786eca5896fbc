//! Helpers shared by the integration tests (each test file that uses them says `mod common;`).

#![allow(dead_code)]

use forgemon::acquire::SourceEvent;
use forgemon::config::{parse_machine, parse_process};
use forgemon::estimate::BlowEstimate;
use forgemon::physics::{Machine, Process};
use forgemon::pipeline::{Pipeline, PipelineEvent};

/// Decoded source events through `p`, a gap ending the stream (the service instead bridges
/// short holes by device time, `pipeline::Feeder`, tested in `tests/service_faults.rs`):
/// the blows, every one of which must have been estimated.
pub fn blows_through(mut p: Pipeline, events: &[SourceEvent]) -> Vec<BlowEstimate> {
    let mut out = Vec::new();
    for e in events {
        match e {
            SourceEvent::Batch(b) => p.push(b, &mut out),
            SourceEvent::Gap(_) => p.end_of_stream(&mut out),
            SourceEvent::Status(_) => {}
        }
    }
    p.end_of_stream(&mut out);
    estimates(&out)
}

/// The blow of a pipeline event, `None` for a billet summary; a blow the estimator
/// rejected fails the test.
pub fn estimate_of(e: &PipelineEvent) -> Option<&BlowEstimate> {
    match e {
        PipelineEvent::Blow { estimate, .. } => Some(estimate),
        PipelineEvent::Billet(_) => None,
        PipelineEvent::Rejected { cut, error } => panic!("blow at {} rejected: {error}", cut.t_contact_s),
    }
}

/// The blows of `events`, in order (`estimate_of`).
pub fn estimates(events: &[PipelineEvent]) -> Vec<BlowEstimate> {
    events.iter().filter_map(estimate_of).cloned().collect()
}

/// The example machine `config/FILE`.
pub fn machine(file: &str) -> Machine {
    parse_machine(file, &read(&format!("config/{file}"))).unwrap_or_else(|e| panic!("{file}: {e}")).machine
}

/// The example process sheet `config/FILE`.
pub fn process(file: &str) -> Process {
    parse_process(file, &read(&format!("config/{file}"))).unwrap_or_else(|e| panic!("{file}: {e}"))
}

/// A free TCP port on loopback.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// The body of `GET path` on the service's loopback port, `None` while it does not answer.
pub fn http_get(port: u16, path: &str) -> Option<String> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(std::time::Duration::from_secs(2))).ok()?;
    write!(s, "GET {path} HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n").ok()?;
    let mut out = String::new();
    s.read_to_string(&mut out).ok()?;
    out.split_once("\r\n\r\n").map(|(_, b)| b.to_string())
}

/// `method path` with `body` on the service's loopback `port`: the status code and the body
/// of the answer. The request is written whole before the answer is read; a server that
/// answers early (413) and closes may cut the writing short, which is not an error here.
pub fn http_send(port: u16, method: &str, path: &str, body: &[u8]) -> (u16, String) {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).expect("connect");
    s.set_read_timeout(Some(std::time::Duration::from_secs(10))).expect("timeout");
    let head = format!(
        "{method} {path} HTTP/1.1\r\nhost: localhost\r\ncontent-length: {}\r\nconnection: close\r\n\r\n",
        body.len()
    );
    let _ = s.write_all(head.as_bytes()).and_then(|()| s.write_all(body));
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    let out = String::from_utf8_lossy(&out).into_owned();
    let code = out.split(' ').nth(1).and_then(|c| c.parse().ok()).unwrap_or_else(|| panic!("no status line: {out:?}"));
    (code, out.split_once("\r\n\r\n").map(|(_, b)| b.to_string()).unwrap_or_default())
}

/// A child process killed and reaped when dropped, so that a test that fails leaves no
/// service running behind it.
pub struct KillOnDrop(pub std::process::Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `forgemon run --config CONFIG`, once its status endpoint on `http` answers (10 s at most).
pub fn spawn_service(config: &std::path::Path, http: u16) -> std::process::Child {
    spawn_service_logging(config, http, std::process::Stdio::null())
}

/// `spawn_service` with the service's log (stderr) going to `log`.
pub fn spawn_service_logging(config: &std::path::Path, http: u16, log: std::process::Stdio) -> std::process::Child {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let child = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["run", "--config", config.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while http_get(http, "/status").is_none() {
        assert!(Instant::now() < deadline, "the service did not come up");
        std::thread::sleep(Duration::from_millis(50));
    }
    child
}

/// `dir/service.toml`: the example hammer, a recording under `dir/rec`, the status on
/// `127.0.0.1:http`, the tables `tables` (TOML text), and one serial source that never
/// opens (the service runs on without it), so that a server's face can be driven alone.
pub fn service_file(dir: &std::path::Path, http: u16, tables: &str) -> std::path::PathBuf {
    service_toml(dir, http, "", tables)
}

/// The files in `dir`, sorted by name.
pub fn files_in(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(dir).unwrap().filter_map(|e| e.ok()).map(|e| e.path()).collect();
    v.sort();
    v
}

/// The recordings in `dir` (`*.mcap`, `*.mcap.part`), sorted by name: the directory also
/// holds the history database (`history.sqlite`, issue 44).
pub fn recordings_in(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    files_in(dir)
        .into_iter()
        .filter(|p| p.to_str().is_some_and(|s| s.ends_with(".mcap") || s.ends_with(".mcap.part")))
        .collect()
}

/// The first MCAP recording in `dir`, by name.
pub fn first_recording(dir: &std::path::Path) -> std::path::PathBuf {
    files_in(dir).into_iter().find(|p| p.extension().is_some_and(|x| x == "mcap")).expect("an mcap file")
}

/// The repository's root (fixtures and configs are found from it).
pub fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A file of the repository, by its path from the root.
pub fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// `forgemon demo --fast --billets N` recorded into `dir/name`, then `forgemon teach` on that
/// recording: the recording and the recipe file written next to it (`dir/flange.recipe.toml`).
pub fn demo_and_teach(dir: &std::path::Path, name: &str, billets: usize) -> (std::path::PathBuf, std::path::PathBuf) {
    let bin = env!("CARGO_BIN_EXE_forgemon");
    let rec = dir.join(name);
    let out = std::process::Command::new(bin)
        .args(["demo", "--fast", "--billets", &billets.to_string(), "--dir"])
        .arg(&rec)
        .output()
        .expect("demo runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mcap = files_in(&rec).into_iter().find(|p| p.extension().is_some_and(|x| x == "mcap")).expect("an mcap file");
    let recipe = dir.join("flange.recipe.toml");
    let out = std::process::Command::new(bin)
        .args(["teach", "--machine"])
        .arg(root().join("config/hammer-lg1000.machine.toml"))
        .arg("--reference")
        .arg(&mcap)
        .arg("-o")
        .arg(&recipe)
        .output()
        .expect("teach runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    (mcap, recipe)
}

/// The demo's hammer (LG1000) and steel sheet, as the service gets them (`daemon::serve`):
/// `config` recording under `dir`, a source that may wait for the service.
pub fn demo_hammer_parts(
    dir: &std::path::Path,
    config: forgemon::config::service::ServiceConfig,
) -> forgemon::daemon::ServiceParts {
    let (machine_text, steel) =
        (read("config/hammer-lg1000.machine.toml"), read("config/steel-16NiCrMo13.process.toml"));
    forgemon::daemon::ServiceParts {
        config,
        config_path: dir.join("service.toml"),
        config_text: String::new(),
        machine: parse_machine("m", &machine_text).expect("machine").machine,
        effects: forgemon::physics::EffectSet::NONE,
        machine_text,
        process: Some(parse_process("p", &steel).expect("process")),
        process_text: Some(steel),
        backpressure: forgemon::acquire::Backpressure::Wait,
    }
}

/// `p` with its flow stress scaled by `factor` (a colder or warmer billet of the same sheet).
pub fn with_flow_stress(mut p: Process, factor: f64) -> Process {
    p.material = p.material.scaled(factor);
    p
}

/// What in the blow lines `blows` (docs/interfaces.md §5 JSON, in order) lies outside its physical
/// range (issue 36): energies below 0, an efficiency outside [0, 1], a non-positive impact
/// speed, a height at or below 0, a start height above the billet's first (the billet only
/// gets flatter), an end height above the start; an incomplete or implausible blow with any
/// energy, and an implausible one without its reason. One line per finding, naming the blow.
pub fn out_of_range(blows: &[serde_json::Value]) -> Vec<String> {
    let mut bad = Vec::new();
    let mut first_height: std::collections::BTreeMap<u64, f64> = Default::default();
    let num = |b: &serde_json::Value, k: &str| b.get(k).and_then(serde_json::Value::as_f64);
    for b in blows {
        let n = &b["blow"];
        let mut say = |what: String| bad.push(format!("blow {n}: {what}"));
        let class = b["class"].as_str().unwrap_or("");
        if !["soft", "intermediate", "hard", "incomplete", "implausible"].contains(&class) {
            say(format!("class {class:?}"));
        }
        let energies = ["kinetic_in_J", "plastic_J", "friction_J", "damped_J", "elastic_J", "efficiency"];
        if class == "incomplete" || class == "implausible" {
            for k in energies.iter().filter(|k| !b[**k].is_null()) {
                say(format!("{class} with {k} {}", b[*k]));
            }
        }
        if (class == "implausible") != b["reason"].is_string() {
            say(format!("class {class} with reason {}", b["reason"]));
        }
        for k in &energies[..5] {
            if let Some(j) = num(b, k).filter(|j| j.is_nan() || *j < 0.0) {
                say(format!("{k} {j} < 0"));
            }
        }
        if let Some(e) = num(b, "efficiency").filter(|e| !(0.0..=1.0).contains(e)) {
            say(format!("efficiency {e} outside [0, 1]"));
        }
        if !num(b, "v_impact_mps").is_some_and(|v| v > 0.0) {
            say(format!("impact speed {}", b["v_impact_mps"]));
        }
        let (h0, h1) = (num(b, "h_start_m"), num(b, "h_end_m"));
        let billet = b["billet"].as_u64().unwrap_or(0);
        if let Some(h0) = h0 {
            let top = *first_height.entry(billet).or_insert(h0);
            if !(h0 > 0.0 && h0 <= top) {
                say(format!("start height {h0} m outside (0, {top}]"));
            }
        }
        if let Some(h1) = h1
            && !(h1 > 0.0 && h0.is_none_or(|h0| h1 <= h0))
        {
            say(format!("end height {h1} m outside (0, start {h0:?}]"));
        }
    }
    bad
}

/// A `service.toml` in `dir` for `forgemon run`: the example hammer, recording to `dir/rec`,
/// the HTTP server on loopback port `http` with the lines `http_extra` in its table, then
/// the tables `extra`, and one serial source on a tty that does not exist (the service waits
/// for it and serves meanwhile).
pub fn service_toml(dir: &std::path::Path, http: u16, http_extra: &str, extra: &str) -> std::path::PathBuf {
    let machine = root().join("config/hammer-lg1000.machine.toml");
    let cfg = format!(
        r#"machine = "{}"
[recording]
dir = "rec"
[http]
listen = "127.0.0.1:{http}"
{http_extra}
{extra}
[[sources]]
name = "daq"
kind = "serial"
path = "{}"
[[sources.channels]]
role = "load_N"
gain = 1.0
[[sources.channels]]
role = "disp_m"
gain = 1.0
[[sources.channels]]
role = "acc_mps2"
gain = 1.0
"#,
        machine.display(),
        dir.join("no-such-tty").display()
    );
    let path = dir.join("service.toml");
    std::fs::write(&path, cfg).unwrap();
    path
}

/// `text` written to `path` readable by its owner only (mode 0600), as a token file must be.
pub fn write_private(path: &std::path::Path, text: &str) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::write(path, text).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600)).unwrap();
}

/// What a held client connection shows: closed by the server, or still open.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Held {
    /// The server closed it (end of stream or reset).
    Closed,
    Open,
}

/// Whether the server closed `s`, reading (and discarding) what it sent for up to `wait`.
pub fn held(s: &mut std::net::TcpStream, wait: std::time::Duration) -> Held {
    use std::io::{ErrorKind, Read};
    let deadline = std::time::Instant::now() + wait;
    let mut buf = [0u8; 4096];
    loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return Held::Open;
        }
        s.set_read_timeout(Some(left.max(std::time::Duration::from_millis(1)))).unwrap();
        match s.read(&mut buf) {
            Ok(0) => return Held::Closed,
            Ok(_) => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted) => {}
            Err(_) => return Held::Closed,
        }
    }
}
