//! What the estimator reports for each blow: the JSON line of `forgemon replay`
//! (docs/interfaces.md §5) and the MCAP blow-result message.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::estimate::billet::BilletCheck;

/// Which rule fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AlertKind {
    /// The blows have turned elastic (docs/interfaces.md §5 `"elastic_blow"`).
    ElasticBlow,
    /// The energy balance no longer closes: the model does not describe the machine.
    ModelHealth,
    /// The load sensor and the accelerometer disagree (`sensor_check`) on `sensor_k` of
    /// the last `sensor_n` complete blows: a wrong gain, a drifting charge amplifier, a
    /// loose or dead accelerometer.
    Sensor,
    /// The blow left its recipe's windows or envelope (docs/interfaces.md §5 `judgement`).
    Nok,
    /// From the service, not a blow: the recording's disk is low or a write failed.
    Storage,
    /// From the service: a die set reached its warning or its limit (`[die_life]`).
    DieLife,
    /// From the service: a quantity drifts at the same settings (`alert::drift`).
    Drift,
}

impl AlertKind {
    pub fn as_str(&self) -> &'static str {
        match self {
            AlertKind::ElasticBlow => "elastic_blow",
            AlertKind::ModelHealth => "model_health",
            AlertKind::Sensor => "sensor",
            AlertKind::Nok => "nok",
            AlertKind::Storage => "storage",
            AlertKind::DieLife => "die_life",
            AlertKind::Drift => "drift",
        }
    }
}

/// An alert with the blow, the figures and a plain-language reason.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Alert {
    pub kind: AlertKind,
    pub blow: u32,
    pub reason: String,
    /// The figures behind it, by name (e.g. "efficiency": 0.31).
    pub figures: BTreeMap<String, f64>,
}

/// Efficiency class of a blow (seed 000 §4.3: soft blows 80–90 %, hard 20–50 %).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BlowClass {
    Soft,
    Intermediate,
    Hard,
    /// Samples were lost inside the blow and it could not be estimated through the hole
    /// (docs/interfaces.md §5): no energies, no efficiency, never an alert.
    Incomplete,
    /// An input or an output lies outside its physical range (`plausibility`): no energies,
    /// no efficiency, no efficiency alert; `reason` says which.
    Implausible,
}

impl BlowClass {
    pub fn as_str(&self) -> &'static str {
        match self {
            BlowClass::Soft => "soft",
            BlowClass::Intermediate => "intermediate",
            BlowClass::Hard => "hard",
            BlowClass::Incomplete => "incomplete",
            BlowClass::Implausible => "implausible",
        }
    }

    /// The class named `s` (`as_str`), `None` for a name this version does not know.
    pub fn parse(s: &str) -> Option<Self> {
        [BlowClass::Soft, BlowClass::Intermediate, BlowClass::Hard, BlowClass::Incomplete, BlowClass::Implausible]
            .into_iter()
            .find(|c| c.as_str() == s)
    }
}

/// The billet's start height from the encoder against the process sheet's measured height
/// after the blow before (issue 15: measured heights are measurements, cross-checked).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HeightCheck {
    /// The sheet's measured height after the previous blow, m.
    pub sheet_m: f64,
    /// The start height chained from the encoder's contact positions, m.
    pub encoder_m: f64,
    /// The encoder's and caliper's resolutions and one sample's travel at impact, m.
    pub tolerance_m: f64,
    /// `|sheet_m - encoder_m| <= tolerance_m`.
    pub agree: bool,
}

impl HeightCheck {
    /// The sheet's height against the encoder's, within `tolerance_m`
    /// (`EstimatorConfig::height_tolerance_m`).
    pub fn compare(sheet_m: f64, encoder_m: f64, tolerance_m: f64) -> HeightCheck {
        HeightCheck { sheet_m, encoder_m, tolerance_m, agree: (sheet_m - encoder_m).abs() <= tolerance_m }
    }
}

/// Where a blow's start height came from (docs/interfaces.md §5 `height_source`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum HeightSource {
    /// The ram encoder: the chain from the blow before's contact on a continuous encoder, or
    /// the die reference less the contact.
    Encoder,
    /// The process sheet: its billet height (a billet's first blow), or its measured height
    /// after the blow before (the encoder's offset unknown).
    Sheet,
    /// The model's own end height of the blow before.
    Model,
    /// Not known (no process sheet, or the billet's track was lost).
    Unknown,
}

