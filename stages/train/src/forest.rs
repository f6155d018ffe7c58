//! Forests of ALN trees: one tree per output bit of every learned variable,
//! `vote` independently seeded trees per bit whose majority is the bit
//! (paper §4.3, §4.7). Trees train in parallel (rayon); each tree's seed
//! derives from the experiment seed and the tree's identity alone, so the
//! result does not depend on the number of threads.

use std::time::Instant;

use alnlab_quantize::bits::BitMatrix;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::compiled::{BLOCK, Block, Chains, Programs};
use crate::shard::Shard;
use crate::tree::{EpochLog, Pruned, Samples, Tree, TreeSpec};

/// Bit-sliced columns: bit `b` of sample `s` is bit `s % 64` of
/// `data[b * words + s / 64]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Columns {
    /// Number of samples.
    pub count: usize,
    /// Number of bits (columns).
    pub bits: usize,
    /// Words per column.
    pub words: usize,
    /// `bits × words` words.
    pub data: Vec<u64>,
}

impl Columns {
    /// The columns of the rows `rows` of a bit matrix.
    pub fn from_rows(matrix: &BitMatrix, rows: &[usize]) -> Columns {
        let (count, bits) = (rows.len(), matrix.bits());
        let words = count.div_ceil(64).max(1);
        let mut data = vec![0u64; bits * words];
        for (s, &r) in rows.iter().enumerate() {
            let row = matrix.row(r);
            for b in 0..bits {
                data[b * words + s / 64] |= (row[b / 64] >> (b % 64) & 1) << (s % 64);
            }
        }
        Columns {
            count,
            bits,
            words,
            data,
        }
    }

    /// Column `b`.
    pub fn column(&self, b: usize) -> &[u64] {
        &self.data[b * self.words..(b + 1) * self.words]
    }

    /// The rows of the 64 samples of word `w`, for at most 64 bits:
    /// `rows[i]` gets the bits of sample 64·w + i.
    pub fn transpose_word(&self, w: usize, rows: &mut [u64; 64]) {
        assert!(self.bits <= 64, "rows of at most 64 bits");
        rows.fill(0);
        for (b, row) in rows.iter_mut().enumerate().take(self.bits) {
            *row = self.data[b * self.words + w];
        }
        transpose(rows);
    }

    /// Hands each sample's bits to `f`, in sample order, as ⌈bits/64⌉ words:
    /// a 64×64 transpose per word of samples when the rows fit one word.
    pub fn for_each_row(&self, mut f: impl FnMut(usize, &[u64])) {
        let samples = |w: usize| (self.count - 64 * w).min(64);
        if self.bits <= 64 {
            let mut rows = [0u64; 64];
            for w in 0..self.words {
                self.transpose_word(w, &mut rows);
                for (i, row) in rows[..samples(w)].iter().enumerate() {
                    f(64 * w + i, std::slice::from_ref(row));
                }
            }
            return;
        }
        let mut row = vec![0u64; self.bits.div_ceil(64)];
        for w in 0..self.words {
            for i in 0..samples(w) {
                row.fill(0);
                for b in 0..self.bits {
                    row[b / 64] |= (self.data[b * self.words + w] >> i & 1) << (b % 64);
                }
                f(64 * w + i, &row);
            }
        }
    }
}

/// Transposes a 64×64 bit matrix in place (bit c of `m[r]` ↔ bit r of
/// `m[c]`) by swapping off-diagonal blocks of 32, 16, … 1: 6·32 masked swaps
/// rather than a loop per bit.
fn transpose(m: &mut [u64; 64]) {
    let mut j = 32;
    let mut mask: u64 = 0x0000_0000_FFFF_FFFF;
    while j != 0 {
        for k in (0..64).filter(|k| k & j == 0) {
            let t = ((m[k] >> j) ^ m[k + j]) & mask;
            m[k + j] ^= t;
            m[k] ^= t << j;
        }
        j >>= 1;
        mask ^= mask << j;
    }
}

/// Which tree: the output variable (index among the learned ones), the bit of
/// its code, and the voter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct TreeId {
    pub variable: u32,
    pub bit: u32,
    pub vote: u32,
}

impl TreeId {
    /// The tree's seed: the experiment seed mixed with its identity.
    pub fn seed(&self, seed: u64) -> u64 {
        let key = u64::from(self.variable) << 40 | u64::from(self.bit) << 20 | u64::from(self.vote);
        alnlab_common::hash::mix_seed(seed, key)
    }
}

