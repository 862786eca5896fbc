//! The physically sensible range of every number the configuration files give, checked
//! once when a file is read. A value outside its range is almost always a typing error
//! (`m1_kg = 1e308`, `k_N_per_m = 1e-300`), and let through it ends deep in the
//! integrator ("step size fell below 1e-14 s") with a message that names neither the
//! file nor the key. The ranges are wide: each spans every machine or billet the
//! service could meet, with a margin of at least ten on both sides of the examples.

/// A closed range of one physical quantity, with its unit for the messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub min: f64,
    pub max: f64,
    pub unit: &'static str,
}

/// Masses, kg: from a bench test rig's 0.1 kg tool to 1e7 kg, ten times the equivalent
/// moving mass (ram, screw and flywheel) of the largest screw presses; the example press's
/// is 1.06e5 kg and the example hammer's lower tool 19 kg.
pub const MASS_KG: Limits = Limits { min: 0.1, max: 1e7, unit: "kg" };

/// Stiffnesses, N/m: from 1e5 (a soft spring on a bench rig) to 1e13, the stiffness of a
/// steel column 1 m² across and 2 cm long (E·A/L); the example machines' springs are
/// 1.7e9..3.4e10 N/m and the default tool contact 6e10 N/m.
pub const STIFFNESS_N_PER_M: Limits = Limits { min: 1e5, max: 1e13, unit: "N/m" };

/// Damping coefficients, Ns/m: from none to 1e11, above the critical damping
/// 2·sqrt(k·m) = 2e10 Ns/m of the heaviest mass on the stiffest spring above.
pub const DAMPING_NS_PER_M: Limits = Limits { min: 0.0, max: 1e11, unit: "Ns/m" };

/// Billet diameter and height before the sheet's first blow, m: from 1 mm (a coin blank)
/// to 2 m (an open-die ingot).
pub const BILLET_DIMENSION_M: Limits = Limits { min: 1e-3, max: 2.0, unit: "m" };

/// A measured height after a blow, m: as a billet, but down to 0.1 mm, since a forged
/// plate can end thinner than any billet starts.
pub const MEASURED_HEIGHT_M: Limits = Limits { min: 1e-4, max: 2.0, unit: "m" };

/// `[caliper] tolerance_m`: how far a hand-measured height may rise, m: from nothing (the
/// sheet's heights are exact) to 10 mm (more is no measurement of a forged part).
pub const CALIPER_TOLERANCE_M: Limits = Limits { min: 0.0, max: 0.01, unit: "m" };

/// Flow stress, Pa: from 1e4 (modelling clay, the soft model material of forging
/// experiments, flows near 0.1 MPa) to 1e10 (five times a hardened tool steel's 2 GPa).
pub const FLOW_STRESS_PA: Limits = Limits { min: 1e4, max: 1e10, unit: "Pa" };

/// Hansel–Spittel `A_Pa`: as a flow stress, with room above for the fits in which
/// exp(m1·T) brings a large A down (A = 1.5e9 with exp(m1·T) ≈ 0.04 for hot steel).
pub const HANSEL_SPITTEL_A_PA: Limits = Limits { min: 1e4, max: 1e12, unit: "Pa" };

/// Hansel–Spittel `m1`, per °C: published fits have |m1| < 0.01; ±0.1 keeps exp(m1·T)
/// finite at every temperature below.
pub const HANSEL_SPITTEL_M1_PER_C: Limits = Limits { min: -0.1, max: 0.1, unit: "1/°C" };

/// Hansel–Spittel `m2`, `m3`, `m4` (exponents of strain, strain rate, and 1/strain): the
/// published fits are within ±1.
pub const HANSEL_SPITTEL_EXPONENT: Limits = Limits { min: -10.0, max: 10.0, unit: "" };

/// Billet temperature, °C: from absolute zero to 2000 °C, above any steel's solidus.
pub const TEMPERATURE_C: Limits = Limits { min: -273.15, max: 2000.0, unit: "°C" };

