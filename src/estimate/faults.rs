//! A channel that failed on a blow (issue 43): judged on the blow's own samples, and left
//! out of its estimate, which then runs in the reduced mode of the channels left.
//!
//! A channel is failed when it is stuck: from the trigger to the blow's end it read one
//! value, where a live sensor shows at least its noise (a dead charge amplifier reads 0, a
//! broken cable or a sensor at its rail one constant); or when it died inside the blow: it
//! read one value from some sample to the blow's last, for at least `MIN_DEAD_RUN_S`, while
//! the other channel says the blow was still under way. The load and the accelerometer are
//! judged; a blow without a working encoder is not estimated in this version.
//!
//! A channel that reads, but wrongly, is outvoted by the other two (`judge`): a gain off, a
//! drifting zero, a clipped or saturated peak (its impulse falls short), a channel that
//! stops short of the blow's end. A quantised healthy peak repeats its value for several
//! samples at 100 kHz, so a flat top alone does not tell.

use std::borrow::Cow;
use std::collections::BTreeMap;

use super::approach::{ACC_GUARD_SAMPLES, ApproachFit};
use super::{EstimateError, Estimator, sensor};
use crate::physics::machine::Machine;
use crate::signal::sample::{Channels, Role, same_reading};
use crate::signal::segment::Blow;

/// The load and accelerometer channels of `blow` that are stuck, by short name, with the
/// reason in words.
pub fn failed_channels(blow: &Blow) -> BTreeMap<String, String> {
    let window = &blow.samples[blow.i_trigger.min(blow.i_end)..=blow.i_end];
    let mut failed = BTreeMap::new();
    for role in [Role::Load, Role::Acc] {
        let value = |s: &crate::signal::sample::Sample| if role == Role::Load { s.load_n } else { s.acc_mps2 };
        let (lo, hi) = window
            .iter()
            .filter(|s| !s.filled)
            .map(value)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if !(lo.is_finite() && hi.is_finite()) {
            continue;
        }
        let unit = if role == Role::Load { "N" } else { "m/s²" };
        if same_reading(lo, hi) {
            let dead = if hi == 0.0 { " (dead)" } else { "" };
            failed.insert(
                role.short().to_string(),
                format!("{} read {hi} {unit} throughout the blow{dead}", role.column()),
            );
        } else if let Some(k) = died_inside(blow, role) {
            let s = &blow.samples[k];
            failed.insert(
                role.short().to_string(),
                format!(
                    "{} read {} {unit} from {:.4} s, {:.1} ms after contact, to the blow's end, while the blow was under way (died inside it)",
                    role.column(),
                    value(s),
                    s.t_s,
                    1e3 * (s.t_s - blow.samples[blow.i_contact].t_s)
                ),
            );
        }
    }
    failed
}

/// The shortest flat run that `died_inside` takes for a dead channel, s: a live sensor's
/// noise changes its reading within a few samples, and the shortest hold that ends a blow
/// (the hammer's, `SegmentConfig::HAMMER`) is 2 ms.
pub const MIN_DEAD_RUN_S: f64 = 1e-3;

/// How far from its quiet level the channel read just before a flat run, as a share of the
/// blow's largest excursion, for the run to be a death: a channel that dies drops from the
/// blow's load in one sample, where a healthy one that settles (a quantised quiet load
/// repeats its value through the hold) reaches the flat run from its quiet band.
pub const DEAD_FROM_SHARE_OF_PEAK: f64 = 0.1;

