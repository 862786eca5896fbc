//! A family of independent renderers (issue 41): the billet's contact and its friction law
//! each chosen apart, so that the diagnosis is judged on data whose contact idea is not the
//! one renderer `super` has (and not the library's either).
//!
//! Contact laws (`Contact`):
//! - `RigidPlastic`, as the papers have it: the billet pushes with its yield load while the
//!   tools close; once they stop closing it is rigid, and the contact force is the constraint
//!   force that keeps the tools' relative acceleration zero, while that lies in [0, Fy]; below
//!   0 they separate, above Fy the billet flows again (Moreau's time stepping: the force is
//!   solved per step on the velocities, not a penalty spring).
//! - `ElasticPlastic`: `super`'s law, a stiff spring (`K_BILLET_STIFF`) capped at the yield
//!   load by return mapping.
//! - `HertzSeries`: a Hertz contact F = k_h δ^{3/2} in series with the plastic flow, capped at
//!   the yield load; k_h puts its tangent stiffness at the billet's typical load at
//!   `K_BILLET_STIFF` (stiff against the machines' 1e9–3e10 N/m springs).
//!
//! A hidden compliant contact (`Hidden::Compliant`, the library's `elastic_recovery`) is a
//! linear spring in series for the rigid and elastic laws, and sets k_h's tangent stiffness
//! at the typical load for the Hertz law.
//!
//! Friction laws for the yield load (`Friction`), each a factor on π r² σ:
//! - `CoulombEq3`: the hammer paper's eq. 3, 2/A ((e^A − 1)/A − 1), A = μ d/h (`super`'s);
//! - `Siebel`: 1 + μ d/(3h);
//! - `Tresca`: 1 + m d/(3√3 h), with m = √3 μ (μ p̄ = m σ/√3 at p̄ = σ), so all three agree to
//!   first order in d/h; this closed form then equals Siebel's, and the Tresca renderer
//!   differs from the Siebel one by its contact law.
//!
//! Integrator: semi-implicit (symplectic) Euler at `FINE` steps per DAQ sample, not `super`'s
//! velocity Verlet and not the library's adaptive Dormand–Prince.

use super::{FINE, G, Hidden, K_BILLET_STIFF, Kind, Rig, frictionless_load};
use forgemon::physics::process::Process;

/// The billet's contact law.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Contact {
    RigidPlastic,
    ElasticPlastic,
    HertzSeries,
}

/// The friction law of the yield load.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Friction {
    CoulombEq3,
    Siebel,
    Tresca,
}

/// One renderer of the family: a contact law with a friction law.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Renderer {
    pub contact: Contact,
    pub friction: Friction,
}

/// The three named renderers of issue 41.
pub const RENDERERS: [Renderer; 3] = [
    Renderer { contact: Contact::RigidPlastic, friction: Friction::CoulombEq3 },
    Renderer { contact: Contact::ElasticPlastic, friction: Friction::Siebel },
    Renderer { contact: Contact::HertzSeries, friction: Friction::Tresca },
];

impl Renderer {
    /// `rigid-eq3`, `elastic-siebel`, `hertz-tresca`, …
    pub fn name(&self) -> String {
        let c = match self.contact {
            Contact::RigidPlastic => "rigid",
            Contact::ElasticPlastic => "elastic",
            Contact::HertzSeries => "hertz",
        };
        let f = match self.friction {
            Friction::CoulombEq3 => "eq3",
            Friction::Siebel => "siebel",
            Friction::Tresca => "tresca",
        };
        format!("{c}-{f}")
    }

    /// Any of the nine combinations by `name`.
    pub fn parse(name: &str) -> Option<Renderer> {
        let (c, f) = name.split_once('-')?;
        let contact = match c {
            "rigid" => Contact::RigidPlastic,
            "elastic" => Contact::ElasticPlastic,
            "hertz" => Contact::HertzSeries,
            _ => return None,
        };
        let friction = match f {
            "eq3" => Friction::CoulombEq3,
            "siebel" => Friction::Siebel,
            "tresca" => Friction::Tresca,
            _ => return None,
        };
        Some(Renderer { contact, friction })
    }
}

