//! The bounded fit: Levenberg–Marquardt (the `levenberg-marquardt` crate, a MINPACK port)
//! on the transformed parameters of `model`, from several starting points (multi-start),
//! with the Jacobian by forward differences, each column a simulation run in parallel.
//! Then the uncertainty: the covariance of ln p from the Jacobian at the optimum, inflated
//! for residuals that are correlated in time, the correlations, and which parameters the
//! data determines.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use statrs::distribution::{ContinuousCDF, StudentsT};

use super::model::{Param, ParamSet};
use super::objective::Objective;

/// Residual given to a simulation that failed (pushes the search away, never NaN).
const FAILED_RESIDUAL: f64 = 1e3;
/// Forward-difference step in u.
const FD_STEP: f64 = 1e-4;
/// The starts beyond the prior are drawn log-uniformly over this central fraction of each
/// parameter's log-range (bounds: 1/20 to 20 times the prior: starts from ~1/6 to 6 times).
const START_SPREAD: f64 = 0.6;
/// A parameter is "determined" when its relative standard error is below this...
pub const DETERMINED_REL_SE: f64 = 0.05;
/// ... and it is not at a bound. A correlation above this is named in the note: the data
/// separates the pair only through the uncertainty already in the standard error.
pub const NOTED_CORR: f64 = 0.95;

/// Residuals of a parameter vector (values, not u); `None` when the model failed.
pub type ResidualFn<'a> = dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync + 'a;

struct Problem<'a> {
    params: &'a [Param],
    f: &'a ResidualFn<'a>,
    /// Residual count, for the failure fill.
    len: usize,
    u: DVector<f64>,
    r: DVector<f64>,
}

fn from_u(params: &[Param], u: &[f64]) -> Vec<f64> {
    params.iter().zip(u).map(|(p, u)| p.from_u(*u)).collect()
}

fn eval(params: &[Param], f: &ResidualFn<'_>, len: usize, u: &[f64]) -> DVector<f64> {
    match f(&from_u(params, u)) {
        Some(r) if r.len() == len && r.iter().all(|x| x.is_finite()) => DVector::from_vec(r),
        _ => DVector::from_element(len, FAILED_RESIDUAL),
    }
}

/// Forward-difference Jacobian of the residuals in u, columns in parallel.
fn jacobian(params: &[Param], f: &ResidualFn<'_>, u: &[f64], r0: &DVector<f64>) -> DMatrix<f64> {
    let cols: Vec<DVector<f64>> = (0..u.len())
        .into_par_iter()
        .map(|j| {
            let mut up = u.to_vec();
            up[j] += FD_STEP;
            (eval(params, f, r0.len(), &up) - r0) / FD_STEP
        })
        .collect();
    DMatrix::from_columns(&cols)
}

/// The Jacobian the covariance is taken from: each column by a forward and a backward
/// difference, and of the two the smaller. Where a step crosses a kink of the residuals (an
/// event of the blow, such as the contact opening, moving across a sample), one side's
/// difference is the kink's jump over the step, and a column that large makes its
/// parameter look determined to a few hundredths of a per cent (the press's link damper:
/// 0.07 % on one seed, 0.9 % on the next). The smaller side is the one the kink spares; on
/// a smooth cost the two agree to the step.
fn covariance_jacobian(params: &[Param], f: &ResidualFn<'_>, u: &[f64], r0: &DVector<f64>) -> DMatrix<f64> {
    let cols: Vec<DVector<f64>> = (0..u.len())
        .into_par_iter()
        .map(|j| {
            let side = |h: f64| {
                let mut up = u.to_vec();
                up[j] += h;
                (eval(params, f, r0.len(), &up) - r0) / h
            };
            let (fwd, bwd) = (side(FD_STEP), side(-FD_STEP));
            if fwd.norm_squared() <= bwd.norm_squared() { fwd } else { bwd }
        })
        .collect();
    DMatrix::from_columns(&cols)
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.u.copy_from(x);
        self.r = eval(self.params, self.f, self.len, self.u.as_slice());
    }

    fn params(&self) -> DVector<f64> {
        self.u.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.r.clone())
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        Some(jacobian(self.params, self.f, self.u.as_slice(), &self.r))
    }
}

