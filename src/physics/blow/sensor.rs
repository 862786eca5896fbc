//! The sensor-only blows: the fits' (`simulate_blow_sensor_until`, issue 17's cost) and the
//! same blow run to its post window with its peak (`simulate_blow_sensor`, which the tests
//! hold the fits' against).

use super::{BlowError, BlowResult, Forming, Path, SimOptions, Trace, TraceEnd, TracePoint, run_until};
use crate::physics::integrator::Stats;
use crate::physics::ledger::Ledger;
use crate::physics::plant::Plant;

/// What a fit keeps of a blow (`simulate_blow_sensor_until`): a `BlowResult` without the
/// sensor's peak and without a trace of outputs. No fit reads the peak, and keeping it took
/// a walk over every sample: 4.5 µs of the suite's 68 µs blow (docs/validation.md, the seventh
/// pass).
#[derive(Debug, Clone, PartialEq)]
pub struct FitBlow {
    pub v0_mps: f64,
    pub h_start_m: f64,
    /// `None` for a bare strike.
    pub forming: Option<Forming>,
    /// First contact until the contact opens for good, s.
    pub contact_time_s: f64,
    pub energy: Ledger,
    pub stats: Stats,
}

impl FitBlow {
    /// The whole `BlowResult`: this blow with its peak and its trace.
    pub(super) fn with_peak(self, peak_load_n: f64, trace: Vec<TracePoint>) -> BlowResult {
        let FitBlow { v0_mps, h_start_m, forming, contact_time_s, energy, stats } = self;
        BlowResult { v0_mps, h_start_m, forming, peak_load_n, contact_time_s, energy, stats, trace }
    }
}

impl From<&BlowResult> for FitBlow {
    /// The same blow less its peak and its trace.
    fn from(b: &BlowResult) -> FitBlow {
        FitBlow {
            v0_mps: b.v0_mps,
            h_start_m: b.h_start_m,
            forming: b.forming,
            contact_time_s: b.contact_time_s,
            energy: b.energy,
            stats: b.stats,
        }
    }
}

/// `simulate_blow` keeping only the sensor's load at each trace sample (from first contact,
/// every `opts.trace_dt_s`), N; the result's `trace` is empty. The samples are the
/// `sensor_n` of the full trace, bit for bit, without evaluating the billet law for the
/// outputs a fit does not compare; except on a base hammer under Dormand–Prince, whose blow
/// runs here with its linear phases advanced exactly (`Path::Exact`: the fits' cost, issue
/// 17), within the general plant's own integration error of it (`blow::tests`).
pub fn simulate_blow_sensor(
    plant: &Plant,
    v0_mps: f64,
    opts: &SimOptions,
) -> Result<(BlowResult, Vec<f64>), BlowError> {
    let (blow, peak_n, sensor) = sensor_run(plant, v0_mps, opts, None, true)?;
    Ok((blow.with_peak(peak_n.expect("a blow run with its peak"), Vec::new()), sensor))
}

/// `simulate_blow_sensor` ending at `end` instead of `opts.post_s` after the contact opens
/// (`post_s` still ends it if the sensor never reaches `end.threshold_n`), and without the
/// peak. The samples it keeps are `simulate_blow_sensor`'s (the steps before the stop are
/// the same; on a plant without exact phases the last step, cut at the stop, may move its
/// last samples by the step control's error) and so are the indicators and the ledger.
pub fn simulate_blow_sensor_until(
    plant: &Plant,
    v0_mps: f64,
    opts: &SimOptions,
    end: TraceEnd,
) -> Result<(FitBlow, Vec<f64>), BlowError> {
    let (blow, _, sensor) = sensor_run(plant, v0_mps, opts, Some(end), false)?;
    Ok((blow, sensor))
}

/// `simulate_blow_sensor_until`'s blow with the ram's kinematic acceleration at each trace
/// sample in place of the sensor's load, m/s² (`identify` without a load channel, whose data
/// are the ram's accelerometer). `end` still watches the sensor's load. It runs on the
/// specialised plant with every output traced: the exact sensor points do not hold the ram.
pub fn simulate_blow_ram_until(
    plant: &Plant,
    v0_mps: f64,
    opts: &SimOptions,
    end: TraceEnd,
) -> Result<(FitBlow, Vec<f64>), BlowError> {
    let (blow, _, trace) =
        run_until(plant, v0_mps, opts, 0.0, Trace::Outputs(Vec::new()), Path::Specialised, Some(end), false)?;
    let acc = match trace {
        Trace::Outputs(v) => v.iter().map(|p| p.out.ram_acc_mps2).collect(),
        Trace::Sensor(_) => Vec::new(),
    };
    Ok((blow, acc))
}

/// The fits' sensor-only blow (`Path::Exact`), to `end` when given, with its peak when
/// `peak` is.
fn sensor_run(
    plant: &Plant,
    v0_mps: f64,
    opts: &SimOptions,
    end: Option<TraceEnd>,
    peak: bool,
) -> Result<(FitBlow, Option<f64>, Vec<f64>), BlowError> {
    // Room for the post window's samples (a fit's whole window, at least), so that the
    // trace is not moved as it grows; at most a million.
    let room = match opts.trace_dt_s {
        Some(dt) if dt > 0.0 && (opts.post_s / dt).is_finite() => (opts.post_s / dt).clamp(0.0, 1e6) as usize + 2,
        _ => 0,
    };
    let trace = Trace::Sensor(Vec::with_capacity(room));
    let (blow, peak_n, trace) = run_until(plant, v0_mps, opts, 0.0, trace, Path::Exact, end, peak)?;
    let sensor = match trace {
        Trace::Sensor(v) => v,
        Trace::Outputs(v) => v.iter().map(|p| p.out.sensor_n).collect(),
    };
    Ok((blow, peak_n, sensor))
}
