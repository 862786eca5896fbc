//! Reference blows and the objective of the press paper's eq. 4 (seed 001 §2.3):
//!
//! OF = f·g·√(1/n Σ (F_exp − F_sim)²/F_exp²) + (1−f)(1−g)·√(1/m Σ (S_exp − S_sim)²/S_exp²),
//! f = m/(m+n), g = 0.5,
//!
//! over the n load samples of the blow and the m spectrum bins up to `f_max`. Two changes,
//! both stated: the relative errors divide by max(|F_exp|, 5 % of the peak) (and likewise
//! for S), because a load near zero would otherwise weigh without limit; and the fit
//! minimises the sum of the two mean squares with those weights (a least-squares form for
//! Levenberg–Marquardt), while OF itself is reported as the paper defines it.
//!
//! Alignment: measured and simulated blows are aligned where the load first rises through
//! 10 % of the measured peak (interpolated between samples), so neither the segmenter's
//! contact sample nor a few samples of trigger jitter enter the fit.

use crate::identify::model::default_prior;
use crate::physics::blow::{SimOptions, TraceEnd, simulate_blow_ram_until, simulate_blow_sensor_until};
use crate::physics::effects::EffectSet;
use crate::physics::integrator::Method;
use crate::physics::machine::{Machine, MachineKind};
use crate::physics::plant::Plant;
use crate::physics::process::{CALIPER_TOLERANCE_M, Process};
use crate::physics::sequence::blow_plant;
use crate::signal::resample::{aligned, moving_average};
use crate::signal::spectrum::{Mode, Spectrum, SpectrumPlanner, blow_modes};

pub use super::reference::{
    ALIGN_FRACTION, EncoderApproach, MIN_NOISE_SAMPLES, MeasuredInstants, PRE_S, Reference, ReferenceError, Signal,
};

/// Floor of the relative errors' denominators, fraction of the peak (load or spectrum).
pub const RELATIVE_FLOOR: f64 = 0.05;
/// The paper's weight of the load against the spectrum.
pub const G_WEIGHT: f64 = 0.5;
/// Zero padding of the spectra (the papers zero-pad for a finer frequency grid).
pub const PAD_FACTOR: usize = 4;
/// Integration tolerance of the fit's simulations: 30× tighter than the default, so that
/// finite-difference Jacobians see the model, not the step-size control.
pub const FIT_RTOL: f64 = 1e-6;
/// Top of eq. 4's spectral term on the papers' machines, Hz: the hammer paper shows its
/// spectrum to 5 kHz (seed 000 §2.2), the press paper to 1 kHz (seed 001 §3.1). A machine
/// whose second mode sits elsewhere gets the same band in units of its own mode
/// (`ModePrior::band_hz`).
pub const PAPER_BAND_HZ_HAMMER: f64 = 5000.0;
pub const PAPER_BAND_HZ_PRESS: f64 = 1000.0;

/// What the objective needs of the machine before the fit: where the prior model's second
/// mode sits, and where the paper's machine of its kind has it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModePrior {
    /// The prior's second mode (`Machine::second_mode_hz`), Hz.
    pub mode2_hz: f64,
    /// The paper's machine's second mode (`model::default_prior`), Hz: 2049 Hz on the
    /// hammer, 275 Hz on the press.
    pub paper_mode2_hz: f64,
    pub kind: MachineKind,
}

impl ModePrior {
    /// Top of the spectral term, Hz: the paper's band scaled by the prior's mode over the
    /// paper machine's, so the band spans the same multiple of the second mode the papers
    /// show (2.44 × on the hammer, where the mode's peak and the pulse's ripples around it
    /// lie; 3.64 × on the press, whose 275 Hz mode sits on a longer pulse's shoulder), and
    /// the papers' machines keep exactly the papers' 5000 and 1000 Hz.
    pub fn band_hz(&self) -> f64 {
        let paper = match self.kind {
            MachineKind::Hammer => PAPER_BAND_HZ_HAMMER,
            MachineKind::ScrewPress => PAPER_BAND_HZ_PRESS,
        };
        // The ratio first: a paper's machine divides its mode by itself, exactly 1.
        paper * (self.mode2_hz / self.paper_mode2_hz)
    }
}