/// Coulomb friction coefficient mu: 0 (none) to 1; sticking friction is reached at
/// mu = 0.577 already (Tresca's limit), so a larger mu is a mistyped number.
pub const FRICTION: Limits = Limits { min: 0.0, max: 1.0, unit: "" };

/// Impact speed, m/s: from a press closing at 1 mm/s to 30 m/s, above the fastest
/// counterblow and high-energy-rate hammers.
pub const IMPACT_SPEED_MPS: Limits = Limits { min: 1e-3, max: 30.0, unit: "m/s" };

/// An efficiency (plastic work over kinetic energy at impact): a fraction in [0, 1].
pub const EFFICIENCY: Limits = Limits { min: 0.0, max: 1.0, unit: "" };

/// Energies, J (a recipe's plastic energy): from none to 4.5e9 J, the kinetic energy of the
/// heaviest moving mass of `MASS_KG` at the fastest impact of `IMPACT_SPEED_MPS`
/// (0.5 · 1e7 kg · (30 m/s)²). No blow of any machine these ranges admit carries more.
pub const ENERGY_J: Limits =
    Limits { min: 0.0, max: 0.5 * MASS_KG.max * IMPACT_SPEED_MPS.max * IMPACT_SPEED_MPS.max, unit: "J" };

/// A peak load, N (compression positive, docs/interfaces.md conventions): from none to 1e11 N, three
/// times the largest flow stress of `FLOW_STRESS_PA` over the largest billet's cross-section
/// of `BILLET_DIMENSION_M` (π · (1 m)² · 1e10 Pa = 3.1e10 N); the largest forging presses
/// built make under 1e9 N.
pub const PEAK_LOAD_N: Limits = Limits { min: 0.0, max: 1e11, unit: "N" };

/// A load anywhere on a blow's curve, N: as a peak load, and as far below zero (a sensor
/// rings through zero after the blow and reads its offset before it, so an envelope's lower
/// bound may be negative).
pub const LOAD_N: Limits = Limits { min: -PEAK_LOAD_N.max, max: PEAK_LOAD_N.max, unit: "N" };

/// The ram's travel from first contact, m (a recipe's travel window and its envelope's
/// compression points): from none to the tallest billet of `BILLET_DIMENSION_M`, which no
/// blow compresses further.
pub const TRAVEL_M: Limits = Limits { min: 0.0, max: BILLET_DIMENSION_M.max, unit: "m" };

/// A whole-number range (byte counts, durations, counters).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WholeLimits {
    pub min: u64,
    pub max: u64,
    pub unit: &'static str,
}

/// Recording file size before rotation, bytes: from 1 MiB (below that a file holds less
/// than a second of one 100 kHz DAQ) to 1 TiB.
pub const ROTATE_BYTES: WholeLimits = WholeLimits { min: 1 << 20, max: 1 << 40, unit: "bytes" };

/// Recording file age before rotation, s: from 1 s to 366 days; the upper bound also keeps
/// the age in nanoseconds far inside a u64.
pub const ROTATE_SECONDS: WholeLimits = WholeLimits { min: 1, max: 366 * 86_400, unit: "s" };

/// `[recording] keep_bytes`, bytes the recording's files may hold before the oldest go:
/// from 16 MiB (a few rotated files) to 1 PiB.
pub const KEEP_BYTES: WholeLimits = WholeLimits { min: 16 << 20, max: 1 << 50, unit: "bytes" };

/// `[recording] keep_days`, days a recording file is kept: from an hour to ten years.
pub const KEEP_DAYS: Limits = Limits { min: 1.0 / 24.0, max: 3660.0, unit: "days" };

/// `[recording] min_free_bytes`, the free space under which a `storage` alert is raised:
/// from none (no alert until a write fails) to 1 PiB.
pub const MIN_FREE_BYTES: WholeLimits = WholeLimits { min: 0, max: 1 << 50, unit: "bytes" };

