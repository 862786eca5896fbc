//! What a blow records while the integrator runs: the sensor's peak, the exits from plastic
//! flow and the sensor's zeros (the indicators of the hammer paper §3.1.3), the separation
//! that ends the blow, and the sampled trace, on the general plant or its specialisation
//! (`Integrated`). In an exact phase of the base hammer the samples and the peak come from
//! the grid points of the exact flow (`exact_points`).

use super::{FORMING_CREEP_M, Forming, TraceEnd, TracePoint};
use crate::physics::integrator::{self, Hybrid, Observer};
use crate::physics::plant::{BaseHammer, Contact, GridPoint, Mode, N, NB, Plant};

/// What a traced blow keeps at each sample.
pub(super) enum Trace {
    /// Every output (`Plant::outputs`).
    Outputs(Vec<TracePoint>),
    /// The sensor's load alone, N: all a fit compares, and it needs no billet law.
    Sensor(Vec<f64>),
}

/// A plant the blow is integrated on: the general `Plant`, or its specialisation on a
/// smaller state (`BaseHammer`), which hands its states back in the general layout.
pub(super) trait Integrated<const M: usize>: Hybrid<M, Mode = Mode> {
    fn sensor_at(&self, y: &[f64; M], mode: Mode) -> f64;
    fn sensor_rate(&self, y: &[f64; M], dy: &[f64; M], mode: Mode) -> f64;
    /// The state in the general plant's layout.
    fn full(&self, y: &[f64; M]) -> [f64; N];
    /// The sensor on the step's cubic Hermite interpolant at `theta`.
    #[allow(clippy::too_many_arguments)]
    fn sensor_within(
        &self,
        y0: &[f64; M],
        dy0: &[f64; M],
        y1: &[f64; M],
        dy1: &[f64; M],
        h: f64,
        theta: f64,
        mode: Mode,
    ) -> f64 {
        self.sensor_at(&integrator::hermite(y0, dy0, y1, dy1, h, theta), mode)
    }
    /// In an exact step from a grid point (`BaseHammer::grid_points`), `f` at each grid
    /// point within it; false (the default), and no call, otherwise.
    fn grid_points<F: FnMut(&GridPoint)>(&self, _t0: f64, _y0: &[f64; M], _mode: Mode, _h: f64, _f: F) -> bool {
        false
    }
    /// The whole state at a grid point `grid_points` gave.
    fn grid_point_state(&self, _t0: f64, _y0: &[f64; M], _mode: Mode, _p: &GridPoint) -> [f64; M] {
        unreachable!("grid_point_state without grid points")
    }
}

impl Integrated<N> for Plant {
    fn sensor_at(&self, y: &[f64; N], mode: Mode) -> f64 {
        Plant::sensor_at(self, y, mode)
    }
    fn sensor_rate(&self, y: &[f64; N], dy: &[f64; N], mode: Mode) -> f64 {
        Plant::sensor_rate(self, y, dy, mode)
    }
    fn full(&self, y: &[f64; N]) -> [f64; N] {
        *y
    }
}

impl Integrated<NB> for BaseHammer<'_> {
    fn sensor_at(&self, y: &[f64; NB], _mode: Mode) -> f64 {
        BaseHammer::sensor_at(self, y)
    }
    fn sensor_rate(&self, y: &[f64; NB], dy: &[f64; NB], _mode: Mode) -> f64 {
        BaseHammer::sensor_rate(self, y, dy)
    }
    fn full(&self, y: &[f64; NB]) -> [f64; N] {
        self.expand(y)
    }
    fn sensor_within(
        &self,
        y0: &[f64; NB],
        dy0: &[f64; NB],
        y1: &[f64; NB],
        dy1: &[f64; NB],
        h: f64,
        theta: f64,
        _mode: Mode,
    ) -> f64 {
        BaseHammer::sensor_within(self, y0, dy0, y1, dy1, h, theta)
    }
    fn grid_points<F: FnMut(&GridPoint)>(&self, t0: f64, y0: &[f64; NB], mode: Mode, h: f64, f: F) -> bool {
        BaseHammer::grid_points(self, t0, y0, mode, h, f)
    }
    fn grid_point_state(&self, t0: f64, y0: &[f64; NB], mode: Mode, p: &GridPoint) -> [f64; NB] {
        BaseHammer::grid_point_state(self, t0, y0, mode, p)
    }
}

