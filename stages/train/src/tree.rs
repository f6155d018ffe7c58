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

/// Reusable buffers for training a tree (no allocation per sample).
#[derive(Default)]
pub struct Scratch {
    values: Vec<bool>,
    stack: Vec<usize>,
}

impl Tree {
    /// A tree with random initial functions and leaves connected at random:
    /// every input bit and its complement appear on a leaf as often as the
    /// leaves allow (all 2k literals at least once when there are ≥ 2k
    /// leaves), the rest at random, shuffled.
    pub fn new(spec: &TreeSpec, rng: &mut impl Rng) -> Tree {
        assert!(
            spec.leaves >= 2 && spec.leaves.is_power_of_two(),
            "leaves: a power of two ≥ 2"
        );
        assert!(spec.inputs >= 1 && spec.counter_bound >= 1 && spec.initial_spread >= 1);
        let internal = spec.leaves - 1;
        let spread = spec.initial_spread.min(spec.counter_bound);
        let mut counter = || rng.random_range(-spread..spread);
        let c01: Vec<i8> = (0..internal).map(|_| counter()).collect();
        let c10: Vec<i8> = (0..internal).map(|_| counter()).collect();
        let literals = (2 * spec.inputs) as u32;
        let mut leaves: Vec<Literal> = Vec::with_capacity(spec.leaves);
        let mut all: Vec<Literal> = (0..literals).collect();
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

    /// Evaluates every node bottom-up into `values` (heap order).
    fn evaluate_all(&self, input: &[u64], values: &mut Vec<bool>) {
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

    /// Trains on one sample: evaluates, marks the heuristically responsible
    /// nodes by the rules of §3.3, and moves the counter of each responsible
    /// node whose inputs are (0,1) or (1,0) one step toward `desired`
    /// (bounded). Returns whether the output was already right.
    pub fn train(&mut self, input: &[u64], desired: bool, scratch: &mut Scratch) -> bool {
        self.evaluate_all(input, &mut scratch.values);
        let values = &scratch.values;
        let correct = values[0] == desired;
        let internal = self.leaves.len() - 1;
        let stack = &mut scratch.stack;
        stack.clear();
        stack.push(0); // rule 1: the root is responsible
        while let Some(i) = stack.pop() {
            let (left, right) = (2 * i + 1, 2 * i + 2);
            let (a, b) = (values[left], values[right]);
            let f = self.function(i);
            let out = f.apply(a, b);
            // Rule 2: an input unequal to the desired output is an error;
            // rule 3: the child opposite an error is responsible; rule 4: a
            // child whose change would change this node's output is too.
            let left_responsible = b != desired || f.apply(!a, b) != out;
            let right_responsible = a != desired || f.apply(a, !b) != out;
            match (a, b) {
                (false, true) => self.c01[i] = step(self.c01[i], desired, self.bound),
                (true, false) => self.c10[i] = step(self.c10[i], desired, self.bound),
                _ => {}
            }
            if left_responsible && left < internal {
                stack.push(left);
            }
            if right_responsible && right < internal {
                stack.push(right);
            }
        }
        correct
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

/// Training samples in bit-sliced form: input bit `b` of sample `s` is bit
/// `s % 64` of `columns[b * words + s / 64]`; the target likewise in
/// `targets[s / 64]`.
pub struct Samples<'a> {
    /// Number of samples.
    pub count: usize,
    /// Words per column: ⌈count / 64⌉.
    pub words: usize,
    /// Input columns, `inputs × words`.
    pub columns: &'a [u64],
    /// Target bits, `words`.
    pub targets: &'a [u64],
}

/// What one epoch of training did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EpochLog {
    /// Samples whose output was wrong when presented.
    pub errors: usize,
    /// Counter updates made.
    pub updates: usize,
}

impl Tree {
    /// Trains for up to `max_epochs` epochs, until an epoch presents every
    /// sample right. Each epoch presents the samples in a fresh random order
    /// drawn from `rng`: samples of a trajectory come in runs of similar
    /// states, and presented in time order a tree would chase the latest run
    /// (right on each sample as it comes, wrong on most of the set at the
    /// end) instead of fitting the whole set. Exactly what
    /// [`Tree::train`] on each sample in turn does, but fast: every node's
    /// value for every sample is kept bit-sliced, and only when a counter
    /// changes sign (the node's function changes) are that node's values and
    /// its ancestors' recomputed.
    pub fn train_epochs(
        &mut self,
        samples: &Samples,
        max_epochs: usize,
        rng: &mut impl Rng,
    ) -> Vec<EpochLog> {
        let internal = self.leaves.len() - 1;
        let words = samples.words;
        let mut values = vec![0u64; (internal + self.leaves.len()) * words];
        for (j, &literal) in self.leaves.iter().enumerate() {
            let bit = (literal / 2) as usize;
            let flip = if literal & 1 == 1 { u64::MAX } else { 0 };
            let column = &samples.columns[bit * words..(bit + 1) * words];
            for (v, c) in values[(internal + j) * words..].iter_mut().zip(column) {
                *v = c ^ flip;
            }
        }
        for i in (0..internal).rev() {
            self.recompute(i, words, &mut values);
        }
        let mut log = Vec::new();
        let (mut stack, mut flipped) = (Vec::new(), Vec::new());
        // Ancestors already queued for recomputation in this sample.
        let mut stale = vec![false; internal];
        let mut order: Vec<usize> = (0..samples.count).collect();
        for _ in 0..max_epochs {
            order.shuffle(rng);
            let mut epoch = EpochLog {
                errors: 0,
                updates: 0,
            };
            for &s in &order {
                let (w, shift) = (s / 64, s % 64);
                let bit = |node: usize| values[node * words + w] >> shift & 1 == 1;
                let desired = samples.targets[w] >> shift & 1 == 1;
                epoch.errors += usize::from(bit(0) != desired);
                stack.clear();
                stack.push(0);
                flipped.clear();
                while let Some(i) = stack.pop() {
                    let (left, right) = (2 * i + 1, 2 * i + 2);
                    let (a, b) = (bit(left), bit(right));
                    let f = self.function(i);
                    let out = f.apply(a, b);
                    let left_responsible = b != desired || f.apply(!a, b) != out;
                    let right_responsible = a != desired || f.apply(a, !b) != out;
                    let counter = match (a, b) {
                        (false, true) => Some(&mut self.c01[i]),
                        (true, false) => Some(&mut self.c10[i]),
                        _ => None,
                    };
                    if let Some(counter) = counter {
                        let before = *counter;
                        *counter = step(before, desired, self.bound);
                        epoch.updates += usize::from(*counter != before);
                        if (before < 0) != (*counter < 0) {
                            flipped.push(i);
                        }
                    }
                    if left_responsible && left < internal {
                        stack.push(left);
                    }
                    if right_responsible && right < internal {
                        stack.push(right);
                    }
                }
                // The changed nodes and all their ancestors, each once.
                // Children have larger indices than parents, so recomputing
                // from the highest index down visits every node after its
                // children.
                let changed = flipped.len();
                for k in 0..changed {
                    let mut i = flipped[k];
                    while i > 0 {
                        i = (i - 1) / 2;
                        if stale[i] {
                            break;
                        }
                        stale[i] = true;
                        flipped.push(i);
                    }
                }
                flipped.sort_unstable_by(|a, b| b.cmp(a));
                flipped.dedup();
                for &i in &flipped {
                    self.recompute(i, words, &mut values);
                    stale[i] = false;
                }
            }
            let done = epoch.errors == 0;
            log.push(epoch);
            if done {
                break;
            }
        }
        log
    }

    /// Recomputes node `i`'s values for all samples from its children's.
    fn recompute(&self, i: usize, words: usize, values: &mut [u64]) {
        let f = self.function(i);
        let (head, tail) = values.split_at_mut((2 * i + 1) * words);
        let out = &mut head[i * words..(i + 1) * words];
        let (a, b) = (&tail[..words], &tail[words..2 * words]);
        for w in 0..words {
            out[w] = match f {
                Function::And => a[w] & b[w],
                Function::Left => a[w],
                Function::Right => b[w],
                Function::Or => a[w] | b[w],
            };
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
    use rand::SeedableRng;
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
    fn learns_a_boolean_function_of_its_inputs() {
        // y = (x0 AND x1) OR (x2 AND NOT x3), over all 16 inputs of 4 bits
        // plus 4 irrelevant bits (256 samples).
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut tree = Tree::new(&spec(256, 8), &mut rng);
        let mut scratch = Scratch::default();
        let target = |x: u64| (x & 1 == 1 && x & 2 == 2) || (x & 4 == 4 && x & 8 == 0);
        let mut epochs = 0;
        loop {
            epochs += 1;
            let right = (0..256u64)
                .filter(|&x| tree.train(&[x], target(x), &mut scratch))
                .count();
            if right == 256 || epochs == 60 {
                break;
            }
        }
        let errors = (0..256u64)
            .filter(|&x| tree.evaluate(&[x], &mut scratch) != target(x))
            .count();
        assert_eq!(errors, 0, "after {epochs} epochs");
    }

    /// Bit-slices per-sample inputs (one word each) and targets.
    fn slice(inputs: &[u64], bits: usize, targets: &[bool]) -> (Vec<u64>, Vec<u64>, usize) {
        let words = inputs.len().div_ceil(64);
        let mut columns = vec![0u64; bits * words];
        let mut target = vec![0u64; words];
        for (s, &x) in inputs.iter().enumerate() {
            for b in 0..bits {
                columns[b * words + s / 64] |= (x >> b & 1) << (s % 64);
            }
            target[s / 64] |= u64::from(targets[s]) << (s % 64);
        }
        (columns, target, words)
    }

    #[test]
    fn bit_sliced_epochs_equal_training_sample_by_sample() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for case in 0..12 {
            let bits = 6 + case;
            let tree = Tree::new(&spec(1 << (3 + case % 6), bits), &mut rng);
            let n = 50 + 37 * case;
            let inputs: Vec<u64> = (0..n)
                .map(|_| rng.random::<u64>() & ((1 << bits) - 1))
                .collect();
            let targets: Vec<bool> = inputs
                .iter()
                .map(|x| (x.count_ones() + case as u32).is_multiple_of(3))
                .collect();
            let (columns, target_words, words) = slice(&inputs, bits, &targets);
            let samples = Samples {
                count: n,
                words,
                columns: &columns,
                targets: &target_words,
            };
            let mut fast = tree.clone();
            let log = fast.train_epochs(&samples, 4, &mut ChaCha8Rng::seed_from_u64(case as u64));
            // The same orders, drawn from the same seed.
            let mut order_rng = ChaCha8Rng::seed_from_u64(case as u64);
            let mut order: Vec<usize> = (0..n).collect();
            let mut slow = tree.clone();
            let mut scratch = Scratch::default();
            for epoch in &log {
                order.shuffle(&mut order_rng);
                let right = order
                    .iter()
                    .filter(|&&s| slow.train(&[inputs[s]], targets[s], &mut scratch))
                    .count();
                assert_eq!(n - right, epoch.errors, "case {case}");
            }
            assert_eq!(fast, slow, "case {case}: counters differ");
        }
    }

    #[test]
    fn learns_and_or_and_majority_among_distractors() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let inputs: Vec<u64> = (0..1024u64).collect(); // all of 10 bits
        type Target = fn(u64) -> bool;
        let targets: [(&str, Target); 3] = [
            ("and", |x| x & 0b11 == 0b11),
            ("or", |x| x & 0b11 != 0),
            ("majority", |x| (x & 0b111).count_ones() >= 2),
        ];
        for (name, target) in targets {
            let wanted: Vec<bool> = inputs.iter().map(|&x| target(x)).collect();
            let (columns, target_words, words) = slice(&inputs, 10, &wanted);
            let samples = Samples {
                count: 1024,
                words,
                columns: &columns,
                targets: &target_words,
            };
            // Majority needs the right pairs of literals close together: a
            // larger tree offers more (with 2048 leaves and counter bound 3,
            // 10 of 10 seeds learn it; with 128 leaves about half do).
            let spec = TreeSpec {
                leaves: 2048,
                inputs: 10,
                counter_bound: 3,
                initial_spread: 1,
            };
            let mut tree = Tree::new(&spec, &mut rng);
            let log = tree.train_epochs(&samples, 40, &mut rng);
            assert_eq!(log.last().unwrap().errors, 0, "{name}: {log:?}");
        }
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
