//! Statistical process control over the history (issue 44): per blow index of a recipe and
//! per quantity, the mean and spread, the process capability against the recipe's window,
//! and the individuals and moving-range (I-MR) chart of the blows in time order.
//!
//! The short-term spread is the moving range's: σ̂ = MR̄/d₂ with d₂ = 1.128 (subgroups of
//! two), as the I-MR chart uses it; Cp = (USL − LSL)/(6σ̂), Cpk = min(USL − x̄, x̄ − LSL)/(3σ̂).
//! Chart limits: x̄ ± 3σ̂ for the individuals (2.66·MR̄), and D₄·MR̄ = 3.267·MR̄ for the
//! moving ranges (Montgomery, *Introduction to Statistical Quality Control*, §6.4). `sd` is
//! the overall sample standard deviation, for Pp/Ppk.

use serde::Serialize;

/// d₂ for subgroups of two.
pub const D2: f64 = 1.128;
/// D₄ for subgroups of two.
pub const D4: f64 = 3.267;

/// One quantity at one blow index.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Capability {
    pub n: usize,
    pub mean: f64,
    /// Overall sample standard deviation.
    pub sd: f64,
    /// Mean moving range of consecutive blows.
    pub mr_bar: f64,
    /// Short-term spread, MR̄/d₂.
    pub sigma_within: f64,
    pub lsl: f64,
    pub usl: f64,
    pub cp: Option<f64>,
    pub cpk: Option<f64>,
    pub pp: Option<f64>,
    pub ppk: Option<f64>,
    /// Individuals chart: centre line and limits.
    pub x_lcl: f64,
    pub x_ucl: f64,
    /// Moving-range chart's upper limit.
    pub mr_ucl: f64,
    /// Points outside the individuals chart's limits (indices into the values).
    pub out_of_control: Vec<usize>,
}

/// The capability of `values` (time order) against the window [`lsl`, `usl`]; `None` with
/// fewer than two values.
pub fn capability(values: &[f64], lsl: f64, usl: f64) -> Option<Capability> {
    let n = values.len();
    if n < 2 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let sd = (values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    let mr_bar = values.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / (n - 1) as f64;
    let sigma_within = mr_bar / D2;
    let ratio = |num: f64, den: f64| (den > 0.0).then(|| num / den);
    let (x_lcl, x_ucl) = (mean - 3.0 * sigma_within, mean + 3.0 * sigma_within);
    Some(Capability {
        n,
        mean,
        sd,
        mr_bar,
        sigma_within,
        lsl,
        usl,
        cp: ratio(usl - lsl, 6.0 * sigma_within),
        cpk: ratio((usl - mean).min(mean - lsl), 3.0 * sigma_within),
        pp: ratio(usl - lsl, 6.0 * sd),
        ppk: ratio((usl - mean).min(mean - lsl), 3.0 * sd),
        x_lcl,
        x_ucl,
        mr_ucl: D4 * mr_bar,
        out_of_control: values.iter().enumerate().filter(|(_, x)| **x < x_lcl || **x > x_ucl).map(|(i, _)| i).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_textbook_series_gives_its_capability() {
        // x = 10, 12, 11, 13, 12: mean 11.6, moving ranges 2, 1, 2, 1 (MR̄ 1.5), σ̂ = 1.5/1.128.
        let c = capability(&[10.0, 12.0, 11.0, 13.0, 12.0], 8.0, 16.0).expect("five values");
        let sigma = 1.5 / 1.128;
        assert!((c.mean - 11.6).abs() < 1e-12 && (c.mr_bar - 1.5).abs() < 1e-12);
        assert!((c.cp.unwrap() - 8.0 / (6.0 * sigma)).abs() < 1e-12);
        assert!((c.cpk.unwrap() - 3.6 / (3.0 * sigma)).abs() < 1e-12);
        assert!((c.mr_ucl - 3.267 * 1.5).abs() < 1e-12);
        // Sample sd: deviations -1.6, 0.4, -0.6, 1.4, 0.4; squares sum 5.2; /4 = 1.3.
        assert!((c.sd - 1.3f64.sqrt()).abs() < 1e-12);
        assert!(c.out_of_control.is_empty());
        assert!(capability(&[1.0], 0.0, 2.0).is_none());
    }

    #[test]
    fn a_point_past_the_limits_is_flagged() {
        let mut xs = vec![10.0, 10.1, 9.9, 10.0, 10.1, 9.9, 10.0, 10.1, 9.9, 10.0];
        xs.push(13.0);
        let c = capability(&xs, 9.0, 11.0).expect("values");
        assert_eq!(c.out_of_control, vec![10]);
    }
}
