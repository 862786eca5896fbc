//! Per-blow estimation with the identified model on measured signals (DESIGN.md §2.4):
//! impact speed from the approach, the energy terms either from the model observer run on
//! the samples or from the machine model fitted to them (`fit`, issue 16), the split into
//! plastic and friction work along the billet's tracked height when a process sheet is
//! given, the efficiency class and the energy-balance residual. Which billet each blow
//! forged comes from the encoder (`billet`) or a new-billet signal. Pure code.
//!
//! **Which method, per blow** (`Estimator::method_for`): the observer differentiates the
//! measured load through the machine's second mode, so it needs that mode resolved: it is
//! used when the samples give at least `OBSERVER_MIN_SAMPLES_PER_MODE` per period of the
//! second mode, or when there is nothing to fit (no process sheet, no tracked height).
//! Otherwise the model is fitted. Contact is located between samples either way: by the
//! fit, or by a hinge fitted to the start of the load's rise (`contact`).

pub mod approach;
pub mod billet;
pub mod billet_book;
pub mod config;
pub mod contact;
pub mod curve;
pub mod decimate;
mod energies;
pub mod faults;
pub mod fit;
mod model_fit;
pub mod modes;
pub mod no_encoder;
pub mod observer;
pub mod plausibility;
pub mod result;
pub mod sensor;
pub mod sensor_chain;
mod track;

pub use config::{EncoderDirection, EstimatorConfig};
pub use result::{BilletTag, BlowClass, BlowEstimate, HeightCheck, HeightSource};

use std::borrow::Cow;

use crate::physics::billet::BilletLaw;
use crate::physics::effects::EffectSet;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::signal::sample::Role;
use crate::signal::segment::{Blow, contact_force_n};
use approach::{ApproachError, ApproachFit, fit_impact_speed};
use billet::{BilletCheck, BilletDetect};
pub use contact::contact_between_samples;
use model_fit::FitStart;
use track::{Continuity, LastEnd};

/// A tracked billet height below this fraction of the sheet's is impossible for an upset
/// cylinder: the billets changed without a new-billet signal, so the height is no longer
/// known (until `new_billet`).
pub const MIN_TRACKED_HEIGHT_FRACTION: f64 = 0.02;

/// The observer is used when a period of the machine's second mode spans at least this
/// many samples (see the module's doc). Measured on the DAQ chain of `daq` (issue 16,
/// tuning seeds of `tests/estimate_rates.rs`): on the hammer (2049 Hz) the observer read
/// efficiencies 0.03 low at 50 kHz (24 samples a period) and within 0.012 at 100 kHz (49),
/// but its end heights scattered by up to 24 µm at 100 kHz once first contact fell between
/// samples, where the fit (on its 10 kHz copy, `decimate`) kept them within 3.6 µm and its
/// efficiencies within 0.013; on the press (275 Hz, 73 samples a period at 20 kHz) both
/// stayed within 0.007 from 5 kHz up, and the observer keeps a press blow's latency near a
/// millisecond where the fit takes tens. So the hammer is fitted up to 100 kHz, the press
/// observed from 20 kHz.
pub const OBSERVER_MIN_SAMPLES_PER_MODE: f64 = 50.0;

/// How a blow's energies were estimated (`"method"` in the results).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The model observer run on the samples (DESIGN.md §2.4).
    Observer,
    /// The machine model fitted to the samples (`fit`).
    ModelFit,
}

impl Method {
    pub fn as_str(&self) -> &'static str {
        match self {
            Method::Observer => "observer",
            Method::ModelFit => "model_fit",
        }
    }

    /// The method named `s` (`as_str`), `None` for a name this version does not know.
    pub fn parse(s: &str) -> Option<Self> {
        [Method::Observer, Method::ModelFit].into_iter().find(|m| m.as_str() == s)
    }
}

/// A blow the estimator could not evaluate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EstimateError {
    #[error("blow {blow}: {source}")]
    Approach {
        blow: u32,
        #[source]
        source: ApproachError,
    },
    /// The encoder's reading fell as the ram approached the die while its direction is set
    /// to down.
    /// The blow lacks a channel its estimate cannot do without here.
    #[error("blow {blow}: {reason}")]
    Unobservable { blow: u32, reason: &'static str },
    #[error(
        "blow {blow}: the ram encoder's reading falls as the ram approaches the die ({v_mps:.3} m/s before \
         contact): it counts up, away from the die, where docs/interfaces.md §1 counts disp_m down towards it. Set \
         [encoder] direction = \"up\" in the service file (--encoder-direction up for replay), or \"auto\""
    )]
    EncoderCountsUp { blow: u32, v_mps: f64 },
}

