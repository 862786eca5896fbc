//! `forgemon replay` (CONTRACTS.md §5): a recording, a capture CSV or a capture directory
//! through exactly the live pipeline; one JSON line per blow; `--out` records the replay.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Args;

use super::{parse_process_warn, read_text};
use crate::config::parse_machine;
use crate::config::service::parse_tuning;
use crate::daemon::{CONTROL_SOURCE, NEW_BILLET_STATE, SERVICE_CONFIG_NAME, tuned_config};
use crate::physics::process::Process;
use crate::pipeline::{Feeder, Pipeline, PipelineEvent};
use crate::record::{BlowBoundary, Payload, RecordReader, RecordWriter, Rotation};
use crate::signal::merge::Merger;
use crate::signal::sample::SampleBatch;

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// A recording (.mcap), a capture CSV, or a capture directory (blow_01.csv, ...).
    pub input: PathBuf,
    /// The machine model (machine.toml).
    #[arg(long)]
    pub machine: PathBuf,
    /// The process sheet; defaults to the capture directory's process.toml, or the one
    /// stored in the recording.
    #[arg(long)]
    pub process: Option<PathBuf>,
    /// The service configuration whose alert rules (`[alerts]`) and billet detection
    /// (`[billets]`) to use; defaults to the one stored in the recording, else the defaults.
    #[arg(long)]
    pub service: Option<PathBuf>,
    /// Record the replay (samples, blows, results, alerts, billets, configuration) to this
    /// MCAP file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// One JSON object per blow (CONTRACTS.md §5) instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// A source of sample batches, whatever the input.
enum Input {
    Files(Vec<PathBuf>),
    /// A recording, streamed in file order (the writer stores each source's samples in
    /// time order), with the samples read ahead while looking for the stored process sheet.
    Recording {
        reader: Box<RecordReader>,
        ahead: Vec<SampleBatch>,
    },
}

/// The configuration files a recording stores before its first samples.
#[derive(Default)]
struct Stored {
    process: Option<String>,
    service: Option<String>,
}

