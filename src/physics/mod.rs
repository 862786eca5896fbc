//! Pure physics: machine models, the billet, the contact, the blow integrator, the energy
//! ledger and the effect library. Nothing here does IO or reads a clock.

pub mod billet;
pub mod blow;
pub mod effects;
pub mod integrator;
pub mod ledger;
pub mod load_filter;
pub mod machine;
pub mod montecarlo;
pub mod oscillator;
pub mod plant;
pub mod process;
pub mod sequence;
#[cfg(test)]
mod validation;

pub use billet::{BilletGeometry, BilletLaw, FlowStress, LoadEffects};
pub use blow::{BlowError, BlowResult, Forming, SimOptions, simulate_blow};
pub use effects::{Effect, EffectSet};
pub use ledger::Ledger;
pub use machine::{Hammer, Machine, MachineKind, ScrewPress};
pub use plant::Plant;
pub use process::Process;
pub use sequence::{SequenceError, simulate_bare, simulate_sequence};