/// Estimates blow after blow, tracking the billet's height from the process sheet.
#[derive(Debug, Clone)]
pub struct Estimator {
    machine: Machine,
    /// The machine file's effects (`[effects.NAME]`), part of the model in every path:
    /// the sensor chain's high-pass undone on the measured load (`sensor_chain`), the rest
    /// in the model (`model_effects`).
    effects: EffectSet,
    /// The process sheet as given.
    process: Option<Process>,
    /// The sheet with the present billet's own height at its first contact, when the
    /// encoder measured one off the sheet's (`first_blow_height`): a billet's strain counts
    /// from its own height, so its law is the sheet's law on that height.
    billet_process: Option<Process>,
    cfg: EstimatorConfig,
    /// Billet height before the next blow, from the model observer's compression.
    h_m: Option<f64>,
    /// Where `h_m` came from.
    h_source: HeightSource,
    /// The stream broke since the last blow (`stream_break`: a new capture, a new timeline):
    /// the encoder's offset is not known to be the last blow's until a contact shows it.
    unverified: bool,
    /// The last blow's encoder contact position and start height, m: the link of the
    /// encoder's height chain.
    chain: Option<(f64, f64)>,
    blows: u32,
    /// Blows on the present billet, this one included once estimated.
    billet_blows: usize,
    detect: BilletDetect,
    /// The present billet's number (0 before the first).
    billet: u32,
    /// Blows the billet before the present one took.
    prev_billet_blows: usize,
    /// A new-billet signal started the present billet and no blow has landed on it yet.
    signalled: bool,
    /// Where the ram would meet the billet left by the last blow (its contact lowered by
    /// the height it lost, when known), m, whether that is known, and the blow's end time, s.
    last_end: Option<LastEnd>,
    /// The encoder's reading at the lower die, m: learnt from the first billet's first
    /// contact and the sheet's height; each later billet's real height is this minus its
    /// first contact.
    die_x_m: Option<f64>,
    /// The flow-stress scale fitted on the last blow: the next fit's start.
    scale: f64,
    /// How the last blow was estimated.
    last_method: Option<Method>,
    /// Blows whose encoder counted up, read negated (`EncoderDirection::Auto`).
    reversed_blows: u64,
    /// The present billet's height before its first blow, m (the plausible range's top).
    billet_height_m: Option<f64>,
    /// What the last blow's estimate saw of its course (the dashboard's curve).
    last_course: Option<curve::Course>,
}

impl Estimator {
    pub fn new(machine: Machine, process: Option<Process>, cfg: EstimatorConfig) -> Self {
        let h_m = process.as_ref().map(|p| p.billet.height_m);
        let detect = BilletDetect::new(h_m, cfg.encoder_resolution_m, cfg.new_billet_rise_m, cfg.idle_new_billet_s);
        Estimator {
            machine,
            effects: EffectSet::NONE,
            billet_process: process.clone(),
            process,
            cfg,
            h_m,
            h_source: HeightSource::Sheet,
            unverified: false,
            chain: None,
            blows: 0,
            billet_blows: 0,
            detect,
            billet: 0,
            prev_billet_blows: 0,
            signalled: false,
            last_end: None,
            die_x_m: cfg.encoder_at_die_m,
            scale: 1.0,
            last_method: None,
            last_course: None,
            reversed_blows: 0,
            billet_height_m: None,
        }
    }

    /// The model with the machine file's effects (`[effects.NAME]`); `unhonoured` says which
    /// of them need what the estimator is not given.
    pub fn with_effects(mut self, effects: EffectSet) -> Self {
        self.effects = effects;
        self
    }