/// What a blow records while the integrator runs.
pub(super) struct Record {
    pub(super) post_s: f64,
    /// The sensor's peak so far; `None` where it is not kept (a fit's blow,
    /// `simulate_blow_sensor_until`: a walk over every sample that no fit reads).
    pub(super) peak_n: Option<f64>,
    /// Every exit from plastic flow: (t, h, sensor load).
    pub(super) plastic_exits: Vec<(f64, f64, f64)>,
    /// Every instant the sensor load reached zero outside plastic flow, after the first exit.
    pub(super) sensor_zeros: Vec<f64>,
    pub(super) separation: Option<(f64, [f64; N], Mode)>,
    pub(super) trace_dt: Option<f64>,
    pub(super) next_sample: f64,
    pub(super) trace: Trace,
    /// Sensor load and its rate at the end of the last step, reused as the next step's start.
    pub(super) last_end: Option<(f64, f64, f64)>,
    /// Where the trace may end (`simulate_blow_sensor_until`), and the instant that makes,
    /// once a sample has reached the threshold.
    pub(super) trace_end: Option<TraceEnd>,
    pub(super) end_at_s: Option<f64>,
}

impl Record {
    /// Where the blow stops: once the contact has opened, `post_s` after that, or the trace's
    /// end if that is known (and not before the opening); `None` before.
    fn stop_s(&self) -> Option<f64> {
        let (t_sep, _, _) = self.separation.as_ref()?;
        Some(self.end_at_s.map_or(t_sep + self.post_s, |t| t.max(*t_sep)))
    }

    /// Note the sample `sensor_n` at `t_s` (before `next_sample` moves on): `ends_at`.
    fn sampled(&mut self, t_s: f64, sensor_n: f64) {
        ends_at(self.trace_end, &mut self.end_at_s, t_s, sensor_n);
    }
}

/// The first sample at or above the trace end's threshold fixes where the trace may end
/// (`Record::end_at_s`).
#[inline(always)]
fn ends_at(trace_end: Option<TraceEnd>, end_at_s: &mut Option<f64>, t_s: f64, sensor_n: f64) {
    if let (Some(e), None) = (trace_end, *end_at_s)
        && sensor_n >= e.threshold_n
    {
        *end_at_s = Some(t_s + e.after_s);
    }
}

/// Records indicators while `sys` (`plant` or its specialisation) is integrated.
pub(super) struct Recorder<'a, S> {
    pub(super) plant: &'a Plant,
    pub(super) sys: &'a S,
    pub(super) r: Record,
    /// The grid points of the last exact step (`exact_points`).
    pub(super) points: Vec<GridPoint>,
}