pub fn run(args: ReplayArgs) -> anyhow::Result<ExitCode> {
    let machine_text = read_text(&args.machine)?;
    let machine = parse_machine(&args.machine.display().to_string(), &machine_text)?.machine;
    let (input, stored) = open_input(&args.input)?;
    let process_text = match (&args.process, &input) {
        (Some(p), _) => Some((p.display().to_string(), read_text(p)?)),
        (None, Input::Files(_)) if args.input.is_dir() => {
            let p = args.input.join("process.toml");
            p.exists().then(|| read_text(&p).map(|t| (p.display().to_string(), t))).transpose()?
        }
        _ => stored.process.map(|t| (format!("{} (process.toml stored in it)", args.input.display()), t)),
    };
    let process: Option<Process> = match &process_text {
        Some((origin, text)) => {
            let p = parse_process_warn(origin, text)?;
            if p.machine != machine.kind() {
                bail!(
                    "{origin}: key 'machine' is \"{}\" but {} has kind \"{}\"",
                    p.machine.as_str(),
                    args.machine.display(),
                    machine.kind().as_str()
                );
            }
            Some(p)
        }
        None => None,
    };
    // The alert rules and billet detection the live run used, unless the caller gives others.
    let service_text = match &args.service {
        Some(p) => Some((p.display().to_string(), read_text(p)?)),
        None => stored.service.map(|t| (format!("{} (service.toml stored in it)", args.input.display()), t)),
    };
    let tuning = match &service_text {
        Some((origin, text)) => parse_tuning(origin, text)?,
        None => parse_tuning("defaults", "")?,
    };
    let mut writer = match &args.out {
        Some(path) => {
            let mut w = RecordWriter::create(path, Rotation::default())
                .with_context(|| format!("{}: cannot record", path.display()))?;
            w.write_config(0, "machine.toml", &machine_text)?;
            if let Some((_, text)) = &process_text {
                w.write_config(0, "process.toml", text)?;
            }
            if let Some((_, text)) = &service_text {
                w.write_config(0, SERVICE_CONFIG_NAME, text)?;
            }
            Some(w)
        }
        None => None,
    };
    let mut feeder = Feeder::new(Pipeline::new(machine, process, tuned_config(&tuning, &machine)));
    let mut input_merge = (Merger::default(), Vec::new());
    let stdout = std::io::stdout();
    let mut w = std::io::BufWriter::new(stdout.lock());
    if !args.json {
        writeln!(
            w,
            "blow  t_contact s     v m/s  kinetic J  plastic J  elastic J  efficiency  class         final kN  h_end mm  alert"
        )?;
    }
    let mut events = Vec::new();
    let mut status = ExitCode::SUCCESS;
    let (mut blows, mut rejected) = (0u64, 0u64);
    let mut handle =
        |events: &mut Vec<PipelineEvent>, writer: &mut Option<RecordWriter>, w: &mut dyn Write| -> anyhow::Result<()> {
            for ev in events.drain(..) {
                match ev {
                    PipelineEvent::Blow { cut, estimate } => {
                        blows += 1;
                        if let Some(rec) = writer.as_mut() {
                            let t_ns = (cut.t_end_s * 1e9).round() as i64;
                            let boundary = BlowBoundary::of(estimate.blow, &cut);
                            rec.write_payload(t_ns, &Payload::Boundary(boundary))?;
                            rec.write_result(t_ns, &estimate)?;
                            if let Some(a) = &estimate.alert {
                                rec.write_alert(t_ns, a)?;
                            }
                        }
                        if args.json {
                            writeln!(w, "{}", serde_json::to_string(&estimate)?)?;
                        } else {
                            writeln!(
                                w,
                                "{:>4}  {:>12.4}  {:>6.3}  {:>9}  {:>9}  {:>9}  {:>10}  {:<12}  {:>8.0}  {:>8}  {}",
                                estimate.blow,
                                estimate.t_contact_s,
                                estimate.v_impact_mps,
                                or_dash(estimate.kinetic_in_j, 0),
                                or_dash(estimate.plastic_j, 0),
                                or_dash(estimate.elastic_j, 0),
                                or_dash(estimate.efficiency, 3),
                                estimate.class.as_str(),
                                estimate.final_load_n / 1e3,
                                estimate.h_end_m.map_or("-".to_string(), |h| format!("{:.2}", h * 1e3)),
                                estimate.alert.as_ref().map_or(String::new(), |a| a.reason.clone()),
                            )?;
                        }
                    }
                    PipelineEvent::Billet(b) => {
                        if let Some(rec) = writer.as_mut() {
                            rec.write_billet((b.t_end_s * 1e9).round() as i64, &b)?;
                        }
                        if !args.json {
                            writeln!(w, "{b}")?;
                        }
                    }
                    PipelineEvent::Rejected { cut, error } => {
                        rejected += 1;
                        eprintln!("forgemon: blow at t = {:.6} s not estimated: {error}", cut.t_contact_s);
                    }
                }
            }
            Ok(())
        };
    match input {
        Input::Files(files) => {
            for path in files {
                super::for_each_capture_batch(&path, |batch| {
                    feed_batch(&batch, &mut input_merge, &mut feeder, &mut writer, &mut events)?;
                    handle(&mut events, &mut writer, &mut w)
                })?;
            }
        }
        Input::Recording { mut reader, ahead } => {
            let mut last_log_ns = 0;
            for batch in &ahead {
                last_log_ns = batch.host_time_ns;
                feed_batch(batch, &mut input_merge, &mut feeder, &mut writer, &mut events)?;
                handle(&mut events, &mut writer, &mut w)?;
            }
            for m in reader.by_ref() {
                match m?.payload {
                    Payload::Samples(batch) => {
                        last_log_ns = batch.host_time_ns;
                        feed_batch(&batch, &mut input_merge, &mut feeder, &mut writer, &mut events)?;
                        handle(&mut events, &mut writer, &mut w)?;
                    }
                    // A new billet went into the dies here during the live run.
                    Payload::Status(st) if st.source == CONTROL_SOURCE && st.state == NEW_BILLET_STATE => {
                        feeder.pipeline_mut().new_billet(&mut events);
                        handle(&mut events, &mut writer, &mut w)?;
                        if let Some(rec) = writer.as_mut() {
                            rec.write_status(last_log_ns, &st)?;
                        }
                    }
                    // The live run reloaded its alert rules here (SIGHUP); a rotated file
                    // repeats the same text, which changes nothing.
                    Payload::Config(c) if c.name == SERVICE_CONFIG_NAME && args.service.is_none() => {
                        let origin = format!("{} (service.toml stored in it)", args.input.display());
                        feeder.pipeline_mut().set_alert_config(parse_tuning(&origin, &c.text)?.alerts);
                    }
                    _ => {}
                }
            }
            if !reader.report().complete {
                eprintln!("forgemon: {}", reader.report());
            }
            status = super::inspect::input_status(reader.report());
        }
    }
    feeder.pipeline_mut().end_of_stream(&mut events);
    feeder.pipeline_mut().close_billet(&mut events);
    handle(&mut events, &mut writer, &mut w)?;
    w.flush()?;
    if let Some(rec) = writer {
        let files = rec.finish()?;
        for f in files {
            eprintln!("forgemon: recorded {}", f.display());
        }
    }
    let s = feeder.pipeline_mut().segment_stats();
    eprintln!(
        "forgemon: replayed {} samples: {blows} blows, {rejected} not estimated, {} triggers without contact, {} batches dropped",
        feeder.samples(),
        s.triggers_without_contact,
        s.batches_dropped
    );
    Ok(status)
}

