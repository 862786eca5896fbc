//! Alerts: rules with debounce over the stream of blow results. A hard blow, or k of the
//! last n blows below an efficiency threshold, means the blows have turned elastic (the part
//! is finished or too cold: further blows only load the machine); an energy balance that no
//! longer closes means the model does not describe the machine; a load sensor that
//! disagrees with the accelerometer on k of the last n blows (`sensor_check`, issue 16)
//! means a sensor or its configuration is wrong. Pure code.

pub mod drift;

use std::collections::{BTreeMap, VecDeque};

use crate::estimate::plausibility::Implausible;
use crate::estimate::{BlowClass, BlowEstimate, HeightSource};
use crate::signal::sample::Role;

// The alert itself is part of a blow's result (`estimate::result`), where the estimate that
// carries it is defined; the rules here read estimates, so the dependency runs one way.
pub use crate::estimate::result::{Alert, AlertKind};

/// The rules' thresholds, with the defaults named.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlertConfig {
    /// Alert on any hard blow.
    pub on_hard_blow: bool,
    /// Alert when `k_low` of the last `n_window` blows are below `low_efficiency`.
    pub k_low: usize,
    pub n_window: usize,
    pub low_efficiency: f64,
    /// Alert when |energy-balance residual| exceeds this.
    pub residual_limit: f64,
    /// After an alert of a kind, the same kind stays quiet for this many blows.
    pub debounce_blows: u32,
    /// A blow fails the sensor check when |`sensor_check`| exceeds this, or when a complete
    /// blow has none (a flat accelerometer); see `DEFAULT_SENSOR_LIMIT`.
    pub sensor_limit: f64,
    /// Alert when `sensor_k` of the last `sensor_n` complete blows fail the sensor check.
    pub sensor_k: usize,
    pub sensor_n: usize,
    /// Alert (model health, once per billet) when a blow's `flow_stress_scale` is this
    /// fraction off the billet's first: see `DEFAULT_SCALE_DRIFT_LIMIT`.
    pub scale_drift_limit: f64,
    /// Alert (model health, once per billet) when the model fitted to a blow misses the
    /// measured load by more than this RMS fraction of its peak (`model_residual`): see
    /// `DEFAULT_MODEL_RESIDUAL_LIMIT`.
    pub model_residual_limit: f64,
}

impl AlertConfig {
    /// Default bound on |`sensor_check`|: 5 %. Two parts, added and rounded up:
    /// - the measurement: on healthy simulated blows (`tests/sensor_health.rs`,
    ///   `sensor_check_spread_on_the_tuning_seeds`, noise seeds 101, 102, 103; the LG1000
    ///   with steel, 24 blows, and the SPR 400 with copper, 30 blows, per rate) the largest
    ///   |`sensor_check`| was 0.0113 at 5 kHz (hammer: mean −0.0085, sd 0.0020, the load's
    ///   2 kHz ring sampled at 2.4 points a period), 0.0014 at 20 kHz and 0.0005 at
    ///   100 kHz; the press stayed within 0.0022 at every rate;
    /// - the model: the identified press model reproduces the measured load to about 3 %
    ///   (seed 001 §3: 1124 kN simulated against 1094 kN measured, 2.7 %, on the first
    ///   copper blow), and the check weighs the load against the model's masses, so a
    ///   healthy real machine can sit that far off. The simulated blows above come from the
    ///   model itself and cannot show this part.
    ///
    /// A 10 % gain error is twice the bound.
    pub const DEFAULT_SENSOR_LIMIT: f64 = 0.05;
    /// Three of the last four, as the low-efficiency rule: one odd blow is not a fault,
    /// a fault that persists is flagged by its third blow.
    pub const DEFAULT_SENSOR_K: usize = 3;
    pub const DEFAULT_SENSOR_N: usize = 4;
    /// Default bound on the drift of the flow-stress scale a billet's blows need under the
    /// model, from its first blow (issue 37, `tests/model_health.rs`): 5 %. The independent
    /// renderer's billets without an effect (seeds 1–3, 5 blows a billet, soft to hard, both
    /// machines, 100 and 10 kHz) drift within 0.0022 on the hammer and 0.011 on the press;
    /// the first limit, 3 %, also fell short of a live stream merged from two DAQs
    /// (`tests/service_merge.rs`: the encoder at a fifth of the rate on its own clock), whose
    /// scale scatters by up to 2.8 % on a clean machine and raised a false alarm in CI. The
    /// scale follows the blow's measured height loss, a few millimetres, so 0.1 mm of
    /// encoder timing is 3 % of it. Of the hidden effects that move an efficiency by more
    /// than 0.02 on blows whose heights the encoder measured, the smallest drift is 0.073.
    /// The false-alarm and detection rates on other seeds are `tests/model_health.rs`'s.
    pub const DEFAULT_SCALE_DRIFT_LIMIT: f64 = 0.05;
    /// Default bound on a blow's `model_residual`, the RMS of the load the fitted model
    /// misses from the end of impact to separation, over the measured peak (issue 37,
    /// `tests/model_health.rs`): 2 %. On the independent renderer's billets without an
    /// effect (its tuning seeds 1–3, 5 blows a billet, soft to hard, both machines, at 5, 10,
    /// 20, 50 and 100 kHz, with its DAQ's filter declared in the machine file) the largest
    /// was 0.0060 (the press at 5 kHz); the hammer's stayed within 0.0047. Before the
    /// estimator honoured the declared filter, the hammer at 5 kHz, whose 1.6 kHz ring falls
    /// 3 samples a period, reached 0.0079. The project's own 5 kHz CAN fixture, sampled
    /// without an anti-alias filter, gives 0.0068. The hidden effects that move an
    /// efficiency by more than 0.02 leave more than the limit on some blow of their billet,
    /// except the press's friction rise (0.011 by the fifth blow), whose drift the scale's
    /// rule sees. The limit sits about 3× above the largest clean blow. The false-alarm and
    /// detection rates on other seeds are `tests/model_health.rs`'s.
    pub const DEFAULT_MODEL_RESIDUAL_LIMIT: f64 = 0.02;
}

