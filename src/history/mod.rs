//! The forge's quality record (issue 44): an embedded SQLite database of every blow and
//! billet, with the part, lot and die set each was forged on, for the questions a quality
//! engineer and a maintenance planner ask across weeks (`forgemon history`).
//!
//! The rows are made from the recording's own messages (`/results`, `/billets`) by one
//! function, [`History::ingest`]: live, from the recorder's tap as the file gets them
//! (`writer.rs`, on a thread of its own behind a bounded queue); offline, from the
//! recordings (`forgemon history rebuild`). MCAP stays the source of truth, and a rebuild
//! gives the rows the service wrote.
//!
//! A blow is keyed by its log time and number, a billet by its number and start: ingesting a
//! message twice changes nothing, so a rebuild into a live database fills only what the live
//! writer dropped. A billet's later summary (finished) replaces its earlier one (unfinished,
//! at a stop).

pub mod die;
pub mod query;
pub mod schema;
pub mod spc;
pub mod trend;
pub mod writer;

use std::path::{Path, PathBuf};

use rusqlite::{Connection, OptionalExtension, params};

use crate::config::history::parse_trace_text;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;
use crate::record::Payload;
use crate::session::{PART_CONFIG_NAME, is_die_change_marker};

/// Nanoseconds in a day, for `keep_days`.
const DAY_NS: f64 = 86_400e9;

/// Why the history could not be opened or written.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    #[error("{path}: {source}")]
    Sqlite {
        path: PathBuf,
        #[source]
        source: rusqlite::Error,
    },
    #[error(
        "{path}: schema version {found} is newer than this forgemon's {known}: a newer forgemon wrote it; use that, or rebuild a database for this one (forgemon history rebuild)"
    )]
    Newer { path: PathBuf, found: i64, known: usize },
    #[error("cannot start the history's writer thread: {0}")]
    Thread(#[source] std::io::Error),
}

/// What a blow was forged on (the part, its lot, the die set): set by the operator, the PLC
/// or OPC UA, or `[part]`'s defaults; carried by every row until it changes.
pub use crate::config::history::Trace;

/// Rows written by `ingest`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ingested {
    pub blows: u64,
    pub billets: u64,
}

/// An open history database.
pub struct History {
    conn: Connection,
    path: PathBuf,
    /// What the rows are forged on now.
    trace: Trace,
    /// The die set the blows count on: its row in `die_sets` and its count.
    die: Option<(i64, die::DieCount)>,
    /// The last blow's billet and recipe: its billet's summary carries the same recipe.
    last_blow: Option<(u32, Option<String>)>,
    /// The billet the last blows were struck on and its first blow's log time.
    first_blow: Option<(u32, i64)>,
    /// Rows older than this before the newest are deleted (`[history] keep_days`).
    keep_ns: Option<i64>,
    newest_ns: i64,
}

