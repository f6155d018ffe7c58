//! The piecewise-linear model from the stage's files (`model =
//! "piecewise-linear"`): per predicted variable one tree ([`crate::pwl`]),
//! trained in parallel, over the current state's logged real values.
//!
//! - **Inputs: real values, not levels.** `pairs.parquet` holds the values
//!   the levels were made from; a level throws away up to half a spacing
//!   of every input, noise a linear piece would pass on to its output.
//!   Each tree reads the output's informative inputs (chosen on the levels
//!   against the change of level, as for the bit models' change targets)
//!   and always the variable itself.
//! - **Target: the change** of the variable's real value, on the circle
//!   for an angle that wraps, in level spacings — so a tree of one piece is
//!   the robust linear baseline and every figure stays in levels.
//! - **Standardized while training**, then folded into each piece's
//!   coefficients, so the model reads the real values as logged.
//! - **Controls given** (`controls = "given"`): the controller's torques g
//!   are read, never predicted.
//! - **What a planner can give** (`never_read`): the state's variables of
//!   the groups named are read by no tree but their own — a frame's
//!   accelerations are those under the torque it applies, which a planner
//!   cannot supply for a candidate torque.
//! - **A hybrid** (`base = "nominal"`, issue 43): the trees also read the
//!   nominal simulator's prediction of every variable (the nominal stage's
//!   `nominal.parquet`: the scene as written, stepped one frame), chosen
//!   among the informative inputs as the state's values are, and always
//!   their own; each learns the change from its variable's nominal
//!   prediction to the logged next value — what the plant did beyond its
//!   nominal model.

use alnlab_aln::linear::least_absolute;
use alnlab_aln::pwl::predict::change;
use alnlab_aln::pwl::{MAX_PIECES, Tree};
use alnlab_codes::Entry;
use alnlab_codes::codebook::{group_of, is_control};
use alnlab_codes::residual::change as level_change;
use alnlab_common::{Error, Result};
use alnlab_tables::levels::Levels;
use alnlab_tables::pairs::{Pairs, Side};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::pwl::{Round, Samples, Settings, Split, train_from};
use crate::select;

/// The `[train.pwl]` table: how each piecewise-linear tree is trained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PwlParams {
    /// How a piece the noise does not explain splits: `hinge` (a kink
    /// fitted at once, robustly) or `copy` (the authors' MIN or MAX of two
    /// copies, pulled apart by the LMS steps).
    pub split: SplitKind,
    /// Where training starts: the robust linear fit of the change
    /// (`linear`) or the targets' mean (`mean`).
    pub start: Start,
    /// LMS epochs between split passes.
    pub epochs: usize,
    /// Split passes at most.
    pub rounds: usize,
    /// The LMS learning rate while growing (the polish runs at a quarter).
    pub rate: f64,
    /// Pieces per tree at most.
    pub max_pieces: usize,
    /// Huber's step in noise standard deviations (absent: least squares).
    pub huber: Option<f64>,
    /// The F-test's level for splitting.
    pub confidence: f64,
    /// A declared noise (level spacings) instead of the nearest-neighbour
    /// estimate.
    pub tolerance: Option<f64>,
    /// With the controls given: every tree reads every control besides its
    /// informative inputs, so that a planner's torques move every
    /// prediction (a forward model's need, not the one-step error's).
    pub read_controls: bool,
    /// Groups of variables (`qdd`, `v`, … as the codebook groups them) the
    /// trees never read of the current state, each tree but its own
    /// variable: a frame's accelerations are those under the torque it
    /// applies, which a planner cannot give for a candidate torque.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub never_read: Vec<String>,
}

/// `split`'s values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SplitKind {
    Hinge,
    Copy,
}

/// `start`'s values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Start {
    Linear,
    Mean,
}

impl Default for PwlParams {
    fn default() -> Self {
        PwlParams {
            split: SplitKind::Hinge,
            start: Start::Linear,
            epochs: 2,
            rounds: 100,
            rate: 0.002,
            max_pieces: 64,
            huber: Some(1.0),
            confidence: 0.75,
            tolerance: None,
            read_controls: false,
            never_read: Vec::new(),
        }
    }
}

