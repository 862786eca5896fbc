//! The effect library: unmodelled physical effects that can be switched on top of either
//! machine model (docs/interfaces.md §6). Diagnosis fits them; simulated devices and tests
//! generate data with them.
//!
//! Each effect has a neutral parameter value at which the model is exactly the base model.

use std::collections::BTreeMap;
use std::fmt;

use super::billet::LoadEffects;
use super::load_filter::LoadFilter;
use super::machine::MachineKind;

/// Default reference strain rate of `strain_rate` when the spec leaves it out, 1/s.
/// Blows of both papers run at 10–40 /s, so the factor stays near 1 at the reference.
pub const DEFAULT_RATE_REF_PER_S: f64 = 10.0;
/// Default reference strain of `strain_hardening` when the spec leaves it out.
pub const DEFAULT_EPS_REF: f64 = 0.2;
/// Default foundation damping when the spec leaves it out, N s/m (undamped foundation).
pub const DEFAULT_FOUNDATION_DAMPING: f64 = 0.0;
/// `clearance`'s contract key for the billet's contact stiffness with a press's loose die.
pub const K_DIE_KEY: &str = "k_die_contact_N_per_m";

/// One effect with its parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Effect {
    /// `m_lower_kg`: the press's lower die, which the base press model lacks (its sensor path
    /// is massless). 0 leaves it out: the gap is then dead travel. A hammer's lower mass is
    /// its machine's `m2_kg`, so there it must be 0.
    /// `k_die_n_per_m`: the press's loose die is struck through the billet's contact, of
    /// this stiffness (a rigid-plastic billet brings the die to the tool's speed; an elastic
    /// one throws it ahead, and the closure, the die's rebound and the load's rise follow
    /// from it). Infinite is the rigid contact; only with a die.
    Clearance {
        gap_m: f64,
        m_lower_kg: f64,
        k_die_n_per_m: f64,
    },
    ElasticRecovery {
        k_contact_n_per_m: f64,
    },
    FrictionRise {
        exponent: f64,
    },
    StrainRate {
        m: f64,
        rate_ref_per_s: f64,
    },
    StrainHardening {
        n: f64,
        eps_ref: f64,
    },
    Thermal {
        q_dt: f64,
    },
    Foundation {
        m3_kg: f64,
        k3_n_per_m: f64,
        c3_ns_per_m: f64,
    },
    SensorHighpass {
        tau_s: f64,
    },
}

