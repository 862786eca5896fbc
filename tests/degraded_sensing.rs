//! Degraded sensing (issue 43): every blow's energy with one of the three channels missing
//! or failing. The papers' two machines are rendered by the DAQ chain (`common/rigs.rs`:
//! another code path than the estimator's model, the truth off the sheet the estimator is
//! given) and by `tests/independent`, and fed to the pipeline as a source without that
//! channel would send them (batches whose roles leave it out), or with it failing (`Fault`:
//! a gain off, clipped, dead inside a blow).
//!
//! The faults' limits (`estimate::faults::ACC_LIMIT`, `LOAD_LIMIT`) come from
//! `cross_check_spread` and `gain_sensitivity` on the tuning seeds.
//!
//! Goals (issue 43): efficiency within 0.03 of the truth on every blow, impact speed within
//! 1 %, end height within 0.1 mm where the mode observes it.
//!
//! Seeds: `TUNING_SEEDS` are the ones the modes were developed and tuned on (run
//! `cargo test --release --test degraded_sensing -- --ignored --nocapture` for their
//! table); the tests assert on `REPORT_SEEDS`, which nothing was tuned on.
//! `FORGEMON_DEGRADED_DOC=docs/degraded-sensing.md` with that command writes the report
//! seeds' table to the docs.

mod common;
mod independent;
#[path = "common/rigs.rs"]
mod rigs;

use forgemon::alert::AlertKind;
use forgemon::config::parse_machine;
use forgemon::estimate::BlowEstimate;
use forgemon::pipeline::{Pipeline, PipelineConfig, PipelineEvent};
use forgemon::signal::sample::{Channels, Role, SampleBatch};
use independent::{HAMMER, Hidden, Kind, PRESS};
use rigs::{Rig, machine, render, sheet, truth_process};

/// Issue 43's accuracy goals.
const EFFICIENCY_TOL: f64 = 0.03;
const SPEED_REL_TOL: f64 = 0.01;
const HEIGHT_TOL_M: f64 = 1e-4;

const TUNING_SEEDS: [u64; 4] = [11, 12, 13, 14];
const REPORT_SEEDS: [u64; 2] = [4301, 4302];

/// The rates of the goal.
const RATES_HZ: [f64; 3] = [5e3, 20e3, 100e3];

/// One blow: the estimate against the truth.
#[derive(Debug)]
struct Row {
    efficiency_err: Option<f64>,
    v_rel_err: f64,
    h_err_m: Option<f64>,
    estimate: Box<BlowEstimate>,
}

/// Which code path renders the blows.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Renderer {
    /// `forgemon::daq`: the project's plant at a fine fixed RK4 step through a DAQ chain
    /// (`common/rigs.rs`), the papers' machines, the truth off the sheet.
    DaqChain,
    /// `tests/independent`: an elastic-plastic billet, velocity Verlet, a Butterworth DAQ
    /// chain, machines off the papers' (`independent::HAMMER`, `PRESS`), the ram lifted and
    /// returned between blows.
    Independent,
}

/// One rendered session as the pipeline takes it: the machine, the sheet, the samples on
/// one clock (load, disp, acc) and each blow's true efficiency, impact speed and end height;
/// and the encoder's reading at the die when the estimator is told it.
struct Rendered {
    machine: forgemon::physics::machine::Machine,
    sheet: forgemon::physics::process::Process,
    rows: Vec<[f64; 3]>,
    truth: Vec<(f64, f64, f64)>,
    encoder_at_die_m: Option<f64>,
}