impl HeightSource {
    pub fn as_str(&self) -> &'static str {
        match self {
            HeightSource::Encoder => "encoder",
            HeightSource::Sheet => "sheet",
            HeightSource::Model => "model",
            HeightSource::Unknown => "unknown",
        }
    }

    /// The source named `s` (`as_str`), `None` for a name this version does not know.
    pub fn parse(s: &str) -> Option<Self> {
        [HeightSource::Encoder, HeightSource::Sheet, HeightSource::Model, HeightSource::Unknown]
            .into_iter()
            .find(|h| h.as_str() == s)
    }
}

/// Which billet a blow forged, as the encoder (or a new-billet signal) told it (issue 22).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct BilletTag {
    /// The billet's number, from 1 (0: not known, a result from an older recording).
    pub billet: u32,
    /// The blow's number on its billet, from 1.
    pub billet_blow: u32,
    /// A contact the billet detector could not reconcile, `None` when all is consistent.
    pub billet_check: Option<BilletCheck>,
    /// On a billet's first blow: its start height from the encoder minus the sheet's, m,
    /// when the two differ by more than the caliper's and the encoder's resolution and one
    /// sample's travel together; `None` otherwise.
    pub h_start_off_sheet_m: Option<f64>,
}

/// One blow as measured and estimated. Field names and units are those of docs/interfaces.md §5;
/// the extra fields are additions the contract allows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlowEstimate {
    pub blow: u32,
    /// Device time of first contact, s (the recording's own time origin).
    pub t_contact_s: f64,
    pub v_impact_mps: f64,
    /// The energies and the efficiency are `None` on an incomplete blow (docs/interfaces.md §5).
    #[serde(rename = "kinetic_in_J")]
    pub kinetic_in_j: Option<f64>,
    /// Plastic work; without a process sheet, plastic plus friction work.
    #[serde(rename = "plastic_J")]
    pub plastic_j: Option<f64>,
    /// `None` without a process sheet.
    #[serde(rename = "friction_J")]
    pub friction_j: Option<f64>,
    #[serde(rename = "damped_J")]
    pub damped_j: Option<f64>,
    #[serde(rename = "elastic_J")]
    pub elastic_j: Option<f64>,
    /// In [0, 1].
    pub efficiency: Option<f64>,
    #[serde(rename = "final_load_N")]
    pub final_load_n: f64,
    /// Billet height after the blow, m, tracked from the process sheet; `None` without one.
    pub h_end_m: Option<f64>,
    pub class: BlowClass,
    /// The alert this blow raised, if any.
    pub alert: Option<Alert>,
    /// The blow against the active recipe (docs/interfaces.md §5, §9): `None` without one, and on an
    /// incomplete blow, which is never judged.
    pub judgement: Option<crate::recipe::Judgement>,
    /// Device time at which the blow's end was detected, s.
    pub t_end_s: f64,
    #[serde(rename = "peak_load_N")]
    pub peak_load_n: f64,
    /// Energy-balance residual `(in - out) / in`: the model-health figure (DESIGN.md §2.4).
    pub residual: Option<f64>,
    /// Load sensor against accelerometer (`estimate::sensor`): the load's impulse over the
    /// momentum the machine lost, less 1; `None` on an incomplete blow or when the
    /// accelerometer gave nothing to compare (docs/interfaces.md §5).
    pub sensor_check: Option<f64>,
    /// How the energies were estimated: `observer` or `model_fit` (`Estimator::method_for`);
    /// `None` on an incomplete blow.
    pub method: Option<super::Method>,
    /// Time lost inside the blow, s: samples interpolated across holes between the start of
    /// the approach fit and the blow's end, plus any time a break in the stream cut off.
    pub gap_s: f64,
    /// Billet height before the blow, m, when known.
    pub h_start_m: Option<f64>,
    /// Where `h_start_m` came from.
    pub height_source: HeightSource,
    /// The encoder's start height against the sheet's measurement, where both exist.
    pub height_check: Option<HeightCheck>,
    /// The billet the blow forged.
    #[serde(flatten)]
    pub billet: BilletTag,
    /// Why the blow is `implausible` (docs/interfaces.md §5 `reason`), `None` otherwise.
    #[serde(rename = "reason", serialize_with = "reason_text")]
    pub implausible: Option<Implausible>,
    /// The scale of the sheet's flow stress the blow's measured work needs under the model:
    /// the fitted scale, or the observed deformation work over the law's work along the same
    /// compression (issue 37). Within one billet it stays put while the model fits; its drift
    /// from the billet's first blow is a model-health figure (`alert`). `None` without a
    /// sheet, a height, or whole samples.
    pub flow_stress_scale: Option<f64>,
    /// The same scale over the first and the second half of the blow's compression (the
    /// model observer's, from whole samples): where in the stroke the work departs from the
    /// model, for the model-health alert's reason. Not in the JSON or the recording: a
    /// replay computes it again.
    #[serde(skip)]
    pub scale_by_half: Option<[f64; 2]>,
    /// How far the model fitted to the blow stays from the measured load: the RMS of the
    /// load's residual over the fitted window, a fraction of the measured peak
    /// (`fit::ModelResidual`). The model is fitted at every rate for this, as the check that
    /// it still describes the machine; the model-health alert weighs it (`alert`). `None`
    /// without a sheet, a height, or whole samples.
    pub model_residual: Option<f64>,
    /// The same by phase of the blow (impact, forming, spring-back): where the model and the
    /// measurement part. Not in the recording: a replay computes it again.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_residual_by_phase: Option<super::fit::PhaseResidual>,
    /// The values reported at a bound of their range, as computed (`plausibility`): within
    /// the estimate's accuracy of it. Left out of the JSON when empty.
    #[serde(skip_serializing_if = "AtBound::is_empty")]
    pub at_bound: AtBound,
    /// The sensor channels the estimate used (docs/interfaces.md §5 `channels`): all three,
    /// or fewer when the source lacks one (issue 43).
    pub channels: crate::signal::sample::Channels,
    /// The efficiency's 1σ under the mode's own error model (`estimate::modes`), `None`
    /// when there is no efficiency.
    pub efficiency_sd: Option<f64>,
    /// Why a value the contract reports is `null` although the blow is whole: the field's
    /// name and the reason in words (the channel that would observe it is missing). Left
    /// out of the JSON when empty.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub unobserved: BTreeMap<String, String>,
    /// The channels the source sent but the blow's estimate left out, by short name, with
    /// why (`estimate::faults`: a channel stuck at one value). Left out of the JSON when
    /// empty.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub excluded: BTreeMap<String, String>,
    /// The accelerometer against the encoder by kinematics (`faults::acc_against_encoder`):
    /// `acc / encoder − 1` over the blow's lost travel; `None` without both channels or on
    /// an incomplete blow. With `sensor_check` it tells which of the load and the
    /// accelerometer is off when the two disagree (issue 43).
    pub acc_check: Option<f64>,
}

