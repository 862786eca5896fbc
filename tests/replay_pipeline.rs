//! `forgemon replay` at the process boundary (issue #3): captures generated with the
//! project's own physics are replayed through the built binary and compared with the
//! simulated truth; replay is deterministic, survives a recording cut at any byte, and
//! refuses bad input with a clear message.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use forgemon::physics::{BilletGeometry, EffectSet, FlowStress, Hammer, Machine, MachineKind, Process, ScrewPress};
use forgemon::signal::capture::write_capture;
use forgemon::simdevice::{BilletPlan, SimMachine};
use forgemon::synth::{CaptureSpec, SynthBlow, idle_rows, synth_blows};
use serde_json::Value;

/// A hammer unlike the paper's (Table 1: 732 kg, 19 kg, 3.15e9, 18540).
const HAMMER_TOML: &str = "kind = \"hammer\"\nm1_kg = 900\nm2_kg = 25\nk_N_per_m = 2.5e9\nc_Ns_per_m = 22000\n";
/// A press unlike the paper's (Table 3).
const PRESS_TOML: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 80000\nk_link_N_per_m = 2.0e9\nc_link_Ns_per_m = 3.0e5\n\
                          k_frame_N_per_m = 8e9\nc_frame_Ns_per_m = 0\nk_sensor_N_per_m = 3e10\n";
const STEEL_TOML: &str = "machine = \"hammer\"\n[billet]\ndiameter_m = 0.05\nheight_m = 0.09\n[material]\nmodel = \"constant\"\nsigma0_Pa = 110e6\n[interface]\nfriction = 0.15\n";
const COPPER_TOML: &str = "machine = \"screw_press\"\n[billet]\ndiameter_m = 0.045\nheight_m = 0.028\n[material]\nmodel = \"hansel_spittel\"\n\
                           A_Pa = 411.19e6\nm1 = -0.00121\nm2 = 0.21554\nm3 = 0.01472\nm4 = -0.00935\ntemperature_C = 20\n[interface]\nfriction = 0.08\n";

fn hammer() -> Machine {
    Machine::Hammer(Hammer {
        m1_kg: 900.0,
        m2_kg: 25.0,
        k_n_per_m: 2.5e9,
        c_ns_per_m: 22000.0,
        k_tool_contact_n_per_m: 6e10,
    })
}
fn press() -> Machine {
    Machine::ScrewPress(ScrewPress {
        m_tool_kg: 2500.0,
        m_ram_kg: 80000.0,
        k_link_n_per_m: 2.0e9,
        c_link_ns_per_m: 3.0e5,
        k_frame_n_per_m: 8e9,
        c_frame_ns_per_m: 0.0,
        k_sensor_n_per_m: 3e10,
        k_tool_contact_n_per_m: f64::INFINITY,
    })
}
fn steel() -> Process {
    Process {
        machine: MachineKind::Hammer,
        billet: BilletGeometry { diameter_m: 0.05, height_m: 0.09 },
        material: FlowStress::Constant { sigma0_pa: 110e6 },
        friction: 0.15,
        measured_final_heights_m: vec![],
    }
}
fn copper() -> Process {
    Process {
        machine: MachineKind::ScrewPress,
        billet: BilletGeometry { diameter_m: 0.045, height_m: 0.028 },
        material: FlowStress::HanselSpittel {
            a_pa: 411.19e6,
            m1: -0.00121,
            m2: 0.21554,
            m3: 0.01472,
            m4: -0.00935,
            temperature_c: 20.0,
        },
        friction: 0.08,
        measured_final_heights_m: vec![],
    }
}

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("forgemon-replay-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn forgemon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forgemon")).args(args).output().expect("run forgemon")
}

fn replay_json(args: &[&str]) -> Vec<Value> {
    let out = forgemon(args);
    assert!(out.status.success(), "forgemon {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line per blow"))
        .collect()
}

/// Write a capture directory (blow_NN.csv + process.toml) and the machine file.
fn write_case(dir: &Path, blows: &[SynthBlow], machine_toml: &str, process_toml: &str) -> PathBuf {
    let caps = dir.join("captures");
    std::fs::create_dir_all(&caps).unwrap();
    for (i, b) in blows.iter().enumerate() {
        let mut f = std::fs::File::create(caps.join(format!("blow_{:02}.csv", i + 1))).unwrap();
        write_capture(&mut f, &b.rows).unwrap();
    }
    std::fs::write(caps.join("process.toml"), process_toml).unwrap();
    std::fs::write(dir.join("machine.toml"), machine_toml).unwrap();
    caps
}

fn f(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"))
}

