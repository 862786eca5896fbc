//! `forgemon identify`: fit `machine.toml` to reference blows (a billet blow with its
//! process sheet, hammer paper §2.3) or bare strikes (press paper §3.1), with standard
//! errors, correlations, the parameters the data cannot determine, and an HTML report.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;

use super::{parse_process_warn, read_text};
use crate::config::parse_machine;
use crate::identify::model::default_prior;
use crate::identify::objective::{Reference, Setting, Signal};
use crate::identify::speed::impact_speed_sd_mps;
use crate::identify::{IdentifyConfig, WithSpeedSd, identify};
use crate::physics::load_filter::LoadFilter;
use crate::physics::machine::MachineKind;
use crate::signal::sample::Role;
use crate::signal::segment::{Blow, SegmentConfig, Segmenter};

#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// Machine kind: hammer | screw_press.
    #[arg(long)]
    pub kind: String,
    /// Capture directory of the reference blows (blow_01.csv, ...).
    #[arg(long, value_name = "DIR")]
    pub reference: PathBuf,
    /// The references are bare strikes (tool on tool), not blows on a billet.
    #[arg(long)]
    pub bare: bool,
    /// Process sheet of the billet (default: DIR/process.toml).
    #[arg(long, value_name = "P.toml")]
    pub process: Option<PathBuf>,
    /// Where to write the identified machine.toml.
    #[arg(short = 'o', long = "out", value_name = "machine.toml")]
    pub out: PathBuf,
    /// Prior machine: the centre of the search bounds and the first start (default: the
    /// paper's machine of the kind). The press's sensor stiffness is taken from it.
    #[arg(long, value_name = "M.toml")]
    pub initial: Option<PathBuf>,
    /// The ram's mass from the machine's data sheet, kg: references without a load channel
    /// (the accelerometer and the encoder alone) see the ram's acceleration, not a force, so
    /// this mass is held and anchors the others. Default: the --initial machine's.
    #[arg(long, value_name = "KG")]
    pub ram_kg: Option<f64>,
    /// Blow numbers to fit, e.g. 1 or 1,3 (default: all); the others are predicted and
    /// reported as held out.
    #[arg(long, value_delimiter = ',')]
    pub fit_blows: Vec<usize>,
    /// Local searches (the prior plus random starts). Default: 8, and without a load
    /// channel `RAM_FORCE_STARTS`.
    #[arg(long)]
    pub starts: Option<usize>,
    /// Seed of the random starts and the Monte Carlo draws (the same seed, the same fit).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Monte Carlo draws for the load bands.
    #[arg(long, default_value_t = 200)]
    pub monte_carlo: usize,
    /// The HTML report (default: the output with .html).
    #[arg(long, value_name = "FILE.html")]
    pub report: Option<PathBuf>,
}