/// A trained tree with its training log.
#[derive(Clone, Debug)]
pub struct Trained {
    pub id: TreeId,
    pub tree: Tree,
    pub epochs: Vec<EpochLog>,
    /// Wall time of each epoch (s) — a measurement, not part of the model.
    pub seconds: Vec<f64>,
}

/// Trains one tree per (variable, bit, voter) — those of `shard` —:
/// `targets[v]` holds variable v's target bits as columns over the same
/// samples as `inputs`.
#[allow(clippy::too_many_arguments)]
pub fn train(
    spec: &TreeSpec,
    epochs: usize,
    vote: u32,
    seed: u64,
    shard: Shard,
    inputs: &Columns,
    targets: &[Columns],
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
            let mut tree = Tree::new(spec, &mut rng);
            let samples = Samples {
                count: inputs.count,
                words: inputs.words,
                columns: &inputs.data,
                targets: targets[id.variable as usize].column(id.bit as usize),
            };
            let clock = Instant::now();
            let epochs_log = tree.train_epochs(&samples, epochs, &mut rng);
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

/// A forest's trees, pruned and compiled for prediction: batches bit-sliced
/// ([`Programs`]), single samples parsimoniously ([`Chains`]).
pub struct Predictor {
    /// Output bits per variable, in tree order.
    widths: Vec<usize>,
    /// Voters per bit.
    vote: usize,
    programs: Programs,
    chains: Chains,
}

impl Predictor {
    /// Compiles `trees`, which must be in training order — by variable, bit,
    /// voter — for outputs of `widths` bits with `vote` voters per bit.
    pub fn new<'a>(
        trees: impl IntoIterator<Item = (TreeId, &'a Tree)>,
        widths: &[usize],
        vote: u32,
    ) -> Predictor {
        let mut expected = widths.iter().enumerate().flat_map(|(v, &bits)| {
            (0..bits as u32).flat_map(move |bit| {
                (0..vote).map(move |voter| TreeId {
                    variable: v as u32,
                    bit,
                    vote: voter,
                })
            })
        });
        let pruned: Vec<Pruned> = trees
            .into_iter()
            .map(|(id, tree)| {
                assert_eq!(Some(id), expected.next(), "trees in training order");
                tree.prune()
            })
            .collect();
        assert_eq!(expected.next(), None, "a tree for every bit and voter");
        Predictor {
            widths: widths.to_vec(),
            vote: vote as usize,
            programs: Programs::new(&pruned),
            chains: Chains::new(&pruned),
        }
    }

    /// The predicted bits of every output variable over all samples of
    /// `inputs`: `out[v]` holds variable v's bits as columns. Blocks of
    /// samples run in parallel; the result does not depend on the threads.
    pub fn predict(&self, inputs: &Columns) -> Vec<Columns> {
        let blocks = inputs.words.div_ceil(BLOCK);
        let per_block: Vec<Vec<Block>> = (0..blocks)
            .into_par_iter()
            .map(|k| {
                let mut block_inputs = vec![[0u64; BLOCK]; inputs.bits];
                let words = (k * BLOCK..inputs.words.min((k + 1) * BLOCK)).enumerate();
                for (b, block) in block_inputs.iter_mut().enumerate() {
                    for (j, w) in words.clone() {
                        block[j] = inputs.data[b * inputs.words + w];
                    }
                }
                let mut trees = vec![[0u64; BLOCK]; self.programs.trees()];
                self.programs.evaluate_block(&block_inputs, &mut trees);
                trees
                    .chunks(self.vote)
                    .map(|voters| std::array::from_fn(|j| majority_of(voters, j)))
                    .collect()
            })
            .collect();
        let padding = (inputs.words * 64 - inputs.count) as u32;
        let last_word = u64::MAX.checked_shr(padding).unwrap_or(0);
        let mut bit_index = 0;
        self.widths
            .iter()
            .map(|&bits| {
                let mut data = vec![0u64; bits * inputs.words];
                for b in 0..bits {
                    let column = &mut data[b * inputs.words..(b + 1) * inputs.words];
                    for (w, word) in column.iter_mut().enumerate() {
                        *word = per_block[w / BLOCK][bit_index][w % BLOCK];
                    }
                    if let Some(last) = column.last_mut() {
                        *last &= last_word;
                    }
                    bit_index += 1;
                }
                Columns {
                    count: inputs.count,
                    bits,
                    words: inputs.words,
                    data,
                }
            })
            .collect()
    }

    /// The predicted code words of every output variable for one sample
    /// (`input`: its bits, 64 per word), evaluated parsimoniously: `out[v]`
    /// gets variable v's code, ⌈width/64⌉ words. `votes` is scratch space.
    /// Returns the number of leaves tested.
    pub fn predict_one(&self, input: &[u64], votes: &mut Vec<bool>, out: &mut [Vec<u64>]) -> usize {
        votes.resize(self.chains.trees(), false);
        let tested = self.chains.evaluate(input, votes);
        let mut voters = votes.chunks(self.vote);
        for (code, &bits) in out.iter_mut().zip(&self.widths) {
            code.clear();
            code.resize(bits.div_ceil(64), 0);
            for b in 0..bits {
                let ones = voters
                    .next()
                    .expect("a bit per tree")
                    .iter()
                    .filter(|&&v| v)
                    .count();
                code[b / 64] |= u64::from(2 * ones > self.vote) << (b % 64);
            }
        }
        tested
    }
}

/// Bitwise majority of word `j` of an odd number of blocks.
fn majority_of(voters: &[Block], j: usize) -> u64 {
    match voters {
        [a] => a[j],
        [a, b, c] => a[j] & b[j] | a[j] & c[j] | b[j] & c[j],
        _ => majority(&voters.iter().map(|v| v[j]).collect::<Vec<_>>()),
    }
}

/// Bitwise majority of an odd number of words.
pub fn majority(words: &[u64]) -> u64 {
    match words {
        [a] => *a,
        [a, b, c] => a & b | a & c | b & c,
        _ => (0..64).fold(0, |acc, bit| {
            let ones = words.iter().filter(|w| *w >> bit & 1 == 1).count();
            acc | u64::from(2 * ones > words.len()) << bit
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_quantize::bits::encode;
    use alnlab_quantize::codes::{Code, Codec};
    use alnlab_quantize::walk::WalkSpec;
    use rand::RngExt;

    fn spec(leaves: usize, inputs: usize) -> TreeSpec {
        TreeSpec {
            leaves,
            inputs,
            counter_bound: 3,
            initial_spread: 1,
        }
    }

    /// y = x + 1 on one variable (walk code, L = 64): train on some levels'
    /// samples, test on unseen ones; returns the mean test error in levels.
    fn successor_error(vote: u32, noise: f64, seed: u64) -> f64 {
        let codec = Codec::new(
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
        .unwrap();
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
                train(&spec(64, 30), 3, 3, 9, shard, &inputs, &targets, &|| {})
            })
            .map(|t| (t.id, t.tree, t.epochs))
            .collect();
        assert_ne!(parts, whole, "dealt round-robin, not in order");
        parts.sort_by_key(|(id, _, _)| *id);
        assert_eq!(parts, whole);
    }

    #[test]
    fn transposing_a_word_gives_each_sample_its_bits() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for bits in [1, 23, 64] {
            let columns = Columns {
                count: 130,
                bits,
                words: 3,
                data: (0..3 * bits).map(|_| rng.random()).collect(),
            };
            let mut rows = [0u64; 64];
            for w in 0..3 {
                columns.transpose_word(w, &mut rows);
                for (i, row) in rows.iter().enumerate() {
                    for b in 0..64 {
                        let expected = b < bits && columns.column(b)[w] >> i & 1 == 1;
                        assert_eq!(
                            row >> b & 1 == 1,
                            expected,
                            "bits {bits}, word {w}, sample {i}, bit {b}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn every_row_comes_out_whole_however_wide() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        for bits in [5, 64, 130] {
            let columns = Columns {
                count: 100,
                bits,
                words: 2,
                data: (0..2 * bits).map(|_| rng.random()).collect(),
            };
            let mut seen = 0;
            columns.for_each_row(|s, row| {
                assert_eq!(s, seen);
                for b in 0..bits {
                    let expected = columns.column(b)[s / 64] >> (s % 64) & 1;
                    assert_eq!(
                        row[b / 64] >> (b % 64) & 1,
                        expected,
                        "bits {bits}, sample {s}"
                    );
                }
                seen += 1;
            });
            assert_eq!(seen, 100);
        }
    }

    #[test]
    fn majority_of_words() {
        assert_eq!(majority(&[0b1100, 0b1010, 0b1001]), 0b1000);
        assert_eq!(majority(&[0b11000, 0b10100, 0b10010, 0b10001, 0]), 0b10000);
    }
}