impl From<&Machine> for ModePrior {
    /// The prior model's own second mode.
    fn from(m: &Machine) -> Self {
        ModePrior {
            mode2_hz: m.second_mode_hz(),
            paper_mode2_hz: default_prior(m.kind()).second_mode_hz(),
            kind: m.kind(),
        }
    }
}

impl From<MachineKind> for ModePrior {
    /// Without a model: the paper's machine of the kind.
    fn from(kind: MachineKind) -> Self {
        ModePrior::from(&default_prior(kind))
    }
}

thread_local! {
    /// The FFT plans of the simulated spectra, kept per thread across calls: a fit simulates
    /// the same window lengths thousands of times, and a new planner computes each plan's
    /// twiddle factors again (a tenth of a hammer blow's time in `benches/diagnose.rs`).
    /// A plan depends only on the length, so the spectra are the same.
    static SIM_PLANNER: std::cell::RefCell<SpectrumPlanner> = std::cell::RefCell::new(SpectrumPlanner::new());
}

/// What the references were struck on.
#[derive(Debug, Clone, PartialEq)]
pub enum Setting {
    /// Tool on tool.
    Bare,
    /// Blows on the billet of the process sheet, the references in blow order.
    Billet(Process),
}

/// Where each billet blow's start height comes from, after the first (the sheet's billet).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Heights {
    /// The sheet's measured height after the blow before, when given; else the model's end
    /// height of the blow before.
    #[default]
    Sheet,
    /// Where the sheet gives measured heights: the encoder's chain, as the live estimator
    /// keeps it, from the first blow's start (the sheet's billet): the blow before's start
    /// less how much lower the ram met the billet this time, when the blow before is the
    /// reference before, the chain is plausible (`chained_height`) and it agrees with the
    /// hand-measured height within `CALIPER_TOLERANCE_M` (a capture whose encoder was zeroed
    /// anew, docs/interfaces.md §1, breaks it; issue 36). Where the ram met
    /// the billet is the model's first contact placed on the measured clock by the
    /// alignment, read off the encoder's approach (`EncoderApproach::at`): a load-level
    /// contact comes late where the load rises from nothing (a fresh copper billet on the
    /// press: ~117 µm on issue #17's independent renderer), and the chain would carry that to
    /// every later blow. A chained blow is simulated first from the reading at its load's
    /// contact sample plus the blow before's lead (the ram's travel from its model's contact
    /// to that sample: its own first contact is not known before it is simulated, and a
    /// billet's blows lead alike); where its model met the billet elsewhere by more than the
    /// contact's uncertainty (a press die crossing its clearance before the load rises), it
    /// is simulated again from the height there. The chain goes on from its model's contact.
    /// Hand-measured heights carry a caliper's scatter (±0.2 mm on issue #17's independent
    /// renderer), the chain its contacts' uncertainty (`Simulated::start_sd_m`, which
    /// `fit::uncertainty` passes through the fit). Elsewhere as `Sheet`: without measured
    /// heights the model's own chain is kept.
    Encoder,
}

/// The start height of a blow by the encoder's chain (`Heights::Encoder`) from the blow
/// before's (`prev`: its start height and contact reading) and this blow's contact reading,
/// or `None` where the chain is implausible: a billet does not grow by more than
/// `tolerance_m` (the contact's uncertainty) nor vanish, so another billet, a part turned
/// over or an encoder zeroed between the captures breaks the chain, as in the estimator.
pub fn chained_height(prev: (f64, f64), x_contact_m: f64, tolerance_m: f64) -> Option<f64> {
    let (h_prev, x_prev) = prev;
    let h = h_prev - (x_contact_m - x_prev);
    (h > 0.0 && h <= h_prev + tolerance_m).then_some(h)
}

/// The contact's uncertainty along the encoder, m: a sample's travel at impact (the contact
/// is known to a sample) and two steps of a 10 µm encoder.
fn contact_tolerance_m(r: &Reference) -> f64 {
    r.v0_mps.abs() * r.dt_s + 20e-6
}

/// Which objective the residuals express.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fidelity {
    /// Eq. 4, as in the module docs.
    Full,
    /// The global stage: the load averaged over one period of the second mode (which
    /// cancels the ring), error over the peak. In the full objective the ring makes the
    /// cost oscillate with the forming time (a half-period misalignment of the unloading
    /// ring costs as much as a wrong mass), so local searches from a distant start stop in
    /// the wrong valley; the averaged load depends smoothly on the masses and springs.
    Envelope,
}

