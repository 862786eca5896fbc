//! The damped oscillator `m x'' + c x' + k x = 0`, solved exactly.
//!
//! While the billet does not flow, a hammer's lower tool rings on its frame spring and
//! damper, alone (the tools apart) or carrying the ram (the tools stuck together): a linear
//! ODE whose flow is known in closed form. `plant::BaseHammer` advances those phases with
//! it instead of Runge–Kutta steps. The closed form is `exp(A t)` for
//! `A = [[0, 1], [-k/m, -c/m]]`; the tests compare it with nalgebra's matrix exponential.

/// `|beta^2| t^2` below which cos/cosh and sin/sinh use their series (five terms reach
/// 1e-17 there, and the series avoids the cancellation of `sinh(g t) / g` near critical
/// damping).
const SERIES_Z: f64 = 1e-2;

/// `m x'' + c x' + k x = 0`, as `x'' + 2 alpha x' + w0^2 x = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oscillator {
    /// `c / 2m`, 1/s.
    alpha_per_s: f64,
    /// `k / m`, 1/s².
    w0_sq: f64,
    /// `w0^2 - alpha^2`: positive underdamped, negative overdamped, 1/s².
    beta_sq: f64,
}

/// The state `[x, v]` after `t` is `phi · [x0, v0]`, row-major.
pub type Propagator = [[f64; 2]; 2];

impl Oscillator {
    /// A mass `m_kg` on a spring `k_n_per_m` and a damper `c_ns_per_m` to ground.
    pub fn new(m_kg: f64, k_n_per_m: f64, c_ns_per_m: f64) -> Oscillator {
        let alpha_per_s = 0.5 * c_ns_per_m / m_kg;
        let w0_sq = k_n_per_m / m_kg;
        Oscillator { alpha_per_s, w0_sq, beta_sq: w0_sq - alpha_per_s * alpha_per_s }
    }

    /// The largest magnitude of the system's eigenvalues, or a bound on it within a factor
    /// of 2: `w0` underdamped, at most `2 alpha` overdamped. 1/s.
    pub fn fastest_rate_per_s(&self) -> f64 {
        self.w0_sq.sqrt().max(2.0 * self.alpha_per_s)
    }

    /// `exp(A t)`: `e^(-alpha t) [[C + alpha S, S], [-w0^2 S, C - alpha S]]`, with
    /// `C = cos(beta t)` and `S = sin(beta t) / beta` (cosh and sinh when overdamped).
    pub fn propagator(&self, t_s: f64) -> Propagator {
        let z = self.beta_sq * t_s * t_s;
        let (c, s) = if z.abs() < SERIES_Z {
            // cos(sqrt z) and sin(sqrt z)/sqrt z as series in -z, valid for either sign.
            let c = 1.0 - z / 2.0 * (1.0 - z / 12.0 * (1.0 - z / 30.0 * (1.0 - z / 56.0 * (1.0 - z / 90.0))));
            let s = t_s * (1.0 - z / 6.0 * (1.0 - z / 20.0 * (1.0 - z / 42.0 * (1.0 - z / 72.0 * (1.0 - z / 110.0)))));
            (c, s)
        } else if self.beta_sq > 0.0 {
            let beta = self.beta_sq.sqrt();
            let (sin, cos) = (beta * t_s).sin_cos();
            (cos, sin / beta)
        } else {
            let gamma = (-self.beta_sq).sqrt();
            ((gamma * t_s).cosh(), (gamma * t_s).sinh() / gamma)
        };
        let e = (-self.alpha_per_s * t_s).exp();
        let a = self.alpha_per_s;
        [[e * (c + a * s), e * s], [-e * self.w0_sq * s, e * (c - a * s)]]
    }
}

