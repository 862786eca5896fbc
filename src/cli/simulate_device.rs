//! `forgemon simulate-device`: a simulated hammer or press forging billets (approach,
//! blow, rebound, pause, next blow; a new billet when one is finished) that drives a real
//! transport, so the service (or any other program) can be pointed at it like a DAQ.
//! Serial: it opens a pty pair, prints the path of the end to open, and streams the binary
//! framing of docs/interfaces.md §7 (or the ASCII lines) in real time, with fault switches.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, ValueEnum};
use tokio::sync::watch;
use tokio_serial::SerialPort;

use super::{parse_process_warn, read_text};
use crate::config::parse_machine;
use crate::physics::effects::{Effect, EffectSet};
use crate::physics::machine::MachineKind;
use crate::simdevice::{BilletPlan, SerialDeviceSpec, SerialFaults, SimMachine, drive_serial};
use crate::synth::CaptureSpec;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Wire {
    /// COBS frames with CRC-32C (docs/interfaces.md §7).
    Binary,
}

/// Where the simulated DAQ's samples go.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Transport {
    /// A pty pair, in real time; the path to open is printed.
    Pty,
    /// A Modbus TCP server with the block-mode sample ring at register 0, in real time.
    ModbusTcp,
    /// A `candump -L` log file, one CAN frame per sample (fixtures/can/hammer.dbc), or with
    /// `--can-fd` one CAN FD frame per 8 samples (config/hammer-canfd.dbc).
    Candump,
}

#[derive(Debug, Args)]
pub struct SimulateDeviceArgs {
    /// The machine model (machine.toml).
    #[arg(long)]
    pub machine: PathBuf,
    /// The billet forged, again and again (process.toml).
    #[arg(long)]
    pub process: PathBuf,
    /// Impact speed of each blow on a billet, m/s, comma separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub v0: Vec<f64>,
    /// How many billets to forge (0: keep going until stopped).
    #[arg(long, default_value_t = 0)]
    pub billets: usize,
    /// Seconds between blows.
    #[arg(long, default_value_t = 3.0)]
    pub interval: f64,
    /// Billet heights vary by up to this fraction around the sheet's (the first billet is
    /// the sheet's own), so the service's billet detection and height tracking are exercised.
    #[arg(long, default_value_t = 0.0)]
    pub height_spread: f64,
    /// Seconds more the machine stands idle before each billet after the first.
    #[arg(long, default_value_t = 0.0)]
    pub billet_idle: f64,
    /// Sample rate, Hz (up to 100 kHz).
    #[arg(long, default_value_t = 100e3)]
    pub rate: f64,
    /// Unmodelled effects to put into the simulated machine: NAME:param=value (repeatable).
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// The byte format on the pty (`--transport pty`).
    #[arg(long, value_enum, default_value = "binary")]
    pub wire: Wire,
    /// Where the samples go: a pty, a Modbus TCP server or a candump log file.
    #[arg(long, value_enum, default_value = "pty")]
    pub transport: Transport,
    /// Modbus TCP: the address to listen on.
    #[arg(long, default_value = "127.0.0.1:5020")]
    pub listen: std::net::SocketAddr,
    /// candump: the log file to write.
    #[arg(long, required_if_eq("transport", "candump"))]
    pub out: Option<PathBuf>,
    /// candump: CAN FD frames, each a block of 8 samples (config/hammer-canfd.dbc), for the
    /// rates a classic bus cannot carry (50 kHz).
    #[arg(long, requires = "out")]
    pub can_fd: bool,
    /// Garbage bytes before every N-th frame (0: never).
    #[arg(long, default_value_t = 0)]
    pub garbage_every: u64,
    /// Corrupt the CRC of every N-th frame (0: never).
    #[arg(long, default_value_t = 0)]
    pub corrupt_every: u64,
    /// Drop every N-th frame (0: never).
    #[arg(long, default_value_t = 0)]
    pub drop_every: u64,
}

