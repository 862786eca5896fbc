//! Recipes a person reads (issue 40), against the real binary: `forgemon teach` writes its
//! windows in round numbers (no 17-digit floats) that still hold the blows it was taught
//! from, even with every tolerance at 0; `replay --recipe` shows OK or NOK on every row of
//! its table; and a blow a few µm past its travel window is printed with the digits that show
//! it outside, where two decimals printed "18.40 mm outside [18.40, 18.60]".
//!
//! The recording is `forgemon demo --fast --billets 1` (the demo's hammer, one billet of 8
//! blows). Taught from it twice with k = 0 and no tolerance, each window is its blow's own
//! value, rounded outward: the tightest recipe there is, which makes the blows' travels
//! known to the micrometre (`recipe::rounding`).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_forgemon");

/// The demo's recording and a recipe taught from it twice with no tolerance.
fn tight_recipe(dir: &Path) -> (PathBuf, PathBuf) {
    let rec = dir.join("rec");
    let out = Command::new(BIN).args(["demo", "--fast", "--billets", "1", "--dir"]).arg(&rec).output().expect("demo");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mcap = common::files_in(&rec).into_iter().find(|p| p.extension().is_some_and(|x| x == "mcap")).expect("mcap");
    let recipe = dir.join("tight.recipe.toml");
    let out = Command::new(BIN)
        .args(["teach", "--machine"])
        .arg(common::root().join("config/hammer-lg1000.machine.toml"))
        .arg("--reference")
        .arg(&mcap)
        .arg("--reference")
        .arg(&mcap)
        .args(["--k", "0", "--tol-efficiency", "0", "--tol-plastic", "0", "--tol-peak-load", "0", "--tol-load", "0"])
        .args(["--tol-compression-mm", "0", "-o"])
        .arg(&recipe)
        .output()
        .expect("teach");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    (mcap, recipe)
}

/// `replay INPUT --recipe R` (a table, or `--json`): its stdout.
fn replay(input: &Path, recipe: &Path, json: bool) -> String {
    let mut cmd = Command::new(BIN);
    cmd.arg("replay").arg(input).arg("--recipe").arg(recipe);
    if json {
        cmd.arg("--json");
    }
    let out = cmd.output().expect("replay");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The table's blow rows, split on whitespace: blow, t, v, kinetic, plastic, elastic,
/// efficiency, class, final kN, h_end mm, recipe, then the reason's words.
fn rows(table: &str) -> Vec<Vec<String>> {
    table
        .lines()
        .map(|l| l.split_whitespace().map(str::to_string).collect::<Vec<_>>())
        .filter(|w| w.len() >= 10 && w[0].parse::<u32>().is_ok() && w[1].parse::<f64>().is_ok())
        .collect()
}

/// The longest run of digits in the recipe's tables (the header and the reference paths
/// left out).
fn longest_digits(text: &str) -> (usize, String) {
    let body = text.lines().filter(|l| !l.starts_with('#') && !l.starts_with("taught_from"));
    let mut worst = (0, String::new());
    for line in body {
        for run in line.split(|c: char| !c.is_ascii_digit()) {
            if run.len() > worst.0 {
                worst = (run.len(), line.chars().take(120).collect());
            }
        }
    }
    worst
}

#[test]
fn a_taught_recipe_is_written_in_round_numbers_that_hold_the_blows_it_was_taught_from() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mcap, recipe) = tight_recipe(dir.path());
    let text = std::fs::read_to_string(&recipe).expect("written");
    // Efficiency to 1e-4, travel and compression to 1 µm, energies and loads to 4 significant
    // digits (`recipe::rounding`): a load in N is at most 7 digits before its ".0", a travel
    // in m 6 after its "0."; a 17-digit float has runs of 15 and more.
    let (longest, line) = longest_digits(&text);
    assert!(longest <= 7, "a run of {longest} digits: {line}");
    let r = forgemon::config::recipe::parse_recipe("tight.recipe.toml", &text).expect("reads back");
    assert_eq!(r.blows.len(), 8);
    for b in &r.blows {
        for x in [b.efficiency.min, b.efficiency.max] {
            assert_eq!((x * 1e4).round() / 1e4, x, "blow {}: efficiency {x} on 1e-4", b.blow);
        }
        for x in b.compression_m.iter().chain([&b.travel_m.min, &b.travel_m.max]) {
            assert_eq!((x * 1e6).round() / 1e6, *x, "blow {}: {x} m on whole µm", b.blow);
        }
        // Zero tolerance: each window is one value rounded outward, at most one step wide.
        assert!(b.travel_m.max - b.travel_m.min <= 1.000_001e-6, "blow {}: {:?}", b.blow, b.travel_m);
        assert!(b.efficiency.max - b.efficiency.min <= 1.000_001e-4, "blow {}: {:?}", b.blow, b.efficiency);
    }
    // The rounded windows still hold every blow they were taught from: all OK.
    let judged: Vec<serde_json::Value> = replay(&mcap, &recipe, true)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("json")["judgement"].clone())
        .collect();
    assert_eq!(judged.len(), 8);
    assert!(judged.iter().all(|j| j["ok"] == true), "{judged:#?}");
}

