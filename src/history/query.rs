//! Reading the history: the rows of a table under a filter (time, part, lot, die set,
//! recipe, NOK only), each as its columns by name, as `forgemon history query` prints them.

use rusqlite::types::{ToSql, Value as SqlValue};
use rusqlite::{Connection, OpenFlags};
use serde_json::{Map, Value};

use super::HistoryError;

/// The tables a query reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Table {
    Blows,
    Billets,
}

impl Table {
    pub fn name(self) -> &'static str {
        match self {
            Table::Blows => "blows",
            Table::Billets => "billets",
        }
    }
}

/// Which rows: every condition set must hold.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Filter {
    /// Log time (the row's `wall_time_ns`) at or after, ns since the epoch.
    pub since_ns: Option<i64>,
    /// Log time before, ns since the epoch.
    pub until_ns: Option<i64>,
    pub part_id: Option<String>,
    pub lot: Option<String>,
    pub die_set: Option<String>,
    pub recipe: Option<String>,
    /// Blows judged NOK; billets with a NOK blow.
    pub nok: bool,
    pub limit: Option<u64>,
}

impl Filter {
    /// The WHERE clause (with a leading space, or empty) and its parameters, for `table`.
    pub fn clause(&self, table: Table) -> (String, Vec<Box<dyn ToSql>>) {
        let mut terms: Vec<String> = Vec::new();
        let mut params: Vec<Box<dyn ToSql>> = Vec::new();
        let mut term = |sql: &str, p: Box<dyn ToSql>| {
            params.push(p);
            terms.push(sql.replace('?', &format!("?{}", params.len())));
        };
        if let Some(t) = self.since_ns {
            term("wall_time_ns >= ?", Box::new(t));
        }
        if let Some(t) = self.until_ns {
            term("wall_time_ns < ?", Box::new(t));
        }
        for (col, v) in
            [("part_id", &self.part_id), ("lot", &self.lot), ("die_set", &self.die_set), ("recipe", &self.recipe)]
        {
            if let Some(v) = v {
                term(&format!("{col} = ?"), Box::new(v.clone()));
            }
        }
        if self.nok {
            terms.push(match table {
                Table::Blows => "judgement = 'NOK'".into(),
                // The billet's blows: its number, between its start and its summary.
                Table::Billets => {
                    "EXISTS (SELECT 1 FROM blows b WHERE b.judgement = 'NOK' AND b.billet = billets.billet \
                    AND b.t_contact_s >= billets.t_start_s AND b.t_contact_s <= billets.t_end_s \
                    AND b.wall_time_ns <= billets.wall_time_ns)"
                        .into()
                }
            });
        }
        let clause = if terms.is_empty() { String::new() } else { format!(" WHERE {}", terms.join(" AND ")) };
        (clause, params)
    }
}

/// `--since`/`--until`'s text as ns since the epoch.
pub fn parse_time(flag: &str, text: &str) -> anyhow::Result<i64> {
    let t = chrono::DateTime::parse_from_rfc3339(text).map(|t| t.to_utc()).or_else(|_| {
        chrono::NaiveDate::parse_from_str(text, "%Y-%m-%d")
            .map(|d| d.and_hms_opt(0, 0, 0).unwrap_or_default().and_utc())
    });
    let t = t.map_err(|_| {
        anyhow::anyhow!("{flag} {text}: not a time; give RFC 3339 (2026-11-30T06:00:00Z) or a date (2026-11-30)")
    })?;
    t.timestamp_nanos_opt().ok_or_else(|| anyhow::anyhow!("{flag} {text}: out of range"))
}

/// Open `path` to read, refusing a file that is not there (SQLite would create it).
pub fn open_read(path: &std::path::Path) -> Result<Connection, HistoryError> {
    let sql = |source| HistoryError::Sqlite { path: path.to_path_buf(), source };
    let conn = Connection::open_with_flags(path, OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX)
        .map_err(sql)?;
    conn.busy_timeout(std::time::Duration::from_secs(5)).map_err(sql)?;
    Ok(conn)
}

/// The rows of `table` under `filter`, oldest first, each its columns by name (NULL as
/// `null`).
pub fn rows(
    conn: &Connection,
    path: &std::path::Path,
    table: Table,
    filter: &Filter,
) -> Result<Vec<Map<String, Value>>, HistoryError> {
    let sql = |source| HistoryError::Sqlite { path: path.to_path_buf(), source };
    let (clause, params) = filter.clause(table);
    let limit = filter.limit.map(|n| format!(" LIMIT {n}")).unwrap_or_default();
    let text = format!("SELECT * FROM {}{clause} ORDER BY wall_time_ns, id{limit}", table.name());
    let mut stmt = conn.prepare(&text).map_err(sql)?;
    let names: Vec<String> = stmt.column_names().map(|s| s.to_string()).collect();
    let params: Vec<&dyn ToSql> = params.iter().map(|p| p.as_ref()).collect();
    let mut out = Vec::new();
    let mut found = stmt.query(params.as_slice()).map_err(sql)?;
    while let Some(row) = found.next().map_err(sql)? {
        let mut m = Map::new();
        for (i, name) in names.iter().enumerate() {
            let v: SqlValue = row.get(i).map_err(sql)?;
            m.insert(name.clone(), json(v));
        }
        out.push(m);
    }
    Ok(out)
}

/// How a column stores its values (its declared SQLite type).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnType {
    Integer,
    Real,
    Text,
}

/// A table's column: its name, type and whether it may be NULL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Column {
    pub name: String,
    pub kind: ColumnType,
    pub nullable: bool,
}

/// `table`'s columns in their order (`PRAGMA table_info`).
pub fn columns(conn: &Connection, path: &std::path::Path, table: Table) -> Result<Vec<Column>, HistoryError> {
    let sql = |source| HistoryError::Sqlite { path: path.to_path_buf(), source };
    let mut stmt = conn.prepare(&format!("PRAGMA table_info({})", table.name())).map_err(sql)?;
    let found = stmt
        .query_map([], |r| {
            let declared: String = r.get("type")?;
            let kind = match declared.to_ascii_uppercase().as_str() {
                "INTEGER" => ColumnType::Integer,
                "REAL" => ColumnType::Real,
                _ => ColumnType::Text,
            };
            let notnull: i64 = r.get("notnull")?;
            Ok(Column { name: r.get("name")?, kind, nullable: notnull == 0 })
        })
        .map_err(sql)?;
    found.collect::<Result<Vec<_>, _>>().map_err(sql)
}

fn json(v: SqlValue) -> Value {
    match v {
        SqlValue::Null => Value::Null,
        SqlValue::Integer(i) => Value::from(i),
        SqlValue::Real(x) => Value::from(x),
        SqlValue::Text(s) => Value::from(s),
        SqlValue::Blob(b) => Value::from(b),
    }
}
