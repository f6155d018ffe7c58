//! Sampling-based model-predictive planners: each decision searches torque
//! sequences over a horizon of H frames with a forward model, and the first
//! frame's torques of the best one found are executed.
//!
//! - **Random shooting**: N sequences drawn uniformly within the torque
//!   bounds, each held constant per frame.
//! - **Cross-entropy method** (CEM): `iterations` rounds of N / iterations
//!   sequences drawn from a Gaussian per frame and torque component
//!   (clamped to the bounds), refitted each round to the `elite` fraction
//!   with the lowest cost.
//!
//! Both try the previous decision's best sequence, shifted by one frame
//! (its last frame repeated), first: a plan carried over is never lost to an
//! unlucky draw. The budget of a decision is N sequences of H frames: N·H
//! forward-model evaluations. Every draw comes from the planner's own seeded
//! generator, so the same seed gives the same decisions.
//!
//! Buffers are sized once for the largest budget; a decision allocates
//! nothing.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// A forward model as a planner sees it: the predicted cost of candidate
/// torque sequences from the state the system is in now.
pub trait Forward {
    /// `actions` holds `costs.len()` sequences back to back, each `horizon`
    /// frames of [`Bounds::dims`] torques; writes each sequence's predicted
    /// cost summed over its frames into `costs`.
    fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]);
}

/// Which planner.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlannerKind {
    RandomShooting,
    Cem,
}

impl PlannerKind {
    /// The name in manifests and tables.
    pub fn name(self) -> &'static str {
        match self {
            PlannerKind::RandomShooting => "random-shooting",
            PlannerKind::Cem => "cem",
        }
    }
}

/// The box the torques are searched in: per component, low and high.
#[derive(Clone, Debug, PartialEq)]
pub struct Bounds {
    pub low: Vec<f64>,
    pub high: Vec<f64>,
}

impl Bounds {
    /// Torque components per frame.
    pub fn dims(&self) -> usize {
        self.low.len()
    }
}

/// How the cross-entropy method refits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CemSettings {
    /// Rounds per decision (≥ 1).
    pub iterations: usize,
    /// The fraction of a round's sequences its refit keeps.
    pub elite: f64,
}

/// One planner for one episode.
pub struct Planner {
    kind: PlannerKind,
    cem: CemSettings,
    horizon: usize,
    bounds: Bounds,
    rng: ChaCha8Rng,
    /// The previous decision's best sequence (H × D).
    best: Vec<f64>,
    /// Candidates (N × H × D) and their costs.
    candidates: Vec<f64>,
    costs: Vec<f64>,
    /// The CEM's mean and spread (H × D), and a round's ranking.
    mean: Vec<f64>,
    spread: Vec<f64>,
    order: Vec<usize>,
    /// The last decision's spread of predicted costs: the largest less the
    /// least finite cost among its first candidates (0 when the model gives
    /// every candidate the same cost).
    cost_spread: f64,
}

impl Planner {
    /// A planner over `horizon` frames in `bounds`, for budgets of up to
    /// `max_sequences`, seeded; its first plan carried over is zero torque
    /// (clamped into the bounds).
    pub fn new(
        kind: PlannerKind,
        cem: CemSettings,
        horizon: usize,
        bounds: Bounds,
        max_sequences: usize,
        seed: u64,
    ) -> Planner {
        let d = bounds.dims();
        let zero: Vec<f64> = (0..horizon * d)
            .map(|k| 0f64.clamp(bounds.low[k % d], bounds.high[k % d]))
            .collect();
        Planner {
            kind,
            cem,
            horizon,
            rng: ChaCha8Rng::seed_from_u64(seed),
            best: zero,
            candidates: vec![0.0; max_sequences.max(1) * horizon * d],
            costs: vec![0.0; max_sequences.max(1)],
            mean: vec![0.0; horizon * d],
            spread: vec![0.0; horizon * d],
            cost_spread: 0.0,
            order: Vec::with_capacity(max_sequences.max(1)),
            bounds,
        }
    }

