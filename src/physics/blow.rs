//! Simulating one blow: integrate the plant from first contact until the contact has been
//! open for the post window, recording the indicators of the hammer paper (§3.1.3), the
//! energy ledger and, when asked, a sampled trace.

use super::integrator::{self, IntegrationError, Limits, Method, Stats};
use super::ledger::Ledger;
use super::plant::{BaseHammer, N, Outputs, Plant, V3, VL, VR, VU, WD, WF, WP, Z};

mod recorder;
mod sensor;

use recorder::{Record, Recorder, Trace, forming_indicators};
pub use sensor::{FitBlow, simulate_blow_ram_until, simulate_blow_sensor, simulate_blow_sensor_until};

/// Simulated time after the contact ends that a blow keeps running (docs/interfaces.md §6 `post`).
pub const POST_WINDOW_S: f64 = 5e-3;
/// Default relative tolerance of the step control. On the hammer paper's blow 1 it is
/// within 0.15 µm of the converged final height and 0.1 % of the converged final load,
/// damped energy and efficiency (RK4 at 1e-8 s agrees); tightening it tenfold moves the
/// height by 0.14 µm (issue #2 asks for < 10 µm).
pub const DEFAULT_RTOL: f64 = 3e-5;
/// Plastic flow after the end of forming smaller than this is creep, not forming, m.
/// A tenth of the 10 µm encoder step of the press paper (seed 001 §2.1).
pub const FORMING_CREEP_M: f64 = 1e-6;
/// A blow that has not ended after this much simulated time is reported as an error.
pub const MAX_BLOW_S: f64 = 1.0;
/// Step budget of one blow: the fixed-step RK4 reference at 1e-8 s needs 1.5 million steps
/// for the paper's hammer blow; an adaptive run needs a few hundred.
pub const MAX_STEPS: u64 = 5_000_000;
/// More switching events than this in one blow means the contact chatters.
pub const MAX_EVENTS: u32 = 20_000;

/// Indicators of a blow on a billet (hammer paper §3.1.3 and docs/interfaces.md §4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Forming {
    /// Billet height at the end of forming, m.
    pub h_end_m: f64,
    /// Sensor load when plastic flow stops for good, N.
    pub final_load_n: f64,
    /// First contact to the end of forming, s (0 when the billet never yielded).
    pub forming_time_s: f64,
    /// End of forming until the sensor load first returns to zero, s (`None` if it did not
    /// within the blow).
    pub spring_back_time_s: Option<f64>,
}

/// A sampled signal point of a simulated blow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TracePoint {
    pub t_s: f64,
    pub out: Outputs,
}

/// Everything a blow simulation reports.
#[derive(Debug, Clone, PartialEq)]
pub struct BlowResult {
    pub v0_mps: f64,
    pub h_start_m: f64,
    /// `None` for a bare strike.
    pub forming: Option<Forming>,
    pub peak_load_n: f64,
    /// First contact until the contact opens for good, s.
    pub contact_time_s: f64,
    pub energy: Ledger,
    pub stats: Stats,
    /// Sampled signals, when asked for.
    pub trace: Vec<TracePoint>,
}

impl BlowResult {
    /// Plastic energy over kinetic energy in (docs/interfaces.md §4).
    pub fn efficiency(&self) -> f64 {
        self.energy.efficiency()
    }
}

/// How to integrate and what to keep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimOptions {
    pub method: Method,
    /// Simulated time kept after the contact opens, s.
    pub post_s: f64,
    /// Sample period of the trace, s; `None` keeps no trace.
    pub trace_dt_s: Option<f64>,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions { method: Method::Dopri5 { rtol: DEFAULT_RTOL }, post_s: POST_WINDOW_S, trace_dt_s: None }
    }
}

/// Where a fit's sensor trace may end (`simulate_blow_sensor_until`): `after_s` after the
/// first sample at or above `threshold_n`, but never before the contact opens (the
/// indicators and the ledger need the whole contact). A fit aligns the blows at its load's
/// first crossing of a threshold, which lies before that sample, and compares a window of
/// known length from there: the samples after it are never read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceEnd {
    pub threshold_n: f64,
    pub after_s: f64,
}

/// Why a blow could not be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BlowError {
    #[error("impact speed {v0_mps} m/s must be finite and > 0")]
    BadSpeed { v0_mps: f64 },
    #[error("billet height {h_m} m must be finite and > 0")]
    BadHeight { h_m: f64 },
    #[error(transparent)]
    Integration(#[from] IntegrationError),
}

