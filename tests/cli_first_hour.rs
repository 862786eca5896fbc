//! A plant user's first hour at the command line (issue 40), against the built binary: the
//! demo keeps its dashboard up on a terminal and forges on with `--billets 0`; a closed
//! stdout (`| head`) ends every verb quietly with its recording closed; a height in
//! millimetres where metres are expected is named as such; `--settings` and `--v-max`
//! stand in for each other; an error's cause is said once; `export --csv -` writes to
//! stdout; every option has a help text.

mod common;

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{files_in, root};

const BIN: &str = env!("CARGO_BIN_EXE_forgemon");

/// `main`'s status once stdout's reader is gone (`cli::out::EXIT_STDOUT_CLOSED`).
const EXIT_STDOUT_CLOSED: i32 = 141;

fn forgemon(args: &[&str]) -> Command {
    let mut c = Command::new(BIN);
    c.args(args);
    c
}

/// The names of the files in `dir`.
fn names(dir: &Path) -> Vec<String> {
    files_in(dir).iter().filter_map(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned()).collect()
}

/// The recording in `dir` is closed: a finished `.mcap`, no `.mcap.part`.
fn assert_closed_recording(dir: &Path) {
    let names = names(dir);
    assert!(names.iter().any(|n| n.ends_with(".mcap")), "no finished recording in {}: {names:?}", dir.display());
    assert!(!names.iter().any(|n| n.ends_with(".part")), "a recording left open in {}: {names:?}", dir.display());
}

/// Wait for `child` to end within `limit`, else kill it and fail.
fn wait_within(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let deadline = Instant::now() + limit;
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("forgemon did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn stderr_of(child: &mut Child) -> String {
    let mut s = String::new();
    child.stderr.take().expect("piped stderr").read_to_string(&mut s).expect("stderr");
    s
}

/// A short demo recording (`billets` of 8 blows, fast) in `dir/rec`: its `.mcap`.
fn demo_recording(dir: &Path, billets: usize) -> PathBuf {
    let rec = dir.join("rec");
    let n = billets.to_string();
    let out = forgemon(&["demo", "--fast", "--billets", &n, "--dir"]).arg(&rec).output().expect("demo runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    files_in(&rec).into_iter().find(|p| p.extension().is_some_and(|x| x == "mcap")).expect("an mcap file")
}

/// Issue 40: the demo ended after about 25 s, so the dashboard URL it printed was dead. On a
/// terminal (a pty here) it now says that the dashboard stays up, serves it after the last
/// billet until Ctrl-C, and closes its recording on Ctrl-C; piped, it ends by itself.
#[test]
fn demo_on_a_terminal_keeps_its_dashboard_up_until_ctrl_c() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("tty");
    let script = root().join("tests/python/on_pty.py");
    let out = Command::new("python3")
        .arg(&script)
        .args(["60", "demo finished", "--", BIN, "demo", "--billets", "1", "--interval", "0.2", "--dir"])
        .arg(&rec)
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e}): the pty test needs Python 3's standard library"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("demo finished: the dashboard stays up at http://127.0.0.1:"),
        "no word that the dashboard stays up:\n{text}"
    );
    assert!(text.contains("GET 200"), "the dashboard is not served after the last billet:\n{text}");
    assert!(text.contains("running yes"), "the demo ended by itself on a terminal:\n{text}");
    assert!(text.contains("exit 0"), "Ctrl-C did not end the demo cleanly:\n{text}");
    assert!(text.contains("forgemon demo: 1 billets, 8 blows"), "no summary after Ctrl-C:\n{text}");
    assert_closed_recording(&rec);

    // Piped, the same demo ends after its billet, as scripts expect, and says nothing of
    // staying up.
    let piped = dir.path().join("piped");
    let out = forgemon(&["demo", "--billets", "1", "--interval", "0.2", "--dir"]).arg(&piped).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!text.contains("stays up"), "a piped demo claims to stay up:\n{text}");
    assert_closed_recording(&piped);
}

