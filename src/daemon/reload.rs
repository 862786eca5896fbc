//! SIGHUP: the service file and every file it names are read and checked again as a start
//! checks them (`ServiceParts::load`) before anything is taken; a file that fails keeps
//! everything in force, and says why in the log and in `/status` (`reload`). What passes
//! is compared with what is in force: the alert rules and the machine model are taken (and
//! recorded where they took effect, so a replay takes them there too); any other changed key
//! is named as needing a restart (`config::reload::needs_restart`), in the log and in
//! `/status`, and never reported as applied.

use std::path::PathBuf;

use serde::Serialize;

use super::{ServiceParts, host_now_ns};
use crate::alert::AlertConfig;
use crate::config::service::ServiceConfig;

/// What the service runs with, as a reload compares it: the configuration and the texts of
/// the files it read.
pub(super) struct InForce {
    pub config_path: PathBuf,
    pub config: ServiceConfig,
    pub machine_kind: &'static str,
    pub machine_text: String,
    pub process_text: Option<String>,
    pub recipe_text: Option<String>,
}

impl InForce {
    pub fn new(parts: &ServiceParts, recipe_text: Option<String>) -> Self {
        InForce {
            config_path: parts.config_path.clone(),
            config: parts.config.clone(),
            machine_kind: parts.machine.kind().as_str(),
            machine_text: parts.machine_text.clone(),
            process_text: parts.process_text.clone(),
            recipe_text,
        }
    }
}

/// The last SIGHUP reload, as `/status` shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReloadReport {
    /// When it happened, s since the Unix epoch.
    pub at_unix_s: f64,
    /// What was taken: `alerts` (the alert rules), `machine` (the machine model).
    pub applied: Vec<String>,
    /// Keys that changed but take effect only at a restart (`http.listen`, `sources`, ...);
    /// the values in force stay.
    pub needs_restart: Vec<String>,
    /// Why nothing was taken (a file missing or failing its check), `None` when it passed.
    pub error: Option<String>,
}

impl ReloadReport {
    pub fn new(applied: Vec<String>, needs_restart: Vec<String>, error: Option<String>) -> Self {
        ReloadReport { at_unix_s: host_now_ns() as f64 * 1e-9, applied, needs_restart, error }
    }
}

/// What a reload found to take, each `None` when unchanged, and what needs a restart.
pub(super) struct Plan {
    /// The new alert rules, with the service file's text to record.
    pub alerts: Option<(AlertConfig, String)>,
    /// The machine file: its path and text.
    pub model: Option<(PathBuf, String)>,
    pub needs_restart: Vec<String>,
    /// The process sheet's warnings, to log.
    pub warnings: Vec<String>,
}

/// Read and check the service file in force again with every file it names, and compare.
/// Nothing is taken here.
pub(super) fn plan(in_force: &InForce) -> anyhow::Result<Plan> {
    let (next, warnings) = ServiceParts::load(&in_force.config_path)?;
    let recipe_text = super::parts::read_recipe(&next.config, next.machine.kind().as_str())?.map(|(_, t)| t);
    let mut needs_restart: Vec<String> =
        crate::config::reload::needs_restart(&in_force.config, &next.config).into_iter().map(String::from).collect();
    // The same path with another text: the file changed, and it is read only at the start.
    for (key, changed) in
        [("process", next.process_text != in_force.process_text), ("recipe", recipe_text != in_force.recipe_text)]
    {
        if changed && !needs_restart.iter().any(|k| k == key) {
            needs_restart.push(key.to_string());
        }
    }
    let new_model =
        next.machine_text != in_force.machine_text || next.config.machine_path != in_force.config.machine_path;
    let model = if next.machine.kind().as_str() != in_force.machine_kind {
        // Another kind of machine: its routes, status and recipes are the old kind's.
        needs_restart.push("machine".to_string());
        None
    } else {
        new_model.then(|| (next.config.machine_path.clone(), next.machine_text.clone()))
    };
    let alerts = (next.config.alerts != in_force.config.alerts).then(|| (next.config.alerts, next.config_text.clone()));
    Ok(Plan { alerts, model, needs_restart, warnings })
}
