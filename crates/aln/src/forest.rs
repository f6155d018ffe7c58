//! A trained forest as a predictor (paper §4.3, §4.7): one tree per output
//! bit of every learned variable, `vote` trees per bit whose majority is the
//! bit; pruned, compiled, and evaluated bit-sliced over many samples or
//! parsimoniously one sample at a time.

use alnlab_codes::bits::Columns;
use rayon::prelude::*;

use crate::compiled::{BLOCK, Block, Chains, Programs};
use crate::tree::{Pruned, Tree};

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

    #[test]
    fn majority_of_words() {
        assert_eq!(majority(&[0b1100, 0b1010, 0b1001]), 0b1000);
        assert_eq!(majority(&[0b11000, 0b10100, 0b10010, 0b10001, 0]), 0b10000);
    }
}
