//! An independent renderer of forging blows (issue #17, "Independent test data"): test-only
//! code that shares no physics with what `forgemon diagnose` fits.
//!
//! - **Contact law**: the billet is elastic-plastic, a stiff spring capped at its yield load
//!   (return mapping each step), not the library's rigid-plastic billet with its hybrid
//!   phases. The yield load is the hammer paper's eq. 3 (written out here, closed form), r
//!   from volume constancy.
//! - **The machine is the papers'**: the hammer paper's model (seed 000 §2.3.1, eqs. 1–2)
//!   assigns the impact speed to the ram and to the lower tool (the clearances caught up
//!   before forming); so does this renderer, and its ram feels no weight from first contact
//!   (eq. 1). A die left at rest here, as this renderer once did, is a clearance that has not
//!   been caught up: the library's base model then met a first peak 2.5× the rendered one.
//! - **Integrator**: velocity Verlet at a fixed fine step (100 per DAQ sample), not
//!   `forgemon::physics`' adaptive Dormand–Prince with located events. The ram falls under
//!   gravity until it touches.
//! - **DAQ chain**: two cascaded second-order Butterworth low-passes at 0.4 × the sample
//!   rate (bilinear transform, written here), decimation, a 16-bit load ADC over ±4 MN,
//!   Gaussian noise, a 10 µm encoder, a noisy accelerometer on the ram.
//! - **Heights**: measured by hand after each blow with ±0.2 mm of caliper noise (uniform;
//!   they need not be monotone).
//! - **Hidden effects** off the library's fixed values: a strain-rate law with its reference
//!   rate at 25 /s (the library holds 10 /s), a damped foundation (the library holds its
//!   damper at 0), a friction rise, a clearance, a compliant contact.
//!
//! What it does share, stated: the material's flow-stress curve is the process sheet's
//! (`FlowStress::sigma_pa`, the sheet's data, not a law the diagnosis fits), and the
//! captures enter through the project's segmenter and `localise::reference`, as a real
//! capture directory would.

#![allow(dead_code)]

pub mod captures;
pub mod drawn;
pub mod family;
pub mod verdict;

use forgemon::config::{parse_machine, parse_process};
use forgemon::identify::objective::{Reference, Setting};
use forgemon::physics::machine::Machine;
use forgemon::physics::process::Process;
use forgemon::signal::capture::CaptureRow;
use forgemon::signal::segment::{SegmentConfig, Segmenter};
use forgemon::synth::rows_batch;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

/// The machine files the tests hand the project: the model without the hidden effect, and
/// the DAQ's anti-alias filter from its data sheet (`daq`, the renderer's own two
/// Butterworths at 0.4 × the rate).
pub const HAMMER: &str = "kind = \"hammer\"\nm1_kg = 910\nm2_kg = 26\nk_N_per_m = 2.6e9\nc_Ns_per_m = 24000\n\
    \n[daq]\nload_filter = \"butterworth\"\norder = 2\ncascade = 2\ncutoff = 0.4\n";
pub const PRESS: &str = "kind = \"screw_press\"\nm_tool_kg = 2500\nm_ram_kg = 90000\nk_link_N_per_m = 2.1e9\n\
    c_link_Ns_per_m = 2.8e5\nk_frame_N_per_m = 8.0e9\nc_frame_Ns_per_m = 5.0e4\nk_sensor_N_per_m = 3.39e10\n\
    \n[daq]\nload_filter = \"butterworth\"\norder = 2\ncascade = 2\ncutoff = 0.4\n";
const STEEL: &str = include_str!("../../config/steel-16NiCrMo13.process.toml");
const COPPER: &str = include_str!("../../config/copper-cu99.process.toml");

