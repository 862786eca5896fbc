//! The serial transport at the IO boundary (issue #4): a simulated hammer's blows, from the
//! project's own physics and the example configs, quantised to counts and streamed over a
//! real pty pair (`tokio_serial::SerialStream::pair()`) in the binary framing of
//! docs/interfaces.md §7 and in the ASCII variant. The driver's events go through the live
//! pipeline, which must find every blow with the simulated efficiency; injected garbage,
//! corrupt CRCs, dropped frames and a lost link are counted and recorded as gaps.

mod common;

use std::time::Duration;

use forgemon::acquire::serial::{
    Frame, HostClock, SerialConfig, SerialFormat, encode_frame, run, run_on_stream, run_with, system_clock_ns,
};
use forgemon::acquire::{ChannelSpec, SourceEvent};
use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::{EffectSet, Machine, Process};
use forgemon::pipeline::{Pipeline, PipelineConfig};
use forgemon::record::{Gap, Status};
use forgemon::signal::capture::CaptureRow;
use forgemon::signal::sample::{Role, SampleBatch};
use forgemon::synth::{CaptureSpec, SynthBlow, idle_rows, synth_blows};
use tokio::io::AsyncWriteExt;
use tokio::sync::{mpsc, watch};
use tokio_serial::{SerialPort, SerialStream};

/// Samples per frame: 1 ms at 100 kHz.
const FRAME_SAMPLES: usize = 100;
/// Period of the simulated DAQ, ns (100 kHz).
const PERIOD_NS: u32 = 10_000;
/// Idle samples before each blow (0.3 s), so the trigger re-arms between blows.
const IDLE_SAMPLES: usize = 30_000;
/// The first frame's sequence: close to the wrap, so the stream crosses it.
const FIRST_SEQ: u32 = u32::MAX - 700;

fn machine_and_process() -> (Machine, Process) {
    let root = env!("CARGO_MANIFEST_DIR");
    let m = std::fs::read_to_string(format!("{root}/config/hammer-lg1000.machine.toml")).unwrap();
    let p = std::fs::read_to_string(format!("{root}/config/steel-16NiCrMo13.process.toml")).unwrap();
    (parse_machine("hammer-lg1000.machine.toml", &m).unwrap().machine, parse_process("steel.process.toml", &p).unwrap())
}

/// The DAQ's channels: load 10 N/count, encoder 1 µm/count, accelerometer 1 mm/s²/count.
fn channels() -> Vec<ChannelSpec> {
    vec![
        ChannelSpec { role: Role::Load, gain: 10.0, offset: -2000.0 },
        ChannelSpec { role: Role::Disp, gain: 1e-6, offset: 0.25 },
        ChannelSpec { role: Role::Acc, gain: 1e-3, offset: 0.0 },
    ]
}

/// Blows of one billet (paper §3.1: 3.9 m/s, then 5.3 m/s) with the machine idle before
/// each, as one continuous 100 kHz stream.
fn session(seed: u64) -> (Vec<SynthBlow>, Vec<CaptureRow>) {
    let (machine, process) = machine_and_process();
    let spec = CaptureSpec::hammer(seed);
    let truth = synth_blows(&machine, &EffectSet::NONE, &process, &[3.9, 5.3, 5.3, 5.3], &spec).unwrap();
    let mut rows = Vec::new();
    for (i, b) in truth.iter().enumerate() {
        rows.extend(idle_rows(IDLE_SAMPLES, 0.0, &spec, b.rows[0].disp_m, 200 + i as u64));
        rows.extend_from_slice(&b.rows);
    }
    rows.extend(idle_rows(IDLE_SAMPLES, 0.0, &spec, rows.last().unwrap().disp_m, 99));
    let t0 = rows[0].t_s;
    for (k, r) in rows.iter_mut().enumerate() {
        r.t_s = t0 + k as f64 * PERIOD_NS as f64 * 1e-9;
    }
    (truth, rows)
}