/// The residuals of an identification objective as a `ResidualFn`.
fn machine_residuals<'a>(obj: &'a Objective, set: &'a ParamSet) -> impl Fn(&[f64]) -> Option<Vec<f64>> + Sync + 'a {
    move |values: &[f64]| {
        let mut out = Vec::with_capacity(obj.len());
        obj.residuals(&set.machine(values), &mut out).then_some(out)
    }
}

/// One local search.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    pub start: Vec<f64>,
    pub values: Vec<f64>,
    /// Sum of squared weighted residuals.
    pub cost: f64,
    pub evaluations: usize,
}

/// Levenberg–Marquardt from `start` (parameter values) on an identification objective.
pub fn local_fit(obj: &Objective, set: &ParamSet, start: &[f64]) -> Run {
    let f = machine_residuals(obj, set);
    bounded_fit(&set.params, obj.len(), &f, start, PATIENCE)
}

/// Levenberg–Marquardt's evaluation budget per parameter (plus one) for identification:
/// `patience` in the `levenberg-marquardt` crate.
pub const PATIENCE: usize = 60;

/// Levenberg–Marquardt on any `len` residuals of the bounded `params`, from `start`, with at
/// most `patience`·(n + 1) evaluations of the residuals (n parameters).
pub fn bounded_fit(params: &[Param], len: usize, f: &ResidualFn<'_>, start: &[f64], patience: usize) -> Run {
    let u0: Vec<f64> = params.iter().zip(start).map(|(p, v)| p.to_u(*v)).collect();
    let r0 = eval(params, f, len, &u0);
    let problem = Problem { params, f, len, u: DVector::from_vec(u0), r: r0 };
    let (p, report) =
        LevenbergMarquardt::new().with_ftol(1e-10).with_xtol(1e-9).with_patience(patience).minimize(problem);
    let cost = p.r.norm_squared();
    Run {
        start: start.to_vec(),
        values: from_u(params, p.u.as_slice()),
        cost,
        evaluations: report.number_of_evaluations,
    }
}

/// The starting points: the prior's values, then `n - 1` drawn log-uniformly (seeded).
pub fn starts(set: &ParamSet, first: &[f64], n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out = vec![first.to_vec()];
    for _ in 1..n.max(1) {
        out.push(
            set.params
                .iter()
                .zip(first)
                .map(|(p, v)| {
                    let half = 0.5 * START_SPREAD * (p.hi.ln() - p.lo.ln());
                    let centre = v.ln().clamp(p.lo.ln() + half, p.hi.ln() - half);
                    (centre + rng.random_range(-half..=half)).exp()
                })
                .collect(),
        );
    }
    out
}

/// Uncertainty of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// Covariance of ln p (so its diagonal's roots are relative standard errors).
    pub cov_ln: DMatrix<f64>,
    pub rel_se: Vec<f64>,
    pub correlations: Vec<Vec<f64>>,
    /// Lag-1 autocorrelation of the load residuals and the variance inflation applied.
    pub residual_lag1: f64,
    pub inflation: f64,
    pub determined: Vec<bool>,
    pub notes: Vec<String>,
}

/// Fitted blows needed for the jackknife over blows (`widen_by_blows`): with two, each
/// leave-one-out fit is one blow's alone.
pub const JACKKNIFE_MIN_BLOWS: usize = 2;