fn rendered(renderer: Renderer, rig: Rig, rate_hz: f64, seed: u64) -> Rendered {
    match renderer {
        Renderer::DaqChain => {
            let session = render(rig, rate_hz, seed, &truth_process(rig));
            Rendered {
                machine: machine(rig),
                sheet: sheet(rig),
                rows: session.rows.iter().map(|r| [r.load_n, r.disp_m, r.acc_mps2]).collect(),
                truth: session
                    .truth
                    .iter()
                    .map(|t| (t.efficiency(), t.v0_mps, t.forming.map_or(f64::NAN, |f| f.h_end_m)))
                    .collect(),
                encoder_at_die_m: Some(forgemon::synth::ENCODER_AT_LOWER_DIE_M),
            }
        }
        Renderer::Independent => {
            // `tests/capture_freedoms.rs`'s billets: a 90 mm steel one, soft to hard; a
            // 25 mm copper one, six blows.
            let (kind, text, v0s, scale): (Kind, &str, &[f64], f64) = match rig {
                Rig::Hammer => (Kind::Hammer, HAMMER, &[4.0, 5.0, 5.3, 5.3, 5.3], 0.090 / 0.112),
                Rig::Press => (Kind::Press, PRESS, &[0.30, 0.33, 0.36, 0.36, 0.36, 0.36], 0.025 / 0.03),
            };
            let r = independent::captures::render(kind, &Hidden::None, v0s, scale, rate_hz, seed);
            let mut rows = Vec::new();
            for (i, c) in r.captures.iter().enumerate() {
                rows.extend(
                    c.iter().chain(r.between.get(i).into_iter().flatten()).map(|s| [s.load_n, s.disp_m, s.acc_mps2]),
                );
            }
            Rendered {
                machine: parse_machine("m", text).expect("machine").machine,
                sheet: r.process.clone(),
                rows,
                truth: r.truth.iter().map(|t| (t.efficiency(), t.v0_mps, t.h_end_m)).collect(),
                encoder_at_die_m: None,
            }
        }
    }
}

/// Render the rig's session and estimate it with `without` missing from every batch (none:
/// the full mode).
fn run(renderer: Renderer, rig: Rig, rate_hz: f64, seed: u64, without: Option<Role>) -> Result<Vec<Row>, String> {
    run_with(renderer, rig, rate_hz, seed, without, None)
}

/// `run`, with one channel's readings multiplied by a gain (a lost calibration) when `gain`
/// names one.
fn run_with_gain(
    renderer: Renderer,
    rig: Rig,
    rate_hz: f64,
    seed: u64,
    without: Option<Role>,
    gain: Option<(Role, f64)>,
) -> Result<Vec<Row>, String> {
    run_with(renderer, rig, rate_hz, seed, without, gain.map(|(role, g)| Fault::Gain(role, g)))
}

/// A channel's failure, applied to the rendered samples before the DAQ would send them.
#[derive(Debug, Clone, Copy)]
enum Fault {
    /// Every reading times the gain (a lost calibration).
    Gain(Role, f64),
    /// Readings clipped at this fraction of the channel's largest magnitude over the
    /// session, either sign (an amplifier or ADC at its rail).
    Clip(Role, f64),
    /// The channel reads 0 from the session's largest magnitude of the accelerometer on:
    /// it dies at the peak of the hardest blow, which is under way.
    DiesAtHardestPeak(Role),
}

impl Fault {
    fn role(self) -> Role {
        match self {
            Fault::Gain(r, _) | Fault::Clip(r, _) | Fault::DiesAtHardestPeak(r) => r,
        }
    }
}

fn column(role: Role) -> usize {
    match role {
        Role::Load => 0,
        Role::Disp => 1,
        Role::Acc => 2,
    }
}

fn apply(fault: Fault, rows: &mut [[f64; 3]]) {
    match fault {
        Fault::Gain(role, g) => rows.iter_mut().for_each(|r| r[column(role)] *= g),
        Fault::Clip(role, fraction) => {
            let c = column(role);
            let rail = fraction * rows.iter().fold(0.0f64, |m, r| m.max(r[c].abs()));
            rows.iter_mut().for_each(|r| r[c] = r[c].clamp(-rail, rail));
        }
        Fault::DiesAtHardestPeak(role) => {
            let peak = (0..rows.len()).max_by(|&a, &b| rows[a][2].abs().total_cmp(&rows[b][2].abs())).unwrap_or(0);
            rows[peak..].iter_mut().for_each(|r| r[column(role)] = 0.0);
        }
    }
}

