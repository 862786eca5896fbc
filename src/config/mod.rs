//! Reading the TOML files of docs/interfaces.md §2–§3 and the service configuration into typed
//! values.
//!
//! Each file is parsed with spans (`document.rs`), deserialized by serde into raw structs
//! that deny unknown keys, then validated once (`limits.rs` names every physical range)
//! into the typed value. Every error names the file, the line and column, and the dotted
//! key, and a misspelt key gets "did you mean". Pure code: the caller reads the file and
//! passes its text and name; nothing here opens a file.

pub mod advisor;
mod can;
mod document;
pub mod history;
pub mod limits;
pub mod machine;
pub mod opcua;
pub mod process;
pub mod recipe;
pub mod reload;
pub mod server_limits;
pub mod service;
mod source;
pub mod uplink;

pub use machine::{MachineFile, parse_machine};
pub use process::{parse_process, parse_process_sheet};

use std::fmt;

/// Where in a file: 1-based line and column (the column counts characters).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Position {
    pub line: usize,
    pub column: usize,
}

/// The file an error is in and, when known, where: shown as `origin:line:column`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Place {
    pub origin: String,
    pub at: Option<Position>,
}

impl Place {
    /// The file, without a position yet.
    pub fn file(origin: &str) -> Self {
        Place { origin: origin.to_string(), at: None }
    }
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.at {
            Some(p) => write!(f, "{}:{}:{}", self.origin, p.line, p.column),
            None => f.write_str(&self.origin),
        }
    }
}

/// What is wrong with a configuration file. The message names the file, the position
/// and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("{place}: not valid TOML: {message}")]
    Syntax { place: Place, message: String },
    /// `table` is the dotted key of the table the key is in, empty at the top level.
    #[error("{place}: unknown key '{key}' {}{}", in_table(table), did_you_mean(suggestion))]
    UnknownKey { place: Place, key: String, table: String, suggestion: Option<String> },
    #[error("{place}: missing key '{key}'")]
    Missing { place: Place, key: String },
    #[error("{place}: key '{key}' {why}")]
    Invalid { place: Place, key: String, why: String },
    /// The file is longer than its kind may be (a recipe, `limits::RECIPE_BYTES`); refused
    /// before it is parsed.
    #[error("{place}: {bytes} bytes, more than the {max} bytes this file may have")]
    TooLarge { place: Place, bytes: u64, max: u64 },
}

fn in_table(table: &str) -> String {
    if table.is_empty() { "at the top level".into() } else { format!("in [{table}]") }
}

fn did_you_mean(suggestion: &Option<String>) -> String {
    suggestion.as_ref().map(|s| format!("; did you mean '{s}'?")).unwrap_or_default()
}

impl ConfigError {
    /// The dotted key the error is about.
    pub fn key(&self) -> Option<&str> {
        match self {
            ConfigError::Syntax { .. } | ConfigError::TooLarge { .. } => None,
            ConfigError::UnknownKey { key, .. }
            | ConfigError::Missing { key, .. }
            | ConfigError::Invalid { key, .. } => Some(key),
        }
    }
}

/// A value read from a file, with what the reader should be told about it but that does
/// not stop it (for example a measured height that rises by caliper noise). Each warning
/// names the file.
#[derive(Debug, Clone, PartialEq)]
pub struct Parsed<T> {
    pub value: T,
    pub warnings: Vec<String>,
}