/// Standard errors that cover the model's error as well as the noise: the jackknife over the
/// fitted blows (each left out in turn, refitted from `values`), whose spread shows where
/// the model explains the blows unalike, which the residuals' noise cannot. Each parameter's
/// error becomes the larger of the two, its covariance row and column scaled with it (the
/// correlations kept), and a widened one says so. Parameters held at a bound (no error)
/// stay as they are; fewer than `JACKKNIFE_MIN_BLOWS` fitted blows change nothing.
pub fn widen_by_blows(obj: &Objective, set: &ParamSet, values: &[f64], mut u: Uncertainty) -> Uncertainty {
    let fitted: Vec<usize> = (0..obj.fitted.len()).filter(|&i| obj.fitted[i]).collect();
    let n = fitted.len();
    if n < JACKKNIFE_MIN_BLOWS {
        return u;
    }
    let outs: Vec<Vec<f64>> = fitted
        .par_iter()
        .map(|&i| {
            let mut o = obj.clone();
            o.fitted[i] = false;
            local_fit(&o, set, values).values.iter().map(|v| v.ln()).collect()
        })
        .collect();
    let nf = n as f64;
    let t = one_sigma_t(n - 1);
    for k in 0..values.len() {
        let mean = outs.iter().map(|o| o[k]).sum::<f64>() / nf;
        let jack = t * ((nf - 1.0) / nf * outs.iter().map(|o| (o[k] - mean).powi(2)).sum::<f64>()).sqrt();
        let se = u.rel_se[k];
        if !(se > 0.0 && jack.is_finite() && jack > se) {
            continue;
        }
        let r = jack / se;
        for j in 0..values.len() {
            u.cov_ln[(k, j)] *= r;
            u.cov_ln[(j, k)] *= r;
        }
        u.rel_se[k] = jack;
        let mut why = format!("widened {r:.1}× to the spread over the blows (jackknife)");
        if jack >= DETERMINED_REL_SE {
            u.determined[k] = false;
            why = format!("relative standard error {:.1} %, {why}", jack * 100.0);
        }
        u.notes[k] = if u.notes[k].is_empty() { why } else { format!("{}; {why}", u.notes[k]) };
    }
    u
}

/// The factor that makes a standard error estimated with `dof` degrees of freedom a 1σ
/// band: the Student-t quantile at which ±1 of it holds 68.3 % (a normal's ±1σ). The
/// jackknife over n blows has n − 1; with two blows a bare ±1 holds 50 % (a Cauchy's),
/// which is what 12 renders of the press gave before this factor (`tests/identify_fit.rs`
/// `coverage`). 1.84 for one degree of freedom, 1.32 for two, 1.05 for twenty.
pub fn one_sigma_t(dof: usize) -> f64 {
    let inside = statrs::function::erf::erf(std::f64::consts::FRAC_1_SQRT_2);
    StudentsT::new(0.0, 1.0, dof.max(1) as f64).map_or(1.0, |t| t.inverse_cdf(0.5 + 0.5 * inside))
}

