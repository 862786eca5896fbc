//! Speed of a full diagnosis (issue #17 target: a press billet pair in ≤ 30 s on the 2-core
//! machine; 8 effects, every parameter of each fitted, 5 calibration and 5 holdout blows),
//! on the withheld-effect suite's hammer and press with a hidden `friction_rise`, as
//! `forgemon diagnose` runs it less the file I/O; and one hammer blow as the fits simulate it
//! (issue #17 target ≤ 50 µs): one measured blow through `Objective::simulate`, window,
//! trace and spectrum included.
//!
//! Each is timed twice: wall-clock (criterion's default) and CPU time (`Cpu`: the blow's
//! thread, the diagnosis's whole process with its rayon workers). The machine is shared,
//! and under a load of 10 on 2 cores the wall time of one thread is 4–5× its CPU time; the
//! CPU time is what the code costs (an idle 2-core machine runs the diagnosis in about its
//! process CPU time over 2, if both workers are kept busy).
//!
//! The bench names keep their "7 pairs" for comparison with earlier runs, but with a single
//! hidden effect no pair is fitted any more: the best single effect leaves an error within
//! five times the noise, which no pair can cut by the verdict's 80 %
//! (`diagnose::attribute::hopeless_pair`). A case with two effects fits its pairs, and is not
//! benched here (`tests/diagnose_families.rs`' ignored `full_diagnosis_table` prints the
//! time of each diagnosis it runs).

use criterion::measurement::{Measurement, ValueFormatter};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use forgemon::config::{parse_machine, parse_process};
use forgemon::diagnose::diagnose;
use forgemon::estimate::EstimatorConfig;
use forgemon::identify::objective::{Reference, Setting};
use forgemon::physics::effects::{Effect, EffectSet};
use forgemon::physics::machine::{Machine, MachineKind};
use forgemon::signal::segment::{SegmentConfig, Segmenter};
use forgemon::synth::{CaptureSpec, rows_batch, synth_blows};

const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n";
const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
                     c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n";

/// One billet's blows with the hidden effect, read as `diagnose` reads a capture directory.
fn billet(m: &Machine, sheet: &str, height_factor: f64, v0s: &[f64], seed: u64) -> (Vec<Reference>, Setting) {
    let kind = m.kind();
    let mut p = parse_process("p", sheet).unwrap();
    p.measured_final_heights_m.clear();
    p.billet.height_m *= height_factor;
    let spec = match kind {
        MachineKind::Hammer => CaptureSpec::hammer(seed),
        MachineKind::ScrewPress => CaptureSpec::press(seed),
    };
    let hidden = EffectSet::from_effects(&[Effect::parse_spec("friction_rise:exponent=1.0").unwrap()]);
    let refs = synth_blows(m, &hidden, &p, v0s, &spec)
        .unwrap()
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let batch = rows_batch("c", 0, 0, 1e9 / spec.sample_rate_hz, &b.rows);
            let cut = Segmenter::cut_all(SegmentConfig::for_kind(kind), [&batch]);
            let fit_s = EstimatorConfig::for_kind(kind).fit_s;
            forgemon::diagnose::localise::reference("b", &cut[0], Some(i + 1), fit_s, m).unwrap()
        })
        .collect();
    (refs, Setting::Billet(p))
}

/// CPU time, ns: of the benchmarking thread, or of the whole process (every thread), by
/// POSIX `clock_gettime` (`/proc`'s counters only move at scheduler ticks, too coarse for a
/// blow). std has no CPU clock and the crate no `libc` dependency, so the call is declared
/// here; the ids are Linux's (`<linux/time.h>`).
#[derive(Debug, Clone, Copy)]
enum Cpu {
    Thread,
    Process,
}

/// `struct timespec` on 64-bit Linux.
#[repr(C)]
struct Timespec {
    tv_sec: i64,
    tv_nsec: i64,
}

unsafe extern "C" {
    fn clock_gettime(clock_id: i32, tp: *mut Timespec) -> i32;
}

const CLOCK_PROCESS_CPUTIME_ID: i32 = 2;
const CLOCK_THREAD_CPUTIME_ID: i32 = 3;

impl Cpu {
    fn now_ns(self) -> f64 {
        let id = match self {
            Cpu::Thread => CLOCK_THREAD_CPUTIME_ID,
            Cpu::Process => CLOCK_PROCESS_CPUTIME_ID,
        };
        let mut ts = Timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid, writable `timespec`; the call writes only into it.
        let rc = unsafe { clock_gettime(id, &mut ts) };
        assert_eq!(rc, 0, "clock_gettime({id})");
        ts.tv_sec as f64 * 1e9 + ts.tv_nsec as f64
    }
}

impl Measurement for Cpu {
    type Intermediate = f64;
    type Value = f64;
    fn start(&self) -> f64 {
        self.now_ns()
    }
    fn end(&self, i: f64) -> f64 {
        self.now_ns() - i
    }
    fn add(&self, a: &f64, b: &f64) -> f64 {
        a + b
    }
    fn zero(&self) -> f64 {
        0.0
    }
    fn to_f64(&self, v: &f64) -> f64 {
        *v
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        &CpuFormatter
    }
}

/// Nanoseconds shown as ns, µs, ms or s, marked as CPU time.
struct CpuFormatter;

