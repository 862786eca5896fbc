//! `forgemon export RECORDING_OR_DIR... (--csv OUT.csv | --parquet OUT.parquet)`: the blow
//! results of recordings as one table for the quality department (issue 19 §4), one row per
//! blow across files and billets: every docs/interfaces.md §5 field, the billet and the blow on
//! it, the file and the wall-clock time the result was recorded at (the MCAP log time),
//! and what it was forged as (part id, lot, die set: the recording's `part.toml`).
//!
//! The rows are the results the recordings hold, read with the project's reader
//! (`record::RecordReader`), not estimated again. A directory stands for the recordings in
//! it (`*.mcap`, `*.mcap.part`, by name: the service's rotated files in order). A file that
//! is not a recording fails the whole export, naming it, and nothing is written; a
//! recording with corrupt chunks is exported with what it holds, its chunks named on stderr
//! and the exit status 3, as `replay` and `inspect` do.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Context, bail};
use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray, TimestampNanosecondArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema, TimeUnit};
use clap::Args;
use serde::Serialize;

use super::inspect::{EXIT_CORRUPT_INPUT, input_status};
use crate::config::history::{Trace, parse_trace_text};
use crate::estimate::BlowEstimate;
use crate::record::{Payload, RecordReader};
use crate::session::PART_CONFIG_NAME;

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Recordings (.mcap, .mcap.part), or directories of them.
    #[arg(required = true, value_name = "RECORDING_OR_DIR")]
    pub inputs: Vec<PathBuf>,
    /// Write CSV (a header row, then one row per blow; an empty field where a value is
    /// `null`); `-` writes it to standard output.
    #[arg(long, value_name = "OUT.csv", required_unless_present = "parquet", conflicts_with = "parquet")]
    pub csv: Option<PathBuf>,
    /// Write Parquet (snappy-compressed; nullable columns where a value can be `null`); `-`
    /// writes it to standard output, when that is not a terminal.
    #[arg(long, value_name = "OUT.parquet")]
    pub parquet: Option<PathBuf>,
}

/// One blow as a row. The field names are the columns, docs/interfaces.md §5's names and units
/// first; `alert` is the alert's kind, `alert_reason` its words.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportRow {
    pub file: String,
    /// When the result was recorded, UTC, RFC 3339 with nanoseconds (Parquet: a UTC
    /// timestamp in ns).
    pub wall_time: String,
    #[serde(skip)]
    pub wall_time_ns: i64,
    pub billet: u32,
    pub billet_blow: u32,
    pub blow: u32,
    pub t_contact_s: f64,
    pub v_impact_mps: f64,
    #[serde(rename = "kinetic_in_J")]
    pub kinetic_in_j: Option<f64>,
    #[serde(rename = "plastic_J")]
    pub plastic_j: Option<f64>,
    #[serde(rename = "friction_J")]
    pub friction_j: Option<f64>,
    #[serde(rename = "damped_J")]
    pub damped_j: Option<f64>,
    #[serde(rename = "elastic_J")]
    pub elastic_j: Option<f64>,
    pub efficiency: Option<f64>,
    #[serde(rename = "final_load_N")]
    pub final_load_n: f64,
    pub h_end_m: Option<f64>,
    pub class: &'static str,
    pub gap_s: f64,
    pub sensor_check: Option<f64>,
    /// `OK`/`NOK` under a recipe; empty (null) without one, which is every recording until
    /// recipes exist (issue 20).
    pub judgement: Option<String>,
    pub alert: Option<&'static str>,
    pub alert_reason: Option<String>,
    #[serde(rename = "peak_load_N")]
    pub peak_load_n: f64,
    pub t_end_s: f64,
    pub h_start_m: Option<f64>,
    pub residual: Option<f64>,
    pub method: Option<&'static str>,
    /// What the blow was forged as (the recording's `part.toml` in force; issue 44).
    pub part_id: Option<String>,
    pub lot: Option<String>,
    pub die_set: Option<String>,
}

impl ExportRow {
    pub fn new(file: &Path, log_time_ns: i64, r: &BlowEstimate) -> Self {
        Self::forged_as(file, log_time_ns, r, &Trace::default())
    }

