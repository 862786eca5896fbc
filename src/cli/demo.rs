//! `forgemon demo`: the whole service against a simulated hammer, on a fresh machine with no
//! hardware. A simulated MONTBARD LG1000 (hammer paper, Table 1) forges steel billets and
//! streams its DAQ samples over an in-process pty pair in the serial framing of
//! docs/interfaces.md §7; the real service reads the other end, prints one line per blow,
//! records to `./forgemon-demo/`, and stops after the billets (or on Ctrl-C). On a terminal
//! its faces (the dashboard, ...) stay up after the last billet until Ctrl-C, so the URL it
//! printed can still be opened; piped or `--fast`, it ends after the last billet. A reader
//! that closes its stdout (`| head`) stops it as Ctrl-C does, with the recording closed.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::{Arc, OnceLock};

use anyhow::Context;
use clap::Args;
use tokio::sync::{mpsc, watch};

use super::out;
use crate::acquire::serial::driver::{SerialConfig, SerialFormat, run_on_stream, system_clock_ns};
use crate::acquire::{Backpressure, ChannelSpec};
use crate::config::advisor::AdvisorConfig;
use crate::config::service::ServiceConfig;
use crate::config::uplink::MqttUplink;
use crate::config::{parse_machine, parse_process};
use crate::daemon::{Control, Hooks, SOURCE_CHANNEL_CAPACITY, ServiceParts, serve};
use crate::estimate::BlowEstimate;
use crate::physics::effects::EffectSet;
use crate::signal::sample::{Channels, Role};
use crate::simdevice::{BilletPlan, SerialDeviceSpec, SerialFaults, SimMachine, drive_serial};
use crate::synth::CaptureSpec;

const MACHINE: &str = include_str!("../../config/hammer-lg1000.machine.toml");
const STEEL: &str = include_str!("../../config/steel-16NiCrMo13.process.toml");

/// `--billets 0`: billets enough to forge until Ctrl-C (at the default interval, 8 blows of
/// 1.5 s a billet, 33 hours); each is a plan held in memory, so not unbounded.
const UNTIL_STOPPED_BILLETS: usize = 10_000;