/// Covariance at the optimum `values`: s²·(JᵀJ)⁺ in ln p, with s² = cost/(n − p) and the
/// variance inflated by (1 + ρ)/(1 − ρ) for residuals correlated in time (ρ the lag-1
/// autocorrelation): neighbouring load samples are not independent measurements. Plus the
/// impact speeds' own errors (`speed_rel_sd[i]`: the relative standard error of reference
/// i's speed, `speed::impact_speed_sd_mps`; empty or 0: exact), passed through the fit:
/// the optimum moves by δln p = −(JᵀJ)⁺Jᵀ ∂r/∂ln v0 per unit of ln v0, and each speed is
/// an independent measurement, so each adds δ δᵀ·sd² (`speed_shift`). And the start heights
/// the encoder's chain gave (`Simulated::start_sd_m`): each link is known to the contact's
/// uncertainty, and moving one moves its blow's start and the chain after it, so each adds
/// δ δᵀ for its 1σ move (`height_shift`). On the independent renderer's press
/// (`tests/identify_fit.rs`, seed 7, blows 1–2 fitted) blow 2's link (1σ 36 µm) takes the
/// link spring's error from the noise's 0.16 % to 0.23 %; its fit lies 0.5 % off.
pub fn uncertainty(obj: &Objective, set: &ParamSet, values: &[f64], speed_rel_sd: &[f64]) -> Uncertainty {
    let u = set.to_u(values);
    let f = machine_residuals(obj, set);
    let r0 = eval(&set.params, &f, obj.len(), &u);
    let mut j = covariance_jacobian(&set.params, &f, &u, &r0);
    for (c, p) in set.params.iter().enumerate() {
        // A parameter the data pushed to its bound is held there: its column, a forward
        // difference where the transform has flattened divided by its near-zero slope, is
        // noise that would leak into the others' errors through the inverse (the press's
        // frame damper at 1/1000 of the prior gave the link damper's error as 0.07 % on one
        // seed and 0.9 % on the next). Its own error is infinite, as an unconstrained one.
        if p.at_bound(values[c]) {
            j.column_mut(c).fill(0.0);
        } else {
            j.column_mut(c).scale_mut(1.0 / p.dlnp_du(u[c]));
        }
    }
    let (n, np) = (r0.len() as f64, values.len() as f64);
    let s2 = r0.norm_squared() / (n - np).max(1.0);
    let rho = lag1(r0.as_slice());
    let inflation = long_run_inflation(r0.as_slice());
    let jtj = j.transpose() * &j;
    // (JᵀJ)⁻¹ through its eigenvectors: a direction the data does not constrain (an
    // eigenvalue ~0) gives the parameters along it an infinite variance, where a
    // pseudo-inverse would quietly report zero.
    let eig = jtj.clone().symmetric_eigen();
    let lmax = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let np_ = values.len();
    let mut cov_ln = DMatrix::zeros(np_, np_);
    let mut unconstrained = vec![false; np_];
    for (e, lambda) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(e);
        if *lambda > 1e-12 * lmax && lambda.is_finite() {
            cov_ln += v * v.transpose() * (s2 * inflation / lambda);
        } else {
            for (i, flag) in unconstrained.iter_mut().enumerate() {
                *flag |= v[i].abs() > 0.05;
            }
        }
    }
    let pinv_jt = {
        let mut pinv = DMatrix::zeros(np_, np_);
        for (e, lambda) in eig.eigenvalues.iter().enumerate() {
            let v = eig.eigenvectors.column(e);
            if *lambda > 1e-12 * lmax && lambda.is_finite() {
                pinv += v * v.transpose() / *lambda;
            }
        }
        pinv * j.transpose()
    };
    let chained: Option<Vec<(usize, f64)>> = obj
        .simulate(&set.machine(values))
        .map(|sims| sims.iter().enumerate().filter_map(|(i, s)| Some((i, s.start_sd_m?))).collect());
    // Each independent error's 1σ move of the optimum, δ: it adds δ δᵀ. One that cannot be
    // taken (its shifted blows do not simulate) is named in every parameter's note: the
    // errors then leave it out.
    let mut shifts: Vec<(String, Option<DVector<f64>>)> = (0..obj.refs.len())
        .into_par_iter()
        .filter_map(|i| {
            let sd = speed_rel_sd.get(i).copied().filter(|sd| *sd > 0.0 && sd.is_finite())?;
            let what = format!("{}'s impact speed", obj.refs[i].label);
            Some((what, speed_shift(obj, set, values, i, &r0, &pinv_jt).map(|d| d * sd)))
        })
        .collect();
    match chained {
        Some(chained) => shifts.par_extend(chained.into_par_iter().map(|(i, sd)| {
            (format!("{}'s chained start height", obj.refs[i].label), height_shift(obj, set, values, i, sd, &pinv_jt))
        })),
        None => shifts.push(("the chained start heights".to_string(), None)),
    }
    let mut left_out = Vec::new();
    for (what, d) in &shifts {
        match d {
            Some(d) => cov_ln += d * d.transpose(),
            None => left_out.push(what.as_str()),
        }
    }
    for (i, flag) in unconstrained.iter().enumerate() {
        if *flag {
            cov_ln[(i, i)] = f64::INFINITY;
        }
    }
    let k = values.len();
    let rel_se: Vec<f64> = (0..k).map(|i| cov_ln[(i, i)].max(0.0).sqrt()).collect();
    let correlations: Vec<Vec<f64>> = (0..k)
        .map(|a| {
            (0..k)
                .map(|b| if a == b { 1.0 } else { cov_ln[(a, b)] / (rel_se[a] * rel_se[b]).max(f64::MIN_POSITIVE) })
                .collect()
        })
        .collect();
    let mut determined = Vec::new();
    let mut notes = Vec::new();
    for i in 0..k {
        let p = &set.params[i];
        let worst =
            (0..k).filter(|&b| b != i).max_by(|&a, &b| correlations[i][a].abs().total_cmp(&correlations[i][b].abs()));
        let mut note = Vec::new();
        if p.at_bound(values[i]) {
            note.push(format!("at the search bound [{:.3e}, {:.3e}]", p.lo, p.hi));
        }
        if rel_se[i].is_nan() || rel_se[i] >= DETERMINED_REL_SE {
            note.push(format!("relative standard error {:.1} %", rel_se[i] * 100.0));
        }
        determined.push(note.is_empty());
        if let Some(b) = worst.filter(|&b| correlations[i][b].abs() > NOTED_CORR) {
            note.push(format!("correlated with {} (r = {:.3})", set.params[b].key, correlations[i][b]));
        }
        if !left_out.is_empty() {
            note.push(format!("without the error of {} (the fit did not simulate it moved)", left_out.join(", ")));
        }
        notes.push(note.join("; "));
    }
    Uncertainty { cov_ln, rel_se, correlations, residual_lag1: rho, inflation, determined, notes }
}

