//! Interop (issue #3, "Must show"): a recording with every channel is decoded by the public
//! Python packages `mcap` and `mcap-protobuf-support` through `tests/python/read_mcap.py`,
//! using only the FileDescriptorSets stored in the file, and what they decode must be what
//! was written, billet summaries included. CI installs the packages (`.ci/run`); elsewhere the test fails saying how.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use forgemon::alert::{Alert, AlertKind};
use forgemon::estimate::billet_book::BilletSummary;
use forgemon::estimate::{BlowClass, BlowEstimate};
use forgemon::record::{BlowBoundary, Gap, RecordWriter, Rotation, Status};
use forgemon::signal::sample::{Channels, Role, SampleBatch};
use serde_json::Value;

const MS: i64 = 1_000_000;
const INSTALL: &str = "python3 -m pip install mcap mcap-protobuf-support";

fn batch(source: &str, k: i64, roles: Vec<Role>) -> SampleBatch {
    let channels = roles.len();
    SampleBatch {
        source: source.into(),
        seq: 1000 + k as u64,
        device_time_ns: -3 * MS + k * 20 * MS,
        host_time_ns: 5_000 * MS + k * 20 * MS,
        period_ns: 10_000.0,
        roles,
        values: (0..2000 * channels).map(|i| (i as f64) * 0.25 - 100.0 + k as f64).collect(),
    }
}

fn alert(blow: u32) -> Alert {
    Alert {
        kind: AlertKind::ElasticBlow,
        blow,
        reason: "hard blow: efficiency 0.31 below 0.5".into(),
        figures: BTreeMap::from([("efficiency".to_string(), 0.31), ("threshold".to_string(), 0.5)]),
    }
}

fn result(blow: u32, with_sheet: bool) -> BlowEstimate {
    // Without a sheet the blow is also an incomplete one: no energies, a gap.
    let whole = with_sheet;
    BlowEstimate {
        judgement: None,
        blow,
        t_contact_s: 81.2031 + f64::from(blow),
        v_impact_mps: 5.21,
        kinetic_in_j: whole.then_some(14931.0),
        plastic_j: whole.then_some(6020.0),
        friction_j: with_sheet.then_some(6900.0),
        damped_j: whole.then_some(520.0),
        elastic_j: whole.then_some(1490.0),
        efficiency: whole.then_some(0.403),
        final_load_n: 2.1e6,
        h_end_m: with_sheet.then_some(0.0124),
        class: if with_sheet { BlowClass::Hard } else { BlowClass::Incomplete },
        alert: with_sheet.then(|| alert(blow)),
        t_end_s: 81.2152 + f64::from(blow),
        peak_load_n: 2.6e6,
        residual: whole.then_some(-0.012),
        sensor_check: whole.then_some(0.021),
        method: with_sheet.then_some(forgemon::estimate::Method::Observer),
        gap_s: if whole { 0.0 } else { 0.0125 },
        h_start_m: with_sheet.then_some(0.0151),
        height_source: forgemon::estimate::HeightSource::Unknown,
        implausible: None,
        flow_stress_scale: None,
        scale_by_half: None,
        model_residual: None,
        model_residual_by_phase: None,
        at_bound: Default::default(),
        height_check: None,
        billet: Default::default(),
        channels: if with_sheet { Default::default() } else { Channels::ALL.without(Role::Load) },
        efficiency_sd: whole.then_some(0.004),
        unobserved: Default::default(),
        excluded: if whole {
            Default::default()
        } else {
            [("load".to_string(), "load_N disagrees with the accelerometer and the encoder".to_string())].into()
        },
        acc_check: whole.then_some(-0.0013),
    }
}