/// Record a batch (with `--out`) and feed it to the pipeline, through the same merge of
/// several sources' roles as the live service (`signal::merge`).
fn feed_batch(
    batch: &SampleBatch,
    input: &mut (Merger, Vec<SampleBatch>),
    feeder: &mut Feeder,
    writer: &mut Option<RecordWriter>,
    events: &mut Vec<PipelineEvent>,
) -> anyhow::Result<()> {
    if let Some(rec) = writer.as_mut() {
        rec.write_samples(batch)?;
    }
    let (merger, merged) = input;
    if merger.push(batch, merged) {
        feeder.push(batch, events);
    }
    for b in merged.drain(..) {
        feeder.push(&b, events);
    }
    Ok(())
}

/// Classify the input and, for a recording, read its samples and stored configuration.
fn open_input(path: &Path) -> anyhow::Result<(Input, Stored)> {
    if path.is_dir() {
        return Ok((Input::Files(super::capture_dir_files(path)?), Stored::default()));
    }
    let name = path.to_string_lossy();
    if name.ends_with(".mcap") || name.ends_with(".mcap.part") {
        let mut reader = RecordReader::open(path)?;
        let mut stored = Stored::default();
        let mut ahead = Vec::new();
        // Configuration is written before the samples; read up to the first batch of them.
        for m in reader.by_ref() {
            match m?.payload {
                Payload::Samples(b) => {
                    ahead.push(b);
                    break;
                }
                Payload::Config(c) if c.name == "process.toml" => stored.process = Some(c.text),
                Payload::Config(c) if c.name == SERVICE_CONFIG_NAME => stored.service = Some(c.text),
                _ => {}
            }
        }
        return Ok((Input::Recording { reader: Box::new(reader), ahead }, stored));
    }
    if !path.exists() {
        bail!("{}: no such file or directory", path.display());
    }
    Ok((Input::Files(vec![path.to_path_buf()]), Stored::default()))
}

/// A figure of the table, or `-` where the blow has none (an incomplete blow).
fn or_dash(v: Option<f64>, decimals: usize) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.decimals$}"))
}
