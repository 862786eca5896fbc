//! One summary per billet (issue 22): the blows a part took, its heights, the energy that
//! reached it and its first hard blow, gathered from the blows' estimates as they come.
//! A billet's summary is final when the next billet starts (by the encoder's detection or
//! a signal); the billet still in the dies when a run ends is summarised as unfinished.
//! Pure code: the same in a live run and in a replay.

use serde::Serialize;

use super::result::{BlowClass, BlowEstimate};

/// What a billet is forged as (issue 44): the part's id, its lot and the die set, as set
/// by the operator, the PLC, OPC UA or `[part]` (the session stamps each summary with the
/// trace in force on its blows). Each is absent until set.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Trace {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part_id: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lot: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub die_set: Option<String>,
}

/// What one billet took. Energies add up the complete blows only; `incomplete_blows`
/// says how many blows they leave out (`energies_partial`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BilletSummary {
    /// The billet's number, from 1.
    pub billet: u32,
    /// Device time of its first blow's contact, s.
    pub t_start_s: f64,
    /// Device time of its last blow's end, s.
    pub t_end_s: f64,
    pub blows: u32,
    /// Blows with samples lost inside them: not in the energies.
    pub incomplete_blows: u32,
    /// Blows with a value outside its physical range (issue 36): not in the energies.
    pub implausible_blows: u32,
    /// Whether the energies leave out incomplete or implausible blows.
    pub energies_partial: bool,
    /// Height before the first blow, m (the sheet's, or the encoder's when they differ).
    pub h_start_m: Option<f64>,
    /// The first blow's height from the encoder minus the sheet's, m, when reported.
    pub h_start_off_sheet_m: Option<f64>,
    /// Height after the last blow, m, when tracked.
    pub h_end_m: Option<f64>,
    /// Kinetic energy of the complete blows, J.
    #[serde(rename = "kinetic_in_J")]
    pub kinetic_in_j: f64,
    /// Plastic work of the complete blows, J (plastic plus friction without a sheet).
    #[serde(rename = "plastic_J")]
    pub plastic_j: f64,
    /// Friction work of the complete blows, J; `None` when a blow had none (no sheet).
    #[serde(rename = "friction_J")]
    pub friction_j: Option<f64>,
    /// Plastic over kinetic over the complete blows; `None` without one.
    pub efficiency: Option<f64>,
    /// The blow number on the billet of its first hard blow, if any.
    pub first_hard_blow: Option<u32>,
    pub hard_blows: u32,
    pub alerts: u32,
    /// Blows whose contact the billet detector flagged (`billet_check`).
    pub checked_blows: u32,
    /// Whether the next billet started; `false`: the run ended with this one in the dies.
    pub finished: bool,
    /// What it was forged as; absent parts are left out of its JSON.
    #[serde(flatten)]
    pub trace: Trace,
}

impl BilletSummary {
    fn open(e: &BlowEstimate) -> Self {
        BilletSummary {
            billet: e.billet.billet,
            t_start_s: e.t_contact_s,
            t_end_s: e.t_end_s,
            blows: 0,
            incomplete_blows: 0,
            implausible_blows: 0,
            energies_partial: false,
            h_start_m: e.h_start_m,
            h_start_off_sheet_m: e.billet.h_start_off_sheet_m,
            h_end_m: None,
            kinetic_in_j: 0.0,
            plastic_j: 0.0,
            friction_j: Some(0.0),
            efficiency: None,
            first_hard_blow: None,
            hard_blows: 0,
            alerts: 0,
            checked_blows: 0,
            finished: false,
            trace: Trace::default(),
        }
    }