/// Standard gravity, m/s².
const G: f64 = 9.80665;
/// Fine steps per DAQ sample.
const FINE: usize = 100;
/// The billet's own elastic stiffness when no compliant contact is hidden, N/m: stiff
/// against the machines' springs (2.6e9 and 6.5e9), so the base model's rigid billet is
/// within 1 % of it in series.
const K_BILLET_STIFF: f64 = 1e12;
/// Load ADC: 16 bits over ±4 MN.
const ADC_LSB_N: f64 = 8e6 / 65536.0;
const ENCODER_STEP_M: f64 = 10e-6;
/// Caliper noise on the hand-measured heights, ± m (uniform).
const CALIPER_M: f64 = 0.2e-3;
/// Approach recorded before contact, and the record after it, s.
const PRE_S: f64 = 0.02;
const POST_S: f64 = 0.03;

/// Which machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Hammer,
    Press,
}

/// A hidden effect with its parameters (all off the library's fixed values where it has
/// any).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Hidden {
    None,
    /// Gap under the lower tool, m; on the press a lower die of `die_kg` crosses it.
    Clearance {
        gap_m: f64,
        die_kg: f64,
    },
    /// The billet's contact stiffness, N/m.
    Compliant {
        k_n_per_m: f64,
    },
    /// μ = μ0 (h0/h)^p.
    FrictionRise {
        p: f64,
    },
    /// σ (ε̇/ε̇₀)^m.
    StrainRate {
        m: f64,
        rate_ref_per_s: f64,
    },
    /// A damped foundation under the frame spring (hammer) or the sensor chain (press).
    Foundation {
        m_kg: f64,
        k_n_per_m: f64,
        c_ns_per_m: f64,
    },
    /// σ (ε/ε₀)^n.
    Hardening {
        n: f64,
        eps_ref: f64,
    },
    /// σ exp(q (i − 1)) on blow i: the billet cools (`captures::render` only).
    Thermal {
        q: f64,
    },
    /// The load sensor's charge amplifier: a first-order high-pass of time constant τ on the
    /// sensor's force (`captures::render` only).
    Highpass {
        tau_s: f64,
    },
}

impl Hidden {
    /// The clearance's gap, m (0 without one).
    pub fn gap_m(&self) -> f64 {
        match self {
            Hidden::Clearance { gap_m, .. } => *gap_m,
            _ => 0.0,
        }
    }

    /// The foundation's mass, spring and damper, if one is hidden.
    pub fn foundation(&self) -> Option<(f64, f64, f64)> {
        match *self {
            Hidden::Foundation { m_kg, k_n_per_m, c_ns_per_m } => Some((m_kg, k_n_per_m, c_ns_per_m)),
            _ => None,
        }
    }

    /// The library's name of the effect this stands for.
    pub fn library_name(&self) -> &'static str {
        match self {
            Hidden::None => "none",
            Hidden::Clearance { .. } => "clearance",
            Hidden::Compliant { .. } => "elastic_recovery",
            Hidden::FrictionRise { .. } => "friction_rise",
            Hidden::StrainRate { .. } => "strain_rate",
            Hidden::Foundation { .. } => "foundation",
            Hidden::Hardening { .. } => "strain_hardening",
            Hidden::Thermal { .. } => "thermal",
            Hidden::Highpass { .. } => "sensor_highpass",
        }
    }
}

/// The machine's parameters as the renderer uses them.
#[derive(Debug, Clone)]
struct Rig {
    kind: Kind,
    /// Upper body (hammer ram, press tool), kg.
    m_upper: f64,
    /// Press ram behind the link, kg, link N/m and N s/m.
    ram: Option<(f64, f64, f64)>,
    /// Lower body: mass, kg (hammer die, press die under a clearance; 0: massless chain).
    m_lower: f64,
    /// Support of the lower body: N/m and N s/m.
    k_support: f64,
    c_support: f64,
    sample_rate_hz: f64,
    load_sd_n: f64,
    acc_sd_mps2: f64,
}

