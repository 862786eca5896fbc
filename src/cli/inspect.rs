//! `forgemon inspect FILE.mcap`: what a recording holds, in forging terms: sources with
//! their rates and durations, blows, results by class, billets, alerts, gaps and drops, the stored
//! configuration, and whether the file was finished or had to be recovered. Corrupt chunks
//! are named on stderr and the exit status is 3 ([`input_status`], shared with `replay`).

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use serde_json::json;

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
    /// The recording (.mcap or .mcap.part).
    pub file: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Default)]
struct SourceSummary {
    batches: u64,
    samples: u64,
    period_ns: f64,
    first_ns: Option<i64>,
    end_ns: f64,
    channels: String,
}

pub fn run(args: InspectArgs) -> anyhow::Result<ExitCode> {
    let mut reader = RecordReader::open(&args.file)?;
    let mut sources: BTreeMap<String, SourceSummary> = BTreeMap::new();
    let (mut boundaries, mut gaps, mut samples_lost) = (0u64, 0u64, 0u64);
    let mut classes: BTreeMap<String, u64> = BTreeMap::new();
    let mut alerts: BTreeMap<String, u64> = BTreeMap::new();
    let mut drops: BTreeMap<String, u64> = BTreeMap::new();
    let mut configs = Vec::new();
    let mut efficiency = Vec::new();
    let mut billets = Vec::new();
    for m in reader.by_ref() {
        match m?.payload {
            Payload::Samples(b) => {
                let s = sources.entry(b.source.clone()).or_default();
                s.batches += 1;
                s.samples += b.len() as u64;
                s.period_ns = b.period_ns;
                s.first_ns = Some(s.first_ns.map_or(b.device_time_ns, |f| f.min(b.device_time_ns)));
                s.end_ns = s.end_ns.max(b.device_time_ns as f64 + b.period_ns * b.len() as f64);
                s.channels = b.roles.iter().map(|r| r.column()).collect::<Vec<_>>().join(",");
            }
            Payload::Boundary(_) => boundaries += 1,
            Payload::Result(r) => {
                *classes.entry(r.class.as_str().to_string()).or_default() += 1;
                efficiency.extend(r.efficiency);
            }
            Payload::Alert(a) => *alerts.entry(a.kind.as_str().to_string()).or_default() += 1,
            Payload::Gap(g) => {
                gaps += 1;
                samples_lost += g.samples_lost;
            }
            Payload::Status(s) => {
                drops.insert(s.source.clone(), s.drops);
            }
            Payload::Config(c) => configs.push(c.name),
            Payload::Billet(b) => billets.push(*b),
        }
    }
    let report = reader.report().clone();
    let src_json: Vec<_> = sources
        .iter()
        .map(|(name, s)| {
            let duration_s = s.first_ns.map_or(0.0, |f| (s.end_ns - f as f64) * 1e-9);
            json!({"source": name, "channels": s.channels, "rate_hz": 1e9 / s.period_ns, "samples": s.samples,
                   "batches": s.batches, "duration_s": duration_s})
        })
        .collect();
    let out = json!({
        "file": args.file.display().to_string(),
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
        "blows": boundaries,
        "results_by_class": classes,
        "mean_efficiency": if efficiency.is_empty() { None } else { Some(efficiency.iter().sum::<f64>() / efficiency.len() as f64) },
        "billets": billets.len(),
        "billets_finished": billets.iter().filter(|b| b.finished).count(),
        "billet_summaries": billets,
        "alerts": alerts,
        "gaps": gaps,
        "samples_lost": samples_lost,
        "drops_by_source": drops,
        "config_files": configs,
    });
    let stdout = std::io::stdout();
    let mut w = stdout.lock();
    if args.json {
        writeln!(w, "{out}")?;
        return Ok(input_status(&report));
    }
    writeln!(w, "{}", args.file.display())?;
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
    for s in out["sources"].as_array().into_iter().flatten() {
        writeln!(
            w,
            "  source {:<12} {} at {:.0} Hz: {} samples, {:.3} s",
            s["source"].as_str().unwrap_or(""),
            s["channels"].as_str().unwrap_or(""),
            s["rate_hz"].as_f64().unwrap_or(0.0),
            s["samples"],
            s["duration_s"].as_f64().unwrap_or(0.0)
        )?;
    }
    writeln!(
        w,
        "  blows: {boundaries}; results by class: {}",
        if classes.is_empty() {
            "none".to_string()
        } else {
            classes.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
        }
    )?;
    if let Some(e) = out["mean_efficiency"].as_f64() {
        writeln!(w, "  mean efficiency: {e:.3}")?;
    }
    let finished = billets.iter().filter(|b| b.finished).count();
    writeln!(w, "  billets: {} ({finished} finished)", billets.len())?;
    for b in &billets {
        writeln!(w, "    {b}")?;
    }
    writeln!(
        w,
        "  alerts: {}",
        if alerts.is_empty() {
            "none".to_string()
        } else {
            alerts.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
        }
    )?;
    writeln!(
        w,
        "  gaps: {gaps} ({samples_lost} samples lost); drops: {}",
        if drops.is_empty() {
            "none reported".to_string()
        } else {
            drops.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
        }
    )?;
    writeln!(
        w,
        "  configuration stored: {}",
        if configs.is_empty() { "none".to_string() } else { configs.join(", ") }
    )?;
    w.flush()?;
    Ok(input_status(&report))
}