/// The rows quantised to counts and cut into frames of `FRAME_SAMPLES`.
fn frames(rows: &[CaptureRow]) -> Vec<Frame> {
    let ch = channels();
    let t0_ns = (rows[0].t_s * 1e9).round() as u64;
    rows.chunks(FRAME_SAMPLES)
        .enumerate()
        .map(|(k, chunk)| {
            let mut counts = Vec::with_capacity(chunk.len() * 3);
            for r in chunk {
                for (c, v) in ch.iter().zip([r.load_n, r.disp_m, r.acc_mps2]) {
                    counts.push(((v - c.offset) / c.gain).round() as i32);
                }
            }
            Frame {
                channel_count: 3,
                sample_count: chunk.len() as u16,
                sequence: FIRST_SEQ.wrapping_add(k as u32),
                device_time_ns: t0_ns + (k * FRAME_SAMPLES) as u64 * PERIOD_NS as u64,
                sample_period_ns: PERIOD_NS,
                counts,
            }
        })
        .collect()
}

/// Frame indices in the idle stretch before the first blow: faults there cost no blow.
fn idle_frame(i: usize) -> usize {
    (IDLE_SAMPLES / FRAME_SAMPLES) * i / 10 + 5
}

/// `wire` (one encoded frame) with a sample bit flipped and the CRC left as it was.
fn corrupt_copy(wire: &[u8]) -> Vec<u8> {
    let mut payload = cobs::decode_vec(&wire[..wire.len() - 1]).unwrap();
    payload[30] ^= 0x04; // a byte of counts[0][..]
    let mut bad = cobs::encode_vec(&payload);
    bad.push(0x00);
    bad
}

fn fixed_clock() -> i64 {
    1_700_000_000_000_000_000
}
const CLOCK: HostClock = fixed_clock;

fn cfg(format: SerialFormat, path: &str) -> SerialConfig {
    SerialConfig::new("daq0", path, 921_600, format, channels())
}

/// Collects everything the driver sends; counts samples as they arrive.
struct Collected {
    batches: Vec<SampleBatch>,
    gaps: Vec<Gap>,
    statuses: Vec<Status>,
    /// Every event, in the order received.
    order: Vec<SourceEvent>,
}

fn spawn_collector(mut rx: mpsc::Receiver<SourceEvent>) -> (tokio::task::JoinHandle<Collected>, watch::Receiver<u64>) {
    let (samples_tx, samples_rx) = watch::channel(0u64);
    let h = tokio::spawn(async move {
        let mut c = Collected { batches: vec![], gaps: vec![], statuses: vec![], order: vec![] };
        let mut n = 0u64;
        while let Some(ev) = rx.recv().await {
            match &ev {
                SourceEvent::Batch(b) => {
                    n += b.len() as u64;
                    let _ = samples_tx.send(n);
                    c.batches.push(b.clone());
                }
                SourceEvent::Gap(g) => c.gaps.push(g.clone()),
                SourceEvent::Status(s) => {
                    c.statuses.push(s.clone());
                    let _ = samples_tx.send(n);
                }
            }
            c.order.push(ev);
        }
        c
    });
    (h, samples_rx)
}

async fn wait_for_samples(rx: &mut watch::Receiver<u64>, n: u64) {
    let ok = tokio::time::timeout(Duration::from_secs(60), rx.wait_for(|got| *got >= n)).await.is_ok();
    assert!(ok, "timed out waiting for {n} samples, got {}", *rx.borrow());
}

/// Feed the events through the pipeline (`common::blows_through`).
fn blows_found(events: &[SourceEvent]) -> Vec<forgemon::estimate::BlowEstimate> {
    let (machine, process) = machine_and_process();
    common::blows_through(Pipeline::new(machine, Some(process), PipelineConfig::for_machine(&machine)), events)
}

/// Issue #4: every blow found; efficiency within 0.03 of the simulated truth (the bound
/// replay meets on the same captures, issue #3), impact speed within 1 %.
fn assert_every_blow(events: &[SourceEvent], truth: &[SynthBlow]) {
    let found = blows_found(events);
    assert_eq!(found.len(), truth.len(), "no blow lost and none invented");
    for (e, t) in found.iter().zip(truth) {
        let want = t.truth.efficiency();
        let eff = e.efficiency.expect("a whole blow has an efficiency");
        assert!((eff - want).abs() < 0.03, "blow {}: efficiency {eff} vs {want}", e.blow);
        assert!((e.v_impact_mps / t.truth.v0_mps - 1.0).abs() < 0.01, "blow {}: speed", e.blow);
    }
}

