//! The operator's screen (issue 19, face 1): `GET /` on the service's HTTP server, one page
//! whose assets are compiled into the binary (no CDN; plant PCs have no internet). It shows
//! what the pipeline produced and nothing it computes itself: the state comes from the
//! status snapshot (`GET /dashboard/state`, `GET /blow/last/curve`), and the live feed
//! (`daemon::live`) arrives as server-sent events on `GET /events`; the page fetches the
//! state again on each event and whenever its event stream (re)connects, so it follows a
//! service restart by itself. `POST /ack` acknowledges the latched alert. `auth` guards the
//! whole server when a token is configured.

pub mod auth;
pub mod board;
pub mod history_page;

use std::convert::Infallible;

use axum::Router;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use futures_util::Stream;
use futures_util::future::BoxFuture;
use serde::Serialize;
use tokio::sync::broadcast::error::RecvError;
use tokio::sync::mpsc;

use super::Control;
use super::faces::{Face, FaceContext, boxed};
use super::live::{Live, LiveEvent};
use super::status::{SharedStatus, StatusSnapshot};
use board::Board;

const INDEX_HTML: &str = include_str!("index.html");
const DASHBOARD_JS: &str = include_str!("dashboard.js");
const DASHBOARD_CSS: &str = include_str!("dashboard.css");

/// What the handlers share.
#[derive(Clone)]
struct Shared {
    status: SharedStatus,
    control: mpsc::Sender<Control>,
    live: Live,
}

/// The dashboard as a face: its routes on the service's HTTP listener. Always on (the
/// listener is the service's `[http]`); it stops with the listener.
pub fn face<'a>(ctx: &'a FaceContext<'a>) -> BoxFuture<'a, anyhow::Result<Option<Box<dyn Face>>>> {
    ctx.serve_routes(routes(ctx.status.clone(), ctx.control.clone(), ctx.bus.clone()));
    ctx.serve_routes(history_page::routes(ctx.config.history.as_ref().map(|h| h.path.clone())));
    Box::pin(async { Ok(boxed(Some(Dashboard))) })
}

/// The running dashboard: its routes are served by the service's listener.
struct Dashboard;

impl Face for Dashboard {}

/// The dashboard's routes: `/`, its assets, `/dashboard/state`, `/blow/last/curve`,
/// `/events` and `POST /ack`.
pub fn routes(status: SharedStatus, control: mpsc::Sender<Control>, live: Live) -> Router {
    Router::new()
        .route("/", get(|| asset(INDEX_HTML, "text/html; charset=utf-8")))
        .route("/dashboard.js", get(|| asset(DASHBOARD_JS, "text/javascript; charset=utf-8")))
        .route("/dashboard.css", get(|| asset(DASHBOARD_CSS, "text/css; charset=utf-8")))
        .route("/dashboard/state", get(state))
        .route("/blow/last/curve", get(curve))
        .route("/events", get(events))
        .route("/ack", post(ack))
        .with_state(Shared { status, control, live })
}

async fn asset(body: &'static str, content_type: &'static str) -> Response {
    ([(header::CONTENT_TYPE, content_type), (header::CACHE_CONTROL, "no-cache")], body).into_response()
}

/// `GET /dashboard/state`: the status snapshot, the board, and each source's sample rate
/// measured now (`Board::rates_hz`), as one JSON object.
#[derive(Serialize)]
struct DashboardState<'a> {
    status: &'a StatusSnapshot,
    #[serde(flatten)]
    board: &'a Board,
    source_rate_hz: std::collections::BTreeMap<String, Option<f64>>,
}

fn json(body: Result<String, serde_json::Error>) -> Response {
    match body {
        Ok(b) => ([(header::CONTENT_TYPE, "application/json")], b).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("cannot serialise: {e}\n")).into_response(),
    }
}