/// The reason of an implausible blow, as its words.
fn reason_text<S: serde::Serializer>(i: &Option<Implausible>, s: S) -> Result<S::Ok, S::Error> {
    match i {
        Some(i) => s.serialize_some(&i.reason),
        None => s.serialize_none(),
    }
}

impl BlowEstimate {
    /// Blow `blow`, in contact from `t_contact_s` to `t_end_s` at `v_impact_mps`, with
    /// nothing estimated yet: `Incomplete`, every energy and height unknown, no checks.
    pub fn incomplete(blow: u32, t_contact_s: f64, v_impact_mps: f64, t_end_s: f64) -> BlowEstimate {
        BlowEstimate {
            judgement: None,
            blow,
            t_contact_s,
            v_impact_mps,
            kinetic_in_j: None,
            plastic_j: None,
            friction_j: None,
            damped_j: None,
            elastic_j: None,
            efficiency: None,
            final_load_n: 0.0,
            h_end_m: None,
            class: BlowClass::Incomplete,
            alert: None,
            t_end_s,
            peak_load_n: 0.0,
            residual: None,
            sensor_check: None,
            method: None,
            gap_s: 0.0,
            h_start_m: None,
            height_source: HeightSource::Unknown,
            height_check: None,
            billet: BilletTag::default(),
            implausible: None,
            flow_stress_scale: None,
            scale_by_half: None,
            model_residual: None,
            model_residual_by_phase: None,
            at_bound: Default::default(),
            channels: crate::signal::sample::Channels::ALL,
            efficiency_sd: None,
            unobserved: BTreeMap::new(),
            excluded: BTreeMap::new(),
            acc_check: None,
        }
    }

