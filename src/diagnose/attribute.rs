//! Attribution: each effect of the library (docs/interfaces.md §6) with all its parameters fitted
//! on the calibration blows (issue #17: the whole family), then scored on the holdout
//! blows.
//!
//! A fit is a global stage, a coarse grid per candidate (log-spaced over the bounds where
//! the cost is far from convex, as in a gap or a time constant; a few points where it has
//! one valley; a damper or a reference searched on the grid in the coordinates the data
//! determine, a damping ratio or a flow-stress level) and a fine scan of a clearance's gap
//! from the best grid points (its valley can be narrower than the grid's step) and at the gap
//! the measured closure shows (the ram's contact leading the load's), followed by
//! Levenberg–Marquardt (`identify::fit`) from the best points found. The global stage's
//! points and costs are `scan.rs`'s. The residuals are the
//! load errors over each blow's baseline window, over the peak, so the cost is the mean
//! nrmse² the contract scores.

use crate::identify::fit::bounded_fit;
use crate::identify::model::Param;
use crate::physics::effects::{DEFAULT_EPS_REF, DEFAULT_RATE_REF_PER_S, Effect, EffectSet, K_DIE_KEY};
use crate::physics::machine::{Machine, MachineKind};

use super::blowset::{BlowSet, mean};
use super::evidence::MIN_PAIR_SHRINK;
use super::scan::{Costs, Scan, fine_points};

/// One library effect: all its parameters fitted (issue #17 item 5: the whole family),
/// with their bounds, the coarse grid the global stage searches, and the effect they give.
#[derive(Debug, Clone)]
pub struct Candidate {
    pub name: &'static str,
    pub params: Vec<Param>,
    /// The coarse grid, one axis per parameter.
    grid: Vec<Axis>,
    /// Turns a grid point's coordinates into parameter values (a damper searched as a
    /// damping ratio, a reference searched as a flow-stress level); identity for most.
    from_grid: fn(&mut [f64]),
    build: fn(&[f64]) -> Effect,
}

/// One axis of the coarse grid.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Axis {
    /// This many log-spaced points over the parameter's bounds.
    Log(usize),
    /// These grid coordinates, which the candidate's `from_grid` turns into values.
    At(&'static [f64]),
}

impl Candidate {
    pub fn effect(&self, values: &[f64]) -> Effect {
        (self.build)(values)
    }

    /// This candidate's parameter values in `e` (one of its effects), within its bounds: a
    /// key `e` leaves out is at its neutral end (a rigid die contact at `K_DIE`'s top, else
    /// the lower bound).
    pub(super) fn values_of(&self, e: &Effect) -> Vec<f64> {
        let given = e.params();
        self.params
            .iter()
            .map(|p| {
                let absent = if p.key == K_DIE_KEY { p.hi } else { p.lo };
                given.iter().find(|(k, _)| *k == p.key).map_or(absent, |(_, v)| *v).clamp(p.lo, p.hi)
            })
            .collect()
    }

    /// Whether the first parameter's valleys can be narrower than the coarse grid's step,
    /// so that it is scanned finely (`scan::FINE`) before the local search: a clearance's gap,
    /// whose closure may last a few samples (issue #17: a 0.3 mm gap under a 50 kg die on a
    /// 20 kHz press was fitted at 52 µm from the coarse grid).
    pub(super) fn fine_first(&self) -> bool {
        self.name == "clearance"
    }

    /// The coarse grid's points, each as parameter values.
    pub(super) fn grid_points(&self) -> Vec<Vec<f64>> {
        let axes: Vec<Vec<f64>> = self
            .params
            .iter()
            .zip(&self.grid)
            .map(|(p, a)| match *a {
                Axis::Log(n) => log_points(p, n),
                Axis::At(v) => v.to_vec(),
            })
            .collect();
        let mut points = product(&axes);
        for v in &mut points {
            (self.from_grid)(v);
        }
        points
    }

