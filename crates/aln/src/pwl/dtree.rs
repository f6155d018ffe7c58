//! A tree compiled over boxes of input space (the authors' DTREE). The
//! inputs' range seen in training, widened, is cut on one input at a time
//! into boxes; on each box, every piece that bounds show can never be the
//! answer there is dropped (at a MIN, a child whose least value on the box
//! is at least the other child's greatest; MAX likewise), so evaluation is
//! a few comparisons, then a small MIN/MAX of the pieces left.
//!
//! Exact: the bounds are rigorous — each piece's bound on a box is widened
//! by the most its rounding and the rounding of its evaluation can differ —
//! so a piece is dropped only where its computed value can never be the
//! answer, and the value is the same number [`Tree::value`] gives. Where
//! the cuts fall is chosen from sample points (the training rows): they
//! decide speed, never the result. A point outside the root box is
//! evaluated lazily.

use super::lazy::Lazy;
use super::{Node, Tree};

/// How the boxes are cut.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// A box with at most this many pieces left is not cut further.
    pub block_pieces: usize,
    /// Cuts from the root box to a block, at most.
    pub max_depth: usize,
    /// A box holding fewer sample points is not cut further.
    pub min_points: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            block_pieces: 2,
            max_depth: 14,
            min_points: 4,
        }
    }
}

/// A cut of a box, or the block of pieces left in it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Decision {
    /// Points with `x[axis] < threshold` go to `below`, the others to `above`.
    Cut {
        axis: u32,
        threshold: f64,
        below: u32,
        above: u32,
    },
    /// Evaluate the MIN/MAX rooted at this node of `blocks`.
    Block(u32),
}

/// A tree compiled over boxes.
#[derive(Clone, Debug, PartialEq)]
pub struct DecisionTree {
    /// The root box.
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// The cuts; the first is the root.
    decisions: Vec<Decision>,
    /// Every block's nodes (children indices into this list; pieces are the
    /// tree's).
    blocks: Vec<Node>,
}

/// A node of a box's pruned tree, with its value's bounds on the box.
#[derive(Clone, Copy, Debug)]
struct Bounded {
    node: u32,
    lo: f64,
    hi: f64,
}

impl DecisionTree {
    /// Compiles `tree` over the box of `points` (rows of `tree.inputs()`
    /// numbers), widened by a tenth of each input's range.
    pub fn build(tree: &Tree, points: &[f64], settings: Settings) -> DecisionTree {
        let n = tree.inputs();
        let rows = points.len().checked_div(n).unwrap_or(0);
        let (mut lo, mut hi) = (vec![f64::INFINITY; n], vec![f64::NEG_INFINITY; n]);
        for row in points.chunks_exact(n.max(1)).take(rows) {
            for i in 0..n {
                lo[i] = lo[i].min(row[i]);
                hi[i] = hi[i].max(row[i]);
            }
        }
        for i in 0..n {
            if lo[i] > hi[i] {
                (lo[i], hi[i]) = (0.0, 0.0);
            }
            let widen = ((hi[i] - lo[i]) / 10.0).max(1e-9 * lo[i].abs().max(hi[i].abs()).max(1.0));
            lo[i] -= widen;
            hi[i] += widen;
        }
        let mut compiled = DecisionTree {
            lo: lo.clone(),
            hi: hi.clone(),
            decisions: Vec::new(),
            blocks: Vec::new(),
        };
        let indices: Vec<usize> = (0..rows).collect();
        compiled.cut(tree, points, &indices, &mut lo, &mut hi, 0, settings);
        compiled
    }

