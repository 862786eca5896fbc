//! The blow advisor (issue 20, docs/interfaces.md §9): from the billet's present height, plan the
//! next blows with the identified machine model (and its effects) so that the billet reaches
//! a target height within `TARGET_TOLERANCE_M` in the fewest blows, without a hard blow
//! where that is possible. The hammer paper names it as a use of the model: knowing the
//! machine and the billet, predict the height after the next blow at each energy setting.
//!
//! The search tries every sequence of the impact speeds, blow by blow, on a table of the
//! simulated outcomes over start heights (`table`: the very plant the simulator runs,
//! `physics::sequence::blow_plant`): states that passed below the window are dropped (a
//! billet only gets flatter), heights within `STATE_BUCKET_M` are merged. The first blow
//! count at which a sequence lands in the window without a hard blow wins; the found speeds
//! are then struck exactly. On a continuous range of speeds, a state whose tried speeds
//! straddle the window finishes on a speed found by bisection. Pure code: no IO, no clock; the service replans with it after
//! every measured blow.

mod table;

use serde::Serialize;

use crate::estimate::{BlowClass, EstimatorConfig};
use crate::physics::blow::{SimOptions, simulate_blow};
use crate::physics::effects::EffectSet;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::physics::sequence::blow_plant;
use table::{Outcome, TABLE_STEP_M, Table};

/// The window around the target: ±0.5 mm (issue 20).
pub const TARGET_TOLERANCE_M: f64 = 0.5e-3;
/// Most blows a plan may take (issue 20's speed target is for 15).
pub const MAX_BLOWS: usize = 15;
/// States closer in height than this count as one (the fewest hard blows kept): a fiftieth
/// of the window.
pub const STATE_BUCKET_M: f64 = 0.02e-3;
/// Most states carried from one blow to the next (the fewest hard blows kept).
pub const MAX_STATES: usize = 4000;
/// Searches again from the exact blows' height when they part from the table's.
const MAX_REPLANS: usize = 3;
/// Speeds tried per blow on a continuous range, evenly from `RANGE_MIN_FRACTION` of the top
/// speed to the top.
pub const RANGE_STEPS: usize = 6;
pub const RANGE_MIN_FRACTION: f64 = 0.25;
/// Bisection steps for the finishing speed on a range: the window is 1 mm wide, the speed
/// interval between two tried speeds moves the end height by a few mm at most, so 12 halvings
/// land well inside.
const BISECTION_STEPS: usize = 12;

/// The impact speeds the machine can strike with.
#[derive(Debug, Clone, PartialEq)]
pub enum Speeds {
    /// Discrete settings (a hammer's drop heights), m/s.
    Settings(Vec<f64>),
    /// Any speed up to this, m/s (a screw press's energy setting).
    UpTo(f64),
}

impl Speeds {
    /// The speeds tried per blow.
    fn tried(&self) -> Vec<f64> {
        match self {
            Speeds::Settings(v) => v.clone(),
            Speeds::UpTo(v_max) => (0..RANGE_STEPS)
                .map(|i| {
                    let f = RANGE_MIN_FRACTION + (1.0 - RANGE_MIN_FRACTION) * i as f64 / (RANGE_STEPS - 1) as f64;
                    v_max * f
                })
                .collect(),
        }
    }
}

/// What to plan.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanRequest {
    pub h_now_m: f64,
    pub target_m: f64,
    /// Blows the billet already took (the `thermal` effect counts them).
    pub blows_done: usize,
    pub speeds: Speeds,
}

/// One advised blow.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlannedBlow {
    /// 1 for the next blow.
    pub blow: usize,
    pub v0_mps: f64,
    #[serde(rename = "kinetic_J")]
    pub kinetic_j: f64,
    pub h_end_m: f64,
    pub efficiency: f64,
    pub class: &'static str,
}

/// The advice (docs/interfaces.md §9 `--json`, plus `hard_blows` and `why`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Plan {
    pub h_now_m: f64,
    pub target_m: f64,
    pub reachable: bool,
    pub blows_to_target: Option<usize>,
    /// Hard blows in the plan: 0 unless no plan within `MAX_BLOWS` avoids them.
    pub hard_blows: usize,
    pub plan: Vec<PlannedBlow>,
    /// Why the target cannot be reached, or why the plan needs hard blows.
    pub why: Option<String>,
}

/// Why no plan could be made at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AdviseError {
    #[error("{what} must be a finite height > 0 m, got {value}")]
    BadHeight { what: &'static str, value: f64 },
    #[error("impact speeds must be finite and > 0 m/s, got {0:?}")]
    BadSpeeds(Vec<f64>),
    #[error("the model could not simulate a blow at {v0_mps} m/s from {h_m} m: {why}")]
    Simulation { v0_mps: f64, h_m: f64, why: String },
}