    /// A press foundation's ring scanned finely about `at` (this candidate's values), at
    /// `RING_ZETAS`: its spring over half the coarse grid's step either way, the mass as at
    /// `at`; and with `band` (Hz, the best point's scan only), its mass over the ring
    /// frequencies the blows can show (`BlowSet::ring_band_hz`) in steps of `RING_MASS_STEP`,
    /// the spring as at `at`, at the lighter damping ratio. The grid's best points settle the
    /// spring (the foundation's compliance in series with the support's) well before its
    /// mass: on the family's report seed 4916 (rigid-eq3 press, 5.1 t on 5.35 GN/m at a
    /// damping ratio of 0.015, 163 Hz) the three best were 0.8, 1.6 and 24 t, all on
    /// 5.08 GN/m (397, 283 and 73 Hz), the spring's scan at those masses reached none of the
    /// hidden ring, and the fit settled on 11 t on 3.2 GN/m damped at 0.24, its calibration
    /// cost 7.9× the hidden one's (verdict uncertain, shrink 0.34); with the mass's scan,
    /// 5.1 t on 5.40 GN/m at 1.0× the hidden cost. Empty for the other candidates, and on a
    /// hammer: its 20 ms window holds a few of a foundation's periods (five of 250 Hz), each
    /// extra local search is time against the hammer's budget (issue 41: 5 s a case), and the
    /// scan was set on press cases only.
    pub(super) fn ring_points(&self, kind: MachineKind, at: &[f64], band: Option<(f64, f64)>) -> Vec<Vec<f64>> {
        if self.name != "foundation" || kind != MachineKind::ScrewPress {
            return Vec::new();
        }
        let k = &self.params[1];
        let half_step = ((k.hi / k.lo).ln() / GRID as f64 / 2.0).exp();
        let span = Param { key: k.key, lo: at[1] / half_step, hi: at[1] * half_step };
        let mut out = Vec::new();
        for zeta in RING_ZETAS {
            out.extend(log_points(&span, RING_POINTS).into_iter().map(|k3| vec![at[0], k3, zeta]));
        }
        if let Some((f_lo, f_hi)) = band {
            // The undamped frequency of the foundation alone, √(k3/m3)/2π: near the coupled
            // ring's, and the local search takes it from there.
            let m = &self.params[0];
            let mass_at = |f: f64| at[1] / (std::f64::consts::TAU * f).powi(2);
            let masses = Param { key: m.key, lo: mass_at(f_hi).max(m.lo), hi: mass_at(f_lo).min(m.hi) };
            if masses.lo < masses.hi {
                let n = ((masses.hi / masses.lo).ln() / RING_MASS_STEP.ln()).ceil() as usize;
                out.extend(log_points(&masses, n).into_iter().map(|m3| vec![m3, at[1], RING_ZETAS[0]]));
            }
        }
        for v in &mut out {
            (self.from_grid)(v);
        }
        out
    }
}

/// `n` log-spaced values over `p`'s bounds, at the centres of equal log-intervals.
pub(super) fn log_points(p: &Param, n: usize) -> Vec<f64> {
    (0..n).map(|i| (p.lo.ln() + (p.hi.ln() - p.lo.ln()) * (i as f64 + 0.5) / n as f64).exp()).collect()
}

/// Every combination of one value per axis.
fn product(axes: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut points: Vec<Vec<f64>> = vec![Vec::new()];
    for axis in axes {
        points = points.into_iter().flat_map(|pt| axis.iter().map(move |v| [pt.clone(), vec![*v]].concat())).collect();
    }
    points
}

/// Grid points of the coarse search for a parameter whose cost has several valleys (a gap,
/// a time constant, a contact stiffness, a foundation's mass and spring): 17 put one within
/// a factor 1.7 of any gap in its bounds. With 9 per axis the press suite's foundation
/// (20 t on 5 GN/m) was fitted in a side valley (10 t on 5.5 GN/m, calibration error 14× the
/// true model's).
const GRID: usize = 17;
/// Grid points for a parameter that only scales a flow stress's rise (a friction exponent,
/// a rate or hardening exponent, a thermal coefficient): the cost along it has one valley,
/// which the local search finds from any point of it.
const GRID_MONOTONE: usize = 7;

