//! The headline benches (issue 42), each against its anchor measured in the same process,
//! and the performance report they regenerate, `docs/performance.md`:
//!
//! - **replay**: `forgemon replay FILE --json` on a demo recording (by default 10 billets:
//!   80 blows, 3 channels at 100 kHz, about 12 M samples and 100 MB), with the parallel read
//!   and with `--sequential`, and `inspect --json` and `export --csv` of the same file,
//!   against the `mcap` crate's own read of the same file (the file
//!   read into memory and every message of every chunk iterated by `MessageStream`, payloads
//!   not decoded). Ratio anchor time / the command's time: ≥ 1.0 means it keeps up with a
//!   raw read. Every round checks that both replays print the same bytes.
//! - **blow**: one hammer blow (the paper's Table 3 blow 1, 3.9 m/s, with its post-contact
//!   window) at the default tolerance, against the fixed-step RK4 of the same blow at 1e-7 s
//!   (the paper's Simulink step). Ratio RK4 time / adaptive time.
//! - **Monte Carlo**: the 3000-run study of that blow on rayon's threads, against the same
//!   study on a pool of one thread (the sequential loop). Ratio sequential / parallel; the
//!   two results must be equal, since each run draws from its own seeded generator.
//!
//! After a round not counted (the file in the page cache, the threads started), each round
//! times the anchor and its cases one after the other; the figures are the best of the
//! rounds, the noise their spread (max − min over the best).
//!
//! `cargo bench --bench headline`; `FORGEMON_BENCH_BILLETS` (default 10) sets the
//! recording's size, `FORGEMON_BENCH_ROUNDS` (default 5) the rounds. The recording is made
//! once by `forgemon demo --fast` and kept in `target/bench-data/`.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::integrator::Method;
use forgemon::physics::montecarlo::{Uncertainty, monte_carlo};
use forgemon::physics::{EffectSet, Machine, Process, SimOptions, simulate_sequence};

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
    forgemon(&["replay".as_ref(), file.as_os_str(), "--json".as_ref()], extra)
}

/// `forgemon ARGS EXTRA`, which must succeed: its standard output.
fn forgemon(args: &[&std::ffi::OsStr], extra: &[&str]) -> Vec<u8> {
    let out = Command::new(EXE).args(args).args(extra).output().expect("run forgemon");
    assert!(out.status.success(), "forgemon {args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
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

/// One line of the report: what, its time, its anchor's, and the ratio.
struct Figure {
    case: String,
    seconds: f64,
    noise: f64,
    anchor: String,
    anchor_seconds: f64,
    anchor_noise: f64,
    /// anchor / case for replay (≥ 1 keeps pace); case slower than anchor otherwise.
    ratio: f64,
    meaning: &'static str,
}

impl Figure {
    fn print(&self) {
        println!(
            "  {}: {} (spread {:.0} %) against {}: {} (spread {:.0} %): ratio {:.2} ({})",
            self.case,
            duration(self.seconds),
            self.noise * 100.0,
            self.anchor,
            duration(self.anchor_seconds),
            self.anchor_noise * 100.0,
            self.ratio,
            self.meaning
        );
    }
}

/// A time in the unit that reads best.
fn duration(s: f64) -> String {
    if s < 1e-3 {
        format!("{:.1} µs", s * 1e6)
    } else if s < 1.0 {
        format!("{:.1} ms", s * 1e3)
    } else {
        format!("{s:.3} s")
    }
}

fn replay_figures(rounds: usize, billets: usize) -> (String, Vec<Figure>) {
    let file = recording(billets);
    let size_mb = std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0) as f64 / 1e6;
    let (mut raw, mut par, mut seq, mut inspect, mut export) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let csv = std::env::temp_dir().join(format!("forgemon-bench-{}.csv", std::process::id()));
    let mut counted = (0, 0);
    let mut outputs = None;
    // A round not counted: the file in the page cache, the binary loaded.
    raw_read(&file);
    replay(&file, &[]);
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
        let (t, _) = timed(|| forgemon(&["inspect".as_ref(), file.as_os_str(), "--json".as_ref()], &[]));
        inspect.push(t);
        let (t, _) = timed(|| forgemon(&["export".as_ref(), "--csv".as_ref(), csv.as_os_str(), file.as_os_str()], &[]));
        export.push(t);
    }
    let _ = std::fs::remove_file(&csv);
    let blows = outputs.as_deref().map_or(0, |o| o.iter().filter(|&&c| c == b'\n').count());
    let (raw_s, raw_noise) = best(&raw);
    // Three f64 a sample (the protobuf framing is a few bytes a batch).
    let samples = counted.1 as f64 / 24.0;
    let what = format!(
        "A demo recording of {billets} billets: {size_mb:.0} MB, {} messages, about {:.1} M samples of 3 f64, {blows} blows; the parallel and sequential outputs byte-identical in every round",
        counted.0,
        samples / 1e6
    );
    let anchor = "mcap MessageStream read".to_string();
    let figure = |case: &str, times: &[Duration]| {
        let (s, noise) = best(times);
        Figure {
            case: case.into(),
            seconds: s,
            noise,
            anchor: anchor.clone(),
            anchor_seconds: raw_s,
            anchor_noise: raw_noise,
            ratio: raw_s / s,
            meaning: "anchor / the command; goal ≥ 1.0",
        }
    };
    let figures = vec![
        figure("replay --json, parallel read", &par),
        figure("replay --json --sequential", &seq),
        figure("inspect --json", &inspect),
        figure("export --csv", &export),
    ];
    (what, figures)
}

