//! Switching the active recipe while the service runs (issue 20, docs/interfaces.md §9): `POST
//! /recipe` with a recipe file's text as the body makes it the one every following blow is
//! judged against; `DELETE /recipe` stops judging. The forge changes parts several times a
//! day, and a restart would cut the recording.
//!
//! The text is checked here, before anything changes, by the check every recipe file gets
//! (`config::recipe::parse_recipe`): a bad file is refused with its line and key and the
//! allowed range (400), a recipe for another kind of machine too (409), a body longer than a
//! recipe may be (`limits::RECIPE_BYTES`) before it is read (413), and the recipe in force
//! stays. An accepted one is recorded (`/config`, `recipe.toml`) where it took effect, so
//! that a replay switches at the same point; "no recipe" is recorded as an empty text. The
//! answers quote the client's text only escaped, so a name cannot carry a control sequence
//! back to a terminal.

use axum::Router;
use axum::extract::rejection::StringRejection;
use axum::extract::{DefaultBodyLimit, State};
use axum::http::StatusCode;
use axum::response::IntoResponse;
use axum::routing::post;
use tokio::sync::mpsc;

use crate::config::limits::RECIPE_BYTES;
use crate::recipe::Recipe;

/// Where a recipe sent over HTTP is said to come from in its errors.
pub const ORIGIN: &str = "POST /recipe";

/// A recipe to judge with from now on (`None`: stop judging), with its text to record.
#[derive(Debug, Clone)]
pub struct RecipeChange {
    pub recipe: Option<Recipe>,
    pub text: String,
}

/// The recipe a recorded `recipe.toml` text holds: `None` for the empty text that records
/// "no recipe from here on".
pub fn from_recorded(origin: &str, text: &str) -> Result<Option<Recipe>, crate::config::ConfigError> {
    if text.trim().is_empty() { Ok(None) } else { crate::config::recipe::parse_recipe(origin, text).map(Some) }
}

#[derive(Clone)]
struct Shared {
    tx: mpsc::Sender<RecipeChange>,
    machine: String,
}

/// `POST /recipe` and `DELETE /recipe` for a service running a `machine` (its kind).
pub fn routes(tx: mpsc::Sender<RecipeChange>, machine: &str) -> Router {
    let limit = DefaultBodyLimit::max(RECIPE_BYTES.max as usize);
    Router::new()
        .route("/recipe", post(switch).delete(clear))
        .layer(limit)
        .with_state(Shared { tx, machine: machine.to_string() })
}

async fn switch(State(s): State<Shared>, body: Result<String, StringRejection>) -> impl IntoResponse {
    let body = match body {
        Ok(b) => b,
        Err(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => {
            let why = format!("{ORIGIN}: the body is longer than the {} bytes a recipe may have\n", RECIPE_BYTES.max);
            return (StatusCode::PAYLOAD_TOO_LARGE, why);
        }
        Err(e) => return (e.status(), format!("{ORIGIN}: {}\n", printable(&e.body_text()))),
    };
    let recipe = match crate::config::recipe::parse_recipe(ORIGIN, &body) {
        Ok(r) => r,
        Err(e) => return (StatusCode::BAD_REQUEST, format!("{}\n", printable(&e.to_string()))),
    };
    if recipe.machine != s.machine {
        let why =
            format!("recipe '{}' was taught on a {}; this machine is a {}\n", recipe.name, recipe.machine, s.machine);
        return (StatusCode::CONFLICT, why);
    }
    let name = recipe.name.clone();
    send(
        &s.tx,
        RecipeChange { recipe: Some(recipe), text: body },
        format!("recipe '{name}' judges from the next blow\n"),
    )
    .await
}

/// `text` with every control character escaped (`\n`, `\u{1b}`), cut after 1000 characters:
/// what an answer may quote of what the client sent.
fn printable(text: &str) -> String {
    let cut: String = text.chars().take(1000).collect();
    cut.chars().flat_map(|c| if c.is_control() { c.escape_default().collect() } else { vec![c] }).collect()
}

async fn clear(State(s): State<Shared>) -> impl IntoResponse {
    send(&s.tx, RecipeChange { recipe: None, text: String::new() }, "no recipe: blows are not judged\n".into()).await
}

async fn send(tx: &mpsc::Sender<RecipeChange>, change: RecipeChange, ok: String) -> (StatusCode, String) {
    match tx.send(change).await {
        Ok(()) => (StatusCode::ACCEPTED, ok),
        Err(_) => (StatusCode::SERVICE_UNAVAILABLE, "the service is stopping\n".into()),
    }
}