/// How long the simulated device keeps the pty open after its last frame.
const DEVICE_LINGER: std::time::Duration = std::time::Duration::from_secs(1);

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// How many billets to forge (0: keep forging until Ctrl-C).
    #[arg(long, default_value_t = 2)]
    pub billets: usize,
    /// Seconds between blows.
    #[arg(long, default_value_t = 1.5)]
    pub interval: f64,
    /// Where to record.
    #[arg(long, default_value = "forgemon-demo")]
    pub dir: PathBuf,
    /// Run as fast as possible instead of in real time, and end after the last billet
    /// (on a terminal the demo otherwise keeps its dashboard up until Ctrl-C).
    #[arg(long)]
    pub fast: bool,
    /// Serve the dashboard and `/status` here (loopback only: the demo has no token);
    /// default: a free loopback port.
    #[arg(long, value_name = "ADDR")]
    pub http: Option<std::net::SocketAddr>,
    /// Serve the PLC result image (Modbus TCP, docs/interfaces.md §8) here.
    #[arg(long, value_name = "ADDR")]
    pub plc: Option<std::net::SocketAddr>,
    /// Serve the Foxglove WebSocket protocol here.
    #[arg(long, value_name = "ADDR")]
    pub foxglove: Option<std::net::SocketAddr>,
    /// Publish Sparkplug B to this MQTT broker (`mqtt://host:port`, docs/interfaces.md §10), as
    /// group `forge`, node `forgemon`, device `machine`; queued under `--dir` while it is down.
    #[arg(long, value_name = "URL")]
    pub mqtt: Option<String>,
    /// Serve the OPC UA Metal Forming server here (`opc.tcp://127.0.0.1:4840`; loopback
    /// only: the demo's sessions are anonymous).
    #[arg(long, value_name = "URL")]
    pub opcua: Option<String>,
    /// With --opcua: the OPC Foundation's NodeSet2 files (Machinery, Machine Tools, Metal
    /// Forming and what they require; `[opcua] nodesets_dir`), whose types the machine's
    /// nodes are then instances of.
    #[arg(long, value_name = "DIR", requires = "opcua")]
    pub opcua_nodesets: Option<PathBuf>,
    /// Start a new recording file after this many MiB (`[recording] rotate_bytes`), as a
    /// long run's files are rotated; default: the service's 512 MiB.
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(1..=1_048_576))]
    pub rotate_mib: Option<u64>,
    /// Judge every blow against this recipe (`forgemon teach`), OK/NOK.
    #[arg(long, value_name = "PART.recipe.toml")]
    pub recipe: Option<PathBuf>,
    /// Run the live blow advisor towards this billet height, m: after each blow it plans the
    /// blows left (`[advisor]` in a service file).
    #[arg(long, value_name = "M")]
    pub target: Option<f64>,
    /// The hammer's impact speeds the advisor may choose from, m/s (its drop heights).
    #[arg(long, value_name = "V,...", value_delimiter = ',', default_value = "2.6,3.9,4.6,5.3")]
    pub settings: Vec<f64>,
    /// Simulate a hammer without this sensor (`load`, `acc` or `disp`): its DAQ sends the
    /// other two channels, and each blow is estimated from them (the `channels` of its
    /// result).
    #[arg(long, value_name = "load|acc|disp", value_parser = parse_channel)]
    pub without: Option<Role>,
    /// Kill a channel of the simulated DAQ this many seconds into the run (`load@12.5`): from
    /// then on it reads 0. The service notices from the next blow, raises one `sensor`
    /// alert naming it, and estimates the blows without it.
    #[arg(long, value_name = "CHANNEL@SECONDS", value_parser = parse_dead)]
    pub dead: Option<(Role, f64)>,
    /// The lot the billets come from (`[part] lot`): on every blow and billet in the
    /// history database (`--dir`/history.sqlite) and the recording.
    #[arg(long, value_name = "LOT", value_parser = parse_id)]
    pub lot: Option<String>,
    /// The die set in the hammer (`[part] die_set`), as --lot.
    #[arg(long, value_name = "DIE_SET", value_parser = parse_id)]
    pub die: Option<String>,
    /// Forge each billet a little unlike the last, as a plant's billets come: its flow stress
    /// ±3 % and its friction ±3 % (one sd, drawn per billet, the same every run of a lot and
    /// die set), so the
    /// history's charts and SPC have a spread to show.
    #[arg(long)]
    pub scatter: bool,
}

fn parse_dead(s: &str) -> Result<(Role, f64), String> {
    let (channel, at) = s.split_once('@').ok_or("must be CHANNEL@SECONDS, e.g. load@12.5")?;
    let role = parse_channel(channel)?;
    let t: f64 = at.parse().map_err(|_| format!("'{at}' is not a number of seconds"))?;
    if !(t.is_finite() && t >= 0.0) {
        return Err(format!("{t} s is not a time into the run"));
    }
    Ok((role, t))
}

fn parse_channel(s: &str) -> Result<Role, String> {
    Role::from_short(s).ok_or_else(|| "must be one of load, acc, disp".to_string())
}

/// A lot or die set as `[part]` takes it.
fn parse_id(s: &str) -> Result<String, String> {
    crate::config::history::check_id(s).map(str::to_string)
}

/// The DAQ's channels: 1 N, 1 µm and 1 mm/s² per count.
pub fn demo_channels() -> Vec<ChannelSpec> {
    vec![
        ChannelSpec { role: Role::Load, gain: 1.0, offset: 0.0 },
        ChannelSpec { role: Role::Disp, gain: 1e-6, offset: 0.0 },
        ChannelSpec { role: Role::Acc, gain: 1e-3, offset: 0.0 },
    ]
}

/// The demo DAQ's channels less the one `--without` leaves out.
fn channels_without(without: Option<Role>) -> Vec<ChannelSpec> {
    demo_channels().into_iter().filter(|c| Some(c.role) != without).collect()
}

