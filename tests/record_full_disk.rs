//! A recording on a disk that fills up and is freed again: the recorder suspends, drops and
//! counts, leaves no empty file, and resumes once there is room. The disk is a real tmpfs of
//! a few MB, mounted in a private mount namespace (`unshare --user --map-root-user --mount`)
//! so that no privilege is needed and nothing outside sees it; a ballast file fills it and
//! is deleted to free it.
//!
//! - The writer itself, rotating every second of log time, runs in a child process of this
//!   test binary inside the namespace (`child_writer`): exact accounting of every message.
//! - `forgemon demo` runs inside one in real time, watched through `/status`, and the
//!   ballast is deleted through `/proc/PID/root` while it runs.
//! - `forgemon demo --fast` on a disk that stays full still prints its summary.
//!
//! Where the kernel allows no user namespaces, each test says it was skipped.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{free_port, http_get};
use forgemon::estimate::BlowEstimate;
use forgemon::record::{Payload, RecordOptions, RecordWriter, Rotation, read_recording};
use forgemon::signal::sample::{Role, SampleBatch};

const BIN: &str = env!("CARGO_BIN_EXE_forgemon");
/// Set in the child: the tmpfs mount point it writes under.
const CHILD_ENV: &str = "FORGEMON_FULL_DISK_CHILD";

/// Whether this kernel lets an unprivileged process mount a tmpfs in its own namespace.
fn namespaces_work() -> bool {
    let ok = Command::new("unshare")
        .args(["--user", "--map-root-user", "--mount", "sh", "-c", "mount -t tmpfs -o size=1m tmpfs /mnt"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        println!("skipped: no unprivileged user and mount namespaces here (unshare failed)");
    }
    ok
}

/// `sh -c script` in a private mount namespace in which `mnt` is a tmpfs of `mb` MB.
fn in_tmpfs(mnt: &Path, mb: u32, script: &str) -> Command {
    let mut c = Command::new("unshare");
    c.args(["--user", "--map-root-user", "--mount", "sh", "-c"])
        .arg(format!("mount -t tmpfs -o size={mb}m tmpfs '{}' && {script}", mnt.display()));
    c
}

/// 100 ms of three channels at 100 kHz, in values zstd cannot shrink much.
fn batch(k: u64, state: &mut u64) -> SampleBatch {
    let values = (0..30_000)
        .map(|_| {
            *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (*state >> 11) as f64
        })
        .collect();
    SampleBatch {
        source: "daq".into(),
        seq: k,
        device_time_ns: (k * 100_000_000) as i64,
        host_time_ns: (1_000_000_000 + k * 100_000_000) as i64,
        period_ns: 10_000.0,
        roles: vec![Role::Load, Role::Disp, Role::Acc],
        values,
    }
}

/// The child's stream: a 100 ms batch at a time, a blow result after every tenth; what it
/// wrote, message by message (configuration files aside).
#[derive(Default)]
struct Feed {
    k: u64,
    rng: u64,
    batches: u64,
    results: u64,
}

impl Feed {
    fn step(&mut self, w: &mut RecordWriter) {
        let b = batch(self.k, &mut self.rng);
        let _ = w.write_samples(&b);
        self.batches += 1;
        if self.k % 10 == 9 {
            let t = self.k as f64 * 0.1;
            let e = BlowEstimate::incomplete((self.k / 10) as u32 + 1, t, 4.0, t + 0.05);
            let _ = w.write_result(b.host_time_ns, &e);
            self.results += 1;
        }
        self.k += 1;
    }
}

/// The child: a recording under `mnt` (a 16 MB tmpfs) rotating every second of log time;
/// the ballast fills the disk, then goes.
fn child_writer(mnt: &Path) {
    let ballast = mnt.join("ballast");
    std::fs::write(&ballast, vec![1u8; 10 << 20]).unwrap();
    let dir = mnt.join("rec");
    let options = RecordOptions {
        rotation: Rotation::by_duration_ns(1_000_000_000),
        chunk_size_bytes: 256 << 10,
        ..RecordOptions::default()
    };
    let mut w = RecordWriter::create_with(&dir, options).unwrap();
    w.write_config(1_000_000_000, "machine.toml", "kind = \"hammer\"\n").unwrap();
    let mut feed = Feed { rng: 7, ..Feed::default() };
    // About 6 MB free: full within 60 batches of 720 kB.
    while w.health().state == "recording" {
        assert!(feed.k < 200, "the disk never filled");
        feed.step(&mut w);
    }
    // Two seconds of log time on the full disk. A retry may find the room the given-up
    // file's unsynced tail freed, and fill it; none leaves an empty file behind.
    for _ in 0..20 {
        feed.step(&mut w);
    }
    let files = recording_files(&dir);
    let suspensions = w.health().suspensions;
    let parts = files.iter().filter(|f| f.to_string_lossy().ends_with(".part")).count() as u64;
    assert!(parts <= suspensions, "{suspensions} suspensions left {parts} given-up files: {files:?}");
    assert_no_empty_file(&files);
    std::fs::remove_file(&ballast).unwrap();
    let freed_at = feed.k;
    while w.health().state == "suspended" {
        feed.step(&mut w);
        // The longest backoff is 2 s of log time: 20 batches, and one more to retry.
        assert!(feed.k - freed_at <= 21, "not resumed {} batches after the disk was freed", feed.k - freed_at);
    }
    // Three more rotations on the freed disk.
    for _ in 0..35 {
        feed.step(&mut w);
    }
    let health = w.health();
    assert_eq!(health.state, "recording");
    w.finish().unwrap();
    let files = recording_files(&dir);
    assert_no_empty_file(&files);
    let (mut batches, mut results) = (0u64, 0u64);
    for f in &files {
        let rec = read_recording(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(!rec.report.is_corrupt(), "{}: {:?}", f.display(), rec.report);
        batches += rec.messages.iter().filter(|m| matches!(m.payload, Payload::Samples(_))).count() as u64;
        results += rec.messages.iter().filter(|m| matches!(m.payload, Payload::Result(_))).count() as u64;
    }
    // Every message is either in a file or counted as dropped, and the blows with them.
    assert_eq!(batches + results + health.dropped_messages, feed.batches + feed.results, "{health:?}");
    assert_eq!(results + health.dropped_blows, feed.results, "{health:?}");
    assert!(health.dropped_blows > 0 && results > 0, "{health:?}");
    println!("child: {} files, {batches} batches and {results} blows kept, {health:?}", files.len());
}

fn recording_files(dir: &Path) -> Vec<PathBuf> {
    // The history database lives there too (`history.sqlite`, its WAL beside it).
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("history.sqlite")))
        .collect();
    v.sort();
    v
}

