//! The renderer family of issue 41 (`independent::family`, `independent::drawn`): the
//! contact and friction laws checked against each other without a diagnosis, the drawn
//! machines and effects checked against their stated ranges, and a few full diagnoses on
//! `report` seeds (`drawn::REPORT`), which nothing in the diagnosis was tuned on.
//!
//! The diagnosis cases (`diagnosed`) are the misses on machines never seen, one
//! machine per kind (`CASE_SEED`): a none case per renderer, a clear compliant contact on the
//! press (called `foundation` before) and a 0.3 mm press clearance (called `none`). A case the
//! current diagnosis fails is `#[ignore]`d with what it gave. The rates over many seeds are the
//! `#[ignore]`d `tests/diagnose_family_rates.rs`.

#[path = "independent/mod.rs"]
mod independent;

use independent::drawn::{self, Drawn, EFFECTS};
use independent::family::{self, Contact, Friction, RENDERERS, Renderer};
use independent::verdict::{names, own_shrink, strength, verdict_of};
use independent::{Hidden, Kind, speeds};

const KINDS: [Kind; 2] = [Kind::Hammer, Kind::Press];

/// The family's elastic-plastic law with eq. 3 is `independent`'s own renderer integrated
/// another way (semi-implicit Euler against velocity Verlet, both at 100 fine steps a
/// sample), each recorded through the blow's end: on the fixed rigs' first calibration blow
/// the two agree on the final height
/// within 5 µm (half the encoder's 10 µm step) and on the plastic energy within 0.2 %
/// (both first-order-small in the step: 1e-7 s against the hammer die's 2 kHz mode).
#[test]
fn the_family_integrates_the_existing_law_as_the_existing_renderer() {
    for kind in KINDS {
        let m = drawn::fixed(kind);
        let p = m.process();
        let (v0, h0) = (speeds(kind).0[0], p.billet.height_m);
        let r = Renderer { contact: Contact::ElasticPlastic, friction: Friction::CoulombEq3 };
        let fam = m.blow(r, &p, &Hidden::None, v0, h0);
        let (h_end, plastic) = family::existing_blow(kind, &p, v0, h0, 0.12);
        eprintln!(
            "{kind:?}: h_end {:.6} vs {:.6} m, plastic {:.1} vs {:.1} J",
            fam.h_end_m, h_end, fam.plastic_j, plastic
        );
        assert!((fam.h_end_m - h_end).abs() <= 5e-6, "{kind:?}: {} against {h_end}", fam.h_end_m);
        assert!((fam.plastic_j / plastic - 1.0).abs() <= 2e-3, "{kind:?}: {} J against {plastic} J", fam.plastic_j);
    }
}

/// The three contact laws put the same plastic energy into one blow (eq. 3 for all): the
/// billet's own compliance (1e12 N/m, the Hertz contact's tangent stiffness at its typical
/// load) is under 1 % of the machines' (≤ 8e9 N/m in series), so it stores and returns under
/// 1 % of the elastic energy, and the plastic energy moves by less than that. Within 1 % on
/// the fixed rigs and on two drawn machines of each kind.
#[test]
fn the_contact_laws_agree_on_the_plastic_energy_of_a_blow() {
    for kind in KINDS {
        for m in [drawn::fixed(kind), drawn::draw(kind, drawn::REPORT), drawn::draw(kind, drawn::REPORT + 1)] {
            let p = m.process();
            let (v0, h0) = (speeds(kind).0[0], p.billet.height_m);
            let e: Vec<f64> = [Contact::RigidPlastic, Contact::ElasticPlastic, Contact::HertzSeries]
                .iter()
                .map(|&contact| {
                    m.blow(Renderer { contact, friction: Friction::CoulombEq3 }, &p, &Hidden::None, v0, h0).plastic_j
                })
                .collect();
            eprintln!(
                "{kind:?} L {:.2}: plastic rigid {:.1} J, elastic {:.1} J, hertz {:.1} J",
                m.scale, e[0], e[1], e[2]
            );
            for x in &e[1..] {
                assert!((x / e[0] - 1.0).abs() <= 0.01, "{kind:?} {}: {e:?}", m.toml);
            }
        }
    }
}

