//! The examples of the README and the user guide, run: every fenced block that follows the
//! line `<!-- readme_examples: checked -->` in README.md or docs/guide.md ([`DOCS`]) holds
//! `$ forgemon ...` commands, each followed by the output the document shows for it. This test runs each command with the
//! built binary from the repository's root, in README order, and compares what it prints
//! (stdout, then stderr) with the README, line by line (trailing spaces ignored), so the
//! examples cannot go stale. Paths under `/tmp/` are moved into a temporary directory and
//! shown back as `/tmp/`. The examples checked are those that run offline in seconds on the
//! repository's configs; the demo (real time, a port that changes) is not.
//!
//! When an output changes on purpose (the physics or the estimator moved), run
//! `cargo nextest run --release --test readme_examples --no-capture`: the failure prints
//! each command's whole output, to paste into README.md.

mod common;

use std::path::Path;
use std::process::Command;

/// The line that marks the next fenced block as checked.
const MARKER: &str = "<!-- readme_examples: checked -->";
/// The documents whose checked blocks are run, from the repository's root.
const DOCS: [&str; 2] = ["README.md", "docs/guide.md"];

/// One command of a checked block and the output the document shows for it.
struct Example {
    /// The document it is in.
    file: &'static str,
    /// The README line the command starts on (from 1).
    line: usize,
    /// The arguments after `forgemon`.
    args: Vec<String>,
    expected: Vec<String>,
}

/// The checked examples of `readme`, in order. A marker not followed by a fenced block, or
/// a block without a `$ forgemon` command, fails the test.
fn examples(file: &'static str, readme: &str) -> Vec<Example> {
    let lines: Vec<&str> = readme.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim() != MARKER {
            i += 1;
            continue;
        }
        assert!(lines.get(i + 1).is_some_and(|l| l.starts_with("```")), "{file}:{}: no block after the marker", i + 1);
        let body_start = i + 2;
        let len = lines[body_start..].iter().position(|l| l.starts_with("```")).expect("the block is closed");
        let before = out.len();
        out.extend(block_examples(file, &lines[body_start..body_start + len], body_start + 1));
        assert!(out.len() > before, "{file}:{}: a checked block without a command", i + 1);
        i = body_start + len + 1;
    }
    out
}

/// The commands of one block whose first line is README line `first_line`: `$ ` starts a
/// command (a trailing `\` continues it), the lines up to the next command are its output.
fn block_examples(file: &'static str, body: &[&str], first_line: usize) -> Vec<Example> {
    let mut out: Vec<Example> = Vec::new();
    let mut k = 0;
    while k < body.len() {
        let Some(start) = body[k].strip_prefix("$ ") else {
            let current =
                out.last_mut().unwrap_or_else(|| panic!("{file}:{}: output before a command", first_line + k));
            current.expected.push(body[k].trim_end().to_string());
            k += 1;
            continue;
        };
        let line = first_line + k;
        let mut command = start.trim_end().to_string();
        while command.ends_with('\\') {
            command.pop();
            k += 1;
            command.push(' ');
            command.push_str(body.get(k).unwrap_or_else(|| panic!("{file}:{line}: unfinished command")).trim());
        }
        let mut words = command.split_whitespace().map(str::to_string);
        assert_eq!(words.next().as_deref(), Some("forgemon"), "{file}:{line}: only forgemon commands are run");
        out.push(Example { file, line, args: words.collect(), expected: Vec::new() });
        k += 1;
    }
    for e in &mut out {
        while e.expected.last().is_some_and(|l| l.is_empty()) {
            e.expected.pop();
        }
    }
    out
}

/// Run one example from `root`, `/tmp/` moved to `tmp`; its output as the README shows it.
fn run(root: &Path, tmp: &Path, e: &Example) -> Vec<String> {
    let tmp = format!("{}/", tmp.display());
    let args: Vec<String> = e.args.iter().map(|a| a.replace("/tmp/", &tmp)).collect();
    let out = Command::new(env!("CARGO_BIN_EXE_forgemon")).args(&args).current_dir(root).output().expect("runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success(),
        "{}:{}: forgemon {} failed ({}):\n{text}",
        e.file,
        e.line,
        e.args.join(" "),
        out.status
    );
    text.replace(&tmp, "/tmp/").lines().map(|l| l.trim_end().to_string()).collect()
}

