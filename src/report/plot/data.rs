//! The data side of a plot: runs of drawable points, their extents and axis ranges, and
//! the decimation of a long record to its envelope. No drawing here.

use std::ops::Range;

use super::LOG_Y_MAX_DECADES;

/// Splits paired values into runs of consecutive points that can be drawn: each value
/// finite and, on a log axis, every y positive.
pub(super) fn runs<const N: usize>(x: &[f64], ys: [&[f64]; N], log_y: bool) -> Vec<Run<N>> {
    let n = ys.iter().map(|y| y.len()).fold(x.len(), usize::min);
    let mut runs = Vec::new();
    let mut run = Vec::new();
    for i in 0..n {
        let y = ys.map(|y| y[i]);
        if x[i].is_finite() && y.iter().all(|v| v.is_finite() && (!log_y || *v > 0.0)) {
            run.push((x[i], y));
        } else if !run.is_empty() {
            runs.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    runs
}

/// The smallest range holding every value, or `None` for none.
pub(super) fn extent(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// `lo..hi` widened by `pad` of its span on each side, or around a single value.
pub(super) fn padded(lo: f64, hi: f64, pad: f64) -> Range<f64> {
    let span = hi - lo;
    if span > 0.0 {
        (lo - pad * span)..(hi + pad * span)
    } else {
        let half = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
        (lo - half)..(hi + half)
    }
}

/// The y range of a log axis: the data's, capped at [`LOG_Y_MAX_DECADES`], with a little
/// room, and widened to the powers of ten around it when it would hold fewer than two
/// (plotters labels a log axis only at powers of ten).
pub(super) fn log_range(lo: f64, hi: f64) -> Range<f64> {
    let lo = lo.max(hi * 10f64.powf(-LOG_Y_MAX_DECADES));
    let (mut lo, mut hi) = if hi > lo {
        let pad = (hi / lo).powf(0.04);
        (lo / pad, hi * pad)
    } else {
        (lo / 10.0, hi * 10.0)
    };
    let decades = |lo: f64, hi: f64| hi.log10().floor() - lo.log10().ceil() + 1.0;
    if decades(lo, hi) < 2.0 {
        lo = 10f64.powf(lo.log10().floor());
    }
    if decades(lo, hi) < 2.0 {
        hi = 10f64.powf(hi.log10().ceil());
    }
    lo..hi
}

/// A run of consecutive drawable points, each x with N y values.
pub(super) type Run<const N: usize> = Vec<(f64, [f64; N])>;

/// `run` cut to about `columns` chunks of consecutive points, each kept as its lowest and
/// highest point in their order, so that a long record draws the same envelope with at
/// most `2 * columns` points (x is assumed to run one way, as time and frequency do).
pub(super) fn decimate_line(run: Run<1>, columns: usize) -> Run<1> {
    if run.len() <= 2 * columns.max(1) {
        return run;
    }
    let chunk = run.len().div_ceil(columns.max(1));
    let mut out = Vec::with_capacity(2 * columns + 2);
    for part in run.chunks(chunk) {
        let by_y = |a: &&(f64, [f64; 1]), b: &&(f64, [f64; 1])| a.1[0].total_cmp(&b.1[0]);
        let lo = part.iter().enumerate().min_by(|a, b| by_y(&a.1, &b.1)).map_or(0, |(i, _)| i);
        let hi = part.iter().enumerate().max_by(|a, b| by_y(&a.1, &b.1)).map_or(0, |(i, _)| i);
        out.push(part[lo.min(hi)]);
        if lo != hi {
            out.push(part[lo.max(hi)]);
        }
    }
    out
}

/// `run` cut to about `columns` chunks, each kept as the envelope of its band (lowest `lo`,
/// highest `hi`) at its first and last x.
pub(super) fn decimate_band(run: Run<2>, columns: usize) -> Run<2> {
    if run.len() <= 2 * columns.max(1) {
        return run;
    }
    let chunk = run.len().div_ceil(columns.max(1));
    let mut out = Vec::with_capacity(2 * columns + 2);
    for part in run.chunks(chunk) {
        let lo = part.iter().map(|p| p.1[0]).fold(f64::INFINITY, f64::min);
        let hi = part.iter().map(|p| p.1[1]).fold(f64::NEG_INFINITY, f64::max);
        let (first, last) = (part[0].0, part[part.len() - 1].0);
        out.push((first, [lo, hi]));
        if part.len() > 1 {
            out.push((last, [lo, hi]));
        }
    }
    out
}
