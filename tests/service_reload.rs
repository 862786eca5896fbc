//! Issue 39: a SIGHUP reload says the truth. The real service (`forgemon run`) is sent
//! SIGHUP after its file is edited: with `machine` naming a file that does not exist (and
//! an alert rule changed beside it) nothing is taken, the log and `/status` say why, and the
//! recording holds no new machine or service file; with `[http] listen` changed (and the
//! alert rule again) the rule is taken and `http.listen` is named as needing a restart, while
//! the service still answers on its old address.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{KillOnDrop, free_port, http_get, spawn_service_logging};
use forgemon::record::{Payload, RecordReader};

const HAMMER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/hammer-lg1000.machine.toml");

/// The service file: `machine`, the status endpoint on `http`, `low_efficiency`, recording
/// under `rec`, and a serial source whose device is absent (the service waits for it).
fn service_text(dir: &Path, machine: &str, http: u16, low_efficiency: f64) -> String {
    format!(
        r#"machine = "{machine}"
[recording]
dir = "rec"
[http]
listen = "127.0.0.1:{http}"
[alerts]
low_efficiency = {low_efficiency}
[[sources]]
name = "daq"
kind = "serial"
path = "{absent}"
[[sources.channels]]
role = "load_N"
gain = 1.0
[[sources.channels]]
role = "disp_m"
gain = 1e-6
[[sources.channels]]
role = "acc_mps2"
gain = 1e-3
"#,
        absent = dir.join("no-such-tty").display()
    )
}

fn status(port: u16) -> serde_json::Value {
    serde_json::from_str(&http_get(port, "/status").expect("/status answers")).expect("json")
}

/// Wait until `f` holds on the status (10 s at most).
fn wait_status(port: u16, what: &str, f: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let s = status(port);
        if f(&s) {
            return s;
        }
        assert!(Instant::now() < deadline, "{what}: {s}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// SIGHUP to `pid`, and the `/status` `reload` object once it is a new one.
fn sighup(pid: u32, port: u16) -> serde_json::Value {
    let before = status(port)["reload"]["at_unix_s"].clone();
    assert!(Command::new("kill").args(["-HUP", &pid.to_string()]).status().expect("kill").success());
    wait_status(port, "a new reload", |s| !s["reload"].is_null() && s["reload"]["at_unix_s"] != before)["reload"]
        .clone()
}

/// The names of the config files the recording in `dir` holds, in order.
fn recorded_configs(dir: &Path) -> Vec<String> {
    common::files_in(dir)
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .flat_map(|p| RecordReader::open(p).expect("a recording"))
        .filter_map(|m| match m.ok()?.payload {
            Payload::Config(c) => Some(c.name),
            _ => None,
        })
        .collect()
}

#[test]
fn a_reload_with_a_missing_machine_file_takes_nothing_and_a_new_listen_address_needs_a_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg: PathBuf = dir.path().join("service.toml");
    let http = free_port();
    std::fs::write(&cfg, service_text(dir.path(), HAMMER, http, 0.5)).expect("write");
    let log = dir.path().join("service.log");
    let mut child =
        KillOnDrop(spawn_service_logging(&cfg, http, Stdio::from(std::fs::File::create(&log).expect("log"))));
    // The event loop (and its SIGHUP handler) runs once the recording is named.
    wait_status(http, "the loop", |s| s["recording"].as_str().is_some_and(|r| !r.is_empty()));
    assert!(status(http)["reload"].is_null(), "no reload yet");

    let missing = dir.path().join("adopted.machine.toml");
    std::fs::write(&cfg, service_text(dir.path(), &missing.display().to_string(), http, 0.6)).expect("write");
    let r = sighup(child.0.id(), http);
    let error = r["error"].as_str().unwrap_or_default();
    assert!(error.contains("adopted.machine.toml") && error.contains("key 'machine'"), "{r}");
    assert_eq!(
        (r["applied"].as_array().map(Vec::len), r["needs_restart"].as_array().map(Vec::len)),
        (Some(0), Some(0))
    );

    let other = free_port();
    std::fs::write(&cfg, service_text(dir.path(), HAMMER, other, 0.6)).expect("write");
    let r = sighup(child.0.id(), http);
    assert_eq!(r["error"], serde_json::Value::Null, "{r}");
    assert_eq!(r["applied"], serde_json::json!(["alerts"]), "{r}");
    assert_eq!(r["needs_restart"], serde_json::json!(["http.listen"]), "{r}");
    assert!(http_get(other, "/status").is_none(), "the new address is not listened on before a restart");
    assert_eq!(status(http)["machine"], "hammer", "the old address still answers");

    assert!(Command::new("kill").args(["-TERM", &child.0.id().to_string()]).status().expect("kill").success());
    assert!(child.0.wait().expect("wait").success());
    let log = std::fs::read_to_string(&log).expect("the log");
    assert!(log.contains("nothing reloaded") && log.contains("adopted.machine.toml"), "{log}");
    assert!(log.contains("taken only at a restart: http.listen"), "{log}");
    // The start's machine and service files and its part trace, then only the service file of the second
    // reload (its alert rule taken): the failed reload recorded nothing.
    let configs = recorded_configs(&dir.path().join("rec"));
    assert_eq!(configs, ["machine.toml", "service.toml", "part.toml", "service.toml"], "{configs:?}");
}