/// `run`, with `fault` applied to the samples when it names one.
fn run_with(
    renderer: Renderer,
    rig: Rig,
    rate_hz: f64,
    seed: u64,
    without: Option<Role>,
    fault: Option<Fault>,
) -> Result<Vec<Row>, String> {
    let mut session = rendered(renderer, rig, rate_hz, seed);
    if let Some(fault) = fault {
        apply(fault, &mut session.rows);
    }
    let events = events_of(&session, rate_hz, without);
    let blows: Vec<&PipelineEvent> = events.iter().filter(|e| !matches!(e, PipelineEvent::Billet(_))).collect();
    if blows.len() != session.truth.len() {
        return Err(format!("{} results for {} blows: {blows:?}", blows.len(), session.truth.len()));
    }
    blows
        .iter()
        .zip(&session.truth)
        .map(|(e, &(efficiency, v0_mps, h_end_m))| match e {
            PipelineEvent::Blow { estimate, .. } => Ok(Row {
                efficiency_err: estimate.efficiency.map(|x| x - efficiency),
                v_rel_err: estimate.v_impact_mps / v0_mps - 1.0,
                h_err_m: estimate.h_end_m.map(|h| h - h_end_m),
                estimate: estimate.clone(),
            }),
            other => Err(format!("{other:?}")),
        })
        .collect()
}

/// The pipeline's events on `session`'s samples, sent without `without`.
fn events_of(session: &Rendered, rate_hz: f64, without: Option<Role>) -> Vec<PipelineEvent> {
    let m = session.machine;
    let roles: Vec<Role> = Role::ALL.into_iter().filter(|r| Some(*r) != without).collect();
    let period_ns = 1e9 / rate_hz;
    let per_batch = (rate_hz * 0.01) as usize;
    let mut cfg = PipelineConfig::for_machine(&m);
    cfg.estimate.encoder_at_die_m = session.encoder_at_die_m;
    let mut p = Pipeline::new(m, Some(session.sheet.clone()), cfg);
    let mut events = Vec::new();
    for (k, chunk) in session.rows.chunks(per_batch).enumerate() {
        let t0 = ((k * per_batch) as f64 * period_ns) as i64;
        let values = chunk
            .iter()
            .flat_map(|r| {
                roles.iter().map(move |role| match role {
                    Role::Load => r[0],
                    Role::Disp => r[1],
                    Role::Acc => r[2],
                })
            })
            .collect();
        let batch = SampleBatch {
            source: "daq".into(),
            seq: k as u64,
            device_time_ns: t0,
            host_time_ns: t0,
            period_ns,
            roles: roles.clone(),
            values,
        };
        p.push(&batch, &mut events);
    }
    p.end_of_stream(&mut events);
    events
}

/// The worst errors over a session's blows: efficiency (absolute), impact speed (relative),
/// end height (m), and how many blows had no efficiency or no end height; the efficiency's
/// root mean square error and the mean `efficiency_sd` reported.
#[derive(Debug, Default, Clone, Copy)]
struct Worst {
    efficiency: f64,
    efficiency_ss: f64,
    sd_sum: f64,
    /// Blows whose efficiency is within 2 of its reported sd of the truth.
    within_2sd: usize,
    speed: f64,
    height_m: f64,
    no_efficiency: usize,
    no_height: usize,
    blows: usize,
}

impl Worst {
    fn add(&mut self, rows: &[Row]) {
        for r in rows {
            self.blows += 1;
            match r.efficiency_err {
                Some(d) => {
                    self.efficiency = self.efficiency.max(d.abs());
                    self.efficiency_ss += d * d;
                }
                None => self.no_efficiency += 1,
            }
            let sd = r.estimate.efficiency_sd.unwrap_or(f64::NAN);
            self.sd_sum += sd;
            self.within_2sd += usize::from(r.efficiency_err.is_some_and(|d| d.abs() <= 2.0 * sd));
            self.speed = self.speed.max(r.v_rel_err.abs());
            match r.h_err_m {
                Some(d) => self.height_m = self.height_m.max(d.abs()),
                None => self.no_height += 1,
            }
        }
    }

    fn efficiency_rms(&self) -> f64 {
        (self.efficiency_ss / (self.blows - self.no_efficiency).max(1) as f64).sqrt()
    }