impl Rig {
    fn new(kind: Kind, hidden: &Hidden) -> Rig {
        match kind {
            Kind::Hammer => Rig {
                kind,
                m_upper: 910.0,
                ram: None,
                m_lower: 26.0,
                k_support: 2.6e9,
                c_support: 24000.0,
                sample_rate_hz: 100e3,
                load_sd_n: 2e3,
                acc_sd_mps2: 2.0,
            },
            Kind::Press => Rig {
                kind,
                m_upper: 2500.0,
                ram: Some((90000.0, 2.1e9, 2.8e5)),
                m_lower: match hidden {
                    Hidden::Clearance { die_kg, .. } => *die_kg,
                    _ => 0.0,
                },
                // Sensor and frame in series; the frame's damper (a 1.2 µs time constant)
                // is left out, as the library folds it too.
                k_support: 1.0 / (1.0 / 3.39e10 + 1.0 / 8.0e9),
                c_support: 0.0,
                sample_rate_hz: 20e3,
                load_sd_n: 5e3,
                acc_sd_mps2: 0.05,
            },
        }
    }
}

/// The state of the fine integration. Positions down, from first contact's instant.
#[derive(Debug, Clone, Copy, Default)]
struct State {
    xu: f64,
    vu: f64,
    xr: f64,
    vr: f64,
    xl: f64,
    vl: f64,
    x3: f64,
    v3: f64,
    /// Plastic compression of the billet, m.
    p: f64,
}

/// One blow's truth at the fine step: time, sensor load, ram position and acceleration.
struct Fine {
    load_n: Vec<f64>,
    ram_m: Vec<f64>,
    ram_acc: Vec<f64>,
    h_end_m: f64,
    /// The work of the frictionless part of the yield load over the plastic compression, J
    /// (docs/interfaces.md §4's plastic energy).
    plastic_j: f64,
}

/// The billet's yield load at height `h_m` (plastic compression `p` from `h_start`) and
/// strain rate, with the hidden load effects.
fn yield_load(process: &Process, hidden: &Hidden, h_m: f64, rate_per_s: f64) -> f64 {
    let g = &process.billet;
    let r_sq = (0.5 * g.diameter_m).powi(2) * g.height_m / h_m;
    let eps = (g.height_m / h_m).ln();
    let rate = rate_per_s.max(1e-3);
    let mut sigma = process.material.sigma_pa(eps, rate);
    let mut mu = process.friction;
    match *hidden {
        Hidden::FrictionRise { p } => mu *= (g.height_m / h_m).powf(p),
        Hidden::StrainRate { m, rate_ref_per_s } => sigma *= (rate / rate_ref_per_s).powf(m),
        Hidden::Hardening { n, eps_ref } => sigma *= (eps.max(1e-4) / eps_ref).powf(n),
        _ => {}
    }
    // The hammer paper's eq. 3, F = π r h σ/μ ((e^A − 1)/A − 1), A = 2μr/h, written here as
    // π r² σ times its friction factor 2/A ((e^A − 1)/A − 1) (→ 1 + A/3 for small A, Siebel's
    // approximation, which is 2 % low at the hammer's flattest billets, A ≈ 0.5, and with the
    // ram's weight made the no-effect hammer look like a flow stress off).
    let a = (2.0 * mu * r_sq.sqrt() / h_m).max(1e-6);
    let factor = 2.0 / a * ((a.exp() - 1.0) / a - 1.0);
    std::f64::consts::PI * r_sq * sigma * factor
}

/// π r² σ at height `h_m`: the yield load without its friction factor.
fn frictionless_load(process: &Process, hidden: &Hidden, h_m: f64, rate_per_s: f64) -> f64 {
    let g = &process.billet;
    let r_sq = (0.5 * g.diameter_m).powi(2) * g.height_m / h_m;
    let eps = (g.height_m / h_m).ln();
    let rate = rate_per_s.max(1e-3);
    let mut sigma = process.material.sigma_pa(eps, rate);
    match *hidden {
        Hidden::StrainRate { m, rate_ref_per_s } => sigma *= (rate / rate_ref_per_s).powf(m),
        Hidden::Hardening { n, eps_ref } => sigma *= (eps.max(1e-4) / eps_ref).powf(n),
        _ => {}
    }
    std::f64::consts::PI * r_sq * sigma
}

