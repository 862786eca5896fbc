//! The dashboard's history page (issue 44): `GET /history` and its script, and
//! `GET /history/data?since=&until=&die=&lot=&part=&recipe=` with the trends of the history
//! database under those filters (`history::trend`): each blow's efficiency over time by die
//! set, the die sets' and lots' tables, and the efficiency's individuals/moving-range chart
//! per blow index. The database is opened read-only for each request (SQLite's WAL lets it
//! read while the writer writes), on a blocking thread.

use std::path::PathBuf;

use axum::Router;
use axum::extract::{Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::Deserialize;

use crate::history::query::{Filter, open_read};
use crate::history::trend::trend;

const HISTORY_HTML: &str = include_str!("history.html");
const HISTORY_JS: &str = include_str!("history.js");

/// The filters the page sends: times as RFC 3339 or a date, as `forgemon history query`'s.
#[derive(Debug, Default, Deserialize)]
pub struct Params {
    since: Option<String>,
    until: Option<String>,
    die: Option<String>,
    lot: Option<String>,
    part: Option<String>,
    recipe: Option<String>,
}

/// An empty form field is no filter.
fn given(v: &Option<String>) -> Option<String> {
    v.as_deref().map(str::trim).filter(|s| !s.is_empty()).map(str::to_string)
}

impl Params {
    fn filter(&self) -> Result<Filter, String> {
        let time = |flag: &str, v: &Option<String>| {
            given(v).map(|t| crate::history::query::parse_time(flag, &t).map_err(|e| e.to_string())).transpose()
        };
        Ok(Filter {
            since_ns: time("since", &self.since)?,
            until_ns: time("until", &self.until)?,
            part_id: given(&self.part),
            lot: given(&self.lot),
            die_set: given(&self.die),
            recipe: given(&self.recipe),
            ..Filter::default()
        })
    }
}

/// The page's routes; `db` is `[history] path`, `None` when the history is off.
pub fn routes(db: Option<PathBuf>) -> Router {
    Router::new()
        .route("/history", get(|| page(HISTORY_HTML, "text/html; charset=utf-8")))
        .route("/history.js", get(|| page(HISTORY_JS, "text/javascript; charset=utf-8")))
        .route("/history/data", get(data))
        .with_state(db)
}

/// The page over `db` on a server of its own (`forgemon history serve`), with the
/// dashboard's style sheet.
pub fn standalone(db: PathBuf) -> Router {
    routes(Some(db)).route("/dashboard.css", get(|| page(super::DASHBOARD_CSS, "text/css; charset=utf-8")))
}

async fn page(body: &'static str, content_type: &'static str) -> Response {
    ([(header::CONTENT_TYPE, content_type), (header::CACHE_CONTROL, "no-cache")], body).into_response()
}

async fn data(State(db): State<Option<PathBuf>>, Query(p): Query<Params>) -> Response {
    let Some(db) = db else {
        return (StatusCode::NOT_FOUND, "no history database: [history] enabled = false\n").into_response();
    };
    let filter = match p.filter() {
        Ok(f) => f,
        Err(why) => return (StatusCode::BAD_REQUEST, format!("{why}\n")).into_response(),
    };
    let found = tokio::task::spawn_blocking(move || {
        if !db.is_file() {
            return Err(format!("{}: no history database yet (the first blow makes it)", db.display()));
        }
        let conn = open_read(&db).map_err(|e| e.to_string())?;
        let t = trend(&conn, &db, &filter).map_err(|e| e.to_string())?;
        serde_json::to_string(&t).map_err(|e| e.to_string())
    })
    .await;
    match found {
        Ok(Ok(body)) => ([(header::CONTENT_TYPE, "application/json")], body).into_response(),
        Ok(Err(why)) => (StatusCode::SERVICE_UNAVAILABLE, format!("{why}\n")).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("the query failed: {e}\n")).into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_is_self_contained_and_its_script_finds_its_elements() {
        for (name, text) in [("history.html", HISTORY_HTML), ("history.js", HISTORY_JS)] {
            for remote in ["http://", "https://", "//cdn", "@import"] {
                assert!(!text.contains(remote), "{name} refers to {remote}");
            }
        }
        let ids: Vec<&str> = HISTORY_JS.split("$(\"").skip(1).filter_map(|s| s.split('"').next()).collect();
        assert!(ids.len() > 5, "{ids:?}");
        for id in ids {
            assert!(HISTORY_HTML.contains(&format!("id=\"{id}\"")), "history.js uses #{id}, absent from history.html");
        }
    }

    #[test]
    fn empty_fields_are_no_filter_and_a_bad_time_is_named() {
        let p = Params { die: Some(" ".into()), lot: Some("4711".into()), ..Params::default() };
        let f = p.filter().unwrap();
        assert_eq!((f.die_set, f.lot.as_deref()), (None, Some("4711")));
        let bad = Params { since: Some("yesterday".into()), ..Params::default() };
        assert!(bad.filter().unwrap_err().contains("since yesterday"));
    }
}