/// The friction factor of `law` on π r² σ, for Coulomb's μ (Tresca's m = √3 μ) and the
/// billet's `d_over_h`.
pub fn friction_factor(law: Friction, mu: f64, d_over_h: f64) -> f64 {
    match law {
        Friction::CoulombEq3 => {
            let a = (mu * d_over_h).max(1e-6);
            2.0 / a * ((a.exp() - 1.0) / a - 1.0)
        }
        Friction::Siebel => 1.0 + mu * d_over_h / 3.0,
        Friction::Tresca => {
            let m = (3f64.sqrt() * mu).min(1.0);
            1.0 + m * d_over_h / (3.0 * 3f64.sqrt())
        }
    }
}

/// The billet's yield load at height `h_m` and strain rate under `law`, with the hidden
/// effects on the flow stress (`super::frictionless_load`) and on friction.
pub fn yield_load(law: Friction, process: &Process, hidden: &Hidden, h_m: f64, rate_per_s: f64) -> f64 {
    let g = &process.billet;
    let d = g.diameter_m * (g.height_m / h_m).sqrt();
    let mut mu = process.friction;
    if let Hidden::FrictionRise { p } = *hidden {
        mu *= (g.height_m / h_m).powf(p);
    }
    frictionless_load(process, hidden, h_m, rate_per_s) * friction_factor(law, mu, d / h_m)
}

/// One blow at the fine step.
pub struct FamilyBlow {
    /// The sensor's load, the ram's position and acceleration (as `super::Fine`).
    pub load_n: Vec<f64>,
    pub ram_m: Vec<f64>,
    pub ram_acc: Vec<f64>,
    /// The billet's force and its yield load at each step, N.
    pub billet_n: Vec<f64>,
    pub yield_n: Vec<f64>,
    pub h_end_m: f64,
    /// The frictionless part of the yield load over the plastic compression, J.
    pub plastic_j: f64,
    /// Fine steps before contact.
    pub pre: usize,
}

/// Before contact, s (as `super::PRE_S`).
pub const PRE_S: f64 = 0.02;
/// At least this long after contact, s, and at least twice the contact's duration: a blow on
/// a large drawn machine lasts longer than the fixed rigs' 30 ms (`super::POST_S`).
pub const POST_MIN_S: f64 = 0.03;
/// The longest record after contact, s.
const POST_MAX_S: f64 = 0.4;

/// The typical load the Hertz contact's stiffness is set at: the yield load at 10 %
/// reduction of the sheet's billet, at 10 /s.
fn typical_load_n(law: Friction, process: &Process) -> f64 {
    yield_load(law, process, &Hidden::None, 0.9 * process.billet.height_m, 10.0)
}

/// k_h whose tangent stiffness 1.5 k_h^{2/3} F^{1/3} is `k_tangent` at load `f`.
fn hertz_k(k_tangent: f64, f: f64) -> f64 {
    (k_tangent / (1.5 * f.cbrt())).powf(1.5)
}

/// The load F of a Hertz contact `k_h` in series with a linear spring `k_s` compressed by
/// `delta` together: F/k_s + (F/k_h)^{2/3} = δ (Newton on u = F^{1/3}, from an upper bound).
pub fn hertz_series_load(k_h: f64, k_s: f64, delta: f64) -> f64 {
    if delta <= 0.0 {
        return 0.0;
    }
    let kh23 = k_h.powf(2.0 / 3.0);
    let mut u = (k_s * delta).cbrt().min(delta.sqrt() * k_h.cbrt());
    for _ in 0..50 {
        let g = u * u * u / k_s + u * u / kh23 - delta;
        let dg = 3.0 * u * u / k_s + 2.0 * u / kh23;
        let step = g / dg;
        u -= step;
        if step.abs() <= 1e-13 * u.abs() {
            break;
        }
    }
    u * u * u
}

/// The elastic compression of a Hertz contact at load `f`.
pub fn hertz_delta(k_h: f64, f: f64) -> f64 {
    (f / k_h).powf(2.0 / 3.0)
}

