//! The billet: a cylinder upset between flat dies.
//!
//! The load is the analytical upsetting law with Coulomb friction of the hammer paper
//! (seed 000, eq. 3), the flow stress is constant or Hansel–Spittel (seed 001, eq. 6), and
//! the load-side effects of the library (`friction_rise`, `strain_rate`,
//! `strain_hardening`, `thermal`) act here. Pure code: no IO, no clock.

use std::f64::consts::PI;

/// Strain below which the flow-stress laws are evaluated at this floor.
///
/// Hansel–Spittel's `eps^m2 * exp(m4/eps)` and the `strain_hardening` power law are zero
/// (or singular) at zero strain; FE codes floor the strain the same way. 1e-4 is far below
/// any strain a blow reaches (a 10 µm dent in a 30 mm billet is 3e-4).
pub const STRAIN_FLOOR: f64 = 1e-4;

/// Strain rate (1/s) below which rate-sensitive laws are evaluated at this floor.
///
/// Stuck and separating phases have zero plastic rate; a quasi-static 1e-2 /s keeps the
/// power laws finite there. Blows run at 1–100 /s.
pub const STRAIN_RATE_FLOOR_PER_S: f64 = 1e-2;

/// The billet as the process sheet describes it (docs/interfaces.md §2).
#[derive(Debug, Clone, PartialEq)]
pub struct BilletGeometry {
    /// Diameter before the first blow of the sheet, m.
    pub diameter_m: f64,
    /// Height before the first blow of the sheet, m. Strains are measured from here.
    pub height_m: f64,
}

impl BilletGeometry {
    /// Volume of the cylinder, conserved while it is upset.
    pub fn volume_m3(&self) -> f64 {
        PI * (0.5 * self.diameter_m).powi(2) * self.height_m
    }

    /// Radius at height `h_m`, by constant volume (the papers' barrelling-free cylinder).
    pub fn radius_at(&self, h_m: f64) -> f64 {
        (self.volume_m3() / (PI * h_m)).sqrt()
    }

    /// Logarithmic strain at height `h_m`: `ln(height_m / h)`.
    pub fn strain_at(&self, h_m: f64) -> f64 {
        (self.height_m / h_m).ln()
    }
}

/// Flow-stress law of the material (docs/interfaces.md §2 `[material]`).
#[derive(Debug, Clone, PartialEq)]
pub enum FlowStress {
    /// Constant flow stress, Pa (the hammer paper's sigma_0).
    Constant { sigma0_pa: f64 },
    /// `sigma = A exp(m1 T) eps^m2 epsdot^m3 exp(m4/eps)` (seed 001, eq. 6), T in °C.
    HanselSpittel { a_pa: f64, m1: f64, m2: f64, m3: f64, m4: f64, temperature_c: f64 },
}

impl FlowStress {
    /// The same material with every flow stress times `factor` (a billet harder or softer
    /// than the sheet: colder, another heat).
    pub fn scaled(&self, factor: f64) -> FlowStress {
        match *self {
            FlowStress::Constant { sigma0_pa } => FlowStress::Constant { sigma0_pa: sigma0_pa * factor },
            FlowStress::HanselSpittel { a_pa, m1, m2, m3, m4, temperature_c } => {
                FlowStress::HanselSpittel { a_pa: a_pa * factor, m1, m2, m3, m4, temperature_c }
            }
        }
    }

    /// Flow stress at strain `eps` and strain rate `epsdot_per_s` (both floored).
    pub fn sigma_pa(&self, eps: f64, epsdot_per_s: f64) -> f64 {
        match *self {
            FlowStress::Constant { sigma0_pa } => sigma0_pa,
            FlowStress::HanselSpittel { a_pa, m1, m2, m3, m4, temperature_c } => {
                let eps = eps.max(STRAIN_FLOOR);
                let rate = epsdot_per_s.max(STRAIN_RATE_FLOOR_PER_S);
                a_pa * (m1 * temperature_c).exp() * eps.powf(m2) * rate.powf(m3) * (m4 / eps).exp()
            }
        }
    }
}