    fn mean_sd(&self) -> f64 {
        self.sd_sum / self.blows.max(1) as f64
    }
}

/// Every renderer at every rate of the goal, on `seeds`.
fn cases(seeds: &[u64]) -> Vec<(Renderer, f64, u64)> {
    let mut out = Vec::new();
    for renderer in [Renderer::DaqChain, Renderer::Independent] {
        for rate_hz in RATES_HZ {
            out.extend(seeds.iter().map(|&seed| (renderer, rate_hz, seed)));
        }
    }
    out
}

/// Of a mode's blows on the report seeds, at least this share lies within two of its
/// reported `efficiency_sd` of the truth: a normal error would put 95 % there; the floor of
/// the error model came from the tuning seeds (`estimate::modes`).
const WITHIN_2SD_SHARE: f64 = 0.9;

fn check(rig: Rig, without: Role) {
    let mut all = Worst::default();
    for (renderer, rate_hz, seed) in cases(&REPORT_SEEDS) {
        {
            let at =
                format!("{rig:?} without {} by {renderer:?} at {} kHz, seed {seed}", without.short(), rate_hz / 1e3);
            let rows = run(renderer, rig, rate_hz, seed, Some(without)).unwrap_or_else(|e| panic!("{at}: {e}"));
            let mut w = Worst::default();
            w.add(&rows);
            all.add(&rows);
            eprintln!("{at}: {w:?}");
            for (i, r) in rows.iter().enumerate() {
                let e = &r.estimate;
                let blow = format!("{at}, blow {}: {r:?}", i + 1);
                assert_eq!(e.channels, Channels::ALL.without(without), "channels: {blow}");
                assert!(r.efficiency_err.is_some_and(|d| d.abs() <= EFFICIENCY_TOL), "efficiency: {blow}");
                assert!(r.v_rel_err.abs() <= SPEED_REL_TOL, "impact speed: {blow}");
                if without == Role::Disp {
                    // Not observed: the billet's own height is not measured.
                    assert!(r.h_err_m.is_none() && e.unobserved.contains_key("h_end_m"), "end height: {blow}");
                } else {
                    assert!(r.h_err_m.is_some_and(|d| d.abs() <= HEIGHT_TOL_M), "end height: {blow}");
                }
                assert!(e.efficiency_sd.is_some_and(|sd| sd > 0.0 && sd < EFFICIENCY_TOL), "efficiency_sd: {blow}");
                assert_eq!(
                    e.sensor_check.is_some(),
                    without == Role::Disp,
                    "a sensor check exactly when both the load and the accelerometer are there: {blow}"
                );
            }
        }
    }
    let share = all.within_2sd as f64 / all.blows as f64;
    assert!(share >= WITHIN_2SD_SHARE, "{rig:?} without {}: {share:.2} of the blows within 2 sd", without.short());
}

#[test]
fn hammer_without_a_load_channel() {
    check(Rig::Hammer, Role::Load);
}

#[test]
fn press_without_a_load_channel() {
    check(Rig::Press, Role::Load);
}

#[test]
fn hammer_without_an_accelerometer() {
    check(Rig::Hammer, Role::Acc);
}

#[test]
fn press_without_an_accelerometer() {
    check(Rig::Press, Role::Acc);
}

#[test]
fn hammer_without_an_encoder() {
    check(Rig::Hammer, Role::Disp);
}

#[test]
fn press_without_an_encoder() {
    check(Rig::Press, Role::Disp);
}

