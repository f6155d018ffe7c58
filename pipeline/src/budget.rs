//! What a variant may cost: `alnlab check` (and every run, which checks
//! first) estimates each variant's work from its parameters and refuses one
//! that cannot finish on a workstation, before anything runs or is written.
//!
//! The estimates are upper bounds made from the parameters alone (no data
//! yet): integration steps simulated, bytes of trajectory log, training
//! rows, tree-node evaluations in training, simulator steps and predictions
//! in the test stage, forward-model evaluations in the plan stage. The limits are [`Budget`]'s defaults — at least a hundred
//! times what the committed experiments ask for, and for the trees' memory
//! about what a large workstation holds — and a manifest may raise them in
//! `[experiment.budget]`.

use alnlab_aln::ModelKind;
use alnlab_common::params::Positive;
use serde::{Deserialize, Serialize};

use crate::stages::Stages;

/// The limits a variant's estimated work must stay under
/// (`[experiment.budget]`; every key optional).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Budget {
    /// Integration steps simulated, over every scene and run (default 1e10).
    #[serde(default = "default_steps")]
    pub steps: Positive,
    /// Bytes of trajectory log written (default 5e10, 50 GB).
    #[serde(default = "default_log_bytes")]
    pub log_bytes: Positive,
    /// Tree-node evaluations in training: epochs × training rows × trees ×
    /// leaves, or for a piecewise-linear model pwl.epochs × (pwl.rounds +
    /// 1) × training rows × variables × pwl.max_pieces (default 1e15).
    #[serde(default = "default_node_updates")]
    pub node_updates: Positive,
    /// Bytes of the trees in memory while training: trees × leaves × 16
    /// (default 6.4e10, 64 GB).
    #[serde(default = "default_model_bytes")]
    pub model_bytes: Positive,
    /// Steps and predictions of the test stage: the re-simulated baselines
    /// (steps per frame × test rows) plus closed-loop predictions (starts ×
    /// horizon × variables) (default 1e10).
    #[serde(default = "default_test_work")]
    pub test_work: Positive,
    /// Forward-model evaluations of the plan stage: tasks × episodes ×
    /// frames × planners × Σ budgets × horizon × (learned models + Σ the
    /// simulator's steps per frame) (default 1e11).
    #[serde(default = "default_plan_work")]
    pub plan_work: Positive,
}

fn default_steps() -> Positive {
    Positive(1e10)
}
fn default_log_bytes() -> Positive {
    Positive(5e10)
}
fn default_node_updates() -> Positive {
    Positive(1e15)
}
fn default_model_bytes() -> Positive {
    Positive(6.4e10)
}
fn default_test_work() -> Positive {
    Positive(1e10)
}
fn default_plan_work() -> Positive {
    Positive(1e11)
}

impl Default for Budget {
    fn default() -> Budget {
        Budget {
            steps: default_steps(),
            log_bytes: default_log_bytes(),
            node_updates: default_node_updates(),
            model_bytes: default_model_bytes(),
            test_work: default_test_work(),
            plan_work: default_plan_work(),
        }
    }
}

/// Upper estimates of one variant's work.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Integration steps simulated.
    pub steps: f64,
    /// Frames logged.
    pub frames: f64,
    /// Bytes of trajectory log.
    pub log_bytes: f64,
    /// Training rows.
    pub train_rows: f64,
    /// Tree-node evaluations in training.
    pub node_updates: f64,
    /// Bytes of the trees while training.
    pub model_bytes: f64,
    /// Test-stage steps and predictions.
    pub test_work: f64,
    /// Plan-stage forward-model evaluations (a simulator's counted in steps).
    pub plan_work: f64,
}

/// An upper estimate of the learned variables of a scene of `links` links:
/// a link's rates, velocities, accelerations, forces and angles (24), and
/// the root's extras.
fn variables(links: f64) -> f64 {
    24.0 * links + 12.0
}