/// Error-control scale of each state component for a blow at `v0_mps`.
fn scales(plant: &Plant, v0_mps: f64, kinetic_in_j: f64) -> [f64; N] {
    let v = v0_mps.max(0.01);
    // Travel in a tenth of the fastest period, and the load that moves a spring that far.
    let x = v / (10.0 * plant.f_max_hz.max(1.0));
    let k_ref = if plant.k_contact_n_per_m.is_finite() { plant.k_contact_n_per_m } else { 1e9 };
    let f = k_ref * x;
    let mut s = [x; N];
    for i in [VU, VR, VL, V3] {
        s[i] = v;
    }
    s[Z] = f;
    for i in [WP, WF, WD] {
        s[i] = kinetic_in_j;
    }
    for (i, used) in plant.used_states().into_iter().enumerate() {
        if !used {
            s[i] = f64::INFINITY;
        }
    }
    s
}

/// Simulate one blow at impact speed `v0_mps`.
pub fn simulate_blow(plant: &Plant, v0_mps: f64, opts: &SimOptions) -> Result<BlowResult, BlowError> {
    simulate_blow_traced_from(plant, v0_mps, opts, 0.0)
}

/// `simulate_blow` with the trace's first point at `trace_t0_s` (≥ 0, clamped) after first
/// contact instead of at contact: the model fit samples the simulated blow on the
/// measurement's grid, which contact falls between (`estimate::fit`).
pub fn simulate_blow_traced_from(
    plant: &Plant,
    v0_mps: f64,
    opts: &SimOptions,
    trace_t0_s: f64,
) -> Result<BlowResult, BlowError> {
    let (res, _) = run(plant, v0_mps, opts, trace_t0_s, Trace::Outputs(Vec::new()), Path::Specialised)?;
    Ok(res)
}

/// Which plant integrates a base hammer's blow (`BaseHammer::of`); other plants always run
/// on the general one. The tests compare the three.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Path {
    /// The general plant.
    General,
    /// The specialised plant, the general one's within roundoff: `simulate_blow` and the
    /// traced blows (`simulate`, the estimator, replay).
    Specialised,
    /// The specialised plant with its phases without plastic flow advanced exactly under
    /// Dormand–Prince (`BaseHammer::with_exact_phases`): `simulate_blow_sensor`, the fits'.
    Exact,
}

/// Integrate one blow, recording `trace`'s kind of samples; the trace is handed back apart.
fn run(
    plant: &Plant,
    v0_mps: f64,
    opts: &SimOptions,
    trace_t0_s: f64,
    trace: Trace,
    path: Path,
) -> Result<(BlowResult, Trace), BlowError> {
    let (blow, peak_n, trace) = run_until(plant, v0_mps, opts, trace_t0_s, trace, path, None, true)?;
    let (trace, kept) = match trace {
        Trace::Outputs(v) => (v, Trace::Outputs(Vec::new())),
        sensor @ Trace::Sensor(_) => (Vec::new(), sensor),
    };
    Ok((blow.with_peak(peak_n.expect("`run` keeps the peak"), trace), kept))
}