/// Integrate one blow from contact at `v0` on a billet of height `h0`, over the window
/// `PRE_S` before contact to `POST_S` after it.
fn blow(rig: &Rig, process: &Process, hidden: &Hidden, v0: f64, h0: f64) -> Fine {
    blow_over(rig, process, hidden, v0, h0, PRE_S, POST_S)
}

/// `blow` over `pre_s` before contact to `post_s` after it.
fn blow_over(rig: &Rig, process: &Process, hidden: &Hidden, v0: f64, h0: f64, pre_s: f64, post_s: f64) -> Fine {
    let dt = 1.0 / (rig.sample_rate_hz * FINE as f64);
    let n = ((post_s + pre_s) / dt) as usize;
    let k_b = match hidden {
        Hidden::Compliant { k_n_per_m } => *k_n_per_m,
        _ => K_BILLET_STIFF,
    };
    let gap = hidden.gap_m();
    let foundation = hidden.foundation();
    let gravity = if rig.kind == Kind::Hammer { G } else { 0.0 };
    let pre = (pre_s / dt).round() as usize;
    // Start `pre_s` before contact, the ram falling (hammer) or driven (press) onto the billet.
    let t0 = -(pre as f64) * dt;
    // x(t) = v0 t + g t²/2, x(0) = 0 at contact: at t0 < 0 the ram is above the billet.
    let mut s = State { vu: v0 + gravity * t0, xu: v0 * t0 + 0.5 * gravity * t0 * t0, ..State::default() };
    s.xr = s.xu;
    s.vr = s.vu;
    let mut rate = 0.0;
    let mut out = Fine {
        load_n: Vec::with_capacity(n),
        ram_m: Vec::with_capacity(n),
        ram_acc: Vec::with_capacity(n),
        h_end_m: h0,
        plastic_j: 0.0,
    };
    let forces = |s: &State, rate: f64, gravity: f64| -> (f64, f64, f64, f64, f64, f64) {
        // Billet force between the upper body and the lower one (or the fixed chain).
        let h = h0 - s.p;
        let fy = yield_load(process, hidden, h, rate);
        let (x_low, massless) = if rig.m_lower > 0.0 { (s.xl, false) } else { (0.0, true) };
        let k_eff = if massless { 1.0 / (1.0 / k_b + 1.0 / rig.k_support) } else { k_b };
        let delta = s.xu - x_low - s.p - if massless { s.x3 } else { 0.0 };
        let f_trial = (k_eff * delta).max(0.0);
        let f_b = f_trial.min(fy);
        // The support's force on the lower body (its sensor).
        let (f_s, f_found) = if massless {
            (f_b, f_b)
        } else {
            let e = s.xl - gap - s.x3;
            // Across a gap the die only bears once it has closed; without one it sits on the
            // support, which holds it either way.
            if gap == 0.0 || e > 0.0 {
                let f = rig.k_support * e + rig.c_support * (s.vl - s.v3);
                (f, f)
            } else {
                (0.0, 0.0)
            }
        };
        let link = rig.ram.map_or(0.0, |(_, k, c)| k * (s.xr - s.xu) + c * (s.vr - s.vu));
        let a_u = (link - f_b) / rig.m_upper + gravity;
        let a_r = rig.ram.map_or(0.0, |(m, _, _)| -link / m);
        let a_l = if massless { 0.0 } else { (f_b - f_s) / rig.m_lower };
        let a_3 = foundation.map_or(0.0, |(m, k, c)| (f_found - k * s.x3 - c * s.v3) / m);
        (f_b, f_s, a_u, a_r, a_l, a_3)
    };
    let mut g_now = gravity;
    let mut acc = forces(&s, rate, g_now);
    // The hammer paper's model (§2.3.1, after eqs. 1–2): "the velocity v0 ... is assigned to
    // mass 1 as well as mass 2"; the clearances of the lower tool-sensor system are caught up
    // before forming starts and bring mass 2 to v0. So at first contact the die moves with the
    // ram, its support unloaded. A hidden clearance is the case where it has not been caught up:
    // the die then starts at rest across the gap (the library's `clearance`).
    let die_caught_up = rig.kind == Kind::Hammer && rig.m_lower > 0.0 && gap == 0.0;
    for step in 0..n {
        if step == pre {
            // From first contact the ram's weight is left out, as eq. 1 (m1 X1'' = F) does:
            // 9 kN against loads of MN, but over a blow its work adds 1–2 % to the energy.
            g_now = 0.0;
            if die_caught_up {
                s.vl = s.vu;
            }
            acc = forces(&s, rate, g_now);
        }
        // Velocity Verlet (the dampers' velocities taken from the half step).
        let (_, _, au, ar, al, a3) = acc;
        s.vu += 0.5 * dt * au;
        s.vr += 0.5 * dt * ar;
        s.vl += 0.5 * dt * al;
        s.v3 += 0.5 * dt * a3;
        s.xu += dt * s.vu;
        s.xr += dt * s.vr;
        s.xl += dt * s.vl;
        s.x3 += dt * s.v3;
        // Return mapping: beyond the yield load the billet flows, so the spring holds it.
        let h = h0 - s.p;
        let fy = yield_load(process, hidden, h, rate);
        let massless = rig.m_lower == 0.0;
        let k_eff = if massless { 1.0 / (1.0 / k_b + 1.0 / rig.k_support) } else { k_b };
        let x_low = if massless { s.x3 } else { s.xl };
        let delta = s.xu - x_low - s.p;
        if k_eff * delta > fy {
            let p_new = s.xu - x_low - fy / k_eff;
            // The plastic energy is the frictionless part of the load, π r² σ, over the
            // compression (docs/interfaces.md §4), taken at the step's mid height.
            let h_mid = h0 - 0.5 * (s.p + p_new);
            out.plastic_j += frictionless_load(process, hidden, h_mid, rate) * (p_new - s.p).max(0.0);
            s.p = p_new;
        }
        // The strain rate from the tools' closing speed (smooth, where the plastic increments
        // of a return mapping flip between steps that flow and steps that do not).
        let v_low = if massless { s.v3 } else { s.vl };
        rate = (s.vu - v_low).max(0.0) / h;
        acc = forces(&s, rate, g_now);
        let (_, f_s, au, ar, al, a3) = acc;
        s.vu += 0.5 * dt * au;
        s.vr += 0.5 * dt * ar;
        s.vl += 0.5 * dt * al;
        s.v3 += 0.5 * dt * a3;
        out.load_n.push(f_s);
        // The encoder and the accelerometer ride on the ram (docs/interfaces.md §1, DESIGN §2.4): the
        // hammer's upper mass, the press's heavy mass behind the link, not its tool.
        let (x_ram, a_ram) = if rig.ram.is_some() { (s.xr, ar) } else { (s.xu, au) };
        out.ram_m.push(x_ram);
        out.ram_acc.push(a_ram);
    }
    out.h_end_m = h0 - s.p;
    out
}

