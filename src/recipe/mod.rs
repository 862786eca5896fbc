//! Teach-in recipes and OK/NOK per blow (issue 20, docs/interfaces.md §9). A recipe is learnt from
//! good billets: per blow index, windows on the efficiency, the plastic energy and the peak
//! load, and an envelope of the load against the billet's compression (the ram's travel
//! since first contact, on the loading branch). Each window and each envelope point is the
//! references' mean ± max(k·sd, a tolerance), Helm's limits as a share of the learnt value
//! (so they follow each job); the envelope is then widened by a compression tolerance, as a
//! DIGIFORCE envelope is by ΔX. A blow is judged against its index's entry: which window it
//! left and by how much (with the digits that show it, `digits`), or where it left the
//! envelope. A taught recipe is rounded outward to what the measurements resolve
//! (`rounding`), so its file reads short and still holds its blows. Pure code: the file is read and
//! written by `config::recipe`, the pipeline judges (`pipeline`), `forgemon teach` teaches.

pub mod digits;
pub mod rounding;
pub mod signature;

use serde::Serialize;

use digits::fixed;
pub use signature::{Estimated, Signature, signature};

/// Envelope points per blow.
pub const ENVELOPE_POINTS: usize = 40;

/// How wide the windows are: mean ± max(k·sd, tolerance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    pub k: f64,
    /// Efficiency, absolute.
    pub efficiency: f64,
    /// Plastic energy, a share of the learnt mean.
    pub plastic_fraction: f64,
    /// Peak load, a share of the learnt mean.
    pub peak_load_fraction: f64,
    /// The envelope's load, a share of the learnt peak load.
    pub load_fraction: f64,
    /// The envelope's widening along the compression, and the travel's tolerance, m.
    pub compression_m: f64,
}

impl Default for Tolerances {
    /// k = 3 (a normal lot's 99.7 %); 0.03 of efficiency (twice the estimator's accuracy on
    /// the paper machines, issue 16's 0.02 target with margin); 5 % of plastic energy and
    /// peak load (Helm's default learnt-sample limits); 5 % of the peak on the envelope;
    /// 0.1 mm along the compression (ten encoder counts; the compression counts from first
    /// contact, so a billet's height spread barely moves the curve along it).
    fn default() -> Self {
        Tolerances {
            k: 3.0,
            efficiency: 0.03,
            plastic_fraction: 0.05,
            peak_load_fraction: 0.05,
            load_fraction: 0.05,
            compression_m: 0.1e-3,
        }
    }
}

/// A closed interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Window {
    pub min: f64,
    pub max: f64,
}

impl Window {
    /// mean ± max(k·sd, tol) of `xs`.
    fn learn(xs: &[f64], k: f64, tol: f64) -> Window {
        let (mean, sd) = mean_sd(xs);
        let half = (k * sd).max(tol);
        Window { min: mean - half, max: mean + half }
    }

    fn contains(&self, x: f64) -> bool {
        x >= self.min && x <= self.max
    }
}

/// What one blow index of the part must look like.
#[derive(Debug, Clone, PartialEq)]
pub struct BlowWindows {
    /// The blow's number on its billet, from 1.
    pub blow: u32,
    pub efficiency: Window,
    pub plastic_j: Window,
    pub peak_load_n: Window,
    /// The blow's deepest compression (the ram's travel from first contact), m: on an
    /// energy-driven machine a harder billet takes the same energy over a shorter travel.
    pub travel_m: Window,
    /// The envelope: compression points, m, and the load's bounds there, N.
    pub compression_m: Vec<f64>,
    pub load_lower_n: Vec<f64>,
    pub load_upper_n: Vec<f64>,
}

/// A part's recipe.
#[derive(Debug, Clone, PartialEq)]
pub struct Recipe {
    pub name: String,
    /// The machine kind it was taught on (`hammer` or `screw_press`).
    pub machine: String,
    pub tolerances: Tolerances,
    /// Good billets it was taught from.
    pub billets: u32,
    /// Where they came from.
    pub taught_from: Vec<String>,
    pub blows: Vec<BlowWindows>,
}

