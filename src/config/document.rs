//! A configuration file parsed with the spans of its keys and values, and serde on top of
//! it: `Document::read_value` deserializes a part of the file into a raw struct (which
//! denies unknown keys) and turns the toml crate's error into a `ConfigError` with the
//! file, line, column and dotted key, and "did you mean" for a misspelt key. Errors found
//! after deserializing (ranges, cross-key checks) are placed by their dotted key too.

use serde::de::DeserializeOwned;
use serde_path_to_error::Segment;
use toml::Spanned;
use toml::de::{DeTable, DeValue, ValueDeserializer};

use super::limits::{Limits, WholeLimits};
use super::{ConfigError, Place, Position};

/// A parsed file: its name, its text and its spanned table.
pub(crate) struct Document<'a> {
    origin: &'a str,
    text: &'a str,
    root: Spanned<DeValue<'a>>,
}

impl<'a> Document<'a> {
    /// Parse `text`, the file `origin`; a syntax error names the line and column.
    pub fn parse(origin: &'a str, text: &'a str) -> Result<Self, ConfigError> {
        let root = DeTable::parse(text).map_err(|e| {
            let at = e.span().map(|s| position(text, s.start));
            let message = e.message().trim().replace('\n', " ");
            let message = match at {
                Some(p) => format!("{message} at line {}, column {}", p.line, p.column),
                None => message,
            };
            ConfigError::Syntax { place: Place { origin: origin.to_string(), at }, message }
        })?;
        let span = root.span();
        Ok(Document { origin, text, root: Spanned::new(span, DeValue::Table(root.into_inner())) })
    }

