//! `forgemon history {query, rebuild, spc, report, export, serve}`: the quality record (issue 44) from the
//! command line.
//! `rebuild` makes the database from recordings by the function the service writes it with
//! (`history::History::ingest`); `query` prints a table's rows under filters.

mod export;
mod report;
mod serve;

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};

use super::inspect::{EXIT_CORRUPT_INPUT, input_status, recordings};
use crate::history::query::{Filter, Table, open_read, rows};
use crate::history::{History, Ingested};
use crate::record::RecordReader;

#[derive(Debug, Args)]
pub struct HistoryArgs {
    #[command(subcommand)]
    pub command: HistoryCommand,
}

#[derive(Debug, Subcommand)]
pub enum HistoryCommand {
    /// Print the blows (or billets) of the history database, oldest first.
    Query(QueryArgs),
    /// Make the history database from recordings: MCAP is the source of truth. Into an
    /// existing database it adds only the rows it lacks.
    Rebuild(RebuildArgs),
    /// Process capability per blow of a recipe: mean, spread, Cp/Cpk against its windows,
    /// and the individuals/moving-range chart's limits.
    Spc(SpcArgs),
    /// A shift's quality report as one HTML file: SPC per blow, I-MR charts, lots and die
    /// sets.
    Report(report::ReportArgs),
    /// A table of the history database as CSV or Parquet, under the same filters as query.
    Export(export::ExportArgs),
    /// Serve the dashboard's history page over a database alone (no machine, no service).
    Serve(serve::ServeArgs),
}

#[derive(Debug, Args)]
pub struct SpcArgs {
    /// The history database.
    #[arg(long, value_name = "DB")]
    pub db: PathBuf,
    /// The recipe file (`forgemon teach`): its name selects the blows, its windows are the
    /// specification limits.
    #[arg(long, value_name = "PART.recipe.toml")]
    pub recipe: PathBuf,
    #[command(flatten)]
    pub filter: FilterArgs,
    /// One JSON object per blow and quantity instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// The filters every reading verb takes.
#[derive(Debug, Args)]
pub struct FilterArgs {
    /// Rows at or after this time: RFC 3339 (2026-11-30T06:00:00Z) or a UTC date (2026-11-30).
    #[arg(long, value_name = "TIME")]
    pub since: Option<String>,
    /// Rows before this time (as --since).
    #[arg(long, value_name = "TIME")]
    pub until: Option<String>,
    /// Only this part id.
    #[arg(long, value_name = "ID")]
    pub part: Option<String>,
    /// Only this lot.
    #[arg(long, value_name = "LOT")]
    pub lot: Option<String>,
    /// Only this die set.
    #[arg(long, value_name = "DIE_SET")]
    pub die: Option<String>,
}

/// Which rows of which table `query` and `export` read.
#[derive(Debug, Args)]
pub struct RowArgs {
    /// The history database (`[history] path`; by default `history.sqlite` in the recording
    /// directory).
    #[arg(long, value_name = "DB")]
    pub db: PathBuf,
    /// Which table.
    #[arg(long, value_enum, default_value = "blows")]
    pub table: Table,
    #[command(flatten)]
    pub filter: FilterArgs,
    /// Only rows of this recipe (its name).
    #[arg(long, value_name = "NAME")]
    pub recipe: Option<String>,
    /// Only blows judged NOK, or billets with one.
    #[arg(long)]
    pub nok: bool,
}

impl RowArgs {
    /// The database, checked to be there, and the filter.
    pub(crate) fn filter(&self) -> anyhow::Result<Filter> {
        existing(&self.db)?;
        Ok(Filter { nok: self.nok, recipe: self.recipe.clone(), ..self.filter.filter()? })
    }
}

#[derive(Debug, Args)]
pub struct QueryArgs {
    #[command(flatten)]
    pub rows: RowArgs,
    /// At most this many rows.
    #[arg(long, value_name = "N")]
    pub limit: Option<u64>,
    /// One JSON object per row (every column) instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct RebuildArgs {
    /// Recordings (.mcap, .mcap.part), or directories of them, in the order they were written.
    #[arg(required = true, value_name = "RECORDING_OR_DIR")]
    pub inputs: Vec<PathBuf>,
    /// The database to write (created if missing).
    #[arg(long, value_name = "DB")]
    pub db: PathBuf,
    /// Delete rows older than this many days before the newest (as `[history] keep_days`).
    #[arg(long, value_name = "DAYS")]
    pub keep_days: Option<f64>,
}

pub fn run(args: HistoryArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        HistoryCommand::Query(a) => query(a),
        HistoryCommand::Rebuild(a) => rebuild(a),
        HistoryCommand::Spc(a) => spc(a),
        HistoryCommand::Report(a) => report::run(a),
        HistoryCommand::Export(a) => export::run(a),
        HistoryCommand::Serve(a) => serve::run(a),
    }
}

