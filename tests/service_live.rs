//! The service end to end (issue #4): the demo (a simulated hammer streaming the serial
//! framing over a pty into the real service) records its live results, and replaying that
//! recording gives the identical per-blow JSON; every blow of the simulated session is found.
//! Both drive the one session core (`forgemon::session`), so the replay's own recording
//! holds the same results, alerts and billet summaries as the live one.

mod common;

use std::process::Command;

use forgemon::record::{Payload, read_recording};

const HAMMER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/hammer-lg1000.machine.toml");

#[test]
fn live_equals_replay_over_a_pty() {
    let dir = std::env::temp_dir().join(format!("forgemon-live-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["demo", "--fast", "--billets", "2", "--interval", "0.3", "--dir", dir.to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "demo failed: {stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let file = common::first_recording(&dir);
    // The live results, as the service recorded them.
    let rec = read_recording(&file).unwrap();
    assert!(rec.report.complete);
    let live: Vec<String> = rec
        .messages
        .iter()
        .filter_map(|m| match &m.payload {
            Payload::Result(r) => Some(serde_json::to_string(r).unwrap()),
            _ => None,
        })
        .collect();
    // Two billets of eight blows (the demo's plan): every blow found, none extra.
    assert_eq!(live.len(), 16, "{stdout}");
    // Both billets end in hard blows, and each raises the elastic-blow alert once.
    assert_eq!(rec.messages.iter().filter(|m| matches!(m.payload, Payload::Alert(_))).count(), 2);
    let again = dir.join("replayed.mcap");
    let replay = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["replay", file.to_str().unwrap(), "--machine", HAMMER, "--json", "--out", again.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(replay.status.success(), "{}", String::from_utf8_lossy(&replay.stderr));
    let replayed: Vec<String> = String::from_utf8(replay.stdout).unwrap().lines().map(String::from).collect();
    assert_eq!(replayed, live, "replaying the live recording gives the live results");
    // What each recording holds, in order: results, alerts, billet summaries, new-billet
    // markers (log times apart: live stamps arrival, a replay the device's clock).
    let outcomes = |path: &std::path::Path| -> Vec<String> {
        read_recording(path)
            .unwrap()
            .messages
            .into_iter()
            .filter_map(|m| match m.payload {
                Payload::Result(r) => Some(format!("{r:?}")),
                Payload::Alert(a) => Some(format!("{a:?}")),
                Payload::Billet(b) => Some(format!("{b:?}")),
                Payload::Status(s) if s.source == "control" => Some(format!("{s:?}")),
                _ => None,
            })
            .collect()
    };
    let (a, b) = (outcomes(&file), outcomes(&again));
    assert_eq!(a.len(), 16 + 2 + 2, "16 results, 2 alerts, 2 billets (found by the billet detector): {a:#?}");
    assert_eq!(a, b, "the replay records what the live run recorded");
    let _ = std::fs::remove_dir_all(&dir);
}