    /// Compiles the box `lo..hi` holding the points `indices`; returns its
    /// decision's index.
    #[allow(clippy::too_many_arguments)]
    fn cut(
        &mut self,
        tree: &Tree,
        points: &[f64],
        indices: &[usize],
        lo: &mut [f64],
        hi: &mut [f64],
        depth: usize,
        settings: Settings,
    ) -> u32 {
        let mut scratch = Vec::new();
        let root = prune(tree, 0, lo, hi, &mut scratch);
        let pieces = scratch_pieces(&scratch, root.node);
        let at = self.decisions.len() as u32;
        let choice = if pieces.len() <= settings.block_pieces
            || depth >= settings.max_depth
            || indices.len() < settings.min_points
        {
            None
        } else {
            best_cut(tree, points, indices, lo, hi)
        };
        let Some((axis, threshold)) = choice else {
            let block = copy_block(&scratch, root.node, &mut self.blocks);
            self.decisions.push(Decision::Block(block));
            return at;
        };
        self.decisions.push(Decision::Cut {
            axis: axis as u32,
            threshold,
            below: 0,
            above: 0,
        });
        let n = tree.inputs();
        let (below, above): (Vec<usize>, Vec<usize>) = indices
            .iter()
            .partition(|&&r| points[r * n + axis] < threshold);
        let saved = hi[axis];
        hi[axis] = threshold;
        let b = self.cut(tree, points, &below, lo, hi, depth + 1, settings);
        hi[axis] = saved;
        let saved = lo[axis];
        lo[axis] = threshold;
        let a = self.cut(tree, points, &above, lo, hi, depth + 1, settings);
        lo[axis] = saved;
        self.decisions[at as usize] = Decision::Cut {
            axis: axis as u32,
            threshold,
            below: b,
            above: a,
        };
        at
    }

    /// f(x), exactly; `fallback` (the same tree's lazy evaluator) answers
    /// for points outside the root box.
    pub fn value(&self, tree: &Tree, x: &[f64], fallback: &mut Lazy) -> f64 {
        if x.iter()
            .zip(self.lo.iter().zip(&self.hi))
            .any(|(v, (lo, hi))| !(v >= lo && v <= hi))
        {
            return fallback.value(x);
        }
        let mut at = 0usize;
        loop {
            match self.decisions[at] {
                Decision::Cut {
                    axis,
                    threshold,
                    below,
                    above,
                } => {
                    at = if x[axis as usize] < threshold {
                        below
                    } else {
                        above
                    } as usize;
                }
                Decision::Block(root) => return self.block_value(tree, root as usize, x),
            }
        }
    }

    fn block_value(&self, tree: &Tree, node: usize, x: &[f64]) -> f64 {
        match self.blocks[node] {
            Node::Piece(p) => tree.piece_value(p as usize, x),
            Node::Min(a, b) => {
                let va = self.block_value(tree, a as usize, x);
                let vb = self.block_value(tree, b as usize, x);
                if vb < va { vb } else { va }
            }
            Node::Max(a, b) => {
                let va = self.block_value(tree, a as usize, x);
                let vb = self.block_value(tree, b as usize, x);
                if vb > va { vb } else { va }
            }
        }
    }

    /// How many boxes, and the mean number of pieces left per box.
    pub fn shape(&self) -> (usize, f64) {
        let blocks: Vec<u32> = self
            .decisions
            .iter()
            .filter_map(|d| match d {
                Decision::Block(root) => Some(*root),
                Decision::Cut { .. } => None,
            })
            .collect();
        let pieces: usize = blocks
            .iter()
            .map(|&r| scratch_pieces(&self.blocks, r).len())
            .sum();
        (blocks.len(), pieces as f64 / blocks.len().max(1) as f64)
    }
}

/// Piece `p`'s value bounds on the box, widened by twice the most rounding
/// can move a sum of its `inputs + 1` terms.
fn piece_bounds(tree: &Tree, p: usize, lo: &[f64], hi: &[f64]) -> (f64, f64) {
    let (bias, weights) = tree.piece(p);
    let (mut low, mut high, mut scale) = (bias, bias, bias.abs());
    for ((w, l), h) in weights.iter().zip(lo).zip(hi) {
        let (a, b) = (w * l, w * h);
        low += a.min(b);
        high += a.max(b);
        scale += a.abs().max(b.abs());
    }
    let margin = 8.0 * (weights.len() as f64 + 2.0) * (f64::EPSILON * scale + f64::MIN_POSITIVE);
    (low - margin, high + margin)
}