pub fn run(args: DemoArgs) -> anyhow::Result<ExitCode> {
    check(&args)?;
    let opcua = args
        .opcua
        .as_deref()
        .map(crate::config::opcua::OpcuaConfig::anonymous)
        .transpose()
        .map_err(|e| anyhow::anyhow!("--opcua {e}"))?
        .map(|o| crate::config::opcua::OpcuaConfig { nodesets_dir: args.opcua_nodesets.clone(), ..o });
    let machine = parse_machine("hammer-lg1000.machine.toml", MACHINE)?.machine;
    let steel = parse_process("steel-16NiCrMo13.process.toml", STEEL)?;
    let billets = if args.billets == 0 { UNTIL_STOPPED_BILLETS } else { args.billets };
    // Each lot and die set its own billets (a fixed seed per pair, the same every run).
    let seed = [&args.lot, &args.die]
        .iter()
        .flat_map(|s| s.as_deref().unwrap_or("").bytes())
        .fold(44u64, |h, b| h.wrapping_mul(31).wrapping_add(u64::from(b)));
    let plans = plans(steel, billets, args.scatter.then_some(seed));
    let sim = SimMachine::new(machine, EffectSet::NONE, plans, CaptureSpec::hammer(7), args.interval);
    let parts = parts(&args, opcua.clone())?;
    let (stop_tx, stop_rx) = watch::channel(false);
    let faces = Faces {
        stay_up: !args.fast && std::io::stdout().is_terminal(),
        http: Arc::new(OnceLock::new()),
        stop: stop_tx,
    };
    let hooks = hooks(&args, opcua.map(|o| o.url), &faces);
    super::run::init_logging("error");
    let rt = tokio::runtime::Runtime::new()?;
    let device = SerialDeviceSpec {
        channels: channels_without(args.without),
        frame_samples: 1000,
        realtime: !args.fast,
        faults: SerialFaults { dead: args.dead, ..Default::default() },
    };
    rt.block_on(serve_demo(sim, device, parts, hooks, faces, stop_rx))?;
    Ok(ExitCode::SUCCESS)
}

/// The demo's billets: the steel sheet's, struck at 3.9 m/s and then 5.3 m/s seven times;
/// with `scatter`, each its own flow stress (±3 %) and friction (±3 %), drawn from its seed.
fn plans(steel: crate::physics::process::Process, billets: usize, scatter: Option<u64>) -> Vec<BilletPlan> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let v0s_mps = vec![3.9, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3];
    let mut rng = rand::rngs::StdRng::seed_from_u64(scatter.unwrap_or(0));
    (0..billets)
        .map(|_| {
            let mut process = steel.clone();
            if scatter.is_some() {
                let (a, b): (f64, f64) = (StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
                process.material = process.material.scaled(1.0 + 0.03 * a);
                process.friction *= 1.0 + 0.03 * b;
            }
            BilletPlan { process, v0s_mps: v0s_mps.clone() }
        })
        .collect()
}

/// How the demo's faces end, and what stops the demo besides the signals.
struct Faces {
    /// Keep the faces up after the last billet until Ctrl-C (stdout a terminal, not `--fast`).
    stay_up: bool,
    /// The dashboard's address, once it listens.
    http: Arc<OnceLock<std::net::SocketAddr>>,
    /// Stops the service as Ctrl-C does: sent when stdout is closed (`say`).
    stop: watch::Sender<bool>,
}

/// One line of the demo's output. A closed stdout (`| head`) stops the demo as Ctrl-C
/// would, so the recording is closed; `main` then exits quietly (`out::EXIT_STDOUT_CLOSED`).
fn say(stop: &watch::Sender<bool>, line: std::fmt::Arguments<'_>) {
    if out::line(line).is_err() {
        stop.send_replace(true);
    }
}

