//! Drift alarms (issue 44): a slow change of the forging at the same settings, as dies wear,
//! lubrication dries or billets come in colder. Pure code, fed the blows and the billets'
//! summaries.
//!
//! **Reference.** The first `learn_billets` (100) good billets (finished, every blow complete and
//! none NOK) give, for each setting (the impact speed to `setting_step_mps`: a drop height or
//! an energy setpoint) and each blow index on the billet, the mean and spread of three
//! quantities: efficiency, plastic energy and travel (the blow's height lost). A billet is
//! then scored per quantity by the mean of its blows' deviations in those spreads, and the
//! scores are scaled by their own spread over the reference billets, so that a billet's
//! blows varying together (a warmer billet) count once; by the 90 % upper bound of that
//! spread, since it is estimated (`sd_upper_factor`).
//!
//! **Watch.** Each quantity has two one-sided CUSUMs over the billets' scores z:
//! S⁺ = max(0, S⁺ + z − k), S⁻ = max(0, S⁻ − z − k), alarming above h. With k = 0.5 and
//! h = 11 (the defaults) and a known spread, a chart's in-control run length is about
//! 385 000 billets by Siegmund's approximation, (e^b − b − 1)/(2k²) with b = 2k(h + 1.166):
//! six charts give 0.16 false alarms per 10 000 billets, and a shift of one spread is found
//! after about 23 billets, (e^−b' + b' − 1)/(2(δ−k)²) with b' = 2(δ−k)(h + 1.166), δ = 1.
//! The reference is itself estimated from 100 billets, and its means' errors act as a small
//! standing shift: measured by simulation below, 0.76 false alarms per 10 000 billets and
//! 26 billets to find a one-spread step; `tests/drift.rs` on rendered sessions.
//!
//! An alarm names the quantity, the direction, the billet since which its CUSUM has grown
//! (the change's start), how far the blows moved since, and the likely causes; it rearms
//! when its CUSUM is back to 0.

use std::collections::BTreeMap;

use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::BilletSummary;

/// The detector's settings, with the false-alarm rate and delay they give (module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriftConfig {
    /// Good billets the reference is learnt from.
    pub learn_billets: usize,
    /// CUSUM allowance, in spreads of the billet score.
    pub k: f64,
    /// CUSUM decision interval, in spreads of the billet score.
    pub h: f64,
    /// Impact speeds within this are one setting, m/s.
    pub setting_step_mps: f64,
}

impl Default for DriftConfig {
    fn default() -> Self {
        DriftConfig { learn_billets: 100, k: 0.5, h: 11.0, setting_step_mps: 0.05 }
    }
}

impl DriftConfig {
    /// Siegmund's approximation of a one-sided CUSUM's average run length for a shift of
    /// `delta` spreads (0: in control).
    pub fn run_length(&self, delta: f64) -> f64 {
        let d = delta - self.k;
        if d.abs() < 1e-9 {
            return (self.h + 1.166).powi(2);
        }
        let b = 2.0 * d * (self.h + 1.166);
        ((-b).exp() + b - 1.0) / (2.0 * d * d)
    }
}

/// What is watched.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Quantity {
    Efficiency,
    Plastic,
    Travel,
}

impl Quantity {
    pub const ALL: [Quantity; 3] = [Quantity::Efficiency, Quantity::Plastic, Quantity::Travel];

    pub fn as_str(self) -> &'static str {
        match self {
            Quantity::Efficiency => "efficiency",
            Quantity::Plastic => "plastic energy",
            Quantity::Travel => "travel",
        }
    }

    fn of(self, e: &BlowEstimate) -> Option<f64> {
        match self {
            Quantity::Efficiency => e.efficiency,
            Quantity::Plastic => e.plastic_j,
            Quantity::Travel => e.h_start_m.zip(e.h_end_m).map(|(a, b)| a - b),
        }
        .filter(|x| x.is_finite())
    }

    fn show(self, x: f64) -> String {
        match self {
            Quantity::Efficiency => format!("{x:+.3}"),
            Quantity::Plastic => format!("{x:+.0} J"),
            Quantity::Travel => format!("{:+.2} mm", x * 1e3),
        }
    }
}

/// The direction of a drift.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    Down,
    Up,
}

