//! `forgemon simulate` (docs/interfaces.md §4): consecutive blows on a billet, bare strikes,
//! effects, the Monte Carlo precision study and time-series traces.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Args;
use serde_json::{Value, json};

use super::{parse_process_warn, read_text};
use crate::config::limits::IMPACT_SPEED_MPS;
use crate::config::{MachineFile, parse_machine};
use crate::physics::blow::{BlowResult, DEFAULT_RTOL, POST_WINDOW_S, SimOptions};
use crate::physics::effects::{Effect, EffectSet};
use crate::physics::integrator::Method;
use crate::physics::ledger::Ledger;
use crate::physics::machine::MachineKind;
use crate::physics::montecarlo::{Uncertainty, monte_carlo};
use crate::physics::process::Process;
use crate::physics::sequence::{simulate_bare, simulate_sequence};
use crate::signal::capture::write_capture;
use crate::synth::{CaptureSpec, synth_blows};

/// Default sample period of `--trace`, s (100 kHz, the DAQ rate of the service).
pub const DEFAULT_TRACE_DT_S: f64 = 1e-5;
/// Default seed of `--monte-carlo`.
pub const DEFAULT_SEED: u64 = 1;

#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// The machine model (machine.toml).
    #[arg(long)]
    pub machine: PathBuf,
    /// The process sheet (process.toml); not needed with --bare.
    #[arg(long, required_unless_present = "bare")]
    pub process: Option<PathBuf>,
    /// Impact speed of each blow, m/s, comma separated: one blow per value.
    #[arg(long, value_delimiter = ',', required = true, num_args = 1.., allow_negative_numbers = true)]
    pub v0: Vec<f64>,
    /// Print one JSON object (docs/interfaces.md §4) instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Bare strikes: tool on tool, no billet; prints peak load and contact time.
    #[arg(long, conflicts_with = "process")]
    pub bare: bool,
    /// Switch on an effect: NAME:param=value[,param=value] (repeatable; overrides the
    /// machine file's [effects.NAME]).
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// Monte Carlo precision study with N runs (hammer paper §2.5).
    #[arg(long, value_name = "N")]
    pub monte_carlo: Option<usize>,
    /// Seed of the Monte Carlo draws.
    #[arg(long, default_value_t = DEFAULT_SEED, requires = "monte_carlo")]
    pub seed: u64,
    /// 95 % bound of the impact speed, m/s (paper Table 2).
    #[arg(long, default_value_t = 0.20, requires = "monte_carlo")]
    pub mc_v0_95: f64,
    /// 95 % bound of the friction coefficient (paper Table 2).
    #[arg(long, default_value_t = 0.05, requires = "monte_carlo")]
    pub mc_friction_95: f64,
    /// 95 % bound of the load measurement, N (paper Table 2).
    #[arg(long, default_value_t = 300e3, requires = "monte_carlo")]
    pub mc_load_95: f64,
    /// Write the simulated time series to this CSV file.
    #[arg(long, value_name = "FILE.csv")]
    pub trace: Option<PathBuf>,
    /// Sample period of the trace, s.
    #[arg(long, default_value_t = DEFAULT_TRACE_DT_S, requires = "trace")]
    pub trace_dt: f64,
    /// Also write the blows as a capture directory (blow_01.csv, ..., process.toml), the way a
    /// DAQ would have recorded them: approach, sensor offset and noise, 10 µm encoder. Where
    /// the sheet lists measured heights, the directory's sheet lists the simulated ones
    /// instead, after every blow, as a caliper reads them (0.01 mm).
    /// With --bare: bare strikes, blow_01.csv, ..., without a process sheet.
    #[arg(long, value_name = "DIR")]
    pub captures: Option<PathBuf>,
    /// Seed of the capture noise.
    #[arg(long, default_value_t = DEFAULT_SEED, requires = "captures")]
    pub capture_seed: u64,
    /// Relative tolerance of the adaptive integrator.
    #[arg(long, default_value_t = DEFAULT_RTOL)]
    pub rtol: f64,
    /// Use the fixed-step RK4 reference at this step, s, instead of the adaptive integrator.
    #[arg(long, value_name = "DT_S")]
    pub rk4_dt: Option<f64>,
}

