//! The evidence that one model's holdout errors are lower than another's (issue #17, item
//! 2): two paired one-sided t-tests over the blows and an exact sign test, any of which
//! suffices.
//!
//! - On the per-blow log-ratio ln(after/before): an effect that scales every blow's error.
//!   The holdout blows of a billet differ in speed, so their errors differ in size; the
//!   log-ratio removes that scale, which the former rule (mean difference over twice its
//!   standard error) carried into its variance, losing cases that shrank the error by
//!   0.6–0.7 on 5 blows.
//! - On the per-blow difference before − after: an effect that removes error where the error
//!   is large and leaves noise-sized blows alone (friction rising as the billet flattens
//!   acts on the last blows; their first blows' log-ratios are noise and swamp the test).
//! - An exact sign test: `after` lower on so many blows that a coin would do as well with
//!   probability at most `ALPHA` (on 5 blows: all 5). It passes an effect that lowers every
//!   blow's error but one blow's far more than the others' (a press clearance that mostly
//!   acts on a billet's first blow: ratios 0.09, 0.76, 0.82, 0.76, 0.82), whose log-ratios and
//!   differences both scatter too much for their t-tests (family report seeds 4902/4904,
//!   issue 41; on the tune seeds 4100-4105 the sign test passes no single effect, on any
//!   case, that the t-tests did not).
//!
//! Chosen on the tuning seeds of `rates.rs`: the log-ratio alone missed 1 of 20
//! `friction_rise:exponent=0.03` hammer billets (shrink 0.65–0.72) that the difference
//! (then at the former 2 standard errors) found; both at 2.5 % (a Bonferroni union) lost half the runs of the weakest cases; an
//! exact sign-flip test on the log-ratios cannot pass `thermal` (whose first blow is
//! unchanged by definition) at 5 % on 5 blows. The t-tests' union's nominal level is ≤ 2 × `ALPHA`;
//! the verdict's false-positive rate on no-effect billets, which also passes the noise and
//! shrink gates, is measured by `rates.rs`; with the sign test the union's nominal level is
//! ≤ 3 × `ALPHA`, and the family's false positives on none are measured by
//! tests/diagnose_family_rates.rs.

/// One-sided level of the test.
pub const ALPHA: f64 = 0.05;

/// The tests in words, for the rule the report and the command print.
pub const TESTS: &str = "paired one-sided tests over the holdout blows: t-tests on ln(after/before) or on before - after, or an exact sign test on the blows lowered; any suffices";

/// One-sided 95 % quantiles of Student's t for 1..=30 degrees of freedom (any table, e.g.
/// NIST/SEMATECH e-Handbook §1.3.6.7.2); beyond 30, the normal's 1.645.
const T95: [f64; 30] = [
    6.314, 2.920, 2.353, 2.132, 2.015, 1.943, 1.895, 1.860, 1.833, 1.812, 1.796, 1.782, 1.771, 1.761, 1.753, 1.746,
    1.740, 1.734, 1.729, 1.725, 1.721, 1.717, 1.714, 1.711, 1.708, 1.706, 1.703, 1.701, 1.699, 1.697,
];

fn t95(dof: usize) -> f64 {
    T95.get(dof.wrapping_sub(1)).copied().unwrap_or(1.645)
}

/// The paired comparison of `after` with `before`, blow by blow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Comparison {
    /// Mean over the blows of ln(after/before): negative when `after` is lower.
    pub mean_log_ratio: f64,
    /// Its standard error (blow-to-blow scatter over √n).
    pub std_error: f64,
    /// The one-sided critical value for `n − 1` degrees of freedom.
    pub t_critical: f64,
    /// Mean over the blows of before − after, and its standard error.
    pub mean_diff: f64,
    pub diff_std_error: f64,
    /// 1 − mean(after)/mean(before): the contract's `holdout_shrink`.
    pub shrink: f64,
    /// The exact one-sided sign test's p-value: the chance of `after` lower on at least as
    /// many of the blows if each were a fair coin.
    pub sign_p: f64,
}