pub fn run(args: IdentifyArgs) -> anyhow::Result<ExitCode> {
    let started = Instant::now();
    let kind = match args.kind.as_str() {
        "hammer" => MachineKind::Hammer,
        "screw_press" => MachineKind::ScrewPress,
        k => bail!("--kind: '{k}' is not hammer or screw_press"),
    };
    let (prior, load_filter) = prior_of(&args, kind)?;
    let setting = setting_of(&args, kind)?;
    let anchor = (args.ram_kg.is_some() || args.initial.is_some()).then_some(prior.ram_kg());
    let (fit, held, signal) =
        read_references_by_signal(&args.reference, kind, args.bare, &args.fit_blows, (anchor, prior.ram_kg()))?;
    let cfg = IdentifyConfig {
        starts: args.starts.unwrap_or(if signal == Signal::Load { LOAD_STARTS } else { RAM_FORCE_STARTS }).max(1),
        seed: args.seed,
        monte_carlo: args.monte_carlo,
        load_filter,
        signal,
    };
    let bar = indicatif::ProgressBar::new((cfg.starts + cfg.monte_carlo) as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "identify {bar:40} {pos}/{len} (local searches, then Monte Carlo) {elapsed}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let result = identify(fit, held, setting, prior, &cfg, &|| bar.inc(1))?;
    bar.finish_and_clear();
    // The sheet against the encoder, as `replay` checks it (`identify::heights`).
    for w in result.sheet_checks.iter().filter_map(|c| c.warning()) {
        eprintln!("forgemon: warning: {w}");
    }
    let n_fit = result.blows.iter().filter(|b| !b.held_out).count();
    let provenance = format!(
        "{} ({} {} fitted{})",
        args.reference.display(),
        n_fit,
        if args.bare { "bare strikes" } else { "billet blows" },
        match (result.blows.iter().any(|b| b.in_doubt), result.blows.iter().any(|b| b.held_out && !b.in_doubt)) {
            (true, true) => ", others held out, some for a start height in doubt",
            (true, false) => ", others held out for a start height in doubt",
            (false, true) => ", others held out",
            (false, false) => "",
        }
    );
    // The filter the model was identified through goes on with it.
    let text = result.to_toml(&provenance) + &load_filter.to_toml();
    std::fs::write(&args.out, text).with_context(|| format!("{}: cannot write", args.out.display()))?;
    let report_path = args.report.clone().unwrap_or_else(|| args.out.with_extension("html"));
    let report = result.report(&provenance, started.elapsed().as_secs_f64());
    crate::identify::report::write_identify_report(&report, &report_path)
        .with_context(|| format!("{}: cannot write the report", report_path.display()))?;

    print_summary(&result, started.elapsed().as_secs_f64());
    eprintln!("forgemon: wrote {} and {}", args.out.display(), report_path.display());
    Ok(ExitCode::SUCCESS)
}

/// The prior machine (`--initial`, else the paper's of `kind`) with its ram mass from
/// `--ram-kg` when given, and the DAQ filter its file declares.
fn prior_of(args: &IdentifyArgs, kind: MachineKind) -> anyhow::Result<(crate::physics::machine::Machine, LoadFilter)> {
    let (mut prior, load_filter) = match &args.initial {
        Some(p) => {
            let file = parse_machine(&p.display().to_string(), &read_text(p)?)?;
            let m = file.machine;
            if m.kind() != kind {
                bail!("{}: key 'kind' is \"{}\" but --kind is {}", p.display(), m.kind().as_str(), kind.as_str());
            }
            (m, file.load_filter)
        }
        None => (default_prior(kind), LoadFilter::None),
    };
    if let Some(kg) = args.ram_kg {
        if !(kg.is_finite() && kg > 0.0) {
            bail!("--ram-kg: {kg} is not a mass (a positive number of kg)");
        }
        let key = prior.ram_key();
        crate::identify::model::set(&mut prior, key, kg);
    }
    Ok((prior, load_filter))
}

/// Bare strikes, or the billet of the process sheet (`--process`, else DIR/process.toml).
fn setting_of(args: &IdentifyArgs, kind: MachineKind) -> anyhow::Result<Setting> {
    if args.bare {
        return Ok(Setting::Bare);
    }
    let path = args.process.clone().unwrap_or_else(|| args.reference.join("process.toml"));
    if !path.exists() {
        bail!(
            "{}: no process sheet: a billet reference needs one (--process, or process.toml in the capture directory); use --bare for bare strikes",
            path.display()
        );
    }
    let p = parse_process_warn(&path.display().to_string(), &read_text(&path)?)?;
    if p.machine != kind {
        bail!("{}: key 'machine' is \"{}\" but --kind is {}", path.display(), p.machine.as_str(), kind.as_str());
    }
    Ok(Setting::Billet(p))
}

/// The fitted parameters, each blow's error and the verdict on the fit, on stdout.
fn print_summary(result: &crate::identify::Identified, elapsed_s: f64) {
    println!("{:<24} {:>14} {:>10}  determined", "parameter", "value", "± 1σ");
    if result.signal != Signal::Load {
        let key = result.machine.ram_key();
        println!("{key:<24} {:>14.6e} {:>10}  {}", result.machine.ram_kg(), "held", crate::identify::ANCHOR_NOTE);
    }
    for (i, p) in result.set.params.iter().enumerate() {
        let u = &result.uncertainty;
        println!(
            "{:<24} {:>14.6e} {:>9.3}%  {}",
            p.key,
            result.values[i],
            u.rel_se[i] * 100.0,
            match (u.determined[i], u.notes[i].is_empty()) {
                (true, true) => "yes".to_string(),
                (true, false) => format!("yes ({})", u.notes[i]),
                (false, _) => format!("NO: {}", u.notes[i]),
            }
        );
    }
    for b in &result.blows {
        println!(
            "{:<28} v0 {:.3} m/s  RMS load error {:.2} % of peak{}{}",
            b.reference.label,
            b.reference.v0_mps,
            b.rms_error * 100.0,
            b.over_noise.map_or(String::new(), |r| format!(", {r:.2}× the noise")),
            match (b.held_out, b.in_doubt) {
                (true, true) => "  (left out, start height in doubt: predicted)",
                (true, false) => "  (held out: predicted)",
                _ => "",
            }
        );
    }
    println!(
        "objective (eq. 4) {:.4}; {} of {} starts reached the best fit; {:.1} s",
        result.objective,
        result.runs_agreeing,
        result.runs.len(),
        elapsed_s
    );
    println!("{}", result.fit_check.verdict());
}

/// Local searches by default on the load.
pub const LOAD_STARTS: usize = 8;
/// ... and on the ram's force (no load channel): its cost has more basins, the lower tool's
/// mass and spring seen only through the billet. On `tests/identify_without_load.rs`'s
/// hammer (910 kg, 26 kg, 2.6e9 N/m, 24 000 N s/m; three blows) 8 and 32 starts ended at
/// 15 kg with the blows 4 times their noise off; 128 found 25.7 kg at 2.1 times (7 s).
pub const RAM_FORCE_STARTS: usize = 128;

/// What `blow` can be compared by: its load, or without a load channel and with the ram's
/// mass known (`ram_anchor`, `identify` only), the ram's force from its accelerometer.
fn blow_signal(blow: &Blow, ram_anchor: Option<Option<f64>>, label: &str) -> anyhow::Result<Signal> {
    let channels = blow.channels();
    if channels.has(Role::Load) {
        return Ok(Signal::Load);
    }
    match ram_anchor {
        None => bail!("{label}: no load channel (load_N): this command compares the load"),
        Some(_) if !channels.has(Role::Acc) => {
            bail!(
                "{label}: neither a load channel (load_N) nor an accelerometer (acc_mps2): nothing to fit the model to"
            )
        }
        Some(None) => bail!(
            "{label}: no load channel (load_N): identifying from the accelerometer and the encoder needs the ram's \
             mass from the machine's data sheet, which anchors the others: --ram-kg KG, or --initial M.toml (its \
             ram mass is held)"
        ),
        Some(Some(m_ram_kg)) => Ok(Signal::RamForce { m_ram_kg }),
    }
}

/// The reference blows of a capture directory, split into fitted and held out.
pub(crate) fn read_references(
    dir: &Path,
    kind: MachineKind,
    bare: bool,
    fit_blows: &[usize],
    locate: Option<&crate::physics::machine::Machine>,
) -> anyhow::Result<(Vec<Reference>, Vec<Reference>)> {
    let (fit, held) = read_references_with_speed_sd(dir, kind, bare, fit_blows, locate)?;
    Ok((fit.into_iter().map(|r| r.0).collect(), held.into_iter().map(|r| r.0).collect()))
}

/// `read_references`, each with its impact speed's standard error, m/s
/// (`identify::speed::impact_speed_sd_mps`; 0 where it cannot be had).
fn read_references_with_speed_sd(
    dir: &Path,
    kind: MachineKind,
    bare: bool,
    fit_blows: &[usize],
    locate: Option<&crate::physics::machine::Machine>,
) -> anyhow::Result<(Vec<WithSpeedSd>, Vec<WithSpeedSd>)> {
    let (fit, held, _) = read_references_of(dir, kind, bare, fit_blows, locate, None)?;
    Ok((fit, held))
}

/// `read_references_with_speed_sd` for `identify`, and the signal they compare: the load, or
/// where the captures have no load channel, the ram's force with the mass `ram_kg.0` (the
/// data sheet's; without it such captures are refused, naming the option). `ram_kg.1`, the
/// prior's ram mass, finds the contacts of such blows (`Segmenter::set_ram_kg`).
fn read_references_by_signal(
    dir: &Path,
    kind: MachineKind,
    bare: bool,
    fit_blows: &[usize],
    ram_kg: (Option<f64>, f64),
) -> anyhow::Result<(Vec<WithSpeedSd>, Vec<WithSpeedSd>, Signal)> {
    read_references_of(dir, kind, bare, fit_blows, None, Some(ram_kg))
}

/// The references of `dir` (`read_references_with_speed_sd`). `ram_anchor`: `None` takes
/// the load alone; `Some((mass, segmenting))` also takes captures without a load channel,
/// by the ram's force when its `mass` is known (every capture of the directory alike).
fn read_references_of(
    dir: &Path,
    kind: MachineKind,
    bare: bool,
    fit_blows: &[usize],
    locate: Option<&crate::physics::machine::Machine>,
    ram_anchor: Option<(Option<f64>, f64)>,
) -> anyhow::Result<(Vec<WithSpeedSd>, Vec<WithSpeedSd>, Signal)> {
    let mut signal: Option<Signal> = None;
    let files = super::capture_dir_files(dir)?;
    let fit_s = crate::estimate::EstimatorConfig::for_kind(kind).fit_s;
    let (mut fit, mut held) = (Vec::new(), Vec::new());
    let mut number = 0usize;
    for path in &files {
        let mut seg = Segmenter::new(SegmentConfig::for_kind(kind));
        if let Some((anchor, prior_kg)) = ram_anchor {
            seg.set_ram_kg(anchor.unwrap_or(prior_kg));
        }
        let mut blows = Vec::new();
        super::for_each_capture_batch(path, |batch| {
            seg.push(&batch, &mut blows);
            Ok(())
        })?;
        seg.finish(&mut blows);
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        for (k, blow) in blows.iter().enumerate() {
            number += 1;
            let label = if blows.len() > 1 { format!("{name} #{}", k + 1) } else { name.clone() };
            let index = (!bare).then_some(number);
            let this = blow_signal(blow, ram_anchor.map(|(anchor, _)| anchor), &label)?;
            if signal.is_some_and(|s| s != this) {
                bail!(
                    "{label}: its channels differ from the blows before (with and without a load channel): a reference \
                     directory is one machine with one set of sensors"
                );
            }
            signal = Some(this);
            let r = match locate {
                Some(m) => crate::diagnose::localise::reference(&label, blow, index, fit_s, m)?,
                None => Reference::of_signal(&label, blow, index, fit_s, this)?,
            };
            let r = (r, impact_speed_sd_mps(blow, fit_s).unwrap_or(0.0));
            if fit_blows.is_empty() || fit_blows.contains(&number) {
                fit.push(r);
            } else {
                held.push(r);
            }
        }
    }
    if number == 0 {
        bail!(
            "{}: no blow found in {} capture file(s); is it a {} capture (the trigger is the ram's deceleration, \
             the contact a load above the noise)?",
            dir.display(),
            files.len(),
            kind.as_str()
        );
    }
    if fit.is_empty() {
        bail!("--fit-blows {:?}: the directory holds blows 1 to {number}", fit_blows);
    }
    Ok((fit, held, signal.unwrap_or(Signal::Load)))
}