/// A second-order Butterworth low-pass at `fc` for samples every `dt` (bilinear transform,
/// prewarped), run over `x`.
fn butterworth(x: &[f64], fc: f64, dt: f64) -> Vec<f64> {
    let k = (std::f64::consts::PI * fc * dt).tan();
    let q = std::f64::consts::FRAC_1_SQRT_2;
    let norm = 1.0 / (1.0 + k / q + k * k);
    let b0 = k * k * norm;
    let (b1, b2) = (2.0 * b0, b0);
    let a1 = 2.0 * (k * k - 1.0) * norm;
    let a2 = (1.0 - k / q + k * k) * norm;
    let (mut x1, mut x2, mut y1, mut y2) = (x[0], x[0], x[0], x[0]);
    x.iter()
        .map(|&v| {
            let y = b0 * v + b1 * x1 + b2 * x2 - a1 * y1 - a2 * y2;
            (x2, x1, y2, y1) = (x1, v, y1, y);
            y
        })
        .collect()
}

/// The DAQ's view of a fine record: anti-aliased (two cascaded Butterworths at 0.4 × the
/// sample rate), every `FINE`-th sample.
fn daq(x: &[f64], rig: &Rig) -> Vec<f64> {
    let dt = 1.0 / (rig.sample_rate_hz * FINE as f64);
    let fc = 0.4 * rig.sample_rate_hz;
    let y = butterworth(&butterworth(x, fc, dt), fc, dt);
    y.iter().step_by(FINE).copied().collect()
}