/// An alarm: the words and figures of a `drift` alert.
#[derive(Debug, Clone, PartialEq)]
pub struct DriftAlarm {
    pub quantity: Quantity,
    pub direction: Direction,
    /// The billet (counted from the start) from which the CUSUM grew, and its log time.
    pub since_billet: u64,
    pub since_ns: i64,
    /// The billet it alarmed on.
    pub at_billet: u64,
    /// Mean deviation of the blows from their reference since then, in the quantity's unit.
    pub shift: f64,
    pub reason: String,
}

/// The detector's state in `/status` `drift`.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct DriftStatus {
    /// `learning` the reference, or `watching`.
    pub state: &'static str,
    /// Good billets in the reference so far.
    pub reference_billets: usize,
    pub learn_billets: usize,
}

/// The name a learnt reference is recorded under (`/config`, docs/interfaces.md §13): when it
/// is learnt, and at the start of each run that resumes it.
pub const REFERENCE_CONFIG_NAME: &str = "drift-reference.json";

/// A learnt reference, as recorded and as the service resumes it after a restart: for each
/// setting, blow index and quantity, the count, mean and sum of squared deviations of the
/// reference billets' values; the billet score's spread bound per quantity; and the settings
/// it was learnt under.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Reference {
    pub learn_billets: usize,
    pub setting_step_mps: f64,
    pub blows: Vec<ReferenceBlow>,
    /// `null` where it could not be estimated.
    pub score_sd: [Option<f64>; 3],
}

/// One setting's, blow index's and quantity's reference (`quantity`: 0 efficiency, 1 plastic
/// energy, 2 travel; `setting`: the impact speed in `setting_step_mps`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReferenceBlow {
    pub setting: i64,
    pub blow: u32,
    pub quantity: usize,
    pub n: f64,
    pub mean: f64,
    pub m2: f64,
}

/// One blow's setting, index and values.
#[derive(Debug, Clone)]
struct Blow {
    key: (i64, u32),
    values: [Option<f64>; 3],
}

/// Mean and spread (Welford).
#[derive(Debug, Clone, Copy, Default)]
struct Stat {
    n: f64,
    mean: f64,
    m2: f64,
}

impl Stat {
    fn add(&mut self, x: f64) {
        self.n += 1.0;
        let d = x - self.mean;
        self.mean += d / self.n;
        self.m2 += d * (x - self.mean);
    }

    fn sd(&self) -> f64 {
        if self.n > 1.0 { (self.m2 / (self.n - 1.0)).sqrt() } else { f64::NAN }
    }
}

/// One-sided CUSUM with where it started growing.
#[derive(Debug, Clone, Copy, Default)]
struct Chart {
    s: f64,
    since: Option<(u64, i64)>,
    /// Sum and count of the blows' raw deviations since `since`.
    shift: (f64, f64),
    alarmed: bool,
}

/// The one-sided confidence with which the score's spread is bounded from above.
const SD_CONFIDENCE: f64 = 0.9;

/// The factor from a spread estimated from `n` values to its `SD_CONFIDENCE` upper bound,
/// sqrt((n − 1)/χ²(1 − confidence; n − 1)): 1.10 for 100 billets. A CUSUM's run length is
/// steep in the spread it scales by (an estimate 15 % low would alarm about ten times as
/// often), so the charts are scaled by the bound, and a shift is found a little later.
fn sd_upper_factor(n: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    if n < 3.0 {
        return f64::NAN;
    }
    ChiSquared::new(n - 1.0).map_or(f64::NAN, |c| ((n - 1.0) / c.inverse_cdf(1.0 - SD_CONFIDENCE)).sqrt())
}

/// A blow's values from at least this many reference billets make a reference.
const MIN_REFERENCE: f64 = 3.0;

/// The detector.
#[derive(Debug, Clone)]
pub struct Drift {
    cfg: DriftConfig,
    /// The blows of the billet in the dies, and whether it is good so far.
    current: Vec<Blow>,
    current_good: bool,
    /// Reference billets while learning.
    learning: Vec<Vec<Blow>>,
    /// Per (setting, blow index) and quantity: the reference.
    reference: BTreeMap<((i64, u32), usize), Stat>,
    /// The spread of the billet score per quantity over the reference billets.
    score_sd: [f64; 3],
    learned: bool,
    /// [quantity][down, up].
    charts: [[Chart; 2]; 3],
    billets: u64,
}

