//! The advisor's outcome table: for each tried impact speed, the simulated blow's end height
//! and efficiency on a grid of start heights, read between the grid's points by cubic
//! (Catmull–Rom) interpolation. The end height of a blow is a smooth function of the height
//! it starts from (the law depends on the height through the strain and the friction
//! factor), so a search over thousands of blow sequences costs a few hundred simulations.

use super::AdviseError;

/// Grid spacing of the start heights, m: the interpolation's error on the end height at this
/// spacing is a few µm on the LG1000 and SPR 400 sheets (`tests/advise.rs` checks the plans
/// against exact simulations), far inside the ±0.5 mm window.
pub const TABLE_STEP_M: f64 = 2.0e-3;
/// Fewest grid points over the heights a plan passes.
pub const TABLE_MIN_POINTS: usize = 8;

/// One simulated outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    pub h_end_m: f64,
    pub efficiency: f64,
}

/// Outcomes on a grid of start heights, per speed.
#[derive(Debug, Clone)]
pub struct Table {
    h_lo_m: f64,
    step_m: f64,
    /// `rows[i][k]`: from height `h_lo_m + i step_m` at speed `k`.
    rows: Vec<Vec<Outcome>>,
}

impl Table {
    /// Simulate `strike(h, k)` for every speed `k < speeds` on a grid covering
    /// [`h_lo_m`, `h_hi_m`].
    pub fn build(
        h_lo_m: f64,
        h_hi_m: f64,
        speeds: usize,
        mut strike: impl FnMut(f64, usize) -> Result<Outcome, AdviseError>,
    ) -> Result<Self, AdviseError> {
        let span = (h_hi_m - h_lo_m).max(0.0);
        let n = ((span / TABLE_STEP_M).ceil() as usize + 1).max(TABLE_MIN_POINTS);
        let step_m = span.max(1e-6) / (n - 1) as f64;
        let mut rows = Vec::with_capacity(n);
        for i in 0..n {
            let h = h_lo_m + i as f64 * step_m;
            rows.push((0..speeds).map(|k| strike(h, k)).collect::<Result<Vec<_>, _>>()?);
        }
        Ok(Table { h_lo_m, step_m, rows })
    }

    /// The outcome at speed `k` from height `h_m` (held at the grid's ends).
    pub fn at(&self, h_m: f64, k: usize) -> Outcome {
        let last = self.rows.len() - 1;
        let x = ((h_m - self.h_lo_m) / self.step_m).clamp(0.0, last as f64);
        let i = (x.floor() as usize).min(last.saturating_sub(1));
        let t = x - i as f64;
        let p = |j: isize| self.rows[j.clamp(0, last as isize) as usize][k];
        let (p0, p1, p2, p3) = (p(i as isize - 1), p(i as isize), p(i as isize + 1), p(i as isize + 2));
        let cr = |a: f64, b: f64, c: f64, d: f64| {
            b + 0.5 * t * (c - a + t * (2.0 * a - 5.0 * b + 4.0 * c - d + t * (3.0 * (b - c) + d - a)))
        };
        Outcome {
            h_end_m: cr(p0.h_end_m, p1.h_end_m, p2.h_end_m, p3.h_end_m),
            efficiency: cr(p0.efficiency, p1.efficiency, p2.efficiency, p3.efficiency),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quadratic (Catmull–Rom reproduces them) is read back exactly between the points.
    #[test]
    fn catmull_rom_reads_a_smooth_function_between_the_points() {
        let f = |h: f64| 0.3 * h + 2.0 * h * h;
        let t = Table::build(0.01, 0.05, 1, |h, _| Ok(Outcome { h_end_m: f(h), efficiency: h })).unwrap();
        for h in [0.0123, 0.0251, 0.0377] {
            let o = t.at(h, 0);
            assert!((o.h_end_m - f(h)).abs() < 1e-9, "{h}: {} vs {}", o.h_end_m, f(h));
            assert!((o.efficiency - h).abs() < 1e-12);
        }
    }
}