/// Serial speed, baud: the standard rates from 300 up to the 12 Mbaud of fast USB bridges.
pub const BAUD: WholeLimits = WholeLimits { min: 300, max: 12_000_000, unit: "baud" };

/// Modbus poll interval and request timeout, ms: 1 ms to one hour.
pub const MODBUS_MS: Limits = Limits { min: 1.0, max: 3.6e6, unit: "ms" };

/// `[http] max_connections`, `[foxglove] max_clients`: connections a server holds at once,
/// from 1 to 65 536 (the most one listening address can take from one client address).
pub const SERVER_CONNECTIONS: WholeLimits = WholeLimits { min: 1, max: 65_536, unit: "connections" };

/// A server's header or handshake timeout, s: from 0.1 s (loopback clients in tests) to
/// 10 minutes (a client that needs longer to send a few hundred bytes is not there).
pub const HANDSHAKE_TIMEOUT_S: Limits = Limits { min: 0.1, max: 600.0, unit: "s" };

/// A server's idle timeout, s: from 1 s to a day. The dashboard's event stream sends a
/// keep-alive every 15 s, so an HTTP idle timeout below that cuts it (it reconnects).
pub const IDLE_TIMEOUT_S: Limits = Limits { min: 1.0, max: 86_400.0, unit: "s" };

/// A recipe file or `POST /recipe` body, bytes: at most 1 MiB. `forgemon teach` writes
/// about 2.8 kB per blow (four windows and a 40-point envelope: 22 kB for the demo's 8
/// blows), so this holds some 370 blows, twenty times the advisor's longest plan
/// (`advise::MAX_BLOWS`, 15) and far more than a closed-die part takes; teach checks its own
/// output against it.
pub const RECIPE_BYTES: WholeLimits = WholeLimits { min: 1, max: 1 << 20, unit: "bytes" };

/// A recipe's name, characters: it is shown in `/status`, the dashboard, logs and every
/// judgement, so a short label.
pub const RECIPE_NAME_CHARS: WholeLimits = WholeLimits { min: 1, max: 64, unit: "characters" };

/// Points of one blow's envelope in a recipe: at least 2 (a segment), at most the 200
/// points a blow's signature keeps (`recipe::signature::SIGNATURE_POINTS`), the curve the envelope is
/// read against: a finer envelope resolves nothing more. `teach` writes
/// `recipe::ENVELOPE_POINTS` (40).
pub const ENVELOPE_POINTS: WholeLimits =
    WholeLimits { min: 2, max: crate::recipe::signature::SIGNATURE_POINTS as u64, unit: "points" };
const _: () = assert!(crate::recipe::ENVELOPE_POINTS as u64 <= ENVELOPE_POINTS.max);

/// Alert window, blows.
pub const ALERT_WINDOW_BLOWS: WholeLimits = WholeLimits { min: 1, max: 10_000, unit: "blows" };

/// Alert debounce, blows.
pub const DEBOUNCE_BLOWS: WholeLimits = WholeLimits { min: 0, max: 1_000_000, unit: "blows" };

/// `[billets] new_billet_rise_m`: from a tenth of a millimetre (10 counts of a 10 µm
/// encoder) to a metre (taller than any billet a hammer takes).
pub const NEW_BILLET_RISE_M: Limits = Limits { min: 1e-4, max: 1.0, unit: "m" };

/// `[billets] encoder_at_die_m`: any reading within ±100 m (an encoder's counter may start
/// anywhere; no ram travels that far).
pub const ENCODER_AT_DIE_M: Limits = Limits { min: -100.0, max: 100.0, unit: "m" };

/// `[billets] idle_s`: from a second (a fast line's part change) to a day.
pub const BILLET_IDLE_S: Limits = Limits { min: 1.0, max: 86_400.0, unit: "s" };

/// Model-health limit on |energy-balance residual|, a fraction of the kinetic energy.
pub const RESIDUAL_LIMIT: Limits = Limits { min: 1e-4, max: 10.0, unit: "" };

