//! The threshold-predicate model (paper §6) as a predictor: one tree per
//! output variable (and voter) computing the predicate p(y, x) = [y < f(x)]
//! over the inputs and a thermometer-coded candidate level y. The prediction
//! is the level at which p turns false, found by binary search over y: one
//! row at a time ([`predict`], parsimonious) or for many rows at once
//! ([`Batched`], bit-sliced).

use alnlab_codes::Codec;
use alnlab_codes::bits::encode_columns;

use crate::forest::{Predictor, TreeId};
use crate::tree::Tree;
#[cfg(test)]
use crate::tree::TreeSpec;

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

/// A threshold model's trees compiled for many rows at once: per output
/// variable, its voters as a one-bit forest over the input bits followed by
/// the candidate's thermometer code.
pub struct Batched {
    /// Per variable: its voters, and its candidate's levels.
    variables: Vec<(Predictor, usize)>,
}

impl Batched {
    /// Compiles `voters[v]` (the trees of variable v, in voter order), whose
    /// candidates have `levels[v]` levels.
    pub fn new(voters: &[Vec<&Tree>], levels: &[usize]) -> Batched {
        let variables = voters
            .iter()
            .zip(levels)
            .map(|(trees, &levels)| {
                let ids = (0..trees.len() as u32).map(|vote| TreeId {
                    variable: 0,
                    bit: 0,
                    vote,
                });
                let predictor =
                    Predictor::new(ids.zip(trees.iter().copied()), &[1], trees.len() as u32);
                (predictor, levels)
            })
            .collect();
        Batched { variables }
    }

    /// The level each variable's search ends at, `[variable][row]`, for the
    /// rows of the input levels `x` (`[variable][row]`, coded with
    /// `codecs`): the binary search of [`transition`] run for every row at
    /// once, one bit-sliced evaluation of the voters per step — the same
    /// levels as [`predict`] row by row. Only the input bits a variable's
    /// trees read are coded.
    pub fn predict(&self, codecs: &[&Codec], x: &[&[u16]]) -> Vec<Vec<usize>> {
        let rows = x.first().map_or(0, |column| column.len());
        let x_bits: usize = codecs.iter().map(|c| c.width() as usize).sum();
        self.variables
            .iter()
            .map(|(predictor, levels)| {
                let reads = predictor.reads();
                let inputs = reads.partition_point(|&bit| (bit as usize) < x_bits);
                let mut joined = encode_columns(codecs, x, &reads[..inputs]);
                // The candidate's thermometer bits the trees read, after the inputs.
                let candidate_bits: Vec<usize> = reads[inputs..]
                    .iter()
                    .map(|&b| b as usize - x_bits)
                    .collect();
                let words = joined.words;
                joined.bits = reads.len();
                joined.data.resize(joined.bits * words, 0);
                let (mut lo, mut hi) = (vec![0usize; rows], vec![*levels; rows]);
                while lo.iter().zip(&hi).any(|(l, h)| l < h) {
                    // Each row's candidate: the middle of its interval, in
                    // thermometer code (bit j set when j < mid).
                    let candidates = &mut joined.data[inputs * words..];
                    candidates.fill(0);
                    for r in 0..rows {
                        let mid = lo[r] + (hi[r] - lo[r]) / 2;
                        for (column, &bit) in candidate_bits.iter().enumerate() {
                            candidates[column * words + r / 64] |= u64::from(bit < mid) << (r % 64);
                        }
                    }
                    let below = &predictor.predict_read(&joined)[0];
                    let below = below.column(0);
                    for r in 0..rows {
                        if lo[r] < hi[r] {
                            let mid = lo[r] + (hi[r] - lo[r]) / 2;
                            if below[r / 64] >> (r % 64) & 1 == 1 {
                                lo[r] = mid + 1;
                            } else {
                                hi[r] = mid;
                            }
                        }
                    }
                }
                lo
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_codes::Code;
    use alnlab_codes::bits::encode;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_batched_search_finds_what_the_one_row_search_finds_on_every_row() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        // 20 input bits; two variables of 9 and 30 candidate levels, three
        // random voters each (random trees: far from monotone, the hard case).
        let levels = [9, 30];
        let voters: Vec<Vec<Tree>> = levels
            .iter()
            .map(|&l| {
                let spec = TreeSpec {
                    leaves: 256,
                    inputs: 20 + l - 1,
                    counter_bound: 3,
                    initial_spread: 1,
                };
                (0..3).map(|_| Tree::new(&spec, &mut rng)).collect()
            })
            .collect();
        let refs: Vec<Vec<&Tree>> = voters.iter().map(|v| v.iter().collect()).collect();
        // Random rows: two 10-bit binary numbers.
        let binary = Codec::new(Code::Binary, 1024, None).unwrap();
        let columns: Vec<Vec<u16>> = (0..2)
            .map(|_| (0..300).map(|_| rng.random_range(0..1024)).collect())
            .collect();
        let x = encode(&[&binary, &binary], &[&columns[0], &columns[1]]);
        let batched =
            Batched::new(&refs, &levels).predict(&[&binary, &binary], &[&columns[0], &columns[1]]);
        let mut scratch = Vec::new();
        for (v, &l) in levels.iter().enumerate() {
            let thermometer = Codec::new(Code::Thermometer, l, None).unwrap();
            for (r, &found) in batched[v].iter().enumerate() {
                let one = predict(&refs[v], 20, &thermometer, x.row(r), &mut scratch);
                assert_eq!(found, one, "variable {v}, row {r}");
            }
        }
    }

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
}