/// Relative tolerance of a number in an example's output against the README's: the
/// estimator's fits end at a relative cost change of 1e-5 (`estimate::fit::COST_RTOL`) on
/// blows integrated at rtol 1e-5, so a change of the physics by roundoff moves a fitted
/// figure within about 1e-5 of itself (the CAN fixture's blows moved by at most 7.5e-4 of a
/// 0.0045 residual share, 3e-6 elsewhere, when the plant's law was folded into one).
const NUMBER_RTOL: f64 = 1e-4;

/// A line of output is the README's: the same words and punctuation, and each number
/// within `NUMBER_RTOL` of the README's (at least 1e-12 absolute, for zeros).
fn same_line(got: &str, want: &str) -> bool {
    let (a, b) = (tokens(got), tokens(want));
    a.len() == b.len()
        && a.iter().zip(&b).all(|(x, y)| {
            x == y
                || match (x.parse::<f64>(), y.parse::<f64>()) {
                    (Ok(x), Ok(y)) => (x - y).abs() <= (NUMBER_RTOL * y.abs()).max(1e-12),
                    _ => false,
                }
        })
}

/// A line cut at the characters that never occur inside a number, each kept as a token.
fn tokens(line: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, c) in line.char_indices() {
        if c.is_whitespace() || ",:;{}[]()\"'|=/<>".contains(c) {
            if start < i {
                out.push(&line[start..i]);
            }
            out.push(&line[i..i + c.len_utf8()]);
            start = i + c.len_utf8();
        }
    }
    if start < line.len() {
        out.push(&line[start..]);
    }
    out
}

#[test]
fn a_readme_line_matches_its_words_exactly_and_its_numbers_within_tolerance() {
    assert!(same_line("{\"efficiency\":0.9314036129775627}", "{\"efficiency\":0.93140361297756}"));
    assert!(same_line("h_end 92.93 mm", "h_end 92.931 mm"));
    assert!(!same_line("h_end 92.93 mm", "h_end 92.99 mm"), "a number off by 6e-4");
    assert!(!same_line("class soft", "class hard"));
    assert!(!same_line("0.5 J", "0.5 J extra"));
    assert!(!same_line("{\"a\":1}", "{\"b\":1}"));
}

#[test]
fn the_readme_examples_print_what_the_readme_shows() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let all: Vec<Example> = DOCS
        .iter()
        .flat_map(|file| {
            let text = std::fs::read_to_string(root.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
            examples(file, &text)
        })
        .collect();
    // The simulate, replay and inspect sections each mark their examples.
    for verb in ["simulate", "replay", "inspect"] {
        assert!(all.iter().any(|e| e.args[0] == verb), "no checked `forgemon {verb}` example in {DOCS:?}");
    }
    let tmp = tempfile::tempdir().expect("tempdir");
    let mut stale = Vec::new();
    let mut out_of_range = Vec::new();
    for e in &all {
        let got = run(root, tmp.path(), e);
        // Every replay the README shows, again as JSON lines: no number outside its range.
        if e.args[0] == "replay" {
            let json = Example { file: e.file, args: replay_as_json(&e.args), expected: Vec::new(), line: e.line };
            let blows: Vec<serde_json::Value> =
                run(root, tmp.path(), &json).iter().filter_map(|l| serde_json::from_str(l).ok()).collect();
            assert!(!blows.is_empty(), "{}:{}: no blow in the replay", e.file, e.line);
            out_of_range
                .extend(common::out_of_range(&blows).into_iter().map(|b| format!("{}:{}: {b}", e.file, e.line)));
        }
        if got.len() != e.expected.len() || got.iter().zip(&e.expected).any(|(a, b)| !same_line(a, b)) {
            let first = got
                .iter()
                .zip(&e.expected)
                .position(|(a, b)| !same_line(a, b))
                .unwrap_or(got.len().min(e.expected.len()));
            stale.push(format!(
                "{}:{}: `forgemon {}` differs from its output line {} on:\n  document: {:?}\n  output: {:?}\nits whole output:\n{}",
                e.file,
                e.line,
                e.args.join(" "),
                first + 1,
                e.expected.get(first),
                got.get(first),
                got.join("\n")
            ));
        }
    }
    assert!(
        stale.is_empty(),
        "{} of {} documented examples are stale:\n\n{}",
        stale.len(),
        all.len(),
        stale.join("\n\n")
    );
    assert!(out_of_range.is_empty(), "{}", out_of_range.join("\n"));
}