/// P(X ≥ k) for X ~ Binomial(n, 1/2).
fn binomial_tail(n: usize, k: usize) -> f64 {
    let mut c = 1.0; // C(n, 0)
    let mut tail = 0.0;
    for i in 0..=n {
        if i >= k {
            tail += c;
        }
        c = c * (n - i) as f64 / (i + 1) as f64;
    }
    tail / 2f64.powi(n as i32)
}

/// Mean and standard error of the mean (n ≥ 2).
fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    (m, sd / n.sqrt())
}

impl Comparison {
    /// Compare per-blow errors (the same blows, in the same order). `None` with fewer than
    /// two blows, blows of different count, or an error that is not positive and finite.
    pub fn of(before: &[f64], after: &[f64]) -> Option<Comparison> {
        let n = before.len();
        if n < 2 || after.len() != n || before.iter().chain(after).any(|x| !(x.is_finite() && *x > 0.0)) {
            return None;
        }
        let l: Vec<f64> = before.iter().zip(after).map(|(b, a)| (a / b).ln()).collect();
        let d: Vec<f64> = before.iter().zip(after).map(|(b, a)| b - a).collect();
        let (mean_log_ratio, std_error) = mean_se(&l);
        let (mean_diff, diff_std_error) = mean_se(&d);
        let shrink = 1.0 - after.iter().sum::<f64>() / before.iter().sum::<f64>();
        let lower = before.iter().zip(after).filter(|(b, a)| a < b).count();
        let sign_p = binomial_tail(n, lower);
        Some(Comparison {
            mean_log_ratio,
            std_error,
            t_critical: t95(n - 1),
            mean_diff,
            diff_std_error,
            shrink,
            sign_p,
        })
    }

    /// `after` is lower than `before` by any of the three tests at its level.
    pub fn significant(&self) -> bool {
        self.mean_log_ratio < -self.t_critical * self.std_error
            || self.mean_diff > self.t_critical * self.diff_std_error
            || self.sign_p <= ALPHA
    }
}

/// `after` improves on `before`: significantly lower, blow by blow, and lower overall by at
/// least `min_shrink`.
pub fn improves(before: &[f64], after: &[f64], min_shrink: f64) -> bool {
    Comparison::of(before, after).is_some_and(|c| c.significant() && c.shrink >= min_shrink)
}

/// `other`'s errors are not significantly higher than `best`'s: the test cannot tell the two
/// apart, whatever their means.
pub fn equivalent(best: &[f64], other: &[f64]) -> bool {
    Comparison::of(other, best).is_some_and(|c| !c.significant())
}

/// Smallest further shrink of a pair over its single effect. Set from the withheld-effect
/// suite (a lone clearance leaves a misfit that a friction exponent halves; a true second
/// effect removes ~98 % of it).
pub const MIN_PAIR_SHRINK: f64 = 0.8;

#[cfg(test)]
mod tests {
    use super::*;

    // The clearance case in kind: errors that differ in scale from blow to blow,
    // each shrunk by 60–80 %. The difference of errors has a standard error too large for
    // the former 2-SE rule; the log-ratio has not.
    #[test]
    fn a_consistent_relative_improvement_is_significant_whatever_the_scale() {
        let before = [0.02, 0.05, 0.10, 0.30, 0.04];
        let after = [0.006, 0.012, 0.03, 0.08, 0.014];
        assert!(improves(&before, &after, 0.2));
        // The difference of errors alone (the former rule) does not see it.
        let c = Comparison::of(&before, &after).unwrap();
        assert!(c.mean_diff < 2.0 * c.diff_std_error, "{c:?}");
    }

    // `thermal` does nothing on a billet's first blow by its definition: one blow unchanged
    // (here a hair worse) must not sink a strong improvement on the other four.
    #[test]
    fn one_unchanged_blow_does_not_hide_an_effect() {
        let before = [0.05, 0.08, 0.10, 0.12, 0.13];
        let after = [0.051, 0.02, 0.02, 0.025, 0.03];
        assert!(improves(&before, &after, 0.2));
    }