/// The machine, its effects and the billet's sheet the advisor plans with.
pub struct Advisor<'a> {
    pub machine: &'a Machine,
    pub effects: &'a EffectSet,
    pub process: &'a Process,
    pub classes: EstimatorConfig,
    pub opts: SimOptions,
}

impl<'a> Advisor<'a> {
    pub fn new(machine: &'a Machine, effects: &'a EffectSet, process: &'a Process) -> Self {
        Advisor {
            machine,
            effects,
            process,
            classes: EstimatorConfig::for_kind(machine.kind()),
            opts: SimOptions::default(),
        }
    }

    /// One blow at `v0_mps` from height `h_m`, the `index`-th of the billet (1-based).
    fn strike(&self, h_m: f64, v0_mps: f64, index: usize) -> Result<PlannedBlow, AdviseError> {
        let plant = blow_plant(self.machine, self.effects, self.process, index, h_m);
        let r = simulate_blow(&plant, v0_mps, &self.opts).map_err(|e| AdviseError::Simulation {
            v0_mps,
            h_m,
            why: e.to_string(),
        })?;
        let efficiency = r.efficiency();
        let class = match self.classes.classify(efficiency) {
            BlowClass::Soft => "soft",
            BlowClass::Intermediate => "intermediate",
            _ => "hard",
        };
        Ok(PlannedBlow {
            blow: 0,
            v0_mps,
            kinetic_j: r.energy.kinetic_in_j,
            h_end_m: r.forming.map_or(h_m, |f| f.h_end_m),
            efficiency,
            class,
        })
    }

