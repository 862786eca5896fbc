//! Replay against its anchor (issue 42): `forgemon replay FILE --json` on a demo recording
//! (by default 10 billets: 80 blows, 3 channels at 100 kHz, about 12 M samples and 100 MB),
//! against the `mcap` crate's own read of the same file in this process (the file read
//! into memory and every message of every chunk iterated by `MessageStream`, payloads not
//! decoded). Each round times the anchor, the parallel replay and `replay --sequential`
//! one after the other; the figures are the best of the rounds, the noise their spread.
//!
//! Prints the ratio anchor time / replay time: ≥ 1.0 means replay keeps up with a raw read
//! of the file. Checks that the parallel and sequential replays print the same bytes.
//!
//! `cargo bench --bench replay`; `FORGEMON_BENCH_BILLETS` (default 10) sets the recording's
//! size, `FORGEMON_BENCH_ROUNDS` (default 5) the rounds. The recording is made once by
//! `forgemon demo --fast` and kept in `target/bench-data/`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_forgemon");

fn env_or(key: &str, default: usize) -> usize {
    std::env::var(key).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The demo's recording of `billets` billets, made once.
fn recording(billets: usize) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("target/bench-data/demo-{billets}"));
    let found = |dir: &Path| -> Option<PathBuf> {
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .ok()?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            .collect();
        files.sort();
        (files.len() == 1).then(|| files.remove(0))
    };
    if let Some(file) = found(&dir) {
        return file;
    }
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!("making the demo recording of {billets} billets in {} ...", dir.display());
    let status = Command::new(EXE)
        .args(["demo", "--fast", "--billets", &billets.to_string(), "--dir"])
        .arg(&dir)
        .stdout(Stdio::null())
        .status()
        .expect("run forgemon demo");
    assert!(status.success(), "forgemon demo failed");
    found(&dir).unwrap_or_else(|| panic!("{}: not one .mcap file (rotated?)", dir.display()))
}

/// The `mcap` crate's read of `file`: its messages, and the payload bytes of its samples.
fn raw_read(file: &Path) -> (usize, usize) {
    let bytes = std::fs::read(file).expect("read the recording");
    let (mut messages, mut payload) = (0, 0);
    for m in mcap::MessageStream::new(&bytes).expect("mcap") {
        let m = m.expect("message");
        messages += 1;
        if m.channel.topic.starts_with("/samples/") {
            payload += m.data.len();
        }
    }
    (messages, payload)
}

/// `forgemon replay FILE --json` (plus `extra`): its standard output.
fn replay(file: &Path, extra: &[&str]) -> Vec<u8> {
    let out = Command::new(EXE).arg("replay").arg(file).arg("--json").args(extra).output().expect("run replay");
    assert!(out.status.success(), "replay failed: {}", String::from_utf8_lossy(&out.stderr));
    out.stdout
}

fn timed<T>(f: impl FnOnce() -> T) -> (Duration, T) {
    let t = Instant::now();
    let v = f();
    (t.elapsed(), v)
}

/// Best of `times` and their spread over it.
fn best(times: &[Duration]) -> (f64, f64) {
    let s: Vec<f64> = times.iter().map(Duration::as_secs_f64).collect();
    let lo = s.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = s.iter().copied().fold(0.0, f64::max);
    (lo, (hi - lo) / lo)
}

fn main() {
    // `cargo bench` passes `--bench`; a test run (`cargo test --benches`) passes nothing.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    let billets = env_or("FORGEMON_BENCH_BILLETS", 10);
    let rounds = env_or("FORGEMON_BENCH_ROUNDS", 5).max(1);
    let file = recording(billets);
    let size_mb = std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0) as f64 / 1e6;
    let (mut raw, mut par, mut seq) = (Vec::new(), Vec::new(), Vec::new());
    let mut counted = (0, 0);
    let mut outputs = None;
    for _ in 0..rounds {
        let (t, n) = timed(|| raw_read(&file));
        raw.push(t);
        counted = n;
        let (t, a) = timed(|| replay(&file, &[]));
        par.push(t);
        let (t, b) = timed(|| replay(&file, &["--sequential"]));
        seq.push(t);
        assert!(a == b, "the parallel and sequential replays printed different output");
        outputs = Some(a);
    }
    let blows = outputs.as_deref().map_or(0, |o| o.iter().filter(|&&c| c == b'\n').count());
    let (raw_s, raw_noise) = best(&raw);
    let (par_s, par_noise) = best(&par);
    let (seq_s, seq_noise) = best(&seq);
    // Three f64 a sample (the protobuf framing is a few bytes a batch).
    let samples = counted.1 as f64 / 24.0;
    println!(
        "replay bench: {} ({size_mb:.0} MB, {} messages, about {:.1} M samples of 3 f64, {blows} blows), best of {rounds} rounds",
        file.display(),
        counted.0,
        samples / 1e6
    );
    println!("  anchor, mcap MessageStream read: {raw_s:.3} s (spread {:.0} %)", raw_noise * 100.0);
    println!(
        "  replay --json, parallel read:    {par_s:.3} s (spread {:.0} %): ratio to the anchor {:.2}",
        par_noise * 100.0,
        raw_s / par_s
    );
    println!(
        "  replay --json --sequential:      {seq_s:.3} s (spread {:.0} %): ratio to the anchor {:.2}",
        seq_noise * 100.0,
        raw_s / seq_s
    );
    println!("  parallel against sequential: {:.2}×; outputs byte-identical in every round", seq_s / par_s);
}