/// Sensor-health limit on |`sensor_check`|, a fraction of the blow's momentum: from 0.1 %
/// (below the simulated spread at 5 kHz, `AlertConfig::DEFAULT_SENSOR_LIMIT`) to 100 %
/// (the two sensors disagree by the whole blow).
pub const SENSOR_LIMIT: Limits = Limits { min: 1e-3, max: 1.0, unit: "" };

/// `[plc_server] idle_timeout_s`, s: from 0.1 s (a few PLC cycles) to a day.
pub const PLC_IDLE_TIMEOUT_S: Limits = Limits { min: 0.1, max: 86_400.0, unit: "s" };

/// `[plc_server] max_connections`: from one client to 10 000, far below the descriptors
/// a service may hold (set `LimitNOFILE` above the sum of every face's cap).
pub const PLC_MAX_CONNECTIONS: WholeLimits = WholeLimits { min: 1, max: 10_000, unit: "connections" };

impl Limits {
    /// The range in words, as the messages give it: `0..1`, `0..4.5e9 J`.
    pub fn range(&self) -> String {
        format!("{}..{}{}", number(self.min), number(self.max), unit(self.unit))
    }

    /// `x` if it is finite and in the range; otherwise why not, in words.
    pub fn check(&self, x: f64) -> Result<f64, String> {
        if self.min > 0.0 && !(x.is_finite() && x > 0.0) {
            return Err(format!("must be finite and > 0, got {x}"));
        }
        if self.min == 0.0 && !(x.is_finite() && x >= 0.0) {
            return Err(format!("must be finite and >= 0, got {x}"));
        }
        if !x.is_finite() {
            return Err(format!("must be finite, got {x}"));
        }
        if x < self.min || x > self.max {
            return Err(format!(
                "must be within {}..{}{} (a physically sensible range), got {}",
                number(self.min),
                number(self.max),
                unit(self.unit),
                number(x)
            ));
        }
        Ok(x)
    }
}

impl WholeLimits {
    /// `x` if it is in the range; otherwise why not, in words.
    pub fn check(&self, x: u64) -> Result<u64, String> {
        if (self.min..=self.max).contains(&x) {
            Ok(x)
        } else {
            Err(format!("must be within {}..={}{}, got {x}", self.min, self.max, unit(self.unit)))
        }
    }
}

fn unit(u: &str) -> String {
    if u.is_empty() { String::new() } else { format!(" {u}") }
}

/// A number as a person writes it: 0.1, 2, 1e7, 1e-300.
fn number(x: f64) -> String {
    if x != 0.0 && (x.abs() >= 1e5 || x.abs() < 1e-2) { format!("{x:e}") } else { format!("{x}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_outside_the_range_say_the_range_and_the_unit() {
        assert_eq!(MASS_KG.check(732.0), Ok(732.0));
        assert_eq!(
            MASS_KG.check(1e308).unwrap_err(),
            "must be within 0.1..1e7 kg (a physically sensible range), got 1e308"
        );
        assert_eq!(
            STIFFNESS_N_PER_M.check(1e-300).unwrap_err(),
            "must be within 1e5..1e13 N/m (a physically sensible range), got 1e-300"
        );
        assert_eq!(MASS_KG.check(0.0).unwrap_err(), "must be finite and > 0, got 0");
        assert_eq!(MASS_KG.check(f64::NAN).unwrap_err(), "must be finite and > 0, got NaN");
        assert_eq!(FRICTION.check(-0.2).unwrap_err(), "must be finite and >= 0, got -0.2");
        assert_eq!(FRICTION.check(0.0), Ok(0.0));
        assert_eq!(TEMPERATURE_C.check(f64::INFINITY).unwrap_err(), "must be finite, got inf");
        assert_eq!(ROTATE_SECONDS.check(0).unwrap_err(), "must be within 1..=31622400 s, got 0");
    }

    #[test]
    fn the_longest_rotation_fits_in_nanoseconds() {
        assert!(ROTATE_SECONDS.max.checked_mul(1_000_000_000).is_some());
    }
}