/// Step in ln v0 of the speed's finite difference: 1e-4, as `FD_STEP` in u.
const SPEED_FD_STEP: f64 = 1e-4;

/// How far the optimum moves in ln p per unit of ln v0 of reference `i`: −(JᵀJ)⁺Jᵀ ∂r/∂ln v0,
/// the derivative by a forward difference (`None`: the shifted reference did not simulate).
fn speed_shift(
    obj: &Objective,
    set: &ParamSet,
    values: &[f64],
    i: usize,
    r0: &DVector<f64>,
    pinv_jt: &DMatrix<f64>,
) -> Option<DVector<f64>> {
    let mut shifted = obj.clone();
    shifted.refs[i].v0_mps *= SPEED_FD_STEP.exp();
    let r = machine_residuals(&shifted, set)(values)?;
    if r.len() != r0.len() {
        return None;
    }
    let g = (DVector::from_vec(r) - r0) / SPEED_FD_STEP;
    Some(-(pinv_jt * g))
}

/// How far the optimum moves in ln p for a 1σ move (`sd_m`) of reference `i`'s chained start
/// height: −(JᵀJ)⁺Jᵀ ∂r/∂h·sd, the derivative by a central difference at ±sd (a step the
/// size of the uncertainty itself: the cost is not smooth finer than that, where a chained
/// blow's model contact crosses the point at which it is simulated again). `None`: a shifted
/// objective did not simulate.
fn height_shift(
    obj: &Objective,
    set: &ParamSet,
    values: &[f64],
    i: usize,
    sd_m: f64,
    pinv_jt: &DMatrix<f64>,
) -> Option<DVector<f64>> {
    let up = machine_residuals(&obj.with_start_offset(i, sd_m), set)(values)?;
    let down = machine_residuals(&obj.with_start_offset(i, -sd_m), set)(values)?;
    if up.len() != down.len() || up.len() != pinv_jt.ncols() {
        return None;
    }
    let g = (DVector::from_vec(up) - DVector::from_vec(down)) / 2.0;
    Some(-(pinv_jt * g))
}