/// The rigid-plastic contact is a constraint, not a spring: its force never pulls and never
/// exceeds the yield load; it holds the tools together below the yield load for a while
/// (the stuck phase a spring would not have at the same force), and they part at the end.
/// On the hammer (die with a mass) and on the press with a clearance's die (the constraint
/// between two masses).
#[test]
fn the_rigid_plastic_contact_never_pulls() {
    let r = Renderer { contact: Contact::RigidPlastic, friction: Friction::CoulombEq3 };
    for (kind, hidden) in [
        (Kind::Hammer, Hidden::None),
        (Kind::Hammer, Hidden::Clearance { gap_m: 0.2e-3, die_kg: 0.0 }),
        (Kind::Press, Hidden::Clearance { gap_m: 0.2e-3, die_kg: 600.0 }),
    ] {
        let m = drawn::draw(kind, drawn::REPORT + 2);
        let p = m.process();
        let b = m.blow(r, &p, &hidden, speeds(kind).0[0], p.billet.height_m);
        let (mut stuck, mut over) = (0, 0);
        for (f, fy) in b.billet_n.iter().zip(&b.yield_n) {
            assert!(*f >= 0.0, "{kind:?}: the contact pulls ({f} N)");
            over += usize::from(*f > fy * (1.0 + 1e-12));
            stuck += usize::from(*f > 0.0 && *f < 0.999 * fy);
        }
        let last = *b.billet_n.last().unwrap();
        eprintln!("{kind:?} {hidden:?}: {stuck} stuck steps of {}", b.billet_n.len());
        assert_eq!(over, 0, "{kind:?}: above the yield load");
        assert!(stuck > 10, "{kind:?}: no stuck phase");
        assert_eq!(last, 0.0, "{kind:?}: the tools never part");
    }
}

/// Eq. 3, Siebel and Tresca (m = √3 μ) agree to first order in d/h: each is 1 + μ d/(3h) +
/// O((μ d/h)²), eq. 3's second-order term being (μ d/h)²/12 (its series 1 + A/3 + A²/12 + …).
#[test]
fn the_friction_laws_agree_to_first_order() {
    for mu in [0.05, 0.2, 0.4] {
        for d_over_h in [0.01, 0.05, 0.2, 0.5] {
            let a: f64 = mu * d_over_h;
            let first = 1.0 + a / 3.0;
            for law in [Friction::CoulombEq3, Friction::Siebel, Friction::Tresca] {
                let f = family::friction_factor(law, mu, d_over_h);
                assert!(
                    (f - first).abs() <= a * a / 12.0 * 1.1 + 1e-12,
                    "{law:?} μ {mu} d/h {d_over_h}: {f} against {first}"
                );
            }
            let eq3 = family::friction_factor(Friction::CoulombEq3, mu, d_over_h);
            assert!(eq3 - first >= a * a / 12.0 * 0.9, "eq. 3's second-order term: {eq3}");
        }
    }
}

/// The Hertz contact in series with a spring: the solved load's two compressions add up to
/// the given one.
#[test]
fn the_hertz_series_load_solves_its_equation() {
    for (k_h, k_s, delta) in [(1e15, 6e9, 1e-4), (1e14, 2e9, 3e-3), (1e16, 3e10, 1e-6)] {
        let f = family::hertz_series_load(k_h, k_s, delta);
        let back = f / k_s + family::hertz_delta(k_h, f);
        assert!((back / delta - 1.0).abs() < 1e-9, "{k_h} {k_s} {delta}: {back}");
    }
}

/// The drawn machines and effects lie in the ranges `independent::drawn` states, on both seed
/// sets, and their files parse.
#[test]
fn the_drawn_machines_lie_in_the_stated_ranges() {
    let within = |x: f64, (lo, hi): (f64, f64)| x >= lo * (1.0 - 1e-9) && x <= hi * (1.0 + 1e-9);
    for first in [drawn::TUNE, drawn::REPORT] {
        for s in first..first + 50 {
            for kind in KINDS {
                let m = drawn::draw(kind, s);
                let mf = &m.file.machine;
                match mf {
                    forgemon::physics::machine::Machine::Hammer(h) => {
                        assert!(within(h.m1_kg, drawn::M1_KG), "{}", m.toml);
                        assert!(within(h.m2_kg / h.m1_kg, drawn::DIE_RATIO), "{}", m.toml);
                        assert!(within(h.k_n_per_m / 2.6e9, drawn::SPREAD), "{}", m.toml);
                    }
                    forgemon::physics::machine::Machine::ScrewPress(p) => {
                        assert!(within(p.m_ram_kg, drawn::M_RAM_KG), "{}", m.toml);
                        assert!(within(p.m_tool_kg / p.m_ram_kg, drawn::TOOL_RATIO), "{}", m.toml);
                        assert!(within(p.k_link_n_per_m / 2.1e9, drawn::SPREAD), "{}", m.toml);
                        assert!(within(p.k_frame_n_per_m / 8.0e9, drawn::SPREAD), "{}", m.toml);
                        assert!(within(p.k_sensor_n_per_m / 3.39e10, drawn::SPREAD), "{}", m.toml);
                    }
                }
                assert_ne!(
                    m.file.effect_set().load_filter,
                    forgemon::physics::load_filter::LoadFilter::None,
                    "the [daq] block"
                );
                for e in EFFECTS {
                    let ok = match drawn::effect(&m, e, s) {
                        Hidden::None => e == "none",
                        Hidden::Clearance { gap_m, die_kg } => {
                            within(gap_m, drawn::GAP_M)
                                && (kind == Kind::Hammer && die_kg == 0.0
                                    || within(die_kg / m.m_upper_kg, drawn::CLEARANCE_DIE_RATIO))
                        }
                        Hidden::Compliant { k_n_per_m } => {
                            within(k_n_per_m / m.k_support_n_per_m, drawn::CONTACT_RATIO)
                        }
                        Hidden::FrictionRise { p } => within(p, drawn::FRICTION_EXPONENT),
                        Hidden::StrainRate { m, rate_ref_per_s } => within(m, drawn::RATE_M) && rate_ref_per_s == 25.0,
                        Hidden::Foundation { k_n_per_m, .. } => {
                            within(k_n_per_m / m.k_support_n_per_m, drawn::FOUNDATION_K_RATIO)
                        }
                        _ => false,
                    };
                    assert!(ok, "seed {s} {kind:?} {e}: {:?}", drawn::effect(&m, e, s));
                }
            }
        }
    }
}

