//! The blow advisor's speed (issue 20: a plan of up to 15 blows over 5 settings in ≤ 50 ms,
//! so the service can replan after every blow). Cases: the LG1000 with steel from 112 mm
//! to 70 mm on five low settings (14 blows, the longest plan within `MAX_BLOWS` found on
//! this sheet), and to 40 mm on five settings up to the paper's 5.3 m/s (4 blows); the SPR
//! 400 with copper from 30 mm to 12 mm on a continuous range up to 0.45 m/s.

use criterion::{Criterion, criterion_group, criterion_main};
use forgemon::advise::{Advisor, PlanRequest, Speeds};
use forgemon::config::{parse_machine, parse_process};
use forgemon::physics::EffectSet;

fn bench(c: &mut Criterion) {
    let hammer = parse_machine("h", include_str!("../config/hammer-lg1000.machine.toml")).expect("machine").machine;
    let steel = parse_process("s", include_str!("../config/steel-16NiCrMo13.process.toml")).expect("sheet");
    let press = parse_machine("p", include_str!("../config/screw-press-spr400.machine.toml")).expect("machine").machine;
    let copper = parse_process("c", include_str!("../config/copper-cu99.process.toml")).expect("sheet");
    let cases = [
        ("hammer 14 blows, 5 settings", &hammer, &steel, 0.112, 0.070, Speeds::Settings(vec![0.9, 1.1, 1.3, 1.5, 1.7])),
        ("hammer 4 blows, 5 settings", &hammer, &steel, 0.112, 0.040, Speeds::Settings(vec![2.5, 3.2, 3.9, 4.6, 5.3])),
        ("press 2 blows, range", &press, &copper, 0.030, 0.012, Speeds::UpTo(0.45)),
    ];
    let mut g = c.benchmark_group("advise");
    g.sample_size(20);
    for (name, m, p, h, t, speeds) in cases {
        let advisor = Advisor::new(m, &EffectSet::NONE, p);
        let req = PlanRequest { h_now_m: h, target_m: t, blows_done: 0, speeds };
        let plan = advisor.plan(&req).expect("a plan");
        eprintln!("{name}: {:?} blows", plan.blows_to_target);
        g.bench_function(name, |b| b.iter(|| advisor.plan(&req).expect("a plan")));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
