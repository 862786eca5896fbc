//! Recording throughput (issue #3 target: ≥ 5 M samples/s into zstd MCAP on one core):
//! 3-channel samples at 100 kHz in 50 ms batches (5000 samples, 15 000 doubles each),
//! written with the default options (zstd level 1, single-threaded compression, 1 MiB
//! chunks, chunk close + `sync_data` every second of log time) to a file in the temp
//! directory, finished and renamed. Reported in samples (per channel) per second. Also:
//! zstd without the syncs (the disk's share), lz4, uncompressed, the sample encoder
//! alone, and reading each file back (the decode share of replay).
//!
//! The history's tap (issue 44): the zstd case with a blow result every 0.5 s, with and
//! without the history database's live writer (`history::writer::LiveHistory`) tapping
//! the recorder, alternated in the same process; printed as the ratio of their times, the
//! anchor the run without it.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use forgemon::record::codec::encode_samples;
use forgemon::record::writer::DEFAULT_SYNC_INTERVAL_NS;
use forgemon::record::{ChunkCompression, RecordOptions, RecordReader, RecordWriter};
use forgemon::signal::sample::{Role, SampleBatch};

const PERIOD_NS: i64 = 10_000; // 100 kHz
const BATCH_SAMPLES: usize = 5_000; // 50 ms
/// 4 s of recording per iteration: 4 syncs.
const BATCHES: usize = 80;

/// Signals as a DAQ delivers them: quantised counts times a gain, with noise.
fn batches() -> Vec<SampleBatch> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f64 / (1u64 << 24) as f64 - 0.5
    };
    (0..BATCHES)
        .map(|k| {
            let mut values = Vec::with_capacity(3 * BATCH_SAMPLES);
            for i in 0..BATCH_SAMPLES {
                let t = (k * BATCH_SAMPLES + i) as f64 * PERIOD_NS as f64 * 1e-9;
                let load_counts = (2e4 * (t * 40.0).sin() + 30.0 * noise()).round();
                let disp_counts = (5e4 * (1.0 - t * 0.1) + 2.0 * noise()).round();
                let acc_counts = (981.0 + 200.0 * noise()).round();
                values.extend([load_counts * 61.03, disp_counts * 1e-5, acc_counts * 0.01]);
            }
            SampleBatch {
                source: "daq0".into(),
                seq: k as u64,
                device_time_ns: k as i64 * BATCH_SAMPLES as i64 * PERIOD_NS,
                host_time_ns: 1_000_000_000 + k as i64 * BATCH_SAMPLES as i64 * PERIOD_NS,
                period_ns: PERIOD_NS as f64,
                roles: vec![Role::Load, Role::Disp, Role::Acc],
                values,
            }
        })
        .collect()
}

fn record(c: &mut Criterion) {
    let input = batches();
    let dir = std::env::temp_dir().join(format!("forgemon-bench-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut g = c.benchmark_group("record");
    g.throughput(Throughput::Elements((BATCHES * BATCH_SAMPLES) as u64));
    g.sample_size(20);
    let zstd = ChunkCompression::Zstd { level: forgemon::record::writer::DEFAULT_ZSTD_LEVEL };
    for (name, compression, sync_interval_ns) in [
        ("zstd_100kHz_3ch_50ms", zstd, DEFAULT_SYNC_INTERVAL_NS),
        // The same without the once-a-second sync_data: what the disk costs.
        ("zstd_100kHz_3ch_50ms_no_sync", zstd, u64::MAX),
        ("lz4_100kHz_3ch_50ms", ChunkCompression::Lz4, DEFAULT_SYNC_INTERVAL_NS),
        ("uncompressed_100kHz_3ch_50ms", ChunkCompression::None, DEFAULT_SYNC_INTERVAL_NS),
    ] {
        let path = dir.join(format!("{name}.mcap"));
        let options = RecordOptions { compression, sync_interval_ns, ..RecordOptions::default() };
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut w = RecordWriter::create_with(&path, options).expect("create");
                for batch in &input {
                    w.write_samples(black_box(batch)).expect("write");
                }
                w.finish().expect("finish")
            })
        });
        let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        let raw = (BATCHES * BATCH_SAMPLES * 3 * 8) as f64;
        eprintln!("{name}: {size} bytes, {:.2} of the raw doubles", size as f64 / raw);
    }
    g.bench_function("encode_samples_only", |b| {
        let mut buf = Vec::new();
        b.iter(|| {
            for batch in &input {
                buf.clear();
                encode_samples(black_box(batch), &mut buf).expect("encode");
            }
            buf.len()
        })
    });
    for name in ["zstd_100kHz_3ch_50ms", "lz4_100kHz_3ch_50ms", "uncompressed_100kHz_3ch_50ms"] {
        let path = dir.join(format!("{name}.mcap"));
        g.bench_function(format!("read_back_{name}"), |b| {
            b.iter(|| {
                let reader = RecordReader::open(&path).expect("open");
                let mut n = 0usize;
                for m in reader {
                    black_box(m.expect("message"));
                    n += 1;
                }
                n
            })
        });
    }
    g.finish();
    history_tap(&input, &dir);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The recorder's time with the history's tap over its time without, alternated for
/// `ROUNDS` rounds: the median ratio and the rounds' range.
fn history_tap(input: &[SampleBatch], dir: &std::path::Path) {
    const ROUNDS: usize = 15;
    let result = forgemon::estimate::BlowEstimate {
        gap_s: 0.4,
        ..forgemon::estimate::BlowEstimate::incomplete(1, 0.5, 5.3, 0.6)
    };
    let run = |tapped: bool, round: usize| {
        let path = dir.join(format!("tap-{tapped}-{round}.mcap"));
        let live = tapped.then(|| {
            forgemon::history::writer::LiveHistory::start(dir.join(format!("tap-{round}.sqlite")), None)
                .expect("a database")
        });
        let options = RecordOptions::default();
        let start = std::time::Instant::now();
        let mut w = RecordWriter::create_with(&path, options).expect("create");
        if let Some(l) = &live {
            w.set_tap(l.tap());
        }
        for (k, batch) in input.iter().enumerate() {
            w.write_samples(black_box(batch)).expect("write");
            // A blow every 0.5 s of samples (10 batches).
            if k % 10 == 9 {
                w.write_result(batch.host_time_ns, &result).expect("write");
            }
        }
        w.finish().expect("finish");
        let took = start.elapsed().as_secs_f64();
        if let Some(l) = live {
            l.finish();
        }
        took
    };
    let mut ratios: Vec<f64> = (0..ROUNDS).map(|r| run(true, r) / run(false, r)).collect();
    ratios.sort_by(f64::total_cmp);
    eprintln!(
        "record/history_tap: {:.3}x the recorder's time without the tap (median of {ROUNDS} alternated rounds; range {:.3}-{:.3})",
        ratios[ROUNDS / 2],
        ratios[0],
        ratios[ROUNDS - 1]
    );
}

criterion_group!(benches, record);
criterion_main!(benches);
