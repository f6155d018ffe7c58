//! One adaptive logic network (paper §3): a complete binary tree whose
//! internal nodes compute AND, LEFT, RIGHT or OR and whose leaves read one
//! input bit or its complement.
//!
//! Each internal node holds two bounded counters, for the input pairs (0,1)
//! and (1,0); their signs induce the node's function (table of §3.3):
//!
//! | (0,1) counter | (1,0) counter | function |
//! |---|---|---|
//! | < 0 | < 0 | AND |
//! | < 0 | ≥ 0 | LEFT |
//! | ≥ 0 | < 0 | RIGHT |
//! | ≥ 0 | ≥ 0 | OR |
//!
//! Nodes are stored in heap order: the root is 0, node i's children are
//! 2i + 1 and 2i + 2, and the leaves are the last `leaves` positions.

use rand::seq::SliceRandom;
use rand::{Rng, RngExt};

/// A node's function.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Function {
    And,
    Left,
    Right,
    Or,
}

impl Function {
    /// The function's output for inputs (a, b).
    #[inline]
    pub fn apply(self, a: bool, b: bool) -> bool {
        match self {
            Function::And => a && b,
            Function::Left => a,
            Function::Right => b,
            Function::Or => a || b,
        }
    }
}

/// A leaf's input: bit `literal / 2`, complemented if `literal` is odd.
pub type Literal = u32;

/// The value of a literal given the input bits (packed little-endian words).
#[inline]
pub fn literal_value(literal: Literal, input: &[u64]) -> bool {
    let bit = (literal / 2) as usize;
    (input[bit / 64] >> (bit % 64) & 1 == 1) ^ (literal & 1 == 1)
}

/// How a tree starts and adapts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TreeSpec {
    /// Leaves; a power of two ≥ 2 (paper: 8192).
    pub leaves: usize,
    /// Number of input bits.
    pub inputs: usize,
    /// Counters stay within −bound..=bound.
    pub counter_bound: i8,
    /// Initial counters are uniform in −spread..=spread − 1 (so every
    /// function is equally likely).
    pub initial_spread: i8,
}

/// An ALN tree with its counters.
#[derive(Clone, Debug, PartialEq)]
pub struct Tree {
    c01: Vec<i8>,
    c10: Vec<i8>,
    leaves: Vec<Literal>,
    bound: i8,
}

/// Reusable buffer for evaluating a tree (no allocation per sample).
#[derive(Default)]
pub struct Scratch {
    values: Vec<bool>,
}

/// What [`Tree::adapt`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Adaptation {
    /// The counter moved (it was not at its bound already).
    pub moved: bool,
    /// The node's function changed.
    pub flipped: bool,
}

impl Tree {
    /// A tree with random initial functions and leaves connected at random:
    /// every input bit and its complement appear on a leaf as often as the
    /// leaves allow (all 2k literals at least once when there are ≥ 2k
    /// leaves), the rest at random, shuffled.
    pub fn new(spec: &TreeSpec, rng: &mut impl Rng) -> Tree {
        let bits: Vec<u32> = (0..spec.inputs as u32).collect();
        Tree::reading(spec, &bits, rng)
    }

    /// Like [`Tree::new`], but the leaves read only the input `bits` given
    /// (indices into the whole input, so the tree evaluates on it).
    pub fn reading(spec: &TreeSpec, bits: &[u32], rng: &mut impl Rng) -> Tree {
        assert!(
            spec.leaves >= 2 && spec.leaves.is_power_of_two(),
            "leaves: a power of two ≥ 2"
        );
        assert!(spec.inputs >= 1 && spec.counter_bound >= 1 && spec.initial_spread >= 1);
        assert!(
            !bits.is_empty() && bits.iter().all(|&b| (b as usize) < spec.inputs),
            "leaves read some of the tree's inputs"
        );
        let internal = spec.leaves - 1;
        let spread = spec.initial_spread.min(spec.counter_bound);
        let mut counter = || rng.random_range(-spread..spread);
        let c01: Vec<i8> = (0..internal).map(|_| counter()).collect();
        let c10: Vec<i8> = (0..internal).map(|_| counter()).collect();
        let mut leaves: Vec<Literal> = Vec::with_capacity(spec.leaves);
        let mut all: Vec<Literal> = bits.iter().flat_map(|&b| [2 * b, 2 * b + 1]).collect();
        while leaves.len() + all.len() <= spec.leaves {
            leaves.extend_from_slice(&all);
        }
        all.shuffle(rng);
        let rest = spec.leaves - leaves.len();
        leaves.extend_from_slice(&all[..rest]);
        leaves.shuffle(rng);
        Tree {
            c01,
            c10,
            leaves,
            bound: spec.counter_bound,
        }
    }