async fn state(State(sh): State<Shared>) -> Response {
    match sh.status.lock() {
        Ok(s) => {
            let source_rate_hz = s.board.rates_hz(super::host_now_ns());
            json(serde_json::to_string(&DashboardState { status: &s, board: &s.board, source_rate_hz }))
        }
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "the status is unavailable\n").into_response(),
    }
}

/// `GET /blow/last/curve`: the last blow's measured and modelled load (`estimate::curve`).
async fn curve(State(sh): State<Shared>) -> Response {
    let c = sh.status.lock().ok().and_then(|s| s.board.curve.clone());
    match c {
        Some(c) => json(serde_json::to_string(&*c)),
        None => (StatusCode::NOT_FOUND, "no blow yet\n").into_response(),
    }
}

/// `POST /ack`: acknowledge the latched alert (the service publishes `Acknowledged`).
async fn ack(State(sh): State<Shared>) -> Response {
    match sh.control.try_send(Control::Acknowledge) {
        Ok(()) => (StatusCode::ACCEPTED, "acknowledged\n").into_response(),
        Err(_) => (StatusCode::SERVICE_UNAVAILABLE, "the service is busy or stopping\n").into_response(),
    }
}

/// The server-sent event for a live event: its name, and the result as JSON; none for the
/// status snapshot (the page reads `/dashboard/state` on each event instead).
fn sse_event(e: &LiveEvent) -> Option<Event> {
    let named = |name: &str, data: Result<String, serde_json::Error>| {
        Event::default().event(name).data(data.unwrap_or_else(|_| "null".into()))
    };
    Some(match e {
        LiveEvent::Blow(b) => named("blow", serde_json::to_string(&**b)),
        LiveEvent::Billet(b) => named("billet", serde_json::to_string(&**b)),
        LiveEvent::Advice(a) => named("advice", serde_json::to_string(&**a)),
        LiveEvent::NewBillet => Event::default().event("new_billet").data("{}"),
        LiveEvent::Acknowledged => Event::default().event("ack").data("{}"),
        LiveEvent::Alert { alert, .. } => named("alert", serde_json::to_string(&**alert)),
        LiveEvent::Stopping => Event::default().event("stopping").data("{}"),
        LiveEvent::Status(_) => return None,
    })
}

/// `GET /events`: the live feed as server-sent events (`blow`, `alert`, `billet`,
/// `new_billet`, `advice`, `ack`, `stopping`; `resync` with the count when this client fell
/// behind and lost events).
async fn events(State(sh): State<Shared>) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let stream = futures_util::stream::unfold(sh.live.subscribe(), |mut rx| async move {
        let ev = loop {
            match rx.recv().await {
                Ok(e) => match sse_event(&e) {
                    Some(ev) => break ev,
                    None => continue,
                },
                Err(RecvError::Lagged(n)) => {
                    tracing::debug!(lost = n, "a dashboard fell behind the live feed");
                    break Event::default().event("resync").data(n.to_string());
                }
                Err(RecvError::Closed) => return None,
            }
        };
        Some((Ok(ev), rx))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The page loads only its own assets: nothing from another host (plant PCs have no
    /// internet), and every element the script fills exists in the page.
    #[test]
    fn the_page_is_self_contained_and_its_script_finds_its_elements() {
        for (name, text) in
            [("index.html", INDEX_HTML), ("dashboard.js", DASHBOARD_JS), ("dashboard.css", DASHBOARD_CSS)]
        {
            for remote in ["http://", "https://", "//cdn", "@import"] {
                assert!(!text.contains(remote), "{name} refers to {remote}");
            }
        }
        let ids: Vec<&str> = DASHBOARD_JS.split("$(\"").skip(1).filter_map(|s| s.split('"').next()).collect();
        assert!(ids.len() > 10, "{ids:?}");
        for id in ids {
            assert!(INDEX_HTML.contains(&format!("id=\"{id}\"")), "dashboard.js uses #{id}, absent from index.html");
        }
    }
}
