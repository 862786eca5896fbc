//! Speed of identification (issue #5 target: a hammer from one reference blow in ≤ 5 s on
//! the 2-core machine): the whole `identify` (8 starts, envelope then full objective,
//! uncertainty, 200 Monte Carlo draws for the bands), and one evaluation of the objective.

use criterion::{Criterion, criterion_group, criterion_main};
use forgemon::config::{parse_machine, parse_process};
use forgemon::identify::model::default_prior;
use forgemon::identify::objective::{Objective, Reference, Setting};
use forgemon::identify::speed::impact_speed_sd_mps;
use forgemon::identify::{IdentifyConfig, identify};
use forgemon::physics::EffectSet;
use forgemon::physics::machine::MachineKind;
use forgemon::signal::segment::{SegmentConfig, Segmenter};
use forgemon::synth::{CaptureSpec, rows_batch, synth_blows};

/// Blow 1 of a hammer unlike the paper's, as a reference.
/// With its impact speed's standard error, m/s, as `forgemon identify` passes it.
fn reference() -> ((Reference, f64), Setting) {
    let m = parse_machine("m", "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n")
        .unwrap()
        .machine;
    let p = parse_process("p", include_str!("../config/steel-16NiCrMo13.process.toml")).unwrap();
    let b = &synth_blows(&m, &EffectSet::NONE, &p, &[4.2], &CaptureSpec::hammer(3)).unwrap()[0];
    let blows = Segmenter::cut_all(SegmentConfig::HAMMER, [&rows_batch("c", 0, 0, 1e4, &b.rows)]);
    let r = Reference::from_blow("blow_01", &blows[0], Some(1), 0.01).unwrap();
    ((r, impact_speed_sd_mps(&blows[0], 0.01).unwrap()), Setting::Billet(p))
}

fn bench(c: &mut Criterion) {
    let (with_sd, setting) = reference();
    let r = with_sd.0.clone();
    let prior = default_prior(MachineKind::Hammer);
    let mut g = c.benchmark_group("identify");
    g.sample_size(10);
    g.bench_function("hammer_one_blow_8_starts_mc200", |b| {
        b.iter(|| {
            identify(vec![with_sd.clone()], Vec::new(), setting.clone(), prior, &IdentifyConfig::default(), &|| {})
                .unwrap()
        })
    });
    let obj = Objective::new(vec![r.clone()], vec![true], setting.clone(), MachineKind::Hammer);
    g.bench_function("objective_one_evaluation", |b| {
        let mut out = Vec::new();
        b.iter(|| {
            out.clear();
            obj.residuals(&prior, &mut out)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
