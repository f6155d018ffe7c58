//! Lazy evaluation with cut-offs: the alpha–beta search of game trees, on
//! a MIN/MAX tree of affine pieces. A node is evaluated with the interval
//! (α, β) outside which its value no longer matters to the root: a MIN
//! whose first child is already ≤ α, or a MAX whose first child is already
//! ≥ β, skips its second child. At the root the interval is the whole line,
//! so the value is exact — the same number [`Tree::value`] computes, since
//! both take the min and max of the same piece values.
//!
//! Each node keeps which child to try first: the one on the path to the
//! piece that answered last, so that for nearby inputs (a row after a row,
//! a planner's candidate after a candidate) the answer is found first and
//! the rest is cut off.

use super::{Node, Tree};

/// A tree with the child order of its last answer.
#[derive(Clone, Debug)]
pub struct Lazy<'t> {
    tree: &'t Tree,
    /// Per node, whether its second child is tried first.
    second_first: Vec<bool>,
    /// Per node, its parent (the root's is itself).
    parent: Vec<u32>,
    /// Per piece, its node.
    node_of_piece: Vec<u32>,
    /// Pieces evaluated since the evaluator was made.
    evaluated: u64,
}

impl<'t> Lazy<'t> {
    /// The evaluator of `tree`, first children first.
    pub fn new(tree: &'t Tree) -> Lazy<'t> {
        let nodes = tree.nodes();
        let mut parent = vec![0u32; nodes.len()];
        let mut node_of_piece = vec![0u32; tree.pieces()];
        for (i, node) in nodes.iter().enumerate() {
            match *node {
                Node::Piece(p) => node_of_piece[p as usize] = i as u32,
                Node::Min(a, b) | Node::Max(a, b) => {
                    parent[a as usize] = i as u32;
                    parent[b as usize] = i as u32;
                }
            }
        }
        Lazy {
            tree,
            second_first: vec![false; nodes.len()],
            parent,
            node_of_piece,
            evaluated: 0,
        }
    }

    /// f(x), exactly; the path to the piece that answered goes first next
    /// time.
    pub fn value(&mut self, x: &[f64]) -> f64 {
        let (value, piece) = self.eval(0, f64::NEG_INFINITY, f64::INFINITY, x);
        let mut node = self.node_of_piece[piece as usize] as usize;
        while node != 0 {
            let up = self.parent[node] as usize;
            let second = matches!(self.tree.nodes()[up], Node::Min(_, b) | Node::Max(_, b) if b as usize == node);
            self.second_first[up] = second;
            node = up;
        }
        value
    }

    /// Pieces evaluated so far (for measuring what the cut-offs save).
    pub fn evaluated(&self) -> u64 {
        self.evaluated
    }

    /// The value of `node` where it lies in (α, β); a value ≤ α that bounds
    /// it from above, or ≥ β that bounds it from below, otherwise. With the
    /// piece it came from.
    fn eval(&mut self, node: usize, alpha: f64, beta: f64, x: &[f64]) -> (f64, u32) {
        match self.tree.nodes()[node] {
            Node::Piece(p) => {
                self.evaluated += 1;
                (self.tree.piece_value(p as usize, x), p)
            }
            Node::Min(a, b) => {
                let (first, second) = self.ordered(node, a, b);
                let (v1, p1) = self.eval(first, alpha, beta, x);
                if v1 <= alpha {
                    return (v1, p1);
                }
                let (v2, p2) = self.eval(second, alpha, beta.min(v1), x);
                if v2 < v1 { (v2, p2) } else { (v1, p1) }
            }
            Node::Max(a, b) => {
                let (first, second) = self.ordered(node, a, b);
                let (v1, p1) = self.eval(first, alpha, beta, x);
                if v1 >= beta {
                    return (v1, p1);
                }
                let (v2, p2) = self.eval(second, alpha.max(v1), beta, x);
                if v2 > v1 { (v2, p2) } else { (v1, p1) }
            }
        }
    }

    fn ordered(&self, node: usize, a: u32, b: u32) -> (usize, usize) {
        if self.second_first[node] {
            (b as usize, a as usize)
        } else {
            (a as usize, b as usize)
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::pwl::tests::sample_tree;

    /// A deep random tree: MIN and MAX at random over random planes.
    pub(crate) fn random_tree(inputs: usize, splits: usize, seed: u64) -> Tree {
        let mut state = seed | 1;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let weights: Vec<f64> = (0..inputs).map(|_| next()).collect();
        let mut tree = Tree::affine(next(), &weights);
        for _ in 0..splits {
            let p = ((next() + 1.0) / 2.0 * tree.pieces() as f64) as usize % tree.pieces();
            let copy = tree.split(p, next() > 0.0);
            let weights: Vec<f64> = (0..inputs).map(|_| next()).collect();
            tree.set_piece(copy, next(), &weights);
        }
        tree
    }

    #[test]
    fn equals_every_piece_evaluated_and_cuts_some_off() {
        let t = sample_tree();
        let mut lazy = Lazy::new(&t);
        for i in 0..100 {
            let x = [i as f64 / 20.0 - 2.5, (i % 7) as f64 / 3.0 - 1.0];
            assert_eq!(lazy.value(&x), t.value(&x), "{x:?}");
        }
        for seed in 1..20 {
            let t = random_tree(3, 40, seed);
            let mut lazy = Lazy::new(&t);
            let mut full = 0;
            for i in 0..200 {
                let x = [
                    (i as f64 * 0.37).sin(),
                    (i as f64 * 0.11).cos() * 2.0,
                    i as f64 / 100.0 - 1.0,
                ];
                assert_eq!(lazy.value(&x).to_bits(), t.value(&x).to_bits());
                full += t.pieces() as u64;
            }
            assert!(
                lazy.evaluated() < full,
                "seed {seed}: no cut-off in 200 rows"
            );
        }
    }
}