/// The scaling rule of `independent::drawn` forges sensibly on drawn machines: every blow of a
/// calibration billet a visible reduction (≥ 4 % of the start height, 15× the caliper's ±0.2 mm
/// on the smallest billet drawn here) and after five blows at least a third of the height left.
/// The project segments and localises each blow (`drawn::billet` fails otherwise).
#[test]
fn the_drawn_blows_forge_sensibly() {
    let r = RENDERERS[0];
    for s in 0..8 {
        for kind in KINDS {
            let m: Drawn = drawn::draw(kind, drawn::REPORT + s);
            let b = drawn::billet(&m, r, &Hidden::None, &speeds(kind).0, 1.0, 1)
                .unwrap_or_else(|e| panic!("{e}\n{}", m.toml));
            let h0 = m.process().billet.height_m;
            let mut before = h0;
            for h in &b.heights_m {
                assert!(before - h >= 0.04 * h0, "seed {s} {kind:?}: {:?} from {h0}", b.heights_m);
                before = *h;
            }
            assert!(before >= h0 / 3.0, "seed {s} {kind:?}: {:?} from {h0}", b.heights_m);
        }
    }
}

/// The report seed of the diagnosis cases' machines and noise.
const CASE_SEED: u64 = drawn::REPORT;

/// Diagnose `renderer`'s blows of `hidden` (from the machine) on machine `kind` drawn for
/// `CASE_SEED`, and assert the verdict names `expected`. The machine file with its `[daq]`
/// filter, as `forgemon diagnose` takes it.
fn diagnosed(
    renderer: Renderer,
    kind: Kind,
    hidden: impl Fn(&Drawn) -> Hidden,
    expected: &str,
) -> forgemon::diagnose::Diagnosis {
    let t = std::time::Instant::now();
    let m = drawn::draw(kind, CASE_SEED);
    let h = hidden(&m);
    let c = drawn::case_with(renderer, m, h, CASE_SEED).unwrap_or_else(|e| panic!("{e}"));
    let d = forgemon::diagnose::diagnose(
        &c.machine.file.machine,
        &c.machine.file.effect_set(),
        (c.calib.refs, c.calib.setting),
        (c.holdout.refs, c.holdout.setting),
        &|| {},
    )
    .expect("the base model simulates the blows");
    let v = verdict_of(&d);
    let what = format!(
        "{} {kind:?} {h:?} seed {CASE_SEED}: verdict {v}, own shrink {:.2}, strength {:.1}, {:.1} s",
        renderer.name(),
        own_shrink(&d, expected),
        strength(&d),
        t.elapsed().as_secs_f64()
    );
    let best: Vec<String> = d
        .candidates
        .iter()
        .take(3)
        .map(|f| format!("{} {:.2}", f.name, 1.0 - f.holdout / d.baseline_holdout))
        .collect();
    eprintln!("DIAGNOSED {what}; best shrinks {best:?}; {}", d.why);
    assert!(if expected == "none" { v == "none" } else { names(&v, expected) }, "{what}");
    d
}

/// A clear compliant contact: half the support's stiffness in series.
fn compliant(m: &Drawn) -> Hidden {
    Hidden::Compliant { k_n_per_m: 0.5 * m.k_support_n_per_m }
}