/// One billet rendered: its blows as the project reads them, and the process sheet the
/// diagnosis gets (with the hand-measured heights).
pub struct Billet {
    pub refs: Vec<Reference>,
    pub setting: Setting,
    /// The true heights after each blow, m.
    pub heights_m: Vec<f64>,
}

/// The machine file the diagnosis gets (without the hidden effect).
pub fn machine(kind: Kind) -> Machine {
    parse_machine("m", if kind == Kind::Hammer { HAMMER } else { PRESS }).expect("test machine").machine
}

/// Render a billet of `height_scale` × the sheet's height struck at `v0s` on `kind`, with
/// `hidden`; noise from `seed`. Panics if the project refuses a blow (for the CI tests,
/// whose seeds are fixed); the rates harness uses `try_billet`.
pub fn billet(kind: Kind, hidden: &Hidden, v0s: &[f64], height_scale: f64, seed: u64) -> Billet {
    try_billet(kind, hidden, v0s, height_scale, seed).unwrap_or_else(|e| panic!("{e}"))
}

/// `billet`, with the project's refusal of a blow (not segmented, or `localise::reference`'s
/// error) returned as a message naming the blow and the seed.
pub fn try_billet(kind: Kind, hidden: &Hidden, v0s: &[f64], height_scale: f64, seed: u64) -> Result<Billet, String> {
    let rig = Rig::new(kind, hidden);
    let mut process = parse_process("p", if kind == Kind::Hammer { STEEL } else { COPPER }).expect("test sheet");
    process.measured_final_heights_m.clear();
    process.billet.height_m *= height_scale;
    let m = machine(kind);
    read_billet(&rig, &m, process, v0s, ADC_LSB_N, seed, "independent", |p, v0, h| {
        let f = blow(&rig, p, hidden, v0, h);
        (f.load_n, f.ram_m, f.ram_acc, f.h_end_m)
    })
}

