//! `forgemon diagnose` (docs/interfaces.md §6): where the model and the measured blows part,
//! which library effect closes the gap on held-out blows, and a verdict; `report.json`
//! and `report.html` in the output directory.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;

use super::{parse_process_warn, read_text};
use crate::config::parse_machine;
use crate::diagnose::{Diagnosis, diagnose, fit_count};
use crate::identify::objective::Setting;
use crate::physics::effects::EffectSet;
use crate::physics::machine::Machine;
use crate::report::{BarPlot, Color, LinePlot, Page, Series, bar_plot_svg, line_plot_svg};

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// The identified machine model.
    #[arg(long, value_name = "M.toml")]
    pub machine: PathBuf,
    /// Capture directory of the calibration billet (effect parameters are fitted here).
    #[arg(long, value_name = "DIR")]
    pub calib: PathBuf,
    /// Capture directory of another billet, used only to measure.
    #[arg(long, value_name = "DIR")]
    pub holdout: PathBuf,
    /// Where report.json, report.html and machine.toml (the machine with the verdict's
    /// effect adopted) go.
    #[arg(long, value_name = "OUTDIR")]
    pub out: PathBuf,
    /// Also write the machine with the verdict's effect over the --machine file (the old one
    /// kept as M.toml.bak): the one-step form for a user who trusts the verdict.
    #[arg(long)]
    pub adopt: bool,
}