    /// Plan the fewest blows to the target: without hard blows if any plan within
    /// `MAX_BLOWS` does so, else the fewest blows with the fewest hard ones.
    pub fn plan(&self, req: &PlanRequest) -> Result<Plan, AdviseError> {
        for (what, value) in [("--h-now", req.h_now_m), ("--target", req.target_m)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(AdviseError::BadHeight { what, value });
            }
        }
        let tried = req.speeds.tried();
        if tried.is_empty() || tried.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(AdviseError::BadSpeeds(tried));
        }
        let (lo, hi) = (req.target_m - TARGET_TOLERANCE_M, req.target_m + TARGET_TOLERANCE_M);
        let mut plan = Plan {
            h_now_m: req.h_now_m,
            target_m: req.target_m,
            reachable: true,
            blows_to_target: Some(0),
            hard_blows: 0,
            plan: Vec::new(),
            why: None,
        };
        if req.h_now_m <= hi {
            if req.h_now_m < lo {
                plan.reachable = false;
                plan.blows_to_target = None;
                plan.why = Some("the billet is already below the target's window".into());
            }
            return Ok(plan);
        }
        // Search on the table, strike the found speeds exactly; where the exact blows part
        // from the table's (by its interpolation error) search again from where they are.
        let mut h = req.h_now_m;
        for _ in 0..MAX_REPLANS {
            let done = req.blows_done + plan.plan.len();
            let Some(found) = self.search(h, req, done, &tried, MAX_BLOWS - plan.plan.len())? else {
                return Ok(unreachable(plan, req, &tried, self, h, done));
            };
            for (i, step) in found.iter().enumerate() {
                let index = done + i + 1;
                let last = i + 1 == found.len();
                let mut b = match *step {
                    Step::Speed(k) if last && matches!(req.speeds, Speeds::UpTo(_)) => {
                        self.land_near(h, &tried, k, req.target_m, index)?
                    }
                    Step::Speed(k) => self.strike(h, tried[k], index)?,
                    Step::Between(a, b) => self.finish_between(h, tried[a], tried[b], req.target_m, index)?,
                };
                b.blow = plan.plan.len() + 1;
                h = b.h_end_m;
                plan.plan.push(b);
                if (lo..=hi).contains(&h) {
                    return Ok(finished(plan));
                }
                if h < lo {
                    break;
                }
            }
            if h < lo || plan.plan.len() >= MAX_BLOWS {
                break;
            }
        }
        plan.reachable = false;
        plan.blows_to_target = None;
        plan.why = Some(format!("the model's blows did not land in the window within {MAX_BLOWS} blows"));
        Ok(plan)
    }

    /// The fewest blows from `h_m` to the window by the table: every sequence of the tried
    /// speeds, their heights merged within `STATE_BUCKET_M` (the fewest hard blows kept),
    /// blow by blow. Without hard blows where any sequence within `max_blows` avoids them.
    fn search(
        &self,
        h_m: f64,
        req: &PlanRequest,
        done: usize,
        tried: &[f64],
        max_blows: usize,
    ) -> Result<Option<Vec<Step>>, AdviseError> {
        let (lo, hi) = (req.target_m - TARGET_TOLERANCE_M, req.target_m + TARGET_TOLERANCE_M);
        let thermal = self.effects.load.thermal_q_dt != 0.0;
        let mut tables: Vec<Table> = Vec::new();
        let mut nodes: Vec<Node> = vec![Node { h_m, hard: 0, parent: usize::MAX, step: Step::Speed(0) }];
        let mut frontier = vec![0usize];
        let mut fallback: Option<usize> = None;
        for depth in 1..=max_blows {
            // One table for every blow, or one per blow when the law changes with the blow's
            // index (the `thermal` effect).
            let slot = if thermal { depth - 1 } else { 0 };
            if tables.len() <= slot {
                let index = done + depth;
                let t = Table::build(lo - TABLE_STEP_M, h_m + TABLE_STEP_M, tried.len(), |h, k| {
                    self.strike(h, tried[k], index).map(|b| Outcome { h_end_m: b.h_end_m, efficiency: b.efficiency })
                })?;
                tables.push(t);
            }
            let table = &tables[slot];
            let hard_min = self.classes.intermediate_min;
            let mut next: std::collections::BTreeMap<i64, usize> = Default::default();
            let mut best_finish: Option<(usize, f64)> = None;
            for &n in &frontier {
                let (h, hard) = (nodes[n].h_m, nodes[n].hard);
                let outs: Vec<Outcome> = (0..tried.len()).map(|k| table.at(h, k)).collect();
                let mut candidates: Vec<(Step, f64, usize)> = outs
                    .iter()
                    .enumerate()
                    .map(|(k, o)| (Step::Speed(k), o.h_end_m, hard + usize::from(o.efficiency < hard_min)))
                    .collect();
                if let Speeds::UpTo(_) = req.speeds {
                    // Between two tried speeds that straddle the window, one lands in it.
                    for k in 1..outs.len() {
                        if outs[k - 1].h_end_m > hi && outs[k].h_end_m < lo {
                            let eff = outs[k - 1].efficiency.min(outs[k].efficiency);
                            candidates.push((
                                Step::Between(k - 1, k),
                                req.target_m,
                                hard + usize::from(eff < hard_min),
                            ));
                        }
                    }
                }
                for (step, h1, hard1) in candidates {
                    if h1 < lo {
                        continue;
                    }
                    let id = nodes.len();
                    nodes.push(Node { h_m: h1, hard: hard1, parent: n, step });
                    if h1 <= hi {
                        let score = (hard1, (h1 - req.target_m).abs());
                        let better = best_finish.is_none_or(|(b, d)| (nodes[b].hard, d) > score);
                        if better {
                            best_finish = Some((id, score.1));
                        }
                        continue;
                    }
                    let bucket = (h1 / STATE_BUCKET_M).floor() as i64;
                    match next.get(&bucket) {
                        Some(&old) if nodes[old].hard <= hard1 => {}
                        _ => {
                            next.insert(bucket, id);
                        }
                    }
                }
            }
            if let Some((id, _)) = best_finish {
                if nodes[id].hard == 0 {
                    return Ok(Some(path(&nodes, id)));
                }
                if fallback.is_none_or(|f| nodes[f].hard > nodes[id].hard) {
                    fallback = Some(id);
                }
            }
            frontier = next.into_values().collect();
            if frontier.len() > MAX_STATES {
                frontier.sort_by_key(|&n| nodes[n].hard);
                frontier.truncate(MAX_STATES);
            }
            if frontier.is_empty() {
                break;
            }
        }
        Ok(fallback.map(|id| path(&nodes, id)))
    }

    /// On a continuous range, the last blow at tried speed `k` moved onto the target: by
    /// bisection towards the neighbouring tried speed on the target's side.
    fn land_near(
        &self,
        h_m: f64,
        tried: &[f64],
        k: usize,
        target_m: f64,
        index: usize,
    ) -> Result<PlannedBlow, AdviseError> {
        let b = self.strike(h_m, tried[k], index)?;
        let neighbour = if b.h_end_m > target_m { tried.get(k + 1) } else { k.checked_sub(1).map(|j| &tried[j]) };
        match neighbour {
            Some(&v) if (b.h_end_m - target_m).abs() > 0.1 * TARGET_TOLERANCE_M => {
                let (slow, fast) = if v > tried[k] { (tried[k], v) } else { (v, tried[k]) };
                let m = self.finish_between(h_m, slow, fast, target_m, index)?;
                Ok(if (m.h_end_m - target_m).abs() < (b.h_end_m - target_m).abs() { m } else { b })
            }
            _ => Ok(b),
        }
    }

    /// On a continuous range, the blow whose end height is the target, by bisection between
    /// speeds `a` and `b` (the end height falls as the speed rises).
    fn finish_between(
        &self,
        h_m: f64,
        a: f64,
        b: f64,
        target_m: f64,
        index: usize,
    ) -> Result<PlannedBlow, AdviseError> {
        let (mut a, mut b) = (a, b);
        let mut best = self.strike(h_m, b, index)?;
        for _ in 0..BISECTION_STEPS {
            let mid = 0.5 * (a + b);
            let m = self.strike(h_m, mid, index)?;
            if m.h_end_m > target_m {
                a = mid;
            } else {
                b = mid;
            }
            if (m.h_end_m - target_m).abs() < (best.h_end_m - target_m).abs() {
                best = m;
            }
            if (best.h_end_m - target_m).abs() < 0.1 * TARGET_TOLERANCE_M {
                break;
            }
        }
        Ok(best)
    }
}