    /// Number of leaves.
    pub fn leaves(&self) -> usize {
        self.leaves.len()
    }

    /// Depth in levels of internal nodes (log₂ leaves).
    pub fn depth(&self) -> u32 {
        self.leaves.len().trailing_zeros()
    }

    /// The function of internal node `i`.
    #[inline]
    pub fn function(&self, i: usize) -> Function {
        match (self.c01[i] < 0, self.c10[i] < 0) {
            (true, true) => Function::And,
            (true, false) => Function::Left,
            (false, true) => Function::Right,
            (false, false) => Function::Or,
        }
    }

    /// The leaves' literals.
    pub fn literals(&self) -> &[Literal] {
        &self.leaves
    }

    /// A tree with the given node functions (heap order) and leaf literals;
    /// each node's counters are set to the smallest values inducing its
    /// function (−1 or 0).
    pub fn from_functions(functions: &[Function], leaves: Vec<Literal>, bound: i8) -> Tree {
        assert_eq!(
            functions.len() + 1,
            leaves.len(),
            "one more leaf than internal nodes"
        );
        let sign = |negative: bool| if negative { -1 } else { 0 };
        let c01 = functions
            .iter()
            .map(|f| sign(matches!(f, Function::And | Function::Left)))
            .collect();
        let c10 = functions
            .iter()
            .map(|f| sign(matches!(f, Function::And | Function::Right)))
            .collect();
        Tree {
            c01,
            c10,
            leaves,
            bound,
        }
    }

    /// Every internal node's function, heap order.
    pub fn functions(&self) -> Vec<Function> {
        (0..self.c01.len()).map(|i| self.function(i)).collect()
    }

    /// Number of internal nodes (leaves − 1).
    #[inline]
    pub fn internal(&self) -> usize {
        self.leaves.len() - 1
    }

    /// The adaptation of §3.3 at internal node `i` whose children output
    /// (`a`, `b`): for (0,1) or (1,0), that pair's counter moves one step
    /// toward `desired`, within the bound; for (0,0) and (1,1) nothing
    /// changes. Says whether the counter moved and whether the node's
    /// function changed with it.
    #[inline]
    pub fn adapt(&mut self, i: usize, a: bool, b: bool, desired: bool) -> Adaptation {
        let counter = match (a, b) {
            (false, true) => &mut self.c01[i],
            (true, false) => &mut self.c10[i],
            _ => return Adaptation::default(),
        };
        let before = *counter;
        *counter = step(before, desired, self.bound);
        Adaptation {
            moved: *counter != before,
            flipped: (before < 0) != (*counter < 0),
        }
    }

    /// Evaluates every node bottom-up into `values` (heap order: internal
    /// nodes, then leaves).
    pub fn evaluate_all(&self, input: &[u64], values: &mut Vec<bool>) {
        let internal = self.leaves.len() - 1;
        values.clear();
        values.resize(internal + self.leaves.len(), false);
        for (j, &literal) in self.leaves.iter().enumerate() {
            values[internal + j] = literal_value(literal, input);
        }
        for i in (0..internal).rev() {
            values[i] = self.function(i).apply(values[2 * i + 1], values[2 * i + 2]);
        }
    }

    /// The output for one input, evaluating every node.
    pub fn evaluate(&self, input: &[u64], scratch: &mut Scratch) -> bool {
        self.evaluate_all(input, &mut scratch.values);
        scratch.values[0]
    }

    /// The output for one input by parsimonious evaluation (§3.2): a child is
    /// evaluated only when the other has not decided the node (LEFT and RIGHT
    /// need one child, AND stops at a 0, OR at a 1). Returns the output and
    /// the number of nodes (internal and leaves) evaluated.
    pub fn evaluate_parsimonious(&self, input: &[u64]) -> (bool, usize) {
        let mut evaluated = 0;
        let value = self.lazy(0, input, &mut evaluated);
        (value, evaluated)
    }

    fn lazy(&self, i: usize, input: &[u64], evaluated: &mut usize) -> bool {
        *evaluated += 1;
        let internal = self.leaves.len() - 1;
        if i >= internal {
            return literal_value(self.leaves[i - internal], input);
        }
        let (left, right) = (2 * i + 1, 2 * i + 2);
        match self.function(i) {
            Function::Left => self.lazy(left, input, evaluated),
            Function::Right => self.lazy(right, input, evaluated),
            Function::And => {
                self.lazy(left, input, evaluated) && self.lazy(right, input, evaluated)
            }
            Function::Or => self.lazy(left, input, evaluated) || self.lazy(right, input, evaluated),
        }
    }