/// What can be wrong with an effect spec; every variant names the effect and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    #[error("unknown effect '{name}' (known: {})", EFFECT_NAMES.join(", "))]
    UnknownEffect { name: String },
    #[error("effect '{effect}' has no parameter '{param}' (it takes: {allowed})")]
    UnknownParam { effect: &'static str, param: String, allowed: String },
    #[error("effect '{effect}' needs parameter '{param}'")]
    MissingParam { effect: &'static str, param: &'static str },
    #[error("effect '{effect}': '{param}={value}' is not a number")]
    NotANumber { effect: &'static str, param: String, value: String },
    #[error("effect '{effect}': {param} = {value} {why}")]
    OutOfRange { effect: &'static str, param: &'static str, value: f64, why: &'static str },
    #[error("effect '{effect}': {param} does not apply to a {machine} ({why})")]
    NotForMachine { effect: &'static str, param: &'static str, machine: &'static str, why: &'static str },
    #[error("effect spec '{spec}' is not NAME or NAME:param=value[,param=value]")]
    Malformed { spec: String },
}

/// The library's names, in docs/interfaces.md §6 order.
pub const EFFECT_NAMES: [&str; 8] = [
    "clearance",
    "elastic_recovery",
    "friction_rise",
    "strain_rate",
    "strain_hardening",
    "thermal",
    "foundation",
    "sensor_highpass",
];

impl Effect {
    /// The library name (docs/interfaces.md §6).
    pub fn name(&self) -> &'static str {
        match self {
            Effect::Clearance { .. } => "clearance",
            Effect::ElasticRecovery { .. } => "elastic_recovery",
            Effect::FrictionRise { .. } => "friction_rise",
            Effect::StrainRate { .. } => "strain_rate",
            Effect::StrainHardening { .. } => "strain_hardening",
            Effect::Thermal { .. } => "thermal",
            Effect::Foundation { .. } => "foundation",
            Effect::SensorHighpass { .. } => "sensor_highpass",
        }
    }

    /// Parameter names and values, with their unit-carrying contract names.
    pub fn params(&self) -> Vec<(&'static str, f64)> {
        match *self {
            Effect::Clearance { gap_m, m_lower_kg, k_die_n_per_m } if m_lower_kg > 0.0 => {
                let mut p = vec![("gap_m", gap_m), ("m_lower_kg", m_lower_kg)];
                if k_die_n_per_m.is_finite() {
                    p.push((K_DIE_KEY, k_die_n_per_m));
                }
                p
            }
            Effect::Clearance { gap_m, .. } => vec![("gap_m", gap_m)],
            Effect::ElasticRecovery { k_contact_n_per_m } => {
                vec![("k_contact_N_per_m", k_contact_n_per_m)]
            }
            Effect::FrictionRise { exponent } => vec![("exponent", exponent)],
            Effect::StrainRate { m, rate_ref_per_s } => {
                vec![("m", m), ("rate_ref_per_s", rate_ref_per_s)]
            }
            Effect::StrainHardening { n, eps_ref } => vec![("n", n), ("eps_ref", eps_ref)],
            Effect::Thermal { q_dt } => vec![("q_dT", q_dt)],
            Effect::Foundation { m3_kg, k3_n_per_m, c3_ns_per_m } => {
                vec![("m3_kg", m3_kg), ("k3_N_per_m", k3_n_per_m), ("c3_Ns_per_m", c3_ns_per_m)]
            }
            Effect::SensorHighpass { tau_s } => vec![("tau_s", tau_s)],
        }
    }

    /// What blows determine of this effect, as names and values (docs/validation.md, "Diagnosis:
    /// effect families"): the parameters themselves, except that `strain_rate` and
    /// `strain_hardening` are determined as their exponent and the flow stress's level at
    /// the default reference (σ·(ε̇/ε̇₀)^m is σ·(10/ε̇₀)^m at 10 /s: ε̇₀ moves the level at a
    /// fixed m), and `foundation`'s damper as its damping ratio c3 / (2 √(k3 m3)).
    pub fn identifiable(&self) -> Vec<(&'static str, f64)> {
        match *self {
            Effect::StrainRate { m, rate_ref_per_s } => {
                vec![("m", m), ("level_at_ref", (DEFAULT_RATE_REF_PER_S / rate_ref_per_s).powf(m))]
            }
            Effect::StrainHardening { n, eps_ref } => {
                vec![("n", n), ("level_at_ref", (DEFAULT_EPS_REF / eps_ref).powf(n))]
            }
            Effect::Foundation { m3_kg, k3_n_per_m, c3_ns_per_m } => vec![
                ("m3_kg", m3_kg),
                ("k3_N_per_m", k3_n_per_m),
                ("zeta3", c3_ns_per_m / (2.0 * (k3_n_per_m * m3_kg).sqrt())),
            ],
            _ => self.params(),
        }
    }

    /// Build an effect from its name and `param -> value` pairs, checking every key.
    pub fn from_params(name: &str, given: &BTreeMap<String, f64>) -> Result<Effect, EffectError> {
        let effect: &'static str = EFFECT_NAMES
            .iter()
            .copied()
            .find(|n| *n == name)
            .ok_or_else(|| EffectError::UnknownEffect { name: name.to_string() })?;
        let allowed: &[&'static str] = match effect {
            "clearance" => &["gap_m", "m_lower_kg", K_DIE_KEY],
            "elastic_recovery" => &["k_contact_N_per_m"],
            "friction_rise" => &["exponent"],
            "strain_rate" => &["m", "rate_ref_per_s"],
            "strain_hardening" => &["n", "eps_ref"],
            "thermal" => &["q_dT"],
            "foundation" => &["m3_kg", "k3_N_per_m", "c3_Ns_per_m"],
            _ => &["tau_s"],
        };
        if let Some(bad) = given.keys().find(|k| !allowed.contains(&k.as_str())) {
            return Err(EffectError::UnknownParam { effect, param: bad.clone(), allowed: allowed.join(", ") });
        }
        let req = |p: &'static str| given.get(p).copied().ok_or(EffectError::MissingParam { effect, param: p });
        let opt = |p: &'static str, d: f64| given.get(p).copied().unwrap_or(d);
        let e = match effect {
            "clearance" => Effect::Clearance {
                gap_m: req("gap_m")?,
                m_lower_kg: opt("m_lower_kg", 0.0),
                k_die_n_per_m: opt(K_DIE_KEY, f64::INFINITY),
            },
            "elastic_recovery" => Effect::ElasticRecovery { k_contact_n_per_m: req("k_contact_N_per_m")? },
            "friction_rise" => Effect::FrictionRise { exponent: req("exponent")? },
            "strain_rate" => {
                Effect::StrainRate { m: req("m")?, rate_ref_per_s: opt("rate_ref_per_s", DEFAULT_RATE_REF_PER_S) }
            }
            "strain_hardening" => Effect::StrainHardening { n: req("n")?, eps_ref: opt("eps_ref", DEFAULT_EPS_REF) },
            "thermal" => Effect::Thermal { q_dt: req("q_dT")? },
            "foundation" => Effect::Foundation {
                m3_kg: req("m3_kg")?,
                k3_n_per_m: req("k3_N_per_m")?,
                c3_ns_per_m: opt("c3_Ns_per_m", DEFAULT_FOUNDATION_DAMPING),
            },
            _ => Effect::SensorHighpass { tau_s: req("tau_s")? },
        };
        e.validate()?;
        Ok(e)
    }

    /// Parse the CLI form `NAME:param=value[,param=value]`.
    pub fn parse_spec(spec: &str) -> Result<Effect, EffectError> {
        let (name, rest) = spec.split_once(':').unwrap_or((spec, ""));
        let name = name.trim();
        if name.is_empty() {
            return Err(EffectError::Malformed { spec: spec.to_string() });
        }
        let mut given = BTreeMap::new();
        for pair in rest.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = pair.split_once('=').ok_or_else(|| EffectError::Malformed { spec: spec.to_string() })?;
            let value: f64 = v.trim().parse().map_err(|_| {
                let effect = EFFECT_NAMES.iter().copied().find(|n| *n == name).unwrap_or("?");
                EffectError::NotANumber { effect, param: k.trim().to_string(), value: v.trim().to_string() }
            })?;
            given.insert(k.trim().to_string(), value);
        }
        Effect::from_params(name, &given)
    }

    /// Whether this effect makes sense on a machine of `kind`.
    pub fn check_machine(&self, kind: MachineKind) -> Result<(), EffectError> {
        match (*self, kind) {
            (Effect::Clearance { m_lower_kg, .. }, MachineKind::Hammer) if m_lower_kg > 0.0 => {
                Err(EffectError::NotForMachine {
                    effect: "clearance",
                    param: "m_lower_kg",
                    machine: kind.as_str(),
                    why: "a hammer's lower mass is m2_kg of machine.toml",
                })
            }
            _ => Ok(()),
        }
    }

    fn validate(&self) -> Result<(), EffectError> {
        let effect = self.name();
        let check = |param: &'static str, value: f64, ok: bool, why: &'static str| {
            if ok && !value.is_nan() { Ok(()) } else { Err(EffectError::OutOfRange { effect, param, value, why }) }
        };
        match *self {
            Effect::Clearance { gap_m, m_lower_kg, k_die_n_per_m: k } => {
                check("gap_m", gap_m, (0.0..f64::INFINITY).contains(&gap_m), "must be finite and >= 0 m")?;
                let m = m_lower_kg;
                check("m_lower_kg", m, (0.0..f64::INFINITY).contains(&m), "must be finite and >= 0 kg")?;
                check(K_DIE_KEY, k, k > 0.0, "must be > 0 (infinite is the rigid contact)")?;
                check(K_DIE_KEY, k, m > 0.0 || k.is_infinite(), "needs a lower die (m_lower_kg > 0)")
            }
            Effect::ElasticRecovery { k_contact_n_per_m: k } => {
                check("k_contact_N_per_m", k, k > 0.0, "must be > 0 (infinite is neutral)")
            }
            Effect::FrictionRise { exponent } => check("exponent", exponent, exponent.is_finite(), "must be finite"),
            Effect::StrainRate { m, rate_ref_per_s } => {
                check("m", m, (0.0..f64::INFINITY).contains(&m), "must be finite and >= 0")?;
                let r = rate_ref_per_s;
                check("rate_ref_per_s", r, r > 0.0 && r.is_finite(), "must be finite and > 0")
            }
            Effect::StrainHardening { n, eps_ref } => {
                check("n", n, (0.0..f64::INFINITY).contains(&n), "must be finite and >= 0")?;
                check("eps_ref", eps_ref, eps_ref > 0.0 && eps_ref.is_finite(), "must be finite and > 0")
            }
            Effect::Thermal { q_dt } => check("q_dT", q_dt, q_dt.is_finite(), "must be finite"),
            Effect::Foundation { m3_kg, k3_n_per_m, c3_ns_per_m } => {
                check("m3_kg", m3_kg, m3_kg > 0.0 && m3_kg.is_finite(), "must be finite and > 0 kg")?;
                check("k3_N_per_m", k3_n_per_m, k3_n_per_m > 0.0, "must be > 0 (infinite is neutral)")?;
                let c3 = c3_ns_per_m;
                check("c3_Ns_per_m", c3, (0.0..f64::INFINITY).contains(&c3), "must be finite and >= 0")
            }
            Effect::SensorHighpass { tau_s } => {
                check("tau_s", tau_s, tau_s > 0.0, "must be > 0 s (infinite is neutral)")
            }
        }
    }
}

