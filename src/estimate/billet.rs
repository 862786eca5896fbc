//! Billet detection from the ram encoder (issue 22): a new part in the dies shows as a
//! contact higher than where the last blow left the billet it forged, since a billet only
//! gets flatter. The detector decides, blow by blow, whether this contact continues the
//! billet in the dies or starts another, and flags the contacts it cannot explain
//! (`BilletCheck`) rather than silently re-basing the height. Pure code: the same in a live
//! run and in a replay.

use serde::Serialize;

/// A new billet is a contact higher than the last blow's end by more than this fraction of
/// the sheet's billet height. Billets of one lot vary by a few per cent (a saw cut to
/// ±1 mm on 112 mm is ±0.9 %), while the next billet of a lot stands far above the last one's
/// forged height (the LG1000's 8-blow plan takes a 112 mm billet to 40 mm): 10 % is a wide
/// margin on both sides.
pub const NEW_BILLET_RISE_FRACTION: f64 = 0.10;

/// ... and by more than this many encoder counts, the floor without a process sheet (or on a
/// tiny billet): 50 counts of 10 µm is 0.5 mm, 10 times the contact position's accuracy (one
/// sample's travel at impact, 53 µm at 5.3 m/s and 100 kHz, plus a count).
pub const NEW_BILLET_RISE_COUNTS: f64 = 50.0;

/// After the machine stood idle this long, a contact higher than the last end by more than
/// the measurement allows starts a new billet even below the rise threshold: a part taken
/// out and another (or the same, re-struck) put in. A hammer's blows on one billet follow
/// each other within seconds; changing a part takes longer.
pub const DEFAULT_IDLE_NEW_BILLET_S: f64 = 20.0;

/// A contact may sit higher than the tracked end of the last blow by the billet's elastic
/// recovery and the estimate's error on the compression: this fraction of the sheet's
/// height (0.2 % of 112 mm is 0.22 mm; the tracked end height is good to 0.1 mm, issue 15,
/// and a steel billet's spring-back at 2 MN over 60 mm diameter is below 0.05 mm). The
/// same allowance holds below the last end.
pub const SAME_BILLET_ALLOWANCE_FRACTION: f64 = 0.002;

/// A contact the detector could not reconcile with the billet it tracked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BilletCheck {
    /// The contact was lower than the last blow's end beyond the allowance: a part cannot
    /// lose height between blows, so another part (shorter than the last one's forged
    /// height) is in the dies. Counted as a new billet, height from the encoder.
    ContactBelowLastEnd,
    /// Higher than the last end beyond the allowance, but below the new-billet threshold and
    /// without an idle gap: kept as the same billet, its height re-based on the encoder.
    ContactAboveLastEnd,
    /// The billet before this one ended after a single blow (a part re-struck for a
    /// correction, or a mis-detection).
    PreviousBilletOneBlow,
}

impl BilletCheck {
    pub fn as_str(&self) -> &'static str {
        match self {
            BilletCheck::ContactBelowLastEnd => "contact_below_last_end",
            BilletCheck::ContactAboveLastEnd => "contact_above_last_end",
            BilletCheck::PreviousBilletOneBlow => "previous_billet_one_blow",
        }
    }

    /// The check named `s` (`as_str`), `None` for a name this version does not know.
    pub fn parse(s: &str) -> Option<Self> {
        [BilletCheck::ContactBelowLastEnd, BilletCheck::ContactAboveLastEnd, BilletCheck::PreviousBilletOneBlow]
            .into_iter()
            .find(|c| c.as_str() == s)
    }
}

/// How a contact relates to the billet in the dies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transition {
    /// The same billet, forged on.
    Same,
    /// The same billet, but its height is re-based on the encoder (flagged).
    Rebase,
    /// Another billet.
    New,
}

/// The detector's thresholds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BilletDetect {
    /// A rise above the last end beyond this starts a new billet, m.
    pub rise_m: f64,
    /// A contact within this of the last end continues the billet, m.
    pub allowance_m: f64,
    /// An idle gap longer than this lowers the rise threshold to the allowance, s.
    pub idle_s: f64,
}

impl BilletDetect {
    /// The defaults for a sheet's billet height (if any) and the encoder's resolution.
    pub fn new(sheet_height_m: Option<f64>, encoder_resolution_m: f64, rise_m: Option<f64>, idle_s: f64) -> Self {
        let h = sheet_height_m.unwrap_or(0.0);
        let floor_m = NEW_BILLET_RISE_COUNTS * encoder_resolution_m;
        BilletDetect {
            rise_m: rise_m.unwrap_or((NEW_BILLET_RISE_FRACTION * h).max(floor_m)),
            allowance_m: SAME_BILLET_ALLOWANCE_FRACTION * h,
            idle_s,
        }
    }

    /// Classify a contact `rise_m` above the last blow's end (negative: below it), `idle_s`
    /// after the last blow ended; `tolerance_m` is the contact position's own accuracy.
    pub fn classify(&self, rise_m: f64, idle_s: f64, tolerance_m: f64) -> (Transition, Option<BilletCheck>) {
        let allow = self.allowance_m + tolerance_m;
        if rise_m > self.rise_m.max(allow) || (rise_m > allow && idle_s > self.idle_s) {
            (Transition::New, None)
        } else if rise_m < -allow {
            (Transition::New, Some(BilletCheck::ContactBelowLastEnd))
        } else if rise_m > allow {
            (Transition::Rebase, Some(BilletCheck::ContactAboveLastEnd))
        } else {
            (Transition::Same, None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn detect() -> BilletDetect {
        BilletDetect::new(Some(0.112), 10e-6, None, DEFAULT_IDLE_NEW_BILLET_S)
    }

    #[test]
    fn the_default_threshold_is_a_tenth_of_the_sheet_or_fifty_counts() {
        assert!((detect().rise_m - 0.0112).abs() < 1e-12);
        let bare = BilletDetect::new(None, 10e-6, None, 20.0);
        assert!((bare.rise_m - 0.5e-3).abs() < 1e-12);
        let set = BilletDetect::new(Some(0.112), 10e-6, Some(0.004), 20.0);
        assert_eq!(set.rise_m, 0.004);
    }

    #[test]
    fn contacts_are_classified_by_their_rise_and_the_idle_gap() {
        let d = detect();
        let tol = 63e-6;
        // A new billet 112 mm high after one forged to 40 mm: 72 mm higher.
        assert_eq!(d.classify(0.072, 0.5, tol), (Transition::New, None));
        // The next blow on the same billet, 30 µm off the tracked end.
        assert_eq!(d.classify(-30e-6, 0.5, tol), (Transition::Same, None));
        // 2 mm higher: too little for a new billet at once, a new one after an idle gap.
        assert_eq!(d.classify(0.002, 0.5, tol), (Transition::Rebase, Some(BilletCheck::ContactAboveLastEnd)));
        assert_eq!(d.classify(0.002, 60.0, tol), (Transition::New, None));
        // 5 mm lower than the part's end: another, shorter part.
        assert_eq!(d.classify(-0.005, 0.5, tol), (Transition::New, Some(BilletCheck::ContactBelowLastEnd)));
    }
}