impl<const M: usize, S: Integrated<M>> Observer<M, Mode> for Recorder<'_, S> {
    fn on_step(
        &mut self,
        t0: f64,
        y0: &[f64; M],
        dy0: &[f64; M],
        t1: f64,
        y1: &[f64; M],
        dy1: &[f64; M],
        mode: Mode,
    ) -> Option<f64> {
        let (sys, r) = (self.sys, &mut self.r);
        let h = t1 - t0;
        // Peak of the sensor load within the step: the cubic through both ends.
        let (s0, rate0) = match r.last_end {
            Some((t, s, rate)) if t == t0 => (s, rate),
            _ => (sys.sensor_at(y0, mode), sys.sensor_rate(y0, dy0, mode)),
        };
        let s1 = sys.sensor_at(y1, mode);
        let rate1 = sys.sensor_rate(y1, dy1, mode);
        r.last_end = Some((t1, s1, rate1));
        let (r0, r1) = (rate0 * h, rate1 * h);
        if let Some(p) = &mut r.peak_n {
            *p = p.max(s0).max(s1);
        }
        if exact_points(sys, self.plant, r, &mut self.points, t0, y0, mode, h, (s0, rate0), (t1, s1, rate1)) {
            return r.stop_s();
        }
        if let Some(p) = &mut r.peak_n
            && h > 0.0
        {
            for theta in cubic_extrema(s0, r0, s1, r1) {
                *p = p.max(hermite_scalar(s0, r0, s1, r1, theta));
            }
        }
        if let Some(dt) = r.trace_dt {
            while r.next_sample <= t1 && h > 0.0 {
                let theta = ((r.next_sample - t0) / h).clamp(0.0, 1.0);
                let sensor_n = match r.trace {
                    Trace::Outputs(ref mut v) => {
                        let y = sys.full(&integrator::hermite(y0, dy0, y1, dy1, h, theta));
                        let out = self.plant.outputs(&y, mode);
                        v.push(TracePoint { t_s: r.next_sample, out });
                        out.sensor_n
                    }
                    Trace::Sensor(ref mut v) => {
                        let s = sys.sensor_within(y0, dy0, y1, dy1, h, theta, mode);
                        v.push(s);
                        s
                    }
                };
                r.sampled(r.next_sample, sensor_n);
                r.next_sample += dt;
            }
        }
        r.stop_s()
    }

    fn on_event(&mut self, t: f64, y: &[f64; M], from: Mode, to: Mode, _guard: u8) {
        let y = &self.sys.full(y);
        let r = &mut self.r;
        // The mode (and possibly the state) changed: the cached step end is stale.
        r.last_end = None;
        if from.contact == Contact::Plastic && to.contact != Contact::Plastic {
            let o = self.plant.outputs(y, to);
            r.plastic_exits.push((t, o.h_m, o.sensor_n));
        }
        if to.contact != Contact::Plastic && !r.plastic_exits.is_empty() && self.plant.outputs(y, to).sensor_n <= 0.0 {
            r.sensor_zeros.push(t);
        }
        // The blow has ended when the tools part with the support path closed: with a
        // clearance, ram and lower tool can fly apart together before the gap has closed.
        // A lower mass that has bounced off its support (rising, the gap opening) with the
        // tools apart ends it too, whichever came first: the model has no gravity to bring
        // it back.
        let parted = to.contact == Contact::Free && from.contact != Contact::Free;
        let lifted = to.contact == Contact::Free && from.engaged && !to.engaged;
        if (parted || lifted) && (to.engaged || self.plant.support_opening(y)) {
            r.separation = Some((t, *y, to));
        } else if from.contact == Contact::Free && to.contact != Contact::Free {
            r.separation = None;
        }
    }
}

/// A trace sample this fraction of the sample period from a grid point is taken there (the
/// sample instants accumulate `dt` and drift from the grid's by roundoff).
const SAMPLE_SNAP: f64 = 1e-6;