    fn add(&mut self, e: &BlowEstimate) {
        self.blows += 1;
        self.t_end_s = e.t_end_s;
        self.h_end_m = e.h_end_m;
        self.alerts += u32::from(e.alert.is_some());
        self.checked_blows += u32::from(e.billet.billet_check.is_some());
        match (e.kinetic_in_j, e.plastic_j) {
            (Some(kinetic), Some(plastic)) if e.has_energies() => {
                self.kinetic_in_j += kinetic;
                self.plastic_j += plastic;
                self.friction_j = self.friction_j.zip(e.friction_j).map(|(a, b)| a + b);
                self.efficiency = (self.kinetic_in_j > 0.0).then(|| self.plastic_j / self.kinetic_in_j);
            }
            _ => {
                if e.class == BlowClass::Implausible {
                    self.implausible_blows += 1;
                } else {
                    self.incomplete_blows += 1;
                }
                self.energies_partial = true;
            }
        }
        if e.class == BlowClass::Hard {
            self.hard_blows += 1;
            self.first_hard_blow = self.first_hard_blow.or(Some(e.billet.billet_blow));
        }
    }
}

/// One line for an operator: `billet 3: 8 blows, height 112.00 -> 40.12 mm, ...`.
impl std::fmt::Display for BilletSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mm = |h: Option<f64>| h.map_or("-".to_string(), |h| format!("{:.2}", h * 1e3));
        write!(f, "billet {}", self.billet)?;
        let t = &self.trace;
        for (word, v) in [("part", &t.part_id), ("lot", &t.lot), ("die set", &t.die_set)] {
            if let Some(v) = v {
                write!(f, " {word} {v}")?;
            }
        }
        if !self.finished {
            write!(f, " (in the dies at the end)")?;
        }
        write!(f, ": {} blows", self.blows)?;
        if self.incomplete_blows > 0 {
            write!(f, " ({} incomplete)", self.incomplete_blows)?;
        }
        if self.implausible_blows > 0 {
            write!(f, " ({} implausible)", self.implausible_blows)?;
        }
        write!(f, ", height {} -> {} mm, plastic {:.0} J", mm(self.h_start_m), mm(self.h_end_m), self.plastic_j)?;
        if self.energies_partial {
            write!(f, " (complete blows only)")?;
        }
        match self.efficiency {
            Some(e) => write!(f, ", efficiency {e:.3}")?,
            None => write!(f, ", efficiency -")?,
        }
        match self.first_hard_blow {
            Some(n) => write!(f, ", first hard blow {n}"),
            None => write!(f, ", no hard blow"),
        }
    }
}

/// Gathers blows into billets, by the billet number each estimate carries.
#[derive(Debug, Clone, Default)]
pub struct BilletBook {
    open: Option<BilletSummary>,
}

impl BilletBook {
    /// Add a blow; returns the billet before it, finished, when this blow started another.
    /// Blows without a billet (number 0, from recordings older than issue 22) are left out.
    pub fn on_blow(&mut self, e: &BlowEstimate) -> Option<BilletSummary> {
        if e.billet.billet == 0 {
            return None;
        }
        let done = match &self.open {
            Some(b) if b.billet != e.billet.billet => self.finish(),
            _ => None,
        };
        self.open.get_or_insert_with(|| BilletSummary::open(e)).add(e);
        done
    }

    /// A new billet was signalled: the one in the dies is finished.
    pub fn finish(&mut self) -> Option<BilletSummary> {
        self.open.take().map(|mut b| {
            b.finished = true;
            b
        })
    }

    /// The run ends: the billet in the dies, unfinished.
    pub fn close(&mut self) -> Option<BilletSummary> {
        self.open.take()
    }

