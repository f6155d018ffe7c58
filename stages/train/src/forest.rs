//! Training forests of ALN trees: one tree per output bit of every learned
//! variable, `vote` independently seeded trees per bit (paper §4.3, §4.7).
//! Trees train in parallel (rayon); each tree's seed derives from the
//! experiment seed and the tree's identity alone, so the result does not
//! depend on the number of threads.

use std::time::Instant;

use alnlab_aln::forest::TreeId;
use alnlab_aln::shard::Shard;
use alnlab_aln::tree::{Tree, TreeSpec};
use alnlab_codes::bits::Columns;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::learn::{EpochLog, Samples, train_epochs};

/// A trained tree with its training log.
#[derive(Clone, Debug)]
pub struct Trained {
    pub id: TreeId,
    pub tree: Tree,
    pub epochs: Vec<EpochLog>,
    /// Wall time of each epoch (s) — a measurement, not part of the model.
    pub seconds: Vec<f64>,
}

/// `variables` lists of every one of `inputs` input bits: what each
/// variable's trees read when they read everything.
pub fn every_bit(inputs: usize, variables: usize) -> Vec<Vec<u32>> {
    vec![(0..inputs as u32).collect(); variables]
}

/// Trains one tree per (variable, bit, voter) — those of `shard` —:
/// `targets[v]` holds variable v's target bits as columns over the same
/// samples as `inputs`; variable v's trees read the input bits `reads[v]`.
#[allow(clippy::too_many_arguments)]
pub fn train(
    spec: &TreeSpec,
    epochs: usize,
    vote: u32,
    seed: u64,
    shard: Shard,
    inputs: &Columns,
    targets: &[Columns],
    reads: &[Vec<u32>],
    on_tree_done: &(dyn Fn() + Sync),
) -> Vec<Trained> {
    let ids: Vec<TreeId> = targets
        .iter()
        .enumerate()
        .flat_map(|(v, t)| {
            (0..t.bits as u32).flat_map(move |bit| {
                (0..vote).map(move |voter| TreeId {
                    variable: v as u32,
                    bit,
                    vote: voter,
                })
            })
        })
        .enumerate()
        .filter(|&(position, _)| shard.owns(position))
        .map(|(_, id)| id)
        .collect();
    ids.par_iter()
        .map(|&id| {
            let mut rng = ChaCha8Rng::seed_from_u64(id.seed(seed));
            let mut tree = Tree::reading(spec, &reads[id.variable as usize], &mut rng);
            let samples = Samples {
                count: inputs.count,
                words: inputs.words,
                columns: &inputs.data,
                targets: targets[id.variable as usize].column(id.bit as usize),
            };
            let clock = Instant::now();
            let epochs_log = train_epochs(&mut tree, &samples, epochs, &mut rng);
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

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_aln::Output;
    use alnlab_aln::forest::Predictor;
    use alnlab_codes::bits::encode;
    use alnlab_codes::codes::{Code, Codec};
    use alnlab_codes::residual::{DeltaSpec, Residual};
    use alnlab_codes::walk::WalkSpec;
    use rand::RngExt;

    fn spec(leaves: usize, inputs: usize) -> TreeSpec {
        TreeSpec {
            leaves,
            inputs,
            counter_bound: 3,
            initial_spread: 1,
        }
    }

    /// The 23-bit walk code of 64 levels the small forests here learn.
    fn walk64() -> Codec {
        Codec::new(
            Code::Walk,
            64,
            Some(WalkSpec {
                levels: 64,
                width: 23,
                step: 1,
                span: 7,
                seed: 3,
            }),
        )
        .unwrap()
    }

    /// y = x + 1 on one variable (walk code, L = 64): train on some levels'
    /// samples, test on unseen ones; returns the mean test error in levels.
    fn successor_error(vote: u32, noise: f64, seed: u64) -> f64 {
        let codec = walk64();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x: Vec<u16> = (0..1200).map(|_| rng.random_range(0..63)).collect();
        let y: Vec<u16> = x
            .iter()
            .map(|&v| {
                if rng.random_bool(noise) {
                    rng.random_range(0..64)
                } else {
                    v + 1
                }
            })
            .collect();
        let x_bits = encode(&[&codec], &[&x]);
        let y_bits = encode(&[&codec], &[&y]);
        let (train_rows, test_rows): (Vec<usize>, Vec<usize>) = (0..1200).partition(|&r| r < 800);
        let inputs = Columns::from_rows(&x_bits, &train_rows);
        let targets = [Columns::from_rows(&y_bits, &train_rows)];
        let trained = train(
            &spec(512, 23),
            10,
            vote,
            seed,
            Shard::ALL,
            &inputs,
            &targets,
            &every_bit(23, 1),
            &|| {},
        );
        let predictor = Predictor::new(trained.iter().map(|t| (t.id, &t.tree)), &[23], vote);
        let test_inputs = Columns::from_rows(&x_bits, &test_rows);
        let predicted = &predictor.predict(&test_inputs)[0];
        let mut total = 0.0;
        for (s, &r) in test_rows.iter().enumerate() {
            let bits: u64 = (0..23).fold(0, |acc, b| {
                acc | (predicted.column(b)[s / 64] >> (s % 64) & 1) << b
            });
            let level = codec.decode(&[bits]) as f64;
            total += (level - f64::from(x[r] + 1)).abs();
        }
        total / test_rows.len() as f64
    }

    /// The mean test error (levels) of a forest learning `output`'s target
    /// for y = x + drift (L = 64, walk-coded inputs): drift is +1, and with
    /// probability 0.2 one of 0 or +2.
    fn drift_error(output: &Output, seed: u64) -> f64 {
        let input = walk64();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x: Vec<u16> = (0..1200).map(|_| rng.random_range(0..62)).collect();
        let y: Vec<u16> = x
            .iter()
            .map(|&v| match rng.random_range(0..10) {
                0 => v,
                1 => v + 2,
                _ => v + 1,
            })
            .collect();
        let targets: Vec<u16> = x
            .iter()
            .zip(&y)
            .map(|(&a, &b)| output.target(a, b))
            .collect();
        let codec = output.codec();
        let width = codec.width() as usize;
        let (train_rows, test_rows): (Vec<usize>, Vec<usize>) = (0..1200).partition(|&r| r < 800);
        let x_bits = encode(&[&input], &[&x]);
        let inputs = Columns::from_rows(&x_bits, &train_rows);
        let target = [Columns::from_rows(
            &encode(&[codec], &[&targets]),
            &train_rows,
        )];
        let trained = train(
            &spec(512, 23),
            10,
            1,
            seed,
            Shard::ALL,
            &inputs,
            &target,
            &every_bit(23, 1),
            &|| {},
        );
        let predictor = Predictor::new(trained.iter().map(|t| (t.id, &t.tree)), &[width], 1);
        let predicted = &predictor.predict(&Columns::from_rows(&x_bits, &test_rows))[0];
        let mut total = 0usize;
        predicted.for_each_row(|s, bits| {
            let r = test_rows[s];
            total += usize::from(output.decode(bits, x[r], None).abs_diff(y[r]));
        });
        total as f64 / test_rows.len() as f64
    }

    #[test]
    fn a_residual_forest_learns_a_drift_better_than_a_level_forest() {
        let level = Output::Level(Codec::new(Code::Gray, 64, None).unwrap());
        let spec = DeltaSpec {
            k: 2,
            period: None,
            code: Code::Gray,
        };
        let delta = Output::Delta(Residual::new(spec, 64, 0).unwrap());
        for seed in [1, 2] {
            let (level, delta) = (drift_error(&level, seed), drift_error(&delta, seed));
            eprintln!("y = x + drift, seed {seed}: level {level:.3}, delta {delta:.3} levels");
            // Predicting the mode (+1) everywhere errs by 0.2 levels.
            assert!(delta <= 0.35, "delta forest: {delta}");
            assert!(delta < level, "delta {delta} against level {level}");
        }
    }

    #[test]
    fn a_forest_learns_the_successor() {
        let error = successor_error(1, 0.0, 1);
        eprintln!("y = x + 1, walk L = 64: mean test error {error:.3} levels");
        assert!(error <= 1.0, "mean test error {error} levels");
    }

    #[test]
    fn majority_vote_beats_a_single_tree_on_a_noisy_target() {
        let (one, three) = (successor_error(1, 0.2, 2), successor_error(3, 0.2, 2));
        eprintln!("20% noise: vote 1 {one:.3}, vote 3 {three:.3} levels");
        assert!(three < one, "vote 3: {three}, vote 1: {one}");
    }

    #[test]
    fn training_is_the_same_on_any_number_of_threads_or_shards() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let inputs = Columns {
            count: 200,
            bits: 30,
            words: 4,
            data: (0..120).map(|_| rng.random()).collect(),
        };
        let targets = [Columns {
            count: 200,
            bits: 5,
            words: 4,
            data: (0..20).map(|_| rng.random()).collect(),
        }];
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                train(
                    &spec(64, 30),
                    3,
                    3,
                    9,
                    Shard::ALL,
                    &inputs,
                    &targets,
                    &every_bit(30, 1),
                    &|| {},
                )
            })
            .into_iter()
            .map(|t| (t.id, t.tree, t.epochs))
            .collect::<Vec<_>>()
        };
        assert_eq!(run(1), run(2));
        // Three shards trained apart hold, together, exactly the same trees.
        let whole = run(1);
        let mut parts: Vec<_> = (1..=3)
            .flat_map(|index| {
                let shard = Shard { index, count: 3 };
                train(
                    &spec(64, 30),
                    3,
                    3,
                    9,
                    shard,
                    &inputs,
                    &targets,
                    &every_bit(30, 1),
                    &|| {},
                )
            })
            .map(|t| (t.id, t.tree, t.epochs))
            .collect();
        assert_ne!(parts, whole, "dealt round-robin, not in order");
        parts.sort_by_key(|(id, _, _)| *id);
        assert_eq!(parts, whole);
    }
}