/// The table: worst errors per mode, rate and machine over a set of seeds
/// (`FORGEMON_DEGRADED_SEEDS=tune|report`, tune by default).
#[test]
#[ignore = "prints the accuracy table; run with --ignored --nocapture"]
fn accuracy_table() {
    let report = std::env::var("FORGEMON_DEGRADED_SEEDS").is_ok_and(|s| s == "report");
    let seeds: &[u64] = if report { &REPORT_SEEDS } else { &TUNING_SEEDS };
    let mut lines = vec![
        "| renderer | machine | without | rate | blows | worst Δefficiency | RMS Δefficiency | mean efficiency_sd | within 2 sd | worst Δv/v | worst Δh_end | no efficiency | no h_end |".to_string(),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|".to_string(),
    ];
    for rig in [Rig::Hammer, Rig::Press] {
        for renderer in [Renderer::DaqChain, Renderer::Independent] {
            for without in [None, Some(Role::Load), Some(Role::Acc), Some(Role::Disp)] {
                for rate_hz in RATES_HZ {
                    let mut w = Worst::default();
                    let mut failed = None;
                    for &seed in seeds {
                        match run(renderer, rig, rate_hz, seed, without) {
                            Ok(rows) => w.add(&rows),
                            Err(e) => failed = Some(format!("seed {seed}: {e}")),
                        }
                    }
                    let line = format!(
                        "| {} | {} | {} | {} kHz | {} | {:.4} | {:.4} | {:.4} | {} | {:.4} % | {:.1} µm | {} | {} |{}",
                        if renderer == Renderer::DaqChain { "DAQ chain" } else { "independent" },
                        if rig == Rig::Hammer { "hammer" } else { "press" },
                        without.map_or("(none)", |r| r.short()),
                        rate_hz / 1e3,
                        w.blows,
                        w.efficiency,
                        w.efficiency_rms(),
                        w.mean_sd(),
                        w.within_2sd,
                        w.speed * 100.0,
                        w.height_m * 1e6,
                        w.no_efficiency,
                        w.no_height,
                        failed
                            .map_or(String::new(), |f| format!(" failed: {}", f.chars().take(300).collect::<String>())),
                    );
                    eprintln!("{line}");
                    lines.push(line);
                }
            }
        }
    }
    let faults = fault_table(seeds);
    if let Ok(path) = std::env::var("FORGEMON_DEGRADED_DOC") {
        let seeds = seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", ");
        let doc = format!(
            "# Degraded sensing: accuracy per mode\n\n\
             Regenerate with `FORGEMON_DEGRADED_SEEDS=report FORGEMON_DEGRADED_DOC=docs/degraded-sensing.md \
             cargo test --release --test degraded_sensing -- --ignored accuracy_table --nocapture`.\n\n\
             Each row is one machine, one mode (the channel left out; `(none)` is the full mode, the anchor) and one \
             sample rate, over seeds {seeds} ({}). Two renderers make the blows, neither of them the estimator's own \
             model at its own step: the DAQ chain (`forgemon::daq`: the project's plant by RK4 at a fine fixed step, a \
             linear-phase anti-alias filter, the papers' machines, the flow stress and billet height off the sheet) and \
             the independent renderer (`tests/independent`: an elastic-plastic billet, velocity Verlet, a Butterworth \
             DAQ chain, machines off the papers'). The goals (issue 43): efficiency within 0.03 of the truth, impact \
             speed within 1 %, end height within 0.1 mm. `efficiency_sd` is the 1σ each blow reports; \
             \"within 2 sd\" counts the blows whose error is within two of it.\n\n\
             Without the encoder (`disp`) the impact speed is fitted with the model to the load and the \
             accelerometer, and the billet's height is the sheet's carried down by the model: `h_end_m` is not \
             observed (\"no h_end\" counts it), and the DAQ chain's billets sit 1.5 % off their sheets, which costs \
             the hammer's last blows about 0.013 of efficiency. `efficiency_sd` carries a height known to 1 % of the \
             sheet's.\n\n{}\n\n\
             ## A channel that fails\n\n\
             The same sessions with all three channels sent and one of them failing: its readings scaled (a lost \
             calibration), clipped at 60 % of the session's peak (an amplifier at its rail), or read 0 from the peak \
             of the hardest blow on (it dies inside a blow, which is under way). `estimate::faults::judge` weighs \
             them: an accelerometer more than 0.8 % off the encoder's travel, the load siding with the encoder, or a \
             load more than 2 % off the momentum the other two agree on, is left out of the blow, which is then \
             estimated without it; a channel that drops from the blow's load to one value held to its end is left \
             out too (`faults::failed_channels`). An encoder 2 % off, the other two agreeing, is left out the same way, \
             and its blows are estimated without it (`a_wrong_encoder_is_outvoted`). \
             \"left out\" counts the blows that left the failed channel out (a clipped channel fails only on the \
             blows whose peak passes the rail); the errors are against the truth.\n\n{}\n",
            if report { "the report seeds, which nothing was tuned on" } else { "the tuning seeds" },
            lines.join("\n"),
            faults.join("\n")
        );
        std::fs::write(path, doc).expect("write the table");
    }
}

