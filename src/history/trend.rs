//! The dashboard's history page's data (issue 44): the blows under a filter as columns (time,
//! efficiency, plastic energy, blow index, die set, lot, NOK), their trends per die set and per
//! lot, and the individuals/moving-range chart's limits of the efficiency per blow index
//! (`spc::capability`). One query of the blows table and one of the billets table; the page
//! draws what it is given and computes no statistic of its own.

use std::collections::BTreeMap;

use rusqlite::Connection;
use rusqlite::types::ToSql;
use serde::Serialize;

use super::HistoryError;
use super::query::{Filter, Table};

/// What the page shows.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Trend {
    /// Log time of each blow, ms since the epoch (UTC), oldest first.
    pub t_ms: Vec<i64>,
    pub efficiency: Vec<Option<f64>>,
    #[serde(rename = "plastic_J")]
    pub plastic_j: Vec<Option<f64>>,
    pub billet_blow: Vec<u32>,
    /// Index into `die_sets`, per blow.
    pub die: Vec<usize>,
    /// Index into `lots`, per blow.
    pub lot: Vec<usize>,
    /// Judged NOK.
    pub nok: Vec<bool>,
    /// The die sets and lots seen, in order of first appearance (`null`: none given).
    pub die_sets: Vec<Option<String>>,
    pub lots: Vec<Option<String>>,
    pub by_die: Vec<Group>,
    pub by_lot: Vec<Group>,
    /// The efficiency's I-MR chart per blow index (two blows or more).
    pub spc: Vec<BlowChart>,
}

/// The blows of one die set or lot.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Group {
    pub name: Option<String>,
    pub blows: u64,
    /// Billet summaries under the filter (the billets table).
    pub billets: u64,
    pub nok: u64,
    pub hard: u64,
    pub mean_efficiency: Option<f64>,
    pub first_ms: i64,
    pub last_ms: i64,
}

/// The efficiency's individuals and moving-range chart at one blow index.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlowChart {
    pub blow: u32,
    pub n: usize,
    pub mean: f64,
    pub x_lcl: f64,
    pub x_ucl: f64,
    pub mr_bar: f64,
    pub mr_ucl: f64,
}

/// The index of `name` in `names`, added at the end when new.
fn index_of(names: &mut Vec<Option<String>>, name: Option<String>) -> usize {
    names.iter().position(|n| *n == name).unwrap_or_else(|| {
        names.push(name);
        names.len() - 1
    })
}

/// The page's data for the rows under `filter` (its `limit` is ignored: a trend is all of it).
pub fn trend(conn: &Connection, path: &std::path::Path, filter: &Filter) -> Result<Trend, HistoryError> {
    let sql = |source| HistoryError::Sqlite { path: path.to_path_buf(), source };
    let (clause, params) = filter.clause(Table::Blows);
    let text = format!(
        "SELECT wall_time_ns, efficiency, plastic_J, billet_blow, die_set, lot, judgement, class \
         FROM blows{clause} ORDER BY wall_time_ns, id"
    );
    let params: Vec<&dyn ToSql> = params.iter().map(|p| p.as_ref()).collect();
    let mut stmt = conn.prepare(&text).map_err(sql)?;
    let mut rows = stmt.query(params.as_slice()).map_err(sql)?;
    let mut t = Trend::default();
    let mut hard = Vec::new();
    while let Some(r) = rows.next().map_err(sql)? {
        t.t_ms.push(r.get::<_, i64>(0).map_err(sql)?.div_euclid(1_000_000));
        t.efficiency.push(r.get(1).map_err(sql)?);
        t.plastic_j.push(r.get(2).map_err(sql)?);
        t.billet_blow.push(r.get(3).map_err(sql)?);
        let die = index_of(&mut t.die_sets, r.get(4).map_err(sql)?);
        t.die.push(die);
        let lot = index_of(&mut t.lots, r.get(5).map_err(sql)?);
        t.lot.push(lot);
        t.nok.push(r.get::<_, Option<String>>(6).map_err(sql)?.as_deref() == Some("NOK"));
        hard.push(r.get::<_, String>(7).map_err(sql)? == "hard");
    }
    let billets_by = |col: &str| billets_per(conn, path, filter, col);
    t.by_die = groups(&t, &t.die, &t.die_sets, &hard, &billets_by("die_set")?);
    t.by_lot = groups(&t, &t.lot, &t.lots, &hard, &billets_by("lot")?);
    t.spc = charts(&t);
    Ok(t)
}

