//! Alerts: rules with debounce over the stream of blow results. Pure code.

use std::collections::BTreeMap;

use serde::Serialize;

/// Which rule fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AlertKind {
    /// A hard blow, or k of the last n blows below the efficiency threshold: the blows have
    /// turned elastic (the part is done or cold).
    ElasticBlow,
    /// The energy balance no longer closes: the model does not describe the machine.
    ModelHealth,
}

/// An alert with the blow, the figures and a plain-language reason.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Alert {
    pub kind: AlertKind,
    pub blow: u32,
    pub reason: String,
    /// The figures behind it, by name (e.g. "efficiency": 0.31).
    pub figures: BTreeMap<String, f64>,
}
