//! The threshold-predicate model (paper §6) as a predictor: one tree per
//! output variable (and voter) computing the predicate p(y, x) = [y < f(x)]
//! over the inputs and a thermometer-coded candidate level y. The prediction
//! is the level at which p turns false, found by binary search over y.

use alnlab_codes::Codec;

use crate::tree::Tree;

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
}