    /// A new machine model from the next blow on (a SIGHUP after `diagnose --adopt`, a
    /// recording's later `machine.toml`); the billet's track goes on. Refused, the old model
    /// kept, when it is of another kind, or has an effect this estimator cannot honour
    /// (`unhonoured`): the error says which.
    pub fn set_model(&mut self, machine: Machine, effects: EffectSet) -> Result<(), String> {
        if machine.kind() != self.machine.kind() {
            return Err(format!(
                "the machine is a {}, not a {}",
                machine.kind().as_str(),
                self.machine.kind().as_str()
            ));
        }
        if let Some(name) = unhonoured(&effects, self.process.as_ref()) {
            return Err(format!("key 'effects.{name}' needs a process sheet, and the service has none"));
        }
        self.machine = machine;
        self.effects = effects;
        Ok(())
    }

    /// The effects the physics of a blow carries: the sensor chain's high-pass is undone on
    /// the measured load instead (`sensor_chain::restore`).
    fn model_effects(&self) -> EffectSet {
        EffectSet { highpass_tau_s: f64::INFINITY, ..self.effects }
    }

    /// Blows whose encoder was found counting up (away from the die) and read negated, under
    /// `EncoderDirection::Auto`.
    pub fn reversed_blows(&self) -> u64 {
        self.reversed_blows
    }

    /// How the last blow's energies were estimated (`None` before the first, and for an
    /// incomplete blow).
    pub fn last_method(&self) -> Option<Method> {
        self.last_method
    }

    /// What the last blow's estimate saw of its course, taken (`None` for an incomplete blow).
    pub fn take_course(&mut self) -> Option<curve::Course> {
        self.last_course.take()
    }

    /// The rule of the module's doc: the observer when the samples resolve the second mode
    /// and the model has no effect only the fit can carry (`fit_only_effect`).
    pub fn method_for(&self, period_s: f64) -> Method {
        let per_period = 1.0 / (period_s * self.machine.second_mode_hz());
        if per_period >= OBSERVER_MIN_SAMPLES_PER_MODE && fit_only_effect(&self.effects).is_none() {
            Method::Observer
        } else {
            Method::ModelFit
        }
    }

    /// Billets started so far (by the encoder or a signal).
    pub fn billets(&self) -> u32 {
        self.billet
    }

    pub fn config(&self) -> &EstimatorConfig {
        &self.cfg
    }

    /// Whether the billet's height is being tracked (a process sheet, and not lost).
    pub fn tracking_height(&self) -> bool {
        self.h_m.is_some()
    }

    /// The longest hole bridged inside a blow, s: a tenth of the machine's second-mode
    /// period (49 µs on the LG1000's 2049 Hz, 0.36 ms on the SPR 400's 275 Hz). Linear
    /// interpolation across it misses at most 1 − cos(π/10) ≈ 5 % of the ring's amplitude
    /// for that instant, a negligible share of the blow's work.
    pub fn max_bridged_s(&self) -> f64 {
        BRIDGE_FRACTION_OF_MODE_PERIOD / self.machine.second_mode_hz()
    }

