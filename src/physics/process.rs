//! The process sheet as the physics uses it (docs/interfaces.md §2): one billet, blow after blow.

use super::billet::{BilletGeometry, BilletLaw, FlowStress, LoadEffects};
use super::machine::MachineKind;

/// How far a hand-measured height may rise above the one before it (or, after blow 1, above
/// the billet's height) and still be taken as the measurement's scatter, m: the default of
/// `process.toml`'s `[caliper] tolerance_m`. A billet measured hot, through scale, at 1100 °C
/// (seed 000's steel) reads 0.1–0.3 mm off from one try to the next (issue 36's caliper
/// noise), and a part measured before it has cooled evenly may read another few tenths high;
/// 1 mm is several times both. A rise can only be the measurement: the hardest blows still
/// flatten the part (the SPR 400's tenth copper blow by 0.15 mm, `forgemon simulate` on the
/// example sheet), never raise it.
pub const CALIPER_TOLERANCE_M: f64 = 1e-3;

/// What was forged: the billet before the sheet's first blow, its material and interface.
#[derive(Debug, Clone, PartialEq)]
pub struct Process {
    pub machine: MachineKind,
    pub billet: BilletGeometry,
    pub material: FlowStress,
    /// Coulomb friction coefficient mu.
    pub friction: f64,
    /// Measured height after each blow, m, in order (may be shorter than the blows).
    pub measured_final_heights_m: Vec<f64>,
}

/// The billet's law is the process's (the law itself knows no process sheet).
impl BilletLaw {
    /// The law of `process`'s billet, material and friction for its blow `blow_index`
    /// (1-based), with `effects`.
    pub fn of(process: &Process, effects: LoadEffects, blow_index: usize) -> Self {
        Self::new(process.billet.clone(), process.material.clone(), process.friction, effects, blow_index)
    }
}
