//! Modbus at the IO boundary (issue #4): a real tokio-modbus server on 127.0.0.1 (and RTU
//! over a pty pair) serves a simulated hammer; the client driver reads it and the events
//! go through the live pipeline. Faults: the server stopped and restarted, slow replies
//! beyond the timeout, exception replies; and the PLC coil write.

mod common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use forgemon::acquire::modbus::block::RingWriter;
use forgemon::acquire::modbus::registers::encode_raw;
use forgemon::acquire::modbus::server::lock;
use forgemon::acquire::modbus::{
    BankService, DataType, Faults, ModbusConfig, Mode, RegisterKind, RegisterSpec, SharedBank, Signal, TcpServer,
    Transport, WordOrder, detail_count, run, serve_rtu, shared_bank, write_coil,
};
use forgemon::acquire::{ChannelSpec, SourceEvent};
use forgemon::physics::{EffectSet, Machine, Process};
use forgemon::pipeline::{Pipeline, PipelineConfig, PipelineEvent};
use forgemon::record::Status;
use forgemon::signal::capture::CaptureRow;
use forgemon::signal::sample::{Role, SampleBatch};
use forgemon::synth::{CaptureSpec, SynthBlow, idle_rows, synth_blows};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// 50 kHz device time, 3 channels of i32 (6 registers a sample, 20 samples a read). The
/// estimator was tuned at 100 kHz and reads the efficiency low at lower
/// rates, because the 2 kHz lower-tool mode (DESIGN.md §2.1) gets fewer samples per
/// period: measured on these blows fed directly, 100 kHz -0.006, 50 kHz -0.02, 10 kHz
/// -0.16. So the tolerance against the truth is 0.05 here (the replay tests' 0.03 at
/// 100 kHz), and the transport itself is checked exactly against the same samples fed
/// to the pipeline directly.
const RATE_HZ: f64 = 50e3;
const EFFICIENCY_TOL: f64 = 0.05;
/// The simulated DAQ writes its 50 kHz samples (device time) at 10 000 samples per wall
/// second: 500 reads/s, which debug builds of client and server keep up with on a loaded
/// 2-core machine (at full pace, several tests at once fell behind the ring there). The
/// pace changes no sample and no device time; what a link sustains is a throughput
/// question for the benchmarks.
const PACE_HZ: f64 = 10e3;
/// Counts of the simulated DAQ: 10 N, 1 µm, 1 mm/s² per count.
const GAINS: [(Role, f64); 3] = [(Role::Load, 10.0), (Role::Disp, 1e-6), (Role::Acc, 1e-3)];
/// 8192 samples: 0.8 s of wall time at the pace.
const RING: u16 = 8192;

fn machine_and_process() -> (Machine, Process) {
    (common::machine("hammer-lg1000.machine.toml"), common::process("steel-16NiCrMo13.process.toml"))
}

/// A continuous stream: `idle_s[i]` of machine at rest before blow i, and 0.1 s after the
/// last. Returns the rows (one clock) and the truth.
fn hammer_stream(v0s: &[f64], idle_s: &[f64]) -> (Vec<CaptureRow>, Vec<SynthBlow>) {
    let (machine, process) = machine_and_process();
    let spec = CaptureSpec { sample_rate_hz: RATE_HZ, ..CaptureSpec::hammer(41) };
    let truth = synth_blows(&machine, &EffectSet::NONE, &process, v0s, &spec).unwrap();
    let mut rows = Vec::new();
    for (i, b) in truth.iter().enumerate() {
        let n = (idle_s[i] * RATE_HZ) as usize;
        rows.extend(idle_rows(n, 0.0, &spec, b.rows[0].disp_m, 500 + i as u64));
        rows.extend_from_slice(&b.rows);
    }
    let last = rows.last().map_or(0.0, |r| r.disp_m);
    rows.extend(idle_rows((0.1 * RATE_HZ) as usize, 0.0, &spec, last, 999));
    let t0 = rows[0].t_s;
    for (k, r) in rows.iter_mut().enumerate() {
        r.t_s = t0 + k as f64 / RATE_HZ;
        // The DAQ's counts, so that the direct feed sees exactly what Modbus carries.
        let q = |v: f64, gain: f64| (v / gain).round() * gain;
        r.load_n = q(r.load_n, GAINS[0].1);
        r.disp_m = q(r.disp_m, GAINS[1].1);
        r.acc_mps2 = q(r.acc_mps2, GAINS[2].1);
    }
    (rows, truth)
}

