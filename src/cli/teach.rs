//! `forgemon teach` (docs/interfaces.md §9, issue 20): learn a part's recipe from good billets, given
//! as capture directories or recordings. Each runs through the very pipeline `replay` runs
//! (`replay::replay_into`), which keeps every complete blow's signature; the blows are
//! grouped by billet and each blow index learnt (`recipe::teach`). Its windows are cut to
//! their physical ranges and the file is checked as the service checks a recipe before it
//! is written, so every taught recipe is one the service takes.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;

use super::replay::{ReplayArgs, replay_into};
use crate::recipe::{Signature, Tolerances, teach};

#[derive(Debug, Args)]
pub struct TeachArgs {
    /// The machine model (machine.toml).
    #[arg(long)]
    pub machine: PathBuf,
    /// The process sheet; defaults to each reference's own (capture directory or recording).
    #[arg(long)]
    pub process: Option<PathBuf>,
    /// Good billets: capture directories or recordings (a recording may hold several).
    #[arg(long = "reference", value_name = "DIR_OR_MCAP", num_args = 1.., required = true)]
    pub references: Vec<PathBuf>,
    /// Where to write the recipe.
    #[arg(short = 'o', long = "out", value_name = "PART.recipe.toml")]
    pub out: PathBuf,
    /// The part's name (default: the output file's name without `.recipe.toml`).
    #[arg(long)]
    pub name: Option<String>,
    /// Windows are mean ± max(k·sd, tolerance).
    #[arg(long, default_value_t = Tolerances::default().k)]
    pub k: f64,
    /// Efficiency tolerance, absolute.
    #[arg(long, default_value_t = Tolerances::default().efficiency)]
    pub tol_efficiency: f64,
    /// Plastic energy tolerance, a share of the learnt mean.
    #[arg(long, default_value_t = Tolerances::default().plastic_fraction)]
    pub tol_plastic: f64,
    /// Peak load tolerance, a share of the learnt mean.
    #[arg(long, default_value_t = Tolerances::default().peak_load_fraction)]
    pub tol_peak_load: f64,
    /// The envelope's load tolerance, a share of the learnt peak load.
    #[arg(long, default_value_t = Tolerances::default().load_fraction)]
    pub tol_load: f64,
    /// The envelope's widening along the compression, mm.
    #[arg(long, default_value_t = Tolerances::default().compression_m * 1e3)]
    pub tol_compression_mm: f64,
}

pub fn run(args: TeachArgs) -> anyhow::Result<ExitCode> {
    let tol = Tolerances {
        k: args.k,
        efficiency: args.tol_efficiency,
        plastic_fraction: args.tol_plastic,
        peak_load_fraction: args.tol_peak_load,
        load_fraction: args.tol_load,
        compression_m: args.tol_compression_mm / 1e3,
    };
    for (flag, x) in [
        ("--k", tol.k),
        ("--tol-efficiency", tol.efficiency),
        ("--tol-plastic", tol.plastic_fraction),
        ("--tol-peak-load", tol.peak_load_fraction),
        ("--tol-load", tol.load_fraction),
        ("--tol-compression-mm", tol.compression_m),
    ] {
        if !(x.is_finite() && x >= 0.0) {
            anyhow::bail!("{flag} must be a finite number >= 0, got {x}");
        }
    }
    let machine = crate::config::parse_machine(&args.machine.display().to_string(), &super::read_text(&args.machine)?)?;
    let mut billets: Vec<Vec<Signature>> = Vec::new();
    for input in &args.references {
        let replay = ReplayArgs {
            input: input.clone(),
            machine: Some(args.machine.clone()),
            process: args.process.clone(),
            service: None,
            out: None,
            json: true,
            recipe: None,
            encoder_direction: None,
            sequential: false,
        };
        let (_, mut feeder) = replay_into(&replay, std::io::sink(), |p| p.keep_signatures())
            .with_context(|| format!("--reference {}", input.display()))?;
        let mut sigs = feeder.pipeline_mut().take_signatures();
        sigs.sort_by_key(|(billet, blow, _)| (*billet, *blow));
        let before = billets.len();
        let mut current = None;
        for (billet, _, sig) in sigs {
            if current != Some(billet) {
                current = Some(billet);
                billets.push(Vec::new());
            }
            if let Some(b) = billets.last_mut() {
                b.push(sig);
            }
        }
        eprintln!("forgemon: {}: {} billets", input.display(), billets.len() - before);
    }
    let name = args.name.clone().unwrap_or_else(|| {
        let file = args.out.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        file.trim_end_matches(".toml").trim_end_matches(".recipe").to_string()
    });
    crate::config::recipe::check_name(&name)
        .map_err(|why| anyhow::anyhow!("--name (or the output file's name) {why}"))?;
    let taught_from = args.references.iter().map(|p| p.display().to_string()).collect();
    let mut recipe = teach(&name, machine.machine.kind().as_str(), &billets, tol, taught_from)?;
    crate::config::recipe::within_limits(&mut recipe);
    let text = crate::config::recipe::write_recipe(&recipe)?;
    // What teach writes passes the check every recipe gets (the service's, `POST /recipe`).
    crate::config::recipe::parse_recipe(&args.out.display().to_string(), &text)
        .context("the taught recipe fails the recipe check")?;
    std::fs::write(&args.out, text).with_context(|| format!("{}: cannot write", args.out.display()))?;
    println!(
        "recipe '{}' for {} blows from {} billets written to {}",
        recipe.name,
        recipe.blows.len(),
        recipe.billets,
        args.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