impl PwlParams {
    /// Checks the values; on error, the key and what is allowed.
    pub fn validate(&self) -> std::result::Result<(), (String, String)> {
        let bad = |key: &str, what: String| Err((format!("pwl.{key}"), what));
        if !(self.rate > 0.0 && self.rate <= 1.0) {
            return bad(
                "rate",
                format!("expected 0 < rate ≤ 1, found {}", self.rate),
            );
        }
        if !(1..=MAX_PIECES).contains(&self.max_pieces) {
            return bad(
                "max_pieces",
                format!("expected 1 to {MAX_PIECES}, found {}", self.max_pieces),
            );
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return bad(
                "confidence",
                format!(
                    "expected a level between 0 and 1, found {}",
                    self.confidence
                ),
            );
        }
        if let Some(empty) = self.never_read.iter().position(|g| g.is_empty()) {
            return bad(
                "never_read",
                format!("entry {empty} is empty: expected a group of variables, e.g. \"qdd\""),
            );
        }
        for (key, value) in [("huber", self.huber), ("tolerance", self.tolerance)] {
            if let Some(v) = value.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return bad(key, format!("expected a positive number, found {v}"));
            }
        }
        Ok(())
    }

    fn settings(&self, seed: u64) -> Settings {
        Settings {
            epochs_per_round: self.epochs,
            rounds: self.rounds,
            rate: self.rate,
            polish_rate: self.rate / 4.0,
            polish_epochs: self.epochs,
            max_pieces: self.max_pieces,
            tolerance: self.tolerance,
            confidence: self.confidence,
            huber: self.huber,
            seed,
            split: match self.split {
                SplitKind::Hinge => Split::Hinge,
                SplitKind::Copy => Split::Copy,
            },
            ..Settings::default()
        }
    }
}

/// One trained output: its variable, the inputs its tree reads (indices
/// among the learned variables, then, for a hybrid, their nominal
/// predictions) and the tree, with its rounds.
pub struct TrainedTree {
    pub variable: usize,
    pub reads: Vec<usize>,
    pub tree: Tree,
    pub rounds: Vec<Round>,
}

