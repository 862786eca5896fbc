//! The global stage of a diagnosis's fit (`attribute::fit_candidates`): the points it costs
//! before the local search (the coarse grid of each candidate not held, a clearance's fine
//! scan over its gap and the gaps the measured closure shows) and their costs, each distinct
//! point costed once, and only where it can still be among the best (`Costed`).

use crate::identify::model::Param;
use crate::physics::machine::{Machine, MachineKind};

use super::attribute::{Candidate, log_points};
use super::blowset::BlowSet;

/// Local searches from the best grid points.
const GRID_STARTS: usize = 3;

/// Points of the fine scan of a `fine_first` parameter over its bounds: a gap within a
/// factor 1.15 (5000^(1/60)) of any in 1 µm..5 mm.
const FINE: usize = 60;

/// A point's cost, and a lower bound of it that is cheaper to take (the first blow's part).
#[derive(Clone, Copy)]
pub(super) struct Costs<'c> {
    pub(super) cost: &'c (dyn Fn(&[f64]) -> f64 + Sync),
    pub(super) bound: &'c (dyn Fn(&[f64]) -> f64 + Sync),
}

/// The global stage's points and their costs, each distinct point costed once (`Costed`).
/// Only the `GRID_STARTS` lowest costs are used (the starts, the scans around them, and the
/// lowest against a pair's first effect alone), so a point that cannot be among them is
/// not costed in full: its cost is INFINITY (`Costed::costs`).
pub(super) struct Scan<'c> {
    pub(super) points: Vec<Vec<f64>>,
    pub(super) costs: Vec<f64>,
    known: Costed,
    f: Costs<'c>,
}

impl<'c> Scan<'c> {
    /// The coarse grid over each candidate not held (every combination), then each
    /// fine-scanned parameter over its whole range and the gaps the measured closure shows,
    /// the others at each of the best grid points.
    pub(super) fn global(
        cands: &[&Candidate],
        params: &[Param],
        held: &[f64],
        calib: &BlowSet,
        machine: &Machine,
        f: Costs<'c>,
    ) -> Scan<'c> {
        let mut k = 0;
        let mut points: Vec<Vec<f64>> = vec![Vec::new()];
        for c in cands {
            let n = c.params.len();
            let axis = if k + n <= held.len() { vec![held[k..k + n].to_vec()] } else { c.grid_points() };
            k += n;
            points =
                points.into_iter().flat_map(|pt| axis.iter().map(move |v| [pt.clone(), v.clone()].concat())).collect();
        }
        let mut scan = Scan { points: Vec::new(), costs: Vec::new(), known: Costed::default(), f };
        scan.add(points);
        let fine = fine_points(cands, params, held.len(), &scan.best_points(), true);
        scan.add(fine);
        let closure = closure_points(cands, held.len(), calib, machine, &scan.best_points());
        scan.add(closure);
        scan
    }

    /// The local searches' starts: the `GRID_STARTS` best distinct points so far, and the
    /// best point of each candidate's ring scan (`Candidate::ring_points`, a press
    /// foundation's) about them, if it is costed: a start of its own beside the grid's, not
    /// in place of one. A ring point can cost less than the grid's best yet lead the local
    /// search into a worse valley: as the grid's starts, it took 3 of the family's 60
    /// rigid-eq3 press foundations at tune seeds 4120–4179 from a holdout shrink of
    /// 0.85–0.93 to 0.52–0.79, the local search ending on a lighter foundation.
    pub(super) fn starts(
        &mut self,
        cands: &[&Candidate],
        held: usize,
        kind: MachineKind,
        band_hz: (f64, f64),
    ) -> Vec<usize> {
        let mut starts = self.distinct_best(GRID_STARTS);
        let ring = ring_points(cands, held, kind, &self.best_points(), band_hz);
        if let Some(i) = self.add_best(ring).filter(|&i| self.costs[i].is_finite())
            && !starts.contains(&i)
        {
            starts.push(i);
        }
        starts
    }

    fn add(&mut self, points: Vec<Vec<f64>>) {
        let new = self.known.costs(&points, self.f, &self.costs);
        self.costs.extend(new);
        self.points.extend(points);
    }

    /// Adds `points`; the index of the best of them, if any.
    pub(super) fn add_best(&mut self, points: Vec<Vec<f64>>) -> Option<usize> {
        let k = self.points.len();
        self.add(points);
        best(&self.costs[k..], 1).next().map(|i| i + k)
    }

    /// The `GRID_STARTS` best points so far.
    fn best_points(&self) -> Vec<Vec<f64>> {
        best(&self.costs, GRID_STARTS).map(|i| self.points[i].clone()).collect()
    }

    /// The indices of the `k` best points, each distinct: a start that repeats an earlier
    /// one (a point the scans reached twice) would repeat its search to the bit.
    fn distinct_best(&self, k: usize) -> Vec<usize> {
        let mut seen = Vec::new();
        best(&self.costs, k)
            .filter(|&i| {
                let key = bits(&self.points[i]);
                let fresh = !seen.contains(&key);
                seen.push(key);
                fresh
            })
            .collect()
    }
}

