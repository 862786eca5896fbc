//! `forgemon simulate-device`: a simulated hammer or press forging billets (approach,
//! blow, rebound, pause, next blow; a new billet when one is finished) that drives a real
//! transport, so the service (or any other program) can be pointed at it like a DAQ.
//! Serial: it opens a pty pair, prints the path of the end to open, and streams the binary
//! framing of CONTRACTS.md §7 (or the ASCII lines) in real time, with fault switches.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, ValueEnum};
use tokio::sync::watch;
use tokio_serial::SerialPort;

use super::read_text;
use crate::config::{parse_machine, parse_process};
use crate::physics::effects::{Effect, EffectSet};
use crate::physics::machine::MachineKind;
use crate::simdevice::{BilletPlan, SerialDeviceSpec, SerialFaults, SimMachine, drive_serial};
use crate::synth::CaptureSpec;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Wire {
    /// COBS frames with CRC-32C (CONTRACTS.md §7).
    Binary,
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
    /// Sample rate, Hz (up to 100 kHz).
    #[arg(long, default_value_t = 100e3)]
    pub rate: f64,
    /// Unmodelled effects to put into the simulated machine: NAME:param=value (repeatable).
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    #[arg(long, value_enum, default_value = "binary")]
    pub wire: Wire,
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
    let process = parse_process(&args.process.display().to_string(), &read_text(&args.process)?)?;
    if process.machine != mf.machine.kind() {
        anyhow::bail!("{}: key 'machine' does not match {}", args.process.display(), args.machine.display());
    }
    if !(args.rate.is_finite() && args.rate >= 1e3 && args.rate <= 100e3) {
        anyhow::bail!("--rate must be between 1 kHz and 100 kHz, got {}", args.rate);
    }
    let mut effects = mf.effects.clone();
    for spec in &args.effects {
        effects.push(Effect::parse_spec(spec).with_context(|| format!("--effect {spec}"))?);
    }
    let mut spec = match mf.machine.kind() {
        MachineKind::Hammer => CaptureSpec::hammer(1),
        MachineKind::ScrewPress => CaptureSpec::press(1),
    };
    spec.sample_rate_hz = args.rate;
    let billets = if args.billets == 0 { 1_000_000 } else { args.billets };
    let plan = BilletPlan { process, v0s_mps: args.v0.clone() };
    let sim = SimMachine::new(mf.machine, EffectSet::from_effects(&effects), vec![plan; billets], spec, args.interval);
    let dev = SerialDeviceSpec {
        channels: super::demo::demo_channels(),
        frame_samples: ((args.rate * 0.01) as usize).max(1),
        realtime: true,
        faults: SerialFaults {
            garbage_every: args.garbage_every,
            garbage_bytes: 64,
            corrupt_every: args.corrupt_every,
            drop_every: args.drop_every,
        },
    };
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async move {
        let (master, slave) = tokio_serial::SerialStream::pair().context("cannot open a pty pair")?;
        let path = slave.name().unwrap_or_default();
        println!("simulated {} on {path}: binary framing, channels load_N (1 N/count), disp_m (1 um/count), acc_mps2 (1 mm/s2/count), {} Hz", mf.machine.kind().as_str(), args.rate);
        let (stop_tx, stop_rx) = watch::channel(false);
        tokio::spawn(async move {
            let _ = tokio::signal::ctrl_c().await;
            let _ = stop_tx.send(true);
        });
        let stats = drive_serial(sim, &dev, master, stop_rx, |k| println!("billet {k}")).await?;
        drop(slave);
        println!(
            "device: {} frames, {} samples sent, {} frames dropped, {} corrupted, {} garbage bursts",
            stats.frames, stats.samples, stats.dropped_frames, stats.corrupted_frames, stats.garbage_bursts
        );
        Ok::<_, anyhow::Error>(())
    })?;
    Ok(ExitCode::SUCCESS)
}
