//! `[history]` and `[part]` in `service.toml` (issue 44): where the quality record is kept
//! and for how long, and what the blows are forged on until someone says otherwise.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::ConfigError;
use super::document::Document;
use super::limits::KEEP_DAYS;
pub use crate::alert::drift::DriftConfig;

/// The database's file in the recording directory when `[history] path` is not given.
pub const DEFAULT_FILE: &str = "history.sqlite";
/// The longest part id, lot or die set name: OPC 40503's PartId is a string, and a PLC
/// register block holds 32 characters (docs/interfaces.md §8).
pub const MAX_ID_CHARS: usize = 32;

/// The history database, on by default.
#[derive(Debug, Clone, PartialEq)]
pub struct HistoryConfig {
    pub path: PathBuf,
    /// Rows older than this before the newest are deleted; `None`: kept.
    pub keep_days: Option<f64>,
}

impl HistoryConfig {
    /// `history.sqlite` in `recording_dir`, kept for ever.
    pub fn in_dir(recording_dir: &Path) -> Self {
        HistoryConfig { path: recording_dir.join(DEFAULT_FILE), keep_days: None }
    }
}

pub use crate::estimate::billet_book::Trace;

/// `trace` as the recording stores it (`session::PART_CONFIG_NAME`): TOML, the parts that
/// are set.
pub fn trace_text(trace: &Trace) -> String {
    format!("# what the blows from here on are forged as\n{}", toml::to_string(trace).unwrap_or_default())
}

/// A recorded trace's text back, each part checked as `[part]`'s are.
pub fn parse_trace_text(text: &str) -> Result<Trace, String> {
    let t: Trace = toml::from_str(text).map_err(|e| e.message().to_string())?;
    for (key, v) in [("part_id", &t.part_id), ("lot", &t.lot), ("die_set", &t.die_set)] {
        if let Some(v) = v {
            check_id(v).map_err(|why| format!("{key} {v:?} {why}"))?;
        }
    }
    Ok(t)
}

/// `[die_life]`: when a die set is due (OPC 40501's tool-life warning and limit), by blows
/// or by the energy its dies took; each optional. A `die_life` alert fires at each.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DieLifeConfig {
    pub warn_blows: Option<u64>,
    pub limit_blows: Option<u64>,
    pub warn_energy_j: Option<f64>,
    pub limit_energy_j: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDieLife {
    warn_blows: Option<u64>,
    limit_blows: Option<u64>,
    #[serde(rename = "warn_energy_J")]
    warn_energy_j: Option<f64>,
    #[serde(rename = "limit_energy_J")]
    limit_energy_j: Option<f64>,
}

/// Blows a die set may take at most in the config: far past any die's life (hammer dies last
/// 10^3–10^5 blows).
const MAX_DIE_BLOWS: u64 = 1_000_000_000;
/// Energy a die set may take at most in the config, J: 10^9 blows of 10 MJ.
const MAX_DIE_ENERGY_J: f64 = 1e16;

/// `[die_life]`: each value positive, each warning under its limit.
pub(super) fn parse_die_life(doc: &Document<'_>, raw: Option<&RawDieLife>) -> Result<DieLifeConfig, ConfigError> {
    let Some(raw) = raw else { return Ok(DieLifeConfig::default()) };
    let blows = |key: &str, v: Option<u64>| -> Result<Option<u64>, ConfigError> {
        match v {
            Some(n) if n == 0 || n > MAX_DIE_BLOWS => {
                Err(doc.invalid(key, format!("must be 1 to {MAX_DIE_BLOWS} blows, not {n}")))
            }
            v => Ok(v),
        }
    };
    let energy = |key: &str, v: Option<f64>| -> Result<Option<f64>, ConfigError> {
        match v {
            Some(e) if !(e > 0.0 && e <= MAX_DIE_ENERGY_J) => {
                Err(doc.invalid(key, format!("must be over 0 and at most {MAX_DIE_ENERGY_J:e} J, not {e}")))
            }
            v => Ok(v),
        }
    };
    let cfg = DieLifeConfig {
        warn_blows: blows("die_life.warn_blows", raw.warn_blows)?,
        limit_blows: blows("die_life.limit_blows", raw.limit_blows)?,
        warn_energy_j: energy("die_life.warn_energy_J", raw.warn_energy_j)?,
        limit_energy_j: energy("die_life.limit_energy_J", raw.limit_energy_j)?,
    };
    if let (Some(w), Some(l)) = (cfg.warn_blows, cfg.limit_blows)
        && w >= l
    {
        return Err(doc.invalid("die_life.warn_blows", format!("{w} must be under limit_blows ({l})")));
    }
    if let (Some(w), Some(l)) = (cfg.warn_energy_j, cfg.limit_energy_j)
        && w >= l
    {
        return Err(doc.invalid("die_life.warn_energy_J", format!("{w} must be under limit_energy_J ({l})")));
    }
    Ok(cfg)
}