/// A lost calibration (issue 43): one channel's gain off by `gain`, on the report seeds at
/// every rate and on both renderers. The other two outvote it on every blow, and the blows
/// keep the goals (`survives`).
fn outvoted(rig: Rig, role: Role, gain: f64) {
    for (i, rows) in survives(rig, Fault::Gain(role, gain)).iter().enumerate() {
        for r in rows {
            assert_eq!(r.estimate.channels, Channels::ALL.without(role), "case {i}: {r:?}");
        }
    }
}

/// An encoder whose scale is 2 % off (its reading times 1.02): the load and the
/// accelerometer agree, so the encoder is named and left out, and the blows are estimated
/// without it (`estimate::no_encoder`).
#[test]
fn a_wrong_encoder_is_outvoted() {
    outvoted(Rig::Hammer, Role::Disp, 1.02);
    outvoted(Rig::Press, Role::Disp, 1.02);
}

/// An encoder that dies at the hardest blow's peak (reads 0 from there on): that blow and
/// every later one are estimated without it.
#[test]
fn an_encoder_dying_inside_a_blow_leaves_the_blows_to_the_reduced_mode() {
    survives(Rig::Hammer, Fault::DiesAtHardestPeak(Role::Disp));
    survives(Rig::Press, Fault::DiesAtHardestPeak(Role::Disp));
}

/// The case: a load sensor reading 25 % high.
#[test]
fn a_load_reading_25_percent_high_is_outvoted() {
    outvoted(Rig::Hammer, Role::Load, 1.25);
    outvoted(Rig::Press, Role::Load, 1.25);
}

/// An accelerometer reading 20 % low.
#[test]
fn an_accelerometer_reading_20_percent_low_is_outvoted() {
    outvoted(Rig::Hammer, Role::Acc, 0.8);
    outvoted(Rig::Press, Role::Acc, 0.8);
}

/// Healthy channels are never outvoted: no blow of the report seeds leaves one out.
#[test]
fn healthy_channels_are_not_outvoted() {
    for rig in [Rig::Hammer, Rig::Press] {
        for (renderer, rate_hz, seed) in cases(&REPORT_SEEDS) {
            let rows = run(renderer, rig, rate_hz, seed, None).expect("run");
            for r in &rows {
                assert!(r.estimate.excluded.is_empty(), "{rig:?} {renderer:?} {rate_hz} Hz seed {seed}: {r:?}");
                assert_eq!(r.estimate.channels, Channels::ALL);
                assert!(r.estimate.acc_check.is_some_and(|x| x.abs() < 0.01), "{r:?}");
            }
        }
    }
}

/// The fault table of `accuracy_table`: per machine, renderer, fault and rate, the blows
/// that left the failed channel out and the worst errors.
fn fault_table(seeds: &[u64]) -> Vec<String> {
    let mut lines = vec![
        "| renderer | machine | fault | rate | blows | left out | worst Δefficiency | worst Δv/v |".to_string(),
        "|---|---|---|---|---|---|---|---|".to_string(),
    ];
    let faults = [
        (Fault::Gain(Role::Load, 1.25), "load × 1.25"),
        (Fault::Gain(Role::Acc, 0.8), "acc × 0.8"),
        (Fault::Clip(Role::Load, 0.6), "load clipped at 60 %"),
        (Fault::Clip(Role::Acc, 0.6), "acc clipped at 60 %"),
        (Fault::DiesAtHardestPeak(Role::Load), "load dies at the hardest peak"),
        (Fault::DiesAtHardestPeak(Role::Acc), "acc dies at the hardest peak"),
        (Fault::Gain(Role::Disp, 1.02), "disp × 1.02"),
        (Fault::DiesAtHardestPeak(Role::Disp), "disp dies at the hardest peak"),
    ];
    for rig in [Rig::Hammer, Rig::Press] {
        for renderer in [Renderer::DaqChain, Renderer::Independent] {
            for (fault, name) in faults {
                let role = fault.role();
                for rate_hz in RATES_HZ {
                    let (mut w, mut left_out) = (Worst::default(), 0);
                    for &seed in seeds {
                        let rows = run_with(renderer, rig, rate_hz, seed, None, Some(fault)).expect("run");
                        left_out += rows.iter().filter(|r| r.estimate.excluded.contains_key(role.short())).count();
                        w.add(&rows);
                    }
                    let line = format!(
                        "| {} | {} | {name} | {} kHz | {} | {left_out} | {:.4} | {:.4} % |",
                        if renderer == Renderer::DaqChain { "DAQ chain" } else { "independent" },
                        if rig == Rig::Hammer { "hammer" } else { "press" },
                        rate_hz / 1e3,
                        w.blows,
                        w.efficiency,
                        w.speed * 100.0,
                    );
                    eprintln!("{line}");
                    lines.push(line);
                }
            }
        }
    }
    lines
}

