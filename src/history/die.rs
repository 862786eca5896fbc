//! Die life (issue 44): what a die set has taken since it was put in, counted the same way
//! live (the service's `/status` and `die_life` alert) and in the history database's
//! `die_sets` table (`History::ingest`, so a rebuild counts as the service did).
//!
//! A die set is one installation: a die change (`POST /die`, recorded as the `die_change`
//! marker) starts a new one from zero, under the name in force then (the same name for
//! reworked dies). Blows count on the latest installation of the trace's `die_set` name;
//! blows before any name was given count on an unnamed one.

use rusqlite::{Connection, OptionalExtension, params};
use serde::Serialize;

use crate::config::history::DieLifeConfig;
use crate::estimate::result::{BlowClass, BlowEstimate};

/// What one installation of a die set has taken.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DieCount {
    /// Its name (`die_set`), `None` when none was given.
    pub die_set: Option<String>,
    /// When it was put in (the first blow's or the die change's log time), ns since the epoch.
    pub installed_ns: i64,
    pub blows: u64,
    pub hard_blows: u64,
    /// Energy the dies took: elastic plus damped, over the blows with energies, J.
    #[serde(rename = "energy_J")]
    pub energy_j: f64,
    /// Blows without energies (incomplete, implausible): counted in `blows`, not in the
    /// energy, which is that much short.
    pub blows_without_energy: u64,
}

/// Where a die set stands against `[die_life]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DieLevel {
    #[default]
    Ok,
    Warning,
    Limit,
}

impl DieCount {
    pub fn new(die_set: Option<String>, installed_ns: i64) -> Self {
        DieCount { die_set, installed_ns, ..DieCount::default() }
    }

    /// Count blow `e`.
    pub fn add(&mut self, e: &BlowEstimate) {
        self.blows += 1;
        self.hard_blows += u64::from(e.class == BlowClass::Hard);
        match e.elastic_j.zip(e.damped_j) {
            Some((elastic, damped)) if (elastic + damped).is_finite() => self.energy_j += elastic + damped,
            _ => self.blows_without_energy += 1,
        }
    }

    /// The level against `cfg`, and the quantity that set it (blows or energy).
    pub fn level(&self, cfg: &DieLifeConfig) -> (DieLevel, &'static str) {
        let blows = self.blows as f64;
        let at = |limit: Option<f64>, x: f64| limit.is_some_and(|l| x >= l);
        let as_f = |v: Option<u64>| v.map(|v| v as f64);
        if at(as_f(cfg.limit_blows), blows) {
            (DieLevel::Limit, "blows")
        } else if at(cfg.limit_energy_j, self.energy_j) {
            (DieLevel::Limit, "energy")
        } else if at(as_f(cfg.warn_blows), blows) {
            (DieLevel::Warning, "blows")
        } else if at(cfg.warn_energy_j, self.energy_j) {
            (DieLevel::Warning, "energy")
        } else {
            (DieLevel::Ok, "")
        }
    }

    /// The alert's words at `level`, reached by `quantity`.
    pub fn reason(&self, level: DieLevel, quantity: &str, cfg: &DieLifeConfig) -> String {
        let name = self.die_set.as_deref().map_or("the unnamed die set".to_string(), |n| format!("die set {n}"));
        let (warn, limit, now, unit) = match quantity {
            "blows" => {
                (cfg.warn_blows.map(|v| v as f64), cfg.limit_blows.map(|v| v as f64), self.blows as f64, "blows")
            }
            _ => (cfg.warn_energy_j, cfg.limit_energy_j, self.energy_j / 1e6, "MJ"),
        };
        let scale = if unit == "MJ" { 1e-6 } else { 1.0 };
        let show = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.0}", v * scale));
        let what = match level {
            DieLevel::Limit => "has reached its limit: change the dies",
            _ => "has reached its warning: plan the die change",
        };
        format!(
            "{name} {what} ({now:.0} {unit} taken; warning {}, limit {}; {} hard blows)",
            show(warn),
            show(limit),
            self.hard_blows
        )
    }
}

/// The columns `row` reads, after the row id.
const COLUMNS: &str = "id, die_set, installed_ns, blows, hard_blows, energy_J, blows_without_energy";

/// A `die_sets` row selected with `COLUMNS`: its id and count.
fn row(r: &rusqlite::Row<'_>) -> rusqlite::Result<(i64, DieCount)> {
    let count = |i: usize| r.get::<_, i64>(i).map(|n| n.max(0) as u64);
    Ok((
        r.get(0)?,
        DieCount {
            die_set: r.get(1)?,
            installed_ns: r.get(2)?,
            blows: count(3)?,
            hard_blows: count(4)?,
            energy_j: r.get(5)?,
            blows_without_energy: count(6)?,
        },
    ))
}