    /// Chooses this frame's torques (`action`, D values) with `sequences`
    /// candidate sequences (at most the planner's maximum); returns the
    /// predicted cost of the sequence chosen.
    pub fn decide(&mut self, model: &mut dyn Forward, sequences: usize, action: &mut [f64]) -> f64 {
        let n = sequences.clamp(1, self.costs.len());
        let d = self.bounds.dims();
        let len = self.horizon * d;
        // The carried-over plan, one frame on: its last frame repeated.
        self.best.copy_within(d.min(len).., 0);
        let tail = len - d.min(len);
        self.best.copy_within(tail.saturating_sub(d)..tail, tail);
        let cost = match self.kind {
            PlannerKind::RandomShooting => {
                self.candidates[..len].copy_from_slice(&self.best);
                for k in len..n * len {
                    let c = k % d;
                    self.candidates[k] = self
                        .rng
                        .random_range(self.bounds.low[c]..=self.bounds.high[c]);
                }
                model.costs(
                    &self.candidates[..n * len],
                    self.horizon,
                    &mut self.costs[..n],
                );
                self.cost_spread = spread_of(&self.costs[..n]);
                let i = argmin(&self.costs[..n]);
                self.best
                    .copy_from_slice(&self.candidates[i * len..(i + 1) * len]);
                self.costs[i]
            }
            PlannerKind::Cem => self.cem(model, n),
        };
        action.copy_from_slice(&self.best[..d]);
        cost
    }

    /// The cross-entropy method's rounds; leaves the best sequence seen in
    /// `best` and returns its cost.
    fn cem(&mut self, model: &mut dyn Forward, n: usize) -> f64 {
        let d = self.bounds.dims();
        let len = self.horizon * d;
        let rounds = self.cem.iterations.clamp(1, n);
        let per_round = n / rounds;
        let elites = ((per_round as f64 * self.cem.elite).ceil() as usize).clamp(1, per_round);
        self.mean.copy_from_slice(&self.best);
        for (k, s) in self.spread.iter_mut().enumerate() {
            let c = k % d;
            *s = (self.bounds.high[c] - self.bounds.low[c]) / 2.0;
        }
        let mut best_cost = f64::INFINITY;
        for round in 0..rounds {
            // The carried-over plan (first round) or the mean so far (later
            // rounds) is tried as it is; the rest are drawn around the mean.
            self.candidates[..len].copy_from_slice(&self.mean);
            for k in len..per_round * len {
                let c = k % d;
                let z: f64 = self.rng.sample(StandardNormal);
                let j = k % len;
                self.candidates[k] = (self.mean[j] + self.spread[j] * z)
                    .clamp(self.bounds.low[c], self.bounds.high[c]);
            }
            let costs = &mut self.costs[..per_round];
            model.costs(&self.candidates[..per_round * len], self.horizon, costs);
            if round == 0 {
                self.cost_spread = spread_of(costs);
            }
            self.order.clear();
            self.order.extend(0..per_round);
            let costs = &self.costs[..per_round];
            self.order
                .sort_unstable_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
            let top = self.order[0];
            if costs[top] < best_cost {
                best_cost = costs[top];
                // Keep the best apart: the next round overwrites candidates.
                self.best
                    .copy_from_slice(&self.candidates[top * len..(top + 1) * len]);
            }
            for j in 0..len {
                let values = self.order[..elites]
                    .iter()
                    .map(|&i| self.candidates[i * len + j]);
                let mean = values.clone().sum::<f64>() / elites as f64;
                let var = values.map(|x| (x - mean) * (x - mean)).sum::<f64>() / elites as f64;
                self.mean[j] = mean;
                self.spread[j] = var.sqrt();
            }
        }
        best_cost
    }
}

impl Planner {
    /// The spread of predicted costs at the last decision: the largest
    /// less the least finite cost of its first candidates (for the CEM, its
    /// first round's, drawn over the whole range).
    pub fn cost_spread(&self) -> f64 {
        self.cost_spread
    }
}

/// The largest less the least finite value (0 when none or one).
fn spread_of(costs: &[f64]) -> f64 {
    let finite = costs.iter().copied().filter(|c| c.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
        (lo.min(c), hi.max(c))
    });
    if hi >= lo { hi - lo } else { 0.0 }
}