fn hammer() -> (Machine, Process) {
    let m = parse_machine("hammer", include_str!("../config/hammer-lg1000.machine.toml")).unwrap().machine;
    let p = parse_process("steel", include_str!("../config/steel-16NiCrMo13.process.toml")).unwrap();
    (m, p)
}

/// Best of `rounds` of the mean time of `reps` calls of `f`.
fn per_call(rounds: usize, reps: usize, mut f: impl FnMut()) -> Vec<Duration> {
    (0..rounds)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..reps {
                f();
            }
            t.elapsed() / reps as u32
        })
        .collect()
}

fn blow_figure(rounds: usize) -> Figure {
    let (m, p) = hammer();
    let adaptive = SimOptions::default();
    let rk4 = SimOptions { method: Method::Rk4 { dt_s: 1e-7 }, ..SimOptions::default() };
    let blow = |o: &SimOptions| simulate_sequence(&m, &EffectSet::NONE, &p, black_box(&[3.9]), o).unwrap();
    let (mut fast, mut fixed) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        fast.extend(per_call(1, 2000, || drop(blow(&adaptive))));
        fixed.extend(per_call(1, 2, || drop(blow(&rk4))));
    }
    let ((s, noise), (a, a_noise)) = (best(&fast), best(&fixed));
    Figure {
        case: "one hammer blow, adaptive (default rtol)".into(),
        seconds: s,
        noise,
        anchor: "fixed-step RK4 at 1e-7 s".into(),
        anchor_seconds: a,
        anchor_noise: a_noise,
        ratio: a / s,
        meaning: "RK4 / adaptive: times faster than the paper's step",
    }
}

fn monte_carlo_figure(rounds: usize) -> (String, Figure) {
    let (m, p) = hammer();
    let study = || {
        monte_carlo(&m, &EffectSet::NONE, &p, &[3.9], &Uncertainty::default(), 3000, 1, &SimOptions::default()).unwrap()
    };
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let (mut par, mut seq) = (Vec::new(), Vec::new());
    let mut last = None;
    // A round not counted: rayon's threads started.
    study();
    for _ in 0..rounds {
        let (t, a) = timed(study);
        par.push(t);
        let (t, b) = timed(|| one.install(study));
        seq.push(t);
        assert!(a == b, "the parallel and the sequential Monte Carlo differ");
        last = Some(a);
    }
    let mc = last.unwrap();
    let b = &mc.blows[0];
    let what = format!(
        "3000 runs of Table 3 blow 1 (seed 1, {} failed) on {} threads: final load {:.1} kN [{:.1}, {:.1}], h_end {:.2} mm [{:.2}, {:.2}], efficiency {:.4} [{:.4}, {:.4}] (mean [95 % band]); equal to the one-thread result in every round",
        mc.failed,
        rayon::current_num_threads(),
        b.final_load_n.mean / 1e3,
        b.final_load_n.p2_5 / 1e3,
        b.final_load_n.p97_5 / 1e3,
        b.h_end_m.mean * 1e3,
        b.h_end_m.p2_5 * 1e3,
        b.h_end_m.p97_5 * 1e3,
        b.efficiency.mean,
        b.efficiency.p2_5,
        b.efficiency.p97_5,
    );
    let ((s, noise), (a, a_noise)) = (best(&par), best(&seq));
    let figure = Figure {
        case: "Monte Carlo, 3000 runs, parallel".into(),
        seconds: s,
        noise,
        anchor: "the same on one thread".into(),
        anchor_seconds: a,
        anchor_noise: a_noise,
        ratio: a / s,
        meaning: "sequential / parallel; the goal is ≤ 0.15 s",
    };
    (what, figure)
}