    /// Whether the blow was estimated whole (not `incomplete`).
    pub fn is_complete(&self) -> bool {
        self.class != BlowClass::Incomplete
    }

    /// Whether its energies and efficiency are reported: neither incomplete nor implausible.
    pub fn has_energies(&self) -> bool {
        !matches!(self.class, BlowClass::Incomplete | BlowClass::Implausible)
    }
}

/// Blows with every field set, for the unit tests of what carries them (the recorder, the
/// PLC image, the OPC UA event, the Sparkplug payload, the advisor).
/// The raw values of the fields reported at a bound, by name (JSON `at_bound`).
pub type AtBound = BTreeMap<String, f64>;

/// Which check a blow failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Check {
    ImpactSpeed,
    StartHeight,
    EndHeight,
    Energy,
    Efficiency,
    Balance,
    FinalLoad,
}

impl Check {
    pub const ALL: [Check; 7] = [
        Check::ImpactSpeed,
        Check::StartHeight,
        Check::EndHeight,
        Check::Energy,
        Check::Efficiency,
        Check::Balance,
        Check::FinalLoad,
    ];

    pub fn as_str(&self) -> &'static str {
        match self {
            Check::ImpactSpeed => "impact_speed",
            Check::StartHeight => "start_height",
            Check::EndHeight => "end_height",
            Check::Energy => "energy",
            Check::Efficiency => "efficiency",
            Check::Balance => "balance",
            Check::FinalLoad => "final_load",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        Check::ALL.into_iter().find(|c| c.as_str() == s)
    }

    /// The alert a billet with such a blow raises: an input out of range (the encoder, the
    /// clock) is a sensor matter, an output out of range a model matter.
    pub fn alert_kind(&self) -> AlertKind {
        match self {
            Check::ImpactSpeed | Check::StartHeight | Check::FinalLoad => AlertKind::Sensor,
            Check::EndHeight | Check::Energy | Check::Efficiency | Check::Balance => AlertKind::ModelHealth,
        }
    }
}

/// Why a blow is implausible: the check it failed and, in words, the value and its range.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Implausible {
    pub check: Check,
    pub reason: String,
}

impl Implausible {
    pub(super) fn new(check: Check, reason: String) -> Self {
        Implausible { check, reason }
    }
}

#[cfg(test)]
pub(crate) mod examples {
    use super::*;

    /// An intermediate blow whose figures each round differently in the PLC's units.
    pub(crate) fn intermediate() -> BlowEstimate {
        BlowEstimate {
            kinetic_in_j: Some(10_280.4),
            plastic_j: Some(7_195.6),
            friction_j: Some(900.0),
            damped_j: Some(500.0),
            elastic_j: Some(100.0),
            efficiency: Some(0.699_95),
            final_load_n: 1.0e6,
            h_end_m: Some(0.040_123),
            class: BlowClass::Intermediate,
            peak_load_n: 1_234_567.0,
            residual: Some(0.0),
            at_bound: AtBound::new(),
            ..BlowEstimate::incomplete(7, 1.0, 5.2996, 1.02)
        }
    }

    /// A soft blow numbered `blow`, like the demo's first.
    pub(crate) fn soft(blow: u32) -> BlowEstimate {
        BlowEstimate {
            judgement: None,
            blow,
            t_contact_s: 0.12 * f64::from(blow),
            v_impact_mps: 3.9,
            kinetic_in_j: Some(5711.0),
            plastic_j: Some(5320.0),
            friction_j: None,
            damped_j: Some(150.0),
            elastic_j: Some(15.0),
            efficiency: Some(0.931),
            final_load_n: 3.25e5,
            h_end_m: Some(0.0929),
            class: BlowClass::Soft,
            alert: None,
            t_end_s: 0.14,
            peak_load_n: 1.16e6,
            residual: Some(0.004),
            sensor_check: Some(0.012),
            method: None,
            gap_s: 0.0,
            h_start_m: None,
            height_source: HeightSource::Unknown,
            height_check: None,
            implausible: None,
            flow_stress_scale: None,
            scale_by_half: None,
            model_residual: None,
            model_residual_by_phase: None,
            at_bound: AtBound::new(),
            billet: Default::default(),
            channels: crate::signal::sample::Channels::ALL,
            efficiency_sd: Some(0.01),
            unobserved: BTreeMap::new(),
            excluded: BTreeMap::new(),
            acc_check: Some(-0.003),
        }
    }
}
