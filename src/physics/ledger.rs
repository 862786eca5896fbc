//! The energy ledger of one blow (docs/interfaces.md §4): kinetic energy in must equal plastic +
//! friction + damped + elastic. Its closure is the simulator's honesty check and, on
//! measured blows, the model-health figure.

/// Where a blow's kinetic energy went, J.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Ledger {
    /// Kinetic energy of the moving bodies at first contact.
    pub kinetic_in_j: f64,
    /// Work of the frictionless upsetting load `pi r^2 sigma` over the height change.
    pub plastic_j: f64,
    /// Work of the load above the frictionless value.
    pub friction_j: f64,
    /// Energy dissipated in the machine's dampers while in contact.
    pub damped_j: f64,
    /// Mechanical energy (kinetic plus spring) left in the machine when contact ends.
    pub elastic_j: f64,
}

impl Ledger {
    /// `plastic / kinetic_in`.
    pub fn efficiency(&self) -> f64 {
        self.plastic_j / self.kinetic_in_j
    }

    /// Sum of the four sinks.
    pub fn out_j(&self) -> f64 {
        self.plastic_j + self.friction_j + self.damped_j + self.elastic_j
    }

    /// Relative closure error `(out - in) / in`.
    pub fn closure_error(&self) -> f64 {
        (self.out_j() - self.kinetic_in_j) / self.kinetic_in_j
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closure_of_the_contract_example() {
        // docs/interfaces.md §4 example: 5320 + 226 + 150 + 15 = 5711.
        let l = Ledger { kinetic_in_j: 5711.0, plastic_j: 5320.0, friction_j: 226.0, damped_j: 150.0, elastic_j: 15.0 };
        assert!(l.closure_error().abs() < 1e-12);
        assert!((l.efficiency() - 0.9315).abs() < 1e-4);
    }
}