impl Drift {
    pub fn new(cfg: DriftConfig) -> Self {
        Drift {
            cfg,
            current: Vec::new(),
            current_good: true,
            learning: Vec::new(),
            reference: BTreeMap::new(),
            score_sd: [f64::NAN; 3],
            learned: false,
            charts: [[Chart::default(); 2]; 3],
            billets: 0,
        }
    }

    /// Whether the reference is learnt and the billets are watched.
    pub fn watching(&self) -> bool {
        self.learned
    }

    /// The learnt reference, to record; `None` while learning.
    pub fn reference(&self) -> Option<Reference> {
        self.learned.then(|| Reference {
            learn_billets: self.cfg.learn_billets,
            setting_step_mps: self.cfg.setting_step_mps,
            blows: self
                .reference
                .iter()
                .map(|(((setting, blow), quantity), st)| ReferenceBlow {
                    setting: *setting,
                    blow: *blow,
                    quantity: *quantity,
                    n: st.n,
                    mean: st.mean,
                    m2: st.m2,
                })
                .collect(),
            score_sd: self.score_sd.map(|x| x.is_finite().then_some(x)),
        })
    }

    /// Watch from a recorded reference (a restart): the CUSUMs start from zero. Refused,
    /// saying why, when it was learnt under other settings (`learn_billets`,
    /// `setting_step_mps`) or does not hold together; the service then learns anew.
    pub fn resume(cfg: DriftConfig, r: &Reference) -> Result<Self, String> {
        if r.learn_billets != cfg.learn_billets || r.setting_step_mps != cfg.setting_step_mps {
            return Err(format!(
                "learnt from {} billets with settings {} m/s apart, and [drift] now says {} and {}",
                r.learn_billets, r.setting_step_mps, cfg.learn_billets, cfg.setting_step_mps
            ));
        }
        let sound = |x: f64| x.is_finite();
        if r.blows.iter().any(|b| b.quantity > 2 || !(sound(b.n) && sound(b.mean) && sound(b.m2)) || b.m2 < 0.0) {
            return Err("a blow's reference is not a count, mean and spread".into());
        }
        let mut d = Drift::new(cfg);
        d.reference = r
            .blows
            .iter()
            .map(|b| (((b.setting, b.blow), b.quantity), Stat { n: b.n, mean: b.mean, m2: b.m2 }))
            .collect();
        d.score_sd = r.score_sd.map(|x| x.unwrap_or(f64::NAN));
        d.learned = true;
        Ok(d)
    }

    /// The state `/status` shows: learning (the good billets so far) or watching.
    pub fn status(&self) -> DriftStatus {
        DriftStatus {
            state: if self.learned { "watching" } else { "learning" },
            reference_billets: if self.learned { self.cfg.learn_billets } else { self.learning.len() },
            learn_billets: self.cfg.learn_billets,
        }
    }

    /// A blow of the billet in the dies.
    pub fn on_blow(&mut self, e: &BlowEstimate) {
        let nok = e.judgement.as_ref().is_some_and(|j| !j.ok);
        if !e.has_energies() || nok {
            self.current_good = false;
        }
        if !e.has_energies() {
            return;
        }
        let setting = (e.v_impact_mps / self.cfg.setting_step_mps).round() as i64;
        let values = Quantity::ALL.map(|q| q.of(e));
        self.current.push(Blow { key: (setting, e.billet.billet_blow), values });
    }

    /// The billet ended (its summary, logged at `t_ns`): learnt from, or scored and
    /// watched; the alarms it raised.
    pub fn on_billet(&mut self, b: &BilletSummary, t_ns: i64) -> Vec<DriftAlarm> {
        let blows = std::mem::take(&mut self.current);
        let good = std::mem::replace(&mut self.current_good, true)
            && b.finished
            && b.incomplete_blows == 0
            && b.implausible_blows == 0
            && !blows.is_empty();
        self.billets += 1;
        if !self.learned {
            if good {
                self.learning.push(blows);
            }
            if self.learning.len() >= self.cfg.learn_billets {
                self.learn();
            }
            return Vec::new();
        }
        self.watch(&blows, t_ns)
    }