    /// The row of `r`, forged as `trace`.
    pub fn forged_as(file: &Path, log_time_ns: i64, r: &BlowEstimate, trace: &Trace) -> Self {
        ExportRow {
            file: file.display().to_string(),
            wall_time: rfc3339_ns(log_time_ns),
            wall_time_ns: log_time_ns,
            billet: r.billet.billet,
            billet_blow: r.billet.billet_blow,
            blow: r.blow,
            t_contact_s: r.t_contact_s,
            v_impact_mps: r.v_impact_mps,
            kinetic_in_j: r.kinetic_in_j,
            plastic_j: r.plastic_j,
            friction_j: r.friction_j,
            damped_j: r.damped_j,
            elastic_j: r.elastic_j,
            efficiency: r.efficiency,
            final_load_n: r.final_load_n,
            h_end_m: r.h_end_m,
            class: r.class.as_str(),
            gap_s: r.gap_s,
            sensor_check: r.sensor_check,
            judgement: r.judgement.as_ref().and_then(|j| serde_json::to_string(j).ok()),
            alert: r.alert.as_ref().map(|a| a.kind.as_str()),
            alert_reason: r.alert.as_ref().map(|a| a.reason.clone()),
            peak_load_n: r.peak_load_n,
            t_end_s: r.t_end_s,
            h_start_m: r.h_start_m,
            residual: r.residual,
            method: r.method.map(|m| m.as_str()),
            part_id: trace.part_id.clone(),
            lot: trace.lot.clone(),
            die_set: trace.die_set.clone(),
        }
    }
}

/// `ns` since the epoch as `2026-11-24T07:15:18.123456789Z`.
pub fn rfc3339_ns(ns: i64) -> String {
    chrono::DateTime::from_timestamp_nanos(ns).format("%Y-%m-%dT%H:%M:%S%.9fZ").to_string()
}

pub fn run(args: ExportArgs) -> anyhow::Result<ExitCode> {
    // Each file with whether it came from a directory's listing.
    let mut files = Vec::new();
    for input in &args.inputs {
        files.extend(super::inspect::recordings(input)?.into_iter().map(|f| (f, input.is_dir())));
    }
    let mut rows = Vec::new();
    let mut corrupt = false;
    // What the blows are forged as, from each recording's `part.toml` (every file of a run
    // starts with the one in force).
    for (file, listed) in &files {
        // A file named on the command line must be a recording; one of a directory's that
        // cannot be read (empty, not MCAP) is named and skipped.
        match file_rows(file) {
            Ok((file_rows, file_corrupt)) => {
                rows.extend(file_rows);
                corrupt |= file_corrupt;
            }
            Err(e) if !listed => return Err(e).with_context(|| format!("{}: cannot export", file.display())),
            Err(e) => {
                eprintln!("forgemon: skipped {}: {e}", file.display());
                corrupt = true;
            }
        }
    }
    match (&args.csv, &args.parquet) {
        (Some(out), _) => write_csv(out, &rows)?,
        (None, Some(out)) => write_parquet(out, &batch(&rows)?)?,
        (None, None) => bail!("say where to write: --csv OUT.csv or --parquet OUT.parquet"),
    }
    eprintln!("forgemon: exported {} blows from {} recordings", rows.len(), files.len());
    Ok(if corrupt { ExitCode::from(EXIT_CORRUPT_INPUT) } else { ExitCode::SUCCESS })
}

/// The rows of the recording `file`, each forged as its recording's `part.toml` in force
/// (every file of a run starts with the one in force; a file without one was forged as
/// nothing recorded), and whether part of it could not be read (named on stderr). Fails
/// when `file` is not a recording.
pub fn file_rows(file: &Path) -> anyhow::Result<(Vec<ExportRow>, bool)> {
    let mut reader = RecordReader::open(file)?;
    let mut trace = Trace::default();
    let mut rows = Vec::new();
    let mut corrupt = false;
    for m in reader.by_ref() {
        match m {
            Ok(m) => match &m.payload {
                Payload::Result(r) => rows.push(ExportRow::forged_as(file, m.log_time_ns, r, &trace)),
                Payload::Config(c) if c.name == PART_CONFIG_NAME => match parse_trace_text(&c.text) {
                    Ok(t) => trace = t,
                    Err(why) => {
                        eprintln!("forgemon: {}: a recorded {PART_CONFIG_NAME} left out: {why}", file.display())
                    }
                },
                _ => {}
            },
            Err(e) => {
                eprintln!("forgemon: {}: the rest of the file skipped: {e}", file.display());
                corrupt = true;
                break;
            }
        }
    }
    corrupt |= input_status(reader.report()) != ExitCode::SUCCESS;
    Ok((rows, corrupt))
}