/// Issue 40: the service takes SIGHUP as "reload"; a demo kept up on a terminal ends on it
/// (its terminal closed) as on Ctrl-C, its recording closed, instead of running on orphaned.
#[test]
fn a_hangup_ends_a_demo_kept_up_on_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("tty");
    let out = Command::new("python3")
        .arg(root().join("tests/python/on_pty.py"))
        .args(["60", "demo finished", "HUP", "--", BIN, "demo", "--billets", "1", "--interval", "0.2", "--dir"])
        .arg(&rec)
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e}): the pty test needs Python 3's standard library"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("running yes"), "the demo did not stay up:\n{text}");
    assert!(text.contains("exit 0"), "SIGHUP did not end the demo cleanly:\n{text}");
    assert_closed_recording(&rec);
}

/// Issue 40: `demo --billets 0` silently forged one billet. It forges until stopped, as
/// `simulate-device --billets 0` does, and SIGTERM closes its recording.
#[test]
fn demo_billets_0_forges_until_sigterm_and_closes_the_recording() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let mut child = forgemon(&["demo", "--fast", "--billets", "0", "--dir"])
        .arg(&rec)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // One billet takes about 1 s at --fast (13 in 8 s on a 2-core machine): the old demo
    // had ended long before.
    std::thread::sleep(Duration::from_secs(6));
    assert!(child.try_wait().unwrap().is_none(), "demo --billets 0 ended by itself");
    let kill = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let status = wait_within(&mut child, Duration::from_secs(30));
    let mut text = String::new();
    child.stdout.take().unwrap().read_to_string(&mut text).unwrap();
    assert!(status.success(), "SIGTERM: {status:?}\n{}", stderr_of(&mut child));
    assert!(text.contains("forges steel billets until Ctrl-C"), "{text}");
    let billets: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("forgemon demo: ")?.split(" billets,").next()?.parse().ok())
        .unwrap_or_else(|| panic!("no summary line:\n{text}"));
    assert!(billets >= 2, "forged {billets} billets in 6 s:\n{text}");
    assert_closed_recording(&rec);
}

/// Issue 40: `forgemon demo | head -1` panicked (exit 101) and left a `.mcap.part`. The
/// reader reads one line and goes; the demo stops quietly with its recording closed.
#[test]
fn demo_into_head_ends_quietly_with_the_recording_closed() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let mut child = forgemon(&["demo", "--fast", "--billets", "20", "--dir"])
        .arg(&rec)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut first).unwrap();
    assert!(first.starts_with("forgemon demo: "), "{first}");
    // The reader is dropped here, as `head -1` exits: the demo's next line finds it gone,
    // long before 20 billets (about 20 s) are forged.
    let status = wait_within(&mut child, Duration::from_secs(15));
    let err = stderr_of(&mut child);
    assert_eq!(status.code(), Some(EXIT_STDOUT_CLOSED), "stderr: {err}");
    assert!(err.is_empty(), "not quiet: {err}");
    assert_closed_recording(&rec);
}

/// Run `args` with its stdout already closed by the reader; its status and stderr.
/// The read end is closed before the child starts: dropped after `spawn`, a fast verb
/// (simulate, two blows) could fill the pipe's buffer and exit 0 before the drop.
fn into_closed_pipe(args: &[&str], paths: &[&Path]) -> (Option<i32>, String) {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let mut child = forgemon(args).args(paths).stdout(writer).stderr(Stdio::piped()).spawn().unwrap();
    let status = wait_within(&mut child, Duration::from_secs(60));
    (status.code(), stderr_of(&mut child))
}