pub fn run(args: SimulateDeviceArgs) -> anyhow::Result<ExitCode> {
    let mf = parse_machine(&args.machine.display().to_string(), &read_text(&args.machine)?)?;
    let process = parse_process_warn(&args.process.display().to_string(), &read_text(&args.process)?)?;
    if process.machine != mf.machine.kind() {
        anyhow::bail!("{}: key 'machine' does not match {}", args.process.display(), args.machine.display());
    }
    if !(args.rate.is_finite() && args.rate >= 1e3 && args.rate <= 100e3) {
        anyhow::bail!("--rate must be between 1 kHz and 100 kHz, got {}", args.rate);
    }
    let mut effects = mf.effects.clone();
    for spec in &args.effects {
        let e = Effect::parse_spec(spec).and_then(|e| e.check_machine(mf.machine.kind()).map(|()| e));
        effects.push(e.with_context(|| format!("--effect {spec}"))?);
    }
    let mut spec = match mf.machine.kind() {
        MachineKind::Hammer => CaptureSpec::hammer(1),
        MachineKind::ScrewPress => CaptureSpec::press(1),
    };
    spec.sample_rate_hz = args.rate;
    if !(args.height_spread.is_finite() && (0.0..=0.5).contains(&args.height_spread)) {
        anyhow::bail!("--height-spread must be between 0 and 0.5, got {}", args.height_spread);
    }
    if !(args.billet_idle.is_finite() && args.billet_idle >= 0.0) {
        anyhow::bail!("--billet-idle must be 0 or more seconds, got {}", args.billet_idle);
    }
    let billets = if args.billets == 0 { 1_000_000 } else { args.billets };
    let plan = BilletPlan { process, v0s_mps: args.v0.clone() };
    let plans = crate::simdevice::spread_plans(&plan, billets, args.height_spread, 1);
    let sim = SimMachine::new(mf.machine, EffectSet::from_effects(&effects), plans, spec, args.interval)
        .with_billet_idle(args.billet_idle);
    let dev = SerialDeviceSpec {
        channels: super::demo::demo_channels(),
        frame_samples: ((args.rate * 0.01) as usize).max(1),
        realtime: true,
        faults: SerialFaults {
            garbage_every: args.garbage_every,
            garbage_bytes: 64,
            corrupt_every: args.corrupt_every,
            drop_every: args.drop_every,
            dead: None,
        },
    };
    if args.can_fd && args.transport != Transport::Candump {
        anyhow::bail!("--can-fd needs --transport candump");
    }
    if args.transport == Transport::Candump {
        return write_candump(
            sim,
            args.out.as_deref().context("--out is required with --transport candump")?,
            args.can_fd,
        );
    }
    let rt = tokio::runtime::Runtime::new()?;
    if args.transport == Transport::ModbusTcp {
        rt.block_on(serve_modbus(sim, args.listen, args.rate))?;
        return Ok(ExitCode::SUCCESS);
    }
    rt.block_on(async move {
        let (master, slave) = tokio_serial::SerialStream::pair().context("cannot open a pty pair")?;
        let path = slave.name().unwrap_or_default();
        println!("simulated {} on {path}: binary framing, channels load_N (1 N/count), disp_m (1 um/count), acc_mps2 (1 mm/s2/count), {} Hz", mf.machine.kind().as_str(), args.rate);
        let (stop_tx, stop_rx) = watch::channel(false);
        tokio::spawn(async move {
            let _ = tokio::signal::ctrl_c().await;
            let _ = stop_tx.send(true);
        });
        let stats = drive_serial(sim, &dev, master, stop_rx, |k, _| println!("billet {k}")).await?;
        drop(slave);
        println!(
            "device: {} frames, {} samples sent, {} frames dropped, {} corrupted, {} garbage bursts",
            stats.frames, stats.samples, stats.dropped_frames, stats.corrupted_frames, stats.garbage_bursts
        );
        Ok::<_, anyhow::Error>(())
    })?;
    Ok(ExitCode::SUCCESS)
}