/// The objective over a set of references.
#[derive(Debug, Clone)]
pub struct Objective {
    /// Every reference, in blow order (the billet's height carries from one to the next).
    pub refs: Vec<Reference>,
    /// Effects of the model (none for identification; `diagnose` fits them).
    pub effects: EffectSet,
    /// Which references the residuals cover (the others are only predicted).
    pub fitted: Vec<bool>,
    pub fidelity: Fidelity,
    /// Averaging window of the envelope, samples of each reference.
    envelope_window: Vec<usize>,
    /// The measured loads averaged over that window.
    measured_envelope: Vec<Vec<f64>>,
    /// The second mode found in the measured spectra, Hz (`None`: none found; the prior's
    /// sets the envelope window).
    pub mode2_hz: Option<f64>,
    pub setting: Setting,
    /// Highest frequency of the spectral term, Hz.
    pub f_max_hz: f64,
    /// Measured spectra, bins 1..=m of each reference.
    measured_spectra: Vec<Vec<f64>>,
    /// Where the billet blows' start heights come from.
    pub heights: Heights,
    /// What the references' `load_n` holds: the load sensor's, or the ram's force.
    pub signal: Signal,
    /// The prior model's second mode, Hz (`ModePrior::mode2_hz`).
    prior_mode2_hz: f64,
    /// A billet blow's start moved (reference index, m) and, through the encoder's chain,
    /// the blows after it: the heights' part of the uncertainty (`fit::uncertainty`).
    start_offset: Option<(usize, f64)>,
}

/// One blow simulated and where the model's clock sits on the measured window's.
struct OneBlow {
    sim: Simulated,
    /// The model's alignment crossing, model time; the measured one, window time.
    t_cross: f64,
    t_align_s: f64,
}

impl OneBlow {
    /// A model instant (model time 0 is first contact) on the window's clock.
    fn on_window(&self, t: f64) -> f64 {
        t - self.t_cross + self.t_align_s
    }
}

/// One reference simulated: the load at the measured samples and its spectrum.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulated {
    pub load_n: Vec<f64>,
    pub spectrum: Vec<f64>,
    /// Billet height after the blow (for the next blow), m.
    pub h_end_m: Option<f64>,
    /// Billet height before the blow, m.
    pub h_start_m: Option<f64>,
    /// The start height's standard uncertainty where the encoder's chain gave it
    /// (`Heights::Encoder`), m.
    pub start_sd_m: Option<f64>,
    /// The model's first contact and end of forming (`None` for a bare strike), s on the
    /// window's clock (sample i at i·dt).
    pub t_contact_s: f64,
    pub t_forming_end_s: Option<f64>,
}

impl Objective {
    /// `fitted[i]`: whether reference i enters the residuals. `prior`: the model the fit
    /// starts from (or only its kind: the paper's machine). The spectral term runs to
    /// `ModePrior::band_hz`; the second mode is looked for in the first fitted reference
    /// below that, and where none is found the prior's own mode sets the envelope window.
    pub fn new(refs: Vec<Reference>, fitted: Vec<bool>, setting: Setting, prior: impl Into<ModePrior>) -> Objective {
        let prior = prior.into();
        let f_max_hz = prior.band_hz();
        let mut planner = SpectrumPlanner::new();
        let spectra: Vec<_> = refs.iter().map(|r| planner.spectrum(&r.load_n, r.dt_s, PAD_FACTOR, 0)).collect();
        let measured_spectra = spectra.iter().map(|s| bins(s, f_max_hz)).collect();
        let first_fitted = fitted.iter().position(|f| *f).unwrap_or(0);
        let mode2_hz = spectra.get(first_fitted).and_then(|s| {
            machine_modes(s, f_max_hz)
                .into_iter()
                .max_by(|a, b| a.amplitude.total_cmp(&b.amplitude))
                .map(|m| m.frequency_hz)
        });
        let period_s = 1.0 / mode2_hz.unwrap_or(prior.mode2_hz);
        let envelope_window: Vec<usize> = refs.iter().map(|r| ((period_s / r.dt_s).round() as usize).max(1)).collect();
        let measured_envelope = refs.iter().zip(&envelope_window).map(|(r, w)| moving_average(&r.load_n, *w)).collect();
        Objective {
            refs,
            effects: EffectSet::NONE,
            fitted,
            fidelity: Fidelity::Full,
            envelope_window,
            measured_envelope,
            mode2_hz,
            setting,
            f_max_hz,
            measured_spectra,
            heights: Heights::Sheet,
            signal: Signal::Load,
            prior_mode2_hz: prior.mode2_hz,
            start_offset: None,
        }
    }