impl Default for AlertConfig {
    fn default() -> Self {
        AlertConfig {
            on_hard_blow: true,
            k_low: 3,
            n_window: 4,
            low_efficiency: 0.6,
            residual_limit: 0.10,
            debounce_blows: 3,
            sensor_limit: Self::DEFAULT_SENSOR_LIMIT,
            sensor_k: Self::DEFAULT_SENSOR_K,
            sensor_n: Self::DEFAULT_SENSOR_N,
            scale_drift_limit: Self::DEFAULT_SCALE_DRIFT_LIMIT,
            model_residual_limit: Self::DEFAULT_MODEL_RESIDUAL_LIMIT,
        }
    }
}

/// A billet's flow-stress scale off its first blow's.
struct Drift {
    drift: f64,
    from_blow: u32,
    /// The drift over the first and the second half of the blow's compression, from the
    /// same reference (`BlowEstimate::scale_by_half`).
    by_half: Option<[f64; 2]>,
}

impl Drift {
    /// Where in the stroke the work departs from the model, in words ("" without a split):
    /// the residual by phase of the blow.
    fn by_phase(&self) -> String {
        let Some([a, b]) = self.by_half else { return String::new() };
        format!(
            "; by phase of the stroke, the work is {:+.1} % off in the first half of the compression and {:+.1} % \
             in the second",
            100.0 * a,
            100.0 * b
        )
    }
}

/// The rules and their memory.
#[derive(Debug, Clone)]
pub struct AlertRules {
    cfg: AlertConfig,
    recent: VecDeque<f64>,
    /// Whether each of the last complete blows failed the sensor check. Kept across
    /// billets: the sensors stay when the part changes.
    sensor_recent: VecDeque<bool>,
    last_fired: BTreeMap<&'static str, u32>,
    /// Whether the present billet has raised its alert for an implausible blow.
    implausible_alerted: bool,
    /// The present billet's first flow-stress scale (blow, scale), and whether the billet
    /// has raised its model-health alert (`model_health`).
    scale_ref: Option<(u32, f64)>,
    health_alerted: bool,
    /// The channels left out of the last blow's estimate (`BlowEstimate::excluded`) whose
    /// `sensor` alert has been raised: once a failure, again only after the channel worked.
    /// Kept across billets, as the sensor memory is.
    excluded_alerted: std::collections::BTreeSet<String>,
}

impl AlertRules {
    pub fn new(cfg: AlertConfig) -> Self {
        AlertRules {
            cfg,
            recent: VecDeque::new(),
            sensor_recent: VecDeque::new(),
            last_fired: BTreeMap::new(),
            implausible_alerted: false,
            scale_ref: None,
            health_alerted: false,
            excluded_alerted: Default::default(),
        }
    }