/// `node` of the tree pruned on the box, its nodes appended to `out`
/// (children indices into `out`; dropped subtrees stay there, unreached).
fn prune(tree: &Tree, node: usize, lo: &[f64], hi: &[f64], out: &mut Vec<Node>) -> Bounded {
    match tree.nodes()[node] {
        Node::Piece(p) => {
            let (l, h) = piece_bounds(tree, p as usize, lo, hi);
            out.push(Node::Piece(p));
            Bounded {
                node: out.len() as u32 - 1,
                lo: l,
                hi: h,
            }
        }
        Node::Min(a, b) | Node::Max(a, b) => {
            let min = matches!(tree.nodes()[node], Node::Min(..));
            let (a, b) = (
                prune(tree, a as usize, lo, hi, out),
                prune(tree, b as usize, lo, hi, out),
            );
            // Where one child is never below the other, a MIN is the
            // lower child and a MAX the upper. Bounds of each child alone
            // first; then their differences, which see that a hinge's two
            // pieces differ along one input only.
            let mut budget = DOMINANCE_BUDGET;
            if a.lo >= b.hi || dominates(tree, out, a.node, b.node, lo, hi, &mut budget) {
                return if min { b } else { a };
            }
            if b.lo >= a.hi || dominates(tree, out, b.node, a.node, lo, hi, &mut budget) {
                return if min { a } else { b };
            }
            let (join, pick): (Node, fn(f64, f64) -> f64) = if min {
                (Node::Min(a.node, b.node), f64::min)
            } else {
                (Node::Max(a.node, b.node), f64::max)
            };
            out.push(join);
            Bounded {
                node: out.len() as u32 - 1,
                lo: pick(a.lo, b.lo),
                hi: pick(a.hi, b.hi),
            }
        }
    }
}

/// Piece pairs one dominance question may compare before it answers no.
const DOMINANCE_BUDGET: usize = 4096;

/// Whether the subtree `a` of `nodes` computes a value at least subtree
/// `b`'s everywhere on the box, as computed (rounding included). Sufficient
/// conditions, decomposed: b a MAX — a above both children; b a MIN — above
/// either; a a MAX — either child above b; a a MIN — both; two pieces —
/// their difference's least value on the box, less both pieces' rounding,
/// is not negative. No when `budget` piece pairs did not settle it.
fn dominates(
    tree: &Tree,
    nodes: &[Node],
    a: u32,
    b: u32,
    lo: &[f64],
    hi: &[f64],
    budget: &mut usize,
) -> bool {
    if *budget == 0 {
        return false;
    }
    let above = |x: u32, y: u32, budget: &mut usize| dominates(tree, nodes, x, y, lo, hi, budget);
    match (nodes[a as usize], nodes[b as usize]) {
        (_, Node::Max(b1, b2)) => above(a, b1, budget) && above(a, b2, budget),
        (_, Node::Min(b1, b2)) => above(a, b1, budget) || above(a, b2, budget),
        (Node::Max(a1, a2), _) => above(a1, b, budget) || above(a2, b, budget),
        (Node::Min(a1, a2), _) => above(a1, b, budget) && above(a2, b, budget),
        (Node::Piece(p), Node::Piece(q)) => {
            if *budget == 0 {
                return false;
            }
            *budget -= 1;
            difference_low(tree, p as usize, q as usize, lo, hi) >= 0.0
        }
    }
}

/// A lower bound of computed p(x) − computed q(x) over the box: the least
/// value of their affine difference, less the most rounding can move it,
/// p's value and q's.
fn difference_low(tree: &Tree, p: usize, q: usize, lo: &[f64], hi: &[f64]) -> f64 {
    let ((bp, wp), (bq, wq)) = (tree.piece(p), tree.piece(q));
    let bias = bp - bq;
    let (mut low, mut scale) = (bias, bp.abs() + bq.abs());
    for (((p, q), l), h) in wp.iter().zip(wq).zip(lo).zip(hi) {
        let d = p - q;
        low += (d * l).min(d * h);
        scale += (p.abs() + q.abs()) * l.abs().max(h.abs());
    }
    // Relative rounding, and an absolute term for products that underflow.
    let terms = wp.len() as f64 + 2.0;
    low - 16.0 * terms * (f64::EPSILON * scale + f64::MIN_POSITIVE)
}

/// The pieces reached from `root` in `nodes`, in order of the first child.
fn scratch_pieces(nodes: &[Node], root: u32) -> Vec<u32> {
    let mut pieces = Vec::new();
    let mut stack = vec![root];
    while let Some(n) = stack.pop() {
        match nodes[n as usize] {
            Node::Piece(p) => pieces.push(p),
            Node::Min(a, b) | Node::Max(a, b) => {
                stack.push(b);
                stack.push(a);
            }
        }
    }
    pieces
}

/// Copies the subtree at `root` of `from` to the end of `to`; its index.
fn copy_block(from: &[Node], root: u32, to: &mut Vec<Node>) -> u32 {
    let at = to.len();
    to.push(from[root as usize]);
    if let Node::Min(a, b) | Node::Max(a, b) = from[root as usize] {
        let a = copy_block(from, a, to);
        let b = copy_block(from, b, to);
        to[at] = match from[root as usize] {
            Node::Min(..) => Node::Min(a, b),
            _ => Node::Max(a, b),
        };
    }
    at as u32
}

