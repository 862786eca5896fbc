//! Issue 39: a recipe is checked like `forgemon teach` output wherever it comes from. The
//! real service (`forgemon run`) judges with a good recipe given at its start, and `POST
//! /recipe` is sent what it used to accept: an efficiency window of [−1e308, 1e308], an
//! infinite envelope bound, a 60,000-point envelope, a name of 65 characters and one with a
//! newline and an ANSI escape; each is refused with 400 naming its key and the allowed range,
//! echoing nothing raw, and a body over 1 MiB with 413. The recipe in force stays (`/status`)
//! and the recording holds only the recipe of the start. A recipe file at the start with the
//! same errors stops it, naming the file and the key.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{KillOnDrop, free_port, http_get, http_send, spawn_service};
use forgemon::config::recipe::write_recipe;
use forgemon::recipe::{BlowWindows, Recipe, Tolerances, Window};
use forgemon::record::{Payload, RecordReader};

const HAMMER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/hammer-lg1000.machine.toml");

/// A hammer recipe named `name`, one blow, as `teach` writes it.
fn recipe_text(name: &str) -> String {
    let r = Recipe {
        name: name.into(),
        machine: "hammer".into(),
        tolerances: Tolerances::default(),
        billets: 3,
        taught_from: vec!["good.mcap".into()],
        blows: vec![BlowWindows {
            blow: 1,
            efficiency: Window { min: 0.9, max: 0.95 },
            plastic_j: Window { min: 6000.0, max: 7000.0 },
            peak_load_n: Window { min: 1e6, max: 1.2e6 },
            travel_m: Window { min: 0.018, max: 0.020 },
            compression_m: vec![0.0, 1e-3, 2e-3],
            load_lower_n: vec![-1e4, 2e5, 4e5],
            load_upper_n: vec![1e4, 3e5, 6e5],
        }],
    };
    write_recipe(&r).expect("a recipe writes")
}

/// `dir/service.toml`: the LG1000 with `recipe`, its status endpoint on `http`, recording
/// under `dir/rec`, and a serial source whose device is absent (the service waits for it).
fn service_file(dir: &Path, http: u16, recipe: &str) -> PathBuf {
    let cfg = format!(
        r#"machine = "{HAMMER}"
recipe = "{recipe}"
[recording]
dir = "rec"
[http]
listen = "127.0.0.1:{http}"
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
    );
    let path = dir.join("service.toml");
    std::fs::write(&path, cfg).expect("write");
    path
}

fn status(port: u16) -> serde_json::Value {
    serde_json::from_str(&http_get(port, "/status").expect("/status answers")).expect("json")
}

/// A recipe text with its one blow's envelope at `n` points (the compression in µm).
fn with_envelope(text: &str, n: usize) -> String {
    let list = |f: &dyn Fn(usize) -> String| (0..n).map(f).collect::<Vec<_>>().join(",");
    let (mut out, mut in_blows): (Vec<String>, bool) = (Vec::new(), false);
    for line in text.lines() {
        in_blows |= line == "[[blows]]";
        out.push(match line.split(" = ").next().filter(|_| in_blows) {
            Some("compression_m") => format!("compression_m = [{}]", list(&|j| format!("{j}e-6"))),
            Some("load_lower_N") => format!("load_lower_N = [{}]", list(&|_| "0".into())),
            Some("load_upper_N") => format!("load_upper_N = [{}]", list(&|_| "1".into())),
            _ => line.to_string(),
        });
    }
    out.join("\n")
}