/// The costs the global stage has evaluated, by point. The fine and closure scans around
/// several grid points repeat each other where the scanned gap is its candidate's only free
/// parameter (a hammer's clearance, alone or as a pair's second effect: 3 × 60 + 3 × 7
/// points, 67 of them distinct, and the scan after the local search all repeats): a point
/// already costed takes its cost again instead of another simulation of every calibration
/// blow. The cost is a function of the point alone, so nothing else changes.
#[derive(Default)]
struct Costed(std::collections::HashMap<Vec<u64>, f64>);

impl Costed {
    /// The cost of each of `points`, in order; each new distinct point evaluated once, in
    /// parallel. A new point whose bound (its first blow's cost) is already no lower than
    /// the `GRID_STARTS`th lowest cost of `so_far` and of the points costed before it (in
    /// the order of their bounds) cannot be among the lowest: it is not simulated further,
    /// nor remembered, and its cost is INFINITY. The lowest costs are those a full costing
    /// finds. On the family's report seed 4907 (hertz-tresca hammer, friction_rise hidden;
    /// timed only: nothing here changes a result), the foundation grids (289 points) took
    /// 0.8 s of each of their fits' 1.1-1.5 s, 0.35 s with the bound.
    fn costs(&mut self, points: &[Vec<f64>], f: Costs, so_far: &[f64]) -> Vec<f64> {
        use rayon::prelude::*;
        let mut queued = std::collections::HashSet::new();
        let fresh: Vec<(Vec<u64>, &Vec<f64>)> = points
            .iter()
            .map(|p| (bits(p), p))
            .filter(|(key, _)| !self.0.contains_key(key) && queued.insert(key.clone()))
            .collect();
        let bounds: Vec<f64> = fresh.par_iter().map(|(_, v)| (f.bound)(v)).collect();
        let mut order: Vec<usize> = (0..fresh.len()).collect();
        order.sort_by(|a, b| bounds[*a].total_cmp(&bounds[*b]));
        let mut lowest: Vec<f64> = so_far.to_vec();
        let batch = 2 * rayon::current_num_threads();
        for chunk in order.chunks(batch) {
            lowest.sort_by(f64::total_cmp);
            lowest.truncate(GRID_STARTS);
            let limit = if lowest.len() < GRID_STARTS { f64::INFINITY } else { lowest[GRID_STARTS - 1] };
            // In the bounds' order: once one reaches the limit, so do the rest.
            let todo: Vec<usize> =
                chunk.iter().copied().take_while(|&i| bounds[i] < limit || bounds[i].is_nan()).collect();
            if todo.is_empty() {
                break;
            }
            let new: Vec<f64> = todo.par_iter().map(|&i| (f.cost)(fresh[i].1)).collect();
            for (&i, c) in todo.iter().zip(new) {
                self.0.insert(fresh[i].0.clone(), c);
                lowest.push(c);
            }
        }
        points.iter().map(|p| self.0.get(&bits(p)).copied().unwrap_or(f64::INFINITY)).collect()
    }
}