/// A press clearance's third parameter, the billet's contact stiffness with the loose die
/// (`Effect::Clearance::k_die_n_per_m`). From `K_DIE_RIGID_N_PER_M` up it is the rigid
/// contact (infinite): the coarse grid starts there, at the bound, and a search that stays
/// in that range simulates the rigid die (a 1e13 N/m spring under a 300 kg die took 15× the
/// rigid one's time per simulation). The compliant contacts are reached from the closure
/// (`scan::K_DIE_STEPS`).
pub(super) const K_DIE: Param = Param { key: K_DIE_KEY, lo: 1e9, hi: 1e13 };
/// Where `K_DIE` becomes the rigid contact: three times the stiffest contact the family's
/// elastic renderers' clearances were fitted at (1.35e12 N/m over tune seeds 4100–4119,
/// their billet is 1e12).
pub const K_DIE_RIGID_N_PER_M: f64 = 3e12;
/// The flow-stress levels at the reference rate (strain) the grid of `strain_rate`
/// (`strain_hardening`) starts from: the sheet's flow stress within ±25 %.
const LEVELS: [f64; 5] = [0.8, 0.9, 1.0, 1.12, 1.25];
/// The rate (1/s) and strain at which `strain_rate`'s and `strain_hardening`'s levels are
/// taken: the defaults of docs/interfaces.md §6, within the blows' ranges (10–40 /s; 0–0.5).
const RATE_AT_LEVEL_PER_S: f64 = DEFAULT_RATE_REF_PER_S;
const STRAIN_AT_LEVEL: f64 = DEFAULT_EPS_REF;
/// Bounds of the references: wide enough that the grid's levels are reached for exponents
/// down to about 0.02 (rate) and 0.1 (strain); below, the level is held nearer 1.
const RATE_REF: Param = Param { key: "rate_ref_per_s", lo: 1e-3, hi: 1e5 };
/// The floor of the rate and hardening exponents' search (`verdict::level_only` reads it).
pub const EXPONENT_FLOOR: f64 = 1e-3;
const EPS_REF: Param = Param { key: "eps_ref", lo: 1e-3, hi: 1e2 };
/// The foundation's damping ratio at the grid's points: the local search moves it either
/// way (from a start at 0 it could not: the log transform's gradient vanishes at a bound).
const FOUNDATION_ZETA_START: f64 = 0.1;
/// The damping ratios of a foundation's fine ring scan (`Candidate::ring_points`). A lightly
/// damped foundation rings for many periods, and the cost's valley in its frequency is then
/// far narrower than the coarse grid's step (×1.5 in frequency): on the family's tune seed
/// 4127 (rigid-eq3 press, a 1.4 t foundation on 18 GN/m at a damping ratio of 0.014), no
/// grid point came near the hidden ring, and the fit settled on a 4.9 t foundation damped at
/// 0.15, its calibration cost 1.6× the hidden one's and its holdout shrink 0.43. The
/// family's foundations are damped at 0.01–0.2 (`tests/independent/drawn.rs`).
const RING_ZETAS: [f64; 2] = [0.015, 0.04];
/// Points of the ring scan over its span: its frequency in steps of 1 %.
const RING_POINTS: usize = 41;
/// Step of the ring scan's mass at the best point's spring: its frequency in steps of 2 %
/// (a ring 2 % off is a tenth of a period out of phase after five periods; the local search
/// takes it from there). About the three best points, and at both damping ratios, it took a
/// press case with no hidden effect from 15.8 to 31.1 s (the family's tune seed 4171,
/// rigid-eq3: 1992 points, 1410 of them costed in full).
const RING_MASS_STEP: f64 = 1.0404;
/// Bounds of the foundation's damper, N s/m. The upper one is half the critical damping of
/// the heaviest stiffest foundation in bounds (1e6 kg on 1e12 N/m: 2e9 N s/m); the lower one
/// is no damping at all for any foundation in bounds (a damping ratio under 2e-4 for the
/// lightest, 10 kg on 1e6 N/m).
const C3_LO: f64 = 1.0;
const C3_HI: f64 = 1e9;
/// A foundation's damping ratio below which it is reported undamped (0, the library's
/// neutral damper). A blow shows at most some ten periods of a foundation's ring (the
/// hammer's 250 Hz foundation in its 20 ms window: five); a ratio of 1e-4 changes the ring's
/// amplitude over ten periods by 2π·10·1e-4 = 0.6 %, of a ring that is itself a part of the
/// load: far below the sensors' noise. Undamped foundations of tests/diagnose.rs (capture
/// seeds 3/4) were fitted at 5e-5 (hammer) and 1.5e-5 (press): seen before this bound was
/// set.
const ZETA_UNDAMPED: f64 = 1e-4;

