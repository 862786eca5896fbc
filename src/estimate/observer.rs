//! The identified model run on measured signals (DESIGN.md §2.4): from the zeroed sensor
//! load and the ram's accelerometer (anchored at the fitted impact speed), reconstruct the
//! motions the sensors do not see, and from them each energy term separately, so that their
//! balance is a real model-health check rather than an identity.
//!
//! Hammer: the lower tool's spring and damper carry the sensor load, so `c x2' + k x2 = F_s`
//! is a first-order filter for x2 (solved exactly for a load linear between samples). The
//! billet force is `m2 x2'' + F_s`; its work `∫F (x1' - x2') dt` is integrated by parts so
//! that x2'' (a second derivative of a noisy load) is never formed:
//! `∫F_s (x1' - x2') dt + m2 ([x2' x1'] - ∫x2' x1'' dt - [x2'^2 / 2])`.
//!
//! Press: the ram's accelerometer gives the link force `-m_ram a_ram`, and the link's stretch
//! follows from `c s' + k s = F_link` (the same filter); the tool sits `s` behind the ram,
//! whose position the encoder gives. The support (sensor in series with the frame) deflects
//! by `F_s / k`. The billet's work is `∫F_s (v_tool - v_support) dt`. The tool's own
//! equation of motion is not used, so a model that does not fit shows in the residual.

use crate::physics::machine::{Hammer, Machine, ScrewPress, series};
use crate::signal::segment::Blow;

/// The energy terms and the billet's motion, as the model sees the measured blow.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Observed {
    pub kinetic_in_j: f64,
    /// Plastic plus friction work on the billet.
    pub deform_j: f64,
    pub damped_j: f64,
    /// Mechanical energy left in the machine at the end of contact.
    pub elastic_j: f64,
    /// The end of forming (the first sample on the largest compression's plateau), samples
    /// from contact.
    pub forming_end: usize,
    /// Zeroed sensor load at the end of forming, N.
    pub final_load_n: f64,
    pub peak_load_n: f64,
    /// Billet compression (plastic plus elastic) at each sample from contact, m.
    pub compression_m: Vec<f64>,
    /// The billet's set, m: the mean compression over the plateau after forming
    /// (`settled_compression`).
    pub set_m: f64,
    /// Work done on the billet during each sample interval, J (sums to `deform_j`).
    pub work_j: Vec<f64>,
}

/// Run the model of `machine` on `blow` from first contact to its end, with impact speed
/// `v0_mps`.
pub fn observe(machine: &Machine, blow: &Blow, v0_mps: f64) -> Observed {
    match machine {
        Machine::Hammer(h) => hammer(h, blow, v0_mps),
        Machine::ScrewPress(p) => press(p, blow, v0_mps),
    }
}

/// Exact step of `tau x' + x = u(t)` with u linear from `u0` to `u1` over `dt` (also the
/// sensor check's link filter, `sensor.rs`).
pub(super) fn first_order_step(x0: f64, u0: f64, u1: f64, dt: f64, tau: f64) -> f64 {
    if tau <= 0.0 {
        return u1;
    }
    let r = dt / tau;
    let alpha = (-r).exp();
    alpha * x0 + u1 - alpha * u0 - (u1 - u0) * (-r).exp_m1().abs() / r
}

