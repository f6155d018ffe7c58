//! Piecewise-linear ALNs: §6 as its authors realized it. A tree whose
//! leaves are affine pieces of the inputs and whose inner nodes are MIN and
//! MAX computes a continuous piecewise-linear function f(x) directly —
//! max(a, b) > c ⇔ (a > c) OR (b > c), and min ⇔ AND, so it is the §6
//! predicate tree with its binary search taken away.
//!
//! Three ways to evaluate one tree, all giving the same number to the bit:
//! - [`Tree::value`] and [`Tree::responsible`]: every piece, and which one
//!   answers (the one whose value reaches the root; ties go to the first
//!   child) — what training credits;
//! - [`lazy::Lazy`]: MIN/MAX with cut-offs (§3.2's parsimony for this
//!   form): under a MIN already bounded by m, a MAX whose first child
//!   reaches m is not looked at further; children in the order of the last
//!   answer;
//! - [`dtree::DecisionTree`]: compiled over boxes of input space (the
//!   authors' DTREE): a few comparisons lead to a box on which every piece
//!   that bounds show cannot answer is dropped, then a small MIN/MAX.
//!
//! Every piece's value is computed by [`Tree::piece_value`] alone, in one
//! order of operations, so the three paths agree exactly: the other two
//! only skip pieces whose values cannot be the answer.

pub mod dtree;
pub mod fixed;
pub mod lazy;
pub mod predict;

use serde::{Deserialize, Serialize};

/// A node: an affine piece (its index), or the MIN or MAX of two nodes
/// (their indices, both greater than the node's own: children come after
/// their parent).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Node {
    Piece(u32),
    Min(u32, u32),
    Max(u32, u32),
}

/// One piecewise-linear tree over `inputs` real inputs; the root is node 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tree {
    inputs: usize,
    nodes: Vec<Node>,
    /// Per piece, its bias then its `inputs` weights: value = bias + w·x.
    coefficients: Vec<f64>,
}

/// The most pieces a tree may have: evaluation recurses as deep as the
/// tree, so a model file cannot ask for more than a thread's stack holds.
pub const MAX_PIECES: usize = 4096;

/// Why a tree's parts do not make a tree.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Malformed(pub String);

impl Tree {
    /// The tree of one piece, `bias + weights·x`.
    pub fn affine(bias: f64, weights: &[f64]) -> Tree {
        let mut coefficients = vec![bias];
        coefficients.extend_from_slice(weights);
        Tree {
            inputs: weights.len(),
            nodes: vec![Node::Piece(0)],
            coefficients,
        }
    }

    /// A tree from its parts, checked: every node reached once from the
    /// root, children after their parents, every piece used once, finite
    /// coefficients.
    pub fn from_parts(
        inputs: usize,
        nodes: Vec<Node>,
        coefficients: Vec<f64>,
    ) -> Result<Tree, Malformed> {
        let bad = |m: String| Err(Malformed(m));
        if nodes.is_empty() {
            return bad("no nodes".into());
        }
        let pieces = coefficients.len() / (inputs + 1);
        if coefficients.len() != pieces * (inputs + 1) {
            return bad(format!(
                "{} coefficients are not whole pieces of {} (bias and {inputs} weights)",
                coefficients.len(),
                inputs + 1
            ));
        }
        if pieces > MAX_PIECES {
            return bad(format!(
                "{pieces} pieces, more than the {MAX_PIECES} a tree may have"
            ));
        }
        if let Some(c) = coefficients.iter().find(|c| !c.is_finite()) {
            return bad(format!("a coefficient is {c}"));
        }
        let mut reached = vec![false; nodes.len()];
        reached[0] = true;
        let mut piece_used = vec![false; pieces];
        for (i, node) in nodes.iter().enumerate() {
            if !reached[i] {
                return bad(format!("node {i} is not reached from the root"));
            }
            match *node {
                Node::Piece(p) => match piece_used.get_mut(p as usize) {
                    Some(used) if !*used => *used = true,
                    Some(_) => return bad(format!("piece {p} is used twice")),
                    None => return bad(format!("node {i} names piece {p} of {pieces}")),
                },
                Node::Min(a, b) | Node::Max(a, b) => {
                    for child in [a, b] {
                        let c = child as usize;
                        if c <= i || c >= nodes.len() {
                            return bad(format!("node {i} has child {c} (of {})", nodes.len()));
                        }
                        if std::mem::replace(&mut reached[c], true) {
                            return bad(format!("node {c} has two parents"));
                        }
                    }
                }
            }
        }
        if let Some(p) = piece_used.iter().position(|u| !u) {
            return bad(format!("piece {p} is in no node"));
        }
        Ok(Tree {
            inputs,
            nodes,
            coefficients,
        })
    }

    /// Inputs per sample.
    pub fn inputs(&self) -> usize {
        self.inputs
    }

    /// The nodes; the root is the first.
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// How many pieces.
    pub fn pieces(&self) -> usize {
        self.coefficients.len() / (self.inputs + 1)
    }

    /// Piece `p`'s bias and weights.
    pub fn piece(&self, p: usize) -> (f64, &[f64]) {
        let row = &self.coefficients[p * (self.inputs + 1)..(p + 1) * (self.inputs + 1)];
        (row[0], &row[1..])
    }

    /// Sets piece `p`'s bias and weights.
    pub fn set_piece(&mut self, p: usize, bias: f64, weights: &[f64]) {
        let row = &mut self.coefficients[p * (self.inputs + 1)..(p + 1) * (self.inputs + 1)];
        row[0] = bias;
        row[1..].copy_from_slice(weights);
    }