/// The peak and the trace samples of an exact step from a grid point, from the sensor at
/// each grid point within it (exact) and the cubic between neighbours (for the peak);
/// false, and nothing recorded, where the step is not one (`Integrated::grid_points`).
///
/// Where the peak is kept, the points are gathered into `points` first (kept from step to
/// step) and then walked twice, for the peak and for the samples: each pass is a short loop
/// the compiler keeps in registers, where one pass interleaving both went through memory at
/// every point. A fit's blow keeps no peak and only the sensor (`sensor_points`).
#[allow(clippy::too_many_arguments)]
fn exact_points<const M: usize, S: Integrated<M>>(
    sys: &S,
    plant: &Plant,
    r: &mut Record,
    points: &mut Vec<GridPoint>,
    t0: f64,
    y0: &[f64; M],
    mode: Mode,
    h: f64,
    (s0, rate0): (f64, f64),
    end: (f64, f64, f64),
) -> bool {
    if r.peak_n.is_none()
        && let (Some(dt), Trace::Sensor(v)) = (r.trace_dt, &mut r.trace)
    {
        return sensor_points(sys, v, (&mut r.next_sample, &mut r.end_at_s, r.trace_end), dt, t0, y0, mode, h, s0);
    }
    points.clear();
    if !sys.grid_points(t0, y0, mode, h, |p: &GridPoint| points.push(*p)) {
        return false;
    }
    let Some(last) = points.last() else { return true };
    if let Some(mut peak) = r.peak_n {
        let mut prev = (t0, s0, rate0);
        for p in points.iter() {
            let here = (p.t_s, p.sensor_n, p.rate);
            peak_between(&mut peak, prev, here);
            prev = here;
        }
        if end.0 > last.t_s {
            // A step cut short of a grid point by the stop: no sample can fall after the last.
            peak_between(&mut peak, prev, end);
        }
        r.peak_n = Some(peak);
    }
    let Some(dt) = r.trace_dt else { return true };
    let snap = SAMPLE_SNAP * dt;
    // The samples up to each grid point (to roundoff): first those up to the step's start
    // (left by the previous step), then those up to each point inside it.
    let at = |k: usize| points.get(k.wrapping_sub(1));
    let Record { trace, next_sample, trace_end, end_at_s, .. } = r;
    for k in 0..=points.len() {
        let (t, s) = at(k).map_or((t0, s0), |p| (p.t_s, p.sensor_n));
        while *next_sample <= t + snap {
            match trace {
                Trace::Sensor(v) => v.push(s),
                Trace::Outputs(v) => {
                    let y = at(k).map_or(*y0, |p| sys.grid_point_state(t0, y0, mode, p));
                    v.push(TracePoint { t_s: *next_sample, out: plant.outputs(&sys.full(&y), mode) })
                }
            }
            ends_at(*trace_end, end_at_s, *next_sample, s);
            *next_sample += dt;
        }
    }
    true
}

/// `exact_points` with no peak to keep and the sensor's samples alone: each grid point's
/// sample is pushed as the point is computed, with the sample clock and the trace's end
/// held in registers and handed back at the end; false, and nothing recorded, where the
/// step is not an exact one from a grid point.
#[allow(clippy::too_many_arguments)]
fn sensor_points<const M: usize, S: Integrated<M>>(
    sys: &S,
    v: &mut Vec<f64>,
    (next_sample, end_at_s, trace_end): (&mut f64, &mut Option<f64>, Option<TraceEnd>),
    dt: f64,
    t0: f64,
    y0: &[f64; M],
    mode: Mode,
    h: f64,
    s0: f64,
) -> bool {
    let kept = v.len();
    let snap = SAMPLE_SNAP * dt;
    let (mut next, mut end_at) = (*next_sample, *end_at_s);
    let mut take = |t: f64, s: f64| {
        while next <= t + snap {
            v.push(s);
            ends_at(trace_end, &mut end_at, next, s);
            next += dt;
        }
    };
    // The samples up to the step's start (left by the previous step), then up to each point.
    take(t0, s0);
    if !sys.grid_points(t0, y0, mode, h, |p: &GridPoint| take(p.t_s, p.sensor_n)) {
        v.truncate(kept);
        return false;
    }
    (*next_sample, *end_at_s) = (next, end_at);
    true
}

/// `*peak = peak.max(x)` for a peak that is not NaN (the recorder's starts at 0), as a
/// predicted branch: `f64::max`'s NaN handling put five instructions per point on the
/// walk's dependency chain.
#[inline(always)]
fn raise(peak: &mut f64, x: f64) {
    if x > *peak {
        *peak = x;
    }
}

