//! Crash safety of recordings at the file boundary (DESIGN.md §3 "Crash safety", issue #3):
//! a recording cut at an arbitrary byte still reads, and gives back exactly the messages
//! of the chunks written completely before the cut — at least everything before the last
//! `sync_data`; a file that is not MCAP is an error naming the file; rotation by size
//! gives finished files that together hold every message in order.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use forgemon::alert::{Alert, AlertKind};
use forgemon::estimate::{BlowClass, BlowEstimate};
use forgemon::record::{
    BlowBoundary, Payload, ReadReport, RecordError, RecordReader, RecordWriter, Recorded, Rotation, SyncPoint,
    read_recording,
};
use forgemon::signal::sample::{Role, SampleBatch};

const MS: i64 = 1_000_000;
/// 10 kHz, 3 channels, 50 ms batches: 500 samples, 1500 values, 12 kB a batch.
const PERIOD_NS: f64 = 100_000.0;
const BATCH_SAMPLES: usize = 500;
const BATCHES: i64 = 160; // 8 s of log time: 8 syncs

/// Deterministic noise, so the chunks do not compress to nothing.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

fn batch(k: i64, rng: &mut Lcg) -> SampleBatch {
    SampleBatch {
        source: "daq0".into(),
        seq: k as u64,
        device_time_ns: 7 * MS + k * 50 * MS,
        host_time_ns: 1_000 * MS + k * 50 * MS,
        period_ns: PERIOD_NS,
        roles: vec![Role::Load, Role::Disp, Role::Acc],
        values: (0..3 * BATCH_SAMPLES).map(|i| 1e5 * rng.next() + i as f64).collect(),
    }
}

fn result(blow: u32) -> BlowEstimate {
    let hard = blow.is_multiple_of(4);
    BlowEstimate {
        judgement: None,
        blow,
        t_contact_s: 0.7 * f64::from(blow),
        v_impact_mps: 3.9,
        kinetic_in_j: Some(5711.0),
        plastic_j: Some(if hard { 1500.0 } else { 5320.0 }),
        friction_j: Some(226.0),
        damped_j: Some(150.0),
        elastic_j: Some(15.0),
        efficiency: Some(if hard { 0.26 } else { 0.93 }),
        final_load_n: 3.25e5,
        h_end_m: Some(0.1 - 0.005 * f64::from(blow)),
        class: if hard { BlowClass::Hard } else { BlowClass::Soft },
        alert: hard.then(|| alert(blow)),
        t_end_s: 0.7 * f64::from(blow) + 0.02,
        peak_load_n: 1.16e6,
        residual: Some(0.001 * f64::from(blow)),
        sensor_check: Some(-0.002 * f64::from(blow)),
        method: None,
        gap_s: 0.0,
        h_start_m: None,
        height_source: forgemon::estimate::HeightSource::Unknown,
        implausible: None,
        flow_stress_scale: None,
        scale_by_half: None,
        model_residual: None,
        model_residual_by_phase: None,
        at_bound: Default::default(),
        height_check: None,
        billet: Default::default(),
        channels: Default::default(),
        efficiency_sd: None,
        unobserved: Default::default(),
        excluded: Default::default(),
        acc_check: None,
    }
}

fn alert(blow: u32) -> Alert {
    Alert {
        kind: AlertKind::ElasticBlow,
        blow,
        reason: format!("blow {blow} is hard: efficiency 0.26 below 0.5"),
        figures: BTreeMap::from([("efficiency".to_string(), 0.26)]),
    }
}

/// The messages of a recording, in the order they are written: config, then sample
/// batches with a blow boundary, result (and alert for hard blows) every 14 batches.
fn messages() -> Vec<(i64, Payload)> {
    let mut rng = Lcg(42);
    let mut out = vec![(
        1_000 * MS,
        Payload::Config(forgemon::record::ConfigFile {
            name: "machine.toml".into(),
            text: "kind = \"hammer\"\n".into(),
        }),
    )];
    let mut blow = 0;
    for k in 0..BATCHES {
        let b = batch(k, &mut rng);
        let t = b.host_time_ns;
        out.push((t, Payload::Samples(b)));
        if k % 14 == 13 {
            blow += 1;
            let r = result(blow);
            out.push((
                t,
                Payload::Boundary(BlowBoundary {
                    blow,
                    t_trigger_s: r.t_contact_s - 0.001,
                    t_contact_s: r.t_contact_s,
                    t_end_s: r.t_end_s,
                    source: "daq0".into(),
                }),
            ));
            if let Some(a) = &r.alert {
                out.push((t, Payload::Alert(a.clone())));
            }
            out.push((t, Payload::Result(Box::new(r))));
        }
    }
    out
}