    /// The same references, whose `load_n` holds `signal`. The ram's force barely shows the
    /// second mode (the billet between ram and lower tool filters the ring): its strongest
    /// peak is the blow's own shape (117 Hz against the hammer's 2 kHz mode on
    /// `tests/identify_without_load.rs`), so the envelope's window is the prior's mode.
    pub fn with_signal(self, signal: Signal) -> Objective {
        if signal == Signal::Load {
            return Objective { signal, ..self };
        }
        let period_s = 1.0 / self.prior_mode2_hz;
        let envelope_window: Vec<usize> =
            self.refs.iter().map(|r| ((period_s / r.dt_s).round() as usize).max(1)).collect();
        let measured_envelope =
            self.refs.iter().zip(&envelope_window).map(|(r, w)| moving_average(&r.load_n, *w)).collect();
        Objective { signal, mode2_hz: None, envelope_window, measured_envelope, ..self }
    }

    /// The same references with the start heights from `heights`.
    pub fn with_heights(self, heights: Heights) -> Objective {
        Objective { heights, ..self }
    }

    /// The same references with the model's effects.
    pub fn with_effects(&self, effects: EffectSet) -> Objective {
        Objective { effects, ..self.clone() }
    }

    /// The same references with reference `i`'s start height moved by `dh_m` (a billet blow's;
    /// through the encoder's chain, the blows after it move with it).
    pub fn with_start_offset(&self, i: usize, dh_m: f64) -> Objective {
        Objective { start_offset: Some((i, dh_m)), ..self.clone() }
    }

    /// The same references under another objective.
    pub fn with_fidelity(&self, fidelity: Fidelity) -> Objective {
        Objective { fidelity, ..self.clone() }
    }