    /// Estimate the next blow.
    pub fn estimate(&mut self, blow: &Blow) -> Result<BlowEstimate, EstimateError> {
        self.blows += 1;
        self.last_method = None;
        self.last_course = None;
        // A channel stuck through the blow is left out: the blow is estimated without it.
        let mut excluded = faults::failed_channels(blow);
        let blow = self.prepared(blow, &excluded);
        if !blow.channels().has(Role::Disp) {
            return self.estimate_without_encoder(&blow, excluded);
        }
        self.channels_of(&blow)?;
        let (blow, approach) = self.approach(&blow)?;
        let (blow, approach, judged) = self.outvote(blow, approach, &mut excluded)?;
        if !blow.channels().has(Role::Disp) {
            return self.estimate_without_encoder(&blow, excluded);
        }
        let blow = blow.as_ref();
        let channels = self.channels_of(blow)?;
        let with_load = channels.has(Role::Load);
        let mut h_guess_m = self.h_m.or(self.process.as_ref().map(|p| p.billet.height_m));
        // Contact between samples: from the load's rise, or where the model fits it
        // (without a load, from the segmenter's contact sample).
        let delta0 = if with_load { self.locate_contact(blow, approach.v_impact_mps, h_guess_m) } else { 0.0 };
        // A billet's first blow with the die reference configured: its height from the
        // locator's contact, so that the fit starts on the billet's own law. The fit's move
        // of the contact is then not refitted (that doubled a first blow's latency, 24 ms at
        // 5 kHz on the hammer): the spring-back's set absorbs it (`fill_from_fit`).
        let premeasured = self.billet_blows == 0 && self.process.is_some() && self.cfg.encoder_at_die_m.is_some();
        if let (true, Some(die_x_m)) = (premeasured, self.cfg.encoder_at_die_m) {
            let h_m = die_x_m - approach.at(delta0 * blow.period_s).x_contact_m;
            if let Some(p) = self.billet_process.as_mut() {
                p.billet.height_m = h_m;
            }
            h_guess_m = Some(h_m);
        }
        let gap_s = self.gap_s(blow);
        let complete = blow.lost_s == 0.0 && gap_s <= self.max_bridged_s();
        // The observer runs on the load and the accelerometer: without either, every blow is
        // fitted.
        let observable = with_load && channels.has(Role::Acc);
        let wants_fit = complete && (!observable || self.method_for(blow.period_s) == Method::ModelFit);
        // The residual of the last fit tried, good or not: the blow's model check.
        let mut check = None;
        let fitted = match h_guess_m {
            Some(h) if wants_fit => {
                self.fit(blow, approach, FitStart::at(h, self.scale, delta0, true, self.billet_blows + 1), &mut check)
            }
            _ => None,
        };
        let delta = fitted.as_ref().map_or(delta0, |f| f.contact_samples);
        let fit = approach.at(delta * blow.period_s);
        let t_contact_s = blow.samples[blow.i_contact].t_s + delta * blow.period_s;
        let tolerance_m = self.contact_tolerance_m(fit.v_impact_mps * blow.period_s);
        let placed = self.place(fit.x_contact_m, fit.v_impact_mps * blow.period_s, t_contact_s, tolerance_m);
        let mut e = started(self.blows, blow, (t_contact_s, fit.v_impact_mps), gap_s, &placed);
        e.channels = channels;
        e.excluded = excluded;
        e.acc_check = judged.acc_check;
        if judged.suspect.is_some() {
            e.sensor_check = judged.sensor_check;
        }
        self.chain = placed.h_start_m.map(|h| (fit.x_contact_m, h));
        self.last_end = Some(LastEnd { x_m: fit.x_contact_m, end_known: false, h_end_m: None, t_s: e.t_end_s });
        if !complete {
            // Cut short or holed beyond bridging: nothing after the hole is known, not even
            // the billet's height (the encoder chain takes it up again at the next blow).
            self.h_m = None;
            return Ok(e);
        }
        let first = FirstFit { fitted, check, delta0, premeasured, wants_fit, h_guess_m };
        self.complete(&mut e, blow, approach, first, &placed, tolerance_m);
        Ok(e)
    }