/// One billet struck at `v0s`, each blow rendered at the fine step by `render` (the sensor's
/// load, the ram's position and acceleration, and the height after it), through the DAQ
/// (`daq`, a load ADC of `lsb`, the encoder's steps, noise from `seed`), cut by the project's
/// segmenter and read by `localise::reference` as a real capture directory would be. The
/// heights after each blow are measured by caliper (`CALIPER_M`) into the sheet.
#[allow(clippy::too_many_arguments)]
fn read_billet(
    rig: &Rig,
    m: &Machine,
    mut process: Process,
    v0s: &[f64],
    lsb: f64,
    seed: u64,
    source: &str,
    render: impl Fn(&Process, f64, f64) -> (Vec<f64>, Vec<f64>, Vec<f64>, f64),
) -> Result<Billet, String> {
    let mut rng = StdRng::seed_from_u64(seed);
    let load_noise = Normal::new(0.0, rig.load_sd_n).expect("finite sd");
    let acc_noise = Normal::new(0.0, rig.acc_sd_mps2).expect("finite sd");
    let dt = 1.0 / rig.sample_rate_hz;
    let mut h = process.billet.height_m;
    let (mut refs, mut heights, mut measured) = (Vec::new(), Vec::new(), Vec::new());
    for (i, &v0) in v0s.iter().enumerate() {
        let (load_n, ram_m, ram_acc, h_end_m) = render(&process, v0, h);
        let (load, ram, acc) = (daq(&load_n, rig), daq(&ram_m, rig), daq(&ram_acc, rig));
        let offset = rng.random_range(-5e3..5e3);
        let encoder_zero = 0.5 - h;
        let rows: Vec<CaptureRow> = (0..load.len())
            .map(|k| CaptureRow {
                t_s: 100.0 * i as f64 + k as f64 * dt,
                load_n: ((load[k] + offset + load_noise.sample(&mut rng)) / lsb).round() * lsb,
                disp_m: ((encoder_zero + ram[k]) / ENCODER_STEP_M).round() * ENCODER_STEP_M,
                acc_mps2: acc[k] + acc_noise.sample(&mut rng),
            })
            .collect();
        let batch = rows_batch(source, 0, 0, 1e9 / rig.sample_rate_hz, &rows);
        let kind_m = m.kind();
        let cut = Segmenter::cut_all(SegmentConfig::for_kind(kind_m), [&batch]);
        let fit_s = forgemon::estimate::EstimatorConfig::for_kind(kind_m).fit_s;
        let b = cut.first().ok_or_else(|| format!("seed {seed}, blow {}: not segmented", i + 1))?;
        refs.push(
            forgemon::diagnose::localise::reference("b", b, Some(i + 1), fit_s, m)
                .map_err(|e| format!("seed {seed}, blow {}: {e}", i + 1))?,
        );
        h = h_end_m;
        heights.push(h);
        measured.push(h + rng.random_range(-CALIPER_M..=CALIPER_M));
    }
    process.measured_final_heights_m = measured;
    Ok(Billet { refs, setting: Setting::Billet(process), heights_m: heights })
}

/// The speeds of the withheld-effect suite: calibration and holdout billets.
pub fn speeds(kind: Kind) -> ([f64; 5], [f64; 5]) {
    match kind {
        Kind::Hammer => ([4.0, 4.5, 5.0, 5.3, 5.3], [4.2, 4.8, 5.1, 5.3, 5.3]),
        Kind::Press => ([0.30, 0.33, 0.36, 0.36, 0.36], [0.31, 0.34, 0.35, 0.36, 0.36]),
    }
}

/// The cases: one hidden effect each, on either machine.
pub fn cases() -> Vec<(&'static str, Kind, Hidden)> {
    vec![
        ("hammer-none", Kind::Hammer, Hidden::None),
        ("hammer-clearance", Kind::Hammer, Hidden::Clearance { gap_m: 0.25e-3, die_kg: 0.0 }),
        ("hammer-compliant", Kind::Hammer, Hidden::Compliant { k_n_per_m: 2.0e9 }),
        ("hammer-friction", Kind::Hammer, Hidden::FrictionRise { p: 0.8 }),
        ("hammer-rate", Kind::Hammer, Hidden::StrainRate { m: 0.08, rate_ref_per_s: 25.0 }),
        ("hammer-foundation", Kind::Hammer, Hidden::Foundation { m_kg: 1500.0, k_n_per_m: 4e9, c_ns_per_m: 1.5e5 }),
        ("press-none", Kind::Press, Hidden::None),
        ("press-clearance", Kind::Press, Hidden::Clearance { gap_m: 0.25e-3, die_kg: 600.0 }),
        ("press-compliant", Kind::Press, Hidden::Compliant { k_n_per_m: 6.0e9 }),
        ("press-friction", Kind::Press, Hidden::FrictionRise { p: 0.8 }),
        ("press-rate", Kind::Press, Hidden::StrainRate { m: 0.08, rate_ref_per_s: 25.0 }),
        ("press-foundation", Kind::Press, Hidden::Foundation { m_kg: 15000.0, k_n_per_m: 4e9, c_ns_per_m: 2e5 }),
    ]
}