    /// Replace the thresholds (SIGHUP reload); the memory of recent blows is kept.
    pub fn set_config(&mut self, cfg: AlertConfig) {
        self.cfg = cfg;
    }

    /// A new billet: forget the recent blows' efficiencies and the debounce (not the
    /// sensor checks nor the sensor alert's debounce: the sensors are the same).
    pub fn reset(&mut self) {
        self.recent.clear();
        self.implausible_alerted = false;
        self.scale_ref = None;
        self.health_alerted = false;
        self.last_fired.retain(|kind, _| *kind == AlertKind::Sensor.as_str());
    }

    /// Judge one blow; at most one alert. First the model's health (`model_health`: when
    /// the model does not fit, the efficiencies that would raise the next alerts cannot be
    /// trusted), unless the sensor alert is due (a sensor that reads wrong also makes the
    /// model miss, and the sensor alert names the cause); then the elastic blows, the
    /// sensors, and the energy balance. An incomplete blow (no efficiency) raises none and is
    /// not remembered: it neither counts toward the low-efficiency window nor breaks it.
    pub fn on_blow(&mut self, b: &BlowEstimate) -> Option<Alert> {
        if let Some(alert) = self.on_excluded(b) {
            return Some(alert);
        }
        if let Some(why) = &b.implausible {
            return self.on_implausible(b.blow, why);
        }
        // The energy balance needs the accelerometer: a blow estimated without one has none.
        let residual = b.residual;
        let (Some(efficiency), Some(plastic_j), Some(kinetic_in_j), Some(elastic_j)) =
            (b.efficiency, b.plastic_j, b.kinetic_in_j, b.elastic_j)
        else {
            return None;
        };
        let c = self.cfg;
        self.recent.push_back(efficiency);
        while self.recent.len() > c.n_window.max(1) {
            self.recent.pop_front();
        }
        let low = self.recent.iter().filter(|e| **e < c.low_efficiency).count();
        // A blow estimated without the load or the accelerometer (issue 43) has nothing for
        // the sensor check to compare, by its mode: it neither passes nor fails it.
        let compared = b.channels.has(Role::Load) && b.channels.has(Role::Acc);
        let sensor_failed = b.sensor_check.is_none_or(|x| x.is_nan() || x.abs() > c.sensor_limit);
        if compared {
            self.sensor_recent.push_back(sensor_failed);
        }
        while self.sensor_recent.len() > c.sensor_n.max(1) {
            self.sensor_recent.pop_front();
        }
        let sensor_fails = self.sensor_recent.iter().filter(|f| **f).count();
        let mut figures = BTreeMap::from([
            ("efficiency".to_string(), efficiency),
            ("plastic_J".to_string(), plastic_j),
            ("kinetic_in_J".to_string(), kinetic_in_j),
            ("elastic_J".to_string(), elastic_j),
        ]);
        // A sensor that reads wrong also makes the model miss the load: where its alert is
        // due, it names the cause, and the model's health is judged on a later blow.
        let sensor_due = c.sensor_k > 0 && sensor_fails >= c.sensor_k && !self.debounced(AlertKind::Sensor, b.blow);
        let health = if sensor_due { None } else { self.model_health(b, &mut figures) };
        let candidate = if let Some(reason) = health {
            // The model does not fit this billet: said before any efficiency alert, which
            // its figures cannot be trusted to raise.
            Some((AlertKind::ModelHealth, reason))
        } else if c.on_hard_blow && b.class == BlowClass::Hard {
            Some((
                AlertKind::ElasticBlow,
                format!(
                    "blow {} was hard: only {:.0} % of its {:.0} J went into the billet and {:.0} J came back as elastic energy; \
                     the part is finished or too cold, and further blows only load the dies and the machine",
                    b.blow,
                    100.0 * efficiency,
                    kinetic_in_j,
                    elastic_j
                ),
            ))
        } else if c.k_low > 0 && low >= c.k_low {
            figures.insert("blows_below_threshold".to_string(), low as f64);
            Some((
                AlertKind::ElasticBlow,
                format!(
                    "{low} of the last {} blows forged with efficiency below {:.0} % (blow {}: {:.0} %): the blows are turning elastic",
                    self.recent.len(),
                    100.0 * c.low_efficiency,
                    b.blow,
                    100.0 * efficiency
                ),
            ))
        } else if c.sensor_k > 0 && sensor_fails >= c.sensor_k {
            figures.insert("blows_failing_sensor_check".to_string(), sensor_fails as f64);
            let this = match b.sensor_check {
                Some(x) => {
                    figures.insert("sensor_check".to_string(), x);
                    format!("the load sensor reads {:+.1} % against the accelerometer", 100.0 * x)
                }
                None => "the accelerometer gave nothing to compare".to_string(),
            };
            Some((
                AlertKind::Sensor,
                format!(
                    "{sensor_fails} of the last {} blows failed the sensor check (limit ±{:.0} %; blow {}: {this}): \
                     check the load sensor's gain and zero, its charge amplifier, and the accelerometer's mounting",
                    self.sensor_recent.len(),
                    100.0 * c.sensor_limit,
                    b.blow
                ),
            ))
        } else if let Some(residual) = residual.filter(|r| r.abs() > c.residual_limit) {
            figures.insert("residual".to_string(), residual);
            Some((
                AlertKind::ModelHealth,
                format!(
                    "blow {}: the energy balance misses by {:.1} % of the energy in (limit {:.0} %): the machine no longer behaves like its identified model",
                    b.blow,
                    100.0 * residual,
                    100.0 * c.residual_limit
                ),
            ))
        } else {
            b.judgement.as_ref().filter(|j| !j.ok).map(|j| {
                let why = j.reasons.join("; ");
                (AlertKind::Nok, format!("blow {} is NOK against recipe '{}': {why}", b.blow, j.recipe))
            })
        };
        let (kind, reason) = candidate?;
        self.fire(kind, b.blow, reason, figures)
    }