impl ValueFormatter for CpuFormatter {
    fn scale_values(&self, typical: f64, values: &mut [f64]) -> &'static str {
        let (div, unit) = match typical {
            t if t < 1e3 => (1.0, "ns cpu"),
            t if t < 1e6 => (1e3, "µs cpu"),
            t if t < 1e9 => (1e6, "ms cpu"),
            _ => (1e9, "s cpu"),
        };
        values.iter_mut().for_each(|v| *v /= div);
        unit
    }
    fn scale_throughputs(&self, _typical: f64, _t: &Throughput, _values: &mut [f64]) -> &'static str {
        "ns cpu"
    }
    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns cpu"
    }
}

/// One hammer blow as each fit's cost function simulates it, per blow of the suite's first
/// calibration billet.
fn blow(c: &mut Criterion) {
    blow_in(c, "diagnose_blow");
}

fn blow_cpu(c: &mut Criterion<Cpu>) {
    blow_in(c, "diagnose_blow_cpu");
}

fn blow_in<M: Measurement>(c: &mut Criterion<M>, group: &str) {
    use forgemon::identify::objective::{ALIGN_FRACTION, FIT_RTOL, Objective};
    use forgemon::physics::blow::{SimOptions, TraceEnd, simulate_blow_sensor, simulate_blow_sensor_until};
    use forgemon::physics::integrator::Method;
    use forgemon::physics::sequence::blow_plant;
    let m = parse_machine("m", HAMMER).unwrap().machine;
    let (refs, setting) =
        billet(&m, include_str!("../config/steel-16NiCrMo13.process.toml"), 1.0, &[4.0, 4.5, 5.0, 5.3, 5.3], 3);
    let r = refs[0].clone();
    let Setting::Billet(ref p) = setting else { unreachable!("a billet") };
    let plant = blow_plant(&m, &EffectSet::NONE, p, 1, p.billet.height_m);
    let one = Objective::new(refs[..1].to_vec(), vec![true], setting.clone(), MachineKind::Hammer);
    let mut g = c.benchmark_group(group);
    g.bench_function("hammer_blow_as_fitted", |b| b.iter(|| one.simulate(&m).unwrap()));
    // The five blows of the billet as one evaluation of a fit's cost function simulates
    // them, with the chain of heights from blow to blow. Every iteration has the same
    // machine, so the tables `BaseHammer::with_exact_phases` keeps per machine are never
    // recomputed here; a fit's evaluations each have a new machine, and recompute them once
    // per five blows.
    let five = Objective::new(refs.clone(), vec![true; refs.len()], setting.clone(), MachineKind::Hammer);
    g.bench_function("hammer_5_blows_as_fitted", |b| b.iter(|| five.simulate(&m).unwrap()));
    // The physics of that blow alone, as `Objective::simulate_to` asks for it, and ending
    // at its last compared sample (`simulate_blow_sensor_until`: the caller's change the
    // README's "Speed" section describes).
    let opts =
        SimOptions { method: Method::Dopri5 { rtol: FIT_RTOL }, post_s: r.duration_s(), trace_dt_s: Some(r.dt_s) };
    let end = TraceEnd { threshold_n: ALIGN_FRACTION * r.peak_n, after_s: r.duration_s() - r.t_align_s };
    g.bench_function("hammer_blow_physics", |b| b.iter(|| simulate_blow_sensor(&plant, r.v0_mps, &opts).unwrap()));
    g.bench_function("hammer_blow_physics_until_last_sample", |b| {
        b.iter(|| simulate_blow_sensor_until(&plant, r.v0_mps, &opts, end).unwrap())
    });
    g.finish();
}

fn bench(c: &mut Criterion) {
    bench_in(c, "diagnose");
}

fn bench_cpu(c: &mut Criterion<Cpu>) {
    bench_in(c, "diagnose_cpu");
}

fn bench_in<M: Measurement>(c: &mut Criterion<M>, group: &str) {
    let mut g = c.benchmark_group(group);
    g.sample_size(10);
    for (name, text, sheet, calib, hold) in [
        (
            "hammer_8_effects_7_pairs_5_plus_5_blows",
            HAMMER,
            include_str!("../config/steel-16NiCrMo13.process.toml"),
            [4.0, 4.5, 5.0, 5.3, 5.3],
            [4.2, 4.8, 5.1, 5.3, 5.3],
        ),
        (
            "press_8_effects_7_pairs_5_plus_5_blows",
            PRESS,
            include_str!("../config/copper-cu99.process.toml"),
            [0.30, 0.33, 0.36, 0.36, 0.36],
            [0.31, 0.34, 0.35, 0.36, 0.36],
        ),
    ] {
        let m = parse_machine("m", text).unwrap().machine;
        let c_set = billet(&m, sheet, 1.0, &calib, 3);
        let h_set = billet(&m, sheet, 0.9, &hold, 4);
        g.bench_function(name, |b| {
            b.iter(|| {
                let d = diagnose(&m, &EffectSet::NONE, c_set.clone(), h_set.clone(), &|| {}).unwrap();
                assert_eq!(d.verdict.map(|v| v.name).as_deref(), Some("friction_rise"));
            })
        });
    }
    g.finish();
}

criterion_group!(benches, blow, bench);
criterion_group! {
    name = cpu;
    config = Criterion::default().with_measurement(Cpu::Thread);
    targets = blow_cpu
}
criterion_group! {
    name = cpu_process;
    config = Criterion::default().with_measurement(Cpu::Process);
    targets = bench_cpu
}
criterion_main!(benches, cpu, cpu_process);