    /// The tree with LEFT and RIGHT nodes replaced by the child they pass on:
    /// what remains is AND and OR nodes over leaves (paper §5).
    pub fn prune(&self) -> Pruned {
        let mut nodes = Vec::new();
        let root = self.prune_into(0, &mut nodes);
        debug_assert_eq!(root as usize, nodes.len() - 1);
        Pruned { nodes }
    }

    fn prune_into(&self, i: usize, nodes: &mut Vec<Gate>) -> u32 {
        let internal = self.leaves.len() - 1;
        if i >= internal {
            nodes.push(Gate::Leaf(self.leaves[i - internal]));
            return (nodes.len() - 1) as u32;
        }
        let (left, right) = (2 * i + 1, 2 * i + 2);
        match self.function(i) {
            Function::Left => self.prune_into(left, nodes),
            Function::Right => self.prune_into(right, nodes),
            f => {
                let a = self.prune_into(left, nodes);
                let b = self.prune_into(right, nodes);
                nodes.push(if f == Function::And {
                    Gate::And(a, b)
                } else {
                    Gate::Or(a, b)
                });
                (nodes.len() - 1) as u32
            }
        }
    }
}

/// One counter step toward the desired output, within ±bound.
#[inline]
fn step(counter: i8, desired: bool, bound: i8) -> i8 {
    if desired {
        (counter + 1).min(bound)
    } else {
        (counter - 1).max(-bound)
    }
}

/// A gate of a pruned tree; children are indices of earlier gates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gate {
    Leaf(Literal),
    And(u32, u32),
    Or(u32, u32),
}

/// A pruned tree: AND/OR gates in post-order, the root last.
#[derive(Clone, Debug, PartialEq)]
pub struct Pruned {
    pub nodes: Vec<Gate>,
}

impl Pruned {
    /// Number of AND/OR gates (its nodes but the leaves).
    pub fn gates(&self) -> usize {
        self.nodes
            .iter()
            .filter(|g| !matches!(g, Gate::Leaf(_)))
            .count()
    }

    /// Depth in gate delays: the longest chain of AND/OR gates.
    pub fn depth(&self) -> u32 {
        let mut depth = vec![0u32; self.nodes.len()];
        for (i, gate) in self.nodes.iter().enumerate() {
            depth[i] = match *gate {
                Gate::Leaf(_) => 0,
                Gate::And(a, b) | Gate::Or(a, b) => 1 + depth[a as usize].max(depth[b as usize]),
            };
        }
        depth.last().copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn spec(leaves: usize, inputs: usize) -> TreeSpec {
        TreeSpec {
            leaves,
            inputs,
            counter_bound: 7,
            initial_spread: 1,
        }
    }

    #[test]
    fn every_literal_is_on_a_leaf_when_there_is_room() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let tree = Tree::new(&spec(64, 20), &mut rng);
        let mut seen = vec![0; 40];
        tree.literals().iter().for_each(|&l| seen[l as usize] += 1);
        assert!(seen.iter().all(|&n| n >= 1), "{seen:?}");
        let small = Tree::new(&spec(8, 20), &mut rng);
        assert_eq!(small.leaves(), 8);
    }

    #[test]
    fn a_tree_over_some_bits_reads_each_of_them_and_nothing_else() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let bits = [3, 17, 40];
        let tree = Tree::reading(&spec(64, 50), &bits, &mut rng);
        let mut seen = vec![0; 100];
        tree.literals().iter().for_each(|&l| seen[l as usize] += 1);
        for (literal, &n) in seen.iter().enumerate() {
            let read = bits.contains(&(literal as u32 / 2));
            assert_eq!(n > 0, read, "literal {literal} seen {n} times");
            // 64 leaves over 6 literals: each on 10 or 11 leaves.
            assert!(!read || (10..=11).contains(&n), "literal {literal}: {n}");
        }
    }

    #[test]
    fn initial_functions_are_all_four() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let tree = Tree::new(&spec(1024, 10), &mut rng);
        let mut counts = [0; 4];
        for i in 0..1023 {
            counts[tree.function(i) as usize] += 1;
        }
        assert!(
            counts.iter().all(|&c| (180..330).contains(&c)),
            "{counts:?}"
        );
    }

    #[test]
    fn parsimony_saves_most_of_a_large_tree() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let tree = Tree::new(&spec(8192, 100), &mut rng);
        let total: usize = (0..200)
            .map(|_| {
                let input: Vec<u64> = (0..2).map(|_| rng.random()).collect();
                tree.evaluate_parsimonious(&input).1
            })
            .sum();
        let fraction = total as f64 / 200.0 / (2.0 * 8192.0 - 1.0);
        // Paper §3.2: about ½·(3/4)^13 ≈ 0.012 of the nodes for random functions.
        assert!(fraction < 0.05, "evaluated {fraction:.4} of the nodes");
    }
}
