//! `forgemon advise` (docs/interfaces.md §9, issue 20): the blows still needed from the billet's
//! present height to a target, and how hard each should be, planned with the identified
//! machine model (`advise`).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::Args;

use super::{parse_process_warn, read_text};
use crate::advise::{Advisor, PlanRequest, Speeds};
use crate::config::limits::{IMPACT_SPEED_MPS, MEASURED_HEIGHT_M};
use crate::config::parse_machine;

#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("speeds").required(true).multiple(false))]
pub struct AdviseArgs {
    /// The machine model (machine.toml), with its effects if it has any.
    #[arg(long)]
    pub machine: PathBuf,
    /// The billet's process sheet (process.toml): its law, friction and original height.
    #[arg(long)]
    pub process: PathBuf,
    /// The billet's height now, m (0.112 for 112 mm).
    #[arg(long, value_name = "H")]
    pub h_now: f64,
    /// The height to reach, m (within ±0.5 mm; 0.04 for 40 mm).
    #[arg(long, value_name = "T")]
    pub target: f64,
    /// The machine's impact speeds, m/s, comma separated (a hammer's drop heights); or
    /// give `--v-max` instead.
    #[arg(long, value_name = "V,...", value_delimiter = ',', num_args = 1.., group = "speeds")]
    pub settings: Vec<f64>,
    /// Any impact speed up to this, m/s (a screw press's energy setting); or give
    /// `--settings` instead. Either supplies the speeds the plan may choose from.
    #[arg(long, value_name = "V", group = "speeds")]
    pub v_max: Option<f64>,
    /// Blows the billet already took (the machine's `thermal` effect counts them).
    #[arg(long, default_value_t = 0)]
    pub blows_done: usize,
    /// Print one JSON object (docs/interfaces.md §9) instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: AdviseArgs) -> anyhow::Result<ExitCode> {
    let h_now_m = super::length_m("--h-now", args.h_now, MEASURED_HEIGHT_M)?;
    let target_m = super::length_m("--target", args.target, MEASURED_HEIGHT_M)?;
    let machine = parse_machine(&args.machine.display().to_string(), &read_text(&args.machine)?)?;
    let process = parse_process_warn(&args.process.display().to_string(), &read_text(&args.process)?)?;
    if process.machine != machine.machine.kind() {
        bail!(
            "{}: key 'machine' is \"{}\" but {} has kind \"{}\"",
            args.process.display(),
            process.machine.as_str(),
            args.machine.display(),
            machine.machine.kind().as_str()
        );
    }
    let speeds = match args.v_max {
        Some(v) => Speeds::UpTo(v),
        None => Speeds::Settings(args.settings.clone()),
    };
    let all = match &speeds {
        Speeds::UpTo(v) => vec![*v],
        Speeds::Settings(v) => v.clone(),
    };
    if let Some((bad, why)) = all.iter().find_map(|v| IMPACT_SPEED_MPS.check(*v).err().map(|w| (v, w))) {
        let flag = if args.v_max.is_some() { "--v-max" } else { "--settings" };
        bail!("{flag}: impact speed {bad} m/s {why}");
    }
    let effects = machine.effect_set();
    let advisor = Advisor::new(&machine.machine, &effects, &process);
    let req = PlanRequest { h_now_m, target_m, blows_done: args.blows_done, speeds };
    let plan = advisor.plan(&req)?;
    // Through `out`: a closed stdout (`| head`) ends the verb quietly (`main`).
    let mut w = super::out::stdout();
    if args.json {
        writeln!(w, "{}", serde_json::to_string(&plan)?)?;
    } else {
        writeln!(w, "from {:.2} mm to {:.2} mm (±0.5 mm):", plan.h_now_m * 1e3, plan.target_m * 1e3)?;
        if !plan.plan.is_empty() {
            writeln!(w, "blow  impact m/s  kinetic J  height after mm  efficiency  class")?;
        }
        for b in &plan.plan {
            writeln!(
                w,
                "{:>4}  {:>10.2}  {:>9.0}  {:>15.2}  {:>10.3}  {}",
                b.blow,
                b.v0_mps,
                b.kinetic_j,
                b.h_end_m * 1e3,
                b.efficiency,
                b.class
            )?;
        }
        match (&plan.blows_to_target, &plan.why) {
            (Some(n), None) => writeln!(w, "{n} blows to the target, none hard")?,
            (Some(n), Some(why)) => writeln!(w, "{n} blows to the target: {why}")?,
            (None, Some(why)) => writeln!(w, "not reachable: {why}")?,
            (None, None) => writeln!(w, "not reachable")?,
        }
    }
    Ok(if plan.reachable { ExitCode::SUCCESS } else { ExitCode::from(3) })
}