/// Run the Python reader on `path`; its JSON.
fn billet(n: u32, whole: bool) -> BilletSummary {
    BilletSummary {
        billet: n,
        t_start_s: 10.5 * f64::from(n),
        t_end_s: 10.5 * f64::from(n) + 3.25,
        blows: if whole { 8 } else { 1 },
        incomplete_blows: u32::from(!whole),
        implausible_blows: 0,
        energies_partial: !whole,
        h_start_m: whole.then_some(0.1121),
        h_start_off_sheet_m: whole.then_some(1.5e-4),
        h_end_m: whole.then_some(0.0402),
        kinetic_in_j: if whole { 91_250.0 } else { 0.0 },
        plastic_j: if whole { 55_125.5 } else { 0.0 },
        friction_j: whole.then_some(20_500.25),
        efficiency: whole.then_some(55_125.5 / 91_250.0),
        first_hard_blow: whole.then_some(6),
        hard_blows: if whole { 3 } else { 0 },
        alerts: if whole { 1 } else { 0 },
        checked_blows: u32::from(!whole),
        finished: whole,
        trace: forgemon::estimate::billet_book::Trace {
            part_id: whole.then(|| format!("P-{n:04}")),
            lot: whole.then(|| "4711".into()),
            die_set: None,
        },
    }
}