    fn learn(&mut self) {
        for billet in &self.learning {
            for blow in billet {
                for (q, v) in blow.values.iter().enumerate() {
                    if let Some(x) = v {
                        self.reference.entry((blow.key, q)).or_default().add(*x);
                    }
                }
            }
        }
        let learning = std::mem::take(&mut self.learning);
        for q in 0..3 {
            let mut s = Stat::default();
            for billet in &learning {
                if let Some((z, _)) = self.score(billet, q) {
                    s.add(z);
                }
            }
            self.score_sd[q] = s.sd() * sd_upper_factor(s.n);
        }
        self.learned = true;
    }

    /// The billet's score for quantity `q` (mean of its blows' deviations in their
    /// references' spreads) and its blows' raw deviations (sum, count).
    fn score(&self, billet: &[Blow], q: usize) -> Option<(f64, (f64, f64))> {
        let (mut z, mut raw, mut n) = (0.0, 0.0, 0.0);
        for blow in billet {
            let (Some(x), Some(r)) = (blow.values[q], self.reference.get(&(blow.key, q))) else { continue };
            let sd = r.sd();
            if r.n < MIN_REFERENCE || sd.is_nan() || sd <= 0.0 {
                continue;
            }
            z += (x - r.mean) / sd;
            raw += x - r.mean;
            n += 1.0;
        }
        (n > 0.0).then(|| (z / n, (raw, n)))
    }

    fn watch(&mut self, billet: &[Blow], t_ns: i64) -> Vec<DriftAlarm> {
        let mut alarms = Vec::new();
        for (q, quantity) in Quantity::ALL.into_iter().enumerate() {
            let Some((score, raw)) = self.score(billet, q) else { continue };
            let sd = self.score_sd[q];
            if sd.is_nan() || sd <= 0.0 {
                continue;
            }
            let z = score / sd;
            for (side, direction) in [Direction::Down, Direction::Up].into_iter().enumerate() {
                let step = if direction == Direction::Up { z } else { -z };
                let chart = &mut self.charts[q][side];
                let before = chart.s;
                chart.s = (chart.s + step - self.cfg.k).max(0.0);
                if chart.s == 0.0 {
                    *chart = Chart::default();
                    continue;
                }
                if before == 0.0 {
                    chart.since = Some((self.billets, t_ns));
                    chart.shift = (0.0, 0.0);
                }
                chart.shift.0 += raw.0;
                chart.shift.1 += raw.1;
                if chart.s > self.cfg.h && !chart.alarmed {
                    chart.alarmed = true;
                    let (since_billet, since_ns) = chart.since.unwrap_or((self.billets, t_ns));
                    let shift = chart.shift.0 / chart.shift.1.max(1.0);
                    alarms.push(DriftAlarm {
                        quantity,
                        direction,
                        since_billet,
                        since_ns,
                        at_billet: self.billets,
                        shift,
                        reason: String::new(),
                    });
                }
            }
        }
        for a in &mut alarms {
            a.reason = self.words(a);
        }
        alarms
    }

    /// Whether `q`'s chart in `direction` is at least half-way to an alarm.
    fn moving(&self, q: Quantity, direction: Direction) -> bool {
        let side = usize::from(direction == Direction::Up);
        self.charts[q as usize][side].s > self.cfg.h / 2.0
    }

    /// The alarm in words: the quantity, direction, since when, by how much, likely causes.
    fn words(&self, a: &DriftAlarm) -> String {
        let dir = if a.direction == Direction::Down { "down" } else { "up" };
        let since = chrono::DateTime::from_timestamp_nanos(a.since_ns).format("%Y-%m-%d %H:%M UTC");
        format!(
            "{} drifting {dir} since billet {} ({since}): {} a blow against the reference at the same settings, over {} billets; likely {}",
            a.quantity.as_str(),
            a.since_billet,
            a.quantity.show(a.shift),
            a.at_billet + 1 - a.since_billet,
            self.causes(a)
        )
    }