/// The library for a machine of `kind`, every parameter of every effect fitted, with bounds
/// wide enough for any machine the papers describe. A press's `clearance` also fits the
/// lower die that crosses the gap: the base press has no mass there, and dead travel of a
/// massless path is a pure delay that leaves no trace in the load.
///
/// `strain_rate`'s σ·(ε̇/ε̇₀)^m changes the flow stress's level with ε̇₀ at a fixed m (and
/// `strain_hardening`'s σ·(ε/ε₀)^n with ε₀), so the reference is fitted too, searched on the
/// grid as the level at 10 /s (at a strain of 0.2). What the data determine is the exponent
/// and that level; the reference itself only as well as the level over the exponent (docs/validation.md,
/// "Diagnosis: effect families").
pub fn library(kind: MachineKind) -> Vec<Candidate> {
    let p = |key, lo, hi| Param { key, lo, hi };
    let same: fn(&mut [f64]) = |_| {};
    let one = |name, param: Param, build| Candidate {
        name,
        params: vec![param],
        grid: vec![Axis::Log(GRID)],
        from_grid: same,
        build,
    };
    let monotone = |name, param: Param, build| Candidate {
        name,
        params: vec![param],
        grid: vec![Axis::Log(GRID_MONOTONE)],
        from_grid: same,
        build,
    };
    let clearance = match kind {
        MachineKind::Hammer => one("clearance", p("gap_m", 1e-6, 5e-3), |v| Effect::Clearance {
            gap_m: v[0],
            m_lower_kg: 0.0,
            k_die_n_per_m: f64::INFINITY,
        }),
        MachineKind::ScrewPress => Candidate {
            name: "clearance",
            params: vec![p("gap_m", 1e-6, 5e-3), p("m_lower_kg", 10.0, 1e5), K_DIE],
            grid: vec![Axis::Log(GRID), Axis::Log(GRID), Axis::At(&[K_DIE.hi])],
            from_grid: same,
            build: |v| Effect::Clearance {
                gap_m: v[0],
                m_lower_kg: v[1],
                k_die_n_per_m: if v[2] >= K_DIE_RIGID_N_PER_M { f64::INFINITY } else { v[2] },
            },
        },
    };
    vec![
        clearance,
        one("elastic_recovery", p("k_contact_N_per_m", 1e7, 1e12), |v| Effect::ElasticRecovery {
            k_contact_n_per_m: v[0],
        }),
        monotone("friction_rise", p("exponent", 1e-3, 3.0), |v| Effect::FrictionRise { exponent: v[0] }),
        Candidate {
            name: "strain_rate",
            params: vec![p("m", EXPONENT_FLOOR, 0.5), RATE_REF],
            grid: vec![Axis::Log(GRID_MONOTONE), Axis::At(&LEVELS)],
            from_grid: |v| v[1] = reference_at_level(RATE_AT_LEVEL_PER_S, v[1], v[0], &RATE_REF),
            build: |v| Effect::StrainRate { m: v[0], rate_ref_per_s: v[1] },
        },
        Candidate {
            name: "strain_hardening",
            params: vec![p("n", EXPONENT_FLOOR, 1.0), EPS_REF],
            grid: vec![Axis::Log(GRID_MONOTONE), Axis::At(&LEVELS)],
            from_grid: |v| v[1] = reference_at_level(STRAIN_AT_LEVEL, v[1], v[0], &EPS_REF),
            build: |v| Effect::StrainHardening { n: v[0], eps_ref: v[1] },
        },
        monotone("thermal", p("q_dT", 1e-4, 2.0), |v| Effect::Thermal { q_dt: v[0] }),
        Candidate {
            name: "foundation",
            params: vec![p("m3_kg", 10.0, 1e6), p("k3_N_per_m", 1e6, 1e12), p("c3_Ns_per_m", C3_LO, C3_HI)],
            grid: vec![Axis::Log(GRID), Axis::Log(GRID), Axis::At(&[FOUNDATION_ZETA_START])],
            from_grid: |v| v[2] = (2.0 * v[2] * (v[0] * v[1]).sqrt()).clamp(C3_LO, C3_HI),
            build: |v| Effect::Foundation { m3_kg: v[0], k3_n_per_m: v[1], c3_ns_per_m: foundation_damper(v) },
        },
        one("sensor_highpass", p("tau_s", 1e-4, 10.0), |v| Effect::SensorHighpass { tau_s: v[0] }),
    ]
}