    /// A complete blow's energies, from its first fit on: refitted where the billet's
    /// follow-up put its start height elsewhere than the fit's guess, the contact moved
    /// where the refit moved it, the energies from the fit or the observer, the model check,
    /// and the blow settled (`settle`).
    fn complete(
        &mut self,
        e: &mut BlowEstimate,
        blow: &Blow,
        approach: ApproachFit,
        first: FirstFit,
        placed: &Placed,
        tolerance_m: f64,
    ) {
        let FirstFit { mut fitted, mut check, delta0, premeasured, wants_fit, h_guess_m } = first;
        let delta = fitted.as_ref().map_or(delta0, |f| f.contact_samples);
        let mut h_start_m = placed.h_start_m;
        // The fit ran on a guess of the start height: again from its optimum if the
        // billet's follow-up says otherwise. A fit that failed on the guess (a new billet the
        // guess did not know) is tried afresh from the follow-up's height and the locator's
        // contact.
        let n = self.billet_blows;
        match (&fitted, h_start_m) {
            (Some(f), Some(h0)) if !premeasured && (f.h_start_m - h0).abs() > REFIT_HEIGHT_M => {
                fitted = self.fit(blow, approach, FitStart::at(h0, f.scale, f.contact_samples, false, n), &mut check);
            }
            (None, Some(h0)) if wants_fit && h_guess_m.is_none_or(|h| (h - h0).abs() > REFIT_HEIGHT_M) => {
                fitted = self.fit(blow, approach, FitStart::at(h0, self.scale, delta0, true, n), &mut check);
            }
            _ => {}
        }
        // The refit may have moved contact. A height the encoder measured moves with it
        // (the ram met the billet lower by the shift, so it was that much shorter); a die
        // reference taught by this contact moves the other way; the chain takes the new one.
        let mut x_contact_m = approach.at(delta * blow.period_s).x_contact_m;
        if let Some(f) = fitted.as_ref().filter(|f| f.contact_samples != delta) {
            let x_m = approach.at(f.contact_samples * blow.period_s).x_contact_m;
            let shift_m = x_m - x_contact_m;
            if placed.measured {
                h_start_m = h_start_m.map(|h| h - shift_m);
                e.h_start_m = h_start_m;
            } else if placed.taught {
                self.die_x_m = self.die_x_m.map(|d| d + shift_m);
            }
            x_contact_m = x_m;
            self.chain = h_start_m.map(|h| (x_m, h));
        }
        if h_start_m.is_none() {
            fitted = None;
        }
        let with_load = e.channels.has(Role::Load);
        let h_end_m = match &fitted {
            Some(f) => {
                self.scale = f.scale;
                e.efficiency_sd = modes::efficiency_sd(e.channels, f.efficiency_sd);
                self.fill_from_fit(e, blow, f)
            }
            None if with_load && e.channels.has(Role::Acc) => self.fill_from_observer(e, blow, h_start_m, delta0),
            None => self.unfitted(e),
        };
        // Where the observer takes the blow by the rule, the model is fitted all the same, as
        // the check that it still describes the machine (a few ms a blow: `fit`).
        if let (false, Some(h0)) = (wants_fit, h_start_m)
            && let Some(f) = self.fit(blow, approach, FitStart::at(h0, self.scale, delta0, false, n), &mut check)
        {
            self.scale = f.scale;
            // The observer's efficiency is the model's on the measured load: its sd is the
            // fitted model's, and at least the two methods' disagreement.
            let apart = e.efficiency.map_or(0.0, |x| (x - f.blow.energy.efficiency()).abs());
            e.efficiency_sd = modes::efficiency_sd(e.channels, f.efficiency_sd).map(|sd| sd.hypot(apart));
        }
        // The model check is the load's residual: without a load, none.
        if h_start_m.is_some() && with_load {
            e.model_residual = check.map(|c| c.load);
            e.model_residual_by_phase = check.map(|c| c.load_by_phase);
        }
        // Load against the accelerometer: both are needed.
        if with_load && e.channels.has(Role::Acc) {
            e.sensor_check = sensor::sensor_check(&self.machine, blow, e.v_impact_mps).ok();
        }
        self.settle(e, blow, placed.first, tolerance_m, (x_contact_m, h_start_m, h_end_m));
    }

    /// The approach fit of a blow whose encoder is already read the way it counts.
    fn approach_as_read(&self, blow: &Blow) -> Result<ApproachFit, EstimateError> {
        fit_impact_speed(&blow.samples, blow.i_contact, self.cfg.fit_s, blow.period_s)
            .map_err(|source| EstimateError::Approach { blow: self.blows, source })
    }