/// Write the whole session as a `candump -L` log, as a bus capture would hold it: one
/// frame per sample (counter and three signals as in `fixtures/can/hammer.dbc`), or with
/// `fd` one CAN FD frame per block of 8 samples (`config/hammer-canfd.dbc`).
fn write_candump(mut sim: SimMachine, out: &std::path::Path, fd: bool) -> anyhow::Result<ExitCode> {
    use crate::acquire::can::{CanDevice, forgemon_fd_mapping, forgemon_mapping};
    use std::io::Write;
    let mut dev = CanDevice::new(if fd { forgemon_fd_mapping() } else { forgemon_mapping() });
    let file = std::fs::File::create(out).with_context(|| format!("{}: cannot write", out.display()))?;
    let mut w = std::io::BufWriter::new(file);
    let mut samples = 0u64;
    while !sim.finished() {
        let rows = sim.next_rows(4096)?;
        samples += rows.len() as u64;
        dev.write_log(&mut w, "can0", &rows).with_context(|| format!("{}: cannot write", out.display()))?;
    }
    w.flush()?;
    if fd {
        let frames = (samples - dev.pending() as u64) / crate::acquire::can::BLOCK_SAMPLES as u64;
        println!(
            "wrote {frames} CAN FD frames of {} samples ({} samples; the last {} not a full block, not sent) to {} (decode with config/hammer-canfd.dbc: Seq, Load_k, Acc_k, Disp_k)",
            crate::acquire::can::BLOCK_SAMPLES,
            samples,
            dev.pending(),
            out.display()
        );
    } else {
        println!(
            "wrote {samples} frames to {} (decode with fixtures/can/hammer.dbc: Load, Disp, Acc, Seq)",
            out.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Serve the session from a Modbus TCP server: every 10 ms the new samples go into the
/// block-mode ring at register 0 (3 channels of i32 counts with the demo's gains).
async fn serve_modbus(mut sim: SimMachine, listen: std::net::SocketAddr, rate: f64) -> anyhow::Result<()> {
    use crate::acquire::modbus::block::RingWriter;
    use crate::acquire::modbus::server::{BankService, TcpServer, lock, shared_bank};
    let bank = shared_bank();
    let server = TcpServer::start(listen, BankService { bank: bank.clone(), faults: Default::default(), unit: None })
        .await
        .with_context(|| format!("{listen}: cannot listen"))?;
    let mut ring = RingWriter::new(0, 8192, 3, 2, (1e9 / rate).round() as u32)?;
    ring.write_header(&mut lock(&bank).holding);
    println!(
        "simulated DAQ on modbus tcp {}: block mode at register 0, ring of 8192 samples x 3 channels (i32)",
        server.addr()
    );
    let channels = super::demo::demo_channels();
    let step = ((rate * 0.01) as usize).max(1);
    let start = tokio::time::Instant::now();
    let mut ticks = 0u32;
    while !sim.finished() {
        let rows = sim.next_rows(step)?;
        {
            let mut b = lock(&bank);
            ring.push(&mut b.holding, &crate::simdevice::to_counts(&rows, &channels));
            ring.write_header(&mut b.holding);
        }
        ticks += 1;
        tokio::select! {
            _ = tokio::time::sleep_until(start + std::time::Duration::from_millis(10) * ticks) => {}
            _ = tokio::signal::ctrl_c() => break,
        }
    }
    // Stay up after the last sample, so that a reader can drain the ring.
    println!("session over; serving the ring for {} s more", DRAIN_LINGER.as_secs());
    tokio::select! {
        _ = tokio::time::sleep(DRAIN_LINGER) => {}
        _ = tokio::signal::ctrl_c() => {}
    }
    drop(server);
    Ok(())
}

/// How long the Modbus device keeps serving after its session has ended.
const DRAIN_LINGER: std::time::Duration = std::time::Duration::from_secs(3);

#[cfg(test)]
mod tests {
    use super::super::{Cli, Command};
    use clap::Parser;

    /// Issue 22: the billets' heights and the idle between them are set on the command line.
    #[test]
    fn height_spread_and_billet_idle_parse() {
        let args = ["forgemon", "simulate-device", "--machine", "m.toml", "--process", "p.toml", "--v0", "3.9"];
        let cli = Cli::try_parse_from(args.iter().chain(&["--height-spread", "0.05", "--billet-idle", "30"])).unwrap();
        let Command::SimulateDevice(a) = cli.command else { panic!("not simulate-device") };
        assert_eq!((a.height_spread, a.billet_idle), (0.05, 30.0));
        let Command::SimulateDevice(d) = Cli::try_parse_from(args).unwrap().command else { panic!() };
        assert_eq!((d.height_spread, d.billet_idle), (0.0, 0.0));
        assert!(!d.can_fd);
    }

    /// Issue 16: a CAN FD log is asked for with --can-fd, which needs a file to write.
    #[test]
    fn can_fd_parses_and_needs_an_output_file() {
        let args = ["forgemon", "simulate-device", "--machine", "m.toml", "--process", "p.toml", "--v0", "3.9"];
        let fd = ["--transport", "candump", "--out", "x.log", "--can-fd", "--rate", "50000"];
        let Command::SimulateDevice(a) = Cli::try_parse_from(args.iter().chain(&fd)).unwrap().command else {
            panic!("not simulate-device")
        };
        assert!(a.can_fd && a.rate == 50e3);
        assert!(Cli::try_parse_from(args.iter().chain(&["--can-fd"])).is_err());
    }
}