/// A blow of a found sequence: a tried speed, or a speed between two of them that lands on
/// the target.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Step {
    Speed(usize),
    Between(usize, usize),
}

/// A state of the search: a height reached, its hard blows and how.
#[derive(Debug, Clone, Copy)]
struct Node {
    h_m: f64,
    hard: usize,
    parent: usize,
    step: Step,
}

/// The steps from the start to node `id`.
fn path(nodes: &[Node], mut id: usize) -> Vec<Step> {
    let mut steps = Vec::new();
    while nodes[id].parent != usize::MAX {
        steps.push(nodes[id].step);
        id = nodes[id].parent;
    }
    steps.reverse();
    steps
}

/// The plan landed: count it and say why it has hard blows, if it has.
fn finished(mut plan: Plan) -> Plan {
    plan.hard_blows = plan.plan.iter().filter(|b| b.class == "hard").count();
    plan.blows_to_target = Some(plan.plan.len());
    if plan.hard_blows > 0 {
        plan.why = Some(format!(
            "no plan within {MAX_BLOWS} blows reaches the target without a hard blow: this one needs {}",
            plan.hard_blows
        ));
    }
    plan
}

/// No sequence reaches the window: say why.
fn unreachable(mut plan: Plan, req: &PlanRequest, tried: &[f64], adv: &Advisor<'_>, h_m: f64, done: usize) -> Plan {
    let lo = req.target_m - TARGET_TOLERANCE_M;
    let weakest = tried.iter().copied().fold(f64::INFINITY, f64::min);
    let overshoots = adv.strike(h_m, weakest, done + 1).is_ok_and(|b| b.h_end_m < lo);
    plan.reachable = false;
    plan.blows_to_target = None;
    plan.plan.clear();
    plan.why = Some(if overshoots {
        format!("the weakest blow ({weakest} m/s) takes the billet below the target's window")
    } else {
        match &req.speeds {
            Speeds::Settings(v) => format!(
                "no sequence of the settings {v:?} m/s lands within ±{:.1} mm of the target in {MAX_BLOWS} blows",
                TARGET_TOLERANCE_M * 1e3
            ),
            Speeds::UpTo(_) => format!("the target is not reached within {MAX_BLOWS} blows"),
        }
    });
    plan
}
/// The advice after a billet's latest blow, as `/status` serves it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Advice {
    /// The billet planned for (0: the next billet, before its first blow).
    pub billet: u32,
    /// Its blows so far; the plan's first blow is the next one.
    pub after_blow: u32,
    /// The plan (docs/interfaces.md §9, as `forgemon advise --json` prints it); `None` when it is not
    /// known, with the reason in `why_not`.
    pub plan: Option<Plan>,
    pub why_not: Option<String>,
    /// How long the plan took, ms.
    pub planned_ms: f64,
}

impl Advice {
    /// Blows still needed to reach the target, when a plan reaches it.
    pub fn blows_to_target(&self) -> Option<usize> {
        self.plan.as_ref().filter(|p| p.reachable).and_then(|p| p.blows_to_target)
    }

    /// The next blow's advised kinetic energy, J, when there is a next blow to strike.
    pub fn next_kinetic_j(&self) -> Option<f64> {
        self.plan.as_ref().filter(|p| p.reachable).and_then(|p| p.plan.first()).map(|b| b.kinetic_j)
    }
}
