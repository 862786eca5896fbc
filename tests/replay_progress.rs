//! `forgemon replay DIR` over a rotated run (issue 42): the files stream in name order as
//! one run, read ahead in parallel or in turn with the same output, and a terminal shows
//! the progress.
//!
//! The run is the fast demo's recording of two billets, written again by the recorder with a
//! rotation every 4 MiB, so its files are a rotated run as the service leaves one (each
//! opening with the configuration again). The terminal is a real pty: the replay's
//! stderr on its slave, its stdout on a file, as `forgemon replay DIR > day.jsonl` is typed.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use forgemon::record::{RecordReader, RecordWriter, Rotation};

const BIN: &str = env!("CARGO_BIN_EXE_forgemon");

fn replay(args: &[&Path]) -> Output {
    let out = Command::new(BIN).arg("replay").args(args).arg("--json").output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    out
}

/// The demo's recording of two billets, and the same messages rotated every 4 MiB.
fn demo_and_rotated(dir: &Path) -> (PathBuf, Vec<PathBuf>) {
    let demo = dir.join("demo");
    let out = Command::new(BIN).args(["demo", "--fast", "--billets", "2", "--dir"]).arg(&demo).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let file = std::fs::read_dir(&demo)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let run = dir.join("run");
    std::fs::create_dir_all(&run).unwrap();
    let mut w = RecordWriter::create(run.join("forgemon.mcap"), Rotation::by_size(4 << 20)).unwrap();
    for m in RecordReader::open(&file).unwrap() {
        let m = m.unwrap();
        w.write_payload(m.log_time_ns, &m.payload).unwrap();
    }
    let files = w.finish().unwrap();
    (file, files)
}

/// Run `command` with its stderr on a pty and its stdout into `stdout`; what the pty showed.
fn on_terminal_stderr(command: &[&str], stdout: &Path) -> String {
    const PY: &str = r#"
import os, pty, subprocess, sys
master, slave = pty.openpty()
with open(sys.argv[1], "wb") as out:
    p = subprocess.Popen(sys.argv[2:], stdout=out, stderr=slave, stdin=subprocess.DEVNULL)
os.close(slave)
seen = b""
while True:
    try:
        chunk = os.read(master, 65536)
    except OSError:
        break
    if not chunk:
        break
    seen += chunk
sys.stdout.buffer.write(seen)
sys.exit(p.wait())
"#;
    let out = Command::new("python3").args(["-c", PY]).arg(stdout).args(command).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn a_rotated_run_replays_as_its_one_file_with_its_progress_on_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let (file, files) = demo_and_rotated(dir.path());
    assert!(files.len() >= 3, "the run has {} files; the rotation is to make several", files.len());
    let run = dir.path().join("run");
    let whole = replay(&[&file]);
    let rotated = replay(&[&run]);
    let blows = whole.stdout.iter().filter(|&&c| c == b'\n').count();
    assert!(blows >= 16, "the demo's two billets gave {blows} blows");
    assert!(whole.stdout == rotated.stdout, "the rotated run's blows differ from its one file's");
    // The chunks read ahead and unpacked on other threads, or each in turn: the same bytes.
    let sequential = Command::new(BIN).arg("replay").arg(&run).args(["--json", "--sequential"]).output().unwrap();
    assert!(sequential.status.success(), "{}", String::from_utf8_lossy(&sequential.stderr));
    assert!(sequential.stdout == rotated.stdout, "--sequential printed other blows than the parallel read");
    // Without a terminal on stderr, no bar: only the closing line.
    let err = String::from_utf8_lossy(&rotated.stderr);
    assert!(!err.contains("eta"), "a bar without a terminal: {err}");

    let jsonl = dir.path().join("day.jsonl");
    let shown = on_terminal_stderr(&[BIN, "replay", run.to_str().unwrap(), "--json"], &jsonl);
    assert!(std::fs::read(&jsonl).unwrap() == whole.stdout, "the output under the bar differs");
    assert!(shown.contains("replay ") && shown.contains("eta"), "no progress bar on the terminal: {shown:?}");
    let total: u64 = files.iter().map(|f| std::fs::metadata(f).unwrap().len()).sum();
    let total_mib = format!("{:.2} MiB", total as f64 / (1 << 20) as f64);
    assert!(shown.contains(&total_mib), "the bar does not count the run's {total_mib}: {shown:?}");
    assert!(shown.contains("forgemon-0000"), "the bar does not name the file being read: {shown:?}");
    assert!(shown.contains("forgemon: replayed "), "the closing line is gone: {shown:?}");
}