pub(crate) use crate::history::query::parse_time;

impl FilterArgs {
    pub(crate) fn filter(&self) -> anyhow::Result<Filter> {
        Ok(Filter {
            since_ns: self.since.as_deref().map(|t| parse_time("--since", t)).transpose()?,
            until_ns: self.until.as_deref().map(|t| parse_time("--until", t)).transpose()?,
            part_id: self.part.clone(),
            lot: self.lot.clone(),
            die_set: self.die.clone(),
            ..Filter::default()
        })
    }
}

/// A database that must already be there, named if it is not.
pub(crate) fn existing(db: &Path) -> anyhow::Result<()> {
    if !db.is_file() {
        bail!(
            "{}: no history database there (the service writes it to [history] path; forgemon history rebuild makes one)",
            db.display()
        );
    }
    Ok(())
}

fn query(a: QueryArgs) -> anyhow::Result<ExitCode> {
    let filter = Filter { limit: a.limit, ..a.rows.filter()? };
    let (db, table) = (&a.rows.db, a.rows.table);
    let conn = open_read(db)?;
    let found = rows(&conn, db, table, &filter)?;
    let mut out = super::out::stdout();
    if a.json {
        for r in &found {
            writeln!(out, "{}", serde_json::Value::Object(r.clone()))?;
        }
    } else {
        print_table(&mut out, table, &found)?;
    }
    out.flush()?;
    eprintln!("forgemon: {} {}", found.len(), table.name());
    Ok(ExitCode::SUCCESS)
}

/// The columns the text table shows; `--json` gives every one.
fn shown(table: Table) -> &'static [&'static str] {
    match table {
        Table::Blows => &[
            "wall_time",
            "part_id",
            "lot",
            "die_set",
            "billet",
            "billet_blow",
            "efficiency",
            "plastic_J",
            "class",
            "judgement",
        ],
        Table::Billets => &[
            "wall_time",
            "part_id",
            "lot",
            "die_set",
            "billet",
            "blows",
            "efficiency",
            "plastic_J",
            "h_end_m",
            "finished",
        ],
    }
}

fn print_table(
    out: &mut impl std::io::Write,
    table: Table,
    found: &[serde_json::Map<String, serde_json::Value>],
) -> anyhow::Result<()> {
    let cols = shown(table);
    writeln!(out, "{}", cols.join("\t"))?;
    for r in found {
        let cell = |c: &str| -> String {
            if c == "wall_time" {
                return r.get("wall_time_ns").and_then(|v| v.as_i64()).map(rfc3339_ms).unwrap_or_default();
            }
            match r.get(c) {
                None | Some(serde_json::Value::Null) => "-".into(),
                Some(serde_json::Value::String(s)) => s.clone(),
                Some(serde_json::Value::Number(n)) if n.is_f64() => format!("{:.4}", n.as_f64().unwrap_or(f64::NAN)),
                Some(v) => v.to_string(),
            }
        };
        writeln!(out, "{}", cols.iter().map(|c| cell(c)).collect::<Vec<_>>().join("\t"))?;
    }
    Ok(())
}

fn rfc3339_ms(ns: i64) -> String {
    chrono::DateTime::from_timestamp_nanos(ns).format("%Y-%m-%dT%H:%M:%S%.3fZ").to_string()
}