/// The flags' values, before anything opens.
fn check(args: &DemoArgs) -> anyhow::Result<()> {
    if !(args.interval.is_finite() && args.interval >= 0.2) {
        anyhow::bail!("--interval must be at least 0.2 s (a blow and its capture take 0.05 s)");
    }
    if let Some(a) = args.http.filter(|a| !a.ip().is_loopback()) {
        anyhow::bail!(
            "--http {a}: the demo serves loopback only (a service file's [http] token_file guards other addresses)"
        );
    }
    if let Some(t) = args.target {
        super::length_m("--target", t, crate::config::limits::MEASURED_HEIGHT_M)?;
        let speed = crate::config::limits::IMPACT_SPEED_MPS;
        for v in &args.settings {
            speed.check(*v).map_err(|why| anyhow::anyhow!("--settings {v}: {why}"))?;
        }
    }
    Ok(())
}

/// The service the demo runs: the paper's hammer and steel, the faces the flags ask for.
fn parts(args: &DemoArgs, opcua: Option<crate::config::opcua::OpcuaConfig>) -> anyhow::Result<ServiceParts> {
    let uplink = match args.mqtt.as_deref() {
        Some(url) => Some(MqttUplink::for_url(url).map_err(|e| anyhow::anyhow!("--mqtt: {e}"))?),
        None => None,
    };
    let config = ServiceConfig {
        recipe_path: args.recipe.clone(),
        http_listen: args.http.unwrap_or_else(|| "127.0.0.1:0".parse().expect("a valid address")),
        plc_listen: args.plc,
        foxglove_listen: args.foxglove,
        opcua,
        advisor: args.target.map(|target_height_m| AdvisorConfig {
            target_height_m,
            speeds: crate::advise::Speeds::Settings(args.settings.clone()),
        }),
        uplink_mqtt: uplink,
        absent_channels: args.without.map_or(Channels::NONE, |r| Channels::NONE.with(r, true)),
        part: crate::config::history::Trace { part_id: None, lot: args.lot.clone(), die_set: args.die.clone() },
        ..ServiceConfig::minimal(PathBuf::from("hammer-lg1000.machine.toml"), args.dir.clone())
    };
    let config = match args.rotate_mib {
        Some(mib) => ServiceConfig { rotate_bytes: mib << 20, ..config },
        None => config,
    };
    // No new-billet signal: the service finds each billet from the encoder (issue 22), so it
    // tracks the billet's height and splits plastic from friction work on every billet.
    Ok(ServiceParts {
        config,
        config_path: args.dir.join("demo.toml"),
        // Recorded as the service file: a replay of the demo's recording uses the defaults.
        config_text: "# forgemon demo: a simulated hammer, every threshold at its default\n".to_string(),
        machine: parse_machine("hammer-lg1000.machine.toml", MACHINE)?.machine,
        effects: crate::physics::effects::EffectSet::NONE,
        machine_text: MACHINE.to_string(),
        process: Some(parse_process("steel-16NiCrMo13.process.toml", STEEL)?),
        process_text: Some(STEEL.to_string()),
        // Run fast, the simulated device waits for the service; in real time it cannot.
        backpressure: if args.fast { Backpressure::Wait } else { Backpressure::DropOldest },
    })
}