/// `[drift]`: the drift alarms (`alert::drift`), on by default with its defaults.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDrift {
    enabled: Option<bool>,
    learn_billets: Option<u64>,
    k: Option<f64>,
    h: Option<f64>,
    setting_step_mps: Option<f64>,
}

/// `[drift]`: `None` when `enabled = false`.
pub(super) fn parse_drift(doc: &Document<'_>, raw: Option<&RawDrift>) -> Result<Option<DriftConfig>, ConfigError> {
    let d = DriftConfig::default();
    let Some(raw) = raw else { return Ok(Some(d)) };
    if raw.enabled == Some(false) {
        return Ok(None);
    }
    let learn_billets = match raw.learn_billets {
        Some(n) if !(10..=100_000).contains(&n) => {
            return Err(doc.invalid("drift.learn_billets", format!("must be 10 to 100000 billets, not {n}")));
        }
        Some(n) => n as usize,
        None => d.learn_billets,
    };
    let positive = |key: &str, v: Option<f64>, max: f64, default: f64| -> Result<f64, ConfigError> {
        match v {
            Some(x) if !(x > 0.0 && x <= max) => {
                Err(doc.invalid(key, format!("must be over 0 and at most {max}, not {x}")))
            }
            Some(x) => Ok(x),
            None => Ok(default),
        }
    };
    Ok(Some(DriftConfig {
        learn_billets,
        k: positive("drift.k", raw.k, 5.0, d.k)?,
        h: positive("drift.h", raw.h, 100.0, d.h)?,
        setting_step_mps: positive("drift.setting_step_mps", raw.setting_step_mps, 5.0, d.setting_step_mps)?,
    }))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawHistory {
    enabled: Option<bool>,
    path: Option<String>,
    keep_days: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPart {
    id: Option<String>,
    lot: Option<String>,
    die_set: Option<String>,
}

/// `[history]`: `None` when `enabled = false`.
pub(super) fn parse_history(
    doc: &Document<'_>,
    raw: Option<&RawHistory>,
    recording_dir: &Path,
    resolve: &dyn Fn(&str) -> PathBuf,
) -> Result<Option<HistoryConfig>, ConfigError> {
    let Some(raw) = raw else { return Ok(Some(HistoryConfig::in_dir(recording_dir))) };
    if raw.enabled == Some(false) {
        return Ok(None);
    }
    let path = match &raw.path {
        Some(p) if p.trim().is_empty() => return Err(doc.invalid("history.path", "must name a file")),
        Some(p) => resolve(p),
        None => recording_dir.join(DEFAULT_FILE),
    };
    let keep_days = raw.keep_days.map(|d| doc.in_range("history.keep_days", d, &KEEP_DAYS)).transpose()?;
    Ok(Some(HistoryConfig { path, keep_days }))
}

/// `[part]`: the defaults until a part, lot or die set is set at run time.
pub(super) fn parse_part(doc: &Document<'_>, raw: Option<&RawPart>) -> Result<Trace, ConfigError> {
    let Some(raw) = raw else { return Ok(Trace::default()) };
    let id = |key: &str, v: &Option<String>| -> Result<Option<String>, ConfigError> {
        v.as_deref().map(|s| check_id(s).map(str::to_string).map_err(|why| doc.invalid(key, why))).transpose()
    };
    Ok(Trace {
        part_id: id("part.id", &raw.id)?,
        lot: id("part.lot", &raw.lot)?,
        die_set: id("part.die_set", &raw.die_set)?,
    })
}

/// A part id, lot or die set as given: 1 to `MAX_ID_CHARS` printable characters, no
/// leading or trailing space. The one check, wherever the value comes from.
pub fn check_id(s: &str) -> Result<&str, String> {
    let n = s.chars().count();
    if n == 0 || n > MAX_ID_CHARS {
        return Err(format!("must be 1 to {MAX_ID_CHARS} characters, not {n}"));
    }
    if s.trim() != s {
        return Err("has leading or trailing spaces".into());
    }
    if let Some(c) = s.chars().find(|c| c.is_control()) {
        return Err(format!("holds a control character ({:?})", c));
    }
    Ok(s)
}

/// A change of what the next billet is forged as (`POST /billet`'s body, the PLC's part
/// block, OPC UA's method): each part given replaces the one in force, `null` clears it,
/// and a part not given is kept.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TraceUpdate {
    pub part_id: Option<Option<String>>,
    pub lot: Option<Option<String>>,
    pub die_set: Option<Option<String>>,
}

impl TraceUpdate {
    /// The trace in force after the change.
    pub fn apply(&self, now: &Trace) -> Trace {
        let pick = |new: &Option<Option<String>>, old: &Option<String>| new.clone().unwrap_or_else(|| old.clone());
        Trace {
            part_id: pick(&self.part_id, &now.part_id),
            lot: pick(&self.lot, &now.lot),
            die_set: pick(&self.die_set, &now.die_set),
        }
    }

    /// A JSON object's change: only the keys `part_id`, `lot`, `die_set`, each a string
    /// (checked as `[part]`'s) or `null`. The error names the key.
    pub fn from_json(body: &[u8]) -> Result<Self, String> {
        let v: serde_json::Value = serde_json::from_slice(body).map_err(|e| format!("not JSON: {e}"))?;
        let serde_json::Value::Object(map) = v else { return Err("must be a JSON object".into()) };
        let mut u = TraceUpdate::default();
        for (key, value) in map {
            let parsed = match value {
                serde_json::Value::Null => None,
                serde_json::Value::String(s) => Some(check_id(&s).map_err(|why| format!("{key}: {why}"))?.to_string()),
                other => return Err(format!("{key}: must be a string or null, not {other}")),
            };
            match key.as_str() {
                "part_id" => u.part_id = Some(parsed),
                "lot" => u.lot = Some(parsed),
                "die_set" => u.die_set = Some(parsed),
                _ => return Err(format!("{key}: unknown key; expected part_id, lot or die_set")),
            }
        }
        Ok(u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_update_replaces_what_it_gives_clears_null_and_keeps_the_rest() {
        let now = Trace { part_id: Some("P-1".into()), lot: Some("4711".into()), die_set: Some("17".into()) };
        let u = TraceUpdate::from_json(br#"{"part_id": "P-2", "die_set": null}"#).expect("a change");
        assert_eq!(u.apply(&now), Trace { part_id: Some("P-2".into()), lot: Some("4711".into()), die_set: None });
        assert_eq!(TraceUpdate::from_json(b"{}").expect("no change").apply(&now), now);
    }

    #[test]
    fn a_bad_update_names_its_key() {
        for (body, key) in [
            (&br#"{"lot": 4711}"#[..], "lot"),
            (br#"{"part": "x"}"#, "part"),
            (br#"{"die_set": ""}"#, "die_set"),
            (br#"{"part_id": " P-1"}"#, "part_id"),
        ] {
            let err = TraceUpdate::from_json(body).expect_err("refused");
            assert!(err.starts_with(key), "{err}");
        }
        assert!(TraceUpdate::from_json(b"[1]").is_err());
        let long = format!(r#"{{"lot": "{}"}}"#, "x".repeat(MAX_ID_CHARS + 1));
        assert!(TraceUpdate::from_json(long.as_bytes()).expect_err("too long").contains("1 to 32"));
    }

    #[test]
    fn a_trace_survives_its_recorded_text() {
        for t in [
            Trace::default(),
            Trace { part_id: Some("P-000417".into()), lot: Some("lot \"A\" #4".into()), die_set: None },
        ] {
            assert_eq!(parse_trace_text(&trace_text(&t)).expect("parses"), t);
        }
        assert!(parse_trace_text("lot = \"\"\n").is_err(), "checked as [part]'s are");
    }
}