    /// An implausible blow (issue 36): no efficiency alert, and one alert per billet, of the
    /// kind its check names (`Check::alert_kind`: an input is the sensors', an output the
    /// model's), with its reason. It is not remembered by the efficiency window.
    /// A channel the source sent but the blow's estimate left out (issue 43): one `sensor`
    /// alert when it first fails, naming it and why, not debounced against other sensor
    /// alerts; it may fire again once the channel has worked on a blow.
    fn on_excluded(&mut self, b: &BlowEstimate) -> Option<Alert> {
        self.excluded_alerted.retain(|c| b.excluded.contains_key(c));
        let (channel, why) = b.excluded.iter().find(|(c, _)| !self.excluded_alerted.contains(*c))?;
        self.excluded_alerted.insert(channel.clone());
        let used = b.channels.names().join(" and ");
        let reason = format!(
            "the {channel} channel failed on blow {}: {why}; it is left out, and the blows are estimated from the {used} channels until it is healthy again",
            b.blow
        );
        self.last_fired.insert(AlertKind::Sensor.as_str(), b.blow);
        Some(Alert { kind: AlertKind::Sensor, blow: b.blow, reason, figures: BTreeMap::new() })
    }

    fn on_implausible(&mut self, blow: u32, why: &Implausible) -> Option<Alert> {
        if std::mem::replace(&mut self.implausible_alerted, true) {
            return None;
        }
        let reason = format!(
            "blow {blow} is implausible ({}): {}; its energies are withheld, and later implausible blows of \
             this billet raise no further alert",
            why.check.as_str(),
            why.reason
        );
        Some(Alert { kind: why.check.alert_kind(), blow, reason, figures: BTreeMap::new() })
    }