    /// Number of residuals.
    pub fn len(&self) -> usize {
        match self.fidelity {
            Fidelity::Full => self.included().map(|i| self.refs[i].load_n.len() + self.measured_spectra[i].len()).sum(),
            Fidelity::Envelope => self.included().map(|i| self.refs[i].load_n.len()).sum(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn measured_spectrum(&self, i: usize) -> &[f64] {
        &self.measured_spectra[i]
    }

    /// Frequency of spectrum bin j (1-based bins, as `measured_spectrum` holds them) of
    /// reference i.
    pub fn bin_hz(&self, i: usize, j: usize) -> f64 {
        let r = &self.refs[i];
        let n = (r.load_n.len() * PAD_FACTOR).next_power_of_two();
        (j + 1) as f64 / (n as f64 * r.dt_s)
    }

    /// Indices of the fitted references.
    fn included(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.refs.len()).filter(|&i| self.fitted[i])
    }

    /// Simulate every reference with `machine`.
    pub fn simulate(&self, machine: &Machine) -> Option<Vec<Simulated>> {
        self.simulate_to(machine, self.refs.len())
    }

    /// The first reference `machine` cannot simulate (in blow order: a billet's heights
    /// carry from blow to blow), `None` when it simulates them all.
    pub fn first_failing(&self, machine: &Machine) -> Option<usize> {
        (1..=self.refs.len()).find(|&n| self.simulate_to(machine, n).is_none()).map(|n| n - 1)
    }

    /// Simulate the first `n` references.
    pub fn simulate_to(&self, machine: &Machine, n: usize) -> Option<Vec<Simulated>> {
        let mut h = match &self.setting {
            Setting::Billet(p) => Some(p.billet.height_m),
            Setting::Bare => None,
        };
        let mut out = Vec::with_capacity(n);
        // The blow before's index, its start height at the model's first contact and the
        // encoder's reading there, for the encoder's chain.
        let mut prev: Option<(usize, f64, Option<f64>)> = None;
        // The blow before's lead: how far the ram travelled from its model's contact to its
        // load's contact sample, m (module docs of `Heights::Encoder`).
        let mut lead_m = 0.0;
        for (i, r) in self.refs[..n].iter().enumerate() {
            // This blow's index, start height, and whether the chain gave it.
            let link: Option<(usize, f64, bool)> = match (&self.setting, r.blow_index, h) {
                (Setting::Billet(p), Some(n), Some(h_start)) => {
                    // The sheet's measured height after the previous blow, when given.
                    let sheet =
                        n.checked_sub(2).and_then(|k| p.measured_final_heights_m.get(k).copied()).unwrap_or(h_start);
                    let measured = !p.measured_final_heights_m.is_empty();
                    // The chain where it agrees with the hand-measured height: each capture may
                    // carry its own encoder offset (docs/interfaces.md §1), and a link it breaks is a
                    // jump the calipers do not see.
                    let encoder = match (self.heights, prev, r.approach) {
                        (Heights::Encoder, Some((k, h_prev, Some(x_prev))), Some(a)) if measured && k + 1 == n => {
                            chained_height((h_prev, x_prev), a.x_m(), contact_tolerance_m(r))
                                .filter(|h| (h - sheet).abs() <= CALIPER_TOLERANCE_M)
                        }
                        _ => None,
                    };
                    Some((n, encoder.unwrap_or(sheet), encoder.is_some()))
                }
                _ => None,
            };
            // A chained start is taken at the load's contact sample, which the ram reaches
            // late where the load rises from nothing (a fresh billet's first blow, every blow
            // on an elastic contact) or only once a lower die has crossed its clearance (a
            // press's: the ram travels the closure first, and a start taken there leaves the
            // billet that much too thin, 0.1-0.3 mm on the family's press clearances, issue
            // 41). So it starts thicker by the blow before's lead (a billet's blows lead
            // alike), and is simulated again from the height where its model met the billet
            // when that guess is off by more than the contact's uncertainty: most blows are
            // simulated once.
            // The start moved for the heights' part of the uncertainty (`fit::uncertainty`).
            let link = link.map(|(n, h0, c)| match self.start_offset {
                Some((k, dh)) if k == i => (n, h0 + dh, c),
                _ => (n, h0, c),
            });
            let start = link.map(|(n, h0, chained)| (n, if chained { h0 + lead_m } else { h0 }));
            let mut blow = self.simulate_one(machine, r, start)?;
            if let (Some((n, h0, chained)), Some((_, h_start))) = (link, start) {
                // The encoder's reading where the model met the billet, and the height there.
                let touch = r.approach.map(|a| (a.at(blow.on_window(0.0)), a.x_m()));
                let mut h_touch = match touch {
                    Some((x_touch, x_sample)) if chained => h0 - (x_touch - x_sample),
                    _ => h_start,
                };
                let mut x_touch = touch.map(|(x, _)| x);
                if chained && (h_touch - h_start).abs() > contact_tolerance_m(r) {
                    blow = self.simulate_one(machine, r, Some((n, h_touch)))?;
                    x_touch = r.approach.map(|a| a.at(blow.on_window(0.0)));
                } else {
                    h_touch = h_start;
                }
                if let Some((x_touch, x_sample)) = x_touch.zip(r.approach.map(|a| a.x_m())) {
                    lead_m = x_sample - x_touch;
                }
                // Each link of the chain is known to the contact's uncertainty (± it, uniform).
                blow.sim.start_sd_m = chained.then(|| contact_tolerance_m(r) / 3f64.sqrt());
                prev = Some((n, h_touch, x_touch));
            }
            h = blow.sim.h_end_m.or(h);
            out.push(blow.sim);
        }
        Some(out)
    }

    /// One reference simulated, a billet blow (`blow`: its index and start height) or a bare
    /// strike, through the declared anti-alias filter and aligned on the measured clock.
    fn simulate_one(&self, machine: &Machine, r: &Reference, blow: Option<(usize, f64)>) -> Option<OneBlow> {
        let plant = match (&self.setting, blow) {
            (Setting::Billet(p), Some((n, h0))) => blow_plant(machine, &self.effects, p, n, h0),
            _ => Plant::new(machine, &self.effects, None, 0.0),
        };
        // Through a declared anti-alias filter, the trace on a step fine enough for the
        // filter (`LoadFilter::steps_per_sample`); else read at the samples.
        let over = self.effects.load_filter.steps_per_sample(r.dt_s);
        let fine_dt = r.dt_s / over as f64;
        let opts =
            SimOptions { method: Method::Dopri5 { rtol: FIT_RTOL }, post_s: r.duration_s(), trace_dt_s: Some(fine_dt) };
        // The blow ends a window after the model's alignment crossing (the last sample
        // compared), never before the contact opens (`TraceEnd`).
        let threshold = ALIGN_FRACTION * r.peak_n;
        let end = TraceEnd { threshold_n: threshold, after_s: r.duration_s() - r.t_align_s };
        let (res, trace) = match self.signal {
            Signal::Load => simulate_blow_sensor_until(&plant, r.v0_mps, &opts, end).ok()?,
            Signal::RamForce { m_ram_kg } => {
                // The model's ram flies free of gravity (its blow starts at contact), so
                // its acceleration is all the billet's: a rigid-plastic billet pushes at
                // once, from the first sample.
                let (res, acc) = simulate_blow_ram_until(&plant, r.v0_mps, &opts, end).ok()?;
                (res, acc.iter().map(|a| -m_ram_kg * a).collect())
            }
        };
        // The DAQ's view: its anti-alias filter as the machine file declares it.
        let trace = self.effects.load_filter.apply(&trace, fine_dt, r.dt_s);
        let (load, t_cross) = aligned(&trace, fine_dt, over, r.load_n.len(), threshold, r.t_align_s);
        let spectrum = SIM_PLANNER.with_borrow_mut(|p| p.amplitudes_up_to(&load, r.dt_s, PAD_FACTOR, 0, self.f_max_hz));
        // The model's instants on the window's clock (model time 0 is first contact).
        let on_window = |t: f64| t - t_cross + r.t_align_s;
        let forming_end = res.forming.map(|f| f.forming_time_s);
        let sim = Simulated {
            load_n: load,
            spectrum,
            h_end_m: res.forming.map(|f| f.h_end_m),
            h_start_m: res.forming.map(|_| res.h_start_m),
            start_sd_m: None,
            t_contact_s: on_window(0.0),
            t_forming_end_s: forming_end.map(on_window),
        };
        Some(OneBlow { sim, t_cross, t_align_s: r.t_align_s })
    }

    /// The weighted residuals of eq. 4 (module docs), appended to `out`; false when a
    /// simulation failed.
    pub fn residuals(&self, machine: &Machine, out: &mut Vec<f64>) -> bool {
        let last = self.fitted.iter().rposition(|f| *f).map_or(0, |i| i + 1);
        let Some(sims) = self.simulate_to(machine, last) else { return false };
        self.residuals_of(&sims, out);
        true
    }

    /// The weighted residuals of simulated references.
    pub fn residuals_of(&self, sims: &[Simulated], out: &mut Vec<f64>) {
        let k = (self.included().count() as f64).sqrt();
        if self.fidelity == Fidelity::Envelope {
            for i in self.included() {
                let (r, s) = (&self.refs[i], &sims[i]);
                let w = 1.0 / ((r.load_n.len() as f64).sqrt() * k * r.peak_n);
                let model = moving_average(&s.load_n, self.envelope_window[i]);
                out.extend(self.measured_envelope[i].iter().zip(&model).map(|(e, x)| w * (e - x)));
            }
            return;
        }
        for i in self.included() {
            let (r, s, sm) = (&self.refs[i], &sims[i], &self.measured_spectra[i]);
            let (n, m) = (r.load_n.len() as f64, sm.len() as f64);
            let f = m / (m + n);
            let (wf, ws) = ((f * G_WEIGHT / n).sqrt() / k, ((1.0 - f) * (1.0 - G_WEIGHT) / m.max(1.0)).sqrt() / k);
            let floor_f = RELATIVE_FLOOR * r.peak_n;
            out.extend(r.load_n.iter().zip(&s.load_n).map(|(e, x)| wf * (e - x) / e.abs().max(floor_f)));
            let floor_s = RELATIVE_FLOOR * sm.iter().copied().fold(0.0, f64::max);
            out.extend(
                sm.iter().zip(&s.spectrum).map(|(e, x)| ws * (e - x) / e.abs().max(floor_s).max(f64::MIN_POSITIVE)),
            );
        }
    }

    /// OF of eq. 4 (averaged over the fitted references) and the RMS load error of every
    /// reference, as a fraction of its peak.
    pub fn report(&self, sims: &[Simulated]) -> (f64, Vec<f64>) {
        let mut of = 0.0;
        let mut rms = Vec::new();
        for (i, ((r, s), sm)) in self.refs.iter().zip(sims).zip(&self.measured_spectra).enumerate() {
            rms.push(rms_peak_error(&r.load_n, &s.load_n, r.peak_n));
            if !self.fitted[i] {
                continue;
            }
            let (n, m) = (r.load_n.len() as f64, sm.len() as f64);
            let f = m / (m + n);
            let floor_f = RELATIVE_FLOOR * r.peak_n;
            let ef =
                (r.load_n.iter().zip(&s.load_n).map(|(e, x)| ((e - x) / e.abs().max(floor_f)).powi(2)).sum::<f64>()
                    / n)
                    .sqrt();
            let floor_s = RELATIVE_FLOOR * sm.iter().copied().fold(0.0, f64::max);
            let es = (sm.iter().zip(&s.spectrum).map(|(e, x)| ((e - x) / e.abs().max(floor_s)).powi(2)).sum::<f64>()
                / m.max(1.0))
            .sqrt();
            of += f * G_WEIGHT * ef + (1.0 - f) * (1.0 - G_WEIGHT) * es;
        }
        (of / self.included().count().max(1) as f64, rms)
    }
}

/// Machine modes in a blow's load spectrum (`spectrum::blow_modes`: the spectrum weighted
/// so that a mode stands above the ripples of the pulse, the papers' carrier, which is
/// flagged and left out), below `f_max_hz`.
pub fn machine_modes(s: &Spectrum, f_max_hz: f64) -> Vec<Mode> {
    blow_modes(s, 8).into_iter().filter(|m| !m.below_resolution && m.frequency_hz < f_max_hz).collect()
}

/// RMS of (measured − model) over the blow, as a fraction of the measured peak.
pub fn rms_peak_error(measured: &[f64], model: &[f64], peak: f64) -> f64 {
    let n = measured.len().max(1) as f64;
    (measured.iter().zip(model).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / n).sqrt() / peak
}

/// Bins 1..=m of a spectrum below `f_max_hz` (bin 0, the pulse's mean, is the carrier).
fn bins(s: &crate::signal::spectrum::Spectrum, f_max_hz: f64) -> Vec<f64> {
    (1..s.len()).take_while(|&k| s.frequency_hz(k) <= f_max_hz).map(|k| s.amplitude[k]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::machine::Hammer;

    #[test]
    fn the_encoder_chain_breaks_where_a_billet_would_grow_or_vanish() {
        // 30 mm before, the ram meets the billet 2 mm lower: 28 mm.
        let h = chained_height((30e-3, 0.470), 0.472, 60e-6).unwrap();
        assert!((h - 28e-3).abs() < 1e-12, "{h}");
        // 50 µm higher than before: within a 60 µm contact uncertainty, kept.
        assert!(chained_height((30e-3, 0.470), 0.470 - 50e-6, 60e-6).is_some());
        // 1 mm higher (another billet, an encoder zeroed between captures): broken.
        assert_eq!(chained_height((30e-3, 0.470), 0.469, 60e-6), None);
        // Lower than the die: broken.
        assert_eq!(chained_height((30e-3, 0.470), 0.501, 60e-6), None);
    }

    #[test]
    fn the_papers_machines_keep_the_papers_bands() {
        // Seed 000 §2.2 shows the hammer's spectrum to 5 kHz, seed 001 §3.1 the press's to
        // 1 kHz; derived from the prior's mode, the papers' own machines must get the same.
        for (kind, hz) in [(MachineKind::Hammer, 5000.0), (MachineKind::ScrewPress, 1000.0)] {
            let band = ModePrior::from(kind).band_hz();
            assert_eq!(band, hz, "{kind:?}");
        }
    }

    #[test]
    fn the_band_follows_the_priors_second_mode() {
        // Four times the spring over the same mass: the mode, sqrt(k/m2)/2π, doubles, so the
        // band must double (2.44 modes wide either way).
        let paper = default_prior(MachineKind::Hammer);
        let Machine::Hammer(h) = paper else { panic!("a hammer") };
        let stiff = Machine::Hammer(Hammer { k_n_per_m: 4.0 * h.k_n_per_m, ..h });
        let (a, b) = (ModePrior::from(&paper), ModePrior::from(&stiff));
        assert!((b.mode2_hz / a.mode2_hz - 2.0).abs() < 1e-12);
        assert!((b.band_hz() / a.band_hz() - 2.0).abs() < 1e-12, "{} vs {}", b.band_hz(), a.band_hz());
    }
}