/// Integrate one blow of `renderer` on `rig` from contact at `v0` on a billet of height
/// `h0`: `PRE_S` before contact to at least `POST_MIN_S` after it.
pub(super) fn blow(rig: &Rig, renderer: Renderer, process: &Process, hidden: &Hidden, v0: f64, h0: f64) -> FamilyBlow {
    let dt = 1.0 / (rig.sample_rate_hz * FINE as f64);
    let law = renderer.friction;
    let compliant = match hidden {
        Hidden::Compliant { k_n_per_m } => Some(*k_n_per_m),
        _ => None,
    };
    // The contact as integrated: a linear spring (rigid with a compliant layer, elastic), a
    // Hertz contact, or the rigid constraint.
    enum Law {
        Spring(f64),
        Hertz(f64),
        Rigid,
    }
    let f_typ = typical_load_n(law, process);
    let contact = match (renderer.contact, compliant) {
        (Contact::RigidPlastic, None) => Law::Rigid,
        (Contact::RigidPlastic | Contact::ElasticPlastic, Some(k)) => Law::Spring(k),
        (Contact::ElasticPlastic, None) => Law::Spring(K_BILLET_STIFF),
        (Contact::HertzSeries, k) => Law::Hertz(hertz_k(k.unwrap_or(K_BILLET_STIFF), f_typ)),
    };
    let gap = hidden.gap_m();
    let foundation = hidden.foundation();
    let massless = rig.m_lower == 0.0;
    let gravity = if rig.kind == Kind::Hammer { G } else { 0.0 };
    let pre = (PRE_S / dt).round() as usize;
    let t0 = -(pre as f64) * dt;
    // Positions down, zero at first contact; the ram (and the press's heavy mass) fall or are
    // driven onto the billet.
    let (mut xu, mut vu) = (v0 * t0 + 0.5 * gravity * t0 * t0, v0 + gravity * t0);
    let (mut xr, mut vr) = (xu, vu);
    let (mut xl, mut vl, mut x3, mut v3, mut p) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut rate: f64 = 0.0;
    let mut out = FamilyBlow {
        load_n: Vec::new(),
        ram_m: Vec::new(),
        ram_acc: Vec::new(),
        billet_n: Vec::new(),
        yield_n: Vec::new(),
        h_end_m: h0,
        plastic_j: 0.0,
        pre,
    };
    let die_caught_up = rig.kind == Kind::Hammer && !massless && gap == 0.0;
    let mut g_now = gravity;
    let mut f_hertz = 0.0;
    let mut last_contact = 0usize;
    let max_steps = pre + (POST_MAX_S / dt) as usize;
    for step in 0..max_steps {
        if step == pre {
            // From contact, eq. 1: no weight on the ram; the die caught up (`super::blow_over`).
            g_now = 0.0;
            if die_caught_up {
                vl = vu;
            }
        }
        let h = h0 - p;
        let fy = yield_load(law, process, hidden, h, rate);
        let link = rig.ram.map_or(0.0, |(_, k, c)| k * (xr - xu) + c * (vr - vu));
        // The support's force on the lower body (with a mass) and on the foundation.
        let f_support = if massless {
            0.0
        } else {
            let e = xl - gap - x3;
            if gap == 0.0 || e > 0.0 { rig.k_support * e + rig.c_support * (vl - v3) } else { 0.0 }
        };
        // The billet's force.
        let x_low = if massless { x3 } else { xl };
        let f_b = match contact {
            Law::Spring(k) => {
                let k_eff = if massless { 1.0 / (1.0 / k + 1.0 / rig.k_support) } else { k };
                (k_eff * (xu - x_low - p)).clamp(0.0, fy)
            }
            Law::Hertz(k_h) => {
                let delta = xu - x_low - p;
                f_hertz = if massless {
                    hertz_series_load(k_h, rig.k_support, delta)
                } else {
                    k_h * delta.max(0.0).powf(1.5)
                };
                f_hertz.min(fy)
            }
            Law::Rigid if massless => (rig.k_support * (xu - x3 - p)).clamp(0.0, fy),
            Law::Rigid => {
                if xu - xl >= p - 1e-12 {
                    // The constraint force that keeps the relative velocity after the step at
                    // zero; within [0, Fy] it holds, above Fy the billet flows at Fy, below 0 the
                    // tools part.
                    let au_free = link / rig.m_upper + g_now;
                    let al_free = -f_support / rig.m_lower;
                    let vrel = (vu + dt * au_free) - (vl + dt * al_free);
                    let f0 = vrel / (dt * (1.0 / rig.m_upper + 1.0 / rig.m_lower));
                    f0.clamp(0.0, fy)
                } else {
                    0.0
                }
            }
        };
        let f_sensor = if massless { f_b } else { f_support };
        let au = (link - f_b) / rig.m_upper + g_now;
        let ar = rig.ram.map_or(0.0, |(m, _, _)| -link / m);
        let al = if massless { 0.0 } else { (f_b - f_support) / rig.m_lower };
        let a3 = foundation.map_or(0.0, |(m, k, c)| (f_sensor - k * x3 - c * v3) / m);
        // Semi-implicit Euler: velocities, then positions with the new velocities.
        vu += dt * au;
        vr += dt * ar;
        vl += dt * al;
        v3 += dt * a3;
        xu += dt * vu;
        xr += dt * vr;
        xl += dt * vl;
        x3 += dt * v3;
        // Plastic flow: the compression beyond what the contact holds elastically at Fy.
        let x_low = if massless { x3 } else { xl };
        let p_new = match contact {
            Law::Spring(k) => {
                let k_eff = if massless { 1.0 / (1.0 / k + 1.0 / rig.k_support) } else { k };
                if k_eff * (xu - x_low - p) > fy { xu - x_low - fy / k_eff } else { p }
            }
            Law::Hertz(k_h) => {
                let elastic = hertz_delta(k_h, fy) + if massless { fy / rig.k_support } else { 0.0 };
                if xu - x_low - p > elastic { xu - x_low - elastic } else { p }
            }
            Law::Rigid if massless => {
                if rig.k_support * (xu - x3 - p) > fy {
                    xu - x3 - fy / rig.k_support
                } else {
                    p
                }
            }
            Law::Rigid => p.max(xu - xl),
        };
        if p_new > p {
            let h_mid = h0 - 0.5 * (p + p_new);
            out.plastic_j += frictionless_load(process, hidden, h_mid, rate) * (p_new - p);
            p = p_new;
        }
        let v_low = if massless { v3 } else { vl };
        rate = (vu - v_low).max(0.0) / (h0 - p);
        out.load_n.push(f_sensor);
        let (x_ram, a_ram) = if rig.ram.is_some() { (xr, ar) } else { (xu, au) };
        out.ram_m.push(x_ram);
        out.ram_acc.push(a_ram);
        out.billet_n.push(f_b);
        out.yield_n.push(fy);
        if f_b > 0.0 || f_hertz > 0.0 {
            last_contact = step;
        }
        // The record ends twice the contact's length after contact, and not before `POST_MIN_S`.
        let after = step.saturating_sub(pre);
        if step > pre && after as f64 * dt >= POST_MIN_S && after >= 2 * last_contact.saturating_sub(pre) {
            break;
        }
    }
    out.h_end_m = h0 - p;
    out
}

/// `super`'s own renderer (elastic-plastic, eq. 3, velocity Verlet) on its fixed rig: the
/// final height and plastic energy of one blow, to compare the family's integrator with;
/// recorded to `post_s` after contact (`super::blow`'s 30 ms end a press blow mid-forming:
/// the fixed press's blows last 57–59 ms).
pub fn existing_blow(kind: Kind, process: &Process, v0: f64, h0: f64, post_s: f64) -> (f64, f64) {
    let fine = super::blow_over(&Rig::new(kind, &Hidden::None), process, &Hidden::None, v0, h0, PRE_S, post_s);
    (fine.h_end_m, fine.plastic_j)
}