    /// The top-level table.
    pub fn table(&self) -> &DeTable<'a> {
        match self.root.get_ref() {
            DeValue::Table(t) => t,
            _ => unreachable!("a document's root is a table"),
        }
    }

    /// The whole file as `T`.
    pub fn read<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        self.read_value(self.root.clone(), "")
    }

    /// `table` (the top-level table, edited) as `T`.
    pub fn read_table<T: DeserializeOwned>(&self, table: DeTable<'a>) -> Result<T, ConfigError> {
        self.read_value(Spanned::new(self.root.span(), DeValue::Table(table)), "")
    }

    /// `value`, found at the dotted key `prefix`, as `T`.
    pub fn read_value<T: DeserializeOwned>(&self, value: Spanned<DeValue<'a>>, prefix: &str) -> Result<T, ConfigError> {
        serde_path_to_error::deserialize(ValueDeserializer::from(value)).map_err(|e| self.serde_error(prefix, e))
    }

    /// The value at the dotted key `path` (`sources[2].channels[1]`), if present.
    pub fn get(&self, path: &str) -> Option<&Spanned<DeValue<'a>>> {
        let mut value = &self.root;
        for (name, index) in segments(path) {
            value = value.get_ref().as_table()?.get(name)?;
            if let Some(i) = index {
                value = value.get_ref().as_array()?.get(i.checked_sub(1)?)?;
            }
        }
        Some(value)
    }

    /// The string at `path`, which must be one of `allowed`.
    pub fn choice(&self, path: &str, allowed: &[&'static str]) -> Result<&'static str, ConfigError> {
        let Some(v) = self.get(path) else { return Err(self.missing(path)) };
        let Some(s) = v.get_ref().as_str() else {
            return Err(self.invalid(path, format!("must be {}, not {}", one_of(allowed), v.get_ref().type_str())));
        };
        allowed.iter().copied().find(|a| *a == s).ok_or_else(|| {
            let hint = suggest(s, allowed).map(|a| format!("; did you mean \"{a}\"?")).unwrap_or_default();
            self.invalid(path, format!("must be {}, got \"{s}\"{hint}", one_of(allowed)))
        })
    }

    /// Where the dotted key `path` is: the key itself, or the deepest table on its way
    /// that exists (a missing key is placed at its table).
    pub fn place(&self, path: &str) -> Place {
        let mut value = &self.root;
        let mut span = None;
        for (name, index) in segments(path) {
            let Some((k, v)) = value.get_ref().as_table().and_then(|t| t.get_key_value(name)) else { break };
            span = Some(k.span());
            value = v;
            if let Some(i) = index {
                let Some(item) = v.get_ref().as_array().and_then(|a| a.get(i.saturating_sub(1))) else { break };
                span = Some(item.span());
                value = item;
            }
        }
        Place { origin: self.origin.to_string(), at: span.map(|s| position(self.text, s.start)) }
    }

    pub fn invalid(&self, path: &str, why: impl Into<String>) -> ConfigError {
        ConfigError::Invalid { place: self.place(path), key: path.to_string(), why: why.into() }
    }

    pub fn missing(&self, path: &str) -> ConfigError {
        ConfigError::Missing { place: self.place(path), key: path.to_string() }
    }

    /// `x`, the number at `path`, if it is inside `limits`.
    pub fn in_range(&self, path: &str, x: f64, limits: &Limits) -> Result<f64, ConfigError> {
        limits.check(x).map_err(|why| self.invalid(path, why))
    }

    /// `x`, the whole number at `path`, if it is inside `limits`.
    pub fn in_whole_range(&self, path: &str, x: u64, limits: &WholeLimits) -> Result<u64, ConfigError> {
        limits.check(x).map_err(|why| self.invalid(path, why))
    }

    /// The line and column of byte `offset`.
    pub fn position(&self, offset: usize) -> Position {
        position(self.text, offset)
    }

    fn serde_error(&self, prefix: &str, e: serde_path_to_error::Error<toml::de::Error>) -> ConfigError {
        let path = dotted(prefix, e.path());
        let inner = e.inner();
        let place = match inner.span() {
            Some(s) => Place { origin: self.origin.to_string(), at: Some(self.position(s.start)) },
            None => self.place(&path),
        };
        let message = inner.message().trim();
        if let Some(rest) = message.strip_prefix("unknown field `")
            && let Some((key, expected)) = rest.split_once('`')
        {
            let table = path.strip_suffix(key).map(|t| t.trim_end_matches('.')).unwrap_or(&path);
            let expected = backticked(expected);
            return ConfigError::UnknownKey {
                place,
                key: key.to_string(),
                table: table.to_string(),
                suggestion: suggest(key, &expected).map(str::to_string),
            };
        }
        if let Some(rest) = message.strip_prefix("missing field `")
            && let Some((key, _)) = rest.split_once('`')
        {
            // Placed at the table it is missing from (serde's span would be the table's whole text).
            let key = join(&path, key);
            return ConfigError::Missing { place: self.place(&key), key };
        }
        if let Some(rest) = message.strip_prefix("unknown variant `")
            && let Some((got, expected)) = rest.split_once('`')
        {
            let expected = backticked(expected);
            let hint = suggest(got, &expected).map(|a| format!("; did you mean \"{a}\"?")).unwrap_or_default();
            return ConfigError::Invalid {
                place,
                key: path,
                why: format!("must be {}, got \"{got}\"{hint}", one_of(&expected)),
            };
        }
        let why = match message.strip_prefix("invalid type: ").or_else(|| message.strip_prefix("invalid value: ")) {
            Some(rest) => match rest.rsplit_once(", expected ") {
                Some((found, expected)) => format!("must be {}, not {found}", expected_in_words(expected)),
                None => rest.to_string(),
            },
            None => message.to_string(),
        };
        ConfigError::Invalid { place, key: path, why }
    }
}

/// The line and column of byte `offset` of `text`.
fn position(text: &str, offset: usize) -> Position {
    let before = text.get(..offset.min(text.len())).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    Position { line, column }
}

/// The parts of a dotted key: `sources[2].channels` is `("sources", Some(2)), ("channels", None)`
/// (indices count from 1, as the messages do).
fn segments(path: &str) -> impl Iterator<Item = (&str, Option<usize>)> {
    path.split('.').filter(|p| !p.is_empty()).map(|part| match part.split_once('[') {
        Some((name, rest)) => (name, rest.trim_end_matches(']').parse().ok()),
        None => (part, None),
    })
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() { key.to_string() } else { format!("{prefix}.{key}") }
}

/// serde's path below `prefix` as a dotted key, array indices counted from 1.
fn dotted(prefix: &str, path: &serde_path_to_error::Path) -> String {
    let mut s = prefix.to_string();
    for segment in path.iter() {
        match segment {
            Segment::Seq { index } => s.push_str(&format!("[{}]", index + 1)),
            Segment::Map { key } => s = join(&s, key),
            _ => {}
        }
    }
    s
}

/// The names between backticks in serde's "expected one of `a`, `b`".
fn backticked(s: &str) -> Vec<&str> {
    s.split('`').skip(1).step_by(2).collect()
}

/// `"a"`, `"a" or "b"`, `one of "a", "b", "c"`.
pub(crate) fn one_of(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("\"{n}\"")).collect();
    match quoted.as_slice() {
        [one] => one.clone(),
        [a, b] => format!("{a} or {b}"),
        _ => format!("one of {}", quoted.join(", ")),
    }
}