/// Load-side effect parameters (docs/interfaces.md §6). Neutral values leave the base law as is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadEffects {
    /// `friction_rise`: mu(h) = mu0 (h0/h)^p. Neutral 0.
    pub friction_exponent: f64,
    /// `strain_rate`: sigma (epsdot/epsdot_ref)^m. Neutral m = 0.
    pub rate_m: f64,
    pub rate_ref_per_s: f64,
    /// `strain_hardening`: sigma (eps/eps_ref)^n. Neutral n = 0.
    pub hardening_n: f64,
    pub hardening_eps_ref: f64,
    /// `thermal`: sigma exp(q_dT (i-1)) on blow i. Neutral 0.
    pub thermal_q_dt: f64,
}

impl LoadEffects {
    /// No load-side effect.
    pub const NEUTRAL: LoadEffects = LoadEffects {
        friction_exponent: 0.0,
        rate_m: 0.0,
        rate_ref_per_s: 1.0,
        hardening_n: 0.0,
        hardening_eps_ref: 1.0,
        thermal_q_dt: 0.0,
    };
}

impl Default for LoadEffects {
    fn default() -> Self {
        Self::NEUTRAL
    }
}

/// Upsetting load at one instant, split as the papers split the energy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UpsetLoad {
    /// Total load with friction, N (eq. 3).
    pub total_n: f64,
    /// Frictionless load `pi r^2 sigma`, N. Work of this part is the plastic energy.
    pub frictionless_n: f64,
}

/// The billet law for one blow: geometry, material, friction and load effects, with the
/// blow index already folded in. `load` is the hot function of the simulator.
#[derive(Debug, Clone, PartialEq)]
pub struct BilletLaw {
    geometry: BilletGeometry,
    material: FlowStress,
    mu0: f64,
    effects: LoadEffects,
    /// `exp(q_dT (i-1))` for this blow.
    thermal_factor: f64,
    /// `r0^2 h0`: volume over pi, so that `r^2 = r0h0 / h`.
    r0sq_h0_m3: f64,
    /// Whether the flow stress depends on strain (else `ln` is skipped in the hot path).
    strain_dependent: bool,
    /// Hansel–Spittel's `A exp(m1 T)`, the first factor of `FlowStress::sigma_pa`'s
    /// product, computed once per blow instead of per evaluation (the same value).
    hs_prefactor_pa: f64,
}

impl BilletLaw {
    /// The law for blow `blow_index` (1-based) of the sheet.
    pub fn new(
        geometry: BilletGeometry,
        material: FlowStress,
        friction: f64,
        effects: LoadEffects,
        blow_index: usize,
    ) -> Self {
        let thermal_factor = (effects.thermal_q_dt * (blow_index.saturating_sub(1)) as f64).exp();
        let r0sq_h0_m3 = (0.5 * geometry.diameter_m).powi(2) * geometry.height_m;
        let strain_dependent = matches!(material, FlowStress::HanselSpittel { .. }) || effects.hardening_n != 0.0;
        let hs_prefactor_pa = match material {
            FlowStress::HanselSpittel { a_pa, m1, temperature_c, .. } => a_pa * (m1 * temperature_c).exp(),
            // Unused; 0 rather than NaN keeps the derived `PartialEq` reflexive.
            FlowStress::Constant { .. } => 0.0,
        };
        Self {
            geometry,
            material,
            mu0: friction,
            effects,
            thermal_factor,
            r0sq_h0_m3,
            strain_dependent,
            hs_prefactor_pa,
        }
    }

    pub fn geometry(&self) -> &BilletGeometry {
        &self.geometry
    }

    /// Whether the load depends on the strain rate (the simulator then needs its slope).
    pub fn is_rate_dependent(&self) -> bool {
        matches!(self.material, FlowStress::HanselSpittel { m3, .. } if m3 != 0.0) || self.effects.rate_m != 0.0
    }

    /// Coulomb friction at height `h_m` (`friction_rise` makes it grow as the billet flattens).
    pub fn friction_at(&self, h_m: f64) -> f64 {
        if self.effects.friction_exponent == 0.0 {
            self.mu0
        } else {
            self.mu0 * (self.geometry.height_m / h_m).powf(self.effects.friction_exponent)
        }
    }

