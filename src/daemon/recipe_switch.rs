//! Switching the active recipe while the service runs (issue 20, CONTRACTS §9): `POST
//! /recipe` with a recipe file's text as the body makes it the one every following blow is
//! judged against; `DELETE /recipe` stops judging. The forge changes parts several times a
//! day, and a restart would cut the recording.
//!
//! The text is checked here, before anything changes: a bad file is refused with its line
//! and key (400), a recipe for another kind of machine too (409), and the recipe in force
//! stays. An accepted one is recorded (`/config`, `recipe.toml`) where it took effect, so
//! that a replay switches at the same point; "no recipe" is recorded as an empty text.

use axum::Router;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::IntoResponse;
use axum::routing::post;
use tokio::sync::mpsc;

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
    Router::new().route("/recipe", post(switch).delete(clear)).with_state(Shared { tx, machine: machine.to_string() })
}

async fn switch(State(s): State<Shared>, body: String) -> impl IntoResponse {
    let recipe = match crate::config::recipe::parse_recipe(ORIGIN, &body) {
        Ok(r) => r,
        Err(e) => return (StatusCode::BAD_REQUEST, format!("{e}\n")),
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

async fn clear(State(s): State<Shared>) -> impl IntoResponse {
    send(&s.tx, RecipeChange { recipe: None, text: String::new() }, "no recipe: blows are not judged\n".into()).await
}

async fn send(tx: &mpsc::Sender<RecipeChange>, change: RecipeChange, ok: String) -> (StatusCode, String) {
    match tx.send(change).await {
        Ok(()) => (StatusCode::ACCEPTED, ok),
        Err(_) => (StatusCode::SERVICE_UNAVAILABLE, "the service is stopping\n".into()),
    }
}