impl fmt::Display for Effect {
    /// The CLI spec form, which `parse_spec` reads back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:", self.name())?;
        for (i, (k, v)) in self.params().iter().enumerate() {
            write!(f, "{}{k}={v:e}", if i > 0 { "," } else { "" })?;
        }
        Ok(())
    }
}

/// A third mass under the machine spring (`foundation`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Foundation {
    pub m3_kg: f64,
    pub k3_n_per_m: f64,
    pub c3_ns_per_m: f64,
}

/// All effects switched on for a simulation, as the blow model consumes them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectSet {
    /// `clearance`: dead travel in the lower tool/sensor path, m. 0 is neutral and keeps
    /// the paper's catch-up assumption (lower mass at the impact speed).
    pub clearance_gap_m: f64,
    /// `clearance`: the press's lower die, kg, at rest at first contact. 0 is neutral.
    pub clearance_lower_kg: f64,
    /// `clearance`: the billet's contact with that die, N/m. Infinite is neutral (rigid).
    pub clearance_die_k_n_per_m: f64,
    /// `elastic_recovery`: contact compliance in series with the billet. Infinite is neutral.
    pub k_contact_n_per_m: f64,
    /// Load-side effects.
    pub load: LoadEffects,
    /// `foundation`: a third mass; `None` (or infinite k3) is neutral.
    pub foundation: Option<Foundation>,
    /// `sensor_highpass`: time constant of the charge amplifier, s. Infinite is neutral.
    pub highpass_tau_s: f64,
    /// The DAQ's anti-alias filter on the load channel (a machine file's `[daq]`, not an
    /// effect of the library): the fits read the model's load through it
    /// (`identify::objective`); the plant does not.
    pub load_filter: LoadFilter,
}