/// Billet summaries under `filter` per value of `col`.
fn billets_per(
    conn: &Connection,
    path: &std::path::Path,
    filter: &Filter,
    col: &str,
) -> Result<BTreeMap<Option<String>, u64>, HistoryError> {
    let sql = |source| HistoryError::Sqlite { path: path.to_path_buf(), source };
    let billets = Filter { nok: false, limit: None, ..filter.clone() };
    let (clause, params) = billets.clause(Table::Billets);
    let mut stmt = conn.prepare(&format!("SELECT {col}, COUNT(*) FROM billets{clause} GROUP BY {col}")).map_err(sql)?;
    let params: Vec<&dyn ToSql> = params.iter().map(|p| p.as_ref()).collect();
    let found = stmt
        .query_map(params.as_slice(), |r| Ok((r.get(0)?, u64::try_from(r.get::<_, i64>(1)?).unwrap_or(0))))
        .map_err(sql)?;
    found.collect::<Result<_, _>>().map_err(sql)
}

/// One group per name, from the blows' indices into `names`.
fn groups(
    t: &Trend,
    index: &[usize],
    names: &[Option<String>],
    hard: &[bool],
    billets: &BTreeMap<Option<String>, u64>,
) -> Vec<Group> {
    let mut out: Vec<Group> = names
        .iter()
        .map(|n| Group { name: n.clone(), billets: billets.get(n).copied().unwrap_or(0), ..Group::default() })
        .collect();
    let mut sums = vec![(0.0, 0u64); names.len()];
    for (i, &g) in index.iter().enumerate() {
        let grp = &mut out[g];
        if grp.blows == 0 {
            grp.first_ms = t.t_ms[i];
        }
        grp.blows += 1;
        grp.last_ms = t.t_ms[i];
        grp.nok += u64::from(t.nok[i]);
        grp.hard += u64::from(hard[i]);
        if let Some(e) = t.efficiency[i] {
            sums[g].0 += e;
            sums[g].1 += 1;
        }
    }
    for (grp, (sum, n)) in out.iter_mut().zip(sums) {
        grp.mean_efficiency = (n > 0).then(|| sum / n as f64);
    }
    out
}

/// The efficiency's I-MR chart per blow index, over the blows with one, in time order.
fn charts(t: &Trend) -> Vec<BlowChart> {
    let mut by_blow: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for (b, e) in t.billet_blow.iter().zip(&t.efficiency) {
        if let Some(e) = e {
            by_blow.entry(*b).or_default().push(*e);
        }
    }
    by_blow
        .into_iter()
        .filter_map(|(blow, xs)| {
            // No window here: the limits are the chart's, not the recipe's.
            let c = super::spc::capability(&xs, 0.0, 0.0)?;
            Some(BlowChart {
                blow,
                n: c.n,
                mean: c.mean,
                x_lcl: c.x_lcl,
                x_ucl: c.x_ucl,
                mr_bar: c.mr_bar,
                mr_ucl: c.mr_ucl,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_count_and_average_their_own_blows() {
        let t = Trend {
            t_ms: vec![1, 2, 3, 4],
            efficiency: vec![Some(0.9), Some(0.7), None, Some(0.5)],
            nok: vec![false, true, false, true],
            ..Trend::default()
        };
        let names = vec![Some("17".to_string()), None];
        let billets = BTreeMap::from([(Some("17".to_string()), 2)]);
        let g = groups(&t, &[0, 1, 0, 0], &names, &[false, false, false, true], &billets);
        assert_eq!((g[0].blows, g[0].nok, g[0].hard, g[0].billets), (3, 1, 1, 2));
        assert!((g[0].mean_efficiency.unwrap() - 0.7).abs() < 1e-12, "(0.9 + 0.5) / 2: a blow without one left out");
        assert_eq!((g[0].first_ms, g[0].last_ms), (1, 4));
        assert_eq!((g[1].blows, g[1].billets, g[1].mean_efficiency), (1, 0, Some(0.7)));
    }
}