    /// Whether `b` says the model does not fit this billet, once per billet: the flow
    /// stress its work needs drifts (`scale_drift`), or the model fitted to it misses the
    /// measured load (`model_residual`). The reason names the figures, by phase of the
    /// stroke where known, and suggests `diagnose`; the figures go into `figures`.
    fn model_health(&mut self, b: &BlowEstimate, figures: &mut BTreeMap<String, f64>) -> Option<String> {
        let c = self.cfg;
        let drift = self.scale_drift(b);
        let misses = b.model_residual.filter(|r| *r > c.model_residual_limit);
        if self.health_alerted || (drift.is_none() && misses.is_none()) {
            return None;
        }
        self.health_alerted = true;
        let mut said = Vec::new();
        if let Some(drift) = &drift {
            figures.insert("flow_stress_scale_drift".to_string(), drift.drift);
            if let Some([a, b]) = drift.by_half {
                figures.insert("flow_stress_scale_drift_first_half".to_string(), a);
                figures.insert("flow_stress_scale_drift_second_half".to_string(), b);
            }
            said.push(format!(
                "the flow stress its work needs under the model is {:+.1} % off blow {}'s on this billet (limit \
                 ±{:.0} %){}",
                100.0 * drift.drift,
                drift.from_blow,
                100.0 * c.scale_drift_limit,
                drift.by_phase()
            ));
        }
        // The fitted model's residual is a figure of every model-health alert that has one,
        // and a reason when beyond its limit.
        if let Some(r) = b.model_residual {
            figures.insert("model_residual".to_string(), r);
        }
        if let Some(p) = b.model_residual_by_phase {
            for (name, v) in [("impact", p.impact), ("forming", p.forming), ("spring_back", p.spring_back)] {
                figures.insert(format!("model_residual_{name}"), v);
            }
        }
        if let Some(r) = misses {
            let mut phases = String::new();
            if let Some(p) = b.model_residual_by_phase {
                phases = format!(
                    ", most in the {} (impact {:.1} %, forming {:.1} %, spring-back {:.1} %)",
                    p.dominant().replace('_', "-"),
                    100.0 * p.impact,
                    100.0 * p.forming,
                    100.0 * p.spring_back
                );
            }
            said.push(format!(
                "the model fitted to it misses the measured load by {:.1} % of the peak, RMS (limit {:.0} %){phases}",
                100.0 * r,
                100.0 * c.model_residual_limit
            ));
        }
        Some(format!(
            "blow {}: {}: the model lacks an effect (friction rising as the part flattens, hardening, cooling, a \
             foundation, a clearance, a compliant contact, a load sensor that loses its low frequencies) or the load \
             sensor drifts, and the efficiencies may be off; run `forgemon diagnose` on this billet's recording",
            b.blow,
            said.join("; and ")
        ))
    }

    /// The drift of `b`'s flow-stress scale from the billet's first, once per billet, when
    /// beyond the limit. Only a blow whose start height the encoder measured counts (and the
    /// billet's first, whose height is the billet's): a height from the sheet's calipers
    /// (±0.2–0.3 mm) or from the model moves the scale by up to 4 % on its own
    /// (`tests/capture_freedoms.rs`, per-file encoder offsets at 5 kHz).
    fn scale_drift(&mut self, b: &BlowEstimate) -> Option<Drift> {
        let measured = b.height_source == HeightSource::Encoder || b.billet.billet_blow == 1;
        let s = b.flow_stress_scale.filter(|s| measured && s.is_finite() && *s > 0.0)?;
        let (from_blow, first) = *self.scale_ref.get_or_insert((b.blow, s));
        let drift = s / first - 1.0;
        let beyond = drift.abs() > self.cfg.scale_drift_limit;
        let by_half = b.scale_by_half.map(|h| h.map(|x| x / first - 1.0));
        beyond.then_some(Drift { drift, from_blow, by_half })
    }

    /// Whether `kind` fired within the debounce before `blow`.
    fn debounced(&self, kind: AlertKind, blow: u32) -> bool {
        self.last_fired.get(kind.as_str()).is_some_and(|&last| blow <= last + self.cfg.debounce_blows)
    }