/// A README replay's arguments as a `--json` replay that records nothing.
fn replay_as_json(args: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--out" {
            it.next();
        } else if a != "--json" {
            out.push(a.clone());
        }
    }
    out.push("--json".to_string());
    out
}

/// Issue 36: the committed fixtures' expected results, and a demo session's recording
/// (the README's first command, two billets), keep every number in its range.
#[test]
fn the_fixtures_and_the_demo_keep_every_number_in_its_range() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let can: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("fixtures/can/hammer_blows.expected.json")).unwrap())
            .unwrap();
    let blows = can["blows"].as_array().expect("the fixture's blows");
    assert_eq!(blows.len(), 3);
    assert_eq!(common::out_of_range(blows), Vec::<String>::new(), "fixtures/can");
    let tmp = tempfile::tempdir().expect("tempdir");
    // `run` moves `/tmp/` into the temporary directory.
    let dir = "/tmp/demo".to_string();
    let demo = Example {
        file: "README.md",
        line: 0,
        args: ["demo", "--fast", "--billets", "2", "--dir", &dir].map(String::from).to_vec(),
        expected: vec![],
    };
    run(root, tmp.path(), &demo);
    let rec = std::fs::read_dir(tmp.path().join("demo"))
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .expect("the demo's recording");
    let name = rec.file_name().expect("a file").to_string_lossy();
    let replay = Example {
        file: "README.md",
        line: 0,
        args: vec!["replay".into(), format!("/tmp/demo/{name}"), "--json".into()],
        expected: vec![],
    };
    let blows: Vec<serde_json::Value> =
        run(root, tmp.path(), &replay).iter().filter_map(|l| serde_json::from_str(l).ok()).collect();
    assert_eq!(blows.len(), 16, "two billets of eight blows");
    assert_eq!(common::out_of_range(&blows), Vec::<String>::new(), "the demo");
}

/// The range check finds what it should: a negative height, an efficiency above 1, a
/// negative energy, an implausible blow with energies or without its reason, a billet that
/// grew.
#[test]
fn the_range_check_finds_each_kind_of_number_out_of_range() {
    let good = serde_json::json!({"blow": 1, "class": "soft", "v_impact_mps": 3.9, "kinetic_in_J": 5711.0,
        "plastic_J": 5320.0, "friction_J": 226.0, "damped_J": 150.0, "elastic_J": 15.0, "efficiency": 0.931,
        "h_start_m": 0.112, "h_end_m": 0.0929, "billet": 1, "reason": null});
    assert_eq!(common::out_of_range(std::slice::from_ref(&good)), Vec::<String>::new());
    let with = |k: &str, v: serde_json::Value| {
        let mut b = good.clone();
        b[k] = v;
        b
    };
    for bad in [
        with("h_start_m", (-0.0068).into()),
        with("efficiency", 1.2.into()),
        with("plastic_J", (-2431.0).into()),
        with("class", "implausible".into()),
        with("h_end_m", 0.2.into()),
        with("v_impact_mps", 0.0.into()),
    ] {
        assert!(!common::out_of_range(std::slice::from_ref(&bad)).is_empty(), "{bad}");
    }
    let grew = [good.clone(), with("blow", 2.into())].map(|mut b| {
        b["h_start_m"] = b["h_start_m"].as_f64().unwrap().into();
        b
    });
    let mut grew = grew.to_vec();
    grew[1]["h_start_m"] = 0.113.into();
    grew[1]["h_end_m"] = 0.1.into();
    assert_eq!(common::out_of_range(&grew).len(), 1, "a billet that grew");
}

/// The parser: commands, continuations, outputs and the README line numbers.
#[test]
fn a_checked_block_is_cut_into_commands_and_their_outputs() {
    let text = format!(
        "intro\n{MARKER}\n```\n$ forgemon a --x 1 \\\n      --y 2\nout 1  \nout 2\n\n$ forgemon b\n```\n\n```\n$ forgemon unchecked\n```\n"
    );
    let got = examples("README.md", &text);
    assert_eq!(got.len(), 2);
    assert_eq!((got[0].line, got[0].args.join(" ")), (4, "a --x 1 --y 2".to_string()));
    assert_eq!(got[0].expected, vec!["out 1", "out 2"]);
    assert_eq!((got[1].line, got[1].args.join(" "), got[1].expected.len()), (9, "b".to_string(), 0));
}