/// Trains one tree per predicted variable on the training `rows`.
/// `levels` gives the level columns the informative inputs are chosen on;
/// `pairs` the real values; `nominal`, for a hybrid, the nominal
/// simulator's predictions of the same rows.
#[allow(clippy::too_many_arguments)]
pub fn train(
    params: &PwlParams,
    informative: Option<usize>,
    controls_given: bool,
    seed: u64,
    learned: &[&Entry],
    levels: &Levels,
    pairs: &Pairs,
    nominal: Option<&Pairs>,
    rows: &[usize],
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<TrainedTree>> {
    if pairs.keys() != levels.keys() {
        return Err(Error::bad_file(
            pairs.path(),
            format!(
                "does not hold the pairs {} was made from ({} rows against {})",
                levels.path().display(),
                pairs.len(),
                levels.len()
            ),
        ));
    }
    let (mut x, y) = (
        pairs.values(Side::Current, learned)?,
        pairs.values(Side::Next, learned)?,
    );
    let width = learned.len();
    // A hybrid's inputs are the state, then the nominal simulator's
    // prediction of it, from which its changes are measured.
    if let Some(nominal) = nominal {
        if nominal.keys() != pairs.keys() {
            return Err(Error::bad_file(
                nominal.path(),
                format!(
                    "does not hold the nominal predictions of {} ({} rows against {})",
                    pairs.path().display(),
                    nominal.len(),
                    pairs.len()
                ),
            ));
        }
        x.extend(nominal.values(Side::Next, learned)?);
    }
    let base_of = |v: usize| if nominal.is_some() { width + v } else { v };
    let predicted: Vec<usize> = (0..learned.len())
        .filter(|&v| !(controls_given && is_control(&learned[v].variable)))
        .collect();
    // The inputs any tree may read: every one but the state's variables of
    // the groups `never_read` names (each tree still reads its own).
    let readable: Vec<usize> = (0..x.len())
        .filter(|&u| {
            u >= width
                || !params
                    .never_read
                    .iter()
                    .any(|g| group_of(&learned[u].variable) == g)
        })
        .collect();
    let reads: Vec<Vec<usize>> = match informative {
        Some(count) => {
            let mut x_levels: Vec<std::borrow::Cow<[u16]>> = learned
                .iter()
                .map(|e| {
                    levels
                        .column(Side::Current, e)
                        .map(std::borrow::Cow::Borrowed)
                })
                .collect::<Result<_>>()?;
            // A nominal prediction is chosen on its level, as a state is.
            for (v, column) in x[width..].iter().enumerate() {
                let q = &learned[v].quantizer;
                x_levels.push(column.iter().map(|&value| q.level(value).0).collect());
            }
            // Scored against what the tree learns: the change of level (on
            // the circle for an angle) from its base, shifted to be
            // non-negative.
            let changes: Vec<Vec<u16>> = predicted
                .iter()
                .map(|&v| {
                    let y = levels.column(Side::Next, learned[v])?;
                    let period = learned[v].period();
                    let top = i32::from(u16::MAX / 2);
                    Ok(x_levels[base_of(v)]
                        .iter()
                        .zip(y)
                        .map(|(&x, &y)| (level_change(x, y, period).clamp(-top, top) + top) as u16)
                        .collect())
                })
                .collect::<Result<_>>()?;
            let targets: Vec<&[u16]> = changes.iter().map(Vec::as_slice).collect();
            // Chosen among the inputs a tree may read.
            let pool: Vec<&[u16]> = readable.iter().map(|&u| x_levels[u].as_ref()).collect();
            let chosen = select::informative(&pool, &targets, rows, count);
            chosen
                .into_iter()
                .zip(&predicted)
                .map(|(inputs, &v)| {
                    let mut inputs: Vec<usize> = inputs.into_iter().map(|i| readable[i]).collect();
                    for own in [v, base_of(v)] {
                        if !inputs.contains(&own) {
                            inputs.push(own);
                        }
                    }
                    if controls_given && params.read_controls {
                        let controls =
                            (0..learned.len()).filter(|&u| is_control(&learned[u].variable));
                        for u in controls {
                            if !inputs.contains(&u) {
                                inputs.push(u);
                            }
                        }
                    }
                    inputs.sort_unstable();
                    inputs
                })
                .collect()
        }
        None => predicted
            .iter()
            .map(|&v| {
                let mut inputs = readable.clone();
                for own in [v, base_of(v)] {
                    if !inputs.contains(&own) {
                        inputs.push(own);
                    }
                }
                inputs.sort_unstable();
                inputs
            })
            .collect(),
    };
    // Standardization on the training rows.
    let scale: Vec<(f64, f64)> = x
        .iter()
        .map(|column| {
            let n = rows.len() as f64;
            let mean = rows.iter().map(|&r| column[r]).sum::<f64>() / n;
            let spread = (rows
                .iter()
                .map(|&r| (column[r] - mean).powi(2))
                .sum::<f64>()
                / n)
                .sqrt();
            (mean, if spread > 0.0 { spread } else { 1.0 })
        })
        .collect();
    let settings = params.settings(seed);
    Ok(predicted
        .par_iter()
        .zip(reads)
        .map(|(&v, inputs)| {
            let standard: Vec<f64> = rows
                .iter()
                .flat_map(|&r| {
                    inputs
                        .iter()
                        .map(|&i| (x[i][r] - scale[i].0) / scale[i].1)
                        .collect::<Vec<_>>()
                })
                .collect();
            let target: Vec<f64> = rows
                .iter()
                .map(|&r| change(learned[v], x[base_of(v)][r], y[v][r]))
                .collect();
            let samples = Samples {
                x: &standard,
                y: &target,
                inputs: inputs.len(),
            };
            let plane = least_absolute(&standard, &target, inputs.len());
            let start = match params.start {
                Start::Linear => Some((plane.0, plane.1.as_slice())),
                Start::Mean => None,
            };
            let (tree, rounds) = train_from(&samples, &settings, start);
            let folded: Vec<(f64, f64)> = inputs.iter().map(|&i| scale[i]).collect();
            tick();
            TrainedTree {
                variable: v,
                reads: inputs,
                tree: unstandardize(&tree, &folded),
                rounds,
            }
        })
        .collect())
}

/// The tree over raw inputs that computes what `tree` computes over
/// inputs standardized by `(mean, spread)` each: w' = w/s, b' = b − Σ w'm.
fn unstandardize(tree: &Tree, scale: &[(f64, f64)]) -> Tree {
    let mut raw = tree.clone();
    for p in 0..tree.pieces() {
        let (bias, weights) = tree.piece(p);
        let weights: Vec<f64> = weights.iter().zip(scale).map(|(w, (_, s))| w / s).collect();
        let bias = bias
            - weights
                .iter()
                .zip(scale)
                .map(|(w, (m, _))| w * m)
                .sum::<f64>();
        raw.set_piece(p, bias, &weights);
    }
    raw
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unstandardizing_keeps_every_value() {
        let tree = Tree::affine(0.5, &[2.0, -1.0]);
        let raw = unstandardize(&tree, &[(10.0, 4.0), (-3.0, 0.5)]);
        let (x0, x1) = (13.0, -2.0);
        let standard = [(x0 - 10.0) / 4.0, (x1 + 3.0) / 0.5];
        assert!((raw.value(&[x0, x1]) - tree.value(&standard)).abs() < 1e-12);
    }
}
