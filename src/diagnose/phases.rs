//! A blow's phases as `diagnose` splits it (docs/interfaces.md §6): impact, forming, spring-back
//! and post, by sample index. `localise` finds them, `location` weighs the error in each.
//! Pure code.

/// `impact` is this fraction of the forming time.
pub const IMPACT_FRACTION: f64 = 0.10;

/// A blow's phase boundaries, sample indices: first contact, end of impact, end of forming,
/// load back at zero, end of `post`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Phases(pub [usize; 5]);

impl Phases {
    /// Boundaries from first contact and the end of forming, with the load back at zero the
    /// first sample of `load` below `threshold` from the end of forming (or from `not_before`).
    pub(super) fn new(
        contact: usize,
        forming_end: usize,
        load: &[f64],
        threshold: f64,
        not_before: usize,
        post: usize,
    ) -> Phases {
        let n = load.len();
        let contact = contact.min(n);
        let forming_end = forming_end.clamp(contact, n);
        let impact_end = contact + ((forming_end - contact) as f64 * IMPACT_FRACTION).round() as usize;
        let zero = (forming_end.max(not_before)..n).find(|&i| load[i] < threshold).unwrap_or(n);
        Phases([contact, impact_end, forming_end, zero, (zero + post).min(n)])
    }

    /// The phase sample `i` is in: -1 before contact, 0..=3 the four phases, 4 after.
    pub(super) fn of(&self, i: usize) -> i32 {
        (0..5).rev().find(|&k| i >= self.0[k]).map_or(-1, |k| k as i32)
    }

    pub fn contact(&self) -> usize {
        self.0[0]
    }

    pub fn forming_end(&self) -> usize {
        self.0[2]
    }

    pub fn zero(&self) -> usize {
        self.0[3]
    }
}