fn hammer(h: &Hammer, blow: &Blow, v0: f64) -> Observed {
    let s = &blow.samples[blow.i_contact..=blow.i_end];
    let dt = blow.period_s;
    let (m1, m2, k, c) = (h.m1_kg, h.m2_kg, h.k_n_per_m, h.c_ns_per_m);
    let tau = c / k;
    let fs = |i: usize| s[i].load_n - blow.load_zero_n;
    let n = s.len();
    let mut o = Observed { kinetic_in_j: 0.5 * (m1 + m2) * v0 * v0, ..Default::default() };
    o.compression_m.reserve(n);
    o.work_j.reserve(n);
    let (mut x1, mut v1, mut x2) = (0.0, v0, 0.0);
    // Lower tool velocity from the filter; with no damper, from the load's slope.
    let x2dot = |f: f64, x2: f64, x2_prev: f64| if c > 0.0 { (f - k * x2) / c } else { (x2 - x2_prev) / dt };
    let mut v2 = x2dot(fs(0), 0.0, 0.0);
    for i in 0..n {
        let f = fs(i);
        o.peak_load_n = o.peak_load_n.max(f);
        o.compression_m.push(x1 - x2);
        if i + 1 == n {
            o.work_j.push(0.0);
            break;
        }
        let (a_now, a_next) = (s[i].acc_mps2, s[i + 1].acc_mps2);
        let v1_next = v1 + 0.5 * (a_now + a_next) * dt;
        let f_next = fs(i + 1);
        let x2_next = first_order_step(x2, f / k, f_next / k, dt, tau);
        let v2_next = x2dot(f_next, x2_next, x2);
        // Trapezoids of F_s (x1' - x2'), of c x2'^2, and of x2' x1''.
        let sensor_work = 0.5 * (f * (v1 - v2) + f_next * (v1_next - v2_next)) * dt;
        let inertia = m2
            * ((v2_next * v1_next - v2 * v1)
                - 0.5 * (v2 * a_now + v2_next * a_next) * dt
                - 0.5 * (v2_next * v2_next - v2 * v2));
        o.work_j.push(sensor_work + inertia);
        o.damped_j += 0.5 * c * (v2 * v2 + v2_next * v2_next) * dt;
        x1 += 0.5 * (v1 + v1_next) * dt;
        (v1, x2, v2) = (v1_next, x2_next, v2_next);
    }
    o.deform_j = o.work_j.iter().sum();
    o.elastic_j = 0.5 * m1 * v1 * v1 + 0.5 * m2 * v2 * v2 + 0.5 * k * x2 * x2;
    o.forming_end = end_of_forming(&o.compression_m);
    o.final_load_n = fs(o.forming_end);
    o.set_m = settled_compression(&o.compression_m);
    o
}