/// The cut that leaves the fewest pieces in the two boxes together (ties:
/// the wider side of the box): per input, at the median of the points in
/// the box. A cut that drops nothing yet is still made — pieces often give
/// way only a few cuts further — so the points bound how far it goes.
/// `None` when the points do not spread on any input.
fn best_cut(
    tree: &Tree,
    points: &[f64],
    indices: &[usize],
    lo: &mut [f64],
    hi: &mut [f64],
) -> Option<(usize, f64)> {
    let n = tree.inputs();
    let mut scratch = Vec::new();
    let mut left = |lo: &[f64], hi: &[f64]| {
        scratch.clear();
        let root = prune(tree, 0, lo, hi, &mut scratch);
        scratch_pieces(&scratch, root.node).len()
    };
    let mut best: Option<(usize, f64, usize, f64)> = None;
    let mut coordinate: Vec<f64> = Vec::with_capacity(indices.len());
    for axis in 0..n {
        coordinate.clear();
        coordinate.extend(indices.iter().map(|&r| points[r * n + axis]));
        coordinate.sort_by(f64::total_cmp);
        let threshold = coordinate[coordinate.len() / 2];
        if !(threshold > lo[axis] && threshold < hi[axis]) || threshold <= coordinate[0] {
            continue;
        }
        let saved = hi[axis];
        hi[axis] = threshold;
        let below = left(lo, hi);
        hi[axis] = saved;
        let saved = lo[axis];
        lo[axis] = threshold;
        let above = left(lo, hi);
        lo[axis] = saved;
        let (score, width) = (below + above, hi[axis] - lo[axis]);
        if best.is_none_or(|(s, w, _, _)| score < s || (score == s && width > w)) {
            best = Some((score, width, axis, threshold));
        }
    }
    best.map(|(_, _, axis, threshold)| (axis, threshold))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pwl::lazy::tests::random_tree;

    #[test]
    fn equals_every_piece_evaluated_on_and_off_the_box() {
        for seed in 1..30 {
            let inputs = 1 + (seed as usize % 4);
            let tree = random_tree(inputs, 30, seed);
            let points: Vec<f64> = (0..400 * inputs)
                .map(|i| ((i as f64 * 0.6180339887).fract() * 2.0 - 1.0) * 3.0)
                .collect();
            let compiled = DecisionTree::build(&tree, &points, Settings::default());
            let (boxes, per_box) = compiled.shape();
            assert!(
                boxes > 1 || per_box <= Settings::default().block_pieces as f64,
                "seed {seed}: not cut"
            );
            assert!(
                per_box < tree.pieces() as f64,
                "seed {seed}: nothing dropped"
            );
            let mut lazy = Lazy::new(&tree);
            // The sample points, fresh points and points far outside.
            for i in 0..1000 {
                let x: Vec<f64> = (0..inputs)
                    .map(|k| ((i * 7 + k * 13) as f64 * 0.7548776662).fract() * 8.0 - 4.0)
                    .collect();
                assert_eq!(
                    compiled.value(&tree, &x, &mut lazy).to_bits(),
                    tree.value(&x).to_bits(),
                    "seed {seed}, {x:?}"
                );
            }
            for row in points.chunks_exact(inputs) {
                assert_eq!(
                    compiled.value(&tree, row, &mut lazy).to_bits(),
                    tree.value(row).to_bits()
                );
            }
        }
    }

    #[test]
    fn a_box_drops_the_pieces_that_cannot_answer() {
        // max(x, −x): left of 0 only −x answers, right only x.
        let mut tree = Tree::affine(0.0, &[1.0]);
        let copy = tree.split(0, true);
        tree.set_piece(copy, 0.0, &[-1.0]);
        let points: Vec<f64> = (0..100).map(|i| i as f64 / 50.0 - 0.9).collect();
        let single = Settings {
            block_pieces: 1,
            ..Settings::default()
        };
        let compiled = DecisionTree::build(&tree, &points, single);
        let (boxes, per_box) = compiled.shape();
        assert!(
            boxes >= 2 && per_box < 2.0,
            "{boxes} boxes, {per_box} pieces each"
        );
        let mut lazy = Lazy::new(&tree);
        for &x in &points {
            assert_eq!(compiled.value(&tree, &[x], &mut lazy), x.abs());
        }
    }
}