fn last_status(c: &Collected) -> &Status {
    c.statuses.last().expect("a status")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn binary_frames_over_a_pty_with_garbage_corrupt_crcs_and_a_dropped_frame() {
    let (truth, rows) = session(41);
    let frames = frames(&rows);
    let dropped = idle_frame(5);
    // Noise glued to the front of these frames (no delimiter between): docs/interfaces.md §7
    // drops the failed segment, so each frame is lost with its noise, a gap like a
    // dropped frame. In the idle stretch, so that no blow is cut.
    let glued = [idle_frame(4), idle_frame(6)];
    let mut wire = Vec::new();
    let (mut garbage, mut corrupt) = (0, 0);
    for (k, f) in frames.iter().enumerate() {
        if k == dropped {
            continue; // lost on the line: one frame of samples
        }
        let bytes = encode_frame(f);
        if k == idle_frame(1) || k == idle_frame(7) {
            // Line noise ended by a delimiter, between frames.
            wire.extend_from_slice(&[0x7E, 0x13, 0x00, 0xC3, 0x55, 0x00]);
            garbage += 2;
        }
        if glued.contains(&k) {
            wire.extend_from_slice(&[0xA5, 0x5A, 0x01, 0xFF]);
            garbage += 1;
        }
        wire.extend_from_slice(&bytes);
        if k == idle_frame(2) || k == idle_frame(3) {
            // A copy of this frame with a corrupt CRC, between frames.
            wire.extend(corrupt_copy(&bytes));
            corrupt += 1;
        }
    }
    let (mut master, slave) = SerialStream::pair().expect("a pty pair");
    let (tx, rx) = mpsc::channel(4096);
    let (stop_tx, stop_rx) = watch::channel(false);
    let (collector, mut samples) = spawn_collector(rx);
    let driver = tokio::spawn(run_on_stream(cfg(SerialFormat::Binary, "pty"), slave, CLOCK, tx, stop_rx));
    let writer = tokio::spawn(async move {
        for chunk in wire.chunks(4093) {
            master.write_all(chunk).await.unwrap();
        }
        master
    });
    let lost_frames = [glued[0], dropped, glued[1]];
    let expected = (rows.len() - lost_frames.len() * FRAME_SAMPLES) as u64;
    wait_for_samples(&mut samples, expected).await;
    let _master = writer.await.unwrap();
    stop_tx.send(true).unwrap();
    let (_end, counters) = driver.await.unwrap();
    let c = collector.await.unwrap();

    assert_eq!(counters.samples, expected);
    assert_eq!(counters.frames, (frames.len() - lost_frames.len()) as u64);
    assert_eq!(counters.crc_errors, corrupt);
    assert_eq!(counters.decode_errors, garbage);
    assert_eq!(counters.drops, 0);
    // Each lost frame (dropped, or lost with its noise) is one gap of one frame's samples,
    // where it was lost.
    assert_eq!(c.gaps.len(), lost_frames.len());
    for (gap, k) in c.gaps.iter().zip(lost_frames) {
        assert_eq!((gap.samples_lost, gap.reason.as_str()), (FRAME_SAMPLES as u64, "sequence_jump"));
        let t_lost = rows[k * FRAME_SAMPLES].t_s;
        assert!((gap.t_s - t_lost).abs() < 1e-6, "gap at {} vs {t_lost}", gap.t_s);
    }
    assert_eq!(counters.gaps, lost_frames.len() as u64);
    // The counters reach the status messages; the sequence crossed the u32 wrap unbroken.
    let s = last_status(&c);
    assert_eq!((s.state.as_str(), s.crc_errors, s.decode_errors, s.gaps), ("stopped", corrupt, garbage, 3));
    assert!(c.batches.windows(2).all(|w| w[1].seq > w[0].seq));
    assert!(c.batches.iter().all(|b| b.host_time_ns == fixed_clock()));
    assert_every_blow(&c.order, &truth);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn run_opens_the_pty_by_its_path() {
    let (truth, rows) = session(42);
    let frames = frames(&rows);
    let (mut master, slave) = SerialStream::pair().expect("a pty pair");
    let path = slave.name().expect("the pty's slave has a path");
    let (tx, rx) = mpsc::channel(4096);
    let (stop_tx, stop_rx) = watch::channel(false);
    let (collector, mut samples) = spawn_collector(rx);
    let mut config = cfg(SerialFormat::Binary, &path);
    config.status_interval_ms = 100;
    let driver = tokio::spawn(run(config, tx, stop_rx));
    // Wait for the driver to open the port before the device starts talking.
    tokio::time::timeout(Duration::from_secs(5), samples.changed()).await.unwrap().unwrap();
    drop(slave);
    for f in &frames {
        master.write_all(&encode_frame(f)).await.unwrap();
    }
    wait_for_samples(&mut samples, rows.len() as u64).await;
    stop_tx.send(true).unwrap();
    let counters = driver.await.unwrap();
    let c = collector.await.unwrap();
    assert_eq!(counters.samples, rows.len() as u64);
    assert_eq!((counters.crc_errors, counters.decode_errors, counters.gaps, counters.drops), (0, 0, 0, 0));
    assert_eq!(c.statuses[0].state, "connected");
    assert_eq!(c.statuses[0].detail, path);
    assert_eq!(last_status(&c).state, "stopped");
    assert!(c.batches.iter().all(|b| b.host_time_ns > 1_600_000_000_000_000_000), "system clock stamps");
    assert_every_blow(&c.order, &truth);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_link_is_reopened_and_the_outage_is_a_gap() {
    let (_truth, rows) = session(43);
    let frames = frames(&rows);
    let (pty_tx, pty_rx) = mpsc::channel::<SerialStream>(4);
    let pty_rx = std::sync::Arc::new(tokio::sync::Mutex::new(pty_rx));
    let open = {
        let pty_rx = pty_rx.clone();
        move || {
            let pty_rx = pty_rx.clone();
            async move { pty_rx.lock().await.recv().await.ok_or_else(|| std::io::Error::other("no more ptys")) }
        }
    };
    let (tx, rx) = mpsc::channel(4096);
    let (stop_tx, stop_rx) = watch::channel(false);
    let (collector, mut samples) = spawn_collector(rx);
    let driver = tokio::spawn(run_with(cfg(SerialFormat::Binary, "pty"), CLOCK, open, tx, stop_rx));

    // First link: 500 frames, then the cable is pulled (the pty's master closes).
    let (mut master, slave) = SerialStream::pair().unwrap();
    pty_tx.send(slave).await.unwrap();
    for f in &frames[..500] {
        master.write_all(&encode_frame(f)).await.unwrap();
    }
    wait_for_samples(&mut samples, 500 * FRAME_SAMPLES as u64).await;
    drop(master);
    // The device keeps sampling while the link is down: 250 frames never arrive.
    let lost_frames = 250;
    let t_lost = std::time::Instant::now();
    let (mut master, slave) = SerialStream::pair().unwrap();
    pty_tx.send(slave).await.unwrap();
    for f in &frames[500 + lost_frames..1000] {
        master.write_all(&encode_frame(f)).await.unwrap();
    }
    wait_for_samples(&mut samples, (1000 - lost_frames) as u64 * FRAME_SAMPLES as u64).await;
    let reconnect_s = t_lost.elapsed().as_secs_f64();
    stop_tx.send(true).unwrap();
    let counters = driver.await.unwrap();
    let c = collector.await.unwrap();
    drop(master);

    assert!(reconnect_s < 2.0, "reconnected and streaming in {reconnect_s} s (issue #4: within 2 s)");
    assert_eq!(counters.reconnects, 1);
    let states: Vec<&str> = c.statuses.iter().map(|s| s.state.as_str()).collect();
    let i = states.iter().position(|s| *s == "reconnecting").expect("a reconnecting status");
    assert_eq!(states[0], "connected");
    assert!(states[i..].contains(&"connected"), "connected again after {states:?}");
    assert_eq!(c.gaps.len(), 1);
    assert_eq!(c.gaps[0].samples_lost, (lost_frames * FRAME_SAMPLES) as u64);
    assert_eq!(counters.samples, (1000 - lost_frames) as u64 * FRAME_SAMPLES as u64);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ascii_lines_over_a_pty_with_malformed_lines() {
    let (truth, rows) = session(44);
    let mut text = String::with_capacity(rows.len() * 48);
    text.push_str("t_s,load_N,disp_m,acc_mps2\n"); // a header: not data, counted
    let mut malformed = 1;
    for (k, r) in rows.iter().enumerate() {
        if k % 20_011 == 7 {
            text.push_str("1.0,garbage\n");
            text.push_str("@#$%^&*\n");
            malformed += 2;
        }
        text.push_str(&format!("{:.7},{:.1},{:.6},{:.3}\n", r.t_s, r.load_n, r.disp_m, r.acc_mps2));
    }
    let (mut master, slave) = SerialStream::pair().expect("a pty pair");
    let (tx, rx) = mpsc::channel(4096);
    let (stop_tx, stop_rx) = watch::channel(false);
    let (collector, mut samples) = spawn_collector(rx);
    let driver = tokio::spawn(run_on_stream(cfg(SerialFormat::Ascii, "pty"), slave, CLOCK, tx, stop_rx));
    let writer = tokio::spawn(async move {
        master.write_all(text.as_bytes()).await.unwrap();
        master
    });
    // The last partial batch is flushed once the line goes quiet.
    wait_for_samples(&mut samples, rows.len() as u64).await;
    let _master = writer.await.unwrap();
    stop_tx.send(true).unwrap();
    let (_end, counters) = driver.await.unwrap();
    let c = collector.await.unwrap();
    assert_eq!(counters.samples, rows.len() as u64);
    assert_eq!(counters.decode_errors, malformed);
    assert_eq!((counters.gaps, counters.drops), (0, 0));
    assert!(c.gaps.is_empty());
    // 20 ms batches at 100 kHz.
    assert!(c.batches.iter().filter(|b| b.len() == 2000).count() > c.batches.len() * 9 / 10);
    assert!(c.batches.iter().all(|b| (b.period_ns - PERIOD_NS as f64).abs() < 1.0));
    assert_eq!(last_status(&c).decode_errors, malformed);
    assert_every_blow(&c.order, &truth);
}

/// CPU time of this process so far, s (utime + stime from /proc/self/stat).
fn process_cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap();
    // Fields after the command name (which ends with ')'): utime and stime are 14 and 15.
    let rest = &stat[stat.rfind(')').unwrap() + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap();
    ticks / 100.0 // USER_HZ is 100 on Linux
}

/// Issue #4 speed target, measured: 3 channels at 100 kHz in real time over a pty, 10 s,
/// in 1 ms frames; the whole test process (paced writer, pty, driver, a counting
/// consumer) must stay under 10 % of one core. `cargo test --release --test
/// acquire_serial -- --ignored --nocapture` prints the figure.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "a 10 s real-time run; run on demand"]
async fn three_channels_at_100_khz_in_real_time_use_under_ten_percent_of_a_core() {
    const SECONDS: usize = 10;
    let frames: Vec<Vec<u8>> = (0..SECONDS * 1000)
        .map(|k| {
            let counts = (0..3 * FRAME_SAMPLES).map(|i| ((k * 7 + i * 13) % 40_000) as i32 - 20_000).collect();
            encode_frame(&Frame {
                channel_count: 3,
                sample_count: FRAME_SAMPLES as u16,
                sequence: k as u32,
                device_time_ns: (k * FRAME_SAMPLES) as u64 * PERIOD_NS as u64,
                sample_period_ns: PERIOD_NS,
                counts,
            })
        })
        .collect();
    let (mut master, slave) = SerialStream::pair().unwrap();
    let (tx, mut rx) = mpsc::channel(1024);
    let (stop_tx, stop_rx) = watch::channel(false);
    let consumer = tokio::spawn(async move {
        let mut n = 0u64;
        while let Some(ev) = rx.recv().await {
            if let SourceEvent::Batch(b) = ev {
                n += b.len() as u64;
            }
        }
        n
    });
    let driver = tokio::spawn(run_on_stream(cfg(SerialFormat::Binary, "pty"), slave, system_clock_ns, tx, stop_rx));
    let cpu0 = process_cpu_s();
    let t0 = std::time::Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    for burst in frames.chunks(10) {
        tick.tick().await;
        for f in burst {
            master.write_all(f).await.unwrap();
        }
    }
    tokio::time::sleep(Duration::from_millis(100)).await;
    let wall_s = t0.elapsed().as_secs_f64();
    let cpu_s = process_cpu_s() - cpu0;
    stop_tx.send(true).unwrap();
    let (_, counters) = driver.await.unwrap();
    let samples = consumer.await.unwrap();
    let share = cpu_s / wall_s;
    println!(
        "3 ch x 100 kHz over a pty: {samples} samples in {wall_s:.2} s wall, {cpu_s:.2} s CPU = {:.1} % of one core",
        100.0 * share
    );
    assert_eq!(samples, (SECONDS * 1000 * FRAME_SAMPLES) as u64);
    assert_eq!((counters.drops, counters.gaps, counters.crc_errors, counters.decode_errors), (0, 0, 0, 0));
    assert!(share < 0.10, "{:.1} % of a core", 100.0 * share);
}
