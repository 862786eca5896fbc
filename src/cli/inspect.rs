//! `forgemon inspect FILE.mcap|DIR`: what a recording holds, in forging terms: sources with
//! their rates and durations, blows, results by class, billets with their statistics (blows,
//! mean and spread of efficiency and plastic energy, the first hard blow), alerts, gaps and
//! drops, the stored configuration, and whether the file was finished or had to be recovered. Corrupt chunks
//! are named on stderr and the exit status is 3 ([`input_status`], shared with `replay`). A
//! directory's recordings are inspected one after the other, in name order; a file that
//! cannot be read (empty, not MCAP) is named and skipped, and the status is 3.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::Args;
use serde_json::json;

use crate::estimate::billet_book::BilletSummary;
use crate::estimate::{BlowClass, BlowEstimate};
use crate::record::{Payload, ReadReport, RecordReader};

/// Exit status when the input recording was corrupt and the results cover only part of it
/// (README, "Recorded blows").
pub const EXIT_CORRUPT_INPUT: u8 = 3;

/// Print what was wrong with a recording on stderr, one line per corrupt chunk (file, byte
/// offset, why, topics lost), and give the exit status it calls for: 3 when part of the
/// file was corrupt and skipped, else success.
pub(crate) fn input_status(report: &ReadReport) -> ExitCode {
    for problem in report.problems() {
        eprintln!("forgemon: {problem}");
    }
    if report.is_corrupt() { ExitCode::from(EXIT_CORRUPT_INPUT) } else { ExitCode::SUCCESS }
}

#[derive(Debug, Args)]
pub struct InspectArgs {
    /// The recording (.mcap or .mcap.part), or a directory of them.
    pub file: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One billet's blows as the recorded results give them (`billet_stats` in the JSON).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BilletStats {
    pub billet: u32,
    pub blows: u32,
    /// Blows with energies (not `incomplete`): the ones the means and spreads cover.
    pub complete_blows: u32,
    pub efficiency_mean: Option<f64>,
    /// Sample standard deviation (n − 1); `None` below two complete blows.
    pub efficiency_sd: Option<f64>,
    #[serde(rename = "plastic_J_mean")]
    pub plastic_j_mean: Option<f64>,
    #[serde(rename = "plastic_J_sd")]
    pub plastic_j_sd: Option<f64>,
    /// The blow on the billet (`billet_blow`) that was its first hard one: the blows it
    /// took to get there; `None` when none was hard.
    pub first_hard_blow: Option<u32>,
}

/// Mean and sample standard deviation of `xs`; the deviation needs two values.
fn mean_sd(xs: &[f64]) -> (Option<f64>, Option<f64>) {
    if xs.is_empty() {
        return (None, None);
    }
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let sd = (xs.len() >= 2).then(|| (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt());
    (Some(mean), sd)
}

/// Per-billet statistics of `results` (in recorded order), by billet number.
pub fn billet_stats(results: &[BlowEstimate]) -> Vec<BilletStats> {
    let mut by_billet: BTreeMap<u32, Vec<&BlowEstimate>> = BTreeMap::new();
    for r in results {
        by_billet.entry(r.billet.billet).or_default().push(r);
    }
    by_billet
        .into_iter()
        .map(|(billet, blows)| {
            let complete: Vec<&&BlowEstimate> = blows.iter().filter(|r| r.has_energies()).collect();
            let (efficiency_mean, efficiency_sd) =
                mean_sd(&complete.iter().filter_map(|r| r.efficiency).collect::<Vec<_>>());
            let (plastic_j_mean, plastic_j_sd) =
                mean_sd(&complete.iter().filter_map(|r| r.plastic_j).collect::<Vec<_>>());
            BilletStats {
                billet,
                blows: blows.len() as u32,
                complete_blows: complete.len() as u32,
                efficiency_mean,
                efficiency_sd,
                plastic_j_mean,
                plastic_j_sd,
                first_hard_blow: blows.iter().find(|r| r.class == BlowClass::Hard).map(|r| r.billet.billet_blow),
            }
        })
        .collect()
}

/// One line for a person: `statistics: 8 blows, efficiency 0.705 ± 0.196, ...`.
impl std::fmt::Display for BilletStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let pm = |mean: Option<f64>, sd: Option<f64>, digits: usize| match (mean, sd) {
            (Some(m), Some(s)) => format!("{m:.digits$} ± {s:.digits$}"),
            (Some(m), None) => format!("{m:.digits$}"),
            _ => "-".to_string(),
        };
        let plural = if self.blows == 1 { "" } else { "s" };
        write!(f, "statistics of billet {}: {} blow{plural}", self.billet, self.blows)?;
        if self.complete_blows < self.blows {
            write!(f, " ({} complete)", self.complete_blows)?;
        }
        write!(
            f,
            ", efficiency {} and plastic {} J (mean ± sd), ",
            pm(self.efficiency_mean, self.efficiency_sd, 3),
            pm(self.plastic_j_mean, self.plastic_j_sd, 0)
        )?;
        match self.first_hard_blow {
            Some(n) => write!(f, "first hard blow at blow {n}"),
            None => write!(f, "no hard blow"),
        }
    }
}