/// Issue #3: every blow found, efficiency within 0.03 absolute of the simulated truth,
/// impact speed within 1 %.
fn assert_matches_truth(found: &[Value], truth: &[SynthBlow]) {
    assert_eq!(found.len(), truth.len(), "no missed and no extra blows");
    for (v, t) in found.iter().zip(truth) {
        let e = f(v, "efficiency");
        assert!(
            (e - t.truth.efficiency()).abs() < 0.03,
            "blow {}: efficiency {e} vs {}",
            v["blow"],
            t.truth.efficiency()
        );
        let s = f(v, "v_impact_mps");
        assert!((s / t.truth.v0_mps - 1.0).abs() < 0.01, "blow {}: speed {s} vs {}", v["blow"], t.truth.v0_mps);
        assert!((f(v, "t_contact_s") - t.t_contact_s).abs() < 1e-3, "blow {}: contact time", v["blow"]);
        let class = v["class"].as_str().unwrap();
        assert!(["soft", "intermediate", "hard"].contains(&class));
    }
}

#[test]
fn hammer_blows_down_to_hard_blows_match_the_simulated_truth() {
    let truth = synth_blows(
        &hammer(),
        &EffectSet::NONE,
        &steel(),
        &[4.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0],
        &CaptureSpec::hammer(11),
    )
    .unwrap();
    assert!(truth.last().unwrap().truth.efficiency() < 0.5, "the sequence reaches hard blows");
    let dir = tmpdir("hammer");
    let caps = write_case(&dir, &truth, HAMMER_TOML, STEEL_TOML);
    let m = dir.join("machine.toml");
    let found = replay_json(&["replay", caps.to_str().unwrap(), "--machine", m.to_str().unwrap(), "--json"]);
    assert_matches_truth(&found, &truth);
    // The hard blows raise the elastic-blow alert (debounced: not on every one).
    let alerts: Vec<&Value> = found.iter().filter(|v| !v["alert"].is_null()).collect();
    assert!(!alerts.is_empty() && alerts.len() < found.iter().filter(|v| v["class"] == "hard").count() + 1);
    assert_eq!(alerts[0]["alert"]["kind"], "elastic_blow");
    // The process sheet was found in the directory: friction and height are reported.
    assert!(found[0]["friction_J"].is_number() && found[0]["h_end_m"].is_number());
}

#[test]
fn press_blows_match_the_simulated_truth() {
    let truth = synth_blows(&press(), &EffectSet::NONE, &copper(), &[0.4; 8], &CaptureSpec::press(12)).unwrap();
    let dir = tmpdir("press");
    let caps = write_case(&dir, &truth, PRESS_TOML, COPPER_TOML);
    let m = dir.join("machine.toml");
    let found = replay_json(&["replay", caps.to_str().unwrap(), "--machine", m.to_str().unwrap(), "--json"]);
    assert_matches_truth(&found, &truth);
}