/// The simulated hammer on one end of a pty, the service on the other, until the device
/// has sent its last billet (or, with `faces.stay_up`, until Ctrl-C); then the summary line.
async fn serve_demo(
    sim: SimMachine,
    spec: SerialDeviceSpec,
    parts: ServiceParts,
    hooks: Hooks,
    faces: Faces,
    stop_rx: watch::Receiver<bool>,
) -> anyhow::Result<()> {
    let (master, slave) = tokio_serial::SerialStream::pair().context("cannot open a pty pair")?;
    let (tx, rx) = mpsc::channel(SOURCE_CHANNEL_CAPACITY);
    // The service ends when its sources hang up; a sender held here keeps it serving after
    // the device's last frame, until Ctrl-C, SIGTERM or a closed stdout.
    let hold_open = faces.stay_up.then(|| tx.clone());
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let device_stop = shutdown_rx.clone();
    stop_on_hangup(faces.stop.clone())?;
    let (control_tx, control_rx) = mpsc::channel::<Control>(16);
    let channels = spec.channels.clone();
    let device = tokio::spawn(async move {
        let mut master = master;
        let stopped = device_stop.clone();
        let stats = drive_serial(sim, &spec, &mut master, device_stop, |_, _| {}).await?;
        // A pty discards what the reader has not read yet when its master closes (the
        // last frame was lost this way: 1 of 24000 on `--fast --billets 20`). The reader
        // needs room for a read's events to take it, which a pipeline at 10× real time
        // frees within tens of ms: stay open a second after the last frame.
        tokio::time::sleep(DEVICE_LINGER).await;
        if faces.stay_up && !*stopped.borrow() {
            let url = faces.http.get().map_or_else(|| "its address".to_string(), |a| format!("http://{a}/"));
            say(&faces.stop, format_args!("demo finished: the dashboard stays up at {url} until Ctrl-C"));
        }
        Ok::<_, std::io::Error>(stats)
    });
    let cfg = SerialConfig {
        backpressure: parts.backpressure,
        ..SerialConfig::new("daq", "pty", 0, SerialFormat::Binary, channels)
    };
    tokio::spawn(run_on_stream(cfg, slave, system_clock_ns, tx, shutdown_rx));
    let summary = serve(parts, rx, shutdown_tx, stop_rx, hooks, Some((control_tx, control_rx))).await?;
    drop(hold_open);
    let stats = device.await.context("the simulated device task")??;
    let files: Vec<String> = summary.files.iter().map(|f| f.display().to_string()).collect();
    // The recording is closed; a closed stdout only loses these lines (`main` exits quietly).
    let _ = out::outln!(
        "forgemon demo: {} billets, {} blows ({} incomplete), {} alerts, {} samples ({} frames from the device, {} events dropped); recorded {}",
        summary.billets,
        summary.blows,
        summary.incomplete_blows,
        summary.alerts,
        summary.samples,
        stats.frames,
        summary.dropped_events,
        files.join(", ")
    )
    .and_then(|()| match summary.record_errors {
        0 => Ok(()),
        n => out::outln!(
            "forgemon demo: {n} recording writes failed; {} blows were not recorded (the disk was full?)",
            summary.dropped_blows
        ),
    });
    Ok(())
}

/// A hangup (the demo's terminal closed) ends the demo as Ctrl-C does. The service takes
/// SIGHUP as "reload", so a demo keeping its faces up would otherwise run on with no
/// terminal to stop it from, its recording open.
fn stop_on_hangup(stop: watch::Sender<bool>) -> anyhow::Result<()> {
    let mut hangup = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())?;
    tokio::spawn(async move {
        if hangup.recv().await.is_some() {
            stop.send_replace(true);
        }
    });
    Ok(())
}

