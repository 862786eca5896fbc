//! A taught recipe's numbers rounded to what the measurements resolve, so that the file
//! reads `travel_m = [0.018312, 0.018513]`, not 17 digits of noise. Each window is rounded
//! outward (its min down, its max up), so a rounded window holds everything the exact one
//! held: every blow it was taught from stays inside. The envelope's compression points are
//! rounded before its bounds are learnt at them (`grid`), so its bounds are those of the
//! rounded points, and the bounds are rounded outward too. The widening is at most one step
//! a side, far inside each default tolerance (`recipe::Tolerances::default`).

use super::{BlowWindows, Window};

/// Efficiency: 4 decimals. The estimator's accuracy is about 0.01 (the 0.03 default
/// tolerance is twice issue 16's 0.02 target, with margin), so the fourth decimal holds no
/// measurement; the widening, at most 1e-4 a side, is 1/300 of the default tolerance.
pub const EFFICIENCY_DECIMALS: i32 = 4;

/// Travel and compression, m: 1 µm, a tenth of the encoder's 10 µm count (docs/interfaces.md §1)
/// and a hundredth of the 0.1 mm default compression tolerance.
pub const LENGTH_DECIMALS_M: i32 = 6;

/// Energies and loads: 4 significant digits of the window's larger bound (of the blow's
/// peak load for the envelope), 0.1 % of the value: finer than a load chain's calibration
/// (of the order of 1 %) and 1/50 of the 5 % default tolerances.
pub const SIGNIFICANT_DIGITS: i32 = 4;

/// Powers of ten past which a step is not a decimal a file would show.
const MOST_DECIMALS: i32 = 22;

/// `x` rounded down (or `up`) to `decimals` decimals (negative: to tens, hundreds, ...),
/// as the double nearest that decimal, so that it prints short; never past `x` the wrong
/// way.
pub fn to_decimals(x: f64, decimals: i32, up: bool) -> f64 {
    if !x.is_finite() {
        return x;
    }
    let d = decimals.clamp(-MOST_DECIMALS, MOST_DECIMALS);
    let scale = 10f64.powi(d.abs());
    let back = |n: f64| if d >= 0 { n / scale } else { n * scale };
    let n = if d >= 0 { x * scale } else { x / scale };
    // Already on a step (x·10^d rounded off a whole number): kept.
    if back(n.round()) == x {
        return x;
    }
    let n = if up { n.ceil() } else { n.floor() };
    let r = back(n);
    // x·10^d is itself rounded: one step more where that carried the result past x.
    if up && r < x {
        back(n + 1.0)
    } else if !up && r > x {
        back(n - 1.0)
    } else {
        r
    }
}

/// The decimals that keep `SIGNIFICANT_DIGITS` digits of `scale` (0 for no scale).
pub fn significant_decimals(scale: f64) -> i32 {
    if scale.is_finite() && scale > 0.0 { SIGNIFICANT_DIGITS - 1 - scale.log10().floor() as i32 } else { 0 }
}

/// `w` rounded outward to `decimals` decimals: it holds all `w` held.
pub fn outward(w: Window, decimals: i32) -> Window {
    Window { min: to_decimals(w.min, decimals, false), max: to_decimals(w.max, decimals, true) }
}

/// `points` compression points evenly from 0 to `reach_m` rounded down to 1 µm, each on a
/// whole µm; evenly unrounded where the reach is too short for distinct µm points.
pub fn grid(reach_m: f64, points: usize) -> Vec<f64> {
    let even =
        |reach: f64| -> Vec<f64> { (0..points).map(|j| reach * j as f64 / (points.max(2) - 1) as f64).collect() };
    let reach_r = to_decimals(reach_m, LENGTH_DECIMALS_M, false).max(0.0);
    let scale = 10f64.powi(LENGTH_DECIMALS_M);
    let rounded: Vec<f64> = even(reach_r).into_iter().map(|x| (x * scale).round() / scale).collect();
    if rounded.windows(2).all(|w| w[0] < w[1]) { rounded } else { even(reach_m) }
}

/// A learnt blow's windows and envelope bounds rounded outward (its compression points are
/// already on `grid`).
pub fn blow(b: BlowWindows) -> BlowWindows {
    let sig = |w: &Window| significant_decimals(w.min.abs().max(w.max.abs()));
    let load_decimals = sig(&b.peak_load_n);
    BlowWindows {
        efficiency: outward(b.efficiency, EFFICIENCY_DECIMALS),
        plastic_j: outward(b.plastic_j, sig(&b.plastic_j)),
        peak_load_n: outward(b.peak_load_n, load_decimals),
        travel_m: outward(b.travel_m, LENGTH_DECIMALS_M),
        load_lower_n: b.load_lower_n.iter().map(|&x| to_decimals(x, load_decimals, false)).collect(),
        load_upper_n: b.load_upper_n.iter().map(|&x| to_decimals(x, load_decimals, true)).collect(),
        ..b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_is_outward_and_prints_short() {
        let w = outward(Window { min: 0.018_312_345_678, max: 0.018_512_000_000_1 }, LENGTH_DECIMALS_M);
        assert_eq!(w, Window { min: 0.018312, max: 0.018513 });
        assert_eq!((w.min.to_string(), w.max.to_string()), ("0.018312".to_string(), "0.018513".to_string()));
        // Four significant digits of a peak load in MN: whole kN.
        assert_eq!(significant_decimals(1.234_567e6), -3);
        let w = outward(Window { min: 1_123_456.7, max: 1_234_567.8 }, -3);
        assert_eq!(w, Window { min: 1_123_000.0, max: 1_235_000.0 });
        // A bound already on a step stays.
        assert_eq!(to_decimals(0.9123, EFFICIENCY_DECIMALS, false), 0.9123);
        assert_eq!(to_decimals(0.9123, EFFICIENCY_DECIMALS, true), 0.9123);
        // Outward everywhere: never inside the value, at most one step out.
        for k in 0..2000 {
            let x = 0.37 + k as f64 * 1.234_567e-7;
            let (lo, hi) = (to_decimals(x, 4, false), to_decimals(x, 4, true));
            assert!(lo <= x && x <= hi && hi - lo <= 1.000_001e-4, "{x}: [{lo}, {hi}]");
            assert!(lo.to_string().len() <= 6 && hi.to_string().len() <= 6, "{lo} {hi}");
        }
        assert_eq!(to_decimals(-49.7, 0, false), -50.0);
    }

    #[test]
    fn the_grid_is_on_whole_micrometres_and_strictly_increasing() {
        let g = grid(0.018_312_7, 40);
        assert_eq!((g.len(), g[0], g[39]), (40, 0.0, 0.018312));
        assert!(g.windows(2).all(|w| w[0] < w[1]));
        assert!(g.iter().all(|x| x.to_string().len() <= 8), "{g:?}");
        // Too short for 40 distinct µm points: evenly, unrounded.
        let g = grid(20e-6, 40);
        assert!(g.windows(2).all(|w| w[0] < w[1]) && g[39] == 20e-6, "{g:?}");
    }
}