/// A point's coordinates to the bit, as a key (distinct NaNs are distinct points).
fn bits(point: &[f64]) -> Vec<u64> {
    point.iter().map(|x| x.to_bits()).collect()
}

/// The indices of the `k` lowest costs, lowest first.
fn best(costs: &[f64], k: usize) -> impl Iterator<Item = usize> {
    let mut order: Vec<usize> = (0..costs.len()).collect();
    order.sort_by(|a, b| costs[*a].total_cmp(&costs[*b]));
    order.into_iter().take(k)
}

/// For each free parameter of a `fine_first` candidate (its first, past the `held` ones),
/// `FINE` log-spaced values over its bounds, the other parameters as at each of `around`.
/// With `whole_grid`, also at each of the candidate's grid values of its other parameters
/// (a press's lower die), the rest as at `around[0]`.
pub(super) fn fine_points(
    cands: &[&Candidate],
    params: &[Param],
    held: usize,
    around: &[Vec<f64>],
    whole_grid: bool,
) -> Vec<Vec<f64>> {
    let mut first = 0;
    let mut out = Vec::new();
    for c in cands {
        if c.fine_first() && first >= held {
            let fine = log_points(&params[first], FINE);
            let n = c.params.len();
            let mut at: Vec<Vec<f64>> = around.to_vec();
            if whole_grid && n > 1 && !around.is_empty() {
                let mut others: Vec<Vec<f64>> = c.grid_points().into_iter().map(|g| g[1..].to_vec()).collect();
                others.dedup();
                at.extend(others.into_iter().map(|g| {
                    let mut v = around[0].clone();
                    v[first + 1..first + n].copy_from_slice(&g);
                    v
                }));
            }
            for pt in &at {
                out.extend((0..FINE).map(|i| {
                    let mut v = pt.clone();
                    v[first] = fine[i];
                    v
                }));
            }
        }
        first += c.params.len();
    }
    out
}

/// Each candidate's ring scan (`Candidate::ring_points`, a press foundation's) about each of
/// `around`, over `band_hz` about the first (the best), for the candidates not held, the
/// other parameters as there.
fn ring_points(
    cands: &[&Candidate],
    held: usize,
    kind: MachineKind,
    around: &[Vec<f64>],
    band_hz: (f64, f64),
) -> Vec<Vec<f64>> {
    let mut first = 0;
    let mut out = Vec::new();
    for c in cands {
        let n = c.params.len();
        if first >= held {
            for (i, pt) in around.iter().enumerate() {
                let band = (i == 0).then_some(band_hz);
                out.extend(c.ring_points(kind, &pt[first..first + n], band).into_iter().map(|r| {
                    let mut v = pt.clone();
                    v[first..first + n].copy_from_slice(&r);
                    v
                }));
            }
        }
        first += n;
    }
    out
}

/// Points of the fine scan of a press's lower die over its bounds at the closure's gaps: a
/// mass within a factor 1.04 (1e4^(1/240)) of any in 10 kg..100 t.
const FINE_DIE: usize = 240;

/// The billet contacts with a press's loose die the global stage tries (`attribute::K_DIE`),
/// by half decades from a billet as stiff as the machine's own springs to the rigid one's
/// threshold (`attribute::K_DIE_RIGID_N_PER_M`).
const K_DIE_STEPS: [f64; 5] = [1e10, 3.16e10, 1e11, 3.16e11, 1e12];
/// The closure's multiples tried with a compliant die contact: a die thrown ahead crosses
/// its gap faster than the tool, so the measured closure is near the gap, not the up to
/// 4× of it the rigid shares allow.
const CLOSURE_SHARES_COMPLIANT: [f64; 3] = [0.7, 1.0, 1.4];
/// The die's masses tried with a compliant contact: within a factor 1.08 of any.
const FINE_DIE_COMPLIANT: usize = 120;