/// The reference (rate or strain) at which the law `(x/ref)^e` gives `level` at `x_at`,
/// within `bounds`: `ref = x_at · level^(-1/e)`.
fn reference_at_level(x_at: f64, level: f64, e: f64, bounds: &Param) -> f64 {
    (x_at * level.powf(-1.0 / e)).clamp(bounds.lo, bounds.hi)
}

/// The foundation's damper from its fitted (m3, k3, c3): 0 below `ZETA_UNDAMPED` of the
/// critical damping, which the blows cannot tell from none, and at most `ZETA_MAX` of it.
fn foundation_damper(v: &[f64]) -> f64 {
    let critical = 2.0 * (v[0] * v[1]).sqrt();
    if v[2] < ZETA_UNDAMPED * critical { 0.0 } else { v[2].min(ZETA_MAX * critical) }
}

/// The largest damping ratio a fitted foundation is given. A foundation on pads or soil is
/// damped far less (a ratio of a few tenths); far above critical the mass no longer moves
/// and the damper's own time constant, m3/c3, becomes the stiffest mode of the model: a
/// 10 kg foundation on 1e12 N/m with a damper of 1e9 N s/m (a ratio of 160, 10 ns) took the
/// integrator 207 s over one fit (tests/independent/drawn.rs, a rigid-eq3 hammer with no
/// hidden effect, seed 4904), the other fits 3 s together.
const ZETA_MAX: f64 = 2.0;

/// A fitted candidate (or pair).
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted {
    /// `"a"` or `"a+b"`.
    pub name: String,
    pub effects: Vec<Effect>,
    /// Parameters fitted (the parsimony of issue #17: fewer wins a tie).
    pub n_params: usize,
    /// Mean nrmse on the calibration and holdout blows, and per holdout blow.
    pub calib: f64,
    pub holdout: f64,
    pub holdout_per_blow: Vec<f64>,
}

/// Levenberg–Marquardt's evaluation budget per parameter for a diagnosis's fits, half
/// identification's (`identify::fit::PATIENCE`). A search that has not converged by then
/// crawls along a valley toward a bound, an exponent heading for its floor: on the
/// family's tune seed 4100 (elastic-siebel hammer, foundation hidden), the pair
/// foundation+friction_rise ran its searches to the old budget, 2508 simulations of the
/// calibration blows for 4 % of its cost, 4.5 s of the case's 6.3 s; 1634 and 3.4 s at
/// this one (the Jacobians' simulations are outside the budget). No verdict or agreement
/// of the family's 108 hammer tune cases moved.
const PATIENCE: usize = 30;