/// The spread of the channels' cross-checks on healthy blows, for the limits of
/// `faults::judge` (tuning seeds).
#[test]
#[ignore = "prints the cross-checks' spread; run with --ignored --nocapture"]
fn cross_check_spread() {
    for rig in [Rig::Hammer, Rig::Press] {
        for (renderer, rate_hz, seed) in cases(&TUNING_SEEDS) {
            let rows = run(renderer, rig, rate_hz, seed, None).expect("run");
            let pick = |f: &dyn Fn(&BlowEstimate) -> Option<f64>| {
                let v: Vec<f64> = rows.iter().filter_map(|r| f(&r.estimate)).collect();
                let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                format!("{lo:+.4}..{hi:+.4} ({} of {})", v.len(), rows.len())
            };
            let excluded = rows.iter().filter(|r| !r.estimate.excluded.is_empty()).count();
            eprintln!(
                "{rig:?} {renderer:?} {} kHz seed {seed}: acc_check {} sensor_check {} excluded {excluded}",
                rate_hz / 1e3,
                pick(&|e| e.acc_check),
                pick(&|e| e.sensor_check)
            );
        }
    }
}

/// What a gain error just inside `faults::ACC_LIMIT` and `LOAD_LIMIT` costs the full mode's
/// efficiency: the worst error per rig, renderer, rate and gain over the tuning seeds, and
/// how many blows left the channel out (the limits' source).
#[test]
#[ignore = "prints the cost of a gain error inside the limits; run with --ignored --nocapture"]
fn gain_sensitivity() {
    use forgemon::estimate::faults::{ACC_LIMIT, LOAD_LIMIT};
    let inside = [
        (Role::Acc, 1.0 - ACC_LIMIT),
        (Role::Acc, 1.0 + ACC_LIMIT),
        (Role::Load, 1.0 - LOAD_LIMIT),
        (Role::Load, 1.0 + LOAD_LIMIT),
    ];
    for rig in [Rig::Hammer, Rig::Press] {
        for (role, g) in inside {
            for renderer in [Renderer::DaqChain, Renderer::Independent] {
                for rate_hz in RATES_HZ {
                    let (mut worst, mut excluded, mut blows) = (0.0f64, 0, 0);
                    for &seed in &TUNING_SEEDS {
                        let rows = run_with_gain(renderer, rig, rate_hz, seed, None, Some((role, g))).expect("run");
                        worst = rows.iter().filter_map(|r| r.efficiency_err).fold(worst, |a, b| a.max(b.abs()));
                        excluded += rows.iter().filter(|r| !r.estimate.excluded.is_empty()).count();
                        blows += rows.len();
                    }
                    eprintln!(
                        "{rig:?} {} ×{g} {renderer:?} {} kHz: worst Δefficiency {worst:.4}, left out on {excluded} of {blows}",
                        role.short(),
                        rate_hz / 1e3
                    );
                }
            }
        }
    }
}

