//! Reading the TOML files of CONTRACTS.md §2–§3 into the physics' types.
//!
//! Each file is parsed to a TOML table, then validated once into a typed value, with every
//! error naming the file and the key. Pure code: the caller reads the file and passes its
//! text and name.

pub mod machine;
pub mod process;
pub mod service;

pub use machine::{MachineFile, parse_machine};
pub use process::parse_process;

use crate::physics::machine::MachineKind;

/// What is wrong with a configuration file. The message names the file and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("{origin}: not valid TOML: {message}")]
    Syntax { origin: String, message: String },
    #[error("{origin}: missing key '{key}'")]
    Missing { origin: String, key: String },
    #[error("{origin}: key '{key}' {why}")]
    Invalid { origin: String, key: String, why: String },
}

/// Typed access to a TOML table with errors that name `origin` and the dotted key.
pub(crate) struct Keys<'a> {
    pub origin: &'a str,
    pub prefix: String,
    pub table: &'a toml::Table,
}

impl<'a> Keys<'a> {
    pub fn root(origin: &'a str, table: &'a toml::Table) -> Self {
        Keys { origin, prefix: String::new(), table }
    }

    pub fn path(&self, key: &str) -> String {
        if self.prefix.is_empty() { key.to_string() } else { format!("{}.{key}", self.prefix) }
    }

    pub fn invalid(&self, key: &str, why: impl Into<String>) -> ConfigError {
        ConfigError::Invalid { origin: self.origin.to_string(), key: self.path(key), why: why.into() }
    }

    pub fn missing(&self, key: &str) -> ConfigError {
        ConfigError::Missing { origin: self.origin.to_string(), key: self.path(key) }
    }

    /// A sub-table.
    pub fn table(&self, key: &str) -> Result<Keys<'a>, ConfigError> {
        match self.table.get(key) {
            Some(toml::Value::Table(t)) => Ok(Keys { origin: self.origin, prefix: self.path(key), table: t }),
            Some(_) => Err(self.invalid(key, "must be a table")),
            None => Err(self.missing(key)),
        }
    }

    pub fn string(&self, key: &str) -> Result<&'a str, ConfigError> {
        match self.table.get(key) {
            Some(toml::Value::String(s)) => Ok(s),
            Some(_) => Err(self.invalid(key, "must be a string")),
            None => Err(self.missing(key)),
        }
    }

    /// An optional number (integers are accepted as numbers).
    pub fn opt_number(&self, key: &str) -> Result<Option<f64>, ConfigError> {
        match self.table.get(key) {
            Some(toml::Value::Float(x)) => Ok(Some(*x)),
            Some(toml::Value::Integer(i)) => Ok(Some(*i as f64)),
            Some(v) => Err(self.invalid(key, format!("must be a number, not {}", v.type_str()))),
            None => Ok(None),
        }
    }

    pub fn number(&self, key: &str) -> Result<f64, ConfigError> {
        self.opt_number(key)?.ok_or_else(|| self.missing(key))
    }

    /// A finite number > 0.
    pub fn positive(&self, key: &str) -> Result<f64, ConfigError> {
        let x = self.number(key)?;
        if x.is_finite() && x > 0.0 {
            Ok(x)
        } else {
            Err(self.invalid(key, format!("must be finite and > 0, got {x}")))
        }
    }

    /// A finite number >= 0.
    pub fn non_negative(&self, key: &str) -> Result<f64, ConfigError> {
        let x = self.number(key)?;
        if x.is_finite() && x >= 0.0 {
            Ok(x)
        } else {
            Err(self.invalid(key, format!("must be finite and >= 0, got {x}")))
        }
    }

    /// A finite number.
    pub fn finite(&self, key: &str) -> Result<f64, ConfigError> {
        let x = self.number(key)?;
        if x.is_finite() { Ok(x) } else { Err(self.invalid(key, format!("must be finite, got {x}"))) }
    }
}

/// The machine kind under `key` ("hammer" | "screw_press"), as both files spell it.
pub(crate) fn machine_kind(keys: &Keys<'_>, key: &str) -> Result<MachineKind, ConfigError> {
    match keys.string(key)? {
        "hammer" => Ok(MachineKind::Hammer),
        "screw_press" => Ok(MachineKind::ScrewPress),
        other => Err(keys.invalid(key, format!("must be \"hammer\" or \"screw_press\", got \"{other}\""))),
    }
}

/// Parse `text` as a TOML table, naming `origin` (and the line) on a syntax error.
pub(crate) fn parse_table(origin: &str, text: &str) -> Result<toml::Table, ConfigError> {
    text.parse::<toml::Table>().map_err(|e| ConfigError::Syntax {
        origin: origin.to_string(),
        message: e.to_string().trim().replace('\n', " "),
    })
}