    /// Raise `kind` unless it fired within the debounce.
    fn fire(&mut self, kind: AlertKind, blow: u32, reason: String, figures: BTreeMap<String, f64>) -> Option<Alert> {
        if self.debounced(kind, blow) {
            return None;
        }
        self.last_fired.insert(kind.as_str(), blow);
        Some(Alert { kind, blow, reason, figures })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blow(n: u32, efficiency: f64, residual: f64) -> BlowEstimate {
        let cfg = crate::estimate::EstimatorConfig::for_kind(crate::physics::MachineKind::Hammer);
        BlowEstimate {
            kinetic_in_j: Some(6000.0),
            plastic_j: Some(6000.0 * efficiency),
            damped_j: Some(100.0),
            elastic_j: Some(6000.0 * (1.0 - efficiency) - 100.0),
            efficiency: Some(efficiency),
            final_load_n: 1e6,
            class: cfg.classify(efficiency),
            peak_load_n: 1e6,
            residual: Some(residual),
            sensor_check: Some(0.0),
            ..BlowEstimate::incomplete(n, n as f64, 4.0, n as f64 + 0.01)
        }
    }

    /// A soft blow `n` of its billet with a flow-stress scale, its start height from `source`.
    fn scaled(n: u32, scale: f64, by_half: Option<[f64; 2]>, source: crate::estimate::HeightSource) -> BlowEstimate {
        let mut b = blow(n, 0.9, 0.0);
        b.flow_stress_scale = Some(scale);
        b.scale_by_half = by_half;
        b.height_source = source;
        b.billet.billet_blow = n;
        b
    }

    /// The drift from the billet's first blow beyond the limit is a model-health alert, once
    /// per billet, that gives the residual by phase of the stroke; a height from the sheet
    /// is not watched.
    #[test]
    fn a_drifting_flow_stress_is_a_model_health_alert_by_phase_of_the_stroke() {
        use crate::estimate::HeightSource::{Encoder, Sheet};
        let mut r = AlertRules::new(AlertConfig::default());
        assert_eq!(r.on_blow(&scaled(1, 1.0, Some([1.0, 1.0]), Sheet)), None);
        // 20 % off, but the height is the calipers': not watched.
        assert_eq!(r.on_blow(&scaled(2, 1.2, Some([1.0, 1.4]), Sheet)), None);
        // Within the 5 % limit.
        assert_eq!(r.on_blow(&scaled(3, 1.04, Some([1.0, 1.08]), Encoder)), None);
        let a = r.on_blow(&scaled(4, 1.10, Some([1.02, 1.20]), Encoder)).expect("the drift's alert");
        assert_eq!((a.kind, a.blow), (AlertKind::ModelHealth, 4));
        assert!(a.reason.contains("+10.0 % off blow 1's"), "{}", a.reason);
        assert!(
            a.reason.contains("+2.0 % off in the first half of the compression and +20.0 % in the second"),
            "{}",
            a.reason
        );
        assert!((a.figures["flow_stress_scale_drift_second_half"] - 0.2).abs() < 1e-12);
        assert!(a.reason.contains("forgemon diagnose"));
        // Once per billet.
        assert_eq!(r.on_blow(&scaled(5, 1.3, None, Encoder)), None);
    }

    /// A blow whose fitted model misses the measured load beyond the limit is a model-health
    /// alert, raised before the efficiency rules would see the blow, once per billet, that
    /// names the phase where the model and the measurement part; a new billet watches again.
    #[test]
    fn a_model_that_misses_the_load_is_a_model_health_alert_by_phase() {
        use crate::estimate::fit::PhaseResidual;
        let missing = |n: u32, r: f64, efficiency: f64| {
            let mut b = blow(n, efficiency, 0.0);
            b.model_residual = Some(r);
            b.model_residual_by_phase = Some(PhaseResidual { impact: 0.01, forming: r, spring_back: 2.0 * r });
            b
        };
        let mut r = AlertRules::new(AlertConfig::default());
        // At the limit (2 %), not beyond it: the hard blow's alert.
        assert_eq!(r.on_blow(&missing(1, 0.02, 0.3)).map(|a| a.kind), Some(AlertKind::ElasticBlow));
        r.reset();
        let a = r.on_blow(&missing(2, 0.05, 0.3)).expect("the residual's alert");
        assert_eq!((a.kind, a.blow), (AlertKind::ModelHealth, 2));
        assert!(a.reason.contains("misses the measured load by 5.0 % of the peak"), "{}", a.reason);
        assert!(a.reason.contains("most in the spring-back"), "{}", a.reason);
        assert!(a.reason.contains("forgemon diagnose"), "{}", a.reason);
        assert_eq!(a.figures["model_residual_spring_back"], 0.1);
        // Once per billet; the next billet is watched again.
        assert_eq!(r.on_blow(&missing(3, 0.2, 0.9)), None);
        r.reset();
        let limit = AlertConfig { model_residual_limit: 0.1, ..AlertConfig::default() };
        r.set_config(limit);
        assert_eq!(r.on_blow(&missing(10, 0.05, 0.9)), None);
        assert_eq!(r.on_blow(&missing(11, 0.12, 0.9)).map(|a| a.kind), Some(AlertKind::ModelHealth));
    }

    fn incomplete(n: u32) -> BlowEstimate {
        BlowEstimate {
            judgement: None,
            kinetic_in_j: None,
            plastic_j: None,
            damped_j: None,
            elastic_j: None,
            efficiency: None,
            residual: None,
            sensor_check: None,
            method: None,
            class: BlowClass::Incomplete,
            gap_s: 0.01,
            ..blow(n, 0.3, 0.0)
        }
    }

    fn implausible(n: u32, check: crate::estimate::plausibility::Check) -> BlowEstimate {
        BlowEstimate {
            class: BlowClass::Implausible,
            implausible: Some(Implausible { check, reason: format!("value {n} out of range") }),
            ..incomplete(n)
        }
    }

    /// Issue 36: an implausible blow raises no efficiency alert, and its billet one alert of
    /// the kind its check names (an input: the sensors'; an output: the model's), carrying
    /// its reason; the next billet may raise one again. It does not fill the window either.
    #[test]
    fn an_implausible_blow_alerts_once_per_billet_by_its_check() {
        use crate::estimate::plausibility::Check;
        let mut r = AlertRules::new(AlertConfig::default());
        let a = r.on_blow(&implausible(1, Check::StartHeight)).expect("the billet's alert");
        assert_eq!(a.kind, AlertKind::Sensor);
        assert!(a.reason.contains("blow 1 is implausible (start_height): value 1 out of range"), "{}", a.reason);
        assert_eq!(r.on_blow(&implausible(2, Check::Balance)), None);
        assert_eq!(r.on_blow(&blow(3, 0.55, 0.0)), None);
        assert_eq!(r.on_blow(&blow(4, 0.55, 0.0)), None, "two low blows of the window, not three");
        r.reset();
        let a = r.on_blow(&implausible(5, Check::Efficiency)).expect("the next billet's alert");
        assert_eq!(a.kind, AlertKind::ModelHealth);
    }

    /// Issue 15: a blow cut by a lost frame must never set the PLC coil, nor fill the
    /// low-efficiency window, nor break a run of low blows either.
    #[test]
    fn an_incomplete_blow_never_alerts_and_is_not_counted() {
        let mut r = AlertRules::new(AlertConfig::default());
        assert_eq!(r.on_blow(&incomplete(1)), None);
        assert_eq!(r.on_blow(&blow(2, 0.55, 0.0)), None);
        assert_eq!(r.on_blow(&incomplete(3)), None);
        assert_eq!(r.on_blow(&blow(4, 0.58, 0.0)), None);
        assert_eq!(r.on_blow(&incomplete(5)), None);
        // The third low blow of the window alerts: the incomplete ones were not counted.
        let a = r.on_blow(&blow(6, 0.57, 0.0)).unwrap();
        assert!(a.reason.starts_with("3 of the last 3 blows"), "{}", a.reason);
    }

    #[test]
    fn soft_blows_raise_nothing() {
        let mut r = AlertRules::new(AlertConfig::default());
        for n in 1..10 {
            assert_eq!(r.on_blow(&blow(n, 0.9, 0.0)), None);
        }
    }

    #[test]
    fn a_hard_blow_alerts_once_then_debounces() {
        let mut r = AlertRules::new(AlertConfig::default());
        let a = r.on_blow(&blow(1, 0.3, 0.0)).unwrap();
        assert_eq!(a.kind, AlertKind::ElasticBlow);
        assert!(a.reason.contains("blow 1 was hard") && a.reason.contains("30 %"), "{}", a.reason);
        // Blows 2–4 are within the debounce of 3; blow 5 alerts again.
        for n in 2..=4 {
            assert_eq!(r.on_blow(&blow(n, 0.3, 0.0)), None, "blow {n}");
        }
        assert!(r.on_blow(&blow(5, 0.3, 0.0)).is_some());
    }

    #[test]
    fn three_of_four_intermediate_blows_alert() {
        let mut r = AlertRules::new(AlertConfig::default());
        assert_eq!(r.on_blow(&blow(1, 0.55, 0.0)), None);
        assert_eq!(r.on_blow(&blow(2, 0.8, 0.0)), None);
        assert_eq!(r.on_blow(&blow(3, 0.58, 0.0)), None);
        let a = r.on_blow(&blow(4, 0.57, 0.0)).unwrap();
        assert!(a.reason.starts_with("3 of the last 4 blows"), "{}", a.reason);
        assert_eq!(a.figures["blows_below_threshold"], 3.0);
    }

    fn checked(n: u32, sensor_check: Option<f64>) -> BlowEstimate {
        BlowEstimate { sensor_check, ..blow(n, 0.9, 0.0) }
    }

    #[test]
    fn three_of_four_blows_over_the_sensor_limit_alert_and_incomplete_ones_do_not_count() {
        let mut r = AlertRules::new(AlertConfig::default());
        let over = AlertConfig::DEFAULT_SENSOR_LIMIT * 1.2;
        assert_eq!(r.on_blow(&checked(1, Some(over))), None);
        assert_eq!(r.on_blow(&checked(2, Some(-over))), None);
        assert_eq!(r.on_blow(&incomplete(3)), None);
        assert_eq!(r.on_blow(&checked(4, Some(0.0))), None);
        let a = r.on_blow(&checked(5, Some(over))).unwrap();
        assert_eq!(a.kind, AlertKind::Sensor);
        assert_eq!(a.figures["blows_failing_sensor_check"], 3.0);
        assert_eq!(a.figures["sensor_check"], over);
        assert!(a.reason.starts_with("3 of the last 4 blows failed the sensor check"), "{}", a.reason);
        // Within the limit, on either side, nothing.
        let mut r = AlertRules::new(AlertConfig::default());
        for n in 1..10 {
            let x = AlertConfig::DEFAULT_SENSOR_LIMIT * 0.9 * if n % 2 == 0 { 1.0 } else { -1.0 };
            assert_eq!(r.on_blow(&checked(n, Some(x))), None, "blow {n}");
        }
    }

    #[test]
    fn complete_blows_without_a_check_fail_it_and_a_new_billet_keeps_the_sensor_memory() {
        let mut r = AlertRules::new(AlertConfig::default());
        assert_eq!(r.on_blow(&checked(1, None)), None);
        assert_eq!(r.on_blow(&checked(2, None)), None);
        r.reset();
        let a = r.on_blow(&checked(3, None)).unwrap();
        assert_eq!(a.kind, AlertKind::Sensor);
        assert!(a.reason.contains("the accelerometer gave nothing to compare"), "{}", a.reason);
        // The debounce also survives the billet change.
        r.reset();
        assert_eq!(r.on_blow(&checked(4, None)), None);
    }

    /// Issue 43: a blow estimated without the load (or the accelerometer) has no sensor
    /// check by its mode, and no energy balance without the accelerometer; neither fails a
    /// rule, and its efficiency still raises the elastic-blow alert.
    #[test]
    fn a_blow_of_a_reduced_mode_fails_no_check_it_cannot_make_and_still_raises_a_hard_blow() {
        let mut r = AlertRules::new(AlertConfig::default());
        let without = |n: u32, role: Role| BlowEstimate {
            channels: crate::signal::sample::Channels::ALL.without(role),
            residual: None,
            ..checked(n, None)
        };
        for n in 1..=6 {
            assert_eq!(r.on_blow(&without(n, if n % 2 == 0 { Role::Load } else { Role::Acc })), None, "blow {n}");
        }
        let hard = BlowEstimate { class: BlowClass::Hard, ..without(7, Role::Acc) };
        assert_eq!(r.on_blow(&hard).map(|a| a.kind), Some(AlertKind::ElasticBlow));
    }

    /// Issue 43: a channel left out of a blow raises one sensor alert naming it, not again
    /// while it stays out, and again once it has worked on a blow and fails anew; another
    /// sensor alert just before does not swallow it.
    #[test]
    fn a_failed_channel_raises_one_alert_until_it_has_worked_again() {
        let mut r = AlertRules::new(AlertConfig::default());
        let dead = |n: u32| BlowEstimate {
            excluded: [("load".to_string(), "load_N read 0 N throughout the blow (dead)".to_string())].into(),
            channels: crate::signal::sample::Channels::ALL.without(Role::Load),
            ..blow(n, 0.9, 0.0)
        };
        r.last_fired.insert(AlertKind::Sensor.as_str(), 1);
        let a = r.on_blow(&dead(2)).expect("the channel's alert");
        assert_eq!(a.kind, AlertKind::Sensor);
        assert!(a.reason.starts_with("the load channel failed on blow 2: load_N read 0 N"), "{}", a.reason);
        assert!(a.reason.contains("from the acc and disp channels"), "{}", a.reason);
        assert_eq!(r.on_blow(&dead(3)), None);
        assert_eq!(r.on_blow(&blow(4, 0.9, 0.0)), None, "the load works again");
        let again = r.on_blow(&dead(30)).expect("a new failure, a new alert");
        assert!(again.reason.contains("failed on blow 30"), "{}", again.reason);
    }

    #[test]
    fn a_broken_energy_balance_is_a_model_health_alert() {
        let mut r = AlertRules::new(AlertConfig::default());
        let a = r.on_blow(&blow(1, 0.9, -0.15)).unwrap();
        assert_eq!(a.kind, AlertKind::ModelHealth);
        assert_eq!(a.figures["residual"], -0.15);
    }
}
