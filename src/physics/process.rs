//! The process sheet as the physics uses it (CONTRACTS.md §2): one billet, blow after blow.

use super::billet::{BilletGeometry, FlowStress};
use super::machine::MachineKind;

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