/// The latest installation of every name in the database (`None`: the unnamed set).
pub fn all_latest(conn: &Connection) -> rusqlite::Result<Vec<DieCount>> {
    let sql = format!(
        "SELECT {COLUMNS} FROM die_sets WHERE id IN (SELECT max(id) FROM die_sets GROUP BY COALESCE(die_set, ''))"
    );
    let mut stmt = conn.prepare(&sql)?;
    let rows = stmt.query_map([], |r| row(r).map(|(_, c)| c))?;
    rows.collect()
}

/// The latest installation of `name` in the database, with its row id.
pub fn latest(conn: &Connection, name: Option<&str>) -> rusqlite::Result<Option<(i64, DieCount)>> {
    let sql = format!("SELECT {COLUMNS} FROM die_sets WHERE die_set IS ?1 ORDER BY id DESC LIMIT 1");
    conn.query_row(&sql, params![name], row).optional()
}

/// The installation of `count`'s die set at its `installed_ns`: a new row, or the one
/// already there (a marker ingested again), with its row id and stored count.
pub(super) fn install(conn: &Connection, count: &DieCount) -> rusqlite::Result<(i64, DieCount)> {
    conn.execute(
        "INSERT OR IGNORE INTO die_sets (die_set, installed_ns, blows, hard_blows, energy_J, blows_without_energy)
         VALUES (?1, ?2, 0, 0, 0, 0)",
        params![count.die_set, count.installed_ns],
    )?;
    let sql = format!("SELECT {COLUMNS} FROM die_sets WHERE die_set IS ?1 AND installed_ns = ?2");
    conn.query_row(&sql, params![count.die_set, count.installed_ns], row)
}

/// Write `count` to its row `id`, last touched at `t`.
pub(super) fn store(conn: &Connection, id: i64, count: &DieCount, t: i64) -> rusqlite::Result<usize> {
    conn.execute(
        "UPDATE die_sets SET blows = ?2, hard_blows = ?3, energy_J = ?4, blows_without_energy = ?5, last_ns = ?6
         WHERE id = ?1",
        params![id, count.blows as i64, count.hard_blows as i64, count.energy_j, count.blows_without_energy as i64, t],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blow(class: BlowClass, elastic: Option<f64>, damped: Option<f64>) -> BlowEstimate {
        BlowEstimate { class, elastic_j: elastic, damped_j: damped, ..BlowEstimate::incomplete(1, 0.5, 3.9, 0.6) }
    }

    #[test]
    fn a_die_set_counts_blows_hard_blows_and_the_energy_the_dies_took() {
        let mut d = DieCount::new(Some("17".into()), 0);
        d.add(&blow(BlowClass::Soft, Some(20.0), Some(270.0)));
        d.add(&blow(BlowClass::Hard, Some(900.0), Some(300.0)));
        d.add(&blow(BlowClass::Incomplete, None, None));
        assert_eq!((d.blows, d.hard_blows, d.blows_without_energy), (3, 1, 1));
        assert_eq!(d.energy_j, 20.0 + 270.0 + 900.0 + 300.0);
    }

    #[test]
    fn the_level_is_the_worst_of_blows_and_energy() {
        let cfg = DieLifeConfig {
            warn_blows: Some(2),
            limit_blows: Some(4),
            warn_energy_j: Some(1000.0),
            limit_energy_j: None,
        };
        let mut d = DieCount::new(None, 0);
        assert_eq!(d.level(&cfg), (DieLevel::Ok, ""));
        d.add(&blow(BlowClass::Soft, Some(600.0), Some(600.0)));
        assert_eq!(d.level(&cfg), (DieLevel::Warning, "energy"));
        d.add(&blow(BlowClass::Soft, Some(0.0), Some(0.0)));
        assert_eq!(d.level(&cfg).0, DieLevel::Warning);
        d.add(&blow(BlowClass::Soft, Some(0.0), Some(0.0)));
        d.add(&blow(BlowClass::Soft, Some(0.0), Some(0.0)));
        assert_eq!(d.level(&cfg), (DieLevel::Limit, "blows"));
        let words = d.reason(DieLevel::Limit, "blows", &cfg);
        assert!(words.contains("unnamed die set has reached its limit") && words.contains("4 blows"), "{words}");
    }
}