/// Where `role` went flat inside the blow: the first sample of a run of one measured value
/// (no sample of it interpolated across a hole) that lasts to the blow's last sample, at
/// least `MIN_DEAD_RUN_S` and 10 samples long, starting after contact, reached from a
/// reading more than `DEAD_FROM_SHARE_OF_PEAK` of the blow's largest excursion away from the
/// channel's quiet level (the load's zero; the accelerometer's mean before contact).
fn died_inside(blow: &Blow, role: Role) -> Option<usize> {
    let value = |i: usize| {
        let s = &blow.samples[i];
        if role == Role::Load { s.load_n } else { s.acc_mps2 }
    };
    let last = blow.samples.len().checked_sub(1)?;
    let v = value(last);
    let mut k = last;
    while k > 0 && !blow.samples[k - 1].filled && same_reading(value(k - 1), v) {
        k -= 1;
    }
    let run = last - k + 1;
    let long = run >= 10 && run as f64 * blow.period_s >= MIN_DEAD_RUN_S;
    if !(long && k > blow.i_contact && !blow.samples[k].filled) {
        return None;
    }
    let quiet = match role {
        Role::Load => blow.load_zero_n,
        _ => {
            let before = &blow.samples[..blow.i_contact];
            before.iter().map(|s| s.acc_mps2).sum::<f64>() / before.len().max(1) as f64
        }
    };
    let peak = (blow.i_contact..k).map(|i| (value(i) - quiet).abs()).fold(0.0, f64::max);
    ((value(k - 1) - quiet).abs() > DEAD_FROM_SHARE_OF_PEAK * peak).then_some(k)
}

/// `blow` with the channels in `failed` (short names) read as missing, as a source without
/// them would give it; without the load, its zero is the ram's stand-in's (0), and its
/// contact the ram's deceleration's (`Blow::ram_cut`).
pub fn without(blow: &Blow, failed: &BTreeMap<String, String>) -> Blow {
    let mut b = blow.clone();
    let gone = |r: Role| failed.contains_key(r.short());
    for s in &mut b.samples {
        if gone(Role::Load) {
            s.load_n = f64::NAN;
        }
        if gone(Role::Acc) {
            s.acc_mps2 = f64::NAN;
        }
        if gone(Role::Disp) {
            s.disp_m = f64::NAN;
        }
    }
    if gone(Role::Load) {
        b.load_zero_n = 0.0;
        // Contact as the ram's deceleration confirms it: a load off by its gain rises
        // through the contact level at another sample. The blow keeps its end (the fit
        // without a load sets its own window, `fit`), unless the ram's came first.
        if let Some((contact, end)) = b.ram_cut.take() {
            b.i_contact = contact;
            if b.i_end <= contact {
                b.i_end = end;
            }
        }
    }
    b
}

