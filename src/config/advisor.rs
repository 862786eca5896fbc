//! `[advisor]` in `service.toml` (issue 20, docs/interfaces.md §9): the live blow advisor's target
//! height and the machine's impact speeds, discrete settings (a hammer's drop heights) or a
//! continuous range up to `v_max` (a screw press's energy setting). Checked once here, so the
//! service never plans with a speed or a height no machine has.

use serde::Deserialize;

use super::ConfigError;
use super::document::Document;
use super::limits::{IMPACT_SPEED_MPS, MEASURED_HEIGHT_M};
use crate::advise::Speeds;

/// Most discrete settings: the advisor tries every sequence of them, so its time grows with
/// their number (5 settings plan in 25–42 ms, `benches/advise.rs`); 12 is more drop heights
/// than any hammer's control offers.
pub const MAX_SETTINGS: usize = 12;

/// The live advisor's configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct AdvisorConfig {
    /// The billet's target height, m (planned to within ±0.5 mm).
    pub target_height_m: f64,
    pub speeds: Speeds,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAdvisor {
    target_height_m: f64,
    settings: Option<Vec<f64>>,
    v_max: Option<f64>,
}

/// `[advisor]`: a target and exactly one of `settings` (m/s, each a possible impact speed)
/// and `v_max` (m/s).
pub(super) fn parse_advisor(
    doc: &Document<'_>,
    raw: Option<&RawAdvisor>,
) -> Result<Option<AdvisorConfig>, ConfigError> {
    let Some(raw) = raw else { return Ok(None) };
    let target_height_m = doc.in_range("advisor.target_height_m", raw.target_height_m, &MEASURED_HEIGHT_M)?;
    let speeds = match (&raw.settings, raw.v_max) {
        (Some(_), Some(_)) => {
            return Err(doc.invalid("advisor.v_max", "give either settings or v_max, not both"));
        }
        (None, None) => {
            return Err(doc.invalid("advisor", "needs the machine's impact speeds: settings = [m/s, ...] or v_max"));
        }
        (None, Some(v)) => Speeds::UpTo(doc.in_range("advisor.v_max", v, &IMPACT_SPEED_MPS)?),
        (Some(v), None) => {
            if v.is_empty() || v.len() > MAX_SETTINGS {
                return Err(doc.invalid("advisor.settings", format!("must list 1 to {MAX_SETTINGS} speeds")));
            }
            for (i, s) in v.iter().enumerate() {
                doc.in_range(&format!("advisor.settings[{}]", i + 1), *s, &IMPACT_SPEED_MPS)?;
            }
            Speeds::Settings(v.clone())
        }
    };
    Ok(Some(AdvisorConfig { target_height_m, speeds }))
}