fn press(p: &ScrewPress, blow: &Blow, v0: f64) -> Observed {
    let s = &blow.samples[blow.i_contact..=blow.i_end];
    let dt = blow.period_s;
    let (mt, mr, kl, cl) = (p.m_tool_kg, p.m_ram_kg, p.k_link_n_per_m, p.c_link_ns_per_m);
    let k_contact = series(p.k_sensor_n_per_m, p.k_tool_contact_n_per_m);
    let damped_frame = p.c_frame_ns_per_m > 0.0;
    // Without frame damping the frame is one more spring in the series.
    let k_series = if damped_frame { k_contact } else { series(k_contact, p.k_frame_n_per_m) };
    let tau_frame = if damped_frame { p.c_frame_ns_per_m / p.k_frame_n_per_m } else { 0.0 };
    let tau_link = cl / kl;
    let fs = |i: usize| s[i].load_n - blow.load_zero_n;
    // The link force on the tool is what decelerates the ram.
    let link = |i: usize| -mr * s[i].acc_mps2;
    let n = s.len();
    let mut o = Observed { kinetic_in_j: 0.5 * (mt + mr) * v0 * v0, ..Default::default() };
    o.compression_m.reserve(n);
    o.work_j.reserve(n);
    // Link stretch s from c s' + k s = F_link; the tool sits s behind the ram, whose position
    // the encoder gives (relative to contact) and whose velocity the accelerometer gives.
    let stretch_rate =
        |f_link: f64, st: f64, st_prev: f64| if cl > 0.0 { (f_link - kl * st) / cl } else { (st - st_prev) / dt };
    let vn_of = |f: f64, xn: f64| if damped_frame { (f - p.k_frame_n_per_m * xn) / p.c_frame_ns_per_m } else { 0.0 };
    let x_ram0 = s[0].disp_m;
    let (mut vr, mut st, mut xn) = (v0, 0.0, 0.0);
    let mut sd = stretch_rate(link(0), 0.0, 0.0);
    for i in 0..n {
        let f = fs(i);
        o.peak_load_n = o.peak_load_n.max(f);
        let xu = (s[i].disp_m - x_ram0) - st;
        o.compression_m.push(xu - (f / k_series + xn));
        if i + 1 == n {
            o.work_j.push(0.0);
            break;
        }
        let f_next = fs(i + 1);
        let vr_next = vr + 0.5 * (s[i].acc_mps2 + s[i + 1].acc_mps2) * dt;
        let st_next = first_order_step(st, link(i) / kl, link(i + 1) / kl, dt, tau_link);
        let sd_next = stretch_rate(link(i + 1), st_next, st);
        let (vu, vu_next) = (vr - sd, vr_next - sd_next);
        let xn_next = if damped_frame {
            first_order_step(xn, f / p.k_frame_n_per_m, f_next / p.k_frame_n_per_m, dt, tau_frame)
        } else {
            0.0
        };
        let (vn, vn_next) = (vn_of(f, xn), vn_of(f_next, xn_next));
        // Work on the billet: F_s v_tool less what the support's springs store and its
        // damper dissipates (their energy is the support's share of F_s v_support).
        let tool_work = 0.5 * (f * vu + f_next * vu_next) * dt;
        let spring_store = 0.5 * (f_next * f_next - f * f) / k_series;
        let frame_store = if damped_frame { 0.5 * p.k_frame_n_per_m * (xn_next * xn_next - xn * xn) } else { 0.0 };
        let frame_damped = 0.5 * p.c_frame_ns_per_m * (vn * vn + vn_next * vn_next) * dt;
        o.work_j.push(tool_work - spring_store - frame_store - frame_damped);
        o.damped_j += 0.5 * cl * (sd * sd + sd_next * sd_next) * dt + frame_damped;
        (vr, st, sd, xn) = (vr_next, st_next, sd_next, xn_next);
    }
    o.deform_j = o.work_j.iter().sum();
    let f_end = fs(n - 1);
    let vu = vr - sd;
    o.elastic_j = 0.5 * mt * vu * vu
        + 0.5 * mr * vr * vr
        + 0.5 * kl * st * st
        + 0.5 * f_end * f_end / k_series
        + 0.5 * p.k_frame_n_per_m * xn * xn;
    o.forming_end = end_of_forming(&o.compression_m);
    o.final_load_n = fs(o.forming_end);
    o.set_m = settled_compression(&o.compression_m);
    o
}

/// Compression within this of its maximum counts as the end of forming, m: the reconstructed
/// compression carries integrated accelerometer noise, so its plateau after forming wanders
/// by micrometres and the plain maximum would land anywhere on it.
pub const FORMING_PLATEAU_M: f64 = 5e-6;

/// The billet's set: the mean of the contiguous run of samples around the largest
/// compression that stay within `SET_PLATEAU_M` of it. The plain maximum of a compression
/// carrying a few micrometres of noise sits that noise's extreme above the set: on the
/// press paper's ten copper blows at 50 kHz (tuning seeds 11, 12) it added 6 µm a blow.
fn settled_compression(compression: &[f64]) -> f64 {
    let Some((peak, max_comp)) = compression.iter().copied().enumerate().max_by(|a, b| a.1.total_cmp(&b.1)) else {
        return 0.0;
    };
    let on = |c: &f64| *c >= max_comp - SET_PLATEAU_M;
    let before = compression[..peak].iter().rev().take_while(|c| on(c)).count();
    let after = compression[peak..].iter().take_while(|c| on(c)).count();
    let run = &compression[peak - before..peak + after];
    run.iter().sum::<f64>() / run.len() as f64
}

/// The set's plateau: samples within this of the largest compression, m (twice
/// `FORMING_PLATEAU_M`: the noise's spread either side of the plateau).
pub const SET_PLATEAU_M: f64 = 2.0 * FORMING_PLATEAU_M;

/// The end of forming: the first sample on the compression's plateau.
fn end_of_forming(compression: &[f64]) -> usize {
    let max_comp = compression.iter().copied().fold(f64::MIN, f64::max);
    compression.iter().position(|c| *c >= max_comp - FORMING_PLATEAU_M).unwrap_or(0)
}
