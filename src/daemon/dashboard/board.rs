//! What the dashboard shows beyond `/status`, kept by the status snapshot as the service's
//! events come (no second computation): the last `RECENT_BLOWS` blows' results (CONTRACTS.md
//! §5), the blows of the billet in the dies (the efficiency bars), the last acknowledged alert,
//! and the last blow's curve (`estimate::curve`). A page that loads or reconnects reads it
//! whole from `GET /dashboard/state`.

use std::collections::VecDeque;
use std::sync::Arc;

use serde::Serialize;

use crate::estimate::BlowEstimate;
use crate::estimate::curve::BlowCurve;
use crate::estimate::result::Alert;

/// Rows of the dashboard's table of blows.
pub const RECENT_BLOWS: usize = 50;

/// The dashboard's state.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Board {
    /// The last `RECENT_BLOWS` blows, newest first.
    pub recent_blows: VecDeque<BlowEstimate>,
    /// The blows of the billet in the dies, in order (empty once it is finished).
    pub billet_blows: Vec<BlowEstimate>,
    /// The alert the operator acknowledged last; `None` once a new alert is latched.
    pub acknowledged_alert: Option<Alert>,
    /// The last blow's curve (served on its own, `GET /blow/last/curve`).
    #[serde(skip)]
    pub curve: Option<Arc<BlowCurve>>,
}

impl Board {
    pub fn on_blow(&mut self, e: &BlowEstimate) {
        if self.recent_blows.len() == RECENT_BLOWS {
            self.recent_blows.pop_back();
        }
        self.recent_blows.push_front(e.clone());
        if self.billet_blows.last().is_some_and(|b| b.billet.billet != e.billet.billet) {
            self.billet_blows.clear();
        }
        self.billet_blows.push(e.clone());
        if e.alert.is_some() {
            self.acknowledged_alert = None;
        }
    }

    /// The billet in the dies was finished (the next one started).
    pub fn on_billet_finished(&mut self) {
        self.billet_blows.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::{BilletTag, BlowClass};

    fn blow(n: u32, billet: u32) -> BlowEstimate {
        BlowEstimate {
            kinetic_in_j: Some(10_000.0),
            plastic_j: Some(8_000.0),
            efficiency: Some(0.8),
            class: BlowClass::Soft,
            peak_load_n: 1e6,
            billet: BilletTag { billet, billet_blow: n, billet_check: None, h_start_off_sheet_m: None },
            ..BlowEstimate::incomplete(n, f64::from(n), 5.3, f64::from(n) + 0.02)
        }
    }

    #[test]
    fn the_table_keeps_the_last_fifty_newest_first_and_the_bars_one_billet() {
        let mut b = Board::default();
        for n in 1..=60 {
            b.on_blow(&blow(n, 1 + u32::from(n > 55)));
        }
        let rows: Vec<u32> = b.recent_blows.iter().map(|e| e.blow).collect();
        assert_eq!(rows, (11..=60).rev().collect::<Vec<_>>());
        // Billet 2 began at blow 56: the bars show its five blows only.
        let bars: Vec<u32> = b.billet_blows.iter().map(|e| e.blow).collect();
        assert_eq!(bars, [56, 57, 58, 59, 60]);
        b.on_billet_finished();
        assert!(b.billet_blows.is_empty());
    }
}
