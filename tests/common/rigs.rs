//! The papers' two machines as the accuracy tests render them (`tests/estimate_rates.rs`,
//! `tests/degraded_sensing.rs`): the hammer paper's LG1000 (steel, the Table 3 series of
//! blow 1 at 3.9 m/s then 5.3 m/s) and the press paper's SPR 400 (copper, ten blows at
//! 0.346 m/s), rendered by the DAQ chain of `forgemon::daq` (RK4 at a fine fixed step, a
//! linear-phase anti-alias low-pass at 0.4 × the sample rate, decimation, 3 kN load noise,
//! 10 µm encoder steps, the accelerometer's noise, a load offset), another path than the
//! estimator's own model. The truth is off the sheet the estimator is given: the flow
//! stress scaled by a factor it is not told, the billet a little higher or lower.

#![allow(dead_code)]

use forgemon::config::{parse_machine, parse_process};
use forgemon::daq::{DaqSpec, daq_blows};
use forgemon::physics::EffectSet;
use forgemon::physics::billet::FlowStress;
use forgemon::physics::blow::BlowResult;
use forgemon::physics::machine::Machine;
use forgemon::physics::process::Process;
use forgemon::signal::capture::CaptureRow;
use forgemon::synth::{CaptureSpec, idle_rows};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rig {
    Hammer,
    Press,
}

pub fn machine(rig: Rig) -> Machine {
    match rig {
        Rig::Hammer => parse_machine("m", include_str!("../../config/hammer-lg1000.machine.toml")),
        Rig::Press => parse_machine("m", include_str!("../../config/screw-press-spr400.machine.toml")),
    }
    .expect("machine file")
    .machine
}

/// The process sheet the estimator is given.
pub fn sheet(rig: Rig) -> Process {
    match rig {
        Rig::Hammer => parse_process("p", include_str!("../../config/steel-16NiCrMo13.process.toml")),
        Rig::Press => parse_process("p", include_str!("../../config/copper-cu99.process.toml")),
    }
    .expect("process file")
}

/// What was really forged: the flow stress and the billet's height off the sheet by
/// factors the estimator is not told.
pub fn truth_process(rig: Rig) -> Process {
    let mut p = sheet(rig);
    let (stress, height) = match rig {
        Rig::Hammer => (1.07, 1.015),
        Rig::Press => (0.93, 0.985),
    };
    p.material = match p.material {
        FlowStress::Constant { sigma0_pa } => FlowStress::Constant { sigma0_pa: sigma0_pa * stress },
        FlowStress::HanselSpittel { a_pa, m1, m2, m3, m4, temperature_c } => {
            FlowStress::HanselSpittel { a_pa: a_pa * stress, m1, m2, m3, m4, temperature_c }
        }
    };
    p.billet.height_m *= height;
    p
}

pub fn speeds(rig: Rig) -> Vec<f64> {
    match rig {
        // Hammer paper §3.1: blow 1 at 3.9 m/s, the later blows at 5.3 m/s.
        Rig::Hammer => vec![3.9, 5.3, 5.3, 5.3, 5.3],
        // Press paper §2.2 Table 1: ten blows at 0.346 m/s.
        Rig::Press => vec![0.346; 10],
    }
}

pub fn capture(rig: Rig, rate_hz: f64, seed: u64) -> CaptureSpec {
    let base = match rig {
        Rig::Hammer => CaptureSpec::hammer(seed),
        Rig::Press => CaptureSpec::press(seed),
    };
    let mut c = CaptureSpec { sample_rate_hz: rate_hz, ..base };
    // Issue 16: 3 kN load noise; the encoder's 10 µm and the accelerometer's noise as synth's.
    c.sensors.load_sd_n = 3e3;
    c
}

/// A rendered session: its rows, on one clock from 0, each blow's truth and its true first
/// contact on that clock (sample k at k periods).
pub struct Session {
    pub rows: Vec<CaptureRow>,
    pub truth: Vec<BlowResult>,
    pub t_contact_s: Vec<f64>,
}

/// The rig's blows at `rate_hz` on billet and material `truth_p`, 150 ms of the machine at
/// rest before each and after the last.
pub fn render(rig: Rig, rate_hz: f64, seed: u64, truth_p: &Process) -> Session {
    let m = machine(rig);
    let spec = DaqSpec::new(capture(rig, rate_hz, seed));
    let blows = daq_blows(&m, &EffectSet::NONE, truth_p, &speeds(rig), &spec).expect("simulate");
    let c = spec.capture;
    let idle = (0.15 * rate_hz) as usize;
    let mut rows: Vec<CaptureRow> = Vec::new();
    let mut t_contact_s = Vec::new();
    for (i, b) in blows.iter().enumerate() {
        rows.extend(idle_rows(idle, 0.0, &c, b.rows[0].disp_m, seed * 100 + i as u64));
        t_contact_s.push(rows.len() as f64 / rate_hz + (b.t_contact_s - b.rows[0].t_s));
        rows.extend_from_slice(&b.rows);
    }
    let last = rows.last().map_or(0.0, |r| r.disp_m);
    rows.extend(idle_rows(idle, 0.0, &c, last, seed * 100 + 99));
    Session { rows, truth: blows.into_iter().map(|b| b.truth).collect(), t_contact_s }
}