/// Messages ingested in one transaction.
const REBUILD_BATCH: usize = 512;

fn rebuild(a: RebuildArgs) -> anyhow::Result<ExitCode> {
    let mut files = Vec::new();
    for input in &a.inputs {
        files.extend(recordings(input)?);
    }
    let mut history = History::open(&a.db, a.keep_days)?;
    let (mut total, mut corrupt) = (Ingested::default(), false);
    for file in &files {
        let mut reader =
            RecordReader::open(file).with_context(|| format!("{}: cannot rebuild from it", file.display()))?;
        let mut batch = Vec::with_capacity(REBUILD_BATCH);
        for m in reader.by_ref() {
            match m {
                Ok(m) => batch.push((m.log_time_ns, m.payload)),
                Err(e) => {
                    eprintln!("forgemon: {}: the rest of the file skipped: {e}", file.display());
                    corrupt = true;
                    break;
                }
            }
            if batch.len() == REBUILD_BATCH {
                add(&mut total, history.ingest(&batch)?);
                batch.clear();
            }
        }
        add(&mut total, history.ingest(&batch)?);
        corrupt |= input_status(reader.report()) != ExitCode::SUCCESS;
    }
    let pruned = history.prune()?;
    eprintln!(
        "forgemon: {}: {} blows and {} billets added from {} recordings{}",
        a.db.display(),
        total.blows,
        total.billets,
        files.len(),
        if pruned > 0 { format!(", {pruned} rows older than --keep-days deleted") } else { String::new() }
    );
    Ok(if corrupt { ExitCode::from(EXIT_CORRUPT_INPUT) } else { ExitCode::SUCCESS })
}

fn add(total: &mut Ingested, n: Ingested) {
    total.blows += n.blows;
    total.billets += n.billets;
}

/// A recipe blow's window of one quantity.
type WindowOf = fn(&crate::recipe::BlowWindows) -> crate::recipe::Window;

/// The quantities SPC follows, by the history's column and the recipe window's.
const SPC_QUANTITIES: [(&str, WindowOf); 3] =
    [("efficiency", |w| w.efficiency), ("plastic_J", |w| w.plastic_j), ("peak_load_N", |w| w.peak_load_n)];

fn spc(a: SpcArgs) -> anyhow::Result<ExitCode> {
    existing(&a.db)?;
    let text = super::read_text(&a.recipe)?;
    let recipe = crate::config::recipe::parse_recipe(&a.recipe.display().to_string(), &text)?;
    let filter = Filter { recipe: Some(recipe.name.clone()), ..a.filter.filter()? };
    let conn = open_read(&a.db)?;
    let blows = rows(&conn, &a.db, Table::Blows, &filter)?;
    let mut out = super::out::stdout();
    if !a.json {
        writeln!(out, "recipe {}: {} blows judged by it", recipe.name, blows.len())?;
        writeln!(out, "blow\tquantity\tn\tmean\tsd\tCp\tCpk\tout of control")?;
    }
    for w in &recipe.blows {
        for (column, window) in SPC_QUANTITIES {
            let values: Vec<f64> = blows
                .iter()
                .filter(|b| b.get("billet_blow").and_then(|v| v.as_u64()) == Some(u64::from(w.blow)))
                .filter_map(|b| b.get(column).and_then(|v| v.as_f64()))
                .collect();
            let window = window(w);
            let Some(c) = crate::history::spc::capability(&values, window.min, window.max) else { continue };
            if a.json {
                let mut obj = serde_json::to_value(&c)?;
                obj["blow"] = w.blow.into();
                obj["quantity"] = column.into();
                writeln!(out, "{obj}")?;
            } else {
                let f = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.2}"));
                writeln!(
                    out,
                    "{}\t{column}\t{}\t{:.4}\t{:.4}\t{}\t{}\t{}",
                    w.blow,
                    c.n,
                    c.mean,
                    c.sd,
                    f(c.cp),
                    f(c.cpk),
                    c.out_of_control.len()
                )?;
            }
        }
    }
    out.flush()?;
    Ok(ExitCode::SUCCESS)
}