    /// The likely causes, from the pattern of the charts. Less travel at the same setting
    /// is a harder billet or more friction, whatever else moved; less work without it is
    /// energy lost elsewhere, in the dies.
    fn causes(&self, a: &DriftAlarm) -> &'static str {
        use Direction::{Down, Up};
        use Quantity::{Efficiency, Plastic, Travel};
        let travel = |d: Direction| self.moving(Travel, d) || (a.quantity == Travel && a.direction == d);
        let less_work = self.moving(Efficiency, Down) || self.moving(Plastic, Down) || a.direction == Down;
        if travel(Down) {
            "colder billets (a higher flow stress: less travel at the same energy), or lubrication drying (more friction)"
        } else if travel(Up) {
            "hotter billets (more travel at the same energy), or fresh lubrication"
        } else if less_work && a.direction == Down {
            "die wear or a clearance growing (energy lost in the dies), or lubrication drying"
        } else {
            "a change of the billets, the lubrication or the dies at the same settings"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};

    /// A billet of `n` blows at 5.3 m/s whose quantities are drawn around 0.85 / 9000 J /
    /// 20 mm with a shared billet term and a blow term, moved by `shift` spreads.
    fn billet(d: &mut Drift, rng: &mut StdRng, n: u32, shift: f64, t: i64) -> Vec<DriftAlarm> {
        let normal = Normal::new(0.0, 1.0).expect("a normal");
        let common = normal.sample(rng);
        for i in 1..=n {
            let z = 0.7 * common + 0.7 * normal.sample(rng) + shift;
            let mut e = BlowEstimate::incomplete(i, 0.0, 5.3, 0.0);
            e.class = crate::estimate::BlowClass::Soft;
            e.billet.billet_blow = i;
            e.efficiency = Some(0.85 + 0.01 * z);
            e.plastic_j = Some(9000.0 + 100.0 * z);
            e.h_start_m = Some(0.1);
            e.h_end_m = Some(0.08 - 0.0002 * z);
            e.kinetic_in_j = Some(10_000.0);
            e.friction_j = Some(0.0);
            e.damped_j = Some(0.0);
            e.elastic_j = Some(0.0);
            d.on_blow(&e);
        }
        let summary = BilletSummary {
            billet: 1,
            t_start_s: 0.0,
            t_end_s: 1.0,
            blows: n,
            incomplete_blows: 0,
            implausible_blows: 0,
            energies_partial: false,
            h_start_m: None,
            h_start_off_sheet_m: None,
            h_end_m: None,
            kinetic_in_j: 0.0,
            plastic_j: 0.0,
            friction_j: None,
            efficiency: None,
            first_hard_blow: None,
            hard_blows: 0,
            alerts: 0,
            checked_blows: 0,
            finished: true,
            trace: Default::default(),
        };
        d.on_billet(&summary, t)
    }

    #[test]
    fn a_resumed_reference_watches_as_the_learnt_one_did() {
        let cfg = DriftConfig { learn_billets: 30, ..DriftConfig::default() };
        let mut rng = StdRng::seed_from_u64(7);
        let mut learnt = Drift::new(cfg);
        for i in 0..30 {
            billet(&mut learnt, &mut rng, 5, 0.0, i);
        }
        // Recorded as JSON and read back, as a restart does.
        let text = serde_json::to_string(&learnt.reference().expect("learnt")).expect("JSON");
        let reference: Reference = serde_json::from_str(&text).expect("reads back");
        let mut resumed = Drift::resume(cfg, &reference).expect("the same settings");
        assert!(resumed.watching());
        // The same billets, drifting down: the same alarms on the same billets.
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for i in 0..200 {
            let (mut r1, mut r2) = (StdRng::seed_from_u64(1000 + i), StdRng::seed_from_u64(1000 + i));
            a.extend(billet(&mut learnt, &mut r1, 5, -0.01 * i as f64, i as i64).into_iter().map(|x| x.at_billet));
            b.extend(billet(&mut resumed, &mut r2, 5, -0.01 * i as f64, i as i64).into_iter().map(|x| x.at_billet));
        }
        assert!(!a.is_empty(), "the drift was found");
        assert_eq!(a.iter().map(|n| n - 30).collect::<Vec<_>>(), b, "billets counted from each run's start");
        // Learnt under other settings: refused, saying which.
        let other = DriftConfig { learn_billets: 50, ..cfg };
        let why = Drift::resume(other, &reference).expect_err("refused");
        assert!(why.contains("30 billets") && why.contains("50"), "{why}");
        assert!(Drift::resume(DriftConfig { setting_step_mps: 0.1, ..cfg }, &reference).is_err());
    }