/// The judgement of one blow (docs/interfaces.md §5 `judgement`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Judgement {
    pub ok: bool,
    pub recipe: String,
    pub reasons: Vec<String>,
}

/// Why a recipe could not be taught.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TeachError {
    #[error("no good billet to teach from: each reference must hold at least one complete blow")]
    NoBillets,
    #[error("blow {blow} is on only {found} of the billets; at least 2 are needed for a spread")]
    TooFew { blow: u32, found: usize },
}

/// Teach a recipe from `billets`, each a list of its blows' signatures in order. Blow
/// indices that at least two billets reach are learnt; the rest are left out (and the
/// recipe's last blow is the last index learnt).
pub fn teach(
    name: &str,
    machine: &str,
    billets: &[Vec<Signature>],
    tol: Tolerances,
    taught_from: Vec<String>,
) -> Result<Recipe, TeachError> {
    let billets: Vec<&Vec<Signature>> = billets.iter().filter(|b| !b.is_empty()).collect();
    if billets.is_empty() {
        return Err(TeachError::NoBillets);
    }
    let most = billets.iter().map(|b| b.len()).max().unwrap_or(0);
    let mut blows = Vec::new();
    for i in 0..most {
        let sigs: Vec<&Signature> = billets.iter().filter_map(|b| b.get(i)).collect();
        let blow = i as u32 + 1;
        if sigs.len() < 2 {
            if blow == 1 {
                return Err(TeachError::TooFew { blow, found: sigs.len() });
            }
            break;
        }
        // Rounded outward to what the measurements resolve: the file reads short, and each
        // window still holds every blow the exact one held (`rounding`).
        blows.push(rounding::blow(learn_blow(blow, &sigs, tol)));
    }
    Ok(Recipe {
        name: name.to_string(),
        machine: machine.to_string(),
        tolerances: tol,
        billets: billets.len() as u32,
        taught_from,
        blows,
    })
}

/// One blow index from its references.
fn learn_blow(blow: u32, sigs: &[&Signature], tol: Tolerances) -> BlowWindows {
    let col = |f: fn(&Signature) -> f64| sigs.iter().map(|s| f(s)).collect::<Vec<f64>>();
    let (plastic_mean, _) = mean_sd(&col(|s| s.plastic_j));
    let (peak_mean, _) = mean_sd(&col(|s| s.peak_load_n));
    // The envelope reaches as far as the shortest reference's compression.
    let reach = sigs.iter().map(|s| s.max_compression_m()).fold(f64::INFINITY, f64::min).max(0.0);
    // On whole micrometres (`rounding::grid`): the bounds below are learnt at the points the
    // file shows.
    let compression_m = rounding::grid(reach, ENVELOPE_POINTS);
    let (mut lower, mut upper) = (Vec::new(), Vec::new());
    for &x in &compression_m {
        let loads: Vec<f64> = sigs.iter().map(|s| s.load_at(x)).collect();
        let w = Window::learn(&loads, tol.k, tol.load_fraction * peak_mean);
        lower.push(w.min);
        upper.push(w.max);
    }
    // Widened along the compression: each point's bounds are the loosest within ±dx.
    let near = |j: usize| -> Vec<usize> {
        let xj = compression_m[j];
        (0..compression_m.len()).filter(|&i| (compression_m[i] - xj).abs() <= tol.compression_m).collect()
    };
    let load_lower_n: Vec<f64> =
        (0..compression_m.len()).map(|j| near(j).into_iter().map(|i| lower[i]).fold(f64::INFINITY, f64::min)).collect();
    let load_upper_n: Vec<f64> = (0..compression_m.len())
        .map(|j| near(j).into_iter().map(|i| upper[i]).fold(f64::NEG_INFINITY, f64::max))
        .collect();
    BlowWindows {
        blow,
        efficiency: Window::learn(&col(|s| s.efficiency), tol.k, tol.efficiency),
        plastic_j: Window::learn(&col(|s| s.plastic_j), tol.k, tol.plastic_fraction * plastic_mean.abs()),
        peak_load_n: Window::learn(&col(|s| s.peak_load_n), tol.k, tol.peak_load_fraction * peak_mean.abs()),
        travel_m: Window::learn(&col(|s| s.max_compression_m()), tol.k, tol.compression_m),
        compression_m,
        load_lower_n,
        load_upper_n,
    }
}

