//! Serial transport throughput (issue #4 target: 3 channels at 100 kHz over the binary
//! framing of docs/interfaces.md §7 use ≤ 10 % of one core, i.e. 300 k samples/s need
//! ≥ 3 M samples/s of decode). One iteration is 1 s of a 100 kHz 3-channel DAQ: 1000
//! frames of 100 samples (1.2 kB each), handed to the decoder in 4 KiB reads as a serial
//! port delivers them, COBS-decoded, CRC-checked and turned into `SampleBatch`es in
//! physical units. Reported in samples (per channel) per second. Also: the same through
//! the ASCII line decoder, and the encoder (the simulated device's cost).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use forgemon::acquire::ChannelSpec;
use forgemon::acquire::serial::ascii::{AsciiEvent, LineDecoder};
use forgemon::acquire::serial::{Frame, FrameDecoder, FrameTracker, encode_frame};
use forgemon::signal::sample::Role;

const FRAME_SAMPLES: usize = 100;
const FRAMES: usize = 1000;
const PERIOD_NS: u32 = 10_000;
/// One read from the port.
const READ_BYTES: usize = 4096;

fn channels() -> Vec<ChannelSpec> {
    vec![
        ChannelSpec { role: Role::Load, gain: 10.0, offset: 0.0 },
        ChannelSpec { role: Role::Disp, gain: 1e-6, offset: 0.0 },
        ChannelSpec { role: Role::Acc, gain: 1e-3, offset: 0.0 },
    ]
}

/// Counts as a DAQ delivers them: a load swing, a moving encoder, a noisy accelerometer.
fn frames() -> Vec<Frame> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f64 / (1u64 << 24) as f64 - 0.5
    };
    (0..FRAMES)
        .map(|k| {
            let mut counts = Vec::with_capacity(3 * FRAME_SAMPLES);
            for i in 0..FRAME_SAMPLES {
                let t = (k * FRAME_SAMPLES + i) as f64 * PERIOD_NS as f64 * 1e-9;
                counts.push((1e5 * (t * 40.0).sin() + 200.0 * noise()) as i32);
                counts.push((437_500.0 + 1e5 * t) as i32);
                counts.push((9810.0 + 2000.0 * noise()) as i32);
            }
            Frame {
                channel_count: 3,
                sample_count: FRAME_SAMPLES as u16,
                sequence: k as u32,
                device_time_ns: k as u64 * FRAME_SAMPLES as u64 * PERIOD_NS as u64,
                sample_period_ns: PERIOD_NS,
                counts,
            }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let frames = frames();
    let wire: Vec<u8> = frames.iter().flat_map(encode_frame).collect();
    let samples = (FRAMES * FRAME_SAMPLES) as u64;
    let mut g = c.benchmark_group("serial");
    g.throughput(Throughput::Elements(samples));
    g.bench_function("binary_decode_3ch_100k_1s", |b| {
        b.iter(|| {
            let mut dec = FrameDecoder::new();
            let mut tracker = FrameTracker::new("daq", channels());
            let mut n = 0;
            for chunk in wire.chunks(READ_BYTES) {
                dec.push(chunk);
                while let Some(r) = dec.next_frame() {
                    let t = tracker.track(&r.expect("a good frame"), 0).expect("3 channels");
                    n += black_box(t.batch).len();
                }
            }
            assert_eq!(n as u64, samples);
        })
    });
    g.bench_function("binary_encode_3ch_100k_1s", |b| {
        b.iter(|| frames.iter().map(|f| black_box(encode_frame(f)).len()).sum::<usize>())
    });
    let text: String = frames
        .iter()
        .flat_map(|f| {
            let t0 = f.device_time_ns as f64 * 1e-9;
            f.counts.chunks(3).enumerate().map(move |(i, c)| {
                format!(
                    "{:.7},{:.1},{:.6},{:.3}\n",
                    t0 + i as f64 * 1e-5,
                    c[0] as f64 * 10.0,
                    c[1] as f64 * 1e-6,
                    c[2] as f64 * 1e-3
                )
            })
        })
        .collect();
    g.bench_function("ascii_decode_3ch_100k_1s", |b| {
        b.iter(|| {
            let mut dec = LineDecoder::new("daq", vec![Role::Load, Role::Disp, Role::Acc], 0.02);
            let mut n = 0;
            for chunk in text.as_bytes().chunks(READ_BYTES) {
                dec.push(chunk, 0);
                while let Some(ev) = dec.next_event() {
                    n += matches!(black_box(ev), AsciiEvent::Batch(_)) as usize;
                }
            }
            dec.flush(0);
            n
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