/// The variance inflation of residuals correlated in time: their long-run variance over
/// their variance, γ(0) + 2 Σ γ(k) over γ(0), summed over the initial positive sequence of
/// pairs (Geyer 1992: the sum stops where γ(2m) + γ(2m+1) first falls to zero or below),
/// at least 1.
///
/// Not the AR(1) form (1 + ρ)/(1 − ρ) from the lag-1 correlation ρ alone: where the model
/// misses a slow part of the load, the residual is white noise plus that part, the noise
/// dilutes ρ, and the geometric decay it implies ends the slow part's correlation far too
/// early (`tests/identify_fit.rs`: the independent renderer's clean hammer, whose residual
/// is 1.7 times its noise, was covered by its 1σ in 1 parameter of 4).
fn long_run_inflation(r: &[f64]) -> f64 {
    let n = r.len();
    if n < 3 {
        return 1.0;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let gamma = |k: usize| r[..n - k].iter().zip(&r[k..]).map(|(a, b)| (a - mean) * (b - mean)).sum::<f64>() / n as f64;
    let g0 = gamma(0);
    if g0 <= 0.0 {
        return 1.0;
    }
    let mut sum = g0;
    let mut k = 1;
    while k + 1 < n {
        let pair = gamma(k) + gamma(k + 1);
        if pair <= 0.0 {
            break;
        }
        sum += 2.0 * pair;
        k += 2;
    }
    (sum / g0).clamp(1.0, n as f64)
}

/// Lag-1 autocorrelation of a sequence.
fn lag1(r: &[f64]) -> f64 {
    let n = r.len();
    if n < 3 {
        return 0.0;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let var: f64 = r.iter().map(|x| (x - mean).powi(2)).sum();
    let cov: f64 = r.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
    if var > 0.0 { (cov / var).clamp(-0.99, 0.99) } else { 0.0 }
}

/// Parameter sets drawn from the fit's uncertainty: ln p ~ N(ln p̂, cov) (the hammer
/// paper's Monte Carlo study of §2.5, on the identified parameters), clamped to the bounds.
pub fn draw(set: &ParamSet, values: &[f64], cov_ln: &DMatrix<f64>, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let k = values.len();
    let l = cov_ln.clone().cholesky().map(|c| c.l()).unwrap_or_else(|| {
        DMatrix::from_diagonal(&DVector::from_iterator(k, (0..k).map(|i| cov_ln[(i, i)].max(0.0).sqrt())))
    });
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = rand_distr::StandardNormal;
    (0..n)
        .map(|_| {
            let z =
                DVector::from_iterator(k, (0..k).map(|_| rand_distr::Distribution::<f64>::sample(&normal, &mut rng)));
            let d = &l * z;
            set.params
                .iter()
                .zip(values)
                .enumerate()
                .map(|(i, (p, v))| (v.ln() + d[i]).exp().clamp(p.lo, p.hi))
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::one_sigma_t;

    /// Student t quantiles at 0.8413 from a table (Abramowitz & Stegun 26.7, interpolated):
    /// one degree of freedom is the Cauchy's tan(0.3413 π), two (2p − 1)/√(2p(1 − p)).
    #[test]
    fn the_one_sigma_factor_is_the_t_quantile_and_tends_to_one() {
        let p: f64 = 0.841_344_7;
        let cauchy = (std::f64::consts::PI * (p - 0.5)).tan();
        let two = (2.0 * p - 1.0) / (2.0 * p * (1.0 - p)).sqrt();
        assert!((one_sigma_t(1) - cauchy).abs() < 1e-6, "{}", one_sigma_t(1));
        assert!((one_sigma_t(2) - two).abs() < 1e-6, "{}", one_sigma_t(2));
        assert!((one_sigma_t(1000) - 1.0).abs() < 2e-3);
        assert_eq!(one_sigma_t(0), one_sigma_t(1));
    }
}