impl Recipe {
    /// Judge the `billet_blow`-th blow of its billet, whose signature is `sig`.
    pub fn judge(&self, billet_blow: u32, sig: &Signature) -> Judgement {
        let mut reasons = Vec::new();
        match self.blows.iter().find(|b| b.blow == billet_blow) {
            None => reasons.push(format!(
                "blow {billet_blow} is beyond the recipe's {} blows: the part should be finished",
                self.blows.len()
            )),
            Some(w) => {
                // Each printed with its usual decimals, more where they would round the value
                // onto a bound (`digits`).
                let mut window = |name: &str, x: f64, win: &Window, unit: f64, u: &str, least: usize| {
                    if !win.contains(x) {
                        let side = if x > win.max { "above" } else { "below" };
                        let (x, min, max) = (x / unit, win.min / unit, win.max / unit);
                        let d = digits::decimals_apart(x, min, max, least);
                        let (x, min, max) = (fixed(x, d), fixed(min, d), fixed(max, d));
                        reasons.push(format!("{name} {side} window: {x} {u} outside [{min}, {max}]"));
                    }
                };
                window("efficiency", sig.efficiency, &w.efficiency, 1.0, "", 3);
                window("plastic_J", sig.plastic_j, &w.plastic_j, 1.0, "J", 0);
                window("peak_load", sig.peak_load_n, &w.peak_load_n, 1e3, "kN", 0);
                window("travel", sig.max_compression_m(), &w.travel_m, 1e-3, "mm", 2);
                if let Some(r) = envelope_exit(w, sig) {
                    reasons.push(r);
                }
            }
        }
        Judgement { ok: reasons.is_empty(), recipe: self.name.clone(), reasons }
    }
}

/// Where the blow's load left the envelope the farthest (in units of the band's half
/// width), within the compression the blow reached.
fn envelope_exit(w: &BlowWindows, sig: &Signature) -> Option<String> {
    let reach = sig.max_compression_m();
    let mut worst: Option<(f64, String)> = None;
    for (j, &x) in w.compression_m.iter().enumerate() {
        if x > reach {
            break;
        }
        let load = sig.load_at(x);
        let (lo, hi) = (w.load_lower_n[j], w.load_upper_n[j]);
        let half = (0.5 * (hi - lo)).max(1.0);
        let (excess, side, bound) = if load > hi {
            ((load - hi) / half, "above", hi)
        } else if load < lo {
            ((lo - load) / half, "below", lo)
        } else {
            continue;
        };
        if worst.as_ref().is_none_or(|(e, _)| excess > *e) {
            let d = digits::decimals_apart(load / 1e3, lo / 1e3, hi / 1e3, 0);
            let why = format!(
                "load left the envelope at {:.2} mm compression: {} kN {side} {} kN",
                x * 1e3,
                fixed(load / 1e3, d),
                fixed(bound / 1e3, d)
            );
            worst = Some((excess, why));
        }
    }
    worst.map(|(_, w)| w)
}

/// Mean and sample standard deviation (0 for fewer than two values).
fn mean_sd(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    if xs.is_empty() {
        return (f64::NAN, 0.0);
    }
    let mean = xs.iter().sum::<f64>() / n;
    let var = if xs.len() > 1 { xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    (mean, var.sqrt())
}
