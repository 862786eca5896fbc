//! The systemd unit (issue #4): `systemd-analyze verify` is clean and
//! `systemd-analyze security --offline=yes` rates its exposure at 2.0 or less. `.ci/run`
//! installs systemd-analyze (Debian's `systemd`) where it is missing; without it the tests
//! fail saying so, rather than passing without having checked anything.
//!
//! Issue 39: the unit's `LimitNOFILE` holds every server's default connection cap (read
//! from the code, `DEFAULT_CONNECTION_CAPS`) with room for the service's own descriptors;
//! without it systemd's default of 1 024 let hostile clients starve `/status`.

use std::process::Command;

const UNIT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/systemd/forgemon.service");

fn analyze() -> Command {
    let found = Command::new("systemd-analyze").arg("--version").output().is_ok_and(|o| o.status.success());
    assert!(found, "systemd-analyze is not installed: run `bash .ci/run`, or `apt-get install systemd`");
    Command::new("systemd-analyze")
}

#[test]
fn the_unit_verifies_clean() {
    let mut cmd = analyze();
    // Verify a copy whose ExecStart is the binary this build made (nothing is installed).
    let dir = std::env::temp_dir().join(format!("forgemon-unit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let unit = dir.join("forgemon.service");
    let text = std::fs::read_to_string(UNIT).unwrap().replace("/usr/bin/forgemon", env!("CARGO_BIN_EXE_forgemon"));
    std::fs::write(&unit, text).unwrap();
    let out = cmd.arg("verify").arg(&unit).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.trim().is_empty(), "systemd-analyze verify: {err}");
}

#[test]
fn the_unit_is_hardened_to_an_exposure_of_two_or_less() {
    let mut cmd = analyze();
    let out = cmd.args(["security", "--offline=yes", UNIT]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.contains("Overall exposure level"))
        .unwrap_or_else(|| panic!("no exposure line: {text}"));
    let level: f64 =
        line.split(':').nth(1).and_then(|r| r.split_whitespace().next()).and_then(|v| v.parse().ok()).unwrap();
    // DESIGN.md §5 and issue #4: exposure <= 2.0.
    assert!(level <= 2.0, "{line}");
}

/// Descriptors the service needs besides its clients: the recording, the sources, the
/// runtime, the listeners, with a margin.
const OWN_DESCRIPTORS: u64 = 256;

#[test]
fn the_descriptor_limit_holds_the_default_connection_caps() {
    use forgemon::config::server_limits::DEFAULT_CONNECTION_CAPS;
    let text = std::fs::read_to_string(UNIT).unwrap();
    let limits: Vec<&str> = text.lines().filter_map(|l| l.trim().strip_prefix("LimitNOFILE=")).map(str::trim).collect();
    assert_eq!(limits.len(), 1, "one LimitNOFILE= line in the unit: {limits:?}");
    // `N` or `SOFT:HARD`: the soft limit is what the service gets.
    let soft: u64 = limits[0].split(':').next().and_then(|n| n.parse().ok()).expect("LimitNOFILE is a number");
    let caps: u64 = DEFAULT_CONNECTION_CAPS.iter().map(|(_, n)| n).sum();
    assert!(
        soft >= caps + OWN_DESCRIPTORS,
        "LimitNOFILE={soft} < {caps} ({DEFAULT_CONNECTION_CAPS:?}) + {OWN_DESCRIPTORS}"
    );
}