    /// In-control alarms over `sessions` sessions of 10 000 billets, and the mean delay to
    /// find a step of `step` billet-score spreads (down, in efficiency) over 40 sessions.
    fn run(cfg: DriftConfig, sessions: u64) -> (f64, f64, f64) {
        let (mut alarms, mut billets) = (0usize, 0u64);
        for seed in 0..sessions {
            let mut rng = StdRng::seed_from_u64(seed);
            let mut d = Drift::new(cfg);
            for i in 0..10_000 {
                alarms += billet(&mut d, &mut rng, 5, 0.0, i).len();
            }
            billets += 10_000 - cfg.learn_billets as u64;
        }
        let mut delays = Vec::new();
        for seed in 0..40 {
            let mut rng = StdRng::seed_from_u64(100 + seed);
            let mut d = Drift::new(cfg);
            for i in 0..cfg.learn_billets as i64 {
                assert!(billet(&mut d, &mut rng, 5, 0.0, i).is_empty());
            }
            assert!(d.watching());
            // One spread of the billet score: the blows' shared term is 0.7 of the draw's
            // unit and five blows average the rest, so a billet's score spread is
            // sqrt(0.49 + 0.49/5) = 0.767 of it.
            let found = (1..=400).find(|&i| {
                let a = billet(&mut d, &mut rng, 5, -0.767, 100_000 + i);
                a.iter().any(|a| a.quantity == Quantity::Efficiency && a.direction == Direction::Down)
            });
            delays.push(found.expect("found within 400 billets") as f64);
        }
        let per_10k = alarms as f64 / billets as f64 * 1e4;
        (per_10k, delays.iter().sum::<f64>() / delays.len() as f64, billets as f64)
    }

    #[test]
    fn with_a_well_known_spread_the_charts_run_as_siegmund_says() {
        // 2000 reference billets: the spread is known to 1.6 % and its bound is 1.02 times
        // it, so the charts are the textbook ones at a shift of 1/1.02 spreads.
        let cfg = DriftConfig { learn_billets: 2000, ..DriftConfig::default() };
        let factor = sd_upper_factor(2000.0);
        assert!((factor - 1.021).abs() < 0.002, "{factor}");
        let (per_10k, delay, billets) = run(cfg, 8);
        let expected_per_10k = 6.0 / cfg.run_length(0.0) * 1e4;
        let expected_delay = cfg.run_length(1.0 / factor);
        eprintln!(
            "known spread: {per_10k:.2} false alarms per 10 000 billets ({billets} billets; Siegmund {expected_per_10k:.2}), delay {delay:.1} billets (Siegmund {expected_delay:.1})"
        );
        // 0.16 per 10 000 expected: over 64 000 billets, 1 alarm; Poisson, < 6 at 99.9 %.
        assert!(per_10k * billets / 1e4 < 6.0, "{per_10k}");
        assert!((delay - expected_delay).abs() < 0.2 * expected_delay, "{delay} against {expected_delay}");
    }

    #[test]
    fn with_the_default_reference_false_alarms_stay_rare_and_a_step_is_found() {
        // The default 100 reference billets and h = 11 were chosen on these seeds (0-19 in
        // control, 100-139 stepped; with 30 billets and h = 9.5 it was 3.8 false alarms per
        // 10 000 billets): the reference's means are themselves estimated, an offset the
        // allowance k only partly absorbs. Measured here: 0.76 per 10 000 billets and 26
        // billets to find a one-spread step. tests/drift.rs reports on rendered sessions.
        let cfg = DriftConfig::default();
        let (per_10k, delay, billets) = run(cfg, 20);
        eprintln!(
            "default: {per_10k:.2} false alarms per 10 000 billets over {billets} billets, delay {delay:.1} billets"
        );
        assert!(per_10k < 1.0, "{per_10k}");
        assert!(delay < 35.0, "{delay}");
    }
}