    /// Piece `p` at `x`: bias + Σ wᵢxᵢ, summed in input order. The one
    /// place a piece's value is computed, so that every path agrees.
    #[inline]
    pub fn piece_value(&self, p: usize, x: &[f64]) -> f64 {
        let (bias, weights) = self.piece(p);
        let mut sum = bias;
        for (w, xi) in weights.iter().zip(x) {
            sum += w * xi;
        }
        sum
    }

    /// f(x), every piece evaluated.
    pub fn value(&self, x: &[f64]) -> f64 {
        self.responsible(x).0
    }

    /// f(x) and the piece whose value it is (ties: the first child's).
    pub fn responsible(&self, x: &[f64]) -> (f64, usize) {
        self.answer(0, x)
    }

    fn answer(&self, node: usize, x: &[f64]) -> (f64, usize) {
        match self.nodes[node] {
            Node::Piece(p) => (self.piece_value(p as usize, x), p as usize),
            Node::Min(a, b) => {
                let (va, pa) = self.answer(a as usize, x);
                let (vb, pb) = self.answer(b as usize, x);
                if vb < va { (vb, pb) } else { (va, pa) }
            }
            Node::Max(a, b) => {
                let (va, pa) = self.answer(a as usize, x);
                let (vb, pb) = self.answer(b as usize, x);
                if vb > va { (vb, pb) } else { (va, pa) }
            }
        }
    }

    /// Replaces piece `p`'s node by a MIN (`max: false`) or MAX of two
    /// copies of the piece: the function is unchanged until training pulls
    /// them apart. Returns the new piece's index (the copy in the second
    /// child). Nodes are renumbered so that children stay after parents.
    pub fn split(&mut self, p: usize, max: bool) -> usize {
        let at = self
            .nodes
            .iter()
            .position(|n| *n == Node::Piece(p as u32))
            .expect("every piece is in a node");
        let copy = self.pieces();
        let row: Vec<f64> = {
            let (bias, weights) = self.piece(p);
            std::iter::once(bias)
                .chain(weights.iter().copied())
                .collect()
        };
        self.coefficients.extend_from_slice(&row);
        // The two new leaves go at the end; the old leaf becomes their parent.
        let n = self.nodes.len() as u32;
        self.nodes[at] = if max {
            Node::Max(n, n + 1)
        } else {
            Node::Min(n, n + 1)
        };
        self.nodes.push(Node::Piece(p as u32));
        self.nodes.push(Node::Piece(copy as u32));
        copy
    }

    /// How many MIN and MAX nodes.
    pub fn operators(&self) -> (usize, usize) {
        self.nodes.iter().fold((0, 0), |(mins, maxes), n| match n {
            Node::Min(..) => (mins + 1, maxes),
            Node::Max(..) => (mins, maxes + 1),
            Node::Piece(_) => (mins, maxes),
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// min(max(x, −x), 1 − y/2 + x/4): a MIN of a MAX and a plane.
    pub fn sample_tree() -> Tree {
        Tree::from_parts(
            2,
            vec![
                Node::Min(1, 2),
                Node::Max(3, 4),
                Node::Piece(2),
                Node::Piece(0),
                Node::Piece(1),
            ],
            vec![0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.25, -0.5],
        )
        .unwrap()
    }

    #[test]
    fn values_and_the_responsible_piece() {
        let t = sample_tree();
        assert_eq!(t.responsible(&[0.5, 0.0]), (0.5, 0));
        assert_eq!(t.responsible(&[-0.5, 0.0]), (0.5, 1));
        // |2| = 2 > 1 + 0.5 − 0 = 1.5: the plane answers.
        assert_eq!(t.responsible(&[2.0, 0.0]), (1.5, 2));
        // A tie between x and −x at 0 goes to the first child.
        assert_eq!(t.responsible(&[0.0, 0.0]), (0.0, 0));
    }

    #[test]
    fn a_split_leaves_the_function_unchanged() {
        let mut t = sample_tree();
        let before: Vec<f64> = (0..50)
            .map(|i| t.value(&[i as f64 / 10.0 - 2.5, 0.3]))
            .collect();
        let copy = t.split(2, true);
        assert_eq!(copy, 3);
        assert_eq!(t.pieces(), 4);
        let t = Tree::from_parts(2, t.nodes.clone(), t.coefficients.clone()).unwrap();
        let after: Vec<f64> = (0..50)
            .map(|i| t.value(&[i as f64 / 10.0 - 2.5, 0.3]))
            .collect();
        assert_eq!(before, after);
        assert_eq!(t.operators(), (1, 2));
    }

    #[test]
    fn malformed_parts_are_refused() {
        let piece = vec![0.0, 1.0];
        let cases: Vec<(Vec<Node>, Vec<f64>)> = vec![
            (vec![], piece.clone()),
            (vec![Node::Piece(1)], piece.clone()),
            (vec![Node::Min(0, 1), Node::Piece(0)], piece.clone()),
            (vec![Node::Min(1, 1), Node::Piece(0)], piece.clone()),
            (vec![Node::Piece(0), Node::Piece(0)], piece.clone()),
            (vec![Node::Piece(0)], vec![0.0, 1.0, 2.0]),
            (vec![Node::Piece(0)], vec![f64::NAN, 1.0]),
            (
                vec![Node::Max(1, 2), Node::Piece(0), Node::Piece(0)],
                vec![0.0, 1.0, 0.0, 2.0],
            ),
        ];
        for (nodes, coefficients) in cases {
            assert!(
                Tree::from_parts(1, nodes.clone(), coefficients.clone()).is_err(),
                "{nodes:?} {coefficients:?}"
            );
        }
    }
}