/// Fit `cands` jointly (one effect, or a pair) on `calib` and score on `holdout`. The
/// first `held.len()` parameters start at `held` (a single effect's fit, when a second is
/// added); the others start from the best points of a log grid.
pub fn fit_candidates(
    machine: &Machine,
    base: &EffectSet,
    cands: &[&Candidate],
    held: &[f64],
    calib: &BlowSet,
    holdout: &BlowSet,
) -> Option<Fitted> {
    if hopeless_pair(machine, base, cands, held, holdout) {
        return None;
    }
    let params: Vec<Param> = cands.iter().flat_map(|c| c.params.iter().copied()).collect();
    let f = |v: &[f64]| calib.residuals(machine, &set_of(base, cands, v));
    let cost = |v: &[f64]| f(v).map_or(f64::INFINITY, |r| r.iter().map(|x| x * x).sum::<f64>());
    let bound = |v: &[f64]| calib.first_blow_cost(machine, &set_of(base, cands, v));
    let mut scan = Scan::global(cands, &params, held, calib, machine, Costs { cost: &cost, bound: &bound });
    if spoils_its_first(machine, base, cands, held, calib, &scan) {
        return None;
    }
    // Levenberg–Marquardt from the best few points (the costs have several valleys),
    // keeping the best.
    let local = |from: &[f64], c: f64| {
        let r = bounded_fit(&params, calib.len(), &f, from, PATIENCE);
        if r.cost <= c { (r.cost, r.values) } else { (c, from.to_vec()) }
    };
    // The starts in parallel: once the quick candidates are done, the slowest one's
    // searches would otherwise run one after the other on a core each.
    use rayon::prelude::*;
    let starts = scan.starts(cands, held.len(), machine.kind(), calib.ring_band_hz());
    let mut start =
        starts.par_iter().map(|i| local(&scan.points[*i], scan.costs[*i])).min_by(|a, b| a.0.total_cmp(&b.0))?;
    // The fine scan again, the other parameters as fitted: a clearance's gap is a shallow
    // valley along which the local search stalls once the die's mass (a sharp one) is
    // right (issue #17's 20 kHz press: a 0.3 mm gap under 50 kg fitted at 52 µm, its
    // calibration error 8 % above the true gap's).
    let again = fine_points(cands, &params, held.len(), std::slice::from_ref(&start.1), false);
    if let Some(i) = scan.add_best(again)
        && scan.costs[i] < start.0
    {
        let polished = local(&scan.points[i], scan.costs[i]);
        if polished.0 < start.0 {
            start = polished;
        }
    }
    let used = |v: &[f64]| effects_of(cands, v).iter().map(|e| e.params().len()).sum::<usize>();
    let scores = |v: &[f64]| {
        let set = set_of(base, cands, v);
        Some((calib.nrmse(machine, &set)?, holdout.nrmse(machine, &set)?))
    };
    let (values, (calib_n, hold_n)) = match scores(&start.1) {
        Some(s) => (start.1, s),
        // A fit that cannot simulate every blow falls back to the best point of the simpler
        // model, polished: a light die thrown ahead by a stiff contact rattles on it without
        // end in some blows (the family's hertz-tresca press, report seed 4900: a 45 kg die
        // at 1e12 N/m fitted the calibration blows, and a holdout blow ran to the 1 s
        // limit), and the candidate would otherwise be lost with its rigid fit.
        None => {
            let n = used(&start.1);
            let i = (0..scan.points.len())
                .filter(|&i| scan.costs[i].is_finite() && used(&scan.points[i]) < n)
                .min_by(|a, b| scan.costs[*a].total_cmp(&scan.costs[*b]))?;
            let simpler = local(&scan.points[i], scan.costs[i]).1;
            let s = scores(&simpler)?;
            (simpler, s)
        }
    };
    Some(Fitted {
        name: cands.iter().map(|c| c.name).collect::<Vec<_>>().join("+"),
        // The parameters the fitted effects use: a press clearance whose die contact stayed
        // rigid is the two-parameter model.
        n_params: used(&values),
        effects: effects_of(cands, &values),
        calib: mean(&calib_n),
        holdout: mean(&hold_n),
        holdout_per_blow: hold_n,
    })
}