    /// The billet in the dies so far.
    pub fn current(&self) -> Option<&BilletSummary> {
        self.open.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::BilletTag;

    fn blow(billet: u32, billet_blow: u32, class: BlowClass, kinetic: f64, plastic: f64) -> BlowEstimate {
        let complete = class != BlowClass::Incomplete;
        let t = f64::from(billet * 10 + billet_blow);
        BlowEstimate {
            judgement: None,
            blow: billet * 10 + billet_blow,
            t_contact_s: t,
            v_impact_mps: 5.0,
            kinetic_in_j: complete.then_some(kinetic),
            plastic_j: complete.then_some(plastic),
            friction_j: complete.then_some(0.1 * plastic),
            damped_j: None,
            elastic_j: None,
            efficiency: complete.then_some(plastic / kinetic),
            final_load_n: 0.0,
            h_end_m: complete.then_some(0.1 - 0.01 * f64::from(billet_blow)),
            class,
            alert: None,
            t_end_s: t + 0.01,
            peak_load_n: 0.0,
            residual: None,
            gap_s: 0.0,
            h_start_m: Some(0.1 - 0.01 * f64::from(billet_blow - 1)),
            height_source: crate::estimate::HeightSource::Unknown,
            implausible: None,
            flow_stress_scale: None,
            model_residual: None,
            model_residual_by_phase: None,
            scale_by_half: None,
            at_bound: Default::default(),
            height_check: None,
            sensor_check: None,
            method: None,
            billet: BilletTag { billet, billet_blow, billet_check: None, h_start_off_sheet_m: None },
            channels: Default::default(),
            efficiency_sd: None,
            unobserved: Default::default(),
            excluded: Default::default(),
            acc_check: None,
        }
    }

    #[test]
    fn blows_are_summed_per_billet_and_a_billet_closes_when_the_next_starts() {
        let mut book = BilletBook::default();
        let blows = [
            blow(1, 1, BlowClass::Soft, 1000.0, 900.0),
            blow(1, 2, BlowClass::Intermediate, 1000.0, 600.0),
            blow(1, 3, BlowClass::Hard, 1000.0, 300.0),
            blow(1, 4, BlowClass::Hard, 1000.0, 200.0),
            blow(2, 1, BlowClass::Soft, 2000.0, 1800.0),
        ];
        let done: Vec<_> = blows.iter().filter_map(|b| book.on_blow(b)).collect();
        assert_eq!(done.len(), 1);
        let b = &done[0];
        assert_eq!((b.billet, b.blows, b.hard_blows, b.first_hard_blow), (1, 4, 2, Some(3)));
        assert!(b.finished && !b.energies_partial);
        assert_eq!((b.kinetic_in_j, b.plastic_j), (4000.0, 2000.0));
        assert!((b.friction_j.expect("sheet") - 200.0).abs() < 1e-9);
        assert_eq!(b.efficiency, Some(0.5));
        assert_eq!((b.h_start_m, b.h_end_m), (Some(0.1), Some(0.1 - 0.04)));
        assert_eq!((b.t_start_s, b.t_end_s), (11.0, 14.01));
        assert_eq!(
            b.to_string(),
            "billet 1: 4 blows, height 100.00 -> 60.00 mm, plastic 2000 J, efficiency 0.500, first hard blow 3"
        );
        let last = book.close().expect("billet 2 open");
        assert_eq!((last.billet, last.blows, last.finished), (2, 1, false));
        assert_eq!(book.close(), None);
    }

    #[test]
    fn incomplete_blows_are_counted_not_summed_and_mark_the_energies_partial() {
        let mut book = BilletBook::default();
        book.on_blow(&blow(3, 1, BlowClass::Soft, 1000.0, 900.0));
        book.on_blow(&blow(3, 2, BlowClass::Incomplete, 0.0, 0.0));
        let b = book.finish().expect("open");
        assert_eq!((b.blows, b.incomplete_blows, b.energies_partial), (2, 1, true));
        assert_eq!((b.kinetic_in_j, b.plastic_j), (1000.0, 900.0));
        // The last blow's end height is unknown, so is the billet's.
        assert_eq!(b.h_end_m, None);
        assert!(b.finished);
        // A blow of an older recording, with no billet, is left out.
        let mut old = blow(1, 1, BlowClass::Soft, 1.0, 1.0);
        old.billet.billet = 0;
        assert_eq!(book.on_blow(&old), None);
        assert_eq!(book.current(), None);
    }
}
