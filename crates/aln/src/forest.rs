//! A trained forest as a predictor (paper §4.3, §4.7): one tree per output
//! bit of every learned variable, `vote` trees per bit whose majority is the
//! bit; pruned, compiled, and evaluated bit-sliced over many samples or
//! parsimoniously one sample at a time.

use alnlab_codes::bits::Columns;
use rayon::prelude::*;

use crate::compiled::{BLOCK, Block, Chains, Programs};
use crate::tree::{Gate, Pruned, Tree};

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
    /// The input bits some tree reads, ascending: the bit-sliced programs
    /// read them by their position here.
    reads: Vec<u32>,
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
        let mut reads: Vec<u32> = pruned
            .iter()
            .flat_map(|tree| tree.nodes.iter())
            .filter_map(|gate| match *gate {
                Gate::Leaf(literal) => Some(literal / 2),
                _ => None,
            })
            .collect();
        reads.sort_unstable();
        reads.dedup();
        // Batches carry only the bits some tree reads; their programs address
        // them by position.
        let position = |literal: u32| {
            let at = reads.binary_search(&(literal / 2)).expect("a read bit");
            (2 * at as u32) | (literal & 1)
        };
        let compact: Vec<Pruned> = pruned
            .iter()
            .map(|tree| Pruned {
                nodes: tree
                    .nodes
                    .iter()
                    .map(|&gate| match gate {
                        Gate::Leaf(literal) => Gate::Leaf(position(literal)),
                        other => other,
                    })
                    .collect(),
            })
            .collect();
        Predictor {
            widths: widths.to_vec(),
            vote: vote as usize,
            programs: Programs::new(&compact),
            chains: Chains::new(&pruned),
            reads,
        }
    }

    /// The input bits some tree reads, ascending: what [`Predictor::predict_read`]
    /// takes.
    pub fn reads(&self) -> &[u32] {
        &self.reads
    }

    /// The predicted bits of every output variable over all samples of
    /// `inputs` (every input bit): `out[v]` holds variable v's bits as
    /// columns. Blocks of samples run in parallel; the result does not
    /// depend on the threads.
    pub fn predict(&self, inputs: &Columns) -> Vec<Columns> {
        self.predict_columns(inputs, |i| inputs.column(self.reads[i] as usize))
    }

    /// The same for inputs holding only the bits of [`Predictor::reads`], in
    /// that order — what a caller that builds the columns itself need make.
    pub fn predict_read(&self, read: &Columns) -> Vec<Columns> {
        assert_eq!(read.bits, self.reads.len(), "a column per read bit");
        self.predict_columns(read, |i| read.column(i))
    }

    fn predict_columns<'a>(
        &self,
        inputs: &Columns,
        column: impl Fn(usize) -> &'a [u64] + Sync,
    ) -> Vec<Columns> {
        let blocks = inputs.words.div_ceil(BLOCK);
        let per_block: Vec<Vec<Block>> = (0..blocks)
            .into_par_iter()
            .map(|k| {
                let mut block_inputs = vec![[0u64; BLOCK]; self.reads.len()];
                let words = k * BLOCK..inputs.words.min((k + 1) * BLOCK);
                for (i, block) in block_inputs.iter_mut().enumerate() {
                    block[..words.len()].copy_from_slice(&column(i)[words.clone()]);
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
        _ => majority_over(voters.iter().map(|v| v[j]), voters.len()),
    }
}

/// Bitwise majority of an odd number of words.
pub fn majority(words: &[u64]) -> u64 {
    match words {
        [a] => *a,
        [a, b, c] => a & b | a & c | b & c,
        _ => majority_over(words.iter().copied(), words.len()),
    }
}

/// Bitwise majority of `n` (< 256) words: each bit's count of ones kept
/// bit-sliced in eight counter words, then compared with n/2 + 1.
fn majority_over(words: impl Iterator<Item = u64>, n: usize) -> u64 {
    assert!(n < 256, "fewer than 256 voters");
    let mut count = [0u64; 8];
    for word in words {
        let mut carry = word;
        for c in count.iter_mut() {
            let next = *c & carry;
            *c ^= carry;
            carry = next;
        }
    }
    let need = n / 2 + 1;
    // count ≥ need, compared from the most significant counter bit down.
    let (mut greater, mut equal) = (0u64, !0u64);
    for (i, &c) in count.iter().enumerate().rev() {
        let t = 0u64.wrapping_sub((need >> i & 1) as u64);
        greater |= equal & c & !t;
        equal &= !(c ^ t);
    }
    greater | equal
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn majority_of_words() {
        assert_eq!(majority(&[0b1100, 0b1010, 0b1001]), 0b1000);
        assert_eq!(majority(&[0b11000, 0b10100, 0b10010, 0b10001, 0]), 0b10000);
        // Every pattern of 5 voters and 64 of 7, one pattern per bit.
        for n in [5usize, 7] {
            let patterns = (1u64 << n).min(64);
            let words: Vec<u64> = (0..n)
                .map(|voter| (0..patterns).fold(0, |w, p| w | (p >> voter & 1) << p))
                .collect();
            for p in 0..patterns {
                let ones = p.count_ones() as usize;
                assert_eq!(
                    majority(&words) >> p & 1 == 1,
                    2 * ones > n,
                    "{n} voters, {p:b}"
                );
            }
        }
    }
}
