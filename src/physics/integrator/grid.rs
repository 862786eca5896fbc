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
        let k_near = nearest(k);
        ((k - k_near).abs() <= GRID_SNAP).then_some(k_near)
    }

    /// The step from `t_s`: its length and its end. From a grid point (within `GRID_SNAP`)
    /// the length is `span_s()` exactly.
    pub(super) fn next_step(&self, t_s: f64) -> (f64, f64) {
        if let Some(k) = self.on_grid(t_s) {
            (self.span_s(), self.t0_s + (k + f64::from(self.points)) * self.dt_s)
        } else {
            let k = (t_s - self.t0_s) / self.dt_s;
            let t_next = self.t0_s + (below(k) + 1.0) * self.dt_s;
            (t_next - t_s, t_next)
        }
    }
}

/// Beyond this magnitude every `f64` is a whole number.
const WHOLE: f64 = 4_503_599_627_370_496.0; // 2^52

/// `k.round()` (half away from zero) without libm's call, which the baseline x86-64 target
/// makes for it (it has no rounding instruction; a conversion to an integer truncates in
/// one). The one value it rounds otherwise, 0.5 - 2^-54 (to 1, as `k + 0.5` rounds up),
/// is half a grid step from a point, where `on_grid` rejects either answer.
fn nearest(k: f64) -> f64 {
    if k.abs() < WHOLE { (k + 0.5f64.copysign(k)) as i64 as f64 } else { k }
}

/// `k.floor()` without libm's call (`nearest`).
fn below(k: f64) -> f64 {
    if k.abs() < WHOLE {
        let t = k as i64 as f64;
        if t > k { t - 1.0 } else { t }
    } else {
        k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_conversions_round_and_floor_as_libm_does() {
        let cases = [
            0.0,
            -0.0,
            0.3,
            0.5,
            0.7,
            1.5,
            2.5,
            -0.5,
            -1.5,
            -2.7,
            1e-300,
            41.999_999_999,
            1e15 + 0.5,
            -1e15 - 0.5,
            2f64.powi(52) - 0.5,
            2f64.powi(52),
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for k in cases {
            assert_eq!(nearest(k), k.round(), "round {k:e}");
            assert_eq!(below(k), k.floor(), "floor {k:e}");
        }
        assert!(nearest(f64::NAN).is_nan() && below(f64::NAN).is_nan());
        // The one difference, half a step from a point: not on the grid either way.
        let g = Grid { t0_s: 0.0, dt_s: 1.0, points: 1 };
        assert_eq!(nearest(0.5 - 2f64.powi(-54)), 1.0);
        assert_eq!(g.on_grid(0.5 - 2f64.powi(-54)), None);
    }
}