/// Write `msgs`; return the finished file and the sync points seen along the way.
fn record(path: &Path, msgs: &[(i64, Payload)]) -> (PathBuf, Vec<SyncPoint>) {
    let mut w = RecordWriter::create(path, Rotation::NEVER).expect("create");
    let mut syncs: Vec<SyncPoint> = Vec::new();
    for (t, p) in msgs {
        w.write_payload(*t, p).expect("write");
        if let Some(s) = w.last_sync()
            && syncs.last() != Some(&s)
        {
            syncs.push(s);
        }
    }
    let files = w.finish().expect("finish");
    assert_eq!(files.len(), 1);
    (files[0].clone(), syncs)
}

/// Every message of a file, in file order, and the report.
fn read_in_file_order(path: &Path) -> Result<(Vec<Recorded>, ReadReport), RecordError> {
    let mut reader = RecordReader::open(path)?;
    let msgs = reader.by_ref().collect::<Result<Vec<_>, _>>()?;
    Ok((msgs, reader.report().clone()))
}

/// (end offset, message count) of each chunk, from the finished file's index.
fn chunk_ends(bytes: &[u8]) -> Vec<(u64, usize)> {
    let summary = mcap::Summary::read(bytes).expect("summary").expect("finished file has a summary");
    summary
        .chunk_indexes
        .iter()
        .map(|c| {
            let count = summary.stream_chunk(bytes, c).expect("chunk").count();
            (c.chunk_start_offset + c.chunk_length, count)
        })
        .collect()
}

#[test]
fn a_recording_cut_anywhere_gives_back_every_chunk_before_the_cut() {
    let dir = tempfile::tempdir().expect("temp dir");
    let written = messages();
    let (path, syncs) = record(&dir.path().join("full.mcap"), &written);
    assert!(syncs.len() >= 7, "8 s of log time syncs at least 7 times, got {}", syncs.len());

    let bytes = std::fs::read(&path).expect("read back");
    let (all, report) = read_in_file_order(&path).expect("read full");
    assert!(report.complete && report.indexed);
    let as_written: Vec<(i64, Payload)> = all.iter().map(|m| (m.log_time_ns, m.payload.clone())).collect();
    assert_eq!(as_written, written, "the finished file holds everything, in order");

    let chunks = chunk_ends(&bytes);
    assert!(chunks.len() >= 8, "a chunk per sync at least: {}", chunks.len());
    let data_end = chunks.last().map(|c| c.0).expect("chunks");
    let (last_start, _) = chunks[chunks.len() - 2];

    let len = bytes.len() as u64;
    let mut cuts: Vec<u64> = [0.10, 0.37, 0.61, 0.90].iter().map(|f| (len as f64 * f) as u64).collect();
    cuts.extend([
        (last_start + data_end) / 2, // inside the last chunk
        chunks[3].0,                 // exactly at the end of a chunk
        chunks[3].0 - 1,             // one byte short of it
        9,                           // the magic and one byte
        data_end + 30,               // data complete, summary cut
        len - 1,                     // footer magic short by one byte
    ]);
    for cut in cuts {
        let cut_path = dir.path().join(format!("cut-{cut}.mcap.part"));
        std::fs::write(&cut_path, &bytes[..cut as usize]).expect("write cut copy");
        let (got, report) = read_in_file_order(&cut_path).unwrap_or_else(|e| panic!("cut at {cut}: {e}"));

        let expected: usize = chunks.iter().filter(|(end, _)| *end <= cut).map(|(_, n)| n).sum();
        assert_eq!(got.len(), expected, "cut at byte {cut} of {len}: {report}");
        assert_eq!(got, all[..expected], "cut at byte {cut}: the recovered messages are the first ones, intact");
        let synced = syncs.iter().filter(|s| s.file_bytes <= cut).map(|s| s.file_messages).max().unwrap_or(0);
        assert!(got.len() as u64 >= synced, "cut at {cut}: lost messages from before the last sync ({synced})");

        assert!(!report.complete, "cut at {cut}: {report}");
        assert_eq!(report.messages, expected as u64);
        assert_eq!(report.total_bytes, cut);
        assert!(report.bytes_recovered <= cut, "{report}");
        assert!(report.stopped_by.is_some(), "cut at {cut}: the report says why it stopped");
        assert!(report.to_string().contains("cut off"), "{report}");

        // The in-memory read of the same cut agrees and is in log-time order.
        let rec = read_recording(&cut_path).expect("read_recording");
        assert_eq!(rec.messages.len(), expected);
        assert!(rec.messages.windows(2).all(|w| w[0].log_time_ns <= w[1].log_time_ns));
    }
}