fn channels() -> Vec<ChannelSpec> {
    GAINS.iter().map(|&(role, gain)| ChannelSpec { role, gain, offset: 0.0 }).collect()
}

/// The simulated DAQ: writes `rows` into a block-mode ring of `ring_len` slots at
/// [`PACE_HZ`], 5 ms at a time.
fn produce(bank: SharedBank, rows: Vec<CaptureRow>, ring_len: u16) -> JoinHandle<()> {
    tokio::spawn(async move {
        let mut ring = RingWriter::new(0, ring_len, 3, 2, (1e9 / RATE_HZ) as u32).unwrap();
        ring.write_header(&mut lock(&bank).holding);
        let start = Instant::now();
        let mut done = 0;
        let mut counts = Vec::new();
        while done < rows.len() {
            tokio::time::sleep(Duration::from_millis(5)).await;
            let due = ((start.elapsed().as_secs_f64() * PACE_HZ) as usize).min(rows.len());
            counts.clear();
            for r in &rows[done..due] {
                for (v, (_, gain)) in [r.load_n, r.disp_m, r.acc_mps2].iter().zip(GAINS) {
                    counts.push((v / gain).round() as i32);
                }
            }
            ring.push(&mut lock(&bank).holding, &counts);
            done = due;
        }
    })
}

/// The Modbus driver running on a config, its events collected into a log.
struct Running {
    switch: watch::Sender<bool>,
    log: Log,
    collector: JoinHandle<()>,
    driver: JoinHandle<()>,
}

impl Running {
    fn start(cfg: ModbusConfig) -> Running {
        let (tx, rx) = mpsc::channel(4096);
        let (stop, shutdown) = watch::channel(false);
        let (log, collector) = collect(rx);
        Running { switch: stop, log, collector, driver: tokio::spawn(run(cfg, tx, shutdown)) }
    }

    /// Stop the driver; every event it sent is in the log after this.
    async fn stop(self) {
        self.switch.send(true).unwrap();
        self.driver.await.unwrap();
        self.collector.await.unwrap();
    }
}

/// Events as they arrive, stamped with the time they arrived.
type Log = Arc<Mutex<Vec<(Instant, SourceEvent)>>>;

fn collect(mut rx: mpsc::Receiver<SourceEvent>) -> (Log, JoinHandle<()>) {
    let log: Log = Arc::new(Mutex::new(Vec::new()));
    let l = log.clone();
    let h = tokio::spawn(async move {
        while let Some(e) = rx.recv().await {
            l.lock().unwrap().push((Instant::now(), e));
        }
    });
    (log, h)
}

fn statuses(log: &Log) -> Vec<(Instant, Status)> {
    log.lock()
        .unwrap()
        .iter()
        .filter_map(|(t, e)| match e {
            SourceEvent::Status(s) => Some((*t, s.clone())),
            _ => None,
        })
        .collect()
}

/// Run the events through the live pipeline: the blows it finds.
fn pipeline_blows(log: &Log) -> Vec<PipelineEvent> {
    let (machine, process) = machine_and_process();
    let cfg = PipelineConfig::for_machine(&machine);
    let mut p = Pipeline::new(machine, Some(process), cfg);
    let mut out = Vec::new();
    for (_, e) in log.lock().unwrap().iter() {
        match e {
            SourceEvent::Batch(b) => p.push(b, &mut out),
            SourceEvent::Gap(g) if g.samples_lost > 0 => p.end_of_stream(&mut out),
            _ => {}
        }
    }
    p.end_of_stream(&mut out);
    out
}

/// The same samples fed to the pipeline directly, from sample `first` on, in batches of
/// 500 with the device times the Modbus driver gives them.
fn direct_blows(rows: &[CaptureRow], first: usize) -> Vec<PipelineEvent> {
    let (machine, process) = machine_and_process();
    let cfg = PipelineConfig::for_machine(&machine);
    let mut p = Pipeline::new(machine, Some(process), cfg);
    let mut out = Vec::new();
    let period_ns = (1e9 / RATE_HZ) as u32 as f64;
    for (k, chunk) in rows[first..].chunks(500).enumerate() {
        let index = first + 500 * k;
        let batch = SampleBatch {
            source: "direct".into(),
            seq: k as u64,
            device_time_ns: (index as f64 * period_ns) as i64,
            host_time_ns: 0,
            period_ns,
            roles: GAINS.iter().map(|(r, _)| *r).collect(),
            values: chunk.iter().flat_map(|r| [r.load_n, r.disp_m, r.acc_mps2]).collect(),
        };
        p.push(&batch, &mut out);
    }
    p.end_of_stream(&mut out);
    out
}

