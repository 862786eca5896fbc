//! Issue 40, against the service (`forgemon run`) and a real pty: a serial port that cannot
//! be opened is logged at warn level with its path and cause, once and not at every retry,
//! and at info level when it opens; a path the system has given to another pty is not
//! reopened. Before, the only log line with the port absent was "forgemon service ready",
//! and after a simulated device exited the service read the next process's pty at its path.
//!
//! The configured path is a symlink the test points at a pty (a pty's own path is the
//! kernel's to choose): `service_toml`'s `dir/no-such-tty`.

mod common;

use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use common::{free_port, http_get, service_toml, spawn_service_logging};
use tokio_serial::SerialPort;

/// A pty pair: (master, slave, the slave's path), on a runtime left running.
fn pty() -> (tokio_serial::SerialStream, tokio_serial::SerialStream, String) {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let _g = rt.enter();
    let (master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let name = slave.name().expect("the pty slave has a path");
    std::mem::forget(rt);
    (master, slave, name)
}

fn log_lines(log: &Path, containing: &str) -> Vec<String> {
    std::fs::read_to_string(log)
        .unwrap_or_default()
        .lines()
        .filter(|l| l.contains(containing))
        .map(String::from)
        .collect()
}

/// Wait up to 10 s for a log line containing `text`.
fn wait_for_line(log: &Path, text: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Some(l) = log_lines(log, text).pop() {
            return l;
        }
        assert!(Instant::now() < deadline, "no line with {text:?} in\n{}", std::fs::read_to_string(log).unwrap());
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn source_status(http: u16) -> serde_json::Value {
    let body = http_get(http, "/status").expect("the status answers");
    serde_json::from_str::<serde_json::Value>(&body).unwrap()["sources"]["daq"].clone()
}

struct Service {
    child: Child,
    http: u16,
    log: std::path::PathBuf,
    tty: std::path::PathBuf,
    _dir: tempfile::TempDir,
}

impl Drop for Service {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start() -> Service {
    let dir = tempfile::tempdir().unwrap();
    let http = free_port();
    let cfg = service_toml(dir.path(), http, "", "");
    let log = dir.path().join("service.log");
    let child = spawn_service_logging(&cfg, http, Stdio::from(std::fs::File::create(&log).unwrap()));
    let tty = dir.path().join("no-such-tty");
    Service { child, http, log, tty, _dir: dir }
}

/// Over 3 s of retries (backoff 50 ms doubling to 1 s: some seven attempts) the missing
/// port is logged once, at warn level, with its path and the system's cause; when the path
/// leads to a pty, the source connects and that is logged at info level.
#[test]
fn a_missing_port_is_logged_once_with_its_path_and_cause_and_again_when_it_opens() {
    let svc = start();
    std::thread::sleep(Duration::from_secs(3));
    let path = svc.tty.display().to_string();
    let failed = log_lines(&svc.log, "cannot open");
    assert_eq!(failed.len(), 1, "{}", std::fs::read_to_string(&svc.log).unwrap());
    assert!(failed[0].contains("WARN") && failed[0].contains(&path), "{}", failed[0]);
    assert!(failed[0].contains("No such file or directory"), "{}", failed[0]);
    assert_eq!(source_status(svc.http)["state"], "reconnecting");
    let (_master, _slave, name) = pty();
    std::os::unix::fs::symlink(&name, &svc.tty).unwrap();
    let back = wait_for_line(&svc.log, "is open again");
    assert!(back.contains("INFO") && back.contains(&path), "{back}");
    assert_eq!(source_status(svc.http)["state"], "connected");
    assert_eq!(log_lines(&svc.log, "cannot open").len(), 1, "still the one warning");
}

/// The device exits (its pty closes) and the path comes to lead to another pty, as when
/// the system hands the number to the next process: refused, named in the log and in
/// /status, and the source stays "reconnecting" (it does not read the other pty).
#[test]
fn a_pty_path_given_to_another_process_is_not_reopened() {
    let svc = start();
    let (master, slave, first) = pty();
    std::os::unix::fs::symlink(&first, &svc.tty).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while source_status(svc.http)["state"] != "connected" {
        assert!(Instant::now() < deadline, "never connected: {}", source_status(svc.http));
        std::thread::sleep(Duration::from_millis(50));
    }
    // Opened once (the first attempts, before the symlink, failed).
    wait_for_line(&svc.log, "is open again");
    // The device exits: its pty closes.
    drop(master);
    drop(slave);
    wait_for_line(&svc.log, "link lost");
    // Another process's pty at the path (often the very same /dev/pts number).
    let (_other_master, _other_slave, other) = pty();
    std::fs::remove_file(&svc.tty).unwrap();
    std::os::unix::fs::symlink(&other, &svc.tty).unwrap();
    let refused = wait_for_line(&svc.log, "refused");
    assert!(refused.contains("WARN") && refused.contains("is there now, not the device first opened"), "{refused}");
    eprintln!("first {first}, then {other}: {refused}");
    // For two seconds of retries it stays refused.
    let until = Instant::now() + Duration::from_secs(2);
    while Instant::now() < until {
        let st = source_status(svc.http);
        assert_eq!(st["state"], "reconnecting", "{st}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let st = source_status(svc.http);
    assert!(st["detail"].as_str().is_some_and(|d| d.contains("refused")), "{st}");
    assert_eq!(log_lines(&svc.log, "is open again").len(), 1, "{}", std::fs::read_to_string(&svc.log).unwrap());
}