/// Machine model and effects, read and checked.
struct Inputs {
    machine: MachineFile,
    effects: Vec<Effect>,
    set: EffectSet,
}

fn load_inputs(args: &SimulateArgs) -> anyhow::Result<Inputs> {
    let machine = parse_machine(&args.machine.display().to_string(), &read_text(&args.machine)?)?;
    let mut effects = machine.effects.clone();
    for spec in &args.effects {
        let e = Effect::parse_spec(spec)
            .and_then(|e| e.check_machine(machine.machine.kind()).map(|()| e))
            .with_context(|| format!("--effect {spec}"))?;
        effects.retain(|x| x.name() != e.name());
        effects.push(e);
    }
    let set = EffectSet::from_effects(&effects);
    Ok(Inputs { machine, effects, set })
}

fn load_process(path: &Path, machine: &MachineFile, machine_path: &Path) -> anyhow::Result<Process> {
    let p = parse_process_warn(&path.display().to_string(), &read_text(path)?)?;
    if p.machine != machine.machine.kind() {
        bail!(
            "{}: key 'machine' is \"{}\" but {} has kind \"{}\"",
            path.display(),
            p.machine.as_str(),
            machine_path.display(),
            machine.machine.kind().as_str()
        );
    }
    Ok(p)
}

fn options(args: &SimulateArgs) -> anyhow::Result<SimOptions> {
    let method = match args.rk4_dt {
        Some(dt) if dt.is_finite() && dt > 0.0 => Method::Rk4 { dt_s: dt },
        Some(dt) => bail!("--rk4-dt must be finite and > 0, got {dt}"),
        None if args.rtol.is_finite() && args.rtol > 0.0 && args.rtol < 1.0 => Method::Dopri5 { rtol: args.rtol },
        None => bail!("--rtol must be in (0, 1), got {}", args.rtol),
    };
    if args.trace.is_some() && !(args.trace_dt.is_finite() && args.trace_dt > 0.0) {
        bail!("--trace-dt must be finite and > 0, got {}", args.trace_dt);
    }
    Ok(SimOptions { method, post_s: POST_WINDOW_S, trace_dt_s: args.trace.as_ref().map(|_| args.trace_dt) })
}