/// The accelerometer against the encoder, by kinematics alone (no model, no mass): over the
/// blow, the ram's travel the encoder read, less the free flight the approach parabola
/// would have carried it (`approach`), is the double integral of its acceleration, less its
/// own mean over the samples before (the free approach as the accelerometer reads it).
/// Both are integrated from `ACC_GUARD_SAMPLES + 1` samples before contact, where the ram
/// still flew free and the anti-alias filter's pre-ringing has not yet begun, and compared
/// from contact to twice the ram's deceleration (to `2 end − contact`, `end` that of
/// `Blow::ram_cut`, or the blow's without one; the samples' end at most), so that the
/// flight after it weighs in. Least squares of the encoder's on the accelerometer's give
/// `acc / encoder − 1`: positive when the accelerometer reads high (a gain 25 % high gives
/// +0.25, a reversed one about −2). The velocity lost is a second regressor: a DAQ whose
/// anti-alias filter delays the accelerometer against the encoder shifts the double
/// integral by that velocity times the delay, and would otherwise read as a gain (−0.8 % at
/// 5 kHz on `tests/sensor_health.rs`'s DAQ, seed 7). The regression has no intercept: an
/// error δv in the approach's speed biases the result by about δv / v. `None` when the
/// blow has no samples after contact or the normal equations are singular.
pub fn acc_against_encoder(blow: &Blow, approach: &ApproachFit) -> Option<f64> {
    let i0 = blow.i_contact.saturating_sub(ACC_GUARD_SAMPLES + 1);
    let ram_end = blow.ram_cut.map_or(blow.i_end, |(_, end)| end);
    let end = (2 * ram_end).saturating_sub(blow.i_contact).min(blow.samples.len().checked_sub(1)?);
    if end <= blow.i_contact {
        return None;
    }
    let dt = blow.period_s;
    let t_contact = blow.samples[blow.i_contact].t_s;
    let start = approach.at(blow.samples[i0].t_s - t_contact);
    // The accelerometer's own reading of the free approach: a gain then scales only what
    // the blow added.
    let before = &blow.samples[..i0];
    let acc_free = before.iter().map(|s| s.acc_mps2).sum::<f64>() / before.len().max(1) as f64;
    let acc_free = if before.is_empty() { start.acc_mps2 } else { acc_free };
    let (mut v_lost, mut x_lost, mut prev) = (0.0, 0.0, None::<f64>);
    // Normal equations of `encoder ≈ β x_lost + γ v_lost`.
    let mut n = nalgebra::Matrix2::<f64>::zeros();
    let mut r = nalgebra::Vector2::<f64>::zeros();
    for (i, s) in blow.samples.iter().enumerate().take(end + 1).skip(i0) {
        let a = s.acc_mps2 - acc_free;
        if let Some(p) = prev {
            let v_before = v_lost;
            v_lost += 0.5 * (p + a) * dt;
            x_lost += 0.5 * (v_before + v_lost) * dt;
        }
        prev = Some(a);
        if i < blow.i_contact {
            continue;
        }
        let tau = s.t_s - blow.samples[i0].t_s;
        let free_m = start.x_contact_m + start.v_impact_mps * tau + 0.5 * start.acc_mps2 * tau * tau;
        let encoder_lost = s.disp_m - free_m;
        let x = nalgebra::Vector2::new(x_lost, v_lost);
        n += x * x.transpose();
        r += x * encoder_lost;
    }
    let beta = n.lu().solve(&r)?[0];
    (beta.is_finite() && beta != 0.0).then(|| 1.0 / beta - 1.0)
}

/// How far the accelerometer may read from the encoder's travel (`acc_against_encoder`)
/// and still be used: 0.8 %. On healthy blows (`tests/degraded_sensing.rs`
/// `cross_check_spread`, tuning seeds 11–14, both renderers, both machines, 5, 20 and
/// 100 kHz) |`acc_check`| stayed within 0.0014, so the limit is nearly six times that. A gain
/// error just inside it costs the full mode at most 0.0237 of efficiency (`gain_sensitivity`,
/// the press's observer at 20 kHz), inside issue 43's 0.03: the press's observer weighs the
/// ram's 106 t by the accelerometer, so 1 % of gain is about 0.03 of efficiency there.
pub const ACC_LIMIT: f64 = 0.008;

/// How far the load may read from the momentum the accelerometer and the encoder agree on
/// (`sensor::sensor_check`) and still be used: 2 %. On healthy simulated blows
/// |`sensor_check`| stayed within 0.0113 (`alert::AlertConfig::DEFAULT_SENSOR_LIMIT` says
/// where; 0.0065 on this module's tuning seeds). A gain error just inside it costs the full
/// mode at most 0.0232 of efficiency (`gain_sensitivity`: the hammer by the independent
/// renderer at 100 kHz). Tighter than the alerts' 5 %, which allows a real machine's model
/// its 3 % against the load: such a machine's blows are then estimated without the load,
/// whose mode does not rest on it (`docs/degraded-sensing.md`), and one `sensor` alert
/// says so.
pub const LOAD_LIMIT: f64 = 0.02;

/// A blow's three channels weighed against each other: the load against the accelerometer
/// (`sensor::sensor_check`, through the model's masses) and the accelerometer against the
/// encoder (`acc_against_encoder`, kinematics alone).
#[derive(Debug, Clone, PartialEq)]
pub struct Judged {
    pub sensor_check: Option<f64>,
    pub acc_check: Option<f64>,
    /// The channel the other two outvote, with why, in words.
    pub suspect: Option<(Role, String)>,
}

