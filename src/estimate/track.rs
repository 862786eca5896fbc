//! The billet's height track (issues 15, 22, 36): which billet each contact belongs to, and
//! where each blow's start height comes from. A billet only gets flatter, so the ram meets
//! it lower by what the last blow took: the encoder's chain. Across a break in the stream
//! the encoder's offset may have changed (docs/interfaces.md §1), so the chain goes on only where
//! the next contact shows it (`Continuity`); otherwise the height comes from the sheet's
//! measured one or the model's. Methods of `Estimator`, apart from its estimate of a blow.

use super::Estimator;
use super::billet::{BilletCheck, Transition};
use super::result::{HeightCheck, HeightSource};

/// Where the last blow left the billet, in encoder terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LastEnd {
    pub(super) x_m: f64,
    /// Whether the blow's end height was known (not an incomplete blow): only then can a
    /// lower contact be told from the billet's own set.
    pub(super) end_known: bool,
    pub(super) h_end_m: Option<f64>,
    pub(super) t_s: f64,
}

/// How a blow's contact relates to the encoder's reading of the blow before.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Continuity {
    /// The same offset: the contact is where the last blow left the billet, or the stream
    /// never broke.
    Shown,
    /// The stream broke and the contact is not where the last blow left the billet: the
    /// encoder was zeroed again, by an offset it cannot measure.
    OffsetUnknown,
    /// The billet's first blow.
    NewBillet,
}

impl Estimator {
    /// A new billet, signalled (`POST /billet`, the PLC coil, a recording's marker): the
    /// next blow starts it, and the encoder does not count it a second time. Its height
    /// starts again from the sheet's (or the encoder's, `first_blow_height`).
    pub fn new_billet(&mut self) {
        if !self.signalled {
            self.start_billet();
            self.signalled = true;
        }
    }

    /// The samples stopped (the end of a capture, a link lost, a new timeline): when they
    /// resume, the encoder may have been zeroed again (docs/interfaces.md §1: the offset may differ
    /// from file to file). The next contact is compared with where the last blow left the
    /// billet: only a match shows the encoder continuous (`Continuity`).
    pub fn stream_break(&mut self) {
        self.unverified = true;
    }

    pub(super) fn start_billet(&mut self) {
        self.h_m = self.process.as_ref().map(|p| p.billet.height_m);
        self.h_source = HeightSource::Sheet;
        self.billet_process = self.process.clone();
        self.chain = None;
        self.billet += 1;
        self.prev_billet_blows = self.billet_blows;
        self.billet_blows = 0;
        self.last_end = None;
    }

    /// Whether this contact starts a new billet (counting it), what it could not explain, and
    /// how it relates to the encoder's reading of the blow before (`Continuity`).
    pub(super) fn follow_billet(
        &mut self,
        x_contact_m: f64,
        t_contact_s: f64,
        tolerance_m: f64,
    ) -> (Option<BilletCheck>, Continuity) {
        let unverified = std::mem::take(&mut self.unverified);
        let (transition, check) = match self.last_end {
            _ if std::mem::take(&mut self.signalled) => {
                // A break before a billet's first blow leaves a learnt die reference in the
                // old offset: this contact teaches it again.
                if unverified && self.cfg.encoder_at_die_m.is_none() {
                    self.die_x_m = None;
                }
                return (None, Continuity::NewBillet);
            }
            None if self.billet == 0 => (Transition::New, None),
            None => (Transition::Same, None),
            // Across a break only a contact where the last blow left the billet shows the
            // encoder continuous. Any other is an offset the encoder cannot tell from a new
            // billet, so the billet goes on (a capture directory is one billet, docs/interfaces.md §1;
            // a stream's next billet after a restart needs its signal).
            Some(end) if unverified => {
                let rise_m = end.x_m - x_contact_m;
                return match self.detect.classify(rise_m, 0.0, tolerance_m) {
                    (Transition::Same, _) => (None, Continuity::Shown),
                    _ => (None, Continuity::OffsetUnknown),
                };
            }
            Some(end) => {
                let rise_m = end.x_m - x_contact_m;
                match self.detect.classify(rise_m, t_contact_s - end.t_s, tolerance_m) {
                    // An incomplete blow's end is unknown: any contact lower is its set.
                    (_, Some(BilletCheck::ContactBelowLastEnd)) if !end.end_known => (Transition::Same, None),
                    other => other,
                }
            }
        };
        match transition {
            Transition::Same => {}
            Transition::New => {
                self.start_billet();
                // A break before a billet's first blow leaves a learnt die reference in the
                // old offset: this contact teaches it again.
                if unverified && self.cfg.encoder_at_die_m.is_none() {
                    self.die_x_m = None;
                }
                return (check, Continuity::NewBillet);
            }
            Transition::Rebase => {
                // The encoder's word for the part in the dies: the die reference, or the
                // last end raised by the rise.
                let from_end = self.last_end.and_then(|e| e.h_end_m.map(|h| h + (e.x_m - x_contact_m)));
                let (h, source) = match (self.die_x_m, from_end) {
                    (Some(d), _) => (Some(d - x_contact_m), HeightSource::Encoder),
                    (None, Some(h)) => (Some(h), HeightSource::Encoder),
                    (None, None) => (self.h_m, self.h_source),
                };
                self.h_m = h;
                self.h_source = source;
                self.chain = None;
            }
        }
        (check, Continuity::Shown)
    }