/// Blow 1's travel window moved just past the blow, each side: the table's row says NOK
/// with the reason, printed with the digits that put the value outside the bounds as
/// printed; every other blow's row says OK. The window is placed in the same 0.01 mm as the
/// blow's travel, where two decimals print the value on the bound.
#[test]
fn a_blow_just_past_its_travel_window_is_nok_in_the_table_with_the_digits_that_show_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mcap, recipe) = tight_recipe(dir.path());
    let text = std::fs::read_to_string(&recipe).expect("written");
    let r = forgemon::config::recipe::parse_recipe("tight.recipe.toml", &text).expect("reads back");
    // The blow's travel x is within [lo, hi], 1 µm wide (the test above), mm.
    let (lo, hi) = (r.blows[0].travel_m.min * 1e3, r.blows[0].travel_m.max * 1e3);
    let two = |mm: f64| format!("{mm:.2}");
    let bucket = |mm: f64| (mm * 100.0).round() / 100.0;
    // Above: a window whose max is below lo, in lo's 0.01 mm; below: whose min is above hi,
    // in hi's. x is in one of the two (both when lo and hi share one).
    let max_above = 0.5 * (lo + bucket(lo) - 0.005);
    let min_below = 0.5 * (hi + bucket(hi) + 0.005);
    assert_eq!((two(max_above), two(min_below)), (two(lo), two(hi)), "each bound rounds as the travel");
    let line = |a_mm: f64, b_mm: f64| format!("travel_m = [{}, {}]", a_mm / 1e3, b_mm / 1e3);
    let old = format!("travel_m = [{}, {}]", r.blows[0].travel_m.min, r.blows[0].travel_m.max);
    assert!(text.contains(&old), "{old}");
    let mut seen_same_two_decimals = false;
    for (side, window) in [("above", (max_above - 0.2, max_above)), ("below", (min_below, min_below + 0.2))] {
        let moved = dir.path().join(format!("{side}.recipe.toml"));
        std::fs::write(&moved, text.replacen(&old, &line(window.0, window.1), 1)).expect("write");
        let table = replay(&mcap, &moved, false);
        let rows = rows(&table);
        assert_eq!(rows.len(), 8, "{table}");
        for row in &rows[1..] {
            assert_eq!(row[10], "OK", "{row:?}");
        }
        let first = rows[0].join(" ");
        assert_eq!(rows[0][10], "NOK", "{first}");
        // "travel above window: 18.4053 mm outside [18.2052, 18.4052]"
        let reason = first.split(&format!("travel {side} window: ")).nth(1).unwrap_or_else(|| panic!("{first}"));
        let nums: Vec<&str> =
            reason.split([' ', '[', ']', ',', ';']).filter(|w| w.parse::<f64>().is_ok()).take(3).collect();
        let [x, a, b] = [nums[0], nums[1], nums[2]].map(|w| w.parse::<f64>().expect("a number"));
        match side {
            "above" => assert!(x > b, "{first}"),
            _ => assert!(x < a, "{first}"),
        }
        // The fewest digits that do it: the bound is within 6 µm of the travel, so about 3
        // or 4 decimals, not 17.
        let decimals = nums[0].split('.').nth(1).map_or(0, str::len);
        assert!((3..=6).contains(&decimals), "{first}");
        // Two decimals (the old print) put the value on the bound here.
        let bound = if side == "above" { b } else { a };
        seen_same_two_decimals |= two(x) == two(bound);
    }
    assert!(seen_same_two_decimals, "neither side would have printed the value on its bound with two decimals");
}