/// Multiples of the closure's gap (`BlowSet::closure_gap_m`) the global stage tries. Where
/// the closure is the ram's travel over the lead (a press): a lower tool struck off a heavier
/// ram as an elastic ball crosses up to twice that (2), one at the ram's speed all along the
/// whole (1), one accelerated from rest at a constant rate until it reaches the ram's speed
/// half (1/2), and one pushed by a load that builds up over the closure, with the load's rise
/// found at a level above its noise, less: 0.29 on the independent hammer at 0.25 mm (seed 3),
/// when its closure was the ram's travel too, so down to a quarter. The hammer's closure is
/// now what its lower tool crosses from rest (`closure_gap_m`), within 21 % of the hidden gap
/// on the independent blows, the press's within 12 %
/// (`tests/diagnose_independent.rs` `the_measured_closure_brackets_the_hidden_gap`, 0.1–0.5 mm).
const CLOSURE_SHARES: [f64; 7] = [0.25, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0];

/// For a clearance not held (the first parameter of a `fine_first` candidate), its gap at
/// `CLOSURE_SHARES` of the measured closure's, the other parameters as at each of `around`
/// (issue #17 item 3: "for a clearance, start from the gap the measured impact shows").
/// None when the calibration blows show no closure.
fn closure_points(
    cands: &[&Candidate],
    held: usize,
    calib: &BlowSet,
    machine: &Machine,
    around: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let Some(gap) = calib.closure_gap_m(machine) else { return Vec::new() };
    let mut first = 0;
    let mut out = Vec::new();
    for c in cands {
        if c.fine_first() && first >= held {
            let p = &c.params[0];
            for pt in around {
                out.extend(CLOSURE_SHARES.iter().map(|k| {
                    let mut v = pt.clone();
                    v[first] = (k * gap).clamp(p.lo, p.hi);
                    v
                }));
            }
            // A press's lower die: at each of those gaps, its mass finely over its bounds. Its
            // valley is narrow (tests/independent/drawn.rs, tune seed 4101: a 0.14 mm gap under
            // 1.5 t has a calibration cost 100× below the fit's, and under 1.2 t or 1.8 t one
            // above the base model's), far narrower than the coarse grid's step (×1.7).
            if let (Some(die), Some(pt)) = (c.params.get(1), around.first()) {
                let masses = log_points(die, FINE_DIE);
                for k in CLOSURE_SHARES {
                    out.extend(masses.iter().map(|m| {
                        let mut v = pt.clone();
                        v[first] = (k * gap).clamp(p.lo, p.hi);
                        v[first + 1] = *m;
                        v
                    }));
                }
                // The die struck through a compliant billet contact: thrown ahead of the tool,
                // it rebounds where a rigid contact carries it along. A rigid fit of such
                // blows misses the gap (the family's elastic-siebel press, tune seed 4102:
                // 0.31 mm under 105 kg fitted at 0.13 mm, holdout error 0.040 against the
                // base model's 0.079); the compliant one from these points finds 0.31 mm at
                // 1e12 N/m, the renderer's billet, and 0.010. Its mass as finely, at fewer
                // gaps.
                if c.params.get(2).is_some() {
                    let masses = log_points(die, FINE_DIE_COMPLIANT);
                    for kd in K_DIE_STEPS {
                        for k in CLOSURE_SHARES_COMPLIANT {
                            out.extend(masses.iter().map(|m| {
                                let mut v = pt.clone();
                                v[first] = (k * gap).clamp(p.lo, p.hi);
                                v[first + 1] = *m;
                                v[first + 2] = kd;
                                v
                            }));
                        }
                    }
                }
            }
        }
        first += c.params.len();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn a_point_costed_once_keeps_its_cost_and_is_not_costed_again() {
        // The scans as a one-parameter clearance makes them: the same fine points around
        // three grid points, then again around the fitted one, with NaN and -0.0 among them
        // (kept apart from 0.0 and from each other by their bits: a key, not a comparison).
        let calls = AtomicUsize::new(0);
        let cost = |v: &[f64]| {
            calls.fetch_add(1, Ordering::Relaxed);
            v.iter().map(|x| (x - 0.3).powi(2)).sum::<f64>()
        };
        // A bound of 0 prunes nothing.
        let f = Costs { cost: &cost, bound: &|_: &[f64]| 0.0 };
        let line: Vec<Vec<f64>> = (0..60).map(|i| vec![1e-6 * 1.15f64.powi(i)]).collect();
        let mut known = Costed::default();
        let mut all = Vec::new();
        for _ in 0..3 {
            all.extend(known.costs(&line, f, &[]));
        }
        assert_eq!(calls.load(Ordering::Relaxed), 60);
        let odd = vec![vec![f64::NAN], vec![-0.0], vec![0.0], vec![f64::NAN], line[7].clone()];
        let got = known.costs(&odd, f, &all);
        assert_eq!(calls.load(Ordering::Relaxed), 63, "NaN, -0.0 and 0.0 once each; line[7] known");
        // Every cost is the cost function's own value at that point, in the points' order.
        for (p, c) in line.iter().cycle().zip(&all).chain(odd.iter().zip(&got)) {
            assert_eq!(c.to_bits(), cost(p).to_bits(), "{p:?}");
        }
    }

    #[test]
    fn points_whose_bound_rules_them_out_are_not_costed_and_the_lowest_costs_are_kept() {
        // A cost of five "blows", the first of which bounds it: a 17 × 17 grid with a valley
        // off its axes, and a few points whose simulation fails (INFINITY).
        let blow = |v: &[f64], k: usize| {
            ((v[0] - 0.37).powi(2) + (v[1] - 0.61 - 0.01 * k as f64).powi(2)) * (1.0 + 0.1 * k as f64)
        };
        let calls = AtomicUsize::new(0);
        let cost = |v: &[f64]| {
            calls.fetch_add(1, Ordering::Relaxed);
            if v[0] > 0.95 { f64::INFINITY } else { (0..5).map(|k| blow(v, k)).sum() }
        };
        let bound = |v: &[f64]| if v[0] > 0.95 { f64::INFINITY } else { blow(v, 0) };
        let grid: Vec<Vec<f64>> =
            (0..17).flat_map(|i| (0..17).map(move |j| vec![i as f64 / 16.0, j as f64 / 16.0])).collect();
        let full: Vec<f64> = grid.iter().map(|p| cost(p)).collect();
        calls.store(0, Ordering::Relaxed);
        let mut known = Costed::default();
        let got = known.costs(&grid, Costs { cost: &cost, bound: &bound }, &[]);
        let n = calls.load(Ordering::Relaxed);
        assert!(n < grid.len() / 4, "{n} of {} points costed in full", grid.len());
        // The lowest GRID_STARTS are the full costing's, at the same points; every other cost
        // is either the point's own or INFINITY, never lower than the lowest ones.
        assert_eq!(best(&got, GRID_STARTS).collect::<Vec<_>>(), best(&full, GRID_STARTS).collect::<Vec<_>>());
        let third = full[best(&full, GRID_STARTS).last().unwrap()];
        for (g, c) in got.iter().zip(&full) {
            assert!(g.to_bits() == c.to_bits() || (*g == f64::INFINITY && *c >= third), "{g} against {c}");
        }
        // A point left out is not remembered: asked again beside lower costs, it is pruned
        // again; asked alone, it is costed.
        let out =
            got.iter().position(|c| c.is_infinite() && full[got.iter().position(|g| g == c).unwrap()].is_finite());
        let out = out.map(|i| grid[i].clone()).expect("a finite point left out");
        let before = calls.load(Ordering::Relaxed);
        assert!(known.costs(std::slice::from_ref(&out), Costs { cost: &cost, bound: &bound }, &got)[0].is_infinite());
        assert_eq!(calls.load(Ordering::Relaxed), before);
        let alone = known.costs(std::slice::from_ref(&out), Costs { cost: &cost, bound: &bound }, &[])[0];
        assert_eq!(alone.to_bits(), cost(&out).to_bits());
    }
}
