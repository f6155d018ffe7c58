//! The threshold-predicate model (paper §6): instead of one tree per output
//! bit, one tree per output variable computing the predicate
//! p(y, x) = [y < f(x)] over thermometer-coded inputs and a thermometer-coded
//! candidate level y. The prediction is the level at which p turns false,
//! found by binary search over y.

use alnlab_quantize::bits::{BitMatrix, encode};
use alnlab_quantize::codes::{Code, Codec};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use std::time::Instant;

use rayon::prelude::*;

use crate::forest::{Columns, Trained, TreeId};
use crate::shard::Shard;
use crate::tree::{EpochLog, Samples, Tree, TreeSpec};

/// The first level in `0..levels` at which `below` (true for levels under
/// the answer, false from it on) is false; `levels` if it never is. With a
/// predicate that is not monotone, one level where it changes from true to
/// false (or an end).
pub fn transition(levels: usize, mut below: impl FnMut(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, levels);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if below(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// A threshold tree for one output variable of `levels` levels, reading
/// `x_bits` input bits followed by the candidate level in thermometer code.
pub struct ThresholdModel {
    pub tree: Tree,
    pub x_bits: usize,
    pub thermometer: Codec,
}

impl ThresholdModel {
    /// Trains on the rows of `x` (thermometer-coded inputs) with true levels
    /// `y`: each row is presented with candidate levels around its true
    /// level (±`near`) and `far` random ones, labelled [candidate < y].
    #[allow(clippy::too_many_arguments)]
    pub fn train(
        spec: &TreeSpec,
        epochs: usize,
        seed: u64,
        x: &BitMatrix,
        y: &[u16],
        levels: usize,
        near: usize,
        far: usize,
    ) -> (ThresholdModel, Vec<EpochLog>) {
        let thermometer = Codec::new(Code::Thermometer, levels, None).expect("levels ≥ 2");
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut rows, mut candidates, mut labels) = (Vec::new(), Vec::new(), Vec::new());
        for (r, &target) in y.iter().enumerate() {
            let target = usize::from(target);
            let lo = target.saturating_sub(near);
            let hi = (target + near).min(levels - 1);
            let around = lo..=hi;
            let random = (0..far).map(|_| rng.random_range(0..levels));
            for candidate in around.chain(random) {
                rows.push(r);
                candidates.push(candidate as u16);
                labels.push(candidate < target);
            }
        }
        let x_bits = x.bits();
        let inputs = joined_columns(x, &rows, &thermometer, &candidates);
        let mut targets = vec![0u64; inputs.words];
        for (s, &label) in labels.iter().enumerate() {
            targets[s / 64] |= u64::from(label) << (s % 64);
        }
        let spec = TreeSpec {
            inputs: inputs.bits,
            ..*spec
        };
        let mut tree = Tree::new(&spec, &mut rng);
        let samples = Samples {
            count: inputs.count,
            words: inputs.words,
            columns: &inputs.data,
            targets: &targets,
        };
        let log = tree.train_epochs(&samples, epochs, &mut rng);
        (
            ThresholdModel {
                tree,
                x_bits,
                thermometer,
            },
            log,
        )
    }

    /// The predicted level for one row of inputs (packed words of `x_bits`
    /// bits, zero beyond): binary search for where the predicate turns false.
    pub fn predict(&self, x_row: &[u64], input: &mut Vec<u64>) -> usize {
        predict(&[&self.tree], self.x_bits, &self.thermometer, x_row, input)
    }
}

/// The level predicted by the majority of `voters` (threshold trees over
/// `x_bits` input bits and `thermometer`'s candidate) for one row of inputs:
/// binary search for where the voted predicate turns false. Each tree is
/// evaluated parsimoniously; `input` is scratch space.
pub fn predict(
    voters: &[&Tree],
    x_bits: usize,
    thermometer: &Codec,
    x_row: &[u64],
    input: &mut Vec<u64>,
) -> usize {
    let width = thermometer.width() as usize;
    input.clear();
    input.resize((x_bits + width).div_ceil(64), 0);
    transition(thermometer.levels(), |candidate| {
        input.fill(0);
        input[..x_row.len()].copy_from_slice(x_row);
        // Level k in thermometer code: its first k bits set.
        for bit in x_bits..x_bits + candidate {
            input[bit / 64] |= 1 << (bit % 64);
        }
        let yes = voters
            .iter()
            .filter(|tree| tree.evaluate_parsimonious(input).0)
            .count();
        2 * yes > voters.len()
    })
}

/// The candidates each training row is presented with (§6): the levels
/// within `near` of its true level and `far` random ones.
#[derive(Clone, Copy, Debug)]
pub struct Candidates {
    pub near: usize,
    pub far: usize,
}

/// Trains `vote` threshold trees for each output variable, in parallel:
/// `targets[v]` holds variable v's true levels for the rows of `x` and its
/// number of levels. Tree (v, voter) is [`TreeId`] { variable: v, bit: 0,
/// vote: voter }, seeded from `seed` and that identity alone.
#[allow(clippy::too_many_arguments)]
pub fn train_forest(
    spec: &TreeSpec,
    epochs: usize,
    vote: u32,
    seed: u64,
    shard: Shard,
    candidates: Candidates,
    x: &BitMatrix,
    targets: &[(&[u16], usize)],
    on_tree_done: &(dyn Fn() + Sync),
) -> Vec<Trained> {
    let ids: Vec<TreeId> = (0..targets.len() as u32)
        .flat_map(|variable| {
            (0..vote).map(move |voter| TreeId {
                variable,
                bit: 0,
                vote: voter,
            })
        })
        .enumerate()
        .filter(|&(position, _)| shard.owns(position))
        .map(|(_, id)| id)
        .collect();
    ids.par_iter()
        .map(|&id| {
            let (y, levels) = targets[id.variable as usize];
            let clock = Instant::now();
            let (model, epochs_log) = ThresholdModel::train(
                spec,
                epochs,
                id.seed(seed),
                x,
                y,
                levels,
                candidates.near,
                candidates.far,
            );
            let per_epoch = clock.elapsed().as_secs_f64() / epochs_log.len().max(1) as f64;
            on_tree_done();
            Trained {
                id,
                tree: model.tree,
                seconds: vec![per_epoch; epochs_log.len()],
                epochs: epochs_log,
            }
        })
        .collect()
}

/// Bit-sliced columns of x rows (`rows[s]`) followed by the thermometer code
/// of `candidates[s]`.
fn joined_columns(
    x: &BitMatrix,
    rows: &[usize],
    thermometer: &Codec,
    candidates: &[u16],
) -> Columns {
    let x_columns = Columns::from_rows(x, rows);
    let candidate_matrix = encode(&[thermometer], &[candidates]);
    let all: Vec<usize> = (0..candidates.len()).collect();
    let c_columns = Columns::from_rows(&candidate_matrix, &all);
    let mut data = x_columns.data;
    data.extend_from_slice(&c_columns.data);
    Columns {
        count: rows.len(),
        bits: x_columns.bits + c_columns.bits,
        words: x_columns.words,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binary_search_finds_the_transition_exactly() {
        for levels in [2, 3, 64, 214] {
            for answer in 0..=levels {
                let mut calls = 0;
                let found = transition(levels, |y| {
                    calls += 1;
                    y < answer
                });
                assert_eq!(found, answer, "L = {levels}");
                assert!(calls <= (levels as f64).log2().ceil() as usize + 1);
            }
        }
    }

    #[test]
    fn a_threshold_tree_learns_the_successor() {
        // y = x + 1 over L = 16 levels, x thermometer-coded.
        let levels = 16;
        let thermometer = Codec::new(Code::Thermometer, levels, None).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<u16> = (0..600)
            .map(|_| rng.random_range(0..levels as u16 - 1))
            .collect();
        let y: Vec<u16> = x.iter().map(|v| v + 1).collect();
        let x_bits = encode(&[&thermometer], &[&x]);
        let spec = TreeSpec {
            leaves: 1024,
            inputs: 0,
            counter_bound: 3,
            initial_spread: 1,
        };
        // Rows 0..400 train (y has 400 entries), rows 400..600 test.
        let (model, log) = ThresholdModel::train(&spec, 20, 5, &x_bits, &y[..400], levels, 2, 2);
        let mut input = Vec::new();
        let errors: Vec<usize> = (400..600)
            .map(|r| {
                model
                    .predict(x_bits.row(r), &mut input)
                    .abs_diff(usize::from(y[r]))
            })
            .collect();
        let mean = errors.iter().sum::<usize>() as f64 / errors.len() as f64;
        eprintln!("threshold tree, y = x + 1 (L = 16): mean test error {mean:.3} levels");
        assert!(mean <= 1.0, "mean error {mean} levels; training {log:?}");
    }
}
