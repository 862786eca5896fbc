//! Capture directories rendered by the independent renderer (issue 36): one billet's blows as
//! a DAQ would record them on one continuous clock and one continuous encoder, with the truth
//! beside them, so that a test can express the same blows in every freedom docs/interfaces.md §1
//! grants (column order, time origin and encoder offset per file, direction, rate, jitter,
//! several blows per file, sheets with or without measured heights) and compare.
//!
//! The physics is the parent module's (`blow_over`: an elastic-plastic billet, velocity
//! Verlet at 100 fine steps a sample, the DAQ's Butterworth chain), not `forgemon::physics`.
//! Between captures the ram is lifted (hammer) or returned (press) along a smooth path whose
//! acceleration stays below the segmenter's re-arm level.

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

use super::{ADC_LSB_N, CALIPER_M, ENCODER_STEP_M, Hidden, Kind, Rig, blow_over, daq};
use forgemon::config::parse_process;
use forgemon::physics::process::Process;

/// One sample as the DAQ recorded it, on the billet's continuous clock and encoder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    pub t_s: f64,
    pub load_n: f64,
    pub disp_m: f64,
    pub acc_mps2: f64,
}

/// What a blow really did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    pub v0_mps: f64,
    pub h_start_m: f64,
    pub h_end_m: f64,
    pub kinetic_j: f64,
    pub plastic_j: f64,
}

impl Truth {
    pub fn efficiency(&self) -> f64 {
        self.plastic_j / self.kinetic_j
    }
}

/// One billet's blows: a triggered capture per blow (`captures`), the stretches between them
/// (`between[i]` follows capture i), the truth, the sheet and the hand-measured heights.
pub struct Rendered {
    pub kind: Kind,
    pub rate_hz: f64,
    pub captures: Vec<Vec<Row>>,
    pub between: Vec<Vec<Row>>,
    pub truth: Vec<Truth>,
    /// The sheet, its billet scaled, without measured heights.
    pub process: Process,
    /// The heights after each blow as a caliper read them (`caliper_m` of noise, uniform).
    pub measured_m: Vec<f64>,
    /// The sheet's text (`process.toml`), without measured heights.
    pub sheet_text: String,
}

/// The encoder's reading with the ram on the lower die, m: any constant.
const DIE_READING_M: f64 = 0.731;
/// Captured before contact and after it, s: a pre-trigger window longer than the
/// estimator's approach fit (10 ms on a hammer, 50 ms on a press).
const PRE_S: (f64, f64) = (0.04, 0.12);
const POST_S: (f64, f64) = (0.04, 0.08);
/// The stretch between two captures, s: long enough for the smooth lift to stay gentle.
const BETWEEN_S: (f64, f64) = (0.4, 2.0);

