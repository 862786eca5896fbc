//! A blow's load against time for a screen (issue 19, the dashboard): the measured sensor
//! load and, for a fitted blow, the fitted model's, both from first contact, with the phases
//! of docs/interfaces.md §6 (impact, forming, spring-back, post). Decimated to a few hundred points
//! a series, keeping each bucket's minimum and maximum so the peak and the ring survive.
//! Nothing here is a result: it is what the estimator already had in hand, kept for the
//! last blow, and never part of the docs/interfaces.md §5 output. Pure code.

use serde::Serialize;

use crate::estimate::{BlowEstimate, Method};
use crate::signal::segment::Blow;

/// Buckets a series is decimated to (two points each, the bucket's minimum and maximum):
/// about one per pixel column of the dashboard's plot on a 1280-pixel panel.
pub const CURVE_BUCKETS: usize = 300;
/// Measured samples kept before first contact, s.
pub const CURVE_PRE_CONTACT_S: f64 = 1e-3;
/// The post phase after the load's return to zero (docs/interfaces.md §6), s.
pub const POST_PHASE_S: f64 = 5e-3;
/// The impact phase's share of the forming time (docs/interfaces.md §6).
pub const IMPACT_SHARE_OF_FORMING: f64 = 0.1;

/// What the estimator knows of a blow's course beyond its §5 figures.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Course {
    /// The fitted model's sensor load, (s from first contact, N); empty for an observed blow.
    pub model_load: Vec<(f64, f64)>,
    /// First contact to the end of forming, s.
    pub forming_time_s: Option<f64>,
    /// End of forming until the sensor load returns to zero, s (the model's, when fitted).
    pub spring_back_time_s: Option<f64>,
}

/// One series: times from first contact, s, and loads, N.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Series {
    pub t_s: Vec<f64>,
    #[serde(rename = "load_N")]
    pub load_n: Vec<f64>,
}

/// Where each phase ends, s from first contact (`None` where the blow does not say).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Phases {
    pub impact_end_s: Option<f64>,
    pub forming_end_s: Option<f64>,
    pub spring_back_end_s: Option<f64>,
    pub post_end_s: Option<f64>,
}

/// The last blow's curve as the dashboard draws it (`GET /blow/last/curve`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlowCurve {
    pub blow: u32,
    pub method: Option<Method>,
    /// The zeroed sensor load as sampled.
    pub measured: Series,
    /// The fitted model's sensor load (empty for an observed or incomplete blow).
    pub model: Series,
    pub phases: Phases,
}

impl BlowCurve {
    /// The curve of `blow`, estimated as `e`, with what the estimator kept of its course.
    pub fn new(blow: &Blow, e: &BlowEstimate, course: Option<&Course>) -> Self {
        let from = blow.samples[blow.i_contact].t_s - CURVE_PRE_CONTACT_S;
        let measured: Vec<(f64, f64)> = blow.samples[..=blow.i_end.min(blow.samples.len() - 1)]
            .iter()
            .filter(|s| s.t_s >= from)
            .map(|s| (s.t_s - e.t_contact_s, s.load_n - blow.load_zero_n))
            .collect();
        let model = course.map_or(&[][..], |c| &c.model_load[..]);
        let phases = course.map_or(Phases::default(), |c| phases(c, &measured));
        BlowCurve {
            blow: e.blow,
            method: e.method,
            measured: decimate(&measured, CURVE_BUCKETS),
            model: decimate(model, CURVE_BUCKETS),
            phases,
        }
    }
}

/// The phases from the forming time, and the spring-back's end from the model or, for an
/// observed blow, where the measured load first returns to zero after forming.
fn phases(c: &Course, measured: &[(f64, f64)]) -> Phases {
    let Some(forming_s) = c.forming_time_s else {
        return Phases::default();
    };
    let spring_back_end_s = match c.spring_back_time_s {
        Some(sb) => Some(forming_s + sb),
        None => measured.iter().find(|(t, l)| *t > forming_s && *l <= 0.0).map(|(t, _)| *t),
    };
    Phases {
        impact_end_s: Some(IMPACT_SHARE_OF_FORMING * forming_s),
        forming_end_s: Some(forming_s),
        spring_back_end_s,
        post_end_s: spring_back_end_s.map(|t| t + POST_PHASE_S),
    }
}

/// `points` cut into `buckets` runs of equal count, each giving its minimum and maximum load
/// in time order (every point when there are fewer than twice as many as buckets).
pub fn decimate(points: &[(f64, f64)], buckets: usize) -> Series {
    let mut s = Series::default();
    let mut push = |p: &(f64, f64)| {
        s.t_s.push(p.0);
        s.load_n.push(p.1);
    };
    if points.len() <= 2 * buckets || buckets == 0 {
        points.iter().for_each(&mut push);
        return s;
    }
    let per = points.len().div_ceil(buckets);
    for run in points.chunks(per) {
        let lo = run.iter().min_by(|a, b| a.1.total_cmp(&b.1));
        let hi = run.iter().max_by(|a, b| a.1.total_cmp(&b.1));
        if let (Some(lo), Some(hi)) = (lo, hi) {
            let (first, second) = if lo.0 <= hi.0 { (lo, hi) } else { (hi, lo) };
            push(first);
            if second.0 != first.0 {
                push(second);
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_the_extremes_in_time_order_and_bounds_the_size() {
        // A 2 kHz ring sampled at 100 kHz for 20 ms: 2000 points, peaks of ±1 at known times.
        let pts: Vec<(f64, f64)> = (0..2000)
            .map(|i| {
                let t = i as f64 * 1e-5;
                (t, (2.0 * std::f64::consts::PI * 2000.0 * t).sin())
            })
            .collect();
        let s = decimate(&pts, 100);
        assert!(s.t_s.len() <= 200 && s.t_s.len() >= 100, "{} points", s.t_s.len());
        assert!(s.t_s.windows(2).all(|w| w[0] < w[1]), "time order");
        let max = s.load_n.iter().copied().fold(f64::MIN, f64::max);
        let min = s.load_n.iter().copied().fold(f64::MAX, f64::min);
        let true_max = pts.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        let true_min = pts.iter().map(|p| p.1).fold(f64::MAX, f64::min);
        assert_eq!((max, min), (true_max, true_min), "the extremes survive exactly");
        // Few points pass through untouched.
        assert_eq!(decimate(&pts[..50], 100).load_n, pts[..50].iter().map(|p| p.1).collect::<Vec<_>>());
    }

    #[test]
    fn phases_follow_contracts_section_6() {
        let c = Course { model_load: vec![], forming_time_s: Some(0.010), spring_back_time_s: Some(0.002) };
        let p = phases(&c, &[]);
        assert_eq!(p.impact_end_s, Some(0.001));
        assert_eq!(p.forming_end_s, Some(0.010));
        assert_eq!(p.spring_back_end_s, Some(0.012));
        assert!((p.post_end_s.unwrap() - 0.017).abs() < 1e-12);
        // An observed blow: the spring-back ends where the measured load first reaches zero
        // after forming (not at the zero before contact).
        let observed = Course { forming_time_s: Some(0.010), ..Course::default() };
        let measured = [(-0.001, 0.0), (0.005, 9e5), (0.011, 4e5), (0.013, -10.0), (0.014, 0.0)];
        assert_eq!(phases(&observed, &measured).spring_back_end_s, Some(0.013));
        assert_eq!(phases(&Course::default(), &measured), Phases::default());
    }
}