    /// Flow stress at height `h_m` and strain rate `epsdot_per_s`, with the load effects.
    pub fn sigma_pa(&self, h_m: f64, epsdot_per_s: f64) -> f64 {
        let eps = if self.strain_dependent { self.geometry.strain_at(h_m) } else { 0.0 };
        let material = match self.material {
            FlowStress::Constant { sigma0_pa } => sigma0_pa,
            // `FlowStress::sigma_pa` with its constant first factor taken from `new`: the
            // product is evaluated left to right, so the result is the same to the bit.
            FlowStress::HanselSpittel { m2, m3, m4, .. } => {
                let eps = eps.max(STRAIN_FLOOR);
                let rate = epsdot_per_s.max(STRAIN_RATE_FLOOR_PER_S);
                self.hs_prefactor_pa * eps.powf(m2) * rate.powf(m3) * (m4 / eps).exp()
            }
        };
        let mut sigma = material * self.thermal_factor;
        let e = &self.effects;
        if e.rate_m != 0.0 {
            sigma *= (epsdot_per_s.max(STRAIN_RATE_FLOOR_PER_S) / e.rate_ref_per_s).powf(e.rate_m);
        }
        if e.hardening_n != 0.0 {
            sigma *= (eps.max(STRAIN_FLOOR) / e.hardening_eps_ref).powf(e.hardening_n);
        }
        sigma
    }

    /// Upsetting load at height `h_m` while compressed at `epsdot_per_s` (eq. 3).
    pub fn load(&self, h_m: f64, epsdot_per_s: f64) -> UpsetLoad {
        self.load_given(h_m, 1.0 / h_m, epsdot_per_s)
    }

    /// Upsetting load at height `h_m` while the dies close at `ddelta_mps` (the strain
    /// rate is `ddelta / h`, and no strain rate while they part): the plant's form of
    /// `load`, which shares the reciprocal of `h`.
    pub fn load_closing(&self, h_m: f64, ddelta_mps: f64) -> UpsetLoad {
        let inv_h = 1.0 / h_m;
        self.load_given(h_m, inv_h, ddelta_mps.max(0.0) * inv_h)
    }

    /// Eq. 3 with `inv_h = 1 / h_m`: the divisions by `h` and by `A` are each taken as one
    /// reciprocal, off the dependent chain of the blow's hot path.
    fn load_given(&self, h_m: f64, inv_h: f64, epsdot_per_s: f64) -> UpsetLoad {
        let r_sq = self.r0sq_h0_m3 * inv_h;
        let r = r_sq.sqrt();
        let sigma = self.sigma_pa(h_m, epsdot_per_s);
        let frictionless_n = PI * r_sq * sigma;
        let a = 2.0 * self.friction_at(h_m) * r * inv_h;
        UpsetLoad { total_n: frictionless_n * friction_factor(a), frictionless_n }
    }
}

/// Largest `A` at which `friction_factor` sums eq. 3's series instead of calling
/// `expm1`: its first left-out term, `2 A^17 / 19!`, is 1.6e-17 of the sum here (below half
/// an ulp), and A stays below it until a billet is flattened to `h < 2 mu r` (A = 2 mu r / h).
const SERIES_MAX_A: f64 = 1.0;

/// `2 / (n + 2)!`, n = 0..=16: eq. 3's factor as a power series in `A`,
/// `(2/A) ((e^A - 1)/A - 1) = sum 2 A^n / (n + 2)!`.
const SERIES: [f64; 17] = {
    let mut c = [0.0; 17];
    let mut fact = 2.0; // (n + 2)!
    let mut n = 0;
    while n < 17 {
        c[n] = 2.0 / fact;
        fact *= (n + 3) as f64;
        n += 1;
    }
    c
};