    /// The approach fit of `blow`'s encoder as configured to count (`EncoderDirection`);
    /// under `Auto`, one whose reading fell before contact counts up, and is read negated
    /// if then it rises. The blow as read, and its fit.
    fn approach<'b>(&mut self, blow: &'b Blow) -> Result<(Cow<'b, Blow>, ApproachFit), EstimateError> {
        let fit = |b: &Blow| self.approach_as_read(b);
        let n = self.blows;
        match (self.cfg.encoder_direction, fit(blow)) {
            (EncoderDirection::Up, _) => {
                let negated = negate_encoder(blow);
                let a = fit(&negated)?;
                Ok((Cow::Owned(negated), a))
            }
            (_, Ok(a)) => Ok((Cow::Borrowed(blow), a)),
            (direction, Err(e @ EstimateError::Approach { source: ApproachError::NotApproaching { v_mps }, .. }))
                if v_mps < 0.0 =>
            {
                if direction == EncoderDirection::Down {
                    return Err(EstimateError::EncoderCountsUp { blow: n, v_mps });
                }
                let negated = negate_encoder(blow);
                let a = fit(&negated).map_err(|_| e)?;
                self.reversed_blows += 1;
                Ok((Cow::Owned(negated), a))
            }
            (_, Err(e)) => Err(e),
        }
    }

    /// Where a contact at encoder position `x_contact_m` puts the blow on its billet: the
    /// billet's follow-up, the start height and its source, and whether this contact
    /// measured the billet's height (the die reference) or taught the reference (the first
    /// billet's first blow, taken at the sheet's height). Counts the blow on its billet.
    fn place(&mut self, x_contact_m: f64, step_m: f64, t_contact_s: f64, tolerance_m: f64) -> Placed {
        let (mut billet_check, continuity) = self.follow_billet(x_contact_m, t_contact_s, tolerance_m);
        let mut h_start_off_sheet_m = None;
        let (mut measured, mut taught) = (false, false);
        if self.billet_blows == 0 {
            taught = self.die_x_m.is_none();
            h_start_off_sheet_m = self.first_blow_height(x_contact_m, tolerance_m);
            measured = !taught && (self.cfg.encoder_at_die_m.is_some() || h_start_off_sheet_m.is_some());
            if self.prev_billet_blows == 1 && self.billet > 1 {
                billet_check = billet_check.or(Some(BilletCheck::PreviousBilletOneBlow));
            }
        }
        self.billet_blows += 1;
        let first = self.billet_blows == 1;
        let (h_start_m, height_check, height_source) =
            self.start_height(x_contact_m, step_m, continuity == Continuity::OffsetUnknown);
        measured |= !first && height_source == HeightSource::Encoder;
        // An encoder zeroed anew: the height came from elsewhere, and this contact is where
        // the ram meets a billet of that height in the new offset (the die reference too).
        if continuity == Continuity::OffsetUnknown && self.cfg.encoder_at_die_m.is_none() {
            self.die_x_m = h_start_m.map(|h| x_contact_m + h);
            taught = self.die_x_m.is_some();
        }
        let billet =
            BilletTag { billet: self.billet, billet_blow: self.billet_blows as u32, billet_check, h_start_off_sheet_m };
        Placed { billet, first, measured, taught, h_start_m, height_check, height_source }
    }

    /// The blow's last word: incomplete when the stream ended before its spring-back,
    /// every number checked against its range (`plausibility`), and where the billet was
    /// left for the next contact. `at` is the contact's encoder position and the start and
    /// end heights the energies gave.
    fn settle(
        &mut self,
        e: &mut BlowEstimate,
        blow: &Blow,
        first: bool,
        tolerance_m: f64,
        at: (f64, Option<f64>, Option<f64>),
    ) {
        let (x_contact_m, h_start_m, h_end_m) = at;
        // The stream ended before the load had held quiet (a capture's end, a stop): the blow
        // is whole only if its samples show the spring-back, the load back under the end
        // level after the blow's own end of forming (docs/interfaces.md §5: cut by the end of the
        // stream, it is incomplete).
        let h_end_m = match blow.open_end_n {
            Some(level) if !self.spring_back_seen(blow, e.t_contact_s, level) => {
                e.class = BlowClass::Incomplete;
                (e.kinetic_in_j, e.plastic_j, e.friction_j, e.damped_j, e.elastic_j) = (None, None, None, None, None);
                (e.efficiency, e.residual, e.method, e.h_end_m, e.sensor_check) = (None, None, None, None, None);
                self.forget_end();
                None
            }
            _ => h_end_m,
        };
        if first {
            self.billet_height_m = e.h_start_m;
        }
        let ranges = plausibility::Ranges {
            v_max_mps: plausibility::v_max_mps(self.machine.kind()),
            sheet_height_m: self.process.as_ref().map(|p| p.billet.height_m),
            billet_height_m: self.billet_height_m,
            height_tolerance_m: tolerance_m,
        };
        let cfg = self.cfg;
        plausibility::settle(e, &ranges, |x| cfg.classify(x));
        if e.efficiency.is_none() {
            e.efficiency_sd = None;
        }
        // An implausible blow's end is not known: the encoder's chain takes the billet up
        // again from its contact at the next blow (its start height too, when that was in
        // range), as after an incomplete one.
        let h_end_m = if e.class == BlowClass::Implausible {
            self.forget_end();
            self.chain = e.h_start_m.map(|h| (x_contact_m, h));
            None
        } else {
            h_end_m
        };
        // The next contact on this billet comes lower by what the billet lost; without a
        // height, by the ram's deepest travel past contact is all that is known.
        let t_s = e.t_end_s;
        self.last_end = Some(match (h_start_m, h_end_m) {
            (Some(h0), Some(h1)) => LastEnd { x_m: x_contact_m + (h0 - h1), end_known: true, h_end_m: Some(h1), t_s },
            _ => LastEnd { x_m: x_contact_m, end_known: false, h_end_m: None, t_s },
        });
    }

    /// The billet's height after this blow is not known: the encoder's chain takes it up
    /// at the next blow.
    fn forget_end(&mut self) {
        self.h_m = None;
        self.last_method = None;
        self.last_course = None;
    }

    /// First contact, samples after the segmenter's contact sample: the hinge shaped by the
    /// process sheet's law from height `h_m` when both are known, else a straight line.
    fn locate_contact(&self, blow: &Blow, v0_mps: f64, h_m: Option<f64>) -> f64 {
        let law = self.billet_process.as_ref().map(|p| {
            let n = self.billet_blows + 1;
            BilletLaw::of(p, self.effects.load, n)
        });
        let rise = law
            .as_ref()
            .zip(h_m)
            .zip(contact::support_stiffness(&self.machine))
            .map(|((law, h0_m), k)| contact::RiseModel { law, h0_m, v0_mps, k_series_n_per_m: k });
        contact_between_samples(blow, rise.as_ref())
    }

    /// Time lost inside the blow: interpolated samples from the start of the approach fit
    /// to the blow's end, and any time cut off by a break in the stream.
    fn gap_s(&self, blow: &Blow) -> f64 {
        let fit_n = (self.cfg.fit_s / blow.period_s).ceil() as usize + approach::GUARD_SAMPLES;
        let from = blow.i_contact.saturating_sub(fit_n);
        blow.filled_in(from..blow.i_end + 1) as f64 * blow.period_s + blow.lost_s
    }

    /// Whether the blow's samples show its spring-back: after the end of forming its estimate
    /// found (`last_course`), the zeroed load falls below `level`.
    fn spring_back_seen(&self, blow: &Blow, t_contact_s: f64, level_n: f64) -> bool {
        let forming_end_s = self.last_course.as_ref().and_then(|c| c.forming_time_s).map(|f| t_contact_s + f);
        let ram_kg = self.machine.ram_kg();
        forming_end_s.is_some_and(|t| {
            blow.samples.iter().any(|s| s.t_s > t && contact_force_n(s, ram_kg) - blow.load_zero_n < level_n)
        })
    }

    /// How well a contact position compares with a height (`EstimatorConfig::height_tolerance_m`).
    fn contact_tolerance_m(&self, sample_travel_m: f64) -> f64 {
        self.cfg.height_tolerance_m(sample_travel_m)
    }
}