/// `--csv -`, `--parquet -`: the table to standard output.
const STDOUT_PATH: &str = "-";

fn write_csv(out: &Path, rows: &[ExportRow]) -> anyhow::Result<()> {
    let (mut w, place) = csv_to(out)?;
    if rows.is_empty() {
        w.write_record(column_names())?;
    }
    for r in rows {
        w.serialize(r).with_context(|| format!("{place}: cannot write"))?;
    }
    w.flush().with_context(|| format!("{place}: cannot write"))?;
    Ok(())
}

/// A CSV writer to `out` (`-`: standard output), and how errors name it.
pub(crate) fn csv_to(out: &Path) -> anyhow::Result<(csv::Writer<Box<dyn std::io::Write>>, String)> {
    if out == Path::new(STDOUT_PATH) {
        // Through `out`: a closed stdout (`| head`) ends the export quietly (`main`).
        return Ok((csv::Writer::from_writer(Box::new(super::out::stdout())), "standard output".into()));
    }
    let file = File::create(out).with_context(|| format!("{}: cannot write", out.display()))?;
    Ok((csv::Writer::from_writer(Box::new(file)), out.display().to_string()))
}

/// The columns in order, as the CSV header names them.
pub fn column_names() -> Vec<String> {
    schema().fields().iter().map(|f| f.name().clone()).collect()
}

/// The Parquet schema: the CSV's columns, each typed; `wall_time` a UTC timestamp.
fn schema() -> Schema {
    let f64_col = |name: &str, nullable| Field::new(name, DataType::Float64, nullable);
    let str_col = |name: &str, nullable| Field::new(name, DataType::Utf8, nullable);
    let u32_col = |name: &str| Field::new(name, DataType::UInt32, false);
    Schema::new(vec![
        str_col("file", false),
        Field::new("wall_time", DataType::Timestamp(TimeUnit::Nanosecond, Some("UTC".into())), false),
        u32_col("billet"),
        u32_col("billet_blow"),
        u32_col("blow"),
        f64_col("t_contact_s", false),
        f64_col("v_impact_mps", false),
        f64_col("kinetic_in_J", true),
        f64_col("plastic_J", true),
        f64_col("friction_J", true),
        f64_col("damped_J", true),
        f64_col("elastic_J", true),
        f64_col("efficiency", true),
        f64_col("final_load_N", false),
        f64_col("h_end_m", true),
        str_col("class", false),
        f64_col("gap_s", false),
        f64_col("sensor_check", true),
        str_col("judgement", true),
        str_col("alert", true),
        str_col("alert_reason", true),
        f64_col("peak_load_N", false),
        f64_col("t_end_s", false),
        f64_col("h_start_m", true),
        f64_col("residual", true),
        str_col("method", true),
        str_col("part_id", true),
        str_col("lot", true),
        str_col("die_set", true),
    ])
}

/// The rows as one Arrow batch, the columns in `schema()`'s order.
pub fn batch(rows: &[ExportRow]) -> anyhow::Result<RecordBatch> {
    fn f64s(rows: &[ExportRow], f: impl Fn(&ExportRow) -> Option<f64>) -> ArrayRef {
        Arc::new(rows.iter().map(f).collect::<Float64Array>())
    }
    fn strs(rows: &[ExportRow], f: impl Fn(&ExportRow) -> Option<&str>) -> ArrayRef {
        Arc::new(rows.iter().map(f).collect::<StringArray>())
    }
    fn u32s(rows: &[ExportRow], f: impl Fn(&ExportRow) -> u32) -> ArrayRef {
        Arc::new(rows.iter().map(f).collect::<UInt32Array>())
    }
    let wall: TimestampNanosecondArray = rows.iter().map(|r| Some(r.wall_time_ns)).collect();
    let columns: Vec<ArrayRef> = vec![
        strs(rows, |r| Some(&r.file)),
        Arc::new(wall.with_timezone("UTC")),
        u32s(rows, |r| r.billet),
        u32s(rows, |r| r.billet_blow),
        u32s(rows, |r| r.blow),
        f64s(rows, |r| Some(r.t_contact_s)),
        f64s(rows, |r| Some(r.v_impact_mps)),
        f64s(rows, |r| r.kinetic_in_j),
        f64s(rows, |r| r.plastic_j),
        f64s(rows, |r| r.friction_j),
        f64s(rows, |r| r.damped_j),
        f64s(rows, |r| r.elastic_j),
        f64s(rows, |r| r.efficiency),
        f64s(rows, |r| Some(r.final_load_n)),
        f64s(rows, |r| r.h_end_m),
        strs(rows, |r| Some(r.class)),
        f64s(rows, |r| Some(r.gap_s)),
        f64s(rows, |r| r.sensor_check),
        strs(rows, |r| r.judgement.as_deref()),
        strs(rows, |r| r.alert),
        strs(rows, |r| r.alert_reason.as_deref()),
        f64s(rows, |r| Some(r.peak_load_n)),
        f64s(rows, |r| Some(r.t_end_s)),
        f64s(rows, |r| r.h_start_m),
        f64s(rows, |r| r.residual),
        strs(rows, |r| r.method),
        strs(rows, |r| r.part_id.as_deref()),
        strs(rows, |r| r.lot.as_deref()),
        strs(rows, |r| r.die_set.as_deref()),
    ];
    Ok(RecordBatch::try_new(Arc::new(schema()), columns)?)
}

