//! The process sheet's measured heights against the ram encoder, before a fit (issue 40):
//! the check `replay` reports as `height_check` (`HeightCheck::compare` within
//! `EstimatorConfig::height_tolerance_m`: the encoder's and the caliper's resolutions and a
//! sample's travel at impact), on the encoder's own chain from the sheet's billet.
//!
//! A sheet off by more than a caliper's scatter (`CALIPER_TOLERANCE_M`) leaves the blow's
//! start height in doubt: either the sheet is wrong, or the encoder was zeroed anew between
//! the captures (docs/interfaces.md §1), and the data cannot tell which. `identify` leaves such a
//! blow out of the fit (it is still predicted) and names it. A smaller disagreement is the
//! calipers' scatter on a hot billet: named too, and the fit takes the encoder's height, as
//! `Heights::Encoder` does, so the sheet's scatter does not enter it.

use super::objective::{Reference, chained_height};
use crate::estimate::{EstimatorConfig, HeightCheck};
use crate::physics::process::{CALIPER_TOLERANCE_M, Process};

/// One blow's start height: the sheet's measured height after the blow before against the
/// encoder's chain.
#[derive(Debug, Clone, PartialEq)]
pub struct SheetCheck {
    /// The billet's blow (1-based) the start height is of.
    pub blow: usize,
    /// Its capture (`Reference::label`).
    pub label: String,
    pub check: HeightCheck,
}

impl SheetCheck {
    /// The sheet and the encoder apart by more than a caliper's scatter: the blow's start
    /// height is in doubt, and the fit leaves the blow out.
    pub fn in_doubt(&self) -> bool {
        (self.check.sheet_m - self.check.encoder_m).abs() > CALIPER_TOLERANCE_M
    }

    /// What a user is told about a disagreement (`None` when the two agree).
    pub fn warning(&self) -> Option<String> {
        let c = &self.check;
        if c.agree {
            return None;
        }
        let what = if self.in_doubt() {
            format!(
                "more than a caliper's scatter ({:.2} mm): the sheet is off or the encoder was zeroed anew between \
                 the captures, so the blow's start height is in doubt and the fit leaves it out (it is only predicted)",
                CALIPER_TOLERANCE_M * 1e3
            )
        } else {
            format!(
                "within a caliper's scatter ({:.2} mm): the fit takes the encoder's height",
                CALIPER_TOLERANCE_M * 1e3
            )
        };
        Some(format!(
            "blow {} ({}): the sheet's height after blow {} is {:.2} mm, the encoder's {:.2} mm: {:.2} mm apart, beyond \
             the encoder's and caliper's resolutions ({:.3} mm), {what}",
            self.blow,
            self.label,
            self.blow - 1,
            c.sheet_m * 1e3,
            c.encoder_m * 1e3,
            (c.sheet_m - c.encoder_m).abs() * 1e3,
            c.tolerance_m * 1e3
        ))
    }
}

/// Each billet blow's start height checked, `refs` in blow order: the encoder's chain runs
/// from the first blow's contact at the sheet's billet height, each blow lower by how much
/// lower the ram met the billet (`chained_height`, at the load's contact sample); where the
/// chain breaks (a billet that would grow or vanish: another offset) it takes up again from
/// the sheet's height, as `replay`'s does, and that blow is not checked.
pub fn cross_check(refs: &[Reference], process: &Process) -> Vec<SheetCheck> {
    let cfg = EstimatorConfig::for_kind(process.machine);
    let mut out = Vec::new();
    // The blow before: its index, its height on the chain and its contact reading.
    let mut prev: Option<(usize, f64, f64)> = None;
    for r in refs {
        let (Some(n), Some(a)) = (r.blow_index, r.approach) else {
            prev = None;
            continue;
        };
        let x_m = a.x_m();
        let tolerance_m = cfg.height_tolerance_m(r.v0_mps.abs() * r.dt_s);
        let sheet = n.checked_sub(2).and_then(|k| process.measured_final_heights_m.get(k).copied());
        let chained = match prev {
            Some((k, h_prev, x_prev)) if k + 1 == n => chained_height((h_prev, x_prev), x_m, tolerance_m),
            _ => None,
        };
        if let (Some(encoder_m), Some(sheet_m)) = (chained, sheet) {
            out.push(SheetCheck {
                blow: n,
                label: r.label.clone(),
                check: HeightCheck::compare(sheet_m, encoder_m, tolerance_m),
            });
        }
        let h = if n == 1 { Some(process.billet.height_m) } else { chained.or(sheet) };
        prev = h.map(|h| (n, h, x_m));
    }
    out
}