/// The index of the lowest value (the first of equals).
fn argmin(values: &[f64]) -> usize {
    values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1).then(a.0.cmp(&b.0)))
        .map_or(0, |(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cart on a line: x' = x + u per frame, cost (x − goal)² per frame,
    /// u in [−1, 1]. From x = 0 with goal 3 the optimum is u = 1 for three
    /// frames, then 0: summed cost 4 + 1 + 0 + 0 … over the horizon.
    struct Cart {
        x: f64,
        goal: f64,
        evaluations: usize,
    }

    impl Forward for Cart {
        fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) {
            for (sequence, cost) in actions.chunks(horizon).zip(costs.iter_mut()) {
                let mut x = self.x;
                *cost = 0.0;
                for u in sequence {
                    x += u;
                    *cost += (x - self.goal) * (x - self.goal);
                    self.evaluations += 1;
                }
            }
        }
    }

    fn drive(
        kind: PlannerKind,
        horizon: usize,
        sequences: usize,
        frames: usize,
    ) -> (Vec<f64>, f64, usize) {
        let bounds = Bounds {
            low: vec![-1.0],
            high: vec![1.0],
        };
        let cem = CemSettings {
            iterations: 4,
            elite: 0.1,
        };
        let mut planner = Planner::new(kind, cem, horizon, bounds, sequences, 7);
        let mut cart = Cart {
            x: 0.0,
            goal: 3.0,
            evaluations: 0,
        };
        let (mut path, mut cost) = (Vec::new(), 0.0);
        let mut u = [0.0];
        for _ in 0..frames {
            planner.decide(&mut cart, sequences, &mut u);
            cart.x += u[0];
            cost += (cart.x - cart.goal).powi(2);
            path.push(cart.x);
        }
        (path, cost, cart.evaluations)
    }

    #[test]
    fn planners_find_the_known_optimum_of_a_toy_model() {
        // The optimal closed loop reaches 3 in three frames and stays:
        // summed cost 4 + 1 + 0 + … = 5. Random shooting one frame ahead
        // (a 1-D search) and the CEM six frames ahead both find it.
        for (kind, horizon) in [(PlannerKind::RandomShooting, 1), (PlannerKind::Cem, 6)] {
            let (path, cost, evaluations) = drive(kind, horizon, 400, 10);
            assert!(
                (cost - 5.0).abs() < 0.3,
                "{kind:?}: cost {cost}, path {path:?}"
            );
            assert!(
                (path[9] - 3.0).abs() < 0.1,
                "{kind:?} holds the goal: {path:?}"
            );
            assert_eq!(evaluations, 10 * 400 * horizon, "{kind:?}: N·H evaluations");
        }
        // Random shooting six frames ahead draws 6-D sequences: a small
        // budget does worse than a large one, neither is optimal.
        let (_, small, _) = drive(PlannerKind::RandomShooting, 6, 4, 10);
        let (_, large, _) = drive(PlannerKind::RandomShooting, 6, 400, 10);
        assert!(small > large && large > 5.0, "{small} vs {large}");
    }

    #[test]
    fn the_same_seed_gives_the_same_decisions() {
        for kind in [PlannerKind::RandomShooting, PlannerKind::Cem] {
            assert_eq!(drive(kind, 4, 50, 8).0, drive(kind, 4, 50, 8).0);
        }
    }

    #[test]
    fn actions_stay_in_bounds() {
        struct Far;
        impl Forward for Far {
            // Rewards ever larger torques: the planner pushes to the bound.
            fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) {
                for (s, c) in actions.chunks(horizon * 2).zip(costs.iter_mut()) {
                    *c = -s.iter().sum::<f64>();
                }
            }
        }
        let bounds = Bounds {
            low: vec![-2.0, -0.5],
            high: vec![2.0, 0.5],
        };
        let cem = CemSettings {
            iterations: 3,
            elite: 0.2,
        };
        for kind in [PlannerKind::RandomShooting, PlannerKind::Cem] {
            let mut planner = Planner::new(kind, cem, 4, bounds.clone(), 90, 1);
            let mut u = [0.0; 2];
            for _ in 0..5 {
                planner.decide(&mut Far, 90, &mut u);
                assert!(u[0] <= 2.0 && u[0] >= -2.0 && u[1].abs() <= 0.5, "{u:?}");
            }
            if kind == PlannerKind::Cem {
                assert!(u[0] > 1.5 && u[1] > 0.4, "{kind:?} near the bound: {u:?}");
            }
        }
    }
}
