//! The estimator's thresholds and what it is told about the DAQ (`EstimatorConfig`), with
//! the defaults named: the efficiency classes, the approach window, the encoder's and the
//! caliper's resolutions, the new-billet rules and the encoder's die reference.

use super::billet;
use super::result::BlowClass;
use crate::physics::machine::MachineKind;

/// Thresholds of the estimator, with the defaults named.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorConfig {
    /// Efficiency at or above which a blow is `soft` (`DEFAULT_SOFT_MIN` says why 0.75).
    pub soft_min: f64,
    /// At or above which it is `intermediate`; below, `hard` (seed 000 §4.3: 20–50 %).
    pub intermediate_min: f64,
    /// Length of the approach window of the impact-speed fit, s.
    pub fit_s: f64,
    /// The ram encoder's resolution, m (docs/interfaces.md §1: "quantised, for example 10 µm").
    pub encoder_resolution_m: f64,
    /// The resolution of the process sheet's measured heights, m: a digital caliper reads
    /// 0.01 mm and is good to ±0.02 mm over 100 mm (DIN 862).
    pub caliper_resolution_m: f64,
    /// A contact higher than the last blow's end by more than this starts a new billet, m;
    /// `None`: `billet::NEW_BILLET_RISE_FRACTION` of the sheet's height, at least
    /// `billet::NEW_BILLET_RISE_COUNTS` encoder counts.
    pub new_billet_rise_m: Option<f64>,
    /// After an idle gap this long, any rise beyond the measurement starts a new billet, s.
    pub idle_new_billet_s: f64,
    /// The encoder's reading with the ram on the lower die, m, when the DAQ's encoder is
    /// referenced to the die (a die-closing calibration). Then every billet's height at its
    /// first contact is measured, the first billet's too; `None`: the first billet is taken
    /// to be the sheet's height and teaches the reference.
    pub encoder_at_die_m: Option<f64>,
    /// Which way the ram encoder counts (docs/interfaces.md §1: `disp_m` is positive towards the lower
    /// die; an encoder mounted the other way is a configuration matter).
    pub encoder_direction: EncoderDirection,
}

/// Which way the ram encoder counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EncoderDirection {
    /// Each blow's approach tells: the ram falls, or is driven, towards the die before
    /// contact, so an encoder whose reading falls then counts up and is read negated.
    #[default]
    Auto,
    /// Positive towards the lower die (docs/interfaces.md §1).
    Down,
    /// Positive away from the die: read negated.
    Up,
}

impl EncoderDirection {
    /// The words of `[encoder] direction` and `--encoder-direction`.
    pub const WORDS: [&'static str; 3] = ["auto", "down", "up"];

    pub fn as_str(&self) -> &'static str {
        match self {
            EncoderDirection::Auto => "auto",
            EncoderDirection::Down => "down",
            EncoderDirection::Up => "up",
        }
    }

    /// The direction named `s` (`as_str`).
    pub fn parse(s: &str) -> Option<Self> {
        [EncoderDirection::Auto, EncoderDirection::Down, EncoderDirection::Up].into_iter().find(|d| d.as_str() == s)
    }
}

impl EstimatorConfig {
    /// Seed 000 §4.3 puts soft blows at 80–90 % and hard ones at 20–50 %, and calls its
    /// blows 1–4 soft (simulated efficiency down to 0.807) and 5–6 intermediate (0.722 and
    /// 0.614): a soft threshold between 0.722 and 0.807 classes the paper's blows as the
    /// paper does, and 0.75 lies within that gap. Below 0.50 a blow is hard, the top of
    /// the paper's hard range.
    pub const DEFAULT_SOFT_MIN: f64 = 0.75;
    pub const DEFAULT_INTERMEDIATE_MIN: f64 = 0.50;
    pub const DEFAULT_ENCODER_RESOLUTION_M: f64 = 10e-6;
    pub const DEFAULT_CALIPER_RESOLUTION_M: f64 = 0.02e-3;

    pub fn for_kind(kind: MachineKind) -> Self {
        EstimatorConfig {
            soft_min: Self::DEFAULT_SOFT_MIN,
            intermediate_min: Self::DEFAULT_INTERMEDIATE_MIN,
            // 10 ms of a 4 m/s free fall is 40 mm of travel; 50 ms at 0.35 m/s is 17 mm.
            fit_s: match kind {
                MachineKind::Hammer => 0.010,
                MachineKind::ScrewPress => 0.050,
            },
            encoder_resolution_m: Self::DEFAULT_ENCODER_RESOLUTION_M,
            caliper_resolution_m: Self::DEFAULT_CALIPER_RESOLUTION_M,
            new_billet_rise_m: None,
            idle_new_billet_s: billet::DEFAULT_IDLE_NEW_BILLET_S,
            encoder_at_die_m: None,
            encoder_direction: EncoderDirection::Auto,
        }
    }

    /// How far an encoder's height and a measured one may differ and still agree, m: the
    /// encoder's and the caliper's resolutions and one sample's travel at impact (the
    /// contact is known to a sample). `replay`'s `height_check` and `identify`'s cross-check
    /// both hold the sheet to this.
    pub fn height_tolerance_m(&self, sample_travel_m: f64) -> f64 {
        self.encoder_resolution_m + self.caliper_resolution_m + sample_travel_m
    }

    pub fn classify(&self, efficiency: f64) -> BlowClass {
        if efficiency >= self.soft_min {
            BlowClass::Soft
        } else if efficiency >= self.intermediate_min {
            BlowClass::Intermediate
        } else {
            BlowClass::Hard
        }
    }
}