/// No file of the recording is empty, or holds nothing but its header and configuration.
fn assert_no_empty_file(files: &[PathBuf]) {
    for f in files {
        let rec = read_recording(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let data = rec.messages.iter().filter(|m| !matches!(m.payload, Payload::Config(_))).count();
        assert!(data > 0, "{} holds no data ({} bytes)", f.display(), std::fs::metadata(f).unwrap().len());
    }
}

#[test]
fn a_rotating_recording_suspends_on_a_full_disk_and_resumes_counting_every_message() {
    if let Ok(mnt) = std::env::var(CHILD_ENV) {
        return child_writer(Path::new(&mnt));
    }
    if !namespaces_work() {
        return;
    }
    let mnt = tempfile::tempdir().unwrap();
    let exe = std::env::current_exe().unwrap();
    let name = "a_rotating_recording_suspends_on_a_full_disk_and_resumes_counting_every_message";
    let script = format!("exec '{}' --exact {name} --nocapture", exe.display());
    let out = in_tmpfs(mnt.path(), 16, &script).env(CHILD_ENV, mnt.path()).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "the child failed:\n{text}");
    assert!(text.contains("child: "), "the child did not run its checks:\n{text}");
}

/// `/status` as JSON, while the demo answers.
fn status(port: u16) -> Option<serde_json::Value> {
    http_get(port, "/status").and_then(|b| serde_json::from_str(&b).ok())
}