/// `run`, ending at `end` when given (`simulate_blow_sensor_until`), and keeping the
/// sensor's peak when `peak` is (then the middle of the answer).
#[allow(clippy::too_many_arguments)]
fn run_until(
    plant: &Plant,
    v0_mps: f64,
    opts: &SimOptions,
    trace_t0_s: f64,
    trace: Trace,
    path: Path,
    end: Option<TraceEnd>,
    peak: bool,
) -> Result<(FitBlow, Option<f64>, Trace), BlowError> {
    if !(v0_mps.is_finite() && v0_mps > 0.0) {
        return Err(BlowError::BadSpeed { v0_mps });
    }
    if plant.billet.is_some() && !(plant.h_start_m.is_finite() && plant.h_start_m > 0.0) {
        return Err(BlowError::BadHeight { h_m: plant.h_start_m });
    }
    let (y0, mode0) = plant.initial_state(v0_mps);
    let kinetic_in_j = plant.kinetic_in(&y0);
    let r = Record {
        post_s: opts.post_s,
        peak_n: peak.then_some(0.0),
        plastic_exits: Vec::new(),
        sensor_zeros: Vec::new(),
        separation: None,
        trace_dt: opts.trace_dt_s,
        next_sample: trace_t0_s.max(0.0),
        trace,
        last_end: None,
        trace_end: end,
        end_at_s: None,
    };
    let limits = Limits {
        t_max_s: MAX_BLOW_S,
        max_events: MAX_EVENTS,
        initial_step_s: 1e-3 / plant.f_max_hz.max(1.0),
        max_steps: MAX_STEPS,
    };
    let scale = scales(plant, v0_mps, kinetic_in_j);
    let (stats, rec) = match BaseHammer::of(plant).filter(|_| path != Path::General) {
        Some(b) => {
            let b = match (path, opts.method) {
                (Path::Exact, Method::Dopri5 { .. }) => b.with_exact_phases(trace_t0_s.max(0.0), opts.trace_dt_s),
                _ => b,
            };
            let mut obs = Recorder { plant, sys: &b, r, points: Vec::new() };
            let stats =
                integrator::integrate(&b, opts.method, &b.reduce(&scale), b.reduce(&y0), mode0, limits, &mut obs)?;
            (stats, obs.r)
        }
        None => {
            let mut obs = Recorder { plant, sys: plant, r, points: Vec::new() };
            (integrator::integrate(plant, opts.method, &scale, y0, mode0, limits, &mut obs)?, obs.r)
        }
    };
    let (t_sep, y_sep, mode_sep) = rec.separation.ok_or(IntegrationError::NoEnd { t_max_s: MAX_BLOW_S })?;
    let energy = Ledger {
        kinetic_in_j,
        plastic_j: y_sep[WP],
        friction_j: y_sep[WF],
        damped_j: y_sep[WD],
        elastic_j: plant.mechanical_energy(&y_sep, mode_sep),
    };
    let forming = plant
        .billet
        .as_ref()
        .map(|_| forming_indicators(&rec.plastic_exits, &rec.sensor_zeros, plant.h_start_m, t_sep));
    let blow = FitBlow { v0_mps, h_start_m: plant.h_start_m, forming, contact_time_s: t_sep, energy, stats };
    Ok((blow, rec.peak_n, rec.trace))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{parse_machine, parse_process};
    use crate::physics::effects::{Effect, EffectSet};
    use crate::physics::machine::Machine;
    use crate::physics::process::Process;
    use crate::physics::sequence::blow_plant;

    fn machine(text: &str) -> Machine {
        parse_machine("m", text).unwrap().machine
    }
    fn paper_hammer() -> Machine {
        machine(include_str!("../../config/hammer-lg1000.machine.toml"))
    }
    fn steel() -> Process {
        parse_process("steel", include_str!("../../config/steel-16NiCrMo13.process.toml")).unwrap()
    }
    fn effects(spec: &str) -> EffectSet {
        EffectSet::from_effects(&[Effect::parse_spec(spec).unwrap()])
    }

    /// Roundoff-level floors of the differences `differences` measures (final height m, an
    /// instant s, a load N, an energy over the energy in, a sensor sample N): a few ulp per
    /// evaluation of the vector field, carried through a blow's steps and its events'
    /// root-finding (`integrator::ROOT_REL_TOL`), far below what a capture resolves
    /// (`the_exact_phases_move_the_blow_by_less_than_the_sensors_can_see`' physical bounds).
    const ROUNDOFF: [f64; 5] = [1e-10, 1e-9, 1.0, 1e-8, 1.0];

    /// Blows `v0s` in sequence on both paths; asserts each result (indicators, ledger and
    /// the trace) and each sensor trace within `ROUNDOFF`, and returns how many blows ran
    /// on the specialised plant.
    fn both_paths(m: &Machine, fx: &EffectSet, p: &Process, v0s: &[f64], opts: &SimOptions) -> usize {
        let mut h = p.billet.height_m;
        let mut specialised = 0;
        for (i, &v0) in v0s.iter().enumerate() {
            let plant = blow_plant(m, fx, p, i + 1, h);
            specialised += usize::from(BaseHammer::of(&plant).is_some());
            let outputs = || Trace::Outputs(Vec::new());
            let (fast, _) = run(&plant, v0, opts, 0.0, outputs(), Path::Specialised).unwrap();
            let (general, _) = run(&plant, v0, opts, 0.0, outputs(), Path::General).unwrap();
            let d = differences(&fast, &general);
            let within = d.iter().zip(ROUNDOFF).all(|(d, tol)| *d <= tol);
            assert!(within, "blow {} at {v0} m/s: {d:?} over {ROUNDOFF:?}", i + 1);
            let (_, Trace::Sensor(fast_s)) =
                run(&plant, v0, opts, 0.0, Trace::Sensor(Vec::new()), Path::Specialised).unwrap()
            else {
                panic!("a sensor trace")
            };
            let general_s: Vec<f64> = general.trace.iter().map(|p| p.out.sensor_n).collect();
            assert!(fast_s.len().abs_diff(general_s.len()) <= 1, "sensor trace of blow {} at {v0} m/s", i + 1);
            for (a, b) in fast_s.iter().zip(&general_s) {
                assert!((a - b).abs() <= ROUNDOFF[4], "sensor trace of blow {} at {v0} m/s: {a} vs {b}", i + 1);
            }
            h = general.forming.map_or(h, |f| f.h_end_m);
        }
        specialised
    }

    /// The largest differences of `run_` from `reference`: final height m, an instant s (end
    /// of forming, spring-back, contact), a load N (final, peak), an energy term over the
    /// energy in, a sensor sample N (the traces may differ by a sample in length: the post
    /// window follows the contact's end, which moves by a fraction of a sample).
    fn differences(run_: &BlowResult, reference: &BlowResult) -> [f64; 5] {
        let mut d = [0.0f64; 5];
        let (fe, fg) = (run_.forming.unwrap(), reference.forming.unwrap());
        d[0] = (fe.h_end_m - fg.h_end_m).abs();
        let spring_back = |f: Forming| f.spring_back_time_s.unwrap_or(f64::NAN);
        for dt in [
            fe.forming_time_s - fg.forming_time_s,
            spring_back(fe) - spring_back(fg),
            run_.contact_time_s - reference.contact_time_s,
        ] {
            d[1] = d[1].max(dt.abs());
        }
        for dl in [fe.final_load_n - fg.final_load_n, run_.peak_load_n - reference.peak_load_n] {
            d[2] = d[2].max(dl.abs());
        }
        let (ee, eg) = (&run_.energy, &reference.energy);
        for (a, b) in [
            (ee.plastic_j, eg.plastic_j),
            (ee.friction_j, eg.friction_j),
            (ee.damped_j, eg.damped_j),
            (ee.elastic_j, eg.elastic_j),
        ] {
            d[3] = d[3].max((a - b).abs() / eg.kinetic_in_j);
        }
        let n = run_.trace.len().min(reference.trace.len());
        assert!(n + 2 >= reference.trace.len(), "{} vs {}", run_.trace.len(), reference.trace.len());
        for (a, b) in run_.trace[..n].iter().zip(&reference.trace[..n]) {
            assert_eq!(a.t_s, b.t_s);
            d[4] = d[4].max((a.out.sensor_n - b.out.sensor_n).abs());
        }
        d
    }

    #[test]
    fn the_base_hammer_blow_is_the_general_plants_within_roundoff() {
        let traced =
            SimOptions { method: Method::Dopri5 { rtol: 1e-6 }, trace_dt_s: Some(1e-5), ..SimOptions::default() };
        // The paper's hammer and steel billet (seed 000 §3.2: 3.9 m/s, then up to 5.3 m/s),
        // at the default and the fits' tolerances; RK4 as well (the same driver).
        let v0s = [3.9, 4.5, 5.3, 5.3, 5.3];
        for opts in [SimOptions::default(), traced] {
            assert_eq!(both_paths(&paper_hammer(), &EffectSet::NONE, &steel(), &v0s, &opts), v0s.len());
        }
        let rk4 = SimOptions { method: Method::Rk4 { dt_s: 2e-7 }, trace_dt_s: Some(1e-5), ..SimOptions::default() };
        assert_eq!(both_paths(&paper_hammer(), &EffectSet::NONE, &steel(), &[4.0], &rk4), 1);
        // The load-side effects live in the billet law, which the specialised plant shares.
        for spec in [
            "friction_rise:exponent=1.0",
            "strain_rate:m=0.1,rate_ref_per_s=1",
            "strain_hardening:n=0.3,eps_ref=0.1",
            "thermal:q_dT=0.3",
        ] {
            assert_eq!(both_paths(&paper_hammer(), &effects(spec), &steel(), &v0s[..3], &traced), 3, "{spec}");
        }
        // A light, soft hammer whose tools stick and part again (the diagnosis suite's).
        let small = machine("kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n");
        assert_eq!(both_paths(&small, &EffectSet::NONE, &steel(), &[4.0, 4.5, 5.0], &traced), 3);
    }

    /// The largest differences of blows `v0s` in sequence run on `path` with `opts` from a
    /// reference, the general plant at rtol 1e-10 (the blow sequence follows the reference's
    /// heights): final height m, an instant s (end of forming, spring-back, contact), a load N
    /// (final, peak), an energy term over the energy in, a sensor sample N. And the run's
    /// largest ledger residual over the energy in.
    fn errors(m: &Machine, v0s: &[f64], path: Path, opts: &SimOptions) -> ([f64; 5], f64) {
        errors_on(m, &steel(), v0s, path, opts)
    }

    /// `errors` on the billet `p`.
    fn errors_on(m: &Machine, p: &Process, v0s: &[f64], path: Path, opts: &SimOptions) -> ([f64; 5], f64) {
        let converged = SimOptions { method: Method::Dopri5 { rtol: 1e-10 }, ..*opts };
        let (mut h, mut d, mut closure) = (p.billet.height_m, [0.0f64; 5], 0.0f64);
        for (i, &v0) in v0s.iter().enumerate() {
            let plant = blow_plant(m, &EffectSet::NONE, p, i + 1, h);
            let outputs = || Trace::Outputs(Vec::new());
            let (run_, _) = run(&plant, v0, opts, 0.0, outputs(), path).unwrap();
            let (reference, _) = run(&plant, v0, &converged, 0.0, outputs(), Path::General).unwrap();
            if path == Path::Exact {
                assert!(run_.stats.exact_steps > 0, "{:?}", run_.stats);
            }
            assert!(run_.trace.len() > 100 || reference.trace.is_empty(), "{}", run_.trace.len());
            for (d, e) in d.iter_mut().zip(differences(&run_, &reference)) {
                *d = d.max(e);
            }
            let ee = &run_.energy;
            let sum = ee.plastic_j + ee.friction_j + ee.damped_j + ee.elastic_j;
            closure = closure.max((sum / ee.kinetic_in_j - 1.0).abs());
            h = reference.forming.unwrap().h_end_m;
        }
        (d, closure)
    }

    #[test]
    fn the_exact_phases_move_the_blow_by_less_than_the_sensors_can_see() {
        // The fits' tolerance and trace (rtol 1e-6, 100 kHz: `identify::objective`) on the
        // paper's hammer (seed 000 §3.2's speeds) and the diagnosis suite's light hammer,
        // whose tools stick and part again; and the default tolerance.
        let fits =
            SimOptions { method: Method::Dopri5 { rtol: 1e-6 }, trace_dt_s: Some(1e-5), ..SimOptions::default() };
        let default_traced = SimOptions { trace_dt_s: Some(1e-5), ..SimOptions::default() };
        let small = machine("kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n");
        // Below these nothing a capture records can tell the blows apart: 1e-3 of the 10 µm
        // encoder step (seed 001 §2.1), a tenth of a 100 kHz sample, a tenth of the hammer
        // captures' 2 kN load noise (`synth::CaptureSpec::hammer`), 1e-3 of docs/interfaces.md §4's
        // 1 % ledger closure.
        let physical = [1e-8, 1e-6, 200.0, 1e-5, 200.0];
        for (m, v0s, opts, at_fits) in [
            (paper_hammer(), &[3.9, 4.5, 5.3][..], fits, true),
            (small, &[4.0, 4.5, 5.0][..], fits, true),
            (small, &[4.0, 4.5][..], default_traced, false),
        ] {
            let (e, ce) = errors(&m, v0s, Path::Exact, &opts);
            let (g, cg) = errors(&m, v0s, Path::General, &opts);
            eprintln!(
                "{opts:?}\n exact   h {:.2e} m, t {:.2e} s, load {:.2e} N, energy {:.2e}, sensor {:.2e} N; closure {ce:.2e}",
                e[0], e[1], e[2], e[3], e[4]
            );
            eprintln!(
                " general h {:.2e} m, t {:.2e} s, load {:.2e} N, energy {:.2e}, sensor {:.2e} N; closure {cg:.2e}",
                g[0], g[1], g[2], g[3], g[4]
            );
            for i in 0..5 {
                // The exact phases add no error of their own, and the plastic phases'
                // exponential steps (`BaseHammer`'s `etd`) follow the lower tool's ringing
                // exactly, so the height, the instants, the loads and the sensor are at least
                // as close as the general plant's Dormand–Prince (1.5x leaves room for the
                // phases' slightly different switch instants). Not the works: their rates
                // ring (c v², F (v_u - v_l)) and those steps integrate them as RK4 does, so
                // the ledger is held to the physical bound alone, at every tolerance.
                if i == 3 {
                    assert!(e[3] <= physical[3], "energy: {:e} (general {:e})", e[3], g[3]);
                    continue;
                }
                assert!(e[i] <= 1.5 * g[i] + ROUNDOFF[i], "quantity {i}: exact {:e} vs general {:e}", e[i], g[i]);
                if at_fits {
                    assert!(e[i] <= physical[i], "quantity {i}: {:e} at the fits' tolerance", e[i]);
                }
            }
            assert!(ce <= 1e-5, "ledger closure {ce:e} (general {cg:e})");
        }
    }

    #[test]
    fn the_fits_tolerance_is_the_loosest_the_captures_cannot_see() {
        // The fits' rtol (`identify::objective::FIT_RTOL`, 1e-6) against the next looser one
        // of issue 17's sweep (1e-6, 3e-6, 1e-5, 3e-5, 1e-4; docs/validation.md "Exact linear phases"),
        // each run as the fits run it (100 kHz on the hammers, 20 kHz on the press; the
        // hammers with their exact phases), errors against the general plant at rtol 1e-10.
        // Bounds: what a capture cannot see (as in the test above): 1e-3 of the 10 µm encoder
        // step (seed 001 §2.1) on the final height, a tenth of the captures' load noise on the
        // sensor (`synth::CaptureSpec`: 2 kN on the hammers, 5 kN on the press), and on the
        // hammers a tenth of a sample on the instants. The press's end of forming (where the
        // flow load drops as the plastic rate reaches the rate floor, located late by the step
        // control: `synth::CAPTURE_RTOL`) is already off by 50 µs, a sample, at 1e-6: printed,
        // not bounded.
        let small = machine("kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n");
        let press = machine(include_str!("../../config/screw-press-spr400.machine.toml"));
        let copper = parse_process("cu", include_str!("../../config/copper-cu99.process.toml")).unwrap();
        let cases = [
            (paper_hammer(), steel(), &[3.9, 4.5, 5.3][..], Path::Exact, 1e-5, [1e-8, 1e-6, 200.0]),
            (small, steel(), &[4.0, 4.5, 5.0][..], Path::Exact, 1e-5, [1e-8, 1e-6, 200.0]),
            // Press paper Table 1's speeds on copper; the press runs on the general plant.
            (press, copper, &[0.30, 0.33, 0.36][..], Path::General, 5e-5, [1e-8, f64::INFINITY, 500.0]),
        ];
        let mut looser_seen = false;
        for (m, p, v0s, path, dt_s, bound) in &cases {
            let within = |rtol: f64| {
                let opts =
                    SimOptions { method: Method::Dopri5 { rtol }, trace_dt_s: Some(*dt_s), ..SimOptions::default() };
                let (e, _) = errors_on(m, p, v0s, *path, &opts);
                eprintln!("{:?} rtol {rtol:e}: h {:.2e} m, t {:.2e} s, sensor {:.2e} N", m.kind(), e[0], e[1], e[4]);
                [e[0], e[1], e[4]].iter().zip(bound).all(|(e, b)| e <= b)
            };
            assert!(within(1e-6), "{:?} at the fits' rtol", m.kind());
            looser_seen |= !within(3e-6);
        }
        // 3e-6 is over a bound somewhere (the press's sensor, 3.8 kN): tightening nothing
        // else, 1e-6 is the loosest of the sweep. The hammers no longer are: their plastic
        // flow takes exponential steps, whose accuracy does not follow rtol (7.2e-10 m and
        // 14 N at 3e-6, where Dormand–Prince left 1.6e-8 m).
        assert!(looser_seen, "rtol 3e-6 is within every bound: the fits' tolerance could be loosened");
    }

    #[test]
    fn a_fits_blow_ends_at_its_last_compared_sample() {
        // The fits' options on the suite's hammer (its post window advanced exactly) and the
        // paper's press on copper (Dormand–Prince throughout; press paper Table 1's speed),
        // a 17 ms window as the suite's hammer captures have, 100 ms on the press (its contact
        // lasts 65 ms): ending the blow 16 ms (80 ms) after the first sample at a tenth of
        // the peak (the window less the 1 ms the fits keep before it) keeps the indicators, the ledger and
        // the samples up to there, and saves steps (it keeps no peak): the hammer's tools ride together for
        // 12.6 ms, so the post window ran 17 ms past the 16 ms the fits compare.
        let small = machine("kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n");
        let press = machine(include_str!("../../config/screw-press-spr400.machine.toml"));
        let copper = parse_process("cu", include_str!("../../config/copper-cu99.process.toml")).unwrap();
        for (m, p, v0, dt, post_s, after_s) in
            [(small, steel(), 4.0, 1e-5, 17e-3, 16e-3), (press, copper, 0.346, 5e-5, 100e-3, 80e-3)]
        {
            let plant = blow_plant(&m, &EffectSet::NONE, &p, 1, p.billet.height_m);
            let opts = SimOptions { method: Method::Dopri5 { rtol: 1e-6 }, post_s, trace_dt_s: Some(dt) };
            let (full, s_full) = simulate_blow_sensor(&plant, v0, &opts).unwrap();
            let end = TraceEnd { threshold_n: 0.1 * full.peak_load_n, after_s };
            let (cut, s_cut) = simulate_blow_sensor_until(&plant, v0, &opts, end).unwrap();
            let k = s_full.iter().position(|&s| s >= end.threshold_n).unwrap();
            // The last sample at or before the stop (the contact is over by then).
            let last = ((k as f64 * dt + end.after_s) / dt * (1.0 + 1e-9)).floor() as usize;
            assert!(full.contact_time_s < (last as f64) * dt, "{:?} {}", m.kind(), full.contact_time_s);
            assert_eq!(s_cut.len(), last + 1, "{:?}", m.kind());
            assert_eq!(FitBlow { stats: full.stats, ..cut.clone() }, FitBlow::from(&full), "{:?}", m.kind());
            assert!(cut.stats.steps < full.stats.steps, "{:?} vs {:?}", cut.stats, full.stats);
            // Samples of the steps before the stop are the same; the last, cut short, moves
            // its samples by the step control's error on the press (its own 1e-6).
            let diff = |i: usize| (s_cut[i] - s_full[i]).abs();
            let moved = (0..=last).filter(|&i| diff(i) > 0.0).count();
            let largest = (0..=last).map(diff).fold(0.0, f64::max);
            eprintln!(
                "{:?}: {} of {} samples, {} steps of {}, {moved} moved by up to {largest:e} N",
                m.kind(),
                s_cut.len(),
                s_full.len(),
                cut.stats.steps,
                full.stats.steps
            );
            assert!(largest <= 1e-6 * full.peak_load_n, "{largest} N");
            // The hammer's exact steps give the cut blow's samples as they are computed
            // (`recorder::sensor_points`, no peak kept) and the full blow's from the points
            // gathered for its peak: the same, bit for bit, up to the stop.
            if m.kind() == crate::physics::machine::MachineKind::Hammer {
                assert_eq!(moved, 0, "{largest} N");
            }
        }
    }

    #[test]
    fn only_a_base_hammer_on_a_billet_is_specialised() {
        let p = steel();
        let plant = |m: &Machine, fx: &EffectSet| blow_plant(m, fx, &p, 1, p.billet.height_m);
        let m = paper_hammer();
        assert!(BaseHammer::of(&plant(&m, &EffectSet::NONE)).is_some());
        for spec in [
            "clearance:gap_m=3e-4",
            "elastic_recovery:k_contact_N_per_m=1e9",
            "foundation:m3_kg=20000,k3_N_per_m=2e9,c3_Ns_per_m=2e5",
            "sensor_highpass:tau_s=2e-3",
        ] {
            assert!(BaseHammer::of(&plant(&m, &effects(spec))).is_none(), "{spec}");
        }
        assert!(BaseHammer::of(&Plant::new(&m, &EffectSet::NONE, None, 0.0)).is_none(), "bare strike");
        let press = machine(include_str!("../../config/screw-press-spr400.machine.toml"));
        assert!(BaseHammer::of(&plant(&press, &EffectSet::NONE)).is_none(), "press");
    }

    #[test]
    fn the_sensor_trace_is_the_full_traces_sensor() {
        // The general plant (a press on copper, press paper Table 1's 0.346 m/s, and a hammer
        // with a machine-side effect) skips the billet law for the sensor; it must not move it.
        let opts =
            SimOptions { method: Method::Dopri5 { rtol: 1e-6 }, trace_dt_s: Some(1e-5), ..SimOptions::default() };
        let copper = parse_process("cu", include_str!("../../config/copper-cu99.process.toml")).unwrap();
        let press = machine(include_str!("../../config/screw-press-spr400.machine.toml"));
        let cases = [
            (press, EffectSet::NONE, copper, 0.346),
            (paper_hammer(), effects("elastic_recovery:k_contact_N_per_m=1e9"), steel(), 3.9),
        ];
        for (m, fx, p, v0) in cases {
            let plant = blow_plant(&m, &fx, &p, 1, p.billet.height_m);
            assert!(BaseHammer::of(&plant).is_none());
            let full = simulate_blow(&plant, v0, &opts).unwrap();
            let (res, sensor) = simulate_blow_sensor(&plant, v0, &opts).unwrap();
            assert!(sensor.len() > 100, "{} samples", sensor.len());
            assert_eq!(sensor, full.trace.iter().map(|p| p.out.sensor_n).collect::<Vec<_>>());
            assert_eq!(res, BlowResult { trace: Vec::new(), ..full });
        }
        // A base hammer's sensor-only blow runs with its exact phases: the full trace on the
        // same path (its samples from the same grid points) has the same sensor.
        let plant = blow_plant(&paper_hammer(), &EffectSet::NONE, &steel(), 1, 0.112);
        let (full, _) = run(&plant, 3.9, &opts, 0.0, Trace::Outputs(Vec::new()), Path::Exact).unwrap();
        let (res, sensor) = simulate_blow_sensor(&plant, 3.9, &opts).unwrap();
        assert!(res.stats.exact_steps > 0, "{:?}", res.stats);
        assert!(res.stats.etd_steps > 0, "{:?}", res.stats);
        assert_eq!(sensor, full.trace.iter().map(|p| p.out.sensor_n).collect::<Vec<_>>());
        assert_eq!(res, BlowResult { trace: Vec::new(), ..full });
    }

    #[test]
    fn the_fits_plastic_flow_takes_exponential_steps_where_they_hold() {
        // The fits' options on the two hammers (seed 000 §3.2's 3.9 m/s; the suite's 4 m/s):
        // their plastic flow takes exponential steps, at well under half the evaluations of
        // Dormand–Prince on the same plant (issue 17's blow; the studied 3.3x is
        // `benches/plastic_integrators.py`'s, on the first plastic phase alone).
        let fits =
            SimOptions { method: Method::Dopri5 { rtol: 1e-6 }, trace_dt_s: Some(1e-5), ..SimOptions::default() };
        let small = machine("kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n");
        for (m, v0) in [(paper_hammer(), 3.9), (small, 4.0)] {
            let plant = blow_plant(&m, &EffectSet::NONE, &steel(), 1, 0.112);
            let outputs = || Trace::Outputs(Vec::new());
            let (etd, _) = run(&plant, v0, &fits, 0.0, outputs(), Path::Exact).unwrap();
            let (dopri, _) = run(&plant, v0, &fits, 0.0, outputs(), Path::Specialised).unwrap();
            // They cover most of the flow: a step spans the samples within 1 rad of the
            // lower tool's ringing (`etd::ETD_STEP_RAD`).
            let span_s = (1.0 / (2.0 * std::f64::consts::PI * m.second_mode_hz() * 1e-5)).floor() * 1e-5;
            let forming_s = etd.forming.unwrap().forming_time_s;
            let covered = f64::from(etd.stats.etd_steps) * span_s / forming_s;
            assert!(covered > 0.8, "{covered}: {:?}", etd.stats);
            assert!(2 * etd.stats.rhs_evals < dopri.stats.rhs_evals, "{:?} vs {:?}", etd.stats, dopri.stats);
        }
        // A rate-dependent law (the `strain_rate` effect, whose damping near the end of flow,
        // m F / h', is not in the linear part) takes none.
        let plant = blow_plant(&paper_hammer(), &effects("strain_rate:m=0.15"), &steel(), 1, 0.112);
        let (res, _) = simulate_blow_sensor(&plant, 3.9, &fits).unwrap();
        assert_eq!(res.stats.etd_steps, 0, "{:?}", res.stats);
        // Asked for 1e-9, most steps' error estimates exceed it: Dormand–Prince takes those
        // spans (114 of 137 here), and the final height follows the tolerance, within the
        // roundoff-level floor of the comparisons above (1e-10 m) of the general plant at
        // 1e-10 (8e-11 m: the estimate is not a bound, and the 23 spans it let through leave
        // more than Dormand–Prince's own 1.8e-12 m; at the fits' 1e-6 the errors are held to
        // what a capture cannot see by the tests above).
        let tight = SimOptions { method: Method::Dopri5 { rtol: 1e-9 }, ..fits };
        let converged = SimOptions { method: Method::Dopri5 { rtol: 1e-10 }, ..fits };
        let plant = blow_plant(&paper_hammer(), &EffectSet::NONE, &steel(), 1, 0.112);
        let (res, _) = simulate_blow_sensor(&plant, 3.9, &tight).unwrap();
        let reference = simulate_blow(&plant, 3.9, &converged).unwrap();
        assert!(res.stats.rejected > res.stats.etd_steps, "{:?}", res.stats);
        let dh = (res.forming.unwrap().h_end_m - reference.forming.unwrap().h_end_m).abs();
        assert!(dh < 1e-10, "{dh:e} m, {:?}", res.stats);
    }
}