#[derive(Default)]
struct SourceSummary {
    /// The capture files it gathers (`capture/<file>` sources, `cli::for_each_capture_batch`).
    captures: std::collections::BTreeSet<String>,
    batches: u64,
    samples: u64,
    period_ns: f64,
    first_ns: Option<i64>,
    end_ns: f64,
    channels: String,
}

/// The recordings an input names: itself, or a directory's `*.mcap` and `*.mcap.part`
/// files in name order.
pub fn recordings(input: &Path) -> anyhow::Result<Vec<PathBuf>> {
    if !input.is_dir() {
        return Ok(vec![input.to_path_buf()]);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(input)
        .with_context(|| format!("{}: cannot list", input.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter(|p| p.to_str().is_some_and(|s| s.ends_with(".mcap") || s.ends_with(".mcap.part")))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("{}: a directory with no recordings (*.mcap, *.mcap.part)", input.display());
    }
    Ok(files)
}

pub fn run(args: InspectArgs) -> anyhow::Result<ExitCode> {
    let files = recordings(&args.file)?;
    if !args.file.is_dir() {
        return inspect(&args.file, args.json);
    }
    let mut status = ExitCode::SUCCESS;
    for file in &files {
        match inspect(file, args.json) {
            Ok(s) if s == ExitCode::SUCCESS => {}
            Ok(s) => status = s,
            Err(e) if super::out::closed() => return Err(e),
            Err(e) => {
                eprintln!("forgemon: skipped {}: {}", file.display(), super::error_message(&e));
                status = ExitCode::from(EXIT_CORRUPT_INPUT);
            }
        }
    }
    Ok(status)
}

/// One recording, as text or one JSON line.
fn inspect(file: &Path, json: bool) -> anyhow::Result<ExitCode> {
    let mut reader = RecordReader::open(file)?;
    let mut tally = Tally::default();
    for m in reader.by_ref() {
        tally.add(m?.payload);
    }
    let report = reader.report().clone();
    let out = tally.json(&file.display().to_string(), &report);
    // Through `out`: a closed stdout (`| head`) ends the verb quietly (`main`).
    let mut w = super::out::stdout();
    if json {
        writeln!(w, "{out}")?;
    } else {
        writeln!(w, "{}", file.display())?;
        print_report(&mut w, &report)?;
        tally.print(&mut w, &out)?;
    }
    w.flush()?;
    Ok(input_status(&report))
}

/// What a recording holds, counted message by message.
#[derive(Default)]
struct Tally {
    sources: BTreeMap<String, SourceSummary>,
    boundaries: u64,
    gaps: u64,
    samples_lost: u64,
    classes: BTreeMap<String, u64>,
    alerts: BTreeMap<String, u64>,
    drops: BTreeMap<String, u64>,
    configs: Vec<String>,
    efficiency: Vec<f64>,
    billets: Vec<BilletSummary>,
    results: Vec<BlowEstimate>,
}

impl Tally {
    fn add(&mut self, payload: Payload) {
        match payload {
            Payload::Samples(b) => {
                // A capture directory's files, each a source of its own, are one machine.
                let (name, file) = match b.source.split_once('/') {
                    Some((group, file)) if group == super::CAPTURE_SOURCE => (group.to_string(), Some(file)),
                    _ => (b.source.clone(), None),
                };
                let s = self.sources.entry(name).or_default();
                s.captures.extend(file.map(str::to_string));
                s.batches += 1;
                s.samples += b.len() as u64;
                s.period_ns = b.period_ns;
                s.first_ns = Some(s.first_ns.map_or(b.device_time_ns, |f| f.min(b.device_time_ns)));
                s.end_ns = s.end_ns.max(b.device_time_ns as f64 + b.period_ns * b.len() as f64);
                s.channels = b.roles.iter().map(|r| r.column()).collect::<Vec<_>>().join(",");
            }
            Payload::Boundary(_) => self.boundaries += 1,
            Payload::Result(r) => {
                *self.classes.entry(r.class.as_str().to_string()).or_default() += 1;
                self.efficiency.extend(r.efficiency);
                self.results.push(*r);
            }
            Payload::Alert(a) => *self.alerts.entry(a.kind.as_str().to_string()).or_default() += 1,
            Payload::Gap(g) => {
                self.gaps += 1;
                self.samples_lost += g.samples_lost;
            }
            Payload::Status(s) => {
                self.drops.insert(s.source.clone(), s.drops);
            }
            Payload::Config(c) => self.configs.push(c.name),
            Payload::Billet(b) => self.billets.push(*b),
        }
    }

    /// `inspect --json`'s object.
    fn json(&self, file: &str, report: &ReadReport) -> serde_json::Value {
        let src_json: Vec<_> = self
            .sources
            .iter()
            .map(|(name, s)| {
                let duration_s = s.first_ns.map_or(0.0, |f| (s.end_ns - f as f64) * 1e-9);
                json!({"source": name, "channels": s.channels, "rate_hz": 1e9 / s.period_ns, "samples": s.samples,
                       "batches": s.batches, "duration_s": duration_s, "captures": s.captures.len()})
            })
            .collect();
        let efficiency = &self.efficiency;
        json!({
            "file": file,
            "complete": report.complete,
            "recovered_messages": report.messages,
            "bytes_recovered": report.bytes_recovered,
            "total_bytes": report.total_bytes,
            "chunks_verified": report.chunks_verified,
            "chunks_unverified": report.chunks_unverified,
            "corrupt_chunks": report.corrupt_chunks.iter().map(|c| json!({
                "offset": c.offset, "length": c.length, "topics": c.topics, "error": c.error.to_string(),
            })).collect::<Vec<_>>(),
            "unknown_channel_messages": report.unknown_channel_messages,
            "summary_error": report.summary_error,
            "sources": src_json,
            "blows": self.boundaries,
            "results_by_class": self.classes,
            "mean_efficiency": if efficiency.is_empty() { None } else { Some(efficiency.iter().sum::<f64>() / efficiency.len() as f64) },
            "billets": self.billets.len(),
            "billets_finished": self.billets.iter().filter(|b| b.finished).count(),
            "billet_summaries": self.billets,
            "billet_stats": billet_stats(&self.results),
            "alerts": self.alerts,
            "gaps": self.gaps,
            "samples_lost": self.samples_lost,
            "drops_by_source": self.drops,
            "config_files": self.configs,
        })
    }

    /// The terminal summary of what the recording holds (`out`: `json`'s object).
    fn print(&self, w: &mut impl Write, out: &serde_json::Value) -> std::io::Result<()> {
        for s in out["sources"].as_array().into_iter().flatten() {
            let captures = match s["captures"].as_u64() {
                Some(n @ 1..) => format!(" ({n} captures)"),
                _ => String::new(),
            };
            writeln!(
                w,
                "  source {:<12} {} at {:.0} Hz: {} samples, {:.3} s{captures}",
                s["source"].as_str().unwrap_or(""),
                s["channels"].as_str().unwrap_or(""),
                s["rate_hz"].as_f64().unwrap_or(0.0),
                s["samples"],
                s["duration_s"].as_f64().unwrap_or(0.0)
            )?;
        }
        writeln!(w, "  blows: {}; results by class: {}", self.boundaries, counts(&self.classes, "none"))?;
        if let Some(e) = out["mean_efficiency"].as_f64() {
            writeln!(w, "  mean efficiency: {e:.3}")?;
        }
        let finished = self.billets.iter().filter(|b| b.finished).count();
        writeln!(w, "  billets: {} ({finished} finished)", self.billets.len())?;
        // Each billet's summary, then its statistics; statistics of billets no summary names
        // (a recording from before the summaries) after them.
        let stats = billet_stats(&self.results);
        for b in &self.billets {
            writeln!(w, "    {b}")?;
            for s in stats.iter().filter(|s| s.billet == b.billet) {
                writeln!(w, "      {s}")?;
            }
        }
        for s in stats.iter().filter(|s| !self.billets.iter().any(|b| b.billet == s.billet)) {
            writeln!(w, "    {s}")?;
        }
        writeln!(w, "  alerts: {}", counts(&self.alerts, "none"))?;
        writeln!(
            w,
            "  gaps: {} ({} samples lost); drops: {}",
            self.gaps,
            self.samples_lost,
            counts(&self.drops, "none reported")
        )?;
        let configs = if self.configs.is_empty() { "none".to_string() } else { self.configs.join(", ") };
        writeln!(w, "  configuration stored: {configs}")
    }
}

/// `name count, ...`, or `none` when there are none.
fn counts(map: &BTreeMap<String, u64>, none: &str) -> String {
    if map.is_empty() {
        none.to_string()
    } else {
        map.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
    }
}

/// Whether the file was read whole, and what was lost if not.
fn print_report(w: &mut impl Write, report: &ReadReport) -> std::io::Result<()> {
    if report.complete {
        writeln!(w, "  finished properly, {} messages", report.messages)?;
    } else {
        writeln!(
            w,
            "  CUT OFF: recovered {} messages from {} of {} bytes{}",
            report.messages,
            report.bytes_recovered,
            report.total_bytes,
            report.stopped_by.as_ref().map_or(String::new(), |s| format!(" ({s})"))
        )?;
    }
    if !report.corrupt_chunks.is_empty() {
        writeln!(w, "  CORRUPT: {} chunks skipped (named on stderr)", report.corrupt_chunks.len())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blow(billet: u32, billet_blow: u32, class: BlowClass, efficiency: f64, plastic_j: f64) -> BlowEstimate {
        let complete = class != BlowClass::Incomplete;
        BlowEstimate {
            judgement: None,
            blow: billet * 10 + billet_blow,
            t_contact_s: 0.0,
            v_impact_mps: 5.0,
            kinetic_in_j: complete.then_some(plastic_j / efficiency),
            plastic_j: complete.then_some(plastic_j),
            friction_j: None,
            damped_j: None,
            elastic_j: None,
            efficiency: complete.then_some(efficiency),
            final_load_n: 0.0,
            h_end_m: None,
            class,
            alert: None,
            t_end_s: 0.0,
            peak_load_n: 0.0,
            residual: None,
            sensor_check: None,
            method: None,
            gap_s: 0.0,
            h_start_m: None,
            height_source: crate::estimate::HeightSource::Unknown,
            implausible: None,
            flow_stress_scale: None,
            model_residual: None,
            model_residual_by_phase: None,
            scale_by_half: None,
            at_bound: Default::default(),
            height_check: None,
            billet: crate::estimate::BilletTag { billet, billet_blow, ..Default::default() },
            channels: Default::default(),
            efficiency_sd: None,
            unobserved: Default::default(),
            excluded: Default::default(),
            acc_check: None,
        }
    }

    #[test]
    fn billet_statistics_cover_the_complete_blows_and_find_the_first_hard_one() {
        use BlowClass::*;
        let results = [
            blow(1, 1, Soft, 0.9, 5000.0),
            blow(1, 2, Incomplete, 0.0, 0.0),
            blow(1, 3, Intermediate, 0.6, 7000.0),
            blow(1, 4, Hard, 0.3, 3000.0),
            blow(1, 5, Hard, 0.3, 3000.0),
            blow(2, 1, Soft, 0.85, 6000.0),
        ];
        let s = billet_stats(&results);
        assert_eq!(s.len(), 2);
        assert_eq!((s[0].billet, s[0].blows, s[0].complete_blows, s[0].first_hard_blow), (1, 5, 4, Some(4)));
        // By hand: efficiencies 0.9, 0.6, 0.3, 0.3: mean 0.525; squared deviations
        // 0.140625 + 0.005625 + 0.050625 + 0.050625 = 0.2475, over 3: sd 0.28723.
        assert!((s[0].efficiency_mean.unwrap_or(0.0) - 0.525).abs() < 1e-12);
        assert!((s[0].efficiency_sd.unwrap_or(0.0) - (0.2475f64 / 3.0).sqrt()).abs() < 1e-12);
        // Plastic 5000, 7000, 3000, 3000 J: mean 4500; squared deviations
        // 0.25e6 + 6.25e6 + 2.25e6 + 2.25e6 = 11e6, over 3.
        assert!((s[0].plastic_j_mean.unwrap_or(0.0) - 4500.0).abs() < 1e-9);
        assert!((s[0].plastic_j_sd.unwrap_or(0.0) - (11e6f64 / 3.0).sqrt()).abs() < 1e-9);
        // One blow: a mean, no spread; no hard blow.
        assert_eq!((s[1].efficiency_mean, s[1].efficiency_sd, s[1].first_hard_blow), (Some(0.85), None, None));
        assert_eq!(
            s[1].to_string(),
            "statistics of billet 2: 1 blow, efficiency 0.850 and plastic 6000 J (mean ± sd), no hard blow"
        );
        assert!(s[0].to_string().contains("5 blows (4 complete), efficiency 0.525 ± 0.287"), "{}", s[0]);
    }
}