impl Judged {
    /// A blow not judged.
    pub const NONE: Judged = Judged { sensor_check: None, acc_check: None, suspect: None };
}

/// Weigh a full blow's channels (`Judged`). An accelerometer off the encoder's travel by more
/// than `ACC_LIMIT` means one of the two is wrong, and the load tells which: an accelerometer
/// reading high by ε makes the machine's momentum high by about ε (it carries the ram's and
/// the tool's masses), so `sensor_check` ≈ −`acc_check`; a wrong encoder leaves
/// `sensor_check` near 0 (the impact speed enters only through the lower tool's small
/// mass). The nearer explanation names the suspect. An accelerometer that agrees with the
/// encoder, against a load off by more than `LOAD_LIMIT`, leaves the load the suspect. A
/// blow lacking any of the three, or whose figures could not be formed, is not judged.
pub fn judge(machine: &Machine, blow: &Blow, approach: &ApproachFit) -> Judged {
    if blow.channels() != Channels::ALL {
        return Judged::NONE;
    }
    let sensor_check = sensor::sensor_check(machine, blow, approach.v_impact_mps).ok();
    let acc_check = acc_against_encoder(blow, approach);
    let pct = |x: Option<f64>| x.map_or("no figure".to_string(), |x| format!("{:+.1} %", 100.0 * x));
    let figures = format!(
        "acceleration against travel {}, limit ±{:.1} %; load against momentum {}, limit ±{:.0} %",
        pct(acc_check),
        100.0 * ACC_LIMIT,
        pct(sensor_check),
        100.0 * LOAD_LIMIT
    );
    let suspect = match (acc_check, sensor_check) {
        (Some(a), s) if a.abs() > ACC_LIMIT => {
            // A reversed accelerometer has no momentum lost, hence no sensor check.
            let acc_nearer = s.is_none_or(|s| (s + a).abs() <= s.abs());
            if acc_nearer {
                Some((Role::Acc, format!("acc_mps2 disagrees with the encoder and the load ({figures})")))
            } else {
                Some((
                    Role::Disp,
                    format!("disp_m disagrees with the accelerometer and the load, which agree ({figures})"),
                ))
            }
        }
        (Some(_), Some(s)) if s.abs() > LOAD_LIMIT => Some((
            Role::Load,
            format!("load_N disagrees with the accelerometer and the encoder, which agree ({figures})"),
        )),
        _ => None,
    };
    Judged { sensor_check, acc_check, suspect }
}

