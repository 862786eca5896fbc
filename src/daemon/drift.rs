//! The drift alarms at the service's start (issue 44): the reference learnt in an earlier run
//! is taken up from the history database (its latest `drift_references` row), so a restart
//! watches on instead of learning from the next 100 billets again; the reference resumed is
//! recorded at the start of the run, as a learnt one is when learnt, so that a replay and a
//! rebuild know it. One learnt under other `[drift]` settings, or one that cannot be read,
//! is set aside, saying why, and the service learns anew.

use std::path::Path;

use crate::alert::drift::{Drift, DriftConfig, REFERENCE_CONFIG_NAME, Reference};
use crate::session::Session;

/// The detector for `cfg`: resumed from `history`'s latest reference when there is one that
/// fits, learning otherwise.
pub(super) fn start(cfg: DriftConfig, history: Option<&Path>, session: &mut Session) -> Drift {
    let Some(path) = history.filter(|p| p.is_file()) else { return Drift::new(cfg) };
    let stored = match crate::history::latest_drift_reference(path) {
        Ok(Some(text)) => text,
        Ok(None) => return Drift::new(cfg),
        Err(e) => {
            tracing::warn!("drift: the learnt reference cannot be read, learning anew: {e}");
            return Drift::new(cfg);
        }
    };
    let resumed = serde_json::from_str::<Reference>(&stored)
        .map_err(|e| format!("not a reference: {e}"))
        .and_then(|r| Drift::resume(cfg, &r));
    match resumed {
        Ok(d) => {
            tracing::info!(path = %path.display(), "drift: watching with the reference learnt before");
            session.record_config("the drift reference", REFERENCE_CONFIG_NAME, &stored, super::host_now_ns());
            d
        }
        Err(why) => {
            tracing::warn!(path = %path.display(), "drift: the reference learnt before is set aside ({why}); learning anew");
            Drift::new(cfg)
        }
    }
}