/// What the demo prints: where each face listens, then a line per blow, billet and plan.
/// Each hook stops the demo when stdout is closed (`say`).
fn hooks(args: &DemoArgs, opcua_url: Option<String>, faces: &Faces) -> Hooks {
    let dir = args.dir.clone();
    let billets = match args.billets {
        0 => "steel billets until Ctrl-C".to_string(),
        n => format!("{n} steel billets"),
    };
    let (plc, foxglove, mqtt) = (args.plc, args.foxglove, args.mqtt.clone());
    let streaming = match args.without {
        None => "3 channels".to_string(),
        Some(r) => format!("2 channels (no {} sensor: its {} is left out)", r.short(), r.column()),
    };
    let (http, stop) = (faces.http.clone(), faces.stop.clone());
    let [blow_stop, reject_stop, billet_stop, advice_stop] = [(); 4].map(|()| faces.stop.clone());
    Hooks {
        on_listening: Some(Box::new(move |addr| {
            let _ = http.set(addr);
            let say = |line: std::fmt::Arguments<'_>| say(&stop, line);
            say(format_args!(
                "forgemon demo: a simulated MONTBARD LG1000 drop hammer (paper Table 1) forges {billets}, 60 x 112 mm,"
            ));
            say(format_args!(
                "  streaming {streaming} at 100 kHz over a pty; recording to {}/; status on http://{addr}/status",
                dir.display()
            ));
            say(format_args!("  dashboard on http://{addr}/"));
            if let Some(plc) = plc {
                say(format_args!("  PLC result image (Modbus TCP, unit 1) on {plc}"));
            }
            if let Some(url) = &opcua_url {
                say(format_args!("  OPC UA server (Metal Forming, anonymous) on {url}"));
            }
            if let Some(fox) = foxglove {
                say(format_args!("  Foxglove live view on ws://{fox}"));
            }
            if let Some(url) = &mqtt {
                say(format_args!("  Sparkplug B to {url} as spBv1.0/forge/DDATA/forgemon/machine"));
            }
            say(format_args!("blow  billet  impact m/s  plastic J  efficiency                    class"));
        })),
        on_blow: Some(Box::new(move |e| print_blow(&blow_stop, e))),
        on_rejected: Some(Box::new(move |m| say(&reject_stop, format_args!("      (not estimated: {m})")))),
        on_billet: Some(Box::new(move |b| say(&billet_stop, format_args!("      {b}")))),
        on_advice: Some(Box::new(move |a| say(&advice_stop, format_args!("      advisor: {}", advice_line(a))))),
    }
}

/// A blow's line: its figures and an efficiency bar, then its judgement and alert.
fn print_blow(stop: &watch::Sender<bool>, e: &BlowEstimate) {
    let billet = e.billet.billet;
    match (e.plastic_j, e.efficiency) {
        (Some(plastic_j), Some(efficiency)) => {
            let bar_len = (efficiency.clamp(0.0, 1.0) * 24.0).round() as usize;
            let bar: String = "#".repeat(bar_len) + &".".repeat(24 - bar_len);
            say(
                stop,
                format_args!(
                    "{:>4}  {:>6}  {:>10.2}  {plastic_j:>9.0}  [{bar}] {efficiency:.2}  {}",
                    e.blow,
                    billet,
                    e.v_impact_mps,
                    e.class.as_str()
                ),
            );
        }
        _ => say(
            stop,
            format_args!(
                "{:>4}  {:>6}  {:>10.2}  {:>9}  {:<31}  {} ({:.1} ms lost)",
                e.blow,
                billet,
                e.v_impact_mps,
                "-",
                "(not estimated: samples lost)",
                e.class.as_str(),
                e.gap_s * 1e3
            ),
        ),
    }
    if let Some(j) = e.judgement.as_ref().filter(|j| !j.ok) {
        say(stop, format_args!("      NOK against recipe '{}': {}", j.recipe, j.reasons.join("; ")));
    }
    if let Some(a) = &e.alert {
        say(stop, format_args!("      ALERT {}: {}", a.kind.as_str(), a.reason));
    }
}

/// The advisor's plan in one line: the blows left and the next blow's speed, or why not.
pub fn advice_line(a: &crate::daemon::advisor::Advice) -> String {
    let Some(p) = &a.plan else { return format!("no plan: {}", a.why_not.as_deref().unwrap_or("unknown")) };
    let target_mm = p.target_m * 1e3;
    match (p.reachable, p.plan.first()) {
        (false, _) => format!("{target_mm:.1} mm not reachable: {}", p.why.as_deref().unwrap_or("")),
        (true, None) => format!("at the target, {target_mm:.1} mm ± 0.5"),
        (true, Some(next)) => {
            let speeds: Vec<String> = p.plan.iter().map(|b| format!("{:.2}", b.v0_mps)).collect();
            format!(
                "{} blow(s) from {:.2} mm to {target_mm:.1} mm at [{}] m/s; next {:.1} kJ{}",
                p.plan.len(),
                p.h_now_m * 1e3,
                speeds.join(", "),
                next.kinetic_j / 1e3,
                if p.hard_blows > 0 { format!(", {} hard", p.hard_blows) } else { String::new() }
            )
        }
    }
}