/// `effects` (a fitted candidate's, each a library effect) fitted again on `calib` with
/// blow `i` counted `weights[i]` times, by Levenberg–Marquardt from their own values: a
/// bootstrap resample's fit (`confidence.rs`). The global stage is not run again: a
/// resample of the same blows moves the optimum within its valley. None when an effect is
/// not the library's or a simulation fails.
pub fn refit(
    machine: &Machine,
    base: &EffectSet,
    effects: &[Effect],
    calib: &BlowSet,
    weights: &[f64],
) -> Option<Vec<Effect>> {
    let lib = library(machine.kind());
    let cands: Vec<&Candidate> =
        effects.iter().map(|e| lib.iter().find(|c| c.name == e.name())).collect::<Option<_>>()?;
    let params: Vec<Param> = cands.iter().flat_map(|c| c.params.iter().copied()).collect();
    let start: Vec<f64> = effects.iter().zip(&cands).flat_map(|(e, c)| c.values_of(e)).collect();
    // Only the parameters the fitted effects use move: a press clearance fitted with a rigid
    // die contact is refitted as the two-parameter model it was chosen as.
    let used: Vec<&str> = effects.iter().flat_map(|e| e.params().into_iter().map(|(k, _)| k)).collect();
    let free: Vec<usize> = (0..params.len()).filter(|&i| used.contains(&params[i].key)).collect();
    let full = |u: &[f64]| {
        let mut v = start.clone();
        for (i, x) in free.iter().zip(u) {
            v[*i] = *x;
        }
        v
    };
    let free_params: Vec<Param> = free.iter().map(|&i| params[i]).collect();
    let free_start: Vec<f64> = free.iter().map(|&i| start[i]).collect();
    let f = |u: &[f64]| calib.residuals_weighted(machine, &set_of(base, &cands, &full(u)), weights);
    let run = bounded_fit(&free_params, calib.len(), &f, &free_start, PATIENCE);
    run.cost.is_finite().then(|| effects_of(&cands, &full(&run.values)))
}

/// The effects of `cands` at the parameter vector `v` (their parameters in order).
fn effects_of(cands: &[&Candidate], v: &[f64]) -> Vec<Effect> {
    let mut k = 0;
    cands
        .iter()
        .map(|c| {
            let n = c.params.len();
            let e = c.effect(&v[k..k + n]);
            k += n;
            e
        })
        .collect()
}

/// `base` with the effects of `cands` at `v`.
fn set_of(base: &EffectSet, cands: &[&Candidate], v: &[f64]) -> EffectSet {
    let mut s = *base;
    for e in effects_of(cands, v) {
        s.apply(&e);
    }
    s
}

/// Whether a pair (`cands[0]` at `held`, plus another) cannot pass the verdict's pair rule
/// (`verdict.rs`: its holdout error at most 1 − `MIN_PAIR_SHRINK` of the first effect's
/// alone): no model's error falls below the sensor noise, so when the first effect alone
/// is already within 1 / (1 − `MIN_PAIR_SHRINK`) of the holdout's noise, the pair is not
/// fitted. In single-effect cases this skips every pair, half the diagnosis's fits.
fn hopeless_pair(machine: &Machine, base: &EffectSet, cands: &[&Candidate], held: &[f64], holdout: &BlowSet) -> bool {
    let Some(first) = cands.first().filter(|c| cands.len() > 1 && held.len() == c.params.len()) else {
        return false;
    };
    let mut set = *base;
    set.apply(&first.effect(held));
    holdout.nrmse(machine, &set).is_some_and(|e| mean(&e) * (1.0 - MIN_PAIR_SHRINK) <= holdout.noise_nrmse())
}

/// Whether a pair (`cands[0]` at `held`, plus another) is worse than its first effect alone
/// at every point `scan` costed: wherever the scan put the second effect (its whole grid,
/// the first held where its own fit ended), it only spoils the first's fit. Such a pair is
/// not searched further: it is named only when it removes most of what the first leaves
/// (`verdict.rs`, rules 4 and 5). On the press of the family's tune seed 4104 (strain_rate
/// hidden, every renderer), strain_rate+clearance's searches took 52 s of a 57 s case, in
/// the stiff blows a light lower die makes with a rate law, and ended 4× worse than
/// strain_rate alone.
fn spoils_its_first(
    machine: &Machine,
    base: &EffectSet,
    cands: &[&Candidate],
    held: &[f64],
    calib: &BlowSet,
    scan: &Scan,
) -> bool {
    if cands.len() < 2 || held.len() != cands[0].params.len() {
        return false;
    }
    let alone = calib.residuals(machine, &set_of(base, &cands[..1], held));
    let Some(alone) = alone.map(|r| r.iter().map(|x| x * x).sum::<f64>()) else { return false };
    scan.costs.iter().all(|c| *c > alone)
}