#[test]
fn post_recipe_refuses_what_teach_never_writes_and_keeps_the_recipe_in_force() {
    let dir = tempfile::tempdir().expect("tempdir");
    let good = recipe_text("good");
    std::fs::write(dir.path().join("good.recipe.toml"), &good).expect("write");
    let http = free_port();
    let mut child = KillOnDrop(spawn_service(&service_file(dir.path(), http, "good.recipe.toml"), http));
    assert_eq!(status(http)["recipe"], "good");
    let bad: [(&str, String, &[&str]); 6] = [
        (
            "efficiency window [-1e308, 1e308]",
            good.replace("efficiency = [0.9, 0.95]", "efficiency = [-1e308, 1e308]"),
            &["blows[1].efficiency", "within 0..1"],
        ),
        (
            "load_upper_N = inf",
            good.replace("load_upper_N = [10000.0,", "load_upper_N = [inf,"),
            &["blows[1].load_upper_N", "-1e11..1e11 N"],
        ),
        ("a 60,000-point envelope", with_envelope(&good, 60_000), &["blows[1].compression_m", "2..=200"]),
        ("a 65-character name", good.replace("\"good\"", &format!("\"{}\"", "n".repeat(65))), &["'name'", "64"]),
        (
            "a name with a newline and an ANSI escape",
            good.replace("\"good\"", "\"good\\n\\u001b[31mred\""),
            &["'name'", "control character"],
        ),
        (
            "a negative travel",
            good.replace("travel_m = [0.018,", "travel_m = [-0.5,"),
            &["blows[1].travel_m", "0..2 m"],
        ),
    ];
    for (what, body, words) in &bad {
        let (code, answer) = http_send(http, "POST", "/recipe", body.as_bytes());
        assert_eq!(code, 400, "{what}: {answer}");
        for w in *words {
            assert!(answer.contains(w), "{what}: the answer names {w:?}: {answer}");
        }
        assert!(!answer.contains('\u{1b}') && answer.lines().count() == 1, "{what}: echoed raw: {answer:?}");
        assert_eq!(status(http)["recipe"], "good", "{what}: the recipe in force changed");
    }
    // A body over 1 MiB is refused before it is read: a name of 1.5 MB.
    let huge = good.replace("\"good\"", &format!("\"{}\"", "n".repeat(1_500_000)));
    let (code, answer) = http_send(http, "POST", "/recipe", huge.as_bytes());
    assert_eq!(code, 413, "{answer}");
    assert!(answer.contains("1048576 bytes"), "{answer}");
    assert_eq!(status(http)["recipe"], "good");
    // A good one still switches (the route works), and its text is what the recording keeps.
    let (code, answer) = http_send(http, "POST", "/recipe", recipe_text("other").as_bytes());
    assert_eq!(code, 202, "{answer}");
    let deadline = Instant::now() + Duration::from_secs(10);
    while status(http)["recipe"] != "other" {
        assert!(Instant::now() < deadline, "the good recipe was not taken");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(Command::new("kill").args(["-TERM", &child.0.id().to_string()]).status().expect("kill").success());
    assert!(child.0.wait().expect("wait").success());
    let rec = common::files_in(&dir.path().join("rec"));
    let recorded: Vec<String> = rec
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .flat_map(|p| RecordReader::open(p).expect("a recording"))
        .filter_map(|m| match m.ok()?.payload {
            Payload::Config(c) if c.name == "recipe.toml" => Some(c.text),
            _ => None,
        })
        .collect();
    assert_eq!(recorded, [good, recipe_text("other")], "the start's recipe and the accepted one, nothing refused");
}

#[test]
fn a_recipe_file_out_of_range_stops_the_start_naming_the_file_and_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = [
        ("efficiency = [0.9, 0.95]", "efficiency = [-1e308, 1e308]", "blows[1].efficiency"),
        ("load_upper_N = [10000.0,", "load_upper_N = [inf,", "blows[1].load_upper_N"),
        ("name = \"good\"", "name = \"good\\u001b[2J\"", "'name'"),
    ];
    for (from, to, key) in cases {
        std::fs::write(dir.path().join("bad.recipe.toml"), recipe_text("good").replace(from, to)).expect("write");
        let log = dir.path().join("run.log");
        let mut child = KillOnDrop(
            Command::new(env!("CARGO_BIN_EXE_forgemon"))
                .args(["run", "--config"])
                .arg(service_file(dir.path(), free_port(), "bad.recipe.toml"))
                .stdout(Stdio::null())
                .stderr(std::fs::File::create(&log).expect("log"))
                .spawn()
                .expect("run runs"),
        );
        let deadline = Instant::now() + Duration::from_secs(10);
        let status = loop {
            if let Some(s) = child.0.try_wait().expect("wait") {
                break s;
            }
            assert!(Instant::now() < deadline, "{to}: the service started with the bad recipe");
            std::thread::sleep(Duration::from_millis(20));
        };
        let err = std::fs::read_to_string(&log).expect("the log");
        assert_eq!(status.code(), Some(1), "{to}: {err}");
        assert!(err.contains("bad.recipe.toml:") && err.contains(key), "{to}: names the file and {key}: {err}");
        assert!(!dir.path().join("rec").exists(), "{to}: refused before anything opened");
    }
}