/// The first machine-side effect of `effects` that the observer does not model and the
/// model fit does (the fit simulates the whole plant): a foundation under the frame, a
/// clearance in the lower tool's path, an elastic contact. With one, every blow is fitted,
/// at every rate, which needs a process sheet (`unhonoured`). The load-side effects enter
/// the observer's split through the billet's law, and the sensor's high-pass is undone on
/// the measured load, in either path.
pub fn fit_only_effect(effects: &EffectSet) -> Option<&'static str> {
    if effects.foundation.is_some_and(|f| f.k3_n_per_m.is_finite()) {
        Some("foundation")
    } else if effects.clearance_gap_m > 0.0 {
        Some("clearance")
    } else if effects.k_contact_n_per_m.is_finite() {
        Some("elastic_recovery")
    } else {
        None
    }
}

/// The effect of the machine file the estimator cannot honour with what it is given, if
/// any: one only the model fit carries (`fit_only_effect`), without a process sheet to fit
/// with. The caller refuses it, naming the file and the key.
pub fn unhonoured(effects: &EffectSet, process: Option<&Process>) -> Option<&'static str> {
    fit_only_effect(effects).filter(|_| process.is_none())
}

/// A blow's first fit, on the guess of its start height, and what decides a refit
/// (`Estimator::complete`).
struct FirstFit {
    fitted: Option<fit::ModelFit>,
    /// The residual of the last fit tried, good or not: the blow's model check.
    check: Option<fit::ModelResidual>,
    /// The locator's contact, samples.
    delta0: f64,
    /// The start height came from the die reference before the fit.
    premeasured: bool,
    wants_fit: bool,
    h_guess_m: Option<f64>,
}