impl Estimator {
    /// `blow` as the estimate reads it: the channels in `excluded` read as missing
    /// (`without`), and the sensor chain's high-pass undone on the measured load
    /// (`sensor_chain`).
    pub(super) fn prepared<'b>(&self, blow: &'b Blow, excluded: &BTreeMap<String, String>) -> Cow<'b, Blow> {
        let blow = if excluded.is_empty() { Cow::Borrowed(blow) } else { Cow::Owned(without(blow, excluded)) };
        if self.effects.highpass_tau_s.is_finite() {
            Cow::Owned(super::sensor_chain::restore(&blow, self.effects.highpass_tau_s))
        } else {
            blow
        }
    }

    /// A channel the other two outvote (`judge`) left out of `blow`, added to
    /// `excluded`, with the approach fitted again; a blow with a hole, or cut before its end
    /// (a capture's end inside the blow: the load sensor still rings), has no whole
    /// impulses to weigh and is not judged. An outvoted encoder rejects the blow.
    pub(super) fn outvote<'b>(
        &self,
        blow: Cow<'b, Blow>,
        approach: ApproachFit,
        excluded: &mut BTreeMap<String, String>,
    ) -> Result<(Cow<'b, Blow>, ApproachFit, Judged), EstimateError> {
        let whole = blow.lost_s == 0.0 && blow.open_end_n.is_none() && self.gap_s(&blow) <= self.max_bridged_s();
        let judged = if whole { judge(&self.machine, &blow, &approach) } else { Judged::NONE };
        match &judged.suspect {
            None => Ok((blow, approach, judged)),
            Some((Role::Disp, why)) => {
                excluded.insert(Role::Disp.short().to_string(), why.clone());
                Ok((Cow::Owned(without(&blow, excluded)), approach, judged))
            }
            Some((role, why)) => {
                excluded.insert(role.short().to_string(), why.clone());
                let reduced = without(&blow, excluded);
                let approach = self.approach_as_read(&reduced)?;
                Ok((Cow::Owned(reduced), approach, judged))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::sample::Sample;

    const DT: f64 = 1e-5;
    const G: f64 = 9.81;

    /// A ram of 732 kg falling at 5 m/s onto a half-sine force of 400 kN over 10 ms from
    /// sample 1000, its encoder the exact double integral of its acceleration (by the
    /// closed form of the half-sine's, not by the check's trapezoids), its load noisy.
    fn blow(acc_gain: f64) -> (Blow, ApproachFit) {
        let (m, v0, peak, len) = (732.0, 5.0, 400e3, 0.01);
        let w = std::f64::consts::PI / len;
        let samples = (0..3000)
            .map(|i| {
                let t = (i as f64 - 1000.0) * DT;
                let tc = t.clamp(0.0, len);
                // ∬ of -peak/m sin(w τ) over the contact, then the velocity it left.
                let lost = -peak / m * (tc / w - (w * tc).sin() / (w * w)) - peak / m * 2.0 / w * (t - tc).max(0.0);
                let f = if (0.0..=len).contains(&t) { peak * (w * t).sin() } else { 0.0 };
                let noise = 500.0 * ((i * 7919 % 1000) as f64 / 1000.0 - 0.5);
                Sample {
                    t_s: t,
                    load_n: 5e3 + f + noise,
                    disp_m: v0 * t + 0.5 * G * t * t + lost,
                    acc_mps2: acc_gain * (G - f / m),
                    filled: false,
                }
            })
            .collect();
        let b = Blow {
            samples,
            i_trigger: 995,
            i_contact: 1000,
            i_end: 2000,
            load_zero_n: 5e3,
            period_s: DT,
            lost_s: 0.0,
            open_end_n: None,
            ram_cut: Some((1000, 2000)),
        };
        // The approach's curvature is the encoder's bend (`approach` weighs it well above a
        // 5 kHz accelerometer's mean).
        (b, ApproachFit { v_impact_mps: v0, acc_mps2: G, x_contact_m: 0.0, v_sd_mps: 0.0 })
    }

    #[test]
    fn an_accelerometer_reads_its_gain_against_the_encoder() {
        let (b, a) = blow(1.0);
        let x = acc_against_encoder(&b, &a).expect("check");
        assert!(x.abs() < 1e-3, "{x}");
        let (b, a) = blow(1.1);
        let x = acc_against_encoder(&b, &a).expect("check");
        assert!((x - 0.1).abs() < 2e-3, "{x}");
    }

    #[test]
    fn a_load_that_goes_flat_inside_the_blow_died_there_and_a_settled_one_did_not() {
        let (mut b, _) = blow(1.0);
        assert!(failed_channels(&b).is_empty());
        for s in &mut b.samples[1500..] {
            s.load_n = 0.0;
        }
        let failed = failed_channels(&b);
        assert!(failed["load"].contains("died inside it"), "{failed:?}");
        // A healthy load settling onto one quantised value after the blow did not die.
        let (mut b, _) = blow(1.0);
        for s in &mut b.samples[2500..] {
            s.load_n = 5e3;
        }
        assert!(failed_channels(&b).is_empty());
        // Nor one whose flat run starts inside a hole.
        let (mut b, _) = blow(1.0);
        for s in &mut b.samples[1500..] {
            s.load_n = 0.0;
        }
        for s in &mut b.samples[1490..1600] {
            s.filled = true;
        }
        assert!(failed_channels(&b).is_empty());
    }
}