#[test]
fn a_live_part_file_copied_mid_chunk_recovers_everything_synced() {
    // What `kill -9` leaves: the open chunk has a placeholder header and is half written.
    let dir = tempfile::tempdir().expect("temp dir");
    let written = messages();
    let mut w = RecordWriter::create(dir.path().join("live.mcap"), Rotation::NEVER).expect("create");
    let part = w.current_path();
    let mut checked = 0;
    // Images with bytes after the last sync: a half-written chunk with a placeholder header.
    let mut partial_tails = 0;
    for (i, (t, p)) in written.iter().enumerate() {
        w.write_payload(*t, p).expect("write");
        // Between syncs, some batches in: the current chunk is open.
        if i % 7 == 6 {
            let image = std::fs::read(&part).expect("copy the live file");
            let crashed = dir.path().join(format!("crash-{i}.mcap.part"));
            std::fs::write(&crashed, &image).expect("write image");
            let (got, report) = read_in_file_order(&crashed).unwrap_or_else(|e| panic!("after message {i}: {e}"));
            let synced = w.last_sync().map_or(0, |s| s.file_messages) as usize;
            if image.len() as u64 > w.last_sync().map_or(0, |s| s.file_bytes) {
                partial_tails += 1;
            }
            assert!(got.len() >= synced, "after message {i}: {} recovered, {synced} synced; {report}", got.len());
            assert!(got.len() <= i + 1);
            let expected: Vec<(i64, Payload)> = written[..got.len()].to_vec();
            let recovered: Vec<(i64, Payload)> = got.into_iter().map(|m| (m.log_time_ns, m.payload)).collect();
            assert_eq!(recovered, expected);
            assert!(!report.complete);
            checked += 1;
        }
    }
    assert!(checked >= 5);
    assert!(partial_tails >= 2, "only {partial_tails} images end in a half-written chunk");
    w.finish().expect("finish");
}

#[test]
fn a_file_that_is_not_mcap_is_an_error_naming_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut rng = Lcg(7);
    let random: Vec<u8> = (0..4096).map(|_| ((rng.next() + 0.5) * 255.0) as u8).collect();
    let cases: [(&str, &[u8]); 4] = [
        ("random.mcap", &random),
        ("blow_01.csv", b"t_s,load_N,disp_m,acc_mps2\n79.9620978,2273.6,0.519860,12.53\n"),
        ("empty.mcap", b""),
        ("short.mcap", b"\x89MC"),
    ];
    for (name, content) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, content).expect("write");
        for result in [read_recording(&path).map(|_| ()), RecordReader::open(&path).map(|_| ())] {
            let err = result.expect_err(name);
            assert!(matches!(err, RecordError::NotMcap { .. }), "{name}: {err:?}");
            assert!(err.to_string().contains(name), "the error names the file: {err}");
        }
    }
    let missing = dir.path().join("missing.mcap");
    let err = read_recording(&missing).expect_err("missing file");
    assert!(err.to_string().contains("missing.mcap"), "{err}");

    // The magic alone is an MCAP file cut right after it: nothing in it, not an error.
    let magic_only = dir.path().join("magic.mcap.part");
    std::fs::write(&magic_only, mcap::MAGIC).expect("write");
    let rec = read_recording(&magic_only).expect("magic only reads");
    assert!(rec.messages.is_empty() && !rec.report.complete);

    // Garbage after a valid start: what is before it is kept, the rest is reported.
    let (full, _) = record(&dir.path().join("ok.mcap"), &messages());
    let mut bytes = std::fs::read(&full).expect("read");
    let keep = chunk_ends(&bytes)[1].0 as usize;
    bytes.truncate(keep);
    bytes.extend(std::iter::repeat_n(0xA5u8, 5000));
    let garbled = dir.path().join("garbled.mcap");
    std::fs::write(&garbled, &bytes).expect("write");
    let (got, report) = read_in_file_order(&garbled).expect("garbage after good chunks reads");
    let expected: usize = chunk_ends(&std::fs::read(&full).expect("read"))[..2].iter().map(|c| c.1).sum();
    assert_eq!(got.len(), expected, "{report}");
    assert!(report.stopped_by.is_some());
}

#[test]
fn rotation_by_size_gives_finished_files_holding_every_message_in_order() {
    let dir = tempfile::tempdir().expect("temp dir");
    let target = dir.path().join("rec");
    let written = messages();
    let mut w = RecordWriter::create(&target, Rotation::by_size(400_000)).expect("create");
    for (t, p) in &written {
        w.write_payload(*t, p).expect("write");
    }
    let files = w.finish().expect("finish");
    assert!(files.len() >= 3, "{} files", files.len());
    for f in std::fs::read_dir(&target).expect("list").flatten() {
        let name = f.file_name().to_string_lossy().to_string();
        assert!(name.ends_with(".mcap") && !name.ends_with(".part"), "{name} left unfinished");
    }

    let mut joined: Vec<(i64, Payload)> = Vec::new();
    for (i, f) in files.iter().enumerate() {
        assert!(std::fs::metadata(f).expect("exists").len() < 400_000 + 1024 * 1024, "at most a chunk over");
        let (msgs, report) = read_in_file_order(f).expect("read");
        assert!(report.complete && report.indexed, "{report}");
        let mut msgs = msgs.into_iter().map(|m| (m.log_time_ns, m.payload));
        if i > 0 {
            // Each later file starts with the configuration again.
            let first = msgs.next().expect("not empty");
            assert_eq!(first.1, written[0].1, "{} starts with the config", f.display());
        }
        joined.extend(msgs);
    }
    assert_eq!(joined, written);
}