fn python_read(path: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/read_mcap.py");
    let out = match Command::new("python3").arg(&script).arg(path).output() {
        Ok(out) => out,
        Err(e) => panic!("cannot run python3 ({e}): install Python 3, then `{INSTALL}`"),
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    match out.status.code() {
        Some(0) => {}
        Some(3) => panic!("the Python MCAP packages are missing: run `{INSTALL}`\n{stderr}"),
        _ => panic!("read_mcap.py failed ({}):\n{stderr}", out.status),
    }
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("read_mcap.py printed no JSON ({e}):\n{stderr}"))
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn python_mcap_protobuf_decodes_every_channel() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("interop.mcap");
    let mut w = RecordWriter::create(&path, Rotation::NEVER).expect("create");
    let t0 = 5_000 * MS;
    let machine = "kind = \"hammer\"\nm1_kg = 732\n";
    let process = "machine = \"hammer\"\n[billet]\ndiameter_m = 0.06\n";
    w.write_config(t0 - MS, "machine.toml", machine).expect("config");
    w.write_config(t0 - MS, "process.toml", process).expect("config");
    w.write_status(t0, &Status { source: "daq0".into(), state: "connected".into(), samples: 0, ..Status::default() })
        .expect("status");
    let mut sums = BTreeMap::<String, f64>::new();
    for k in 0..60 {
        let a = batch("daq0", k, vec![Role::Load, Role::Disp, Role::Acc]);
        let b = batch("modbus1", k, vec![Role::Load]);
        *sums.entry("daq0".into()).or_default() += a.values.iter().sum::<f64>();
        *sums.entry("modbus1".into()).or_default() += b.values.iter().sum::<f64>();
        w.write_samples(&a).expect("samples");
        w.write_samples(&b).expect("samples");
    }
    let t_blow = t0 + 600 * MS;
    for blow in 1..=3 {
        let t = t_blow + i64::from(blow) * 100 * MS;
        let r = result(blow, blow != 2);
        w.write_boundary(
            t,
            &BlowBoundary {
                blow,
                t_trigger_s: r.t_contact_s - 0.002,
                t_contact_s: r.t_contact_s,
                t_end_s: r.t_end_s,
                source: "daq0".into(),
            },
        )
        .expect("boundary");
        w.write_result(t, &r).expect("result");
        if let Some(a) = &r.alert {
            w.write_alert(t, a).expect("alert");
        }
    }
    // Billet 1 finished with every figure; billet 2 in the dies at the end, its one blow
    // incomplete, so no heights, efficiency or hard blow.
    let billets = [billet(1, true), billet(2, false)];
    for (i, b) in billets.iter().enumerate() {
        w.write_billet(t_blow + 400 * MS + i as i64 * MS, b).expect("billet");
    }
    w.write_gap(t0 + 700 * MS, &Gap { source: "daq0".into(), t_s: 0.7, samples_lost: 400, reason: "crc".into() })
        .expect("gap");
    w.write_status(
        t0 + 1_500 * MS,
        &Status {
            source: "daq0".into(),
            state: "stopped".into(),
            samples: 120_000,
            frames: 60,
            drops: 1,
            gaps: 1,
            crc_errors: 2,
            decode_errors: 3,
            reconnects: 4,
            detail: "/dev/ttyACM0".into(),
        },
    )
    .expect("status");
    w.finish().expect("finish");

    let json = python_read(&path);
    let topics = &json["topics"];
    let count = |t: &str| topics[t]["count"].as_u64().unwrap_or(0);
    let expected = [
        ("/samples/daq0", 60, "forgemon.SampleBatch"),
        ("/samples/modbus1", 60, "forgemon.SampleBatch"),
        ("/blows", 3, "forgemon.BlowBoundary"),
        ("/results", 3, "forgemon.BlowResult"),
        ("/alerts", 2, "forgemon.Alert"),
        ("/gaps", 1, "forgemon.Gap"),
        ("/status", 2, "forgemon.Status"),
        ("/config", 2, "forgemon.ConfigFile"),
        ("/billets", 2, "forgemon.BilletSummary"),
    ];
    assert_eq!(topics.as_object().map(|o| o.len()), Some(expected.len()), "topics: {topics}");
    for (topic, n, schema) in expected {
        assert_eq!(count(topic), n, "{topic}");
        assert_eq!(topics[topic]["schema"], schema, "{topic}");
        assert_eq!(topics[topic]["schema_encoding"], "protobuf");
        assert_eq!(topics[topic]["message_encoding"], "protobuf");
    }
    assert_eq!(json["summary_message_count"], 135);

    // Samples: every field of the first batch, and the sum of every value of each source.
    for source in ["daq0", "modbus1"] {
        let msgs = topics[format!("/samples/{source}")]["messages"].as_array().expect("messages").clone();
        let first = &msgs[0];
        let roles: Vec<Role> =
            if source == "daq0" { vec![Role::Load, Role::Disp, Role::Acc] } else { vec![Role::Load] };
        let want = batch(source, 0, roles.clone());
        assert_eq!(first["source"], source);
        assert_eq!(first["seq"], 1000);
        assert_eq!(first["device_time_ns"], -3 * MS);
        assert_eq!(first["host_time_ns"], 5_000 * MS);
        assert_eq!(first["log_time"], 5_000 * MS, "log time = host time");
        assert_eq!(f(&first["period_ns"]), 10_000.0);
        let role_names: Vec<&str> =
            first["roles"].as_array().expect("roles").iter().filter_map(Value::as_str).collect();
        let want_names: Vec<&str> = roles
            .iter()
            .map(|r| match r {
                Role::Load => "ROLE_LOAD_N",
                Role::Disp => "ROLE_DISP_M",
                Role::Acc => "ROLE_ACC_MPS2",
            })
            .collect();
        assert_eq!(role_names, want_names);
        assert_eq!(first["n_values"], want.values.len());
        let head: Vec<f64> = first["values_head"].as_array().expect("head").iter().map(f).collect();
        assert_eq!(head, want.values[..6]);
        let sum: f64 = msgs.iter().map(|m| f(&m["values_sum"])).sum();
        let want_sum = sums[source];
        assert!((sum - want_sum).abs() <= 1e-9 * want_sum.abs().max(1.0), "{source}: {sum} vs {want_sum}");
    }

    // Results: the optional fields are absent exactly when they were None.
    let results = topics["/results"]["messages"].as_array().expect("results");
    for (i, r) in results.iter().enumerate() {
        let blow = i as u32 + 1;
        let want = result(blow, blow != 2);
        assert_eq!(r["blow"], blow);
        assert_eq!(r["efficiency"].as_f64(), want.efficiency, "blow {blow}");
        assert_eq!(r["kinetic_in_J"].as_f64(), want.kinetic_in_j, "blow {blow}");
        assert_eq!(r["plastic_J"].as_f64(), want.plastic_j, "blow {blow}");
        assert_eq!(r["residual"].as_f64(), want.residual, "blow {blow}");
        assert_eq!(f(&r["gap_s"]), want.gap_s, "blow {blow}");
        assert_eq!(f(&r["final_load_N"]), want.final_load_n);
        assert_eq!(f(&r["t_contact_s"]), want.t_contact_s);
        assert_eq!(r["class"], want.class.as_str());
        assert_eq!(r["friction_J"].as_f64(), want.friction_j, "blow {blow}");
        assert_eq!(r["h_end_m"].as_f64(), want.h_end_m, "blow {blow}");
        assert_eq!(r["method"].as_str(), want.method.map(|m| m.as_str()), "blow {blow}");
        assert_eq!(r["channels"], serde_json::json!(want.channels.names()), "blow {blow}");
        assert_eq!(r["efficiency_sd"].as_f64(), want.efficiency_sd, "blow {blow}");
        assert_eq!(r["acc_check"].as_f64(), want.acc_check, "blow {blow}");
        assert_eq!(
            serde_json::from_value::<std::collections::BTreeMap<String, String>>(r["excluded"].clone()).ok().as_ref(),
            Some(&want.excluded),
            "blow {blow}"
        );
        match &want.alert {
            Some(a) => {
                assert_eq!(r["alert"]["kind"], "elastic_blow");
                assert_eq!(r["alert"]["blow"], a.blow);
                assert_eq!(f(&r["alert"]["figures"]["efficiency"]), 0.31);
            }
            None => assert!(r["alert"].is_null(), "blow {blow}: {}", r["alert"]),
        }
    }
    let alerts = topics["/alerts"]["messages"].as_array().expect("alerts");
    assert_eq!(alerts[0]["reason"], alert(1).reason);
    assert_eq!(f(&alerts[1]["figures"]["threshold"]), 0.5);

    let blows = topics["/blows"]["messages"].as_array().expect("blows");
    assert_eq!(blows[2]["blow"], 3);
    assert_eq!(blows[2]["source"], "daq0");
    assert_eq!(f(&blows[2]["t_contact_s"]), result(3, true).t_contact_s);

    let gap = &topics["/gaps"]["messages"][0];
    assert_eq!((gap["samples_lost"].as_u64(), gap["reason"].as_str()), (Some(400), Some("crc")));
    let status = &topics["/status"]["messages"][1];
    assert_eq!(status["state"], "stopped");
    assert_eq!(status["crc_errors"], 2);
    assert_eq!(status["reconnects"], 4);
    assert_eq!(status["detail"], "/dev/ttyACM0");

    // Billets: every field, the optional ones absent exactly when they were None.
    let decoded = topics["/billets"]["messages"].as_array().expect("billets");
    for (d, b) in decoded.iter().zip(&billets) {
        let n = b.billet;
        assert_eq!((d["billet"].as_u64(), d["blows"].as_u64()), (Some(u64::from(n)), Some(u64::from(b.blows))));
        assert_eq!((f(&d["t_start_s"]), f(&d["t_end_s"])), (b.t_start_s, b.t_end_s), "billet {n}");
        assert_eq!(d["incomplete_blows"].as_u64(), Some(u64::from(b.incomplete_blows)), "billet {n}");
        assert_eq!(d["energies_partial"].as_bool(), Some(b.energies_partial), "billet {n}");
        assert_eq!(d["h_start_m"].as_f64(), b.h_start_m, "billet {n}");
        assert_eq!(d["h_start_off_sheet_m"].as_f64(), b.h_start_off_sheet_m, "billet {n}");
        assert_eq!(d["h_end_m"].as_f64(), b.h_end_m, "billet {n}");
        assert_eq!((f(&d["kinetic_in_J"]), f(&d["plastic_J"])), (b.kinetic_in_j, b.plastic_j), "billet {n}");
        assert_eq!(d["friction_J"].as_f64(), b.friction_j, "billet {n}");
        assert_eq!(d["efficiency"].as_f64(), b.efficiency, "billet {n}");
        assert_eq!(d["first_hard_blow"].as_u64(), b.first_hard_blow.map(u64::from), "billet {n}");
        assert_eq!(d["hard_blows"].as_u64(), Some(u64::from(b.hard_blows)), "billet {n}");
        assert_eq!(d["alerts"].as_u64(), Some(u64::from(b.alerts)), "billet {n}");
        assert_eq!(d["checked_blows"].as_u64(), Some(u64::from(b.checked_blows)), "billet {n}");
        assert_eq!(d["finished"].as_bool(), Some(b.finished), "billet {n}");
        assert_eq!(d["part_id"].as_str(), b.trace.part_id.as_deref(), "billet {n}");
        assert_eq!(d["lot"].as_str(), b.trace.lot.as_deref(), "billet {n}");
        assert_eq!(d["die_set"].as_str(), b.trace.die_set.as_deref(), "billet {n}");
    }

    let configs = topics["/config"]["messages"].as_array().expect("config");
    assert_eq!(configs[0]["name"], "machine.toml");
    assert_eq!(configs[0]["text"], machine);
    assert_eq!(configs[1]["name"], "process.toml");
    assert_eq!(configs[1]["text"], process);
}