/// Issue 40: every verb that prints ends quietly when the reader of its stdout is gone:
/// inspect, advise, replay and simulate wrote "Broken pipe" as an error (exit 1; replay
/// left its `--out` recording open), teach panicked (101), `export --csv -` wrote a file `-`.
#[test]
fn verbs_into_a_closed_pipe_end_quietly() {
    let dir = tempfile::tempdir().unwrap();
    // Two billets: teach needs two for a spread.
    let mcap = demo_recording(dir.path(), 2);
    let machine = root().join("config/hammer-lg1000.machine.toml");
    let steel = root().join("config/steel-16NiCrMo13.process.toml");
    let replayed = dir.path().join("replayed");
    let recipe = dir.path().join("part.recipe.toml");
    let runs: [(&[&str], Vec<&Path>); 7] = [
        (&["inspect"], vec![&mcap]),
        (&["inspect", "--json"], vec![mcap.parent().unwrap()]),
        (&["export", "--csv", "-"], vec![&mcap]),
        (&["replay", "--out"], vec![&replayed, &mcap]),
        // simulate writes with `writeln!(stdout)?`, teach with `println!` (main's fallbacks).
        (&["simulate", "--v0", "3.9,5.3", "--machine"], vec![&machine, Path::new("--process"), &steel]),
        (&["teach", "--machine"], vec![&machine, Path::new("--reference"), &mcap, Path::new("-o"), &recipe]),
        (
            &["advise", "--h-now", "0.112", "--target", "0.04", "--v-max", "5.3", "--machine"],
            vec![&machine, Path::new("--process"), &steel],
        ),
    ];
    for (args, paths) in runs {
        let (code, err) = into_closed_pipe(args, &paths);
        assert_eq!(code, Some(EXIT_STDOUT_CLOSED), "{args:?}: stderr {err}");
        assert!(!err.contains("Broken pipe") && !err.contains("panicked"), "{args:?}: not quiet: {err}");
    }
    assert_closed_recording(&replayed);
    assert!(!Path::new("-").exists() && !dir.path().join("-").exists());
}

/// Issue 40: `export --csv -` wrote a file named `-`; `-` is stdout.
#[test]
fn export_csv_dash_writes_to_stdout() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = demo_recording(dir.path(), 1);
    let out = forgemon(&["export", "--csv", "-"]).arg(&mcap).current_dir(dir.path()).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let mut lines = text.lines();
    assert!(lines.next().is_some_and(|h| h.starts_with("file,wall_time,billet,")), "no CSV header:\n{text}");
    assert_eq!(lines.count(), 8, "one row per blow of the demo's billet:\n{text}");
    assert!(!dir.path().join("-").exists(), "a file named '-' was written");
    let help = forgemon(&["export", "--help"]).output().unwrap();
    assert!(String::from_utf8_lossy(&help.stdout).contains("`-` writes it to standard output"));
}

fn advise(extra: &[&str]) -> Output {
    forgemon(&["advise", "--machine"])
        .arg(root().join("config/hammer-lg1000.machine.toml"))
        .arg("--process")
        .arg(root().join("config/steel-16NiCrMo13.process.toml"))
        .args(extra)
        .output()
        .unwrap()
}