/// Render one billet of `height_scale` × the sheet's height on `kind` at `rate_hz`, struck at
/// `v0s`, with `hidden`; noise and caliper errors from `seed`.
pub fn render(kind: Kind, hidden: &Hidden, v0s: &[f64], height_scale: f64, rate_hz: f64, seed: u64) -> Rendered {
    let mut rig = Rig::new(kind, hidden);
    rig.sample_rate_hz = rate_hz;
    let sheet = match kind {
        Kind::Hammer => include_str!("../../config/steel-16NiCrMo13.process.toml"),
        Kind::Press => include_str!("../../config/copper-cu99.process.toml"),
    };
    // The sheet without its measured heights, its billet scaled.
    let text: String = sheet.lines().take_while(|l| !l.starts_with("[[blows]]")).collect::<Vec<_>>().join("\n");
    let mut process = parse_process("p", &text).expect("test sheet");
    process.billet.height_m *= height_scale;
    let sheet_text = text.replace(
        &format!("height_m = {}", fmt_sheet(process.billet.height_m / height_scale)),
        &format!("height_m = {}", process.billet.height_m),
    );
    assert_eq!(parse_process("p", &sheet_text).unwrap().billet.height_m, process.billet.height_m, "{sheet_text}");
    let (pre_s, post_s, between_s) = match kind {
        Kind::Hammer => (PRE_S.0, POST_S.0, BETWEEN_S.0),
        Kind::Press => (PRE_S.1, POST_S.1, BETWEEN_S.1),
    };
    let mut rng = StdRng::seed_from_u64(seed);
    let load_noise = Normal::new(0.0, rig.load_sd_n).expect("finite sd");
    let acc_noise = Normal::new(0.0, rig.acc_sd_mps2).expect("finite sd");
    let dt = 1.0 / rate_hz;
    // The energy in: the ram (and the press's heavy mass behind the link), and the hammer's
    // die where it moves with the ram at contact (the clearances caught up, `blow_over`); a
    // hidden clearance leaves the die at rest.
    let die_moves = !matches!(hidden, Hidden::Clearance { .. });
    let kinetic_mass = rig.m_upper + rig.ram.map_or(if die_moves { rig.m_lower } else { 0.0 }, |(m, _, _)| m);
    let mut h = process.billet.height_m;
    let mut out = Rendered {
        kind,
        rate_hz,
        captures: Vec::new(),
        between: Vec::new(),
        truth: Vec::new(),
        process: process.clone(),
        measured_m: Vec::new(),
        sheet_text,
    };
    // The clock runs on from an arbitrary origin.
    let mut t_s = 731.25;
    let mut load_zero_n = rng.random_range(-5e3..5e3);
    for (i, &v0) in v0s.iter().enumerate() {
        // A billet that cools from blow to blow: its flow stress scaled on blow i.
        let blow_process = match *hidden {
            Hidden::Thermal { q } => scaled(&process, (q * i as f64).exp()),
            _ => process.clone(),
        };
        let mut fine = blow_over(&rig, &blow_process, hidden, v0, h, pre_s, post_s);
        if let Hidden::Highpass { tau_s } = *hidden {
            fine.load_n = high_pass(&fine.load_n, tau_s, 1.0 / (rate_hz * super::FINE as f64));
        }
        let (load, ram, acc) = (daq(&fine.load_n, &rig), daq(&fine.ram_m, &rig), daq(&fine.ram_acc, &rig));
        let rows: Vec<Row> = (0..load.len())
            .map(|k| Row {
                t_s: t_s + k as f64 * dt,
                load_n: ((load[k] + load_zero_n + load_noise.sample(&mut rng)) / ADC_LSB_N).round() * ADC_LSB_N,
                disp_m: quantise(DIE_READING_M - h + ram[k]),
                acc_mps2: acc[k] + acc_noise.sample(&mut rng),
            })
            .collect();
        t_s += rows.len() as f64 * dt;
        out.truth.push(Truth {
            v0_mps: v0,
            h_start_m: h,
            h_end_m: fine.h_end_m,
            kinetic_j: 0.5 * kinetic_mass * v0 * v0,
            plastic_j: fine.plastic_j,
        });
        out.captures.push(rows);
        h = fine.h_end_m;
        out.measured_m.push(h + rng.random_range(-CALIPER_M..=CALIPER_M));
        // The load's zero wanders a little from capture to capture.
        load_zero_n += rng.random_range(-500.0..500.0);
    }
    // Between captures: the ram taken from where the last capture left it to where the next
    // begins, along a smoothstep (its largest acceleration 5.8 d / T²).
    for i in 0..out.captures.len().saturating_sub(1) {
        let (a, b) = (*out.captures[i].last().unwrap(), out.captures[i + 1][0]);
        let n = (between_s / dt).round() as usize;
        let d = b.disp_m - a.disp_m;
        let stretch: Vec<Row> = (1..n)
            .map(|k| {
                let u = k as f64 / n as f64;
                let s = u * u * (3.0 - 2.0 * u);
                let s_dd = (6.0 - 12.0 * u) / (between_s * between_s);
                Row {
                    t_s: a.t_s + k as f64 * dt,
                    load_n: ((a.load_n + (b.load_n - a.load_n) * u + load_noise.sample(&mut rng)) / ADC_LSB_N).round()
                        * ADC_LSB_N,
                    disp_m: quantise(a.disp_m + d * s),
                    acc_mps2: d * s_dd + acc_noise.sample(&mut rng),
                }
            })
            .collect();
        // The next capture starts after the stretch.
        let shift = n as f64 * dt - (b.t_s - a.t_s);
        for later in &mut out.captures[i + 1..] {
            for r in later.iter_mut() {
                r.t_s += shift;
            }
        }
        out.between.push(stretch);
    }
    out
}

/// `p` with its flow stress scaled by `k`.
fn scaled(p: &Process, k: f64) -> Process {
    use forgemon::physics::billet::FlowStress;
    let mut q = p.clone();
    q.material = match p.material {
        FlowStress::Constant { sigma0_pa } => FlowStress::Constant { sigma0_pa: sigma0_pa * k },
        FlowStress::HanselSpittel { a_pa, m1, m2, m3, m4, temperature_c } => {
            FlowStress::HanselSpittel { a_pa: a_pa * k, m1, m2, m3, m4, temperature_c }
        }
    };
    q
}

/// A first-order high-pass `y' = x' - y/τ` over `x` at step `dt` (exact for x linear over a
/// step), from rest: a piezo's charge amplifier.
fn high_pass(x: &[f64], tau_s: f64, dt: f64) -> Vec<f64> {
    let a = (-dt / tau_s).exp();
    let mut y = 0.0;
    let mut prev = x.first().copied().unwrap_or(0.0);
    x.iter()
        .map(|&v| {
            y = a * y + (v - prev) * tau_s / dt * (1.0 - a);
            prev = v;
            y
        })
        .collect()
}

/// A height as the example sheets write it (`0.112`, `0.030`).
fn fmt_sheet(h_m: f64) -> String {
    format!("{h_m:.3}")
}

fn quantise(x_m: f64) -> f64 {
    (x_m / ENCODER_STEP_M).round() * ENCODER_STEP_M
}

/// Write `r` as a capture directory in its plainest form: one file per blow on the billet's
/// own clock and encoder, the sheet with the hand-measured heights, and `machine` as the
/// directory's `machine.toml`.
pub fn write_dir(dir: &std::path::Path, r: &Rendered, machine: &str) {
    std::fs::create_dir_all(dir).unwrap();
    for (i, rows) in r.captures.iter().enumerate() {
        let mut text = String::from("t_s,load_N,disp_m,acc_mps2\n");
        for s in rows {
            text.push_str(&format!("{:.9},{:.1},{:.5},{:.4}\n", s.t_s, s.load_n, s.disp_m, s.acc_mps2));
        }
        std::fs::write(dir.join(format!("blow_{:02}.csv", i + 1)), text).unwrap();
    }
    let mut sheet = r.sheet_text.clone();
    for h in &r.measured_m {
        sheet.push_str(&format!("\n[[blows]]\nfinal_height_m = {h:.5}\n"));
    }
    std::fs::write(dir.join("process.toml"), sheet).unwrap();
    std::fs::write(dir.join("machine.toml"), machine).unwrap();
}