/// What a constant unit force per unit mass does over `t` (the second column of
/// `phi_k(A t)`, k = 1, 2, 3) beside the free flow `e = exp(A t)`: an exponential
/// integrator's weights (`plant::BaseHammer`'s plastic steps). With `phi_0 = exp` and
/// `phi_(k+1)(Z) = Z^-1 (phi_k(Z) - I / k!)`, a forcing `f(s) = f0 + f1 s/t + f2 (s/t)^2` over
/// the step moves the state by `t (phi_1 f0 + phi_2 f1 + 2 phi_3 f2)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phi {
    pub e: Propagator,
    /// `phi_k(A t) [0, 1]`, k = 1, 2, 3, as `[x, v]`.
    pub p: [[f64; 2]; 3],
}

/// `|lambda| t` below which `Oscillator::phi` sums the series `sum_j (A t)^j / (j + k)!`
/// instead of the recurrence, whose `Z^-1` loses up to `1 / (|lambda| t)^3` roundoffs (8 at
/// the switch); 20 terms leave `0.5^20 / 21!` there.
const PHI_SERIES_RATE_T: f64 = 0.5;

impl Oscillator {
    /// `Phi` over `t_s`, for an underdamped oscillator (both eigenvalues of magnitude `w0`,
    /// so that one switch serves the series and the recurrence); `None` otherwise: an
    /// overdamped one's slow eigenvalue, far below its fast one, would leave neither form
    /// accurate.
    pub fn phi(&self, t_s: f64) -> Option<Phi> {
        if !(self.beta_sq > 0.0 && t_s > 0.0) {
            return None;
        }
        let e = self.propagator(t_s);
        // Z = A t = [[0, t], [-w0^2 t, -2 alpha t]].
        let z = [[0.0, t_s], [-self.w0_sq * t_s, -2.0 * self.alpha_per_s * t_s]];
        let mut p = [[0.0; 2]; 3];
        if self.w0_sq.sqrt() * t_s < PHI_SERIES_RATE_T {
            // Z^j e2 summed with 1 / (j + k)!, smallest terms first.
            let mut terms = [[0.0; 2]; 20];
            let mut u = [0.0, 1.0];
            for term in &mut terms {
                *term = u;
                u = [z[0][0] * u[0] + z[0][1] * u[1], z[1][0] * u[0] + z[1][1] * u[1]];
            }
            for (k, pk) in p.iter_mut().enumerate() {
                for j in (0..terms.len()).rev() {
                    let fact: f64 = (1..=j + k + 1).map(|i| i as f64).product();
                    pk[0] += terms[j][0] / fact;
                    pk[1] += terms[j][1] / fact;
                }
            }
        } else {
            // Z^-1 = [[-2 alpha, -1], [w0^2, 0]] / (w0^2 t).
            let det = self.w0_sq * t_s;
            let solve = |r: [f64; 2]| [(-2.0 * self.alpha_per_s * r[0] - r[1]) / det, self.w0_sq * r[0] / det];
            let mut prev = [e[0][1], e[1][1]];
            let mut fact = 1.0;
            for (k, pk) in p.iter_mut().enumerate() {
                *pk = solve([prev[0], prev[1] - 1.0 / fact]);
                fact *= (k + 1) as f64;
                prev = *pk;
            }
        }
        Some(Phi { e, p })
    }
}