fn efficiencies(found: &[PipelineEvent]) -> Vec<f64> {
    found
        .iter()
        .filter_map(|e| if let PipelineEvent::Blow { estimate, .. } = e { estimate.efficiency } else { None })
        .collect()
}

fn assert_blows_match(found: &[PipelineEvent], truth: &[SynthBlow]) {
    let blows: Vec<_> = found.iter().filter_map(common::estimate_of).collect();
    assert_eq!(blows.len(), truth.len(), "every blow found, none extra");
    for (b, t) in blows.iter().zip(truth) {
        let e = t.truth.efficiency();
        let eff = b.efficiency.expect("a whole blow has an efficiency");
        assert!((eff - e).abs() < EFFICIENCY_TOL, "blow {}: efficiency {eff} vs truth {e}", b.blow);
        assert!((b.v_impact_mps / t.truth.v0_mps - 1.0).abs() < 0.02, "blow {}: speed", b.blow);
    }
}

fn block_config(server: &TcpServer) -> ModbusConfig {
    ModbusConfig {
        source: "daq".into(),
        transport: Transport::Tcp { addr: server.addr() },
        unit_id: 1,
        poll_interval: Duration::from_millis(10),
        timeout: Duration::from_millis(250),
        map: vec![],
        mode: Mode::Block { base: 0, channels: channels() },
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn block_mode_over_tcp_finds_every_blow_of_a_simulated_hammer() {
    let (rows, truth) = hammer_stream(&[3.9, 5.0, 5.0], &[0.15, 0.15, 0.15]);
    let bank = shared_bank();
    let service = BankService { bank: bank.clone(), faults: Arc::new(Faults::default()), unit: None };
    let server = TcpServer::start("127.0.0.1:0".parse().unwrap(), service).await.unwrap();
    let driver = Running::start(block_config(&server));
    let log = driver.log.clone();
    produce(bank, rows.clone(), RING).await.unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    driver.stop().await;

    let samples: usize =
        log.lock().unwrap().iter().map(|(_, e)| if let SourceEvent::Batch(b) = e { b.len() } else { 0 }).sum();
    // The first read only sets the starting point: at most the first poll's worth is missed.
    assert!(samples + (0.05 * PACE_HZ) as usize >= rows.len() && samples <= rows.len(), "{samples} of {}", rows.len());
    let gaps = log.lock().unwrap().iter().filter(|(_, e)| matches!(e, SourceEvent::Gap(_))).count();
    assert_eq!(gaps, 0, "no samples lost on a healthy link");
    let st = statuses(&log);
    assert_eq!(st.last().unwrap().1.state, "stopped");
    assert_eq!(st.last().unwrap().1.drops, 0);
    let found = pipeline_blows(&log);
    assert_blows_match(&found, &truth);
    // The transport changes nothing: the same estimates as the samples fed directly.
    let first = rows.len() - samples;
    let direct = efficiencies(&direct_blows(&rows, first));
    assert_eq!(efficiencies(&found), direct, "Modbus equals direct");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn block_mode_over_rtu_on_a_pty_finds_every_blow() {
    // A pty ignores the baud rate: a real line at 921 600 baud (11 bits a byte) carries
    // about 35 000 registers/s, a 5 kHz ring of 3 i32 channels; this test moves 60 000.
    // It checks the protocol path (RTU framing, CRC, slave address) end to end.
    use tokio_serial::SerialPort;
    let (rows, truth) = hammer_stream(&[3.9, 5.0, 5.0], &[0.15, 0.15, 0.15]);
    let (master, slave) = tokio_serial::SerialStream::pair().expect("a pty pair");
    let path = slave.name().expect("the pty has a path");
    let bank = shared_bank();
    let server =
        serve_rtu(master, BankService { bank: bank.clone(), faults: Arc::new(Faults::default()), unit: Some(3) });
    let cfg = ModbusConfig {
        source: "daq-rtu".into(),
        transport: Transport::Rtu { path, baud: 921_600 },
        unit_id: 3,
        poll_interval: Duration::from_millis(10),
        timeout: Duration::from_millis(250),
        map: vec![],
        mode: Mode::Block { base: 0, channels: channels() },
    };
    let driver = Running::start(cfg);
    let log = driver.log.clone();
    produce(bank, rows.clone(), RING).await.unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    driver.stop().await;
    server.abort();
    drop(slave);

    let gaps = log.lock().unwrap().iter().filter(|(_, e)| matches!(e, SourceEvent::Gap(_))).count();
    assert_eq!(gaps, 0, "the RTU link keeps up with the pace over a pty");
    let samples: usize =
        log.lock().unwrap().iter().map(|(_, e)| if let SourceEvent::Batch(b) = e { b.len() } else { 0 }).sum();
    let found = pipeline_blows(&log);
    assert_blows_match(&found, &truth);
    assert_eq!(efficiencies(&found), efficiencies(&direct_blows(&rows, rows.len() - samples)));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn server_stopped_and_restarted_is_reconnected_with_a_gap_and_the_driver_keeps_going() {
    // A long rest after blow 1 (0.6 s device time, 3 s of wall time at the pace): the
    // server goes away for 1 s in it, longer than the ring of 2048 samples holds (0.2 s),
    // so samples are really lost.
    let (rows, truth) = hammer_stream(&[3.9, 5.0], &[0.15, 0.6]);
    let blow1_end_wall_s = (0.15 * RATE_HZ + truth[0].rows.len() as f64) / PACE_HZ;
    let bank = shared_bank();
    let service = BankService { bank: bank.clone(), faults: Arc::new(Faults::default()), unit: None };
    let mut server = TcpServer::start("127.0.0.1:0".parse().unwrap(), service).await.unwrap();
    let driver = Running::start(block_config(&server));
    let log = driver.log.clone();
    let producer = produce(bank, rows, 2048);
    tokio::time::sleep(Duration::from_secs_f64(blow1_end_wall_s + 0.3)).await;
    server.stop();
    tokio::time::sleep(Duration::from_millis(1000)).await;
    assert!(!driver.driver.is_finished(), "the driver never exits on a lost link");
    server.restart().await.unwrap();
    let restarted = Instant::now();
    producer.await.unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(!driver.driver.is_finished());
    driver.stop().await;

    let st = statuses(&log);
    assert!(st.iter().any(|(_, s)| s.state == "reconnecting"), "the outage was reported");
    let back =
        st.iter().find(|(t, s)| *t >= restarted && s.state == "connected").expect("connected again after the restart");
    assert!(back.0 - restarted < Duration::from_secs(2), "reconnected within 2 s: {:?}", back.0 - restarted);
    assert!(back.1.reconnects >= 1);
    let gaps: Vec<_> = log
        .lock()
        .unwrap()
        .iter()
        .filter_map(|(_, e)| if let SourceEvent::Gap(g) = e { Some(g.clone()) } else { None })
        .collect();
    assert_eq!(gaps.len(), 1, "{gaps:?}");
    assert_eq!(gaps[0].reason, "link_down");
    // 1 s at the pace (10 000 samples) less the readable ring (1792 samples) at least.
    assert!(gaps[0].samples_lost > 8_000, "{gaps:?}");
    assert_eq!(st.last().unwrap().1.gaps, 1);
    // The blows on either side of the outage are all found.
    assert_blows_match(&pipeline_blows(&log), &truth);
}

/// The slow-signal map: a load in i32 (big-endian), a setpoint in u16 at 0.1 J/count, a
/// temperature in f32 word-swapped in the input registers.
fn poll_map() -> Vec<RegisterSpec> {
    let spec = |signal, address, kind, data_type, word_order, scale| RegisterSpec {
        signal,
        address,
        kind,
        data_type,
        word_order,
        scale,
        offset: 0.0,
    };
    vec![
        spec(Signal::Role(Role::Load), 0, RegisterKind::Holding, DataType::I32, WordOrder::BigEndian, 10.0),
        spec(Signal::Named("setpoint_J".into()), 20, RegisterKind::Holding, DataType::U16, WordOrder::BigEndian, 0.1),
        spec(
            Signal::Named("temperature_C".into()),
            10,
            RegisterKind::Input,
            DataType::F32,
            WordOrder::LittleEndian,
            1.0,
        ),
    ]
}

fn fill_poll_bank(bank: &SharedBank, load_n: f64) {
    let mut b = lock(bank);
    let load = encode_raw(load_n / 10.0, DataType::I32, WordOrder::BigEndian);
    b.holding[0..2].copy_from_slice(&load);
    b.holding[20] = 52_000; // 5200 J
    let t = encode_raw(1100.5, DataType::F32, WordOrder::LittleEndian);
    b.input[10..12].copy_from_slice(&t);
}

fn batches(log: &Log) -> Vec<(Instant, Vec<f64>)> {
    log.lock()
        .unwrap()
        .iter()
        .filter_map(|(t, e)| if let SourceEvent::Batch(b) = e { Some((*t, b.values.clone())) } else { None })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn slow_replies_and_exceptions_are_counted_and_not_fatal() {
    let bank = shared_bank();
    fill_poll_bank(&bank, -1230.0);
    let faults = Arc::new(Faults::default());
    let service = BankService { bank: bank.clone(), faults: faults.clone(), unit: None };
    let server = TcpServer::start("127.0.0.1:0".parse().unwrap(), service).await.unwrap();
    let cfg = ModbusConfig {
        source: "plc".into(),
        transport: Transport::Tcp { addr: server.addr() },
        unit_id: 1,
        poll_interval: Duration::from_millis(20),
        timeout: Duration::from_millis(100),
        map: poll_map(),
        mode: Mode::Poll,
    };
    let driver = Running::start(cfg);
    let log = driver.log.clone();
    tokio::time::sleep(Duration::from_millis(300)).await;
    // Every 3rd request is an exception (two reads per poll: holding, input).
    faults.set_exception_every(3);
    tokio::time::sleep(Duration::from_millis(500)).await;
    faults.set_exception_every(0);
    // Replies slower than the 100 ms limit.
    faults.set_delay(Duration::from_millis(300));
    tokio::time::sleep(Duration::from_millis(700)).await;
    faults.set_delay(Duration::ZERO);
    let healed = Instant::now();
    tokio::time::sleep(Duration::from_millis(1300)).await;
    assert!(!driver.driver.is_finished(), "faults are not fatal");
    driver.stop().await;

    let b = batches(&log);
    assert!(b.len() > 20, "{} polls", b.len());
    assert!(b.iter().all(|(_, v)| v == &vec![-1230.0]), "1-sample batches of the load");
    assert!(b.iter().any(|(t, _)| *t > healed), "polling resumed after the slow replies");
    let last = statuses(&log).last().unwrap().1.clone();
    assert_eq!(last.state, "stopped");
    let exceptions = detail_count(&last.detail, "exceptions").unwrap();
    let timeouts = detail_count(&last.detail, "timeouts").unwrap();
    assert!(exceptions >= 3, "{}", last.detail);
    assert!(timeouts >= 1, "{}", last.detail);
    // Every exception the server sent was counted by the client.
    assert_eq!(exceptions, faults.exceptions.load(std::sync::atomic::Ordering::Relaxed), "{}", last.detail);
    // The named slow signals are reported.
    assert!(last.detail.contains("setpoint_J=5200") && last.detail.contains("temperature_C=1100.5"), "{}", last.detail);
}

/// Polling unit 7 over RTU at `path` every 20 ms (`poll_map`).
fn rtu_poll(path: String) -> ModbusConfig {
    ModbusConfig {
        source: "rtu".into(),
        transport: Transport::Rtu { path, baud: 115_200 },
        unit_id: 7,
        poll_interval: Duration::from_millis(20),
        timeout: Duration::from_millis(200),
        map: poll_map(),
        mode: Mode::Poll,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn rtu_polling_over_a_pty_pair() {
    use tokio_serial::SerialPort;
    let (master, slave) = tokio_serial::SerialStream::pair().expect("a pty pair");
    let path = slave.name().expect("the pty has a path");
    let bank = shared_bank();
    fill_poll_bank(&bank, 250_000.0);
    let faults = Arc::new(Faults::default());
    // An RTU slave answers its own address only.
    let server = serve_rtu(master, BankService { bank: bank.clone(), faults: faults.clone(), unit: Some(7) });
    let driver = Running::start(rtu_poll(path));
    let log = driver.log.clone();
    tokio::time::sleep(Duration::from_millis(400)).await;
    fill_poll_bank(&bank, -7_500.0);
    tokio::time::sleep(Duration::from_millis(400)).await;
    driver.stop().await;
    server.abort();
    drop(slave);

    let b = batches(&log);
    assert!(b.len() >= 10, "{} polls over RTU", b.len());
    assert_eq!(b.first().unwrap().1, vec![250_000.0]);
    assert_eq!(b.last().unwrap().1, vec![-7_500.0]);
    let last = statuses(&log).last().unwrap().1.clone();
    assert!(last.detail.contains("temperature_C=1100.5"), "{}", last.detail);
    assert_eq!(detail_count(&last.detail, "timeouts"), Some(0), "{}", last.detail);
}

/// Issue 40: a device that exits leaves its pty path to whoever the system gives it next;
/// an RTU source, like the serial source, reopens the path only while it is the device it
/// first opened (`serial::identity`). The path is a link to the pty, re-pointed at another
/// process's pty (often the very same /dev/pts number) with other values in its registers.
#[tokio::test]
async fn an_rtu_path_given_to_another_process_is_not_reopened() {
    use tokio_serial::SerialPort;
    let dir = tempfile::tempdir().expect("temp dir");
    let link = dir.path().join("ttyDAQ");
    let (master, slave) = tokio_serial::SerialStream::pair().expect("a pty pair");
    std::os::unix::fs::symlink(slave.name().expect("a path"), &link).expect("link");
    let bank = shared_bank();
    fill_poll_bank(&bank, 250_000.0);
    let server = serve_rtu(master, BankService { bank, faults: Arc::new(Faults::default()), unit: Some(7) });
    let driver = Running::start(rtu_poll(link.display().to_string()));
    let log = driver.log.clone();
    tokio::time::sleep(Duration::from_millis(400)).await;
    assert!(!batches(&log).is_empty(), "no poll over the first pty");
    // The device exits, and another process's pty takes the path.
    server.abort();
    drop(slave);
    let (other_master, other_slave) = tokio_serial::SerialStream::pair().expect("another pty pair");
    std::fs::remove_file(&link).expect("unlink");
    std::os::unix::fs::symlink(other_slave.name().expect("a path"), &link).expect("link again");
    let other = shared_bank();
    fill_poll_bank(&other, -7_500.0);
    let other_server =
        serve_rtu(other_master, BankService { bank: other, faults: Arc::new(Faults::default()), unit: Some(7) });
    tokio::time::sleep(Duration::from_millis(1500)).await;
    driver.stop().await;
    other_server.abort();
    drop(other_slave);
    // Nothing was read from the other process's device, and the source says why.
    assert!(batches(&log).iter().all(|(_, v)| v == &vec![250_000.0]), "values read from the other pty");
    // (the status detail writes the error's spaces as underscores)
    let refused = statuses(&log).iter().any(|(_, s)| s.detail.contains("not_the_device_first_opened"));
    assert!(refused, "{:?}", statuses(&log).last().map(|(_, s)| s.detail.clone()));
}

#[tokio::test]
async fn the_coil_write_reaches_the_server_coil_bank() {
    let bank = shared_bank();
    let service = BankService { bank: bank.clone(), faults: Arc::new(Faults::default()), unit: None };
    let mut server = TcpServer::start("127.0.0.1:0".parse().unwrap(), service).await.unwrap();
    let limit = Duration::from_millis(500);
    write_coil(server.addr(), 1, 12, true, limit).await.unwrap();
    assert!(lock(&bank).coils[12]);
    write_coil(server.addr(), 1, 12, false, limit).await.unwrap();
    assert!(!lock(&bank).coils[12]);
    // A PLC that is not there is an error, within the limit, not a hang.
    let addr = server.addr();
    server.stop();
    tokio::time::sleep(Duration::from_millis(50)).await;
    let t = Instant::now();
    assert!(write_coil(addr, 1, 12, true, limit).await.is_err());
    assert!(t.elapsed() < limit * 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ring_unlike_the_config_is_counted_not_fatal() {
    // The device has 3 channels; the config names 2.
    let bank = shared_bank();
    let ring = RingWriter::new(0, RING, 3, 2, 20_000).unwrap();
    ring.write_header(&mut lock(&bank).holding);
    let service = BankService { bank, faults: Arc::new(Faults::default()), unit: None };
    let server = TcpServer::start("127.0.0.1:0".parse().unwrap(), service).await.unwrap();
    let mut cfg = block_config(&server);
    cfg.mode = Mode::Block { base: 0, channels: channels()[..2].to_vec() };
    let driver = Running::start(cfg);
    let log = driver.log.clone();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(!driver.driver.is_finished());
    driver.stop().await;
    assert!(batches(&log).is_empty());
    let last = statuses(&log).last().unwrap().1.clone();
    assert!(last.decode_errors >= 10, "every poll counted: {last:?}");
    assert_eq!(last.reconnects, 0, "a bad header is not a lost link");
    assert!(last.detail.contains("3_channels"), "{}", last.detail);
}
