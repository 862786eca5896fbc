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