impl History {
    /// Open (or create) the database at `path` and bring its schema up to date.
    pub fn open(path: &Path, keep_days: Option<f64>) -> Result<Self, HistoryError> {
        let sql = |source| HistoryError::Sqlite { path: path.to_path_buf(), source };
        let mut conn = Connection::open(path).map_err(sql)?;
        // WAL: readers (the CLI, the dashboard) never wait for the writer, nor it for them.
        conn.pragma_update(None, "journal_mode", "WAL").map_err(sql)?;
        conn.pragma_update(None, "synchronous", "NORMAL").map_err(sql)?;
        conn.busy_timeout(std::time::Duration::from_secs(5)).map_err(sql)?;
        migrate(&mut conn, path)?;
        Ok(History {
            conn,
            path: path.to_path_buf(),
            trace: Trace::default(),
            last_blow: None,
            first_blow: None,
            die: None,
            keep_ns: keep_days.map(|d| (d * DAY_NS) as i64),
            newest_ns: i64::MIN,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn connection(&self) -> &Connection {
        &self.conn
    }

    fn error(&self, source: rusqlite::Error) -> HistoryError {
        HistoryError::Sqlite { path: self.path.clone(), source }
    }

    /// A new recording file follows: what its blows are forged as comes from its own
    /// `part.toml` (every file of a run starts with the one in force), not the last file's.
    pub fn start_file(&mut self) {
        self.trace = Trace::default();
    }

    /// Write `messages` (log time, payload) in one transaction; messages that make no row
    /// (samples, configs, ...) are passed over.
    pub fn ingest(&mut self, messages: &[(i64, Payload)]) -> Result<Ingested, HistoryError> {
        let tx = self.conn.transaction().map_err(|e| HistoryError::Sqlite { path: self.path.clone(), source: e })?;
        let mut n = Ingested::default();
        for (t, payload) in messages {
            self.newest_ns = self.newest_ns.max(*t);
            let written = match payload {
                Payload::Result(r) => {
                    let recipe = r.judgement.as_ref().map(|j| j.recipe.clone());
                    self.last_blow = Some((r.billet.billet, recipe));
                    // A billet's first blow: another billet's number, or its blow 1 (a new
                    // run numbers billets from 1 again).
                    if r.billet.billet_blow == 1 || self.first_blow.is_none_or(|(b, _)| b != r.billet.billet) {
                        self.first_blow = Some((r.billet.billet, *t));
                    }
                    insert_blow(&tx, *t, r, &self.trace).and_then(|k| {
                        n.blows += k as u64;
                        // A blow already there is not counted again.
                        if k == 1 { count_die(&tx, &mut self.die, &self.trace, *t, r) } else { Ok(()) }
                    })
                }
                Payload::Status(st) if is_die_change_marker(st) => {
                    let count = die::DieCount::new(self.trace.die_set.clone(), *t);
                    die::install(&tx, &count).map(|found| self.die = Some(found))
                }
                Payload::Billet(b) => {
                    let recipe = match &self.last_blow {
                        Some((billet, recipe)) if *billet == b.billet => recipe.as_deref(),
                        _ => None,
                    };
                    let first = self.first_blow.filter(|(n, _)| *n == b.billet).map_or(0, |(_, t)| t);
                    insert_billet(&tx, *t, b, recipe, first).map(|k| n.billets += k as u64)
                }
                Payload::Config(c) if c.name == crate::alert::drift::REFERENCE_CONFIG_NAME => tx
                    .execute(
                        "INSERT OR IGNORE INTO drift_references (wall_time_ns, reference) VALUES (?1, ?2)",
                        params![t, c.text],
                    )
                    .map(|_| ()),
                Payload::Config(c) if c.name == PART_CONFIG_NAME => {
                    match parse_trace_text(&c.text) {
                        Ok(trace) => self.trace = trace,
                        Err(why) => tracing::warn!("history: a recorded {PART_CONFIG_NAME} left out: {why}"),
                    }
                    Ok(())
                }
                _ => Ok(()),
            };
            written.map_err(|e| HistoryError::Sqlite { path: self.path.clone(), source: e })?;
        }
        tx.commit().map_err(|e| self.error(e))?;
        Ok(n)
    }

    /// Delete the rows older than `keep_days` before the newest ingested; the rows deleted.
    pub fn prune(&mut self) -> Result<u64, HistoryError> {
        let (Some(keep), true) = (self.keep_ns, self.newest_ns > i64::MIN) else { return Ok(0) };
        let before = self.newest_ns.saturating_sub(keep);
        let mut n = 0;
        for table in ["blows", "billets"] {
            let sql = format!("DELETE FROM {table} WHERE wall_time_ns < ?1");
            n += self.conn.execute(&sql, params![before]).map_err(|e| self.error(e))? as u64;
        }
        Ok(n)
    }
}

/// Bring `conn` to the last schema version, one migration per transaction.
fn migrate(conn: &mut Connection, path: &Path) -> Result<(), HistoryError> {
    let sql = |source| HistoryError::Sqlite { path: path.to_path_buf(), source };
    let found: i64 = conn.pragma_query_value(None, "user_version", |r| r.get(0)).map_err(sql)?;
    let known = schema::MIGRATIONS.len();
    if found > known as i64 {
        return Err(HistoryError::Newer { path: path.to_path_buf(), found, known });
    }
    for (i, migration) in schema::MIGRATIONS.iter().enumerate().skip(found.max(0) as usize) {
        let tx = conn.transaction().map_err(sql)?;
        tx.execute_batch(migration).map_err(sql)?;
        tx.pragma_update(None, "user_version", i as i64 + 1).map_err(sql)?;
        tx.commit().map_err(sql)?;
    }
    Ok(())
}

/// Count blow `r` at `t` on the die set in force (`trace`'s name): the one `die` holds, or
/// the latest of that name in the database, or a new one.
fn count_die(
    tx: &rusqlite::Transaction<'_>,
    die: &mut Option<(i64, die::DieCount)>,
    trace: &Trace,
    t: i64,
    r: &BlowEstimate,
) -> rusqlite::Result<()> {
    let name = trace.die_set.as_deref();
    if die.as_ref().is_none_or(|(_, d)| d.die_set.as_deref() != name) {
        *die = match die::latest(tx, name)? {
            Some(found) => Some(found),
            None => Some(die::install(tx, &die::DieCount::new(trace.die_set.clone(), t))?),
        };
    }
    let Some((id, count)) = die.as_mut() else { return Ok(()) };
    count.add(r);
    die::store(tx, *id, count, t).map(|_| ())
}

/// A finite value, or NULL (SQLite would store NaN as NULL anyway; this says so).
fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

fn insert_blow(tx: &rusqlite::Transaction<'_>, t: i64, r: &BlowEstimate, trace: &Trace) -> rusqlite::Result<usize> {
    let judgement = r.judgement.as_ref();
    let mut stmt = tx.prepare_cached(
        "INSERT OR IGNORE INTO blows (wall_time_ns, billet, billet_blow, blow, t_contact_s, v_impact_mps,
            kinetic_in_J, plastic_J, friction_J, damped_J, elastic_J, efficiency, final_load_N, peak_load_N,
            h_start_m, h_end_m, class, gap_s, sensor_check, residual, method, recipe, judgement,
            judgement_reasons, alert, alert_reason, part_id, lot, die_set)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18, ?19,
            ?20, ?21, ?22, ?23, ?24, ?25, ?26, ?27, ?28, ?29)",
    )?;
    stmt.execute(params![
        t,
        r.billet.billet,
        r.billet.billet_blow,
        r.blow,
        r.t_contact_s,
        finite(r.v_impact_mps),
        r.kinetic_in_j,
        r.plastic_j,
        r.friction_j,
        r.damped_j,
        r.elastic_j,
        r.efficiency,
        finite(r.final_load_n),
        finite(r.peak_load_n),
        r.h_start_m,
        r.h_end_m,
        r.class.as_str(),
        finite(r.gap_s),
        r.sensor_check,
        r.residual,
        r.method.map(|m| m.as_str()),
        judgement.map(|j| j.recipe.as_str()),
        judgement.map(|j| if j.ok { "OK" } else { "NOK" }),
        judgement.filter(|j| !j.reasons.is_empty()).map(|j| j.reasons.join("; ")),
        r.alert.as_ref().map(|a| a.kind.as_str()),
        r.alert.as_ref().map(|a| a.reason.as_str()),
        trace.part_id,
        trace.lot,
        trace.die_set,
    ])
}

/// The billet row's columns, in the order `insert_billet` binds them.
const BILLET_COLUMNS: [&str; 25] = [
    "wall_time_ns",
    "billet",
    "t_start_s",
    "t_end_s",
    "blows",
    "incomplete_blows",
    "implausible_blows",
    "energies_partial",
    "h_start_m",
    "h_start_off_sheet_m",
    "h_end_m",
    "kinetic_in_J",
    "plastic_J",
    "friction_J",
    "efficiency",
    "first_hard_blow",
    "hard_blows",
    "alerts",
    "checked_blows",
    "finished",
    "recipe",
    "part_id",
    "lot",
    "die_set",
    "first_blow_ns",
];

fn insert_billet(
    tx: &rusqlite::Transaction<'_>,
    t: i64,
    b: &BilletSummary,
    recipe: Option<&str>,
    first_blow_ns: i64,
) -> rusqlite::Result<usize> {
    // A later summary of the billet (finished, after an unfinished one) updates its row in
    // place; the same summary again changes nothing.
    let update: Vec<String> = BILLET_COLUMNS.iter().map(|c| format!("{c} = excluded.{c}")).collect();
    let sql = format!(
        "INSERT INTO billets ({}) VALUES ({}) ON CONFLICT (billet, t_start_s, first_blow_ns) DO UPDATE SET {}
         WHERE excluded.wall_time_ns > billets.wall_time_ns",
        BILLET_COLUMNS.join(", "),
        (1..=BILLET_COLUMNS.len()).map(|i| format!("?{i}")).collect::<Vec<_>>().join(", "),
        update.join(", ")
    );
    let mut stmt = tx.prepare_cached(&sql)?;
    stmt.execute(params![
        t,
        b.billet,
        b.t_start_s,
        b.t_end_s,
        b.blows,
        b.incomplete_blows,
        b.implausible_blows,
        b.energies_partial,
        b.h_start_m,
        b.h_start_off_sheet_m,
        b.h_end_m,
        finite(b.kinetic_in_j),
        finite(b.plastic_j),
        b.friction_j,
        b.efficiency,
        b.first_hard_blow,
        b.hard_blows,
        b.alerts,
        b.checked_blows,
        b.finished,
        recipe,
        b.trace.part_id,
        b.trace.lot,
        b.trace.die_set,
        first_blow_ns,
    ])
}

/// The drift alarms' latest learnt reference in the database at `path` (its JSON), if any.
pub fn latest_drift_reference(path: &Path) -> Result<Option<String>, HistoryError> {
    let conn = query::open_read(path)?;
    conn.query_row("SELECT reference FROM drift_references ORDER BY wall_time_ns DESC, id DESC LIMIT 1", [], |r| {
        r.get(0)
    })
    .optional()
    .map_err(|source| HistoryError::Sqlite { path: path.to_path_buf(), source })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::ConfigFile;
    use crate::record::codec::tests::{billet, estimate};

    fn temp_db(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("forgemon-history-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a temp dir");
        dir.join("h.sqlite")
    }

    fn count(h: &History, table: &str) -> i64 {
        h.connection().query_row(&format!("SELECT count(*) FROM {table}"), [], |r| r.get(0)).expect("counts")
    }

    fn part(text: &str) -> Payload {
        Payload::Config(ConfigFile { name: PART_CONFIG_NAME.into(), text: text.into() })
    }

    #[test]
    fn a_new_database_gets_every_migration_and_reopening_changes_nothing() {
        let path = temp_db("migrate");
        let h = History::open(&path, None).expect("opens");
        let v: i64 = h.connection().pragma_query_value(None, "user_version", |r| r.get(0)).expect("a version");
        assert_eq!(v, schema::MIGRATIONS.len() as i64);
        drop(h);
        History::open(&path, None).expect("reopens at the same version");
    }

    #[test]
    fn a_database_from_a_newer_forgemon_is_refused_naming_its_version() {
        let path = temp_db("newer");
        drop(History::open(&path, None).expect("opens"));
        let conn = Connection::open(&path).expect("opens");
        conn.pragma_update(None, "user_version", 99).expect("set");
        drop(conn);
        let err = History::open(&path, None).err().expect("refused").to_string();
        assert!(err.contains("schema version 99") && err.contains("h.sqlite"), "{err}");
    }

    #[test]
    fn a_message_ingested_twice_makes_one_row_and_a_later_summary_replaces_the_earlier() {
        let mut h = History::open(&temp_db("twice"), None).expect("opens");
        let blow = Payload::Result(Box::new(estimate(true)));
        let open = Payload::Billet(Box::new(billet(false)));
        let mut done = billet(false);
        done.finished = true;
        let done = Payload::Billet(Box::new(done));
        let n = h.ingest(&[(10, blow.clone()), (11, open)]).expect("written");
        assert_eq!(n, Ingested { blows: 1, billets: 1 });
        h.ingest(&[(10, blow), (12, done)]).expect("written");
        assert_eq!((count(&h, "blows"), count(&h, "billets")), (1, 1));
        let finished: bool = h.connection().query_row("SELECT finished FROM billets", [], |r| r.get(0)).expect("a row");
        assert!(finished, "the later summary is kept");
    }

    #[test]
    fn two_runs_whose_clocks_both_start_at_zero_keep_their_billets_apart() {
        // The same billet number and device times (a power-cycled DAQ, the simulator) in two
        // runs: two rows, known apart by their first blow's log time.
        let mut h = History::open(&temp_db("runs"), None).expect("opens");
        let mut first = estimate(true);
        (first.billet.billet, first.billet.billet_blow) = (4, 1);
        let blow = Payload::Result(Box::new(first));
        let summary = Payload::Billet(Box::new(billet(true)));
        h.ingest(&[(10, blow.clone()), (11, summary.clone())]).expect("run 1");
        h.ingest(&[(500, blow), (501, summary)]).expect("run 2");
        assert_eq!((count(&h, "blows"), count(&h, "billets")), (2, 2));
        let firsts: Vec<i64> = h
            .connection()
            .prepare("SELECT first_blow_ns FROM billets ORDER BY id")
            .and_then(|mut s| s.query_map([], |r| r.get(0))?.collect())
            .expect("rows");
        assert_eq!(firsts, [10, 500]);
    }

    #[test]
    fn a_version_2_database_keeps_its_billets_and_takes_their_first_blows_times() {
        let path = temp_db("v2");
        let conn = Connection::open(&path).expect("opens");
        conn.execute_batch(schema::MIGRATIONS[0]).and_then(|_| conn.execute_batch(schema::MIGRATIONS[1])).expect("v2");
        conn.pragma_update(None, "user_version", 2).expect("set");
        conn.execute_batch(
            "INSERT INTO blows (wall_time_ns, billet, billet_blow, blow, t_contact_s, class) VALUES (70, 1, 1, 1, 5.0, 'soft');
             INSERT INTO blows (wall_time_ns, billet, billet_blow, blow, t_contact_s, class) VALUES (80, 1, 2, 2, 6.0, 'soft');
             INSERT INTO billets (wall_time_ns, billet, t_start_s, t_end_s, blows, incomplete_blows, implausible_blows,
                 energies_partial, hard_blows, alerts, checked_blows, finished, lot)
                 VALUES (90, 1, 5.0, 6.0, 2, 0, 0, 0, 0, 0, 0, 1, '4711');",
        )
        .expect("rows");
        drop(conn);
        let h = History::open(&path, None).expect("migrates");
        let (lot, first): (String, i64) = h
            .connection()
            .query_row("SELECT lot, first_blow_ns FROM billets", [], |r| Ok((r.get(0)?, r.get(1)?)))
            .expect("the row kept");
        assert_eq!((lot.as_str(), first), ("4711", 70));
    }

    #[test]
    fn rows_carry_the_recorded_trace_until_it_changes() {
        let mut h = History::open(&temp_db("trace"), None).expect("opens");
        let blow = |b: u32| {
            let mut e = estimate(true);
            e.blow = b;
            Payload::Result(Box::new(e))
        };
        h.ingest(&[
            (1, part("lot = \"4711\"\ndie_set = \"17\"\n")),
            (2, blow(1)),
            (3, part("part_id = \"P-2\"\nlot = \"4711\"\n")),
            (4, blow(2)),
            // Not a trace: left out, the one in force kept.
            (5, part("lot = 4711\n")),
            (6, blow(3)),
        ])
        .expect("written");
        let rows: Vec<(Option<String>, Option<String>, Option<String>)> = h
            .connection()
            .prepare("SELECT part_id, lot, die_set FROM blows ORDER BY blow")
            .and_then(|mut s| s.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))?.collect())
            .expect("rows");
        let s = |x: &str| Some(x.to_string());
        assert_eq!(rows, [(None, s("4711"), s("17")), (s("P-2"), s("4711"), None), (s("P-2"), s("4711"), None)]);
    }

    #[test]
    fn blows_count_on_their_die_set_and_a_die_change_starts_a_new_one() {
        let mut h = History::open(&temp_db("dies"), None).expect("opens");
        let blow = |b: u32| {
            let mut e = estimate(true);
            e.blow = b;
            Payload::Result(Box::new(e))
        };
        let change = Payload::Status(crate::session::die_change_marker());
        let batch = [
            (1, part("die_set = \"17\"\n")),
            (2, blow(1)),
            (3, blow(2)),
            (4, change.clone()),
            (5, blow(3)),
            (6, part("die_set = \"18\"\n")),
            (7, change),
            (8, blow(4)),
        ];
        h.ingest(&batch).expect("written");
        // Again, as a rebuild into the same file: nothing is installed or counted twice.
        h.die = None;
        h.ingest(&batch).expect("written again");
        let dies: Vec<(Option<String>, i64, i64)> = h
            .connection()
            .prepare("SELECT die_set, installed_ns, blows FROM die_sets ORDER BY id")
            .and_then(|mut s| s.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))?.collect())
            .expect("rows");
        let s = |x: &str| Some(x.to_string());
        assert_eq!(dies, [(s("17"), 2, 2), (s("17"), 4, 1), (s("18"), 7, 1)]);
    }

    #[test]
    fn retention_deletes_rows_older_than_keep_days_before_the_newest() {
        let mut h = History::open(&temp_db("keep"), Some(1.0)).expect("opens");
        let day = DAY_NS as i64;
        let blow = |b: u32| {
            let mut e = estimate(false);
            e.blow = b;
            Payload::Result(Box::new(e))
        };
        h.ingest(&[(0, blow(1)), (day / 2, blow(2)), (2 * day, blow(3))]).expect("written");
        assert_eq!(h.prune().expect("pruned"), 2);
        assert_eq!(count(&h, "blows"), 1);
    }
}