    // Error removed where it is large, noise-sized blows made a little worse (the kind of
    // billet the tuning seeds' `hammer-friction-0.03` miss was): the log-ratio alone is not
    // significant, the difference is, and the union takes it.
    #[test]
    fn an_improvement_on_the_large_blows_only_is_significant() {
        let before = [0.001, 0.001, 0.020, 0.022, 0.025];
        let after = [0.002, 0.002, 0.005, 0.006, 0.006];
        let c = Comparison::of(&before, &after).unwrap();
        assert!(c.mean_log_ratio > -c.t_critical * c.std_error, "{c:?}");
        assert!(c.mean_diff > c.t_critical * c.diff_std_error, "{c:?}");
        assert!(improves(&before, &after, 0.2));
    }

    // The family's Siebel press clearance (report seed 4904): every blow lower, the first
    // far more than the rest. Neither t-test sees it; the sign test does (all 5 lower:
    // p = 1/32). With one blow not lower it does not (p = 6/32).
    #[test]
    fn an_improvement_on_every_blow_of_uneven_size_is_significant() {
        let before = [0.1515, 0.0449, 0.0509, 0.073, 0.0744];
        let after = [0.0128, 0.0341, 0.0419, 0.0555, 0.0611];
        let c = Comparison::of(&before, &after).unwrap();
        assert!(c.mean_log_ratio > -c.t_critical * c.std_error, "{c:?}");
        assert!(c.mean_diff < c.t_critical * c.diff_std_error, "{c:?}");
        assert!((c.sign_p - 1.0 / 32.0).abs() < 1e-12, "{c:?}");
        assert!(improves(&before, &after, 0.2));
        let mut one_worse = after;
        one_worse[2] = 0.052;
        let c = Comparison::of(&before, &one_worse).unwrap();
        assert!((c.sign_p - 6.0 / 32.0).abs() < 1e-12, "{c:?}");
        assert!(!c.significant(), "{c:?}");
    }

    #[test]
    fn the_sign_test_s_tail_is_the_binomial_s() {
        assert_eq!(binomial_tail(5, 0), 1.0);
        assert!((binomial_tail(5, 5) - 1.0 / 32.0).abs() < 1e-15);
        // 8 of 10: (45 + 10 + 1) / 1024.
        assert!((binomial_tail(10, 8) - 56.0 / 1024.0).abs() < 1e-15);
        assert_eq!(binomial_tail(3, 4), 0.0);
    }

    #[test]
    fn noise_sized_changes_of_either_sign_are_not_significant() {
        let before = [0.030, 0.031, 0.029, 0.030, 0.032];
        let after = [0.029, 0.032, 0.028, 0.031, 0.030];
        let c = Comparison::of(&before, &after).unwrap();
        assert!(!c.significant(), "{c:?}");
        assert!(!improves(&before, &after, 0.0));
    }

    // Significant but small: the shrink gate refuses it.
    #[test]
    fn a_small_consistent_improvement_is_below_the_shrink_gate() {
        let before = [0.05, 0.06, 0.07, 0.08, 0.09];
        let after: Vec<f64> = before.iter().map(|x| x * 0.9).collect();
        assert!(Comparison::of(&before, &after).unwrap().significant());
        assert!(!improves(&before, &after, 0.2));
    }

    #[test]
    fn equivalence_is_the_same_test_read_the_other_way() {
        let best = [0.010, 0.012, 0.011, 0.013, 0.010];
        // 3 % worse on average, not consistently: equivalent.
        let close = [0.011, 0.011, 0.012, 0.013, 0.0105];
        assert!(equivalent(&best, &close));
        // Twice as bad on every blow: not.
        let worse: Vec<f64> = best.iter().map(|x| 2.0 * x).collect();
        assert!(!equivalent(&best, &worse));
    }

    #[test]
    fn degenerate_inputs_give_no_comparison() {
        assert!(Comparison::of(&[0.1], &[0.05]).is_none());
        assert!(Comparison::of(&[0.1, 0.2], &[0.05]).is_none());
        assert!(Comparison::of(&[0.1, 0.0], &[0.05, 0.01]).is_none());
        assert!(Comparison::of(&[0.1, f64::NAN], &[0.05, 0.01]).is_none());
        assert!(!improves(&[0.1], &[0.01], 0.0));
    }
}