/// The press clearance: 0.3 mm under a lower die of a quarter of the tool's mass.
fn clearance(m: &Drawn) -> Hidden {
    Hidden::Clearance { gap_m: 0.3e-3, die_kg: 0.25 * m.m_upper_kg }
}

#[test]
fn rigid_eq3_hammer_none_is_none() {
    diagnosed(RENDERERS[0], Kind::Hammer, |_| Hidden::None, "none");
}

#[test]
fn rigid_eq3_press_clearance_is_clearance() {
    diagnosed(RENDERERS[0], Kind::Press, clearance, "clearance");
}

/// Siebel's law is eq. 3 to first order; at the fifth blow's d/h ≈ 1.5 (A = μ d/h ≈ 0.08 on
/// copper, 0.3 on steel) the second-order term A²/12 is a load difference of up to 0.75 %.
#[test]
fn elastic_siebel_press_none_is_none() {
    diagnosed(RENDERERS[1], Kind::Press, |_| Hidden::None, "none");
}

#[test]
fn elastic_siebel_press_compliant_is_elastic_recovery() {
    diagnosed(RENDERERS[1], Kind::Press, compliant, "elastic_recovery");
}

/// The Tresca law's gap from eq. 3 (strength 5.0) was met by `strain_rate` at its exponent's
/// floor, a flow-stress level ("uncertain between strain_rate and none", agreement 0.47) until
/// the verdict took such a level as a rival rather than an effect.
#[test]
fn hertz_tresca_hammer_none_is_none() {
    diagnosed(RENDERERS[2], Kind::Hammer, |_| Hidden::None, "none");
}

#[test]
fn hertz_tresca_press_compliant_is_elastic_recovery() {
    diagnosed(RENDERERS[2], Kind::Press, compliant, "elastic_recovery");
}

#[test]
// Ignored until the press's lower die was scanned finely at the closure's gaps
// (src/diagnose/attribute.rs `closure_points`, chosen on tune seeds 4100–4105): it gave none
// (clearance shrinking 0.14), now clearance.
fn hertz_tresca_press_clearance_is_clearance() {
    diagnosed(RENDERERS[2], Kind::Press, clearance, "clearance");
}

/// The press clearance on the elastic billet, which throws the loose die ahead of
/// the tool. With the rigid die contact alone, the family's tune seeds 4102 and 4111 were
/// uncertain on this renderer; the die's contact is a parameter of the press's clearance
/// since (`k_die_contact_N_per_m`, set on tune seeds 4100–4119).
#[test]
fn elastic_siebel_press_clearance_is_clearance() {
    diagnosed(RENDERERS[1], Kind::Press, clearance, "clearance");
}

/// A foundation at the foot of the family's damping (ζ = 0.01, `drawn::FOUNDATION_ZETA`),
/// a fifth of the ram's mass on four times the support's stiffness, a weak effect (strength
/// 2.8): it rings through the whole blow, in a valley of its frequency far narrower than the
/// coarse grid's step. Before the foundation's ring scan (src/diagnose/attribute.rs
/// `RING_ZETAS`, set on tune seed 4127) the verdict was uncertain (foundation's holdout
/// shrink 0.24); with it, foundation (0.47), its frequency within 0.1 %.
#[test]
fn rigid_eq3_press_lightly_damped_foundation_is_foundation() {
    let light = |m: &Drawn| {
        let (m_kg, k) = (0.2 * m.m_ram_kg.expect("a press"), 4.0 * m.k_support_n_per_m);
        Hidden::Foundation { m_kg, k_n_per_m: k, c_ns_per_m: 2.0 * 0.01 * (k * m_kg).sqrt() }
    };
    let d = diagnosed(RENDERERS[0], Kind::Press, light, "foundation");
    let hidden = light(&drawn::draw(Kind::Press, CASE_SEED));
    let Hidden::Foundation { m_kg, k_n_per_m, .. } = hidden else { unreachable!() };
    let fitted = d.verdict.as_ref().and_then(|v| {
        v.effects.iter().find_map(|e| match e {
            forgemon::physics::effects::Effect::Foundation { m3_kg, k3_n_per_m, .. } => Some((*m3_kg, *k3_n_per_m)),
            _ => None,
        })
    });
    let (m3, k3) = fitted.expect("the verdict's foundation");
    // Its ring's frequency within 3 %: the ring scan's step is 1 %, and a ring 3 % off is a
    // quarter period out of phase after eight periods.
    let (f_fit, f_hidden) = ((k3 / m3).sqrt(), (k_n_per_m / m_kg).sqrt());
    assert!((f_fit / f_hidden - 1.0).abs() < 0.03, "fitted {m3:.0} kg on {k3:.3e} N/m, hidden {hidden:?}");
}