/// The machine the figures are from.
fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let load =
        std::fs::read_to_string("/proc/loadavg").ok().and_then(|t| t.split_whitespace().next().map(String::from));
    format!(
        "{} logical cores, {cpu}; load average {} at the start",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        load.unwrap_or_else(|| "?".into())
    )
}

fn report(rounds: usize, sections: &[(&str, String, Vec<Figure>)]) -> String {
    let mut doc = String::from(
        "# Performance report\n\nRegenerated by `cargo bench --bench headline` (benches/headline.rs, benches/README.md). \
         Each figure is the best of the rounds, and its noise the spread of the rounds over the best; each ratio is to an \
         anchor measured in the same process in the same rounds, so a busy machine moves it far less than the times.\n\n",
    );
    doc += &format!("Machine: {}. Rounds: {rounds}.\n\n", machine());
    for (title, what, figures) in sections {
        doc += &format!(
            "## {title}\n\n{what}.\n\n| case | time | spread | anchor | anchor time | spread | ratio | meaning |\n|---|---|---|---|---|---|---|---|\n"
        );
        for f in figures {
            doc += &format!(
                "| {} | {} | {:.0} % | {} | {} | {:.0} % | **{:.2}** | {} |\n",
                f.case,
                duration(f.seconds),
                f.noise * 100.0,
                f.anchor,
                duration(f.anchor_seconds),
                f.anchor_noise * 100.0,
                f.ratio,
                f.meaning
            );
        }
        doc += "\n";
    }
    doc += "## The live service\n\nThe service's cost (3 channels at 100 kHz with the dashboard, the PLC image and \
            Foxglove, each with one client; goal ≤ 5 % of one core with RSS flat) is measured from outside over 10 \
            minutes by `benches/live_cost.py`, not by this run; its last result on this machine";
    let live = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/bench-data/live_cost.txt");
    match std::fs::read_to_string(&live) {
        Ok(text) => doc += &format!(":\n\n{}\n", text.trim()),
        Err(_) => doc += " is not there (run it first).\n",
    }
    doc
}

fn main() {
    // `cargo bench` passes `--bench`; a test run (`cargo test --benches`) passes nothing.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    let billets = env_or("FORGEMON_BENCH_BILLETS", 10);
    let rounds = env_or("FORGEMON_BENCH_ROUNDS", 5).max(1);
    let mut sections = Vec::new();
    let (what, figures) = replay_figures(rounds, billets);
    println!("replay: {what}");
    figures.iter().for_each(Figure::print);
    sections.push(("Replay against a raw MCAP read", what, figures));
    let blow = blow_figure(rounds);
    println!("blow:");
    blow.print();
    sections.push((
        "One blow against the fixed-step reference",
        "Table 3 blow 1 of the hammer paper (3.9 m/s on the 16NiCrMo13 billet), contact and post-contact window"
            .to_string(),
        vec![blow],
    ));
    let (what, mc) = monte_carlo_figure(rounds);
    println!("Monte Carlo: {what}");
    mc.print();
    sections.push(("Monte Carlo against the sequential loop", what, vec![mc]));
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/performance.md");
    match std::fs::write(&path, report(rounds, &sections)) {
        Ok(()) => println!("wrote {}", path.display()),
        Err(e) => eprintln!("{}: cannot write: {e}", path.display()),
    }
}