/// Where a blow's contact put it on its billet (`Estimator::place`).
struct Placed {
    billet: BilletTag,
    first: bool,
    /// The contact measured the billet's height against the die reference.
    measured: bool,
    /// The contact taught the die reference.
    taught: bool,
    h_start_m: Option<f64>,
    height_check: Option<HeightCheck>,
    height_source: HeightSource,
}

/// A blow's estimate before its energies: incomplete, with its contact (time, impact
/// speed), the time bridged and its place on the billet.
fn started(n: u32, blow: &Blow, contact: (f64, f64), gap_s: f64, placed: &Placed) -> BlowEstimate {
    let (t_contact_s, v_impact_mps) = contact;
    BlowEstimate {
        gap_s,
        h_start_m: placed.h_start_m,
        height_source: placed.height_source,
        height_check: placed.height_check,
        billet: placed.billet,
        ..BlowEstimate::incomplete(n, t_contact_s, v_impact_mps, blow.samples[blow.i_end].t_s)
    }
}

/// `blow` with its encoder read negated (an encoder counting up, away from the die).
fn negate_encoder(blow: &Blow) -> Blow {
    let mut b = blow.clone();
    for s in &mut b.samples {
        s.disp_m = -s.disp_m;
    }
    b
}

/// A fit whose start height differs from the billet's by more than this is run again, m:
/// half the encoder's resolution. A start height off by that moves the fitted set by about
/// set / height × 5 µm, under 2 µm on the papers' billets (sets of a third of the height
/// at most), and the chain gives the next start from the encoder regardless.
pub const REFIT_HEIGHT_M: f64 = 5e-6;

/// Fraction of the second-mode period that a hole inside a blow may last and still be
/// bridged by interpolation (`Estimator::max_bridged_s`).
pub const BRIDGE_FRACTION_OF_MODE_PERIOD: f64 = 0.1;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{parse_machine, parse_process};
    use crate::physics::effects::EffectSet;
    use crate::signal::capture::CaptureReader;
    use crate::signal::segment::{SegmentConfig, Segmenter};
    use crate::synth::{CaptureSpec, synth_blows};

    /// Billets changed without a new-billet signal: the tracked height would go negative.
    /// Past 2 % of the sheet's height the estimator stops reporting one (and the split that
    /// needs it) until `new_billet`, which restores it.
    #[test]
    fn an_impossible_billet_height_is_reported_as_unknown() {
        let m = parse_machine("m", include_str!("../../config/hammer-lg1000.machine.toml")).unwrap().machine;
        let p = parse_process("p", include_str!("../../config/steel-16NiCrMo13.process.toml")).unwrap();
        // Four blows on one billet, estimated as if the sheet were 20 mm high: the tracked
        // height runs out after the first blows.
        let blows = synth_blows(&m, &EffectSet::NONE, &p, &[5.3; 4], &CaptureSpec::hammer(9)).unwrap();
        let mut short = p.clone();
        short.billet.height_m = 0.020;
        let mut est = Estimator::new(m, Some(short), EstimatorConfig::for_kind(m.kind()));
        let mut heights = Vec::new();
        for b in &blows {
            let mut text = Vec::new();
            crate::signal::capture::write_capture(&mut text, &b.rows).unwrap();
            let batches = CaptureReader::new("x", text.as_slice(), 0.05).unwrap().read_all().unwrap();
            let cut = Segmenter::cut_all(SegmentConfig::HAMMER, &batches);
            let e = est.estimate(&cut[0]).unwrap();
            assert!(e.h_end_m.is_none_or(|h| h > 0.0), "{:?}", e.h_end_m);
            heights.push(e.h_end_m);
        }
        assert!(heights.iter().any(|h| h.is_none()), "{heights:?}");
        assert!(!est.tracking_height());
        est.new_billet();
        assert!(est.tracking_height());
    }
}