    /// A billet's first blow: its height is the sheet's unless the encoder's (the die
    /// reference less the contact) differs by more than the measurement; the first billet
    /// teaches the die reference, unless it is configured (`encoder_at_die_m`): then the
    /// encoder's height is always taken, and becomes the billet's own (`billet_process`).
    /// Returns the encoder's height less the sheet's when reported.
    pub(super) fn first_blow_height(&mut self, x_contact_m: f64, tolerance_m: f64) -> Option<f64> {
        let nominal_m = self.process.as_ref()?.billet.height_m;
        let Some(die_x_m) = self.die_x_m else {
            self.die_x_m = Some(x_contact_m + nominal_m);
            return None;
        };
        let off_m = (die_x_m - x_contact_m) - nominal_m;
        // A configured reference measures every billet; a learnt one only tells a billet
        // off the sheet by more than the measurement.
        if self.cfg.encoder_at_die_m.is_some() || off_m.abs() > tolerance_m {
            self.h_m = Some(nominal_m + off_m);
            self.h_source = HeightSource::Encoder;
            // The billet's own law only on a configured reference: with a learnt one, a
            // "billet" off the sheet may be the same billet taken up again after lost data
            // (its strain does not start again), whose blows must keep the intact run's
            // figures (tests/record_corrupt.rs).
            if let (Some(p), Some(_)) = (self.billet_process.as_mut(), self.cfg.encoder_at_die_m) {
                p.billet.height_m = nominal_m + off_m;
            }
        }
        (off_m.abs() > tolerance_m).then_some(off_m)
    }

    /// The billet's height before this blow and where it came from: the encoder's chain from
    /// the last contact (the ram meets the billet lower by exactly the height the billet
    /// lost), else the one tracked through the last blow. With the encoder's offset unknown
    /// (`offset_unknown`: a break the contact could not bridge) there is no chain: the sheet's
    /// measured height after the blow before, else the tracked one. The chain is also checked
    /// against the sheet's measured height after the blow before.
    pub(super) fn start_height(
        &self,
        x_contact_m: f64,
        sample_travel_m: f64,
        offset_unknown: bool,
    ) -> (Option<f64>, Option<HeightCheck>, HeightSource) {
        if self.process.is_none() {
            return (None, None, HeightSource::Unknown);
        }
        let tolerance_m = self.contact_tolerance_m(sample_travel_m);
        // A billet does not grow: a contact higher than the last one (beyond the tolerance)
        // breaks the chain (another billet, or the part turned over); within it, the billet
        // kept its height (the rise is the contact's own scatter).
        let chained = self
            .chain
            .filter(|_| !offset_unknown)
            .map(|(x_prev, h_prev)| (h_prev - (x_contact_m - x_prev), h_prev))
            .filter(|(h, h_prev)| *h <= h_prev + tolerance_m && *h > 0.0)
            .map(|(h, h_prev)| h.min(h_prev));
        let sheet = self
            .process
            .as_ref()
            .and_then(|p| self.billet_blows.checked_sub(2).and_then(|i| p.measured_final_heights_m.get(i).copied()));
        let check =
            chained.zip(sheet).map(|(encoder_m, sheet_m)| HeightCheck::compare(sheet_m, encoder_m, tolerance_m));
        match (chained, sheet) {
            (Some(h), _) => (Some(h), check, HeightSource::Encoder),
            (None, Some(h)) if offset_unknown => (Some(h), check, HeightSource::Sheet),
            (None, _) => match self.h_m {
                Some(h) => (Some(h), check, self.h_source),
                None => (None, check, HeightSource::Unknown),
            },
        }
    }
}