impl EffectSet {
    /// The base model: every effect neutral.
    pub const NONE: EffectSet = EffectSet {
        clearance_gap_m: 0.0,
        clearance_lower_kg: 0.0,
        clearance_die_k_n_per_m: f64::INFINITY,
        k_contact_n_per_m: f64::INFINITY,
        load: LoadEffects::NEUTRAL,
        foundation: None,
        highpass_tau_s: f64::INFINITY,
        load_filter: LoadFilter::None,
    };

    /// The set with the given effects switched on (a later one of the same name wins).
    pub fn from_effects<'a>(effects: impl IntoIterator<Item = &'a Effect>) -> EffectSet {
        let mut set = EffectSet::NONE;
        for e in effects {
            set.apply(e);
        }
        set
    }

    pub fn apply(&mut self, effect: &Effect) {
        match *effect {
            Effect::Clearance { gap_m, m_lower_kg, k_die_n_per_m } => {
                self.clearance_gap_m = gap_m;
                self.clearance_lower_kg = m_lower_kg;
                self.clearance_die_k_n_per_m = k_die_n_per_m;
            }
            Effect::ElasticRecovery { k_contact_n_per_m } => self.k_contact_n_per_m = k_contact_n_per_m,
            Effect::FrictionRise { exponent } => self.load.friction_exponent = exponent,
            Effect::StrainRate { m, rate_ref_per_s } => {
                self.load.rate_m = m;
                self.load.rate_ref_per_s = rate_ref_per_s;
            }
            Effect::StrainHardening { n, eps_ref } => {
                self.load.hardening_n = n;
                self.load.hardening_eps_ref = eps_ref;
            }
            Effect::Thermal { q_dt } => self.load.thermal_q_dt = q_dt,
            Effect::Foundation { m3_kg, k3_n_per_m, c3_ns_per_m } => {
                self.foundation = k3_n_per_m.is_finite().then_some(Foundation { m3_kg, k3_n_per_m, c3_ns_per_m })
            }
            Effect::SensorHighpass { tau_s } => self.highpass_tau_s = tau_s,
        }
    }
}

