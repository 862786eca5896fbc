//! A channel that failed on a blow (issue 43): judged on the blow's own samples, and left
//! out of its estimate, which then runs in the reduced mode of the channels left.
//!
//! A channel is failed when it is stuck: from the trigger to the blow's end it read one
//! value, where a live sensor shows at least its noise (a dead charge amplifier reads 0, a
//! broken cable or a sensor at its rail one constant). The load and the accelerometer are
//! judged; a blow without a working encoder is not estimated in this version.
//!
//! Not judged here: a clipped peak (a quantised healthy peak repeats its value for several
//! samples at 100 kHz, so a flat top alone does not tell), a drifting zero, and a gain off
//! by a few per cent (the sensor check, `sensor`, flags those; the alert names them).

use std::collections::BTreeMap;

use crate::signal::sample::Role;
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
        if hi - lo <= 1e-9 * hi.abs().max(1.0) {
            let unit = if role == Role::Load { "N" } else { "m/s²" };
            let dead = if hi == 0.0 { " (dead)" } else { "" };
            failed.insert(
                role.short().to_string(),
                format!("{} read {hi} {unit} throughout the blow{dead}", role.column()),
            );
        }
    }
    failed
}

/// `blow` with the channels in `failed` (short names) read as missing, as a source without
/// them would give it; without the load, its zero is the ram's stand-in's (0).
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
    }
    if gone(Role::Load) {
        b.load_zero_n = 0.0;
    }
    b
}
