//! Speed of the physics core (issue #2 targets): one hammer blow at the default tolerance
//! (≤ 50 µs), the fixed-step RK4 at 1e-7 s (the paper's Simulink step) for the ratio, a
//! press bare strike, the ten copper blows, and the 3000-run Monte Carlo (≤ 0.5 s wall on
//! 2 cores).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::integrator::Method;
use forgemon::physics::montecarlo::{Uncertainty, monte_carlo};
use forgemon::physics::{EffectSet, Machine, Process, SimOptions, simulate_bare, simulate_sequence};

fn hammer() -> Machine {
    parse_machine("hammer", include_str!("../config/hammer-lg1000.machine.toml")).unwrap().machine
}
fn press() -> Machine {
    parse_machine("press", include_str!("../config/screw-press-spr400.machine.toml")).unwrap().machine
}
fn steel() -> Process {
    parse_process("steel", include_str!("../config/steel-16NiCrMo13.process.toml")).unwrap()
}
fn copper() -> Process {
    parse_process("copper", include_str!("../config/copper-cu99.process.toml")).unwrap()
}

fn blows(c: &mut Criterion) {
    let (m, p) = (hammer(), steel());
    let fast = SimOptions::default();
    let no_post = SimOptions { post_s: 0.0, ..SimOptions::default() };
    // Still converged by issue #2's test (h moves 0.6 µm when tightened tenfold), but the
    // final load moves by 1.6 kN, which is why it is not the default.
    let loose = SimOptions { method: Method::Dopri5 { rtol: 1e-4 }, ..SimOptions::default() };
    let rk4 = SimOptions { method: Method::Rk4 { dt_s: 1e-7 }, ..SimOptions::default() };
    let mut g = c.benchmark_group("blow");
    g.bench_function("hammer_table3_blow1", |b| {
        b.iter(|| simulate_sequence(&m, &EffectSet::NONE, &p, black_box(&[3.9]), &fast).unwrap())
    });
    g.bench_function("hammer_table3_blow1_no_post_window", |b| {
        b.iter(|| simulate_sequence(&m, &EffectSet::NONE, &p, black_box(&[3.9]), &no_post).unwrap())
    });
    g.bench_function("hammer_table3_blow1_rtol_1e-4", |b| {
        b.iter(|| simulate_sequence(&m, &EffectSet::NONE, &p, black_box(&[3.9]), &loose).unwrap())
    });
    let pr = press();
    g.bench_function("press_bare_strike", |b| {
        b.iter(|| simulate_bare(&pr, &EffectSet::NONE, black_box(0.363), &fast).unwrap())
    });
    let cu = copper();
    g.bench_function("press_copper_ten_blows", |b| {
        b.iter(|| simulate_sequence(&pr, &EffectSet::NONE, &cu, black_box(&[0.346; 10]), &fast).unwrap())
    });
    g.sample_size(10);
    g.bench_function("hammer_table3_blow1_rk4_1e-7", |b| {
        b.iter(|| simulate_sequence(&m, &EffectSet::NONE, &p, black_box(&[3.9]), &rk4).unwrap())
    });
    g.finish();
}

fn study(c: &mut Criterion) {
    let (m, p) = (hammer(), steel());
    let mut g = c.benchmark_group("monte_carlo");
    g.sample_size(10);
    g.bench_function("hammer_blow1_3000_runs", |b| {
        b.iter(|| {
            monte_carlo(
                &m,
                &EffectSet::NONE,
                &p,
                &[3.9],
                &Uncertainty::default(),
                black_box(3000),
                1,
                &SimOptions::default(),
            )
            .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, blows, study);
criterion_main!(benches);
