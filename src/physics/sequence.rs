//! Consecutive blows on one billet: the final height of blow i is the start height of
//! blow i+1 (hammer paper §3.2, press paper §3.3). The machine is at rest, its springs
//! unloaded, at each first contact.

use super::billet::BilletLaw;
use super::blow::{BlowError, BlowResult, SimOptions, simulate_blow};
use super::effects::EffectSet;
use super::machine::Machine;
use super::plant::Plant;
use super::process::Process;

/// A blow of a sequence that failed, with its number.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("blow {blow} (v0 {v0_mps} m/s)")]
pub struct SequenceError {
    pub blow: usize,
    pub v0_mps: f64,
    #[source]
    pub source: BlowError,
}

/// The plant of blow `blow` (1-based) starting at height `h_start_m`.
pub fn blow_plant(machine: &Machine, effects: &EffectSet, process: &Process, blow: usize, h_start_m: f64) -> Plant {
    let law = BilletLaw::of(process, effects.load, blow);
    Plant::new(machine, effects, Some(law), h_start_m)
}

/// Simulate one blow per impact speed in `v0s_mps`, each starting where the last ended.
pub fn simulate_sequence(
    machine: &Machine,
    effects: &EffectSet,
    process: &Process,
    v0s_mps: &[f64],
    opts: &SimOptions,
) -> Result<Vec<BlowResult>, SequenceError> {
    let mut h = process.billet.height_m;
    let mut out = Vec::with_capacity(v0s_mps.len());
    for (i, &v0) in v0s_mps.iter().enumerate() {
        let plant = blow_plant(machine, effects, process, i + 1, h);
        let r = simulate_blow(&plant, v0, opts).map_err(|source| SequenceError { blow: i + 1, v0_mps: v0, source })?;
        if let Some(f) = r.forming {
            h = f.h_end_m;
        }
        out.push(r);
    }
    Ok(out)
}

/// A bare strike (tool on tool, no billet) at `v0_mps`.
pub fn simulate_bare(
    machine: &Machine,
    effects: &EffectSet,
    v0_mps: f64,
    opts: &SimOptions,
) -> Result<BlowResult, BlowError> {
    simulate_blow(&Plant::new(machine, effects, None, 0.0), v0_mps, opts)
}
