//! `forgemon history export`: a table of the history database, under the reading verbs'
//! filters, as CSV or Parquet for a spreadsheet, pandas or a data lake
//! (docs/interfaces.md §18). The columns are the table's own, typed as it declares them, with
//! `wall_time` (the row's log time, UTC) in place of `wall_time_ns` and without the row id.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::Context;
use arrow_array::{ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray, TimestampNanosecondArray};
use arrow_schema::{DataType, Field, Schema, TimeUnit};
use clap::Args;
use serde_json::{Map, Value};

use super::RowArgs;
use crate::cli::export::{csv_to, rfc3339_ns, write_parquet};
use crate::history::query::{Column, ColumnType, columns, open_read, rows};

#[derive(Debug, Args)]
pub struct ExportArgs {
    #[command(flatten)]
    pub rows: RowArgs,
    /// Write CSV (a header row, then the rows oldest first; an empty field for NULL); `-`
    /// writes it to standard output.
    #[arg(long, value_name = "OUT.csv", required_unless_present = "parquet", conflicts_with = "parquet")]
    pub csv: Option<PathBuf>,
    /// Write Parquet (snappy-compressed; `wall_time` a UTC timestamp in ns); `-` writes it to
    /// standard output, when that is not a terminal.
    #[arg(long, value_name = "OUT.parquet")]
    pub parquet: Option<PathBuf>,
}

/// The row id is the database's own; `wall_time_ns` leaves as `wall_time`.
const LEFT_OUT: [&str; 2] = ["id", "wall_time_ns"];

pub fn run(a: ExportArgs) -> anyhow::Result<ExitCode> {
    let filter = a.rows.filter()?;
    let (db, table) = (&a.rows.db, a.rows.table);
    let conn = open_read(db)?;
    let cols: Vec<Column> =
        columns(&conn, db, table)?.into_iter().filter(|c| !LEFT_OUT.contains(&c.name.as_str())).collect();
    let found = rows(&conn, db, table, &filter)?;
    match (&a.csv, &a.parquet) {
        (Some(out), _) => write_csv(out, &cols, &found)?,
        (None, Some(out)) => write_parquet(out, &batch(&cols, &found)?)?,
        (None, None) => anyhow::bail!("say where to write: --csv OUT.csv or --parquet OUT.parquet"),
    }
    eprintln!("forgemon: exported {} {}", found.len(), table.name());
    Ok(ExitCode::SUCCESS)
}

fn wall_ns(row: &Map<String, Value>) -> i64 {
    row.get("wall_time_ns").and_then(Value::as_i64).unwrap_or_default()
}

fn write_csv(out: &std::path::Path, cols: &[Column], found: &[Map<String, Value>]) -> anyhow::Result<()> {
    let (mut w, place) = csv_to(out)?;
    let header = std::iter::once("wall_time").chain(cols.iter().map(|c| c.name.as_str()));
    w.write_record(header).with_context(|| format!("{place}: cannot write"))?;
    for row in found {
        let cell = |c: &Column| match row.get(&c.name) {
            None | Some(Value::Null) => String::new(),
            Some(Value::String(s)) => s.clone(),
            // serde_json prints the shortest text that reads back to the same number.
            Some(v) => v.to_string(),
        };
        let record = std::iter::once(rfc3339_ns(wall_ns(row))).chain(cols.iter().map(cell));
        w.write_record(record).with_context(|| format!("{place}: cannot write"))?;
    }
    w.flush().with_context(|| format!("{place}: cannot write"))?;
    Ok(())
}

/// The rows as one Arrow batch: `wall_time`, then the columns, each typed as declared.
fn batch(cols: &[Column], found: &[Map<String, Value>]) -> anyhow::Result<RecordBatch> {
    let wall = Field::new("wall_time", DataType::Timestamp(TimeUnit::Nanosecond, Some("UTC".into())), false);
    let fields = std::iter::once(wall).chain(cols.iter().map(|c| {
        let t = match c.kind {
            ColumnType::Integer => DataType::Int64,
            ColumnType::Real => DataType::Float64,
            ColumnType::Text => DataType::Utf8,
        };
        Field::new(&c.name, t, c.nullable)
    }));
    let schema = Schema::new(fields.collect::<Vec<_>>());
    let wall: TimestampNanosecondArray = found.iter().map(|r| Some(wall_ns(r))).collect();
    let mut arrays: Vec<ArrayRef> = vec![Arc::new(wall.with_timezone("UTC"))];
    for c in cols {
        let values = found.iter().map(|r| r.get(&c.name).unwrap_or(&Value::Null));
        arrays.push(match c.kind {
            ColumnType::Integer => Arc::new(values.map(Value::as_i64).collect::<Int64Array>()),
            ColumnType::Real => Arc::new(values.map(Value::as_f64).collect::<Float64Array>()),
            ColumnType::Text => Arc::new(values.map(Value::as_str).collect::<StringArray>()),
        });
    }
    Ok(RecordBatch::try_new(Arc::new(schema), arrays)?)
}