#[test]
fn a_continuous_stream_with_several_blows_is_cut_into_each_blow() {
    // The blows of one billet in one CSV, with the machine idle between them.
    let spec = CaptureSpec::hammer(13);
    let truth = synth_blows(&hammer(), &EffectSet::NONE, &steel(), &[4.0, 5.0, 5.0], &spec).unwrap();
    let mut rows = Vec::new();
    for (i, b) in truth.iter().enumerate() {
        rows.extend(idle_rows(50_000, 0.0, &spec, b.rows[0].disp_m, 100 + i as u64));
        rows.extend_from_slice(&b.rows);
    }
    // Make the stream one clock: shift each piece to follow the previous one.
    let dt = 1.0 / spec.sample_rate_hz;
    let t_start = rows[0].t_s;
    for (k, r) in rows.iter_mut().enumerate() {
        r.t_s = t_start + k as f64 * dt;
    }
    let dir = tmpdir("stream");
    let csv = dir.join("stream.csv");
    write_capture(&mut std::fs::File::create(&csv).unwrap(), &rows).unwrap();
    std::fs::write(dir.join("machine.toml"), HAMMER_TOML).unwrap();
    let found = replay_json(&[
        "replay",
        csv.to_str().unwrap(),
        "--machine",
        dir.join("machine.toml").to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(found.len(), 3);
    for (v, t) in found.iter().zip(&truth) {
        // Without a process sheet plastic_J holds plastic + friction (docs/interfaces.md §5).
        assert!(v["friction_J"].is_null() && v["h_end_m"].is_null());
        let deform = t.truth.energy.plastic_j + t.truth.energy.friction_j;
        assert!((f(v, "plastic_J") / deform - 1.0).abs() < 0.03, "{v}");
    }
}

#[test]
fn replay_is_deterministic_and_its_recording_replays_identically() {
    let truth =
        synth_blows(&hammer(), &EffectSet::NONE, &steel(), &[4.0, 5.0, 5.0, 5.0], &CaptureSpec::hammer(14)).unwrap();
    let dir = tmpdir("determinism");
    let caps = write_case(&dir, &truth, HAMMER_TOML, STEEL_TOML);
    let m = dir.join("machine.toml");
    let (m, caps) = (m.to_str().unwrap(), caps.to_str().unwrap());
    let rec = dir.join("replay.mcap");
    let first = forgemon(&["replay", caps, "--machine", m, "--json", "--out", rec.to_str().unwrap()]);
    let second = forgemon(&["replay", caps, "--machine", m, "--json"]);
    assert!(first.status.success() && second.status.success());
    assert_eq!(first.stdout, second.stdout, "replaying twice gives identical JSON");
    // The recording holds the process sheet, so replaying it needs only the machine.
    let again = forgemon(&["replay", rec.to_str().unwrap(), "--machine", m, "--json"]);
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
    assert_eq!(first.stdout, again.stdout, "replaying the --out recording gives identical JSON");
}

#[test]
fn a_recording_cut_at_any_byte_replays_the_blows_it_holds() {
    let truth =
        synth_blows(&hammer(), &EffectSet::NONE, &steel(), &[4.0, 5.0, 5.0, 5.0, 5.0, 5.0], &CaptureSpec::hammer(15))
            .unwrap();
    let dir = tmpdir("crash");
    let caps = write_case(&dir, &truth, HAMMER_TOML, STEEL_TOML);
    let m = dir.join("machine.toml");
    let m = m.to_str().unwrap();
    let rec = dir.join("full.mcap");
    let full =
        replay_json(&["replay", caps.to_str().unwrap(), "--machine", m, "--json", "--out", rec.to_str().unwrap()]);
    let bytes = std::fs::read(&rec).unwrap();
    let mut recovered_any = false;
    for frac in [0.15, 0.37, 0.61, 0.83, 0.97] {
        let cut = dir.join(format!("cut-{frac}.mcap"));
        std::fs::write(&cut, &bytes[..(bytes.len() as f64 * frac) as usize]).unwrap();
        let out = forgemon(&["replay", cut.to_str().unwrap(), "--machine", m, "--json"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "cut at {frac}: {err}");
        assert!(err.contains("cut off"), "the reader says the file was cut: {err}");
        let got: Vec<Value> =
            String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        // Every blow it holds completely comes out exactly as in the full replay; a blow
        // whose samples were cut may come out different or not at all, and only the last.
        for (i, g) in got.iter().enumerate() {
            if i + 1 < got.len() {
                assert_eq!(g, &full[i], "cut at {frac}, blow {}", i + 1);
            }
        }
        recovered_any |= got.len() >= 2;
    }
    assert!(recovered_any, "cuts past the middle recover whole blows");
}

fn fails_naming(args: &[&str], needles: &[&str]) {
    let out = forgemon(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} should fail");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr of {args:?} should name '{n}': {err}");
    }
}

#[test]
fn bad_input_is_refused_with_file_line_and_key() {
    let dir = tmpdir("bad");
    let m = dir.join("machine.toml");
    std::fs::write(&m, HAMMER_TOML).unwrap();
    let m = m.to_str().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    // One channel may be missing (issue 43), two may not.
    let missing = write("missing.csv", "t_s,load_N\n0,1\n");
    fails_naming(&["replay", &missing, "--machine", m], &[&missing, ":1:", "disp_m", "at least two of"]);
    let back = write("back.csv", "t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,1,2,3\n0.0005,1,2,3\n");
    fails_naming(&["replay", &back, "--machine", m], &[&back, ":4:", "does not increase"]);
    let text = write("text.csv", "t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,heavy,2,3\n");
    fails_naming(&["replay", &text, "--machine", m], &[&text, ":3:", "load_N", "heavy"]);
    let empty = write("empty.csv", "");
    fails_naming(&["replay", &empty, "--machine", m], &[&empty, "empty"]);
    let junk = write("junk.mcap", "this is not an MCAP file at all, just text\n");
    fails_naming(&["replay", &junk, "--machine", m], &[&junk]);
    let caps = dir.join("caps");
    std::fs::create_dir_all(&caps).unwrap();
    std::fs::write(caps.join("blow_01.csv"), "t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,1,2,3\n").unwrap();
    std::fs::write(caps.join("process.toml"), COPPER_TOML).unwrap();
    fails_naming(&["replay", caps.to_str().unwrap(), "--machine", m], &["process.toml", "'machine'", "screw_press"]);
    let nodir = dir.join("nothing");
    std::fs::create_dir_all(&nodir).unwrap();
    fails_naming(&["replay", nodir.to_str().unwrap(), "--machine", m], &["no blow_NN.csv"]);
    // A capture holds no machine model: without --machine, the error says what to give.
    fails_naming(&["replay", &missing], &[&missing, "holds no machine model", "--machine"]);
}

/// Issue 22: a recording replays with the alert rules and billet detection it was recorded
/// with (the service file it stores), unless `--service` gives others. Four billets of
/// heights up to 8 % apart in one continuous stream: recorded with a new-billet rise of
/// 0.5 m (more than any billet) and a low-efficiency alert on any blow below 0.99, they are
/// one billet that alerts on at least half its blows (debounced over one); with the
/// defaults, four billets and fewer alerts.
#[test]
fn a_recording_replays_with_the_billet_detection_and_alert_rules_it_stored() {
    let base = BilletPlan { process: steel(), v0s_mps: vec![4.0, 5.0, 5.0] };
    let plans = forgemon::simdevice::spread_plans(&base, 4, 0.08, 3);
    let mut sim = SimMachine::new(hammer(), EffectSet::NONE, plans, CaptureSpec::hammer(31), 0.2);
    let mut rows = Vec::new();
    while !sim.finished() {
        rows.extend(sim.next_rows(50_000).unwrap());
    }
    let dir = tmpdir("tuning");
    let csv = dir.join("stream.csv");
    write_capture(&mut std::fs::File::create(&csv).unwrap(), &rows).unwrap();
    std::fs::write(dir.join("machine.toml"), HAMMER_TOML).unwrap();
    std::fs::write(dir.join("process.toml"), STEEL_TOML).unwrap();
    std::fs::write(dir.join("tuned.toml"), "[alerts]\nlow_efficiency = 0.99\nk_low = 1\nn_window = 1\ndebounce_blows = 1\n[billets]\nnew_billet_rise_m = 0.5\n")
        .unwrap();
    std::fs::write(dir.join("defaults.toml"), "").unwrap();
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (m, p, rec) = (path("machine.toml"), path("process.toml"), path("tuned.mcap"));
    let billets = |v: &[Value]| v.iter().map(|b| b["billet"].as_u64().unwrap()).collect::<Vec<_>>();
    // A blow below `low_efficiency` raises an `elastic_blow` alert (k of the last n).
    let low = |v: &[Value]| v.iter().filter(|b| b["alert"]["kind"] == "elastic_blow").count();

    let tuned = forgemon(&[
        "replay",
        &path("stream.csv"),
        "--machine",
        &m,
        "--process",
        &p,
        "--service",
        &path("tuned.toml"),
        "--json",
        "--out",
        &rec,
    ]);
    assert!(tuned.status.success(), "{}", String::from_utf8_lossy(&tuned.stderr));
    let tuned_json: Vec<Value> =
        String::from_utf8(tuned.stdout.clone()).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(tuned_json.len(), 12);
    assert_eq!(billets(&tuned_json), vec![1; 12]);
    let tuned_low = low(&tuned_json);
    assert!(tuned_low >= 6, "{tuned_low} elastic-blow alerts");
    // The stored service file rules the replay of the recording: the same JSON, byte for byte
    // (the machine model and the process sheet come from the recording too).
    let again = forgemon(&["replay", &rec, "--json"]);
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
    assert_eq!(again.stdout, tuned.stdout);
    // Other rules on the same recording: four billets, and fewer alerts.
    let defaults = replay_json(&["replay", &rec, "--machine", &m, "--service", &path("defaults.toml"), "--json"]);
    assert_eq!(billets(&defaults), [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4]);
    assert!(low(&defaults) < tuned_low, "{} vs {tuned_low} elastic-blow alerts", low(&defaults));
    // Every billet's summary is in the recording, and the table prints one line per billet.
    let out = forgemon(&["inspect", "--json", &rec]);
    let inspected: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((inspected["billets"].as_u64(), inspected["billets_finished"].as_u64()), (Some(1), Some(0)));
    assert_eq!(inspected["billet_summaries"][0]["blows"], 12);
    let table = forgemon(&["replay", &rec, "--machine", &m, "--service", &path("defaults.toml")]);
    let text = String::from_utf8_lossy(&table.stdout);
    assert_eq!(text.lines().filter(|l| l.starts_with("billet ")).count(), 4, "{text}");
}