/// Raise `peak` to the largest value of the cubic Hermite through `(t, s, rate)` at both
/// ends. The cubic stays within `max(s_a, s_b) + 4/27 (|r_a| + |r_b|) h` (the Hermite basis'
/// bounds), so a segment below the peak by that much is skipped; and so is one whose scaled
/// slopes are both of the change's sign and at most 3 times it: such a cubic is monotone
/// (Fritsch and Carlson 1980, the square of their monotonicity region), its largest value
/// at an end.
///
/// The tests that skip are inlined into the walk over the grid points (once per point);
/// the cubic's extrema are not.
#[inline(always)]
fn peak_between(peak: &mut f64, (ta, sa, ra): (f64, f64, f64), (tb, sb, rb): (f64, f64, f64)) {
    let h = tb - ta;
    let (r0, r1) = (ra * h, rb * h);
    raise(peak, sa);
    raise(peak, sb);
    if h <= 0.0 || (if sa > sb { sa } else { sb }) + 0.15 * (r0.abs() + r1.abs()) < *peak {
        return;
    }
    peak_inside(peak, sa, r0, sb, r1);
}

/// `peak_between` past its first test.
#[inline(never)]
fn peak_inside(peak: &mut f64, sa: f64, r0: f64, sb: f64, r1: f64) {
    let d = sb - sa;
    let within = |r: f64| if d > 0.0 { (0.0..=3.0 * d).contains(&r) } else { (3.0 * d..=0.0).contains(&r) };
    if d != 0.0 && within(r0) && within(r1) {
        return;
    }
    for theta in cubic_extrema(sa, r0, sb, r1) {
        *peak = peak.max(hermite_scalar(sa, r0, sb, r1, theta));
    }
}

/// The end of forming is the first exit from plastic flow after which the billet loses less
/// than `FORMING_CREEP_M` more height: near the end the stick force can hover at the flow
/// load, and a sub-micrometre re-entry must not move the end of forming (docs/interfaces.md §4:
/// "numerical creep after that instant does not move it").
pub(super) fn forming_indicators(exits: &[(f64, f64, f64)], zeros: &[f64], h_start_m: f64, t_sep: f64) -> Forming {
    let Some(&(_, h_final, _)) = exits.last() else {
        // The billet never yielded: a fully elastic blow. Forming ends at first contact
        // (load 0), and the spring-back is the whole contact.
        return Forming { h_end_m: h_start_m, final_load_n: 0.0, forming_time_s: 0.0, spring_back_time_s: Some(t_sep) };
    };
    let &(t_end, h_end, load) =
        exits.iter().find(|e| e.1 - h_final < FORMING_CREEP_M).expect("the last exit qualifies");
    Forming {
        h_end_m: h_end,
        final_load_n: load,
        forming_time_s: t_end,
        // A sensor already at or below zero when forming ends (a high-passed sensor) has a
        // spring-back of 0.
        spring_back_time_s: zeros.iter().find(|&&t| t >= t_end).map(|t| t - t_end),
    }
}

/// Extrema of the cubic Hermite segment of a scalar (values s0, s1, scaled slopes r0, r1)
/// inside (0, 1).
fn cubic_extrema(s0: f64, r0: f64, s1: f64, r1: f64) -> impl Iterator<Item = f64> {
    // s(θ) = a θ^3 + b θ^2 + r0 θ + s0
    let a = 2.0 * s0 + r0 - 2.0 * s1 + r1;
    let b = -3.0 * s0 - 2.0 * r0 + 3.0 * s1 - r1;
    // s'(θ) = 3a θ^2 + 2b θ + r0
    let (qa, qb, qc) = (3.0 * a, 2.0 * b, r0);
    let mut roots = [f64::NAN; 2];
    if qa.abs() < 1e-300 {
        if qb != 0.0 {
            roots[0] = -qc / qb;
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            roots = [(-qb + sq) / (2.0 * qa), (-qb - sq) / (2.0 * qa)];
        }
    }
    roots.into_iter().filter(|t| *t > 0.0 && *t < 1.0)
}

fn hermite_scalar(s0: f64, r0: f64, s1: f64, r1: f64, theta: f64) -> f64 {
    integrator::hermite(&[s0], &[r0], &[s1], &[r1], 1.0, theta)[0]
}
