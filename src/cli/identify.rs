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
use crate::identify::objective::{Reference, Setting};
use crate::identify::speed::impact_speed_sd_mps;
use crate::identify::{IdentifyConfig, WithSpeedSd, identify};
use crate::physics::load_filter::LoadFilter;
use crate::physics::machine::MachineKind;
use crate::signal::segment::{SegmentConfig, Segmenter};

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
    /// Blow numbers to fit, e.g. 1 or 1,3 (default: all); the others are predicted and
    /// reported as held out.
    #[arg(long, value_delimiter = ',')]
    pub fit_blows: Vec<usize>,
    /// Local searches (the prior plus random starts).
    #[arg(long, default_value_t = 8)]
    pub starts: usize,
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
    let (prior, load_filter) = match &args.initial {
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
    let setting = if args.bare {
        Setting::Bare
    } else {
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
        Setting::Billet(p)
    };
    let (fit, held) = read_references_with_speed_sd(&args.reference, kind, args.bare, &args.fit_blows, None)?;
    let cfg =
        IdentifyConfig { starts: args.starts.max(1), seed: args.seed, monte_carlo: args.monte_carlo, load_filter };
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

/// The fitted parameters, each blow's error and the verdict on the fit, on stdout.
fn print_summary(result: &crate::identify::Identified, elapsed_s: f64) {
    println!("{:<24} {:>14} {:>10}  determined", "parameter", "value", "± 1σ");
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
    let files = super::capture_dir_files(dir)?;
    let fit_s = crate::estimate::EstimatorConfig::for_kind(kind).fit_s;
    let (mut fit, mut held) = (Vec::new(), Vec::new());
    let mut number = 0usize;
    for path in &files {
        let mut seg = Segmenter::new(SegmentConfig::for_kind(kind));
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
            let r = match locate {
                Some(m) => crate::diagnose::localise::reference(&label, blow, index, fit_s, m)?,
                None => Reference::from_blow(&label, blow, index, fit_s)?,
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
    Ok((fit, held))
}
