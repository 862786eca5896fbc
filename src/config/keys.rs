//! `Keys`: typed access to a plain `toml::Table` with errors that name the file and the
//! dotted key. The machine, process and service files are read by serde now
//! (`document.rs`); this accessor remains only for the CAN source's value checks
//! (`acquire/can/config.rs`), whose key names the service reader checks first with serde
//! (`source.rs`), and whose errors it places at their line and column.

use super::{ConfigError, Place};

/// Typed access to a TOML table with errors that name `origin` and the dotted key.
pub(crate) struct Keys<'a> {
    pub origin: &'a str,
    pub prefix: String,
    pub table: &'a toml::Table,
}

impl<'a> Keys<'a> {
    pub fn path(&self, key: &str) -> String {
        if self.prefix.is_empty() { key.to_string() } else { format!("{}.{key}", self.prefix) }
    }

    pub fn invalid(&self, key: &str, why: impl Into<String>) -> ConfigError {
        ConfigError::Invalid { place: Place::file(self.origin), key: self.path(key), why: why.into() }
    }

    pub fn missing(&self, key: &str) -> ConfigError {
        ConfigError::Missing { place: Place::file(self.origin), key: self.path(key) }
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

    fn number(&self, key: &str) -> Result<f64, ConfigError> {
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

    /// A finite number.
    pub fn finite(&self, key: &str) -> Result<f64, ConfigError> {
        let x = self.number(key)?;
        if x.is_finite() { Ok(x) } else { Err(self.invalid(key, format!("must be finite, got {x}"))) }
    }
}
