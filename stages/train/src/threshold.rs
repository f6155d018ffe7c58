//! Training the threshold-predicate model (paper §6): one tree per output
//! variable (and voter) learning p(y, x) = [y < f(x)] from each training
//! row presented with several candidate levels y. Prediction is
//! `alnlab_aln::threshold`.

use std::time::Instant;

use alnlab_aln::forest::TreeId;
use alnlab_aln::shard::Shard;
use alnlab_aln::tree::{Tree, TreeSpec};
use alnlab_codes::bits::{BitMatrix, Columns, encode};
use alnlab_codes::codes::{Code, Codec};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::forest::Trained;
use crate::learn::{EpochLog, Samples, train_epochs};

/// Trains a threshold tree for one output variable of `levels` levels on
/// the rows of `x` with true levels `y`: the tree reads the row's bits
/// followed by a candidate level in thermometer code, and each row is
/// presented with candidate levels around its true level (±`near`) and
/// `far` random ones, labelled [candidate < y]. Of the row's bits, the tree
/// reads those in `reads` (and every candidate bit).
#[allow(clippy::too_many_arguments)]
pub fn train_tree(
    spec: &TreeSpec,
    epochs: usize,
    seed: u64,
    x: &BitMatrix,
    reads: &[u32],
    y: &[u16],
    levels: usize,
    near: usize,
    far: usize,
) -> (Tree, Vec<EpochLog>) {
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
    let inputs = joined_columns(x, &rows, &thermometer, &candidates);
    let mut targets = vec![0u64; inputs.words];
    for (s, &label) in labels.iter().enumerate() {
        targets[s / 64] |= u64::from(label) << (s % 64);
    }
    let spec = TreeSpec {
        inputs: inputs.bits,
        ..*spec
    };
    let candidate_bits = x.bits() as u32..inputs.bits as u32;
    let bits: Vec<u32> = reads.iter().copied().chain(candidate_bits).collect();
    let mut tree = Tree::reading(&spec, &bits, &mut rng);
    let samples = Samples {
        count: inputs.count,
        words: inputs.words,
        columns: &inputs.data,
        targets: &targets,
    };
    let log = train_epochs(&mut tree, &samples, epochs, &mut rng);
    (tree, log)
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
/// number of levels; its trees read the bits `reads[v]` of `x`. Tree (v, voter) is [`TreeId`] { variable: v, bit: 0,
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
    reads: &[Vec<u32>],
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
            let (tree, epochs_log) = train_tree(
                spec,
                epochs,
                id.seed(seed),
                x,
                &reads[id.variable as usize],
                y,
                levels,
                candidates.near,
                candidates.far,
            );
            let per_epoch = clock.elapsed().as_secs_f64() / epochs_log.len().max(1) as f64;
            on_tree_done();
            Trained {
                id,
                tree,
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
    use alnlab_aln::threshold::predict;

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
        let reads: Vec<u32> = (0..x_bits.bits() as u32).collect();
        let (tree, log) = train_tree(&spec, 20, 5, &x_bits, &reads, &y[..400], levels, 2, 2);
        let mut input = Vec::new();
        let errors: Vec<usize> = (400..600)
            .map(|r| {
                predict(
                    &[&tree],
                    x_bits.bits(),
                    &thermometer,
                    x_bits.row(r),
                    &mut input,
                )
                .abs_diff(usize::from(y[r]))
            })
            .collect();
        let mean = errors.iter().sum::<usize>() as f64 / errors.len() as f64;
        eprintln!("threshold tree, y = x + 1 (L = 16): mean test error {mean:.3} levels");
        assert!(mean <= 1.0, "mean error {mean} levels; training {log:?}");
    }
}