impl Default for EffectSet {
    fn default() -> Self {
        Self::NONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_library_name_parses_and_prints_back() {
        let specs = [
            "clearance:gap_m=0.0003,m_lower_kg=800",
            "elastic_recovery:k_contact_N_per_m=2.6e9",
            "friction_rise:exponent=0.3",
            "strain_rate:m=0.1,rate_ref_per_s=5",
            "strain_hardening:n=0.2,eps_ref=0.3",
            "thermal:q_dT=0.05",
            "foundation:m3_kg=5000,k3_N_per_m=1e9,c3_Ns_per_m=1e5",
            "sensor_highpass:tau_s=0.01",
        ];
        for (spec, name) in specs.iter().zip(EFFECT_NAMES) {
            let e = Effect::parse_spec(spec).unwrap();
            assert_eq!(e.name(), name);
            assert_eq!(Effect::parse_spec(&e.to_string()).unwrap(), e);
        }
    }

    #[test]
    fn bad_specs_name_what_is_wrong() {
        let err = Effect::parse_spec("clearence:gap_m=1e-4").unwrap_err();
        assert!(err.to_string().contains("unknown effect 'clearence'"), "{err}");
        let err = Effect::parse_spec("clearance:gap=1e-4").unwrap_err();
        assert!(err.to_string().contains("no parameter 'gap'"), "{err}");
        let err = Effect::parse_spec("clearance:gap_m=abc").unwrap_err();
        assert!(err.to_string().contains("'gap_m=abc' is not a number"), "{err}");
        let err = Effect::parse_spec("clearance").unwrap_err();
        assert!(err.to_string().contains("needs parameter 'gap_m'"), "{err}");
        let err = Effect::parse_spec("sensor_highpass:tau_s=-1").unwrap_err();
        assert!(err.to_string().contains("tau_s = -1"), "{err}");
        let err = Effect::parse_spec("clearance:gap_m").unwrap_err();
        assert!(matches!(err, EffectError::Malformed { .. }), "{err}");
    }

    #[test]
    fn a_lower_die_belongs_to_a_press_only() {
        let e = Effect::parse_spec("clearance:gap_m=3e-4,m_lower_kg=800").unwrap();
        assert!(e.check_machine(MachineKind::ScrewPress).is_ok());
        let err = e.check_machine(MachineKind::Hammer).unwrap_err();
        assert!(err.to_string().contains("m_lower_kg does not apply to a hammer"), "{err}");
        assert!(Effect::parse_spec("clearance:gap_m=3e-4").unwrap().check_machine(MachineKind::Hammer).is_ok());
        let err = Effect::parse_spec("clearance:gap_m=3e-4,m_lower_kg=-1").unwrap_err();
        assert!(err.to_string().contains("m_lower_kg = -1"), "{err}");
        // Without a die the gap is the old dead travel, and prints back as before.
        assert_eq!(Effect::parse_spec("clearance:gap_m=3e-4").unwrap().to_string(), "clearance:gap_m=3e-4");
    }

    #[test]
    fn a_die_contact_is_optional_rigid_by_default_and_needs_a_die() {
        let rigid = Effect::parse_spec("clearance:gap_m=3e-4,m_lower_kg=800").unwrap();
        assert_eq!(rigid, Effect::Clearance { gap_m: 3e-4, m_lower_kg: 800.0, k_die_n_per_m: f64::INFINITY });
        // A rigid contact prints as before: the key is only there when it is finite.
        assert_eq!(rigid.to_string(), "clearance:gap_m=3e-4,m_lower_kg=8e2");
        let spec = "clearance:gap_m=3e-4,m_lower_kg=800,k_die_contact_N_per_m=1e12";
        let compliant = Effect::parse_spec(spec).unwrap();
        assert_eq!(compliant, Effect::Clearance { gap_m: 3e-4, m_lower_kg: 800.0, k_die_n_per_m: 1e12 });
        assert_eq!(Effect::parse_spec(&compliant.to_string()).unwrap(), compliant);
        let mut set = EffectSet::NONE;
        set.apply(&compliant);
        assert_eq!((set.clearance_die_k_n_per_m, set.k_contact_n_per_m), (1e12, f64::INFINITY));
        let err = Effect::parse_spec("clearance:gap_m=3e-4,k_die_contact_N_per_m=1e12").unwrap_err();
        assert!(err.to_string().contains("needs a lower die"), "{err}");
        let err = Effect::parse_spec("clearance:gap_m=3e-4,m_lower_kg=800,k_die_contact_N_per_m=0").unwrap_err();
        assert!(err.to_string().contains("k_die_contact_N_per_m = 0"), "{err}");
    }

    #[test]
    fn optional_parameters_take_their_named_defaults() {
        let e = Effect::parse_spec("strain_rate:m=0.1").unwrap();
        assert_eq!(e, Effect::StrainRate { m: 0.1, rate_ref_per_s: DEFAULT_RATE_REF_PER_S });
    }

    /// The level is the law's factor at the default reference: 1 there when the reference is
    /// the default, (10/2.5)^0.1 = 4^0.1 at 10 /s for a reference of 2.5 /s.
    #[test]
    fn a_reference_is_determined_as_the_level_it_gives_at_the_default() {
        let level = |spec: &str| Effect::parse_spec(spec).unwrap().identifiable()[1].1;
        assert_eq!(level("strain_rate:m=0.1"), 1.0);
        assert!((level("strain_rate:m=0.1,rate_ref_per_s=2.5") - 4f64.powf(0.1)).abs() < 1e-12);
        assert!((level("strain_hardening:n=0.5,eps_ref=0.05") - 2.0).abs() < 1e-12);
        let zeta = Effect::parse_spec("foundation:m3_kg=100,k3_N_per_m=1e6,c3_Ns_per_m=2e3").unwrap().identifiable();
        assert_eq!(zeta[2], ("zeta3", 0.1));
    }

    #[test]
    fn infinite_stiffness_is_accepted_as_neutral() {
        let e = Effect::parse_spec("elastic_recovery:k_contact_N_per_m=inf").unwrap();
        let set = EffectSet::from_effects([&e]);
        assert_eq!(set, EffectSet::NONE);
    }
}