/// `batch` as one snappy-compressed Parquet file at `out` (`-`: standard output, when that
/// is not a terminal).
pub(crate) fn write_parquet(out: &Path, batch: &RecordBatch) -> anyhow::Result<()> {
    if out == Path::new(STDOUT_PATH) {
        if std::io::IsTerminal::is_terminal(&std::io::stdout()) {
            bail!("--parquet -: standard output is a terminal, and Parquet is binary; give a file, or a pipe");
        }
        // Through `out`: a closed stdout ends the export quietly (`main`).
        return write_parquet_to(super::out::stdout(), batch, "standard output");
    }
    let file = File::create(out).with_context(|| format!("{}: cannot write", out.display()))?;
    write_parquet_to(file, batch, &out.display().to_string())
}

/// `batch` as Parquet to `w`, which `place` names in the errors.
fn write_parquet_to<W: std::io::Write + Send>(w: W, batch: &RecordBatch, place: &str) -> anyhow::Result<()> {
    use parquet::arrow::ArrowWriter;
    use parquet::basic::Compression;
    use parquet::file::properties::WriterProperties;
    let props = WriterProperties::builder().set_compression(Compression::SNAPPY).build();
    let mut w = ArrowWriter::try_new(BufWriter::new(w), batch.schema(), Some(props))?;
    w.write(batch).with_context(|| format!("{place}: cannot write"))?;
    w.close().with_context(|| format!("{place}: cannot write"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn the_csv_header_and_the_parquet_schema_name_the_same_columns_in_order() {
        // The CSV's header comes from the row's serde names, the Parquet's from `schema()`:
        // one row written as CSV must start with exactly the schema's names.
        let r = sample();
        let mut w = csv::Writer::from_writer(Vec::new());
        w.serialize(ExportRow::new(Path::new("a.mcap"), 0, &r)).expect("serialises");
        let text = String::from_utf8(w.into_inner().expect("flushed")).expect("utf-8");
        let header: Vec<&str> = text.lines().next().expect("a header").split(',').collect();
        assert_eq!(header, column_names());
        assert_eq!(batch(&[ExportRow::new(Path::new("a.mcap"), 0, &r)]).expect("a batch").num_columns(), header.len());
    }

    #[test]
    fn wall_time_is_utc_with_nanoseconds() {
        // 2026-11-24T07:15:18Z is 1 795 504 518 s after the epoch (`date -u -d @1795504518`).
        assert_eq!(rfc3339_ns(1_795_504_518_000_000_123), "2026-11-24T07:15:18.000000123Z");
    }

    #[test]
    fn exactly_one_output_is_required() {
        let parse = |a: &[&str]| crate::cli::Cli::try_parse_from([&["forgemon", "export"], a].concat());
        assert!(parse(&["a.mcap", "--csv", "o.csv"]).is_ok());
        assert!(parse(&["a.mcap", "b", "--parquet", "o.parquet"]).is_ok());
        assert!(parse(&["a.mcap"]).is_err(), "no output");
        assert!(parse(&["a.mcap", "--csv", "o.csv", "--parquet", "o.parquet"]).is_err(), "two outputs");
        assert!(parse(&["--csv", "o.csv"]).is_err(), "no input");
    }

    fn sample() -> BlowEstimate {
        BlowEstimate { gap_s: 0.01, ..BlowEstimate::incomplete(1, 0.5, 3.9, 0.6) }
    }
}