pub fn run(args: DiagnoseArgs) -> anyhow::Result<ExitCode> {
    let started = Instant::now();
    let machine_text = read_text(&args.machine)?;
    let file = parse_machine(&args.machine.display().to_string(), &machine_text)?;
    let machine = file.machine;
    let effects = file.effect_set();
    let calib = read_dir(&args.calib, &machine)?;
    let holdout = read_dir(&args.holdout, &machine)?;
    let bar = indicatif::ProgressBar::new(fit_count(machine.kind()) as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("diagnose {bar:40} {pos}/{len} effects and pairs fitted {elapsed}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    // Ties among the single effects add pairs beyond `fit_count`: the bar grows with them.
    let step = || {
        if bar.length().is_some_and(|len| bar.position() >= len) {
            bar.inc_length(1);
        }
        bar.inc(1);
    };
    let d =
        diagnose(&machine, &effects, calib, holdout, &step).context("the base model cannot simulate these blows")?;
    bar.finish_and_clear();
    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create", args.out.display()))?;
    let json = d.to_json();
    let path = args.out.join("report.json");
    std::fs::write(&path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("{}: cannot write", path.display()))?;
    let html = args.out.join("report.html");
    write_html(&d, &machine, &html, started.elapsed().as_secs_f64())?;
    println!(
        "baseline nrmse: calib {:.4}, holdout {:.4}; dominant phase {}",
        d.baseline_calib,
        d.baseline_holdout,
        d.by_phase.dominant()
    );
    for c in &d.candidates {
        println!(
            "{:<36} calib {:.4}  holdout {:.4}  shrink {:+.2}",
            c.name,
            c.calib,
            c.holdout,
            1.0 - c.holdout / d.baseline_holdout
        );
    }
    println!(
        "verdict: {} ({:.1} s)",
        json["verdict"]["effect"].as_str().unwrap_or("none"),
        started.elapsed().as_secs_f64()
    );
    println!("{}", crate::diagnose::words::opening(&d));
    eprintln!("forgemon: wrote {} and {}", path.display(), html.display());
    write_adopted(&args, &machine_text, &machine, &effects, &d)?;
    Ok(ExitCode::SUCCESS)
}

/// `OUTDIR/machine.toml`: the machine file with the verdict's effect adopted
/// (`diagnose::adopt`); with `--adopt`, over the machine file too, the old one kept beside it.
fn write_adopted(
    args: &DiagnoseArgs,
    machine_text: &str,
    machine: &Machine,
    effects: &EffectSet,
    d: &Diagnosis,
) -> anyhow::Result<()> {
    use crate::diagnose::adopt::{Provenance, machine_toml, rel_sd};
    let Some(v) = &d.verdict else {
        eprintln!("forgemon: the verdict is none: no machine.toml written, nothing to adopt");
        return Ok(());
    };
    let sd = rel_sd(machine, effects, &v.effects, &d.calib).unwrap_or_default();
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |t| t.as_secs());
    let date = chrono::DateTime::from_timestamp(now as i64, 0).map_or_else(String::new, |t| t.to_rfc3339());
    let provenance = Provenance {
        verdict: v.name.clone(),
        calib: args.calib.display().to_string(),
        holdout: args.holdout.display().to_string(),
        date,
        holdout_shrink: 1.0 - v.holdout / d.baseline_holdout,
    };
    let text = machine_toml(machine_text, &v.effects, &provenance, &sd)
        .with_context(|| format!("{}: cannot be rewritten", args.machine.display()))?;
    let out = args.out.join("machine.toml");
    std::fs::write(&out, &text).with_context(|| format!("{}: cannot write", out.display()))?;
    eprintln!("forgemon: wrote {}: the machine with {} adopted", out.display(), v.name);
    if args.adopt {
        let mut backup = args.machine.clone().into_os_string();
        backup.push(".bak");
        std::fs::copy(&args.machine, &backup)
            .with_context(|| format!("{}: cannot keep a copy", args.machine.display()))?;
        std::fs::write(&args.machine, &text).with_context(|| format!("{}: cannot write", args.machine.display()))?;
        eprintln!(
            "forgemon: adopted {} into {} (the old file is {})",
            v.name,
            args.machine.display(),
            std::path::Path::new(&backup).display()
        );
    }
    Ok(())
}

/// A capture directory's blows and its process sheet.
fn read_dir(dir: &Path, machine: &Machine) -> anyhow::Result<(Vec<crate::identify::objective::Reference>, Setting)> {
    let sheet = dir.join("process.toml");
    if !sheet.exists() {
        bail!(
            "{}: no process.toml: the diagnosis simulates each blow on its billet and needs the process sheet",
            dir.display()
        );
    }
    let p = parse_process_warn(&sheet.display().to_string(), &read_text(&sheet)?)?;
    if p.machine != machine.kind() {
        bail!(
            "{}: key 'machine' is \"{}\" but the machine is a {}",
            sheet.display(),
            p.machine.as_str(),
            machine.kind().as_str()
        );
    }
    let (refs, _) = super::identify::read_references(dir, machine.kind(), false, &[], Some(machine))?;
    Ok((refs, Setting::Billet(p)))
}

/// The HTML report: a conclusion in words, then where, what and which blows, each plot
/// with a caption.
fn write_html(d: &Diagnosis, machine: &Machine, path: &Path, elapsed_s: f64) -> anyhow::Result<()> {
    let mut page = Page::new("forgemon diagnose: the sim-to-real gap");
    page.section("Conclusion");
    page.paragraph(crate::diagnose::words::opening(d));
    page.paragraph(conclusion(d, elapsed_s));
    page.paragraph(rule(d));
    page.section("Where the gap lies (calibration blows, base model)");
    where_figures(&mut page, d, machine)?;
    indicator_figures(&mut page, d)?;
    page.section("Ranking (mean nrmse; parameters fitted on calibration, scored on holdout)");
    ranking_table(&mut page, d);
    page.section("Holdout blows: measured, base model, and the model with the verdict");
    holdout_figures(&mut page, d, machine)?;
    page.write(path).with_context(|| format!("{}: cannot write the report", path.display()))?;
    Ok(())
}

fn verdict_name(d: &Diagnosis) -> String {
    d.verdict.as_ref().map_or("none".to_string(), |v| v.name.clone())
}

/// The conclusion in words: how far off, where, the verdict and why.
fn conclusion(d: &Diagnosis, elapsed_s: f64) -> String {
    let shrink = d.verdict.as_ref().map_or(0.0, |v| 1.0 - v.holdout / d.baseline_holdout);
    let share = d.location.share();
    let share_of = |p: &str| match p {
        "impact" => share.impact,
        "forming" => share.forming,
        "spring_back" => share.spring_back,
        _ => share.post,
    };
    format!(
        "The base model misses the measured load by {:.1} % of the peak on the holdout blows (nrmse); compared phase \
         with phase, {:.0} % of the error lies in the {} phase (the largest error density is in the {} phase){}. \
         Verdict: {}{}. {} (Computed in {elapsed_s:.1} s.)",
        d.baseline_holdout * 100.0,
        share_of(d.location.phase()) * 100.0,
        d.location.phase(),
        d.by_phase.dominant(),
        crate::diagnose::indicators::dominant(&d.indicator_summary).map_or(String::new(), |s| format!(
            "; of the blow's indicators, its {} departs most ({:+.0} %, model against measurement)",
            s.name.replace('_', " "),
            s.mean_rel_error * 100.0
        )),
        verdict_name(d),
        if d.verdict.is_some() {
            format!(", which shrinks the holdout error by {:.0} %", shrink * 100.0)
        } else {
            String::new()
        },
        d.why
    )
}

/// The verdict's rule, with the equivalent effects of this case.
fn rule(d: &Diagnosis) -> String {
    let equivalent = if d.equivalent.is_empty() {
        String::new()
    } else {
        let each: Vec<String> =
            d.equivalent.iter().map(|(n, why)| why.as_ref().map_or(n.clone(), |w| format!("{n}: {w}"))).collect();
        format!(" (equivalent here: {})", each.join("; "))
    };
    format!(
        "The rule: a gap exists only when the baseline holdout error exceeds {}× the sensor noise ({:.4} of the peak); an effect \
         is real when its holdout errors are significantly lower than the base model's, blow by blow ({}, \
         5 % each), and the holdout error shrinks by at least {:.0} %; effects the same test cannot tell apart \
         are equivalent and the one with the fewest fitted parameters wins{equivalent}; a pair replaces its single effect only when it \
         removes at least {:.0} % of what that effect leaves, by the same test. Effect parameters are fitted on the calibration \
         billet only.",
        crate::diagnose::NOISE_FACTOR,
        d.noise_nrmse,
        crate::diagnose::evidence::TESTS,
        crate::diagnose::MIN_SHRINK * 100.0,
        crate::diagnose::MIN_PAIR_SHRINK * 100.0
    )
}

/// The error by phase (phase with phase, and by density) and by band.
fn where_figures(page: &mut Page, d: &Diagnosis, machine: &Machine) -> anyhow::Result<()> {
    let groups = || vec!["impact".into(), "forming".into(), "spring_back".into(), "post".into()];
    let share = d.location.share();
    let location = BarPlot {
        title: "share of the error, phase with phase".into(),
        y_label: "share".into(),
        groups: groups(),
        bars: vec![("base model".into(), vec![share.impact, share.forming, share.spring_back, share.post])],
    };
    page.figure(
        bar_plot_svg(&location, 800, 320)?,
        "Each phase of the measured and the modelled blow laid on its own time, start to end, and compared there; a \
         phase's error in length (the impact's: its first contact) counts to it. Read: which phase carries the error, \
         wherever on the clock the model's phase falls.",
    );
    let phases = BarPlot {
        title: "nrmse by phase".into(),
        y_label: "RMS error / peak".into(),
        groups: groups(),
        bars: vec![(
            "base model".into(),
            vec![d.by_phase.impact, d.by_phase.forming, d.by_phase.spring_back, d.by_phase.post],
        )],
    };
    page.figure(
        bar_plot_svg(&phases, 800, 320)?,
        "The RMS load error within each phase of the blow, each blow's phases on its own instants; where model and \
         measurement are out of step, the error counts to the phase whose length put them out of step, and so does \
         the part of a spring-back's (or post's) error that the model's late (or early) start explains, when that \
         start is further off than the phase's own length.",
    );
    let bands = BarPlot {
        title: "nrmse by band".into(),
        y_label: "RMS error / peak".into(),
        groups: vec!["low".into(), "mode2".into(), "high".into()],
        bars: vec![("base model".into(), vec![d.by_band.low, d.by_band.mode2, d.by_band.high])],
    };
    page.figure(
        bar_plot_svg(&bands, 800, 320)?,
        format!("The error's energy by band around the second mode ({:.0} Hz).", machine.second_mode_hz()),
    );
    Ok(())
}

/// The indicators' errors, and their measured and modelled means.
fn indicator_figures(page: &mut Page, d: &Diagnosis) -> anyhow::Result<()> {
    let present: Vec<_> = d.indicator_summary.iter().filter(|s| s.mean_rel_error.is_finite()).collect();
    let indicators = BarPlot {
        title: "indicators: model against measurement".into(),
        y_label: "relative error".into(),
        groups: present.iter().map(|s| s.name.to_string()).collect(),
        bars: vec![("base model".into(), present.iter().map(|s| s.mean_rel_error).collect())],
    };
    page.figure(
        bar_plot_svg(&indicators, 800, 320)?,
        "(model − measured) / measured over the calibration blows. The phases' lengths come from each blow's own \
         instants (the measured end of forming is the billet's largest compression, as the model run on the measured \
         signals sees it).",
    );
    page.table(
        vec!["indicator (mean over blows)".into(), "measured".into(), "base model".into(), "blows".into()],
        indicator_rows(d),
    );
    Ok(())
}

/// One row per indicator: its measured and modelled means over the blows that have it.
fn indicator_rows(d: &Diagnosis) -> Vec<Vec<String>> {
    use crate::diagnose::indicators::{Indicators, Pair};
    let mean_of = |f: fn(&Indicators) -> Option<Pair>| {
        let v: Vec<_> = d.indicators.iter().filter_map(f).collect();
        let k = v.len().max(1) as f64;
        (v.iter().map(|p| p.measured).sum::<f64>() / k, v.iter().map(|p| p.model).sum::<f64>() / k, v.len())
    };
    [
        ("peak load, kN", 1e-3, mean_of(|i| Some(i.peak_load_n))),
        ("final load, kN", 1e-3, mean_of(|i| Some(i.final_load_n))),
        ("forming time, ms", 1e3, mean_of(|i| Some(i.forming_time_s))),
        ("spring-back time, ms", 1e3, mean_of(|i| Some(i.spring_back_time_s))),
        ("final height, mm", 1e3, mean_of(|i| i.final_height_m)),
        ("second-mode frequency, Hz", 1.0, mean_of(|i| i.mode2_frequency_hz)),
        ("second-mode damping ratio", 1.0, mean_of(|i| i.mode2_damping_ratio)),
    ]
    .iter()
    .map(|(name, scale, (m, s, n))| {
        if *n == 0 {
            return vec![name.to_string(), "–".into(), "–".into(), "0".into()];
        }
        let f = |x: f64| crate::report::format_number(x * scale, 4);
        vec![name.to_string(), f(*m), f(*s), n.to_string()]
    })
    .collect()
}

/// Every candidate with its fitted parameters, best holdout first.
fn ranking_table(page: &mut Page, d: &Diagnosis) {
    let rows = d
        .candidates
        .iter()
        .map(|c| {
            let params: Vec<String> = c
                .effects
                .iter()
                .flat_map(|e| e.params())
                .map(|(k, v)| format!("{k} = {}", crate::report::format_number(v, 3)))
                .collect();
            vec![
                c.name.clone(),
                params.join(", "),
                format!("{:.4}", c.calib),
                format!("{:.4}", c.holdout),
                format!("{:+.2}", 1.0 - c.holdout / d.baseline_holdout),
            ]
        })
        .collect();
    page.table(
        vec!["effect".into(), "fitted parameters".into(), "calib".into(), "holdout".into(), "holdout shrink".into()],
        rows,
    );
}

/// Each holdout blow: measured, base model and with the verdict, and the residual's
/// spectrum.
fn holdout_figures(page: &mut Page, d: &Diagnosis, machine: &Machine) -> anyhow::Result<()> {
    let base = d.holdout.obj.simulate(machine);
    let with = d.verdict.as_ref().and_then(|v| {
        let mut set = d.holdout.obj.effects;
        for e in &v.effects {
            set.apply(e);
        }
        d.holdout.obj.with_effects(set).simulate(machine)
    });
    for k in 0..d.holdout.obj.refs.len() {
        let b = base.as_ref().map(|b| &b[k].load_n[..]);
        holdout_blow(page, d, k, b, with.as_ref().map(|w| &w[k].load_n[..]))?;
        if let Some(b) = b {
            residual_spectrum(page, &d.holdout.obj.refs[k], b, machine)?;
        }
    }
    Ok(())
}

/// Holdout blow `k`: measured, the base model's `base` and the verdict's `with`.
fn holdout_blow(
    page: &mut Page,
    d: &Diagnosis,
    k: usize,
    base: Option<&[f64]>,
    with: Option<&[f64]>,
) -> anyhow::Result<()> {
    let verdict = verdict_name(d);
    let r = &d.holdout.obj.refs[k];
    let t: Vec<f64> = (0..r.load_n.len()).map(|i| (i as f64 * r.dt_s - r.t_align_s) * 1e3).collect();
    let kn = |x: &[f64]| x.iter().map(|x| x * 1e-3).collect::<Vec<_>>();
    let mut plot = LinePlot::new(format!("{} (holdout)", r.label), "time (ms)", "load (kN)");
    plot.series.push(Series::new("measured", t.clone(), kn(&r.load_n), Color::Black));
    if let Some(b) = base {
        plot.series.push(Series::new("base model", t.clone(), kn(b), Color::Vermillion).dashed());
    }
    if let Some(w) = with {
        plot.series.push(Series::new(format!("with {verdict}"), t.clone(), kn(w), Color::Blue));
    }
    let mut caption = format!("nrmse: base {:.4}", d.baseline_holdout_per_blow[k]);
    if let Some(after) = d.verdict.as_ref().and_then(|v| v.holdout_per_blow.get(k)) {
        caption += &format!(", with {verdict} {after:.4}");
    }
    page.figure(line_plot_svg(&plot, 900, 360)?, caption);
    Ok(())
}

/// The spectrum of the measured load less the base model's, up to 4× the second mode.
fn residual_spectrum(
    page: &mut Page,
    r: &crate::identify::objective::Reference,
    base: &[f64],
    machine: &Machine,
) -> anyhow::Result<()> {
    let resid: Vec<f64> = r.load_n.iter().zip(base).map(|(m, s)| m - s).collect();
    let spec = crate::signal::spectrum::amplitude_spectrum(&resid, r.dt_s, 4, 0);
    let f_max = 4.0 * machine.second_mode_hz();
    let n = (1..spec.len()).take_while(|&i| spec.frequency_hz(i) <= f_max).count();
    let mut sp = LinePlot::new("Residual spectrum (measured − base model)", "frequency (Hz)", "amplitude (N)");
    sp.log_y = true;
    sp.series.push(Series::new(
        "residual",
        (1..=n).map(|i| spec.frequency_hz(i)).collect(),
        spec.amplitude[1..=n].to_vec(),
        Color::Purple,
    ));
    sp.markers_x.push((machine.second_mode_hz(), "mode 2".into()));
    page.figure(line_plot_svg(&sp, 900, 300)?, "Where in frequency the base model misses.");
    Ok(())
}