fn wait_for(port: u16, what: &str, deadline: Duration, ok: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let end = Instant::now() + deadline;
    loop {
        if let Some(s) = status(port).filter(|s| ok(s)) {
            return s;
        }
        assert!(Instant::now() < end, "waited {deadline:?} for {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Blows in each recording file (`forgemon inspect --json`).
fn blows_recorded(dir: &Path) -> u64 {
    let mut blows = 0;
    for f in recording_files(dir) {
        assert!(std::fs::metadata(&f).unwrap().len() > 0, "{} is empty", f.display());
        let out = Command::new(BIN).args(["inspect", "--json"]).arg(&f).output().unwrap();
        let json: serde_json::Value = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("inspect {}: {e}: {}", f.display(), String::from_utf8_lossy(&out.stderr)));
        let by_class = json["results_by_class"].as_object().cloned().unwrap_or_default();
        blows += by_class.values().filter_map(|n| n.as_u64()).sum::<u64>();
    }
    blows
}

/// The number before `word` in `line` ("24 blows" → 24).
fn count_before(line: &str, word: &str) -> u64 {
    let i = line.find(word).unwrap_or_else(|| panic!("no {word:?} in {line:?}"));
    line[..i].split_whitespace().last().and_then(|n| n.parse().ok()).unwrap()
}

#[test]
fn the_demo_resumes_recording_within_eight_blows_of_a_full_disk_being_freed() {
    if !namespaces_work() {
        return;
    }
    let (mnt, out) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let port = free_port();
    // 20 MB with 15 MB of ballast: the demo fills the rest within a few blows. The demo's
    // output and its recording are copied out before the namespace goes.
    let m = mnt.path().display();
    let o = out.path().display();
    let script = format!(
        "head -c 15000000 /dev/zero > '{m}/ballast' && \
         '{BIN}' demo --billets 4 --interval 0.5 --dir '{m}/rec' --http 127.0.0.1:{port} > '{o}/demo.txt' 2>&1; \
         echo \"exit $?\" >> '{o}/demo.txt'; cp -r '{m}/rec' '{o}/rec'"
    );
    let mut child = in_tmpfs(mnt.path(), 20, &script).spawn().unwrap();
    let full = wait_for(port, "the recording to be suspended", Duration::from_secs(30), |s| {
        s["storage"]["state"] == "suspended"
    });
    assert_eq!(full["storage"]["low"], true, "{full}");
    assert!(full["alerts"].as_u64() > Some(0), "no alert: {full}");
    // The disk as the namespace sees it (`unshare` execs the shell: same process).
    let inside = PathBuf::from(format!("/proc/{}/root{}", child.id(), mnt.path().display()));
    std::thread::sleep(Duration::from_secs(1));
    for f in recording_files(&inside.join("rec")) {
        assert!(std::fs::metadata(&f).unwrap().len() > 0, "{} is empty while the disk is full", f.display());
    }
    std::fs::remove_file(inside.join("ballast")).unwrap();
    let freed_at = status(port).unwrap()["blows"].as_u64().unwrap();
    let back =
        wait_for(port, "the recording to resume", Duration::from_secs(20), |s| s["storage"]["state"] == "recording");
    let resumed_at = back["blows"].as_u64().unwrap();
    assert!(resumed_at - freed_at <= 8, "resumed {} blows after the disk was freed", resumed_at - freed_at);
    assert!(child.wait().unwrap().success());
    let text = std::fs::read_to_string(out.path().join("demo.txt")).unwrap();
    assert!(text.contains("exit 0"), "{text}");
    let summary = text.lines().find(|l| l.starts_with("forgemon demo: ") && l.contains(" blows (")).unwrap();
    let lost = text.lines().find(|l| l.contains("were not recorded")).unwrap_or_else(|| panic!("{text}"));
    let (blows, dropped) = (count_before(summary, " blows"), count_before(lost, " blows were not recorded"));
    assert!(dropped > 0 && dropped < blows, "{text}");
    // Every blow is in a file or counted as not recorded.
    assert_eq!(blows_recorded(&out.path().join("rec")) + dropped, blows, "{text}");
    // `replay DIR` streams the run's files in order: every recorded blow comes back, at the
    // same contact instant.
    let out_dir = out.path().join("rec");
    let replayed = Command::new(BIN).args(["replay", "--json"]).arg(&out_dir).output().unwrap();
    let err = String::from_utf8_lossy(&replayed.stderr);
    assert!(replayed.status.success(), "{err}");
    let contacts: Vec<f64> = String::from_utf8_lossy(&replayed.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["t_contact_s"].as_f64().unwrap())
        .collect();
    for f in recording_files(&out_dir) {
        for m in read_recording(&f).unwrap().messages {
            if let Payload::Result(r) = m.payload {
                let t = r.t_contact_s;
                assert!(contacts.iter().any(|c| (c - t).abs() < 1e-6), "blow at {t} s not replayed: {contacts:?}");
            }
        }
    }
    // An empty file before the run's and a foreign one between them: named, skipped, the
    // same blows, exit status 3.
    std::fs::write(out_dir.join("forgemon-00000.mcap"), b"").unwrap();
    std::fs::write(out_dir.join("forgemon-00001.mcap.x.mcap"), b"junk").unwrap();
    let again = Command::new(BIN).args(["replay", "--json"]).arg(&out_dir).output().unwrap();
    let err = String::from_utf8_lossy(&again.stderr);
    assert_eq!(again.status.code(), Some(3), "{err}");
    for bad in ["forgemon-00000.mcap", "forgemon-00001.mcap.x.mcap"] {
        assert!(err.lines().any(|l| l.contains("skipped") && l.contains(bad)), "{bad} not named: {err}");
    }
    assert_eq!(again.stdout, replayed.stdout, "the skipped files changed the blows");
    for junk in ["forgemon-00000.mcap", "forgemon-00001.mcap.x.mcap"] {
        std::fs::remove_file(out_dir.join(junk)).unwrap();
    }
    // The low-space alert, raised before the disk was full, is in the first file.
    let first = read_recording(&recording_files(&out.path().join("rec"))[0]).unwrap();
    assert!(
        first.messages.iter().any(|m| matches!(&m.payload, Payload::Alert(a) if a.kind.as_str() == "storage")),
        "no storage alert recorded"
    );
}

#[test]
fn the_fast_demo_on_a_disk_that_stays_full_prints_its_summary_and_keeps_what_it_synced() {
    if !namespaces_work() {
        return;
    }
    let (mnt, out) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let (m, o) = (mnt.path().display(), out.path().display());
    let script = format!(
        "'{BIN}' demo --fast --billets 3 --dir '{m}/rec' > '{o}/demo.txt' 2>&1; \
         echo \"exit $?\" >> '{o}/demo.txt'; cp -r '{m}/rec' '{o}/rec'"
    );
    assert!(in_tmpfs(mnt.path(), 6, &script).status().unwrap().success());
    let text = std::fs::read_to_string(out.path().join("demo.txt")).unwrap();
    assert!(text.contains("exit 0"), "{text}");
    let summary = text.lines().find(|l| l.starts_with("forgemon demo: ") && l.contains(" blows (")).unwrap();
    let lost = text.lines().find(|l| l.contains("were not recorded")).unwrap_or_else(|| panic!("{text}"));
    let (blows, dropped) = (count_before(summary, " blows"), count_before(lost, " blows were not recorded"));
    assert_eq!(blows, 24, "{text}");
    assert_eq!(blows_recorded(&out.path().join("rec")) + dropped, blows, "{text}");
}

#[test]
fn export_and_inspect_of_a_directory_name_and_skip_empty_and_unreadable_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Two good recordings around an empty file (what a full disk used to leave) and one
    // that is not MCAP at all.
    for (name, blows) in [("forgemon-00001.mcap", 3u32), ("forgemon-00004.mcap", 2)] {
        let mut w = RecordWriter::create(d.join(name), Rotation::NEVER).unwrap();
        for b in 1..=blows {
            let t = f64::from(b);
            w.write_result(1_000_000_000 * i64::from(b), &BlowEstimate::incomplete(b, t, 4.0, t + 0.05)).unwrap();
        }
        w.finish().unwrap();
    }
    std::fs::write(d.join("forgemon-00002.mcap.part"), b"").unwrap();
    std::fs::write(d.join("forgemon-00003.mcap"), b"not a recording at all").unwrap();
    let csv = d.join("out.csv");
    let out = Command::new(BIN).args(["export", "--csv"]).arg(&csv).arg(d).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    for bad in ["forgemon-00002.mcap.part", "forgemon-00003.mcap"] {
        assert!(err.lines().any(|l| l.contains("skipped") && l.contains(bad)), "{bad} not named: {err}");
    }
    let rows = std::fs::read_to_string(&csv).unwrap().lines().count() - 1;
    assert_eq!(rows, 5, "{err}");
    let out = Command::new(BIN).args(["inspect", "--json"]).arg(d).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    let inspected: Vec<serde_json::Value> =
        String::from_utf8_lossy(&out.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let names: Vec<&str> = inspected.iter().filter_map(|j| j["file"].as_str()).collect();
    assert!(names.len() == 2 && names[0].ends_with("00001.mcap") && names[1].ends_with("00004.mcap"), "{names:?}");
    for bad in ["forgemon-00002.mcap.part", "forgemon-00003.mcap"] {
        assert!(err.lines().any(|l| l.contains("skipped") && l.contains(bad)), "{bad} not named: {err}");
    }
}

/// `forgemon run` on a recording directory that already holds 25 files of 1 MiB, the first
/// five last written ten days ago, with `keep_days = 7` and `keep_bytes = 16 MiB`: at the
/// start the five old ones go for their age, then the oldest while more than 16 MiB are
/// kept, each deletion logged, and the file being written stays.
#[test]
fn retention_deletes_the_oldest_whole_files_at_the_start_and_logs_each() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    std::fs::create_dir_all(&rec).unwrap();
    let ten_days_ago = std::time::SystemTime::now() - Duration::from_secs(10 * 86_400);
    for i in 1..=25 {
        let f = std::fs::File::create(rec.join(format!("forgemon-{i:05}.mcap"))).unwrap();
        f.set_len(1 << 20).unwrap();
        if i <= 5 {
            f.set_modified(ten_days_ago).unwrap();
        }
    }
    let http = free_port();
    let config = common::service_toml(dir.path(), http, "", "");
    let text = std::fs::read_to_string(&config).unwrap();
    let text = text.replace("dir = \"rec\"", "dir = \"rec\"\nkeep_days = 7\nkeep_bytes = 16777216");
    std::fs::write(&config, text).unwrap();
    let log = std::fs::File::create(dir.path().join("log")).unwrap();
    let service = common::KillOnDrop(common::spawn_service_logging(&config, http, log.into()));
    let s = wait_for(http, "the storage report", Duration::from_secs(10), |s| s["storage"]["state"] == "recording");
    drop(service);
    let left: Vec<String> = recording_files(&rec)
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".mcap"))
        .collect();
    // 20 MiB younger than a week and the new file: 00006–00010 go, 15 MiB stay.
    let expected: Vec<String> = (11..=25).map(|i| format!("forgemon-{i:05}.mcap")).collect();
    assert_eq!(left, expected);
    assert!(rec.join("forgemon-00026.mcap").exists() || rec.join("forgemon-00026.mcap.part").exists());
    assert_eq!(s["storage"]["deleted_files"], 10, "{s}");
    let log = std::fs::read_to_string(dir.path().join("log")).unwrap();
    for i in 1..=10 {
        let name = format!("forgemon-{i:05}.mcap");
        let why = if i <= 5 { "keep_days" } else { "keep_bytes" };
        assert!(
            log.lines().any(|l| l.contains("retention: deleted") && l.contains(&name) && l.contains(why)),
            "{name} not logged ({why}):\n{log}"
        );
    }
}