/// Issue 40: `advise --h-now 112 --target 40` (millimetres by habit) answered "could not
/// simulate a blow at 2.6 m/s from 39.997 m". The error names the slip and the value in
/// metres; demo's `--target` is checked the same way.
#[test]
fn a_height_in_millimetres_is_named_with_the_value_in_metres() {
    let out = advise(&["--h-now", "112", "--target", "40", "--settings", "2.6,5.3"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("--h-now 112 looks like millimetres; the option takes metres: 0.112"), "{err}");
    let out = advise(&["--h-now", "0.112", "--target", "40", "--settings", "2.6,5.3"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--target 40 looks like millimetres; the option takes metres: 0.04"), "{err}");
    // Out of range in both units: the range, not a guess.
    let out = advise(&["--h-now", "5000", "--target", "0.04", "--settings", "5.3"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--h-now 5000: must be within") && !err.contains("millimetres"), "{err}");
    let out = forgemon(&["demo", "--target", "40", "--billets", "1"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--target 40 looks like millimetres; the option takes metres: 0.04"), "{err}");
}

/// Issue 40: advise demanded `--settings` where `--v-max` would do. Either gives the
/// speeds; without both, the error names both; with both, that only one is taken.
#[test]
fn advise_takes_settings_or_v_max() {
    let plan = ["--h-now", "0.112", "--target", "0.04"];
    let missing = advise(&plan);
    let err = String::from_utf8_lossy(&missing.stderr);
    assert_eq!(missing.status.code(), Some(2), "{err}");
    assert!(err.contains("--settings") && err.contains("--v-max"), "the error names one option only: {err}");
    for speeds in [["--settings", "2.6,3.9,4.6,5.3"], ["--v-max", "5.3"]] {
        let out = advise(&[&plan[..], &speeds[..]].concat());
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{speeds:?}: {}", String::from_utf8_lossy(&out.stderr));
        assert!(text.contains("blows to the target"), "{speeds:?}: {text}");
    }
    let both = advise(&[&plan[..], &["--settings", "5.3", "--v-max", "5.3"]].concat());
    assert_eq!(both.status.code(), Some(2), "{}", String::from_utf8_lossy(&both.stderr));
}

/// Issue 40: `inspect` said "Is a directory (os error 21)" twice: an error that prints its
/// cause was printed with the cause again.
#[test]
fn an_error_says_its_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.mcap");
    for verb in ["inspect", "replay"] {
        let out = forgemon(&[verb]).arg(&missing).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{verb}: {err}");
        assert_eq!(err.matches("(os error 2)").count(), 1, "{verb}: {err}");
    }
}

/// The option lines of `forgemon CMD --help` that carry no help text.
fn options_without_help(cmd: &str) -> Vec<String> {
    let out = forgemon(&[cmd, "--help"]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let lines: Vec<&str> = text.lines().collect();
    let is_option = |l: &str| {
        let t = l.trim_start();
        l.starts_with("  ") && (t.starts_with("--") || t.starts_with('-') && t.chars().nth(2) == Some(','))
    };
    let mut bare = Vec::new();
    for (i, l) in lines.iter().enumerate().filter(|(_, l)| is_option(l)) {
        // `--flag <VALUE>  help` on one line, or the help on the next (long help).
        let words: Vec<&str> = l.split_whitespace().collect();
        let after = l.trim().split_once("  ").map_or("", |(_, help)| help.trim());
        let next = lines.get(i + 1).map_or("", |n| n.trim());
        let same_line = !after.is_empty() && !after.starts_with('[');
        let next_line = !next.is_empty()
            && !is_option(lines[i + 1])
            && !["Possible values", "[default", "[possible"].iter().any(|p| next.starts_with(p));
        if !same_line && !next_line {
            bare.push(format!("{cmd} {}", words.iter().find(|w| w.starts_with("--")).unwrap_or(&words[0])));
        }
    }
    bare
}

/// Issue 40: `identify --seed`, `simulate-device --wire` and `--transport` had no help text.
/// Every option of every verb has one.
#[test]
fn every_option_has_a_help_text() {
    let top = forgemon(&["--help"]).output().unwrap();
    let top = String::from_utf8_lossy(&top.stdout).into_owned();
    let verbs: Vec<&str> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|v| *v != "help")
        .collect();
    assert!(verbs.len() >= 12 && verbs.contains(&"simulate-device"), "{verbs:?}");
    let bare: Vec<String> = verbs.iter().flat_map(|v| options_without_help(v)).collect();
    assert!(bare.is_empty(), "options without a help text: {bare:?}");
    // `--billets 0` says what it does.
    let help = forgemon(&["demo", "--help"]).output().unwrap();
    assert!(String::from_utf8_lossy(&help.stdout).contains("0: keep forging until Ctrl-C"));
}