/// A channel that fails in `fault` on the report seeds, every rate, both renderers: every
/// blow keeps issue 43's goals (efficiency within 0.03 of the truth and its class, impact
/// speed within 1 %); the blows that leave a channel out leave out the failed one, at least
/// one does, none before the failure shows, and the session raises one `sensor` alert,
/// naming it. Each case's rows.
fn survives(rig: Rig, fault: Fault) -> Vec<Vec<Row>> {
    let role = fault.role();
    let cfg = forgemon::estimate::EstimatorConfig::for_kind(machine(rig).kind());
    let mut all = Vec::new();
    for (renderer, rate_hz, seed) in cases(&REPORT_SEEDS) {
        let at = format!("{rig:?}, {fault:?} by {renderer:?} at {} kHz, seed {seed}", rate_hz / 1e3);
        let rows = run_with(renderer, rig, rate_hz, seed, None, Some(fault)).unwrap_or_else(|e| panic!("{at}: {e}"));
        let truth = rendered(renderer, rig, rate_hz, seed).truth;
        let mut sensor_alerts = Vec::new();
        let mut first_out = None;
        for (i, (r, t)) in rows.iter().zip(&truth).enumerate() {
            let e = &r.estimate;
            let blow = format!("{at}, blow {}: {r:?}", i + 1);
            assert!(r.efficiency_err.is_some_and(|d| d.abs() <= EFFICIENCY_TOL), "efficiency: {blow}");
            // The true class, or the neighbour across a boundary the blow's own 2σ spans
            // (without an encoder the unknown billet height costs up to 0.014 of
            // efficiency, `estimate::modes::SHEET_HEIGHT_SD_FRACTION`).
            let spans = r.efficiency_err.zip(e.efficiency_sd).is_some_and(|(d, sd)| d.abs() <= 2.0 * sd);
            assert!(e.class == cfg.classify(t.0) || spans, "class: {blow}");
            assert!(r.v_rel_err.abs() <= SPEED_REL_TOL, "impact speed: {blow}");
            if !e.excluded.is_empty() {
                assert_eq!(e.excluded.keys().collect::<Vec<_>>(), [role.short()], "excluded: {blow}");
                first_out.get_or_insert(i);
            }
            sensor_alerts.extend(e.alert.iter().filter(|a| a.kind == AlertKind::Sensor).map(|a| a.reason.clone()));
        }
        let first_out = first_out.unwrap_or_else(|| panic!("{at}: no blow left the {} channel out", role.short()));
        assert_eq!(sensor_alerts.len(), 1, "{at}: {sensor_alerts:?}");
        assert!(sensor_alerts[0].contains(&format!("the {} channel", role.short())), "{at}: {sensor_alerts:?}");
        assert!(rows[first_out].estimate.alert.is_some(), "{at}: the alert comes with the first blow left out");
        all.push(rows);
    }
    all
}

/// A load amplifier at its rail: readings clipped at 60 % of the session's peak.
#[test]
fn a_clipped_load_is_outvoted() {
    survives(Rig::Hammer, Fault::Clip(Role::Load, 0.6));
    survives(Rig::Press, Fault::Clip(Role::Load, 0.6));
}

/// A saturated accelerometer: readings clipped at 60 % of the session's peak.
#[test]
fn a_saturated_accelerometer_is_outvoted() {
    survives(Rig::Hammer, Fault::Clip(Role::Acc, 0.6));
    survives(Rig::Press, Fault::Clip(Role::Acc, 0.6));
}

/// The load dies (reads 0) at the peak of the hardest blow: that blow, under way, is
/// estimated without it (`faults::died_inside`).
#[test]
fn a_load_dying_inside_a_blow_leaves_that_blow_to_the_reduced_mode() {
    survives(Rig::Hammer, Fault::DiesAtHardestPeak(Role::Load));
    survives(Rig::Press, Fault::DiesAtHardestPeak(Role::Load));
}

/// The accelerometer dies at the peak of the hardest blow.
#[test]
fn an_accelerometer_dying_inside_a_blow_leaves_that_blow_to_the_reduced_mode() {
    survives(Rig::Hammer, Fault::DiesAtHardestPeak(Role::Acc));
    survives(Rig::Press, Fault::DiesAtHardestPeak(Role::Acc));
}