impl Estimate {
    /// The estimate for `stages`.
    pub fn of(stages: &Stages) -> Estimate {
        let (mut steps, mut frames, mut log_bytes, mut vars) = (0.0, 0.0, 0.0, 0.0f64);
        for scene in &stages.simulate.scene {
            let runs = scene.runs.0 as f64;
            let links = scene.links.map_or(1.0, |n| n.0 as f64);
            let scene_frames = runs * (scene.duration.get() / scene.frame_dt.get() + 1.0);
            steps += runs * scene.duration.get() / scene.dt.get();
            frames += scene_frames;
            // Every variable and state component a float64, plus the header.
            log_bytes += scene_frames * (16.0 + 8.0 * (variables(links) + 13.0 * links));
            vars = vars.max(variables(links));
        }
        let stride = &stages.stride;
        let rows = frames / stride.n.0 as f64;
        let train_rows = stride.train_rows.map_or(rows, |cap| rows.min(cap.0 as f64));
        let test_rows = stride
            .test_rows
            .map_or(rows * stride.test_fraction.get(), |cap| cap.0 as f64);
        let q = &stages.quantize;
        let width = f64::from(q.code.width(q.levels.0.max(2) as usize, q.width.0 as u32));
        let t = &stages.train;
        let trees = vars * width * t.vote.0 as f64;
        let node_updates = match t.model {
            // Every round's LMS epochs and the polish, each row through every
            // piece of every variable's tree.
            ModelKind::PiecewiseLinear => {
                let (pwl, pieces) = (&t.pwl, t.pwl.max_pieces as f64);
                pwl.epochs as f64 * (pwl.rounds as f64 + 1.0) * train_rows * vars * pieces
            }
            _ => t.epochs.0 as f64 * train_rows * trees * t.leaves.0 as f64,
        };
        let test = &stages.test;
        let resimulated: f64 = test.resimulate_steps.iter().map(|s| s.0 as f64).sum();
        let closed_loop = test.rollout_starts.0 as f64 * test.horizon.0 as f64 * vars;
        let plan = &stages.plan;
        let decisions = plan.task.len() as f64 * plan.episodes.0 as f64 * plan.frames.0 as f64;
        let sum = |budgets: &[alnlab_common::params::Count]| {
            budgets.iter().map(|b| b.0 as f64).sum::<f64>()
        };
        let steps_simulated: f64 = plan
            .simulator_steps
            .iter()
            .chain(&plan.plant_steps)
            .map(|k| k.0 as f64)
            .sum();
        // Model evaluations: a learned model's one, a simulator's k steps.
        let evaluations = plan.models.len() as f64 * sum(&plan.budgets)
            + steps_simulated * sum(plan.simulator_budgets());
        let plan_work =
            decisions * plan.planners.len() as f64 * plan.horizon.0 as f64 * evaluations;
        Estimate {
            steps,
            frames,
            log_bytes,
            train_rows,
            node_updates,
            model_bytes: trees * t.leaves.0 as f64 * 16.0,
            test_work: resimulated * test_rows + closed_loop,
            plan_work,
        }
    }

    /// The first limit of `budget` this estimate exceeds: the stage table
    /// it concerns and a message saying what and how to proceed.
    pub fn exceeds(&self, budget: &Budget) -> Option<(&'static str, String)> {
        let over = [
            (
                "simulate",
                "integration steps",
                self.steps,
                budget.steps,
                "steps",
                "fewer runs, a shorter duration or a larger dt",
            ),
            (
                "simulate",
                "bytes of trajectory log",
                self.log_bytes,
                budget.log_bytes,
                "log_bytes",
                "fewer runs, a shorter duration or a larger frame_dt",
            ),
            (
                "train",
                "tree-node evaluations",
                self.node_updates,
                budget.node_updates,
                "node_updates",
                "fewer epochs, leaves, votes or training rows — for a piecewise-linear model, \
                 fewer pwl.epochs, pwl.rounds or pwl.max_pieces",
            ),
            (
                "train",
                "bytes of trees in memory",
                self.model_bytes,
                budget.model_bytes,
                "model_bytes",
                "fewer leaves, votes, output bits or variables",
            ),
            (
                "test",
                "test-stage steps and predictions",
                self.test_work,
                budget.test_work,
                "test_work",
                "fewer resimulate_steps, rollout_starts, a shorter horizon or fewer test rows",
            ),
            (
                "plan",
                "forward-model evaluations",
                self.plan_work,
                budget.plan_work,
                "plan_work",
                "fewer tasks, episodes, frames, planners or models, smaller budgets or a shorter \
                 horizon",
            ),
        ];
        over.into_iter()
            .find(|o| o.2 > o.3.get())
            .map(|(stage, what, estimate, limit, key, remedy)| {
                let limit = limit.get();
                (
                    stage,
                    format!(
                        "this asks for about {estimate:.2e} {what}, over the budget of {limit:.2e}: \
                         it would not finish (choose {remedy}, or raise \
                         `[experiment.budget] {key}` if you mean it)"
                    ),
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifest::Manifest;
    use std::path::Path;

    #[test]
    fn every_committed_experiment_is_well_within_budget() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments");
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            // Manifests; the scripts and tables beside them are not.
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let manifest = Manifest::load(&path).unwrap();
            for variant in &manifest.variants {
                let e = Estimate::of(&variant.stages);
                // Room to grow: a fifth of every limit (the trees' memory,
                // an overestimate for the strongest forest, half).
                let d = Budget::default();
                let tight = Budget {
                    steps: Positive(d.steps.get() / 5.0),
                    log_bytes: Positive(d.log_bytes.get() / 5.0),
                    node_updates: Positive(d.node_updates.get() / 5.0),
                    model_bytes: Positive(d.model_bytes.get() / 2.0),
                    test_work: Positive(d.test_work.get() / 5.0),
                    plan_work: Positive(d.plan_work.get() / 5.0),
                };
                assert_eq!(e.exceeds(&tight), None, "{}: {e:?}", path.display());
            }
        }
    }

    #[test]
    fn a_plan_too_large_is_refused_naming_its_table_and_key() {
        let text = r#"
            [experiment]
            name = "huge"
            seed = 1
            [plan]
            episodes = 1000
            frames = 1000
            budgets = [100000]
            [[plan.task]]
            kind = "spin"
            name = "spin"
            variable = "omega.1.x"
            rate = 1.0
        "#;
        // 1000 × 1000 decisions × 2 planners × 1e5 sequences × 10 frames ×
        // (aln + linear + 10 + 2 steps) = 2.8e13: refused before anything runs.
        let error = Manifest::parse(text, Path::new("huge.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("huge.toml")
                && error.contains("2.80e13 forward-model evaluations")
                && error.contains("plan_work"),
            "{error}"
        );
    }
}