/// `F / (pi r^2 sigma)` of eq. 3, `(2/A) ((e^A - 1)/A - 1)`, which tends to 1 as A -> 0.
/// Up to `SERIES_MAX_A` it is the series' polynomial by Estrin's scheme: every term is
/// positive, so nothing cancels (a few ulp), where the closed form's `(e^A - 1)/A - 1`
/// cancels to about `A/2` and loses `2/A` ulps; and it needs no `expm1` and no division.
/// Above it, the closed form with one reciprocal of `A`.
pub fn friction_factor(a: f64) -> f64 {
    if a <= SERIES_MAX_A {
        let c = &SERIES;
        let a2 = a * a;
        let a4 = a2 * a2;
        let a8 = a4 * a4;
        let pair = |i: usize| c[i] + c[i + 1] * a;
        let quad = |i: usize| pair(i) + a2 * pair(i + 2);
        let oct = |i: usize| quad(i) + a4 * quad(i + 4);
        (oct(0) + a8 * oct(8)) + (a8 * a8) * c[16]
    } else {
        let inv_a = 1.0 / a;
        2.0 * inv_a * (a.exp_m1() * inv_a - 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn steel() -> BilletLaw {
        // Hammer paper §2.1/§2.3.2: 60 mm x 112 mm, mu 0.2, sigma_0 90 MPa.
        BilletLaw::new(
            BilletGeometry { diameter_m: 0.060, height_m: 0.112 },
            FlowStress::Constant { sigma0_pa: 90e6 },
            0.2,
            LoadEffects::NEUTRAL,
            1,
        )
    }

    #[test]
    fn frictionless_limit_is_area_times_stress() {
        let law = BilletLaw::new(
            BilletGeometry { diameter_m: 0.060, height_m: 0.112 },
            FlowStress::Constant { sigma0_pa: 90e6 },
            0.0,
            LoadEffects::NEUTRAL,
            1,
        );
        let l = law.load(0.112, 10.0);
        let expect = PI * 0.03 * 0.03 * 90e6;
        assert!((l.total_n - expect).abs() < 1e-6 * expect);
        assert_eq!(l.total_n, l.frictionless_n);
    }

    #[test]
    fn eq3_matches_the_design_reproduction_at_the_final_height() {
        // DESIGN.md §2.1 reproduction table, billet column: eq. 3 at the simulated final
        // height of 92.93 mm gives 322 kN (±0.5 %, the table's rounding).
        let l = steel().load(0.09293, 10.0);
        assert!((l.total_n / 322e3 - 1.0).abs() < 0.005, "load at 92.93 mm: {}", l.total_n);
    }

    /// Eq. 3 as the paper writes it, by another path than `load`: divisions, and the
    /// closed form's `expm1` at every `A` (its second-order series below 1e-6, where the
    /// closed form cancels completely).
    fn eq3_closed_form(law: &BilletLaw, h_m: f64, rate: f64) -> (f64, f64) {
        let r = (law.r0sq_h0_m3 / h_m).sqrt();
        let a = 2.0 * law.friction_at(h_m) * r / h_m;
        let factor = if a < 1e-6 { 1.0 + a / 3.0 + a * a / 12.0 } else { 2.0 / a * (a.exp_m1() / a - 1.0) };
        let frictionless = PI * r * r * law.sigma_pa(h_m, rate);
        (frictionless * factor, frictionless)
    }

    #[test]
    fn the_load_is_eq3_in_closed_form_within_a_few_ulp() {
        // `load` takes `h`'s and `A`'s divisions as reciprocals; each rounding moves a result
        // by an ulp (1.1e-16), but the closed form's `(e^A - 1)/A - 1` (about A/2) cancels,
        // so an ulp of its first term is 2/A ulps of the difference; and `e^A` turns an ulp
        // of A into A ulps. Allowed: 16 ulps times (1 + 2/A + A); A is 0.1–0.6 at the heights
        // a blow reaches on these billets, so about 1e-14 (the fits' rtol is 1e-6).
        let ulps = |a: f64| 16.0 * f64::EPSILON * (1.0 + 2.0 / a + a);
        let mut e = LoadEffects::NEUTRAL;
        e.friction_exponent = 0.7;
        let rising = BilletLaw::new(steel().geometry.clone(), steel().material.clone(), 0.2, e, 1);
        for law in [steel(), rising] {
            for h_m in [0.112, 0.1, 0.0893, 0.05, 0.02, 0.005] {
                let a = 2.0 * law.friction_at(h_m) * law.geometry.radius_at(h_m) / h_m;
                for rate in [0.0, 3.0, 40.0] {
                    let (total, frictionless) = eq3_closed_form(&law, h_m, rate);
                    let l = law.load(h_m, rate);
                    assert!((l.total_n / total - 1.0).abs() <= ulps(a), "h {h_m}: {l:?} vs {total}");
                    assert!((l.frictionless_n / frictionless - 1.0).abs() <= ulps(1.0), "h {h_m}");
                    let closing = law.load_closing(h_m, rate * h_m);
                    assert!((closing.total_n / l.total_n - 1.0).abs() <= ulps(1.0), "h {h_m} rate {rate}");
                }
                assert_eq!(law.load_closing(h_m, -1.0), law.load(h_m, 0.0), "parting dies strain at no rate");
            }
        }
        assert_eq!(friction_factor(0.0), 1.0);
    }

    #[test]
    fn the_friction_factor_sums_the_series_to_a_few_ulp() {
        // Another path to eq. 3's factor: its series summed term by term (40 terms, each
        // with its own power and factorial, added smallest first), accurate to about an ulp
        // for A in [0, 1]; the Estrin polynomial must agree within 4 ulps (its own
        // rounding, every term positive). Across the switch to `expm1` at
        // `SERIES_MAX_A`, the two forms agree within the closed form's own 2/A ulps of
        // cancellation (`the_load_is_eq3_in_closed_form_within_a_few_ulp`).
        let series = |a: f64| {
            let terms: Vec<f64> = (0..40)
                .map(|n| {
                    let fact: f64 = (1..=n + 2).map(f64::from).product();
                    2.0 * a.powi(n) / fact
                })
                .collect();
            terms.iter().rev().sum::<f64>()
        };
        for i in 0..=2000 {
            let a = SERIES_MAX_A * f64::from(i) / 2000.0;
            let (f, s) = (friction_factor(a), series(a));
            assert!((f / s - 1.0).abs() <= 4.0 * f64::EPSILON, "A {a}: {f} vs {s}");
        }
        let (below, above) = (friction_factor(SERIES_MAX_A), friction_factor(SERIES_MAX_A + 1e-15));
        assert!((above / below - 1.0).abs() <= 16.0 * f64::EPSILON * (1.0 + 2.0 / SERIES_MAX_A), "{below} vs {above}");
    }

    #[test]
    fn friction_rise_raises_mu_as_the_billet_flattens() {
        let mut e = LoadEffects::NEUTRAL;
        e.friction_exponent = 0.5;
        let law = BilletLaw::new(steel().geometry.clone(), steel().material.clone(), 0.2, e, 1);
        assert_eq!(law.friction_at(0.112), 0.2);
        assert!((law.friction_at(0.028) - 0.4).abs() < 1e-12); // (112/28)^0.5 = 2
    }

    #[test]
    fn hansel_spittel_copper_at_forty_percent_strain() {
        // Press paper Table 2 (copper, 20 °C). Direct evaluation of eq. 6 at eps 0.4, 10 /s:
        // 411.19 * e^(-0.0242) * 0.4^0.21554 * 10^0.01472 * e^(-0.0234) = 333 MPa.
        let hs = FlowStress::HanselSpittel {
            a_pa: 411.19e6,
            m1: -0.00121,
            m2: 0.21554,
            m3: 0.01472,
            m4: -0.00935,
            temperature_c: 20.0,
        };
        let s = hs.sigma_pa(0.4, 10.0);
        assert!((s / 333e6 - 1.0).abs() < 0.005, "{s}");
        // Floors keep the law finite at zero strain and rate.
        assert!(hs.sigma_pa(0.0, 0.0).is_finite());
    }

    #[test]
    fn the_laws_hansel_spittel_is_the_flow_stress_to_the_bit() {
        // `BilletLaw` keeps A exp(m1 T) from its constructor; the simulator's fixtures are
        // compared to 1e-12, so the product must be the same to the last bit, not merely close.
        let hs = FlowStress::HanselSpittel {
            a_pa: 411.19e6,
            m1: -0.00121,
            m2: 0.21554,
            m3: 0.01472,
            m4: -0.00935,
            temperature_c: 20.0,
        };
        let geometry = BilletGeometry { diameter_m: 0.035, height_m: 0.050 };
        let law = BilletLaw::new(geometry.clone(), hs.clone(), 0.1, LoadEffects::NEUTRAL, 1);
        for h_m in [0.050, 0.049_999, 0.041, 0.030, 0.012] {
            for rate in [0.0, 1e-3, 0.7, 12.0, 95.0] {
                let direct = hs.sigma_pa(geometry.strain_at(h_m), rate);
                assert_eq!(law.sigma_pa(h_m, rate).to_bits(), direct.to_bits(), "h {h_m} rate {rate}");
            }
        }
        assert_eq!(law, BilletLaw::new(geometry, hs, 0.1, LoadEffects::NEUTRAL, 1));
    }
}