pub fn run(args: SimulateArgs) -> anyhow::Result<ExitCode> {
    let out = output(&args)?;
    let stdout = std::io::stdout();
    let mut w = stdout.lock();
    if args.json {
        writeln!(w, "{out}")?;
    } else {
        write_table(&mut w, &out)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// What `forgemon simulate --json` prints (docs/interfaces.md §4), with the files `args`
/// asks for (captures, trace) written.
pub fn output(args: &SimulateArgs) -> anyhow::Result<Value> {
    let inputs = load_inputs(args)?;
    let opts = options(args)?;
    if let Some((bad, why)) = args.v0.iter().find_map(|v| IMPACT_SPEED_MPS.check(*v).err().map(|w| (v, w))) {
        bail!("--v0: impact speed {bad} m/s {why}");
    }
    let mut out = json!({});
    let results: Vec<BlowResult>;
    if args.bare {
        if args.monte_carlo.is_some() {
            bail!("--monte-carlo needs a billet: it studies blows, not bare strikes");
        }
        results = args
            .v0
            .iter()
            .map(|&v| {
                simulate_bare(&inputs.machine.machine, &inputs.set, v, &opts)
                    .with_context(|| format!("bare strike at {v} m/s"))
            })
            .collect::<anyhow::Result<_>>()?;
        out["strikes"] = results.iter().enumerate().map(|(i, r)| strike_json(i + 1, r)).collect();
        if let Some(dir) = &args.captures {
            let spec = capture_spec(inputs.machine.machine.kind(), args.capture_seed);
            let strikes = crate::synth::synth_bare(&inputs.machine.machine, &inputs.set, &args.v0, &spec)?;
            write_capture_files(dir, &strikes)
                .with_context(|| format!("{}: cannot write the capture directory", dir.display()))?;
        }
    } else {
        let process_path = args.process.as_ref().context("--process is required without --bare")?;
        let process = load_process(process_path, &inputs.machine, &args.machine)?;
        results = simulate_sequence(&inputs.machine.machine, &inputs.set, &process, &args.v0, &opts)?;
        if let Some(dir) = &args.captures {
            write_captures(dir, &inputs, &process, process_path, args)
                .with_context(|| format!("{}: cannot write the capture directory", dir.display()))?;
        }
        out["blows"] = results
            .iter()
            .enumerate()
            .map(|(i, r)| blow_json(i + 1, r, process.measured_final_heights_m.get(i)))
            .collect();
        if let Some(runs) = args.monte_carlo {
            let unc = Uncertainty { v0_mps: args.mc_v0_95, friction: args.mc_friction_95, load_n: args.mc_load_95 };
            let mc = monte_carlo(
                &inputs.machine.machine,
                &inputs.set,
                &process,
                &args.v0,
                &unc,
                runs,
                args.seed,
                &SimOptions { trace_dt_s: None, ..opts },
            )?;
            out["monte_carlo"] = serde_json::to_value(&mc)?;
        }
    }
    out["effects"] = inputs.effects.iter().map(|e| Value::String(e.to_string())).collect();
    if let Some(path) = &args.trace {
        write_trace(path, &results).with_context(|| format!("{}: cannot write the trace", path.display()))?;
    }
    Ok(out)
}

fn energy_json(e: &Ledger) -> Value {
    json!({
        "kinetic_in_J": e.kinetic_in_j,
        "plastic_J": e.plastic_j,
        "friction_J": e.friction_j,
        "damped_J": e.damped_j,
        "elastic_J": e.elastic_j,
    })
}

fn blow_json(n: usize, r: &BlowResult, measured: Option<&f64>) -> Value {
    let f = r.forming.expect("sequence blows always have forming indicators");
    let mut v = json!({
        "blow": n,
        "v0_mps": r.v0_mps,
        "h_start_m": r.h_start_m,
        "h_end_m": f.h_end_m,
        "final_load_N": f.final_load_n,
        "peak_load_N": r.peak_load_n,
        "forming_time_s": f.forming_time_s,
        "spring_back_time_s": f.spring_back_time_s,
        "energy": energy_json(&r.energy),
        "efficiency": r.efficiency(),
        "contact_time_s": r.contact_time_s,
        "ledger_closure": r.energy.closure_error(),
    });
    if let Some(h) = measured {
        v["measured_h_end_m"] = json!(h);
    }
    v
}

fn strike_json(n: usize, r: &BlowResult) -> Value {
    json!({
        "strike": n,
        "v0_mps": r.v0_mps,
        "peak_load_N": r.peak_load_n,
        "contact_time_s": r.contact_time_s,
        "energy": energy_json(&r.energy),
        "ledger_closure": r.energy.closure_error(),
    })
}

fn write_captures(
    dir: &Path,
    inputs: &Inputs,
    process: &Process,
    process_path: &Path,
    args: &SimulateArgs,
) -> anyhow::Result<()> {
    let spec = capture_spec(inputs.machine.machine.kind(), args.capture_seed);
    let blows = synth_blows(&inputs.machine.machine, &inputs.set, process, &args.v0, &spec)?;
    write_capture_files(dir, &blows)?;
    // A sheet without measured heights stays without (each blow then starts where the
    // model's one before ended); measured heights are another billet's: the simulated ones.
    if process.measured_final_heights_m.is_empty() {
        std::fs::copy(process_path, dir.join("process.toml"))?;
        return Ok(());
    }
    let heights: Vec<f64> = blows.iter().filter_map(|b| b.truth.forming.map(|f| f.h_end_m)).collect();
    let sheet = sheet_with_heights(&read_text(process_path)?, &heights)
        .with_context(|| format!("{}: cannot be read as TOML", process_path.display()))?;
    std::fs::write(dir.join("process.toml"), sheet)?;
    Ok(())
}

/// A caliper's readings per metre: it reads to 0.01 mm (and is good to
/// `EstimatorConfig::DEFAULT_CALIPER_RESOLUTION_M`).
const CALIPER_READINGS_PER_M: f64 = 1e5;

/// The process sheet `text` with its measured heights (`[[blows]] final_height_m`) replaced
/// by `heights_m`, each read to a caliper's 0.01 mm (`CALIPER_READINGS_PER_M`): the heights the simulated blows left,
/// so that a capture directory's sheet agrees with its encoder (the input sheet's heights
/// are another billet's, measured).
fn sheet_with_heights(text: &str, heights_m: &[f64]) -> Result<String, toml_edit::TomlError> {
    use toml_edit::{ArrayOfTables, DocumentMut, Table, value};
    let mut doc: DocumentMut = text.parse()?;
    let mut blows = ArrayOfTables::new();
    for (i, h) in heights_m.iter().enumerate() {
        let mut t = Table::new();
        t["final_height_m"] = value((h * CALIPER_READINGS_PER_M).round() / CALIPER_READINGS_PER_M);
        if i == 0 {
            t.decor_mut()
                .set_prefix("\n# The heights the simulated blows left (forgemon simulate --captures), to 0.01 mm.\n");
        }
        blows.push(t);
    }
    doc.remove("blows");
    if !blows.is_empty() {
        doc.insert("blows", toml_edit::Item::ArrayOfTables(blows));
    }
    Ok(doc.to_string())
}

fn capture_spec(kind: MachineKind, seed: u64) -> CaptureSpec {
    match kind {
        MachineKind::Hammer => CaptureSpec::hammer(seed),
        MachineKind::ScrewPress => CaptureSpec::press(seed),
    }
}

fn write_capture_files(dir: &Path, blows: &[crate::synth::SynthBlow]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    for (i, b) in blows.iter().enumerate() {
        let mut w = std::io::BufWriter::new(std::fs::File::create(dir.join(format!("blow_{:02}.csv", i + 1)))?);
        write_capture(&mut w, &b.rows)?;
        w.flush()?;
    }
    Ok(())
}

fn write_trace(path: &Path, results: &[BlowResult]) -> anyhow::Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(w, "blow,t_s,load_N,billet_load_N,x_upper_m,x_lower_m,h_m")?;
    for (i, r) in results.iter().enumerate() {
        for p in &r.trace {
            let o = &p.out;
            writeln!(
                w,
                "{},{:.9},{:.3},{:.3},{:.9},{:.9},{:.9}",
                i + 1,
                p.t_s,
                o.sensor_n,
                o.billet_n,
                o.upper_m,
                o.lower_m,
                o.h_m
            )?;
        }
    }
    w.flush()?;
    Ok(())
}

/// A table for people: one line per blow (or strike), then the Monte Carlo bands.
fn write_table(w: &mut impl Write, out: &Value) -> anyhow::Result<()> {
    let num = |v: &Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    if let Some(strikes) = out["strikes"].as_array() {
        writeln!(w, "strike  v0 m/s  peak kN  contact ms")?;
        for s in strikes {
            writeln!(
                w,
                "{:>6}  {:>6.3}  {:>7.0}  {:>10.2}",
                s["strike"].as_u64().unwrap_or(0),
                num(s, "v0_mps"),
                num(s, "peak_load_N") / 1e3,
                num(s, "contact_time_s") * 1e3
            )?;
        }
    }
    if let Some(blows) = out["blows"].as_array() {
        writeln!(
            w,
            "blow  v0 m/s  h_end mm  final kN  peak kN  forming ms  spring-back ms  plastic J  friction J  damped J  elastic J  efficiency"
        )?;
        for b in blows {
            let e = &b["energy"];
            writeln!(
                w,
                "{:>4}  {:>6.3}  {:>8.2}  {:>8.0}  {:>7.0}  {:>10.2}  {:>14.2}  {:>9.0}  {:>10.0}  {:>8.0}  {:>9.0}  {:>10.3}",
                b["blow"].as_u64().unwrap_or(0),
                num(b, "v0_mps"),
                num(b, "h_end_m") * 1e3,
                num(b, "final_load_N") / 1e3,
                num(b, "peak_load_N") / 1e3,
                num(b, "forming_time_s") * 1e3,
                num(b, "spring_back_time_s") * 1e3,
                num(e, "plastic_J"),
                num(e, "friction_J"),
                num(e, "damped_J"),
                num(e, "elastic_J"),
                num(b, "efficiency"),
            )?;
        }
    }
    if let Some(mc) = out["monte_carlo"].as_object() {
        writeln!(
            w,
            "\nMonte Carlo: {} runs (seed {}, {} failed); mean [95 % band]",
            mc["runs"], mc["seed"], mc["failed"]
        )?;
        writeln!(w, "blow  final load kN              h_end mm                 efficiency")?;
        for b in mc["blows"].as_array().into_iter().flatten() {
            let band = |k: &str, s: f64| {
                format!("{:.1} [{:.1}, {:.1}]", num(&b[k], "mean") * s, num(&b[k], "p2_5") * s, num(&b[k], "p97_5") * s)
            };
            let eff = format!(
                "{:.3} [{:.3}, {:.3}]",
                num(&b["efficiency"], "mean"),
                num(&b["efficiency"], "p2_5"),
                num(&b["efficiency"], "p97_5")
            );
            writeln!(
                w,
                "{:>4}  {:<24} {:<24} {}",
                b["blow"].as_u64().unwrap_or(0),
                band("final_load_N", 1e-3),
                band("h_end_m", 1e3),
                eff
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{Cli, Command};
    use super::sheet_with_heights;
    use clap::Parser;

    #[test]
    fn contract_command_line_parses() {
        let cli = Cli::try_parse_from([
            "forgemon",
            "simulate",
            "--machine",
            "m.toml",
            "--process",
            "p.toml",
            "--v0",
            "3.9,5.3",
            "--json",
        ])
        .unwrap();
        let Command::Simulate(a) = cli.command else { panic!("not simulate") };
        assert_eq!(a.v0, vec![3.9, 5.3]);
        assert!(a.json && !a.bare);
    }

    #[test]
    fn process_is_required_unless_bare() {
        assert!(Cli::try_parse_from(["forgemon", "simulate", "--machine", "m.toml", "--v0", "3.9"]).is_err());
        assert!(
            Cli::try_parse_from(["forgemon", "simulate", "--machine", "m.toml", "--v0", "0.363", "--bare"]).is_ok()
        );
        assert!(
            Cli::try_parse_from(["forgemon", "simulate", "--machine", "m", "--process", "p", "--v0", "1", "--bare"])
                .is_err()
        );
    }

    #[test]
    fn the_capture_sheet_carries_the_simulated_heights() {
        let text =
            "machine = \"hammer\"\n[billet]\nheight_m = 0.112 # note\n\n[[blows]]\nfinal_height_m = 0.089  # Table 3\n";
        let out = sheet_with_heights(text, &[0.0929303714, 0.0663104]).unwrap();
        let t: toml::Table = out.parse().unwrap();
        let h: Vec<f64> =
            t["blows"].as_array().unwrap().iter().map(|b| b["final_height_m"].as_float().unwrap()).collect();
        assert_eq!(h, vec![0.09293, 0.06631]);
        assert!(out.contains("height_m = 0.112 # note") && !out.contains("Table 3"), "{out}");
        // No blows: no measured heights.
        let none: toml::Table = sheet_with_heights(text, &[]).unwrap().parse().unwrap();
        assert!(!none.contains_key("blows"));
    }

    #[test]
    fn seed_needs_monte_carlo() {
        assert!(
            Cli::try_parse_from([
                "forgemon",
                "simulate",
                "--machine",
                "m",
                "--process",
                "p",
                "--v0",
                "1",
                "--seed",
                "3"
            ])
            .is_err()
        );
    }
}
