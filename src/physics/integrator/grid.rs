//! The grid the exact and exponential steps of `integrator` end on.

/// An instant within this fraction of a grid step of a grid point is on it: the next exact
/// step is a whole one (its propagator precomputed), the time error at most this fraction of
/// the step (1e-14 s on a 10 µs grid).
const GRID_SNAP: f64 = 1e-9;

/// The instants `t0_s + k dt_s` (k integer) at which the exact steps of a linear phase end.
/// A step from a grid point spans `points` of them (`span_s`); a step from elsewhere ends at
/// the next one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub t0_s: f64,
    pub dt_s: f64,
    pub points: u32,
}

impl Grid {
    /// Length of a step from a grid point, s (computed here only, so that it compares equal).
    pub fn span_s(&self) -> f64 {
        self.dt_s * f64::from(self.points)
    }

    /// Whether `t_s` is a grid point (within `GRID_SNAP` of a step), and its index.
    pub fn on_grid(&self, t_s: f64) -> Option<f64> {
        let k = (t_s - self.t0_s) / self.dt_s;
        let k_near = k.round();
        ((k - k_near).abs() <= GRID_SNAP).then_some(k_near)
    }

    /// The step from `t_s`: its length and its end. From a grid point (within `GRID_SNAP`)
    /// the length is `span_s()` exactly.
    pub(super) fn next_step(&self, t_s: f64) -> (f64, f64) {
        if let Some(k) = self.on_grid(t_s) {
            (self.span_s(), self.t0_s + (k + f64::from(self.points)) * self.dt_s)
        } else {
            let k = (t_s - self.t0_s) / self.dt_s;
            let t_next = self.t0_s + (k.floor() + 1.0) * self.dt_s;
            (t_next - t_s, t_next)
        }
    }
}