/// serde's name of an expected type, as a person would say it.
fn expected_in_words(expected: &str) -> String {
    match expected {
        "f64" | "f32" => "a number".into(),
        "u64" | "usize" => "a whole number >= 0".into(),
        "u32" => "a whole number in 0..=4294967295".into(),
        "u16" => "a whole number in 0..=65535".into(),
        "u8" => "a whole number in 0..=255".into(),
        "i64" | "i32" => "a whole number".into(),
        "a boolean" => "true or false".into(),
        "a sequence" => "an array".into(),
        e if e.starts_with("struct ") || e == "a map" => "a table".into(),
        e => e.to_string(),
    }
}

/// The known name that `key` is most likely a typing error of: at most one edit in three
/// characters (at most 2), a transposition counting as one, case ignored.
pub(crate) fn suggest<'k>(key: &str, known: &[&'k str]) -> Option<&'k str> {
    let key = key.to_lowercase();
    known
        .iter()
        .map(|k| (strsim::damerau_levenshtein(&key, &k.to_lowercase()), *k))
        .filter(|(d, k)| *d <= (k.chars().count() / 3).clamp(1, 2))
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_count_lines_and_characters_from_one() {
        let text = "a = 1\nµ = 2\n";
        assert_eq!(position(text, 0), Position { line: 1, column: 1 });
        assert_eq!(position(text, 6), Position { line: 2, column: 1 });
        // 'µ' is two bytes and one column.
        assert_eq!(position(text, 9), Position { line: 2, column: 3 });
    }

    #[test]
    fn near_misses_are_suggested_and_strangers_are_not() {
        let known = ["hard_blow", "low_efficiency", "k_low", "n_window", "baud", "rotate_bytes", "k_N_per_m"];
        assert_eq!(suggest("hard_blwo", &known), Some("hard_blow"));
        assert_eq!(suggest("buad", &known), Some("baud"));
        assert_eq!(suggest("rotate_byte", &known), Some("rotate_bytes"));
        assert_eq!(suggest("k_n_per_m", &known), Some("k_N_per_m"));
        assert_eq!(suggest("provenance", &known), None);
        assert_eq!(suggest("x", &known), None);
    }

    #[test]
    fn dotted_keys_find_their_place() {
        let text = "a = 1\n[t]\nb = 2\n[[s]]\nc = 3\n[[s]]\nc = 4\n";
        let d = Document::parse("f.toml", text).unwrap();
        assert_eq!(d.place("t.b").to_string(), "f.toml:3:1");
        assert_eq!(d.place("s[2].c").to_string(), "f.toml:7:1");
        // A missing key is placed at the deepest table that exists.
        assert_eq!(d.place("t.nope").to_string(), "f.toml:2:2");
        assert_eq!(
            d.get("s[1].c").and_then(|v| v.get_ref().as_integer()).map(|i| i.as_str().to_string()),
            Some("3".into())
        );
        assert!(d.get("s[3].c").is_none() && d.get("s[0].c").is_none());
    }

    #[test]
    fn syntax_errors_name_line_and_column() {
        let e = Document::parse("f.toml", "a = 1\nb = = 2\n").err().unwrap().to_string();
        assert!(e.starts_with("f.toml:2:") && e.contains("not valid TOML") && e.contains("line 2"), "{e}");
    }
}