/// `phi · [x, v]`.
pub fn apply(phi: &Propagator, x: f64, v: f64) -> (f64, f64) {
    (phi[0][0] * x + phi[0][1] * v, phi[1][0] * x + phi[1][1] * v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    /// The closed form against nalgebra's matrix exponential (Padé with scaling and
    /// squaring, another code path) of `A t`; 1e-12 of the matrix's largest entry is a few
    /// thousand roundoffs, far below the 1e-6 the blow's step control works to.
    fn check(m: f64, k: f64, c: f64, t: f64) {
        let phi = Oscillator::new(m, k, c).propagator(t);
        let reference = (Matrix2::new(0.0, 1.0, -k / m, -c / m) * t).exp();
        let size = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for (i, row) in phi.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                let err = (v - reference[(i, j)]).abs() / size;
                assert!(err < 1e-12, "m {m} k {k} c {c} t {t}: phi[{i}][{j}] {v} vs {} ({err:e})", reference[(i, j)]);
            }
        }
    }

    #[test]
    fn the_closed_form_is_the_matrix_exponential() {
        // The diagnosis suite's hammer (m2 26 kg, k 2.6e9 N/m, c 24000 N s/m) alone and
        // carrying its 910 kg ram, over a 10 µs sample, a tenth of it, and 1 ms.
        for m in [26.0, 936.0] {
            for t in [1e-6, 1e-5, 1e-3] {
                check(m, 2.6e9, 24000.0, t);
            }
        }
        // Overdamped (c far above 2 sqrt(k m) = 5.2e5), near critical either side, undamped.
        for c in [5e6, 5.2e5 * 1.001, 5.2e5 * 0.999, 0.0] {
            for t in [1e-7, 1e-5, 1e-4] {
                check(26.0, 2.6e9, c, t);
            }
        }
    }

    #[test]
    fn the_forced_response_is_the_augmented_exponentials() {
        // phi_1..3 (A t) e2 against nalgebra's exponential of [[A t, e2, 0, 0], [0, 0, 1, 0],
        // [0, 0, 0, 1], [0, 0, 0, 0]] (Al-Mohy and Higham's augmented matrix: its first
        // rows hold exp(A t) and phi_k(A t) e2), on both sides of the series' switch, for
        // the suite's hammer, near critical damping (c 0.999 of 2 sqrt(k m)) and undamped.
        // 1e-12 of the largest entry, as above. Overdamped, critically damped and a step
        // that is not one have none.
        for (m, k, c) in [(26.0, 2.6e9, 24000.0), (26.0, 2.6e9, 5.2e5 * 0.999), (19.0, 3.15e9, 0.0)] {
            let o = Oscillator::new(m, k, c);
            let w0 = (k / m).sqrt();
            for t in [1e-7, 1e-5, 0.4 / w0, 0.6 / w0, 1e-4, 1.5e-4] {
                let got = o.phi(t).unwrap();
                let mut aug = nalgebra::SMatrix::<f64, 5, 5>::zeros();
                aug[(0, 1)] = t;
                aug[(1, 0)] = -k / m * t;
                aug[(1, 1)] = -c / m * t;
                aug[(1, 2)] = 1.0;
                aug[(2, 3)] = 1.0;
                aug[(3, 4)] = 1.0;
                let x = aug.exp();
                for (kk, pk) in got.p.iter().enumerate() {
                    let want = [x[(0, 2 + kk)], x[(1, 2 + kk)]];
                    let size = want[0].abs().max(want[1].abs());
                    for i in 0..2 {
                        let err = (pk[i] - want[i]).abs() / size;
                        assert!(
                            err < 1e-12,
                            "m {m} c {c} t {t}: phi_{}[{i}] {} vs {} ({err:e})",
                            kk + 1,
                            pk[i],
                            want[i]
                        );
                    }
                }
                assert_eq!(got.e, o.propagator(t));
            }
        }
        assert_eq!(Oscillator::new(26.0, 2.6e9, 5e6).phi(1e-5), None);
        assert_eq!(Oscillator::new(1.0, 4.0, 4.0).phi(1e-5), None);
        assert_eq!(Oscillator::new(26.0, 2.6e9, 24000.0).phi(0.0), None);
    }

    #[test]
    fn the_propagator_composes() {
        // exp(A (s + t)) = exp(A s) exp(A t): the flow of 7 µs then 3 µs is that of 10 µs.
        let o = Oscillator::new(26.0, 2.6e9, 24000.0);
        let (a, b, ab) = (o.propagator(7e-6), o.propagator(3e-6), o.propagator(1e-5));
        let (x1, v1) = apply(&b, 1e-4, 2.0);
        let (x2, v2) = apply(&a, x1, v1);
        let (x3, v3) = apply(&ab, 1e-4, 2.0);
        assert!((x2 - x3).abs() < 1e-12 * 1e-4 && (v2 - v3).abs() < 1e-12 * 2.0, "{x2} {x3} {v2} {v3}");
    }
}
