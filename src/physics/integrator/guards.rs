//! The switching functions (guards) a mode of an `integrator` system arms.

use super::MAX_GUARDS;

/// Which sign change of a guard counts as its event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Crossing {
    /// From non-positive to strictly positive.
    Rising,
    /// From non-negative to strictly negative.
    Falling,
}

/// The switching functions armed in one mode.
#[derive(Debug, Clone, Copy)]
pub struct Guards {
    pub value: [f64; MAX_GUARDS],
    pub crossing: [Crossing; MAX_GUARDS],
    /// Caller-defined identity of each guard, handed back in `on_event`.
    pub id: [u8; MAX_GUARDS],
    pub len: usize,
}

impl Guards {
    pub fn new() -> Self {
        Guards { value: [0.0; MAX_GUARDS], crossing: [Crossing::Rising; MAX_GUARDS], id: [0; MAX_GUARDS], len: 0 }
    }

    pub fn push(&mut self, id: u8, value: f64, crossing: Crossing) {
        debug_assert!(self.len < MAX_GUARDS);
        self.value[self.len] = value;
        self.crossing[self.len] = crossing;
        self.id[self.len] = id;
        self.len += 1;
    }

    /// A guard fires when the step ends strictly on its triggering side having started on
    /// the other side or exactly at zero. A mode entered at a switch often starts with a
    /// guard at exactly zero (entering `Plastic` from `Stuck`, the relative velocity is 0):
    /// if it then moves the wrong way at once, the mode must end at once.
    pub(super) fn fired(&self, i: usize, start: f64) -> bool {
        let end = self.value[i];
        match self.crossing[i] {
            Crossing::Rising => start <= 0.0 && end > 0.0,
            Crossing::Falling => start >= 0.0 && end < 0.0,
        }
    }
}

impl Default for Guards {
    fn default() -> Self {
        Self::new()
    }
}
