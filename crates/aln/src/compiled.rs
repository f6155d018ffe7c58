//! Pruned trees compiled for fast evaluation, in two forms of the same
//! AND/OR functions, each laid out flat for a whole forest:
//!
//! - [`Chains`], one sample at a time (parsimonious, §3.2): a tree becomes a
//!   chain of leaf tests. Each step reads one literal and jumps on its value
//!   to the next leaf to test or to the tree's answer, so it visits exactly
//!   the leaves short-circuit evaluation visits, with no stack and no
//!   internal nodes. Several trees are walked in interleaved lanes so that
//!   their memory latencies overlap.
//! - [`Programs`], bit-sliced batches: a tree becomes a post-order stack
//!   program in which an AND/OR with a leaf operand is one instruction. It
//!   runs over blocks of [`BLOCK`] words (64·BLOCK samples), so each
//!   instruction's decode is paid once per block.

use crate::tree::{Gate, Literal, Pruned, literal_value};

/// A chain step: test `literal`, go to `next[value]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
struct Step {
    literal: Literal,
    next: [u32; 2],
}

/// Chain indices 0 and 1 are the answers false and true.
const ANSWERS: u32 = 2;
/// Trees walked at once by [`Chains::evaluate`].
const LANES: usize = 8;

/// The parsimonious single-sample form of a forest's trees.
#[derive(Clone, Debug, PartialEq)]
pub struct Chains {
    /// Steps of all trees; 0 and 1 are the answers.
    steps: Vec<Step>,
    /// Each tree's first step.
    starts: Vec<u32>,
}

impl Chains {
    /// Compiles the trees, in order.
    pub fn new<'a>(trees: impl IntoIterator<Item = &'a Pruned>) -> Chains {
        let answer = Step {
            literal: 0,
            next: [0, 0],
        };
        let mut chains = Chains {
            steps: vec![answer; ANSWERS as usize],
            starts: Vec::new(),
        };
        for tree in trees {
            chains.push(tree);
        }
        chains
    }

    fn push(&mut self, tree: &Pruned) {
        let base = self.steps.len() as u32;
        // Post-order lists the leaves left to right, the order of the chain;
        // `first[g]` is the chain index of gate g's leftmost leaf.
        let mut first = Vec::with_capacity(tree.nodes.len());
        let mut leaves = 0;
        for gate in &tree.nodes {
            first.push(match *gate {
                Gate::Leaf(literal) => {
                    self.steps.push(Step {
                        literal,
                        next: [0, 0],
                    });
                    leaves += 1;
                    base + leaves - 1
                }
                Gate::And(a, _) | Gate::Or(a, _) => first[a as usize],
            });
        }
        self.starts.push(base);
        let root = tree.nodes.len() as u32 - 1;
        // Where each gate goes when it is true and when it is false: AND
        // tests its right side only when its left side is true, OR only when
        // its left side is false.
        let mut pending = vec![(root, [0, 1])];
        while let Some((g, next)) = pending.pop() {
            match tree.nodes[g as usize] {
                Gate::Leaf(_) => self.steps[first[g as usize] as usize].next = next,
                Gate::And(a, b) => {
                    pending.push((a, [next[0], first[b as usize]]));
                    pending.push((b, next));
                }
                Gate::Or(a, b) => {
                    pending.push((a, [first[b as usize], next[1]]));
                    pending.push((b, next));
                }
            }
        }
    }

    /// Number of trees.
    pub fn trees(&self) -> usize {
        self.starts.len()
    }

    /// Evaluates every tree on one sample (`input` holds the literals' bits,
    /// 64 per word); `out[t]` gets tree t's output. Returns the number of
    /// leaves tested.
    pub fn evaluate(&self, input: &[u64], out: &mut [bool]) -> usize {
        assert_eq!(out.len(), self.trees(), "one output per tree");
        let steps = &self.steps[..];
        let mut at = [0u32; LANES];
        let mut tree = [usize::MAX; LANES];
        let mut next_tree = 0;
        let mut running = 0;
        for lane in 0..LANES.min(self.trees()) {
            at[lane] = self.starts[lane];
            tree[lane] = lane;
            next_tree += 1;
            running += 1;
        }
        let mut tested = 0;
        while running > 0 {
            for lane in 0..LANES {
                let i = at[lane];
                if i < ANSWERS {
                    if tree[lane] == usize::MAX {
                        continue;
                    }
                    out[tree[lane]] = i == 1;
                    if next_tree < self.trees() {
                        at[lane] = self.starts[next_tree];
                        tree[lane] = next_tree;
                        next_tree += 1;
                    } else {
                        tree[lane] = usize::MAX;
                        running -= 1;
                    }
                    continue;
                }
                let step = steps[i as usize];
                at[lane] = step.next[usize::from(literal_value(step.literal, input))];
                tested += 1;
            }
        }
        tested
    }
}

/// Words per block of [`Programs`]: 1024 samples.
pub const BLOCK: usize = 16;

/// One block of a bit-sliced column: 64·BLOCK samples.
pub type Block = [u64; BLOCK];

const LITERAL_BITS: u32 = 29;
const LITERAL_MASK: u32 = (1 << LITERAL_BITS) - 1;
/// Instructions (the top three bits): push a literal; AND or OR a literal
/// into the top of the stack; pop the top and AND or OR it into the next.
const PUSH: u32 = 0;
const AND_LITERAL: u32 = 1;
const OR_LITERAL: u32 = 2;
const AND_POP: u32 = 3;
const OR_POP: u32 = 4;

/// The bit-sliced batch form of a forest's trees.
#[derive(Clone, Debug, PartialEq)]
pub struct Programs {
    /// Instructions of all trees: opcode << 29 | literal.
    code: Vec<u32>,
    /// Tree t's instructions are `code[starts[t]..starts[t + 1]]`.
    starts: Vec<u32>,
    /// The deepest stack any tree needs (the first push stores the empty
    /// top, so this counts the top too).
    stack: usize,
}

impl Programs {
    /// Compiles the trees, in order.
    pub fn new<'a>(trees: impl IntoIterator<Item = &'a Pruned>) -> Programs {
        let mut programs = Programs {
            code: Vec::new(),
            starts: vec![0],
            stack: 0,
        };
        for tree in trees {
            let need = stack_need(tree);
            let root = tree.nodes.len() - 1;
            emit(tree, root, &need, &mut programs.code);
            programs.stack = programs.stack.max(need[root] as usize);
            programs.starts.push(programs.code.len() as u32);
        }
        programs
    }

    /// Number of trees.
    pub fn trees(&self) -> usize {
        self.starts.len() - 1
    }

    /// Evaluates every tree on one block of samples: `inputs[b]` is input
    /// bit b's block; `out[t]` gets tree t's output block.
    pub fn evaluate_block(&self, inputs: &[Block], out: &mut [Block]) {
        assert_eq!(out.len(), self.trees(), "one output block per tree");
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.evaluate_block_avx2(inputs, out) };
        }
        self.evaluate_block_portable(inputs, out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn evaluate_block_avx2(&self, inputs: &[Block], out: &mut [Block]) {
        self.evaluate_block_portable(inputs, out);
    }

    #[inline(always)]
    fn evaluate_block_portable(&self, inputs: &[Block], out: &mut [Block]) {
        let mut stack = vec![[0u64; BLOCK]; self.stack];
        for (t, block) in out.iter_mut().enumerate() {
            let code = &self.code[self.starts[t] as usize..self.starts[t + 1] as usize];
            *block = run(code, inputs, &mut stack);
        }
    }
}

#[inline(always)]
fn run(code: &[u32], inputs: &[Block], stack: &mut [Block]) -> Block {
    let mut top = [0u64; BLOCK];
    let mut depth = 0;
    for &instruction in code {
        let literal = instruction & LITERAL_MASK;
        let flip = 0u64.wrapping_sub(u64::from(literal & 1));
        let column = &inputs[(literal / 2) as usize];
        match instruction >> LITERAL_BITS {
            PUSH => {
                stack[depth] = top;
                depth += 1;
                for j in 0..BLOCK {
                    top[j] = column[j] ^ flip;
                }
            }
            AND_LITERAL => {
                for j in 0..BLOCK {
                    top[j] &= column[j] ^ flip;
                }
            }
            OR_LITERAL => {
                for j in 0..BLOCK {
                    top[j] |= column[j] ^ flip;
                }
            }
            AND_POP => {
                depth -= 1;
                for j in 0..BLOCK {
                    top[j] &= stack[depth][j];
                }
            }
            _ => {
                depth -= 1;
                for j in 0..BLOCK {
                    top[j] |= stack[depth][j];
                }
            }
        }
    }
    top
}

/// Stack slots (top included) each gate's program needs, children ordered
/// the hungrier first (Sethi–Ullman); a leaf operand needs none of its own.
fn stack_need(tree: &Pruned) -> Vec<u32> {
    let mut need: Vec<u32> = Vec::with_capacity(tree.nodes.len());
    for gate in &tree.nodes {
        need.push(match *gate {
            Gate::Leaf(_) => 1,
            Gate::And(a, b) | Gate::Or(a, b) => {
                let (na, nb) = (need[a as usize], need[b as usize]);
                if is_leaf(tree, a) || is_leaf(tree, b) || na != nb {
                    na.max(nb)
                } else {
                    na + 1
                }
            }
        });
    }
    need
}

fn is_leaf(tree: &Pruned, gate: u32) -> bool {
    matches!(tree.nodes[gate as usize], Gate::Leaf(_))
}

fn emit(tree: &Pruned, g: usize, need: &[u32], code: &mut Vec<u32>) {
    let (a, b, with_literal, pop) = match tree.nodes[g] {
        Gate::Leaf(literal) => {
            code.push(PUSH << LITERAL_BITS | literal);
            return;
        }
        Gate::And(a, b) => (a, b, AND_LITERAL, AND_POP),
        Gate::Or(a, b) => (a, b, OR_LITERAL, OR_POP),
    };
    let leaf = |x: u32| match tree.nodes[x as usize] {
        Gate::Leaf(literal) => Some(literal),
        _ => None,
    };
    match (leaf(a), leaf(b)) {
        (_, Some(literal)) => {
            emit(tree, a as usize, need, code);
            code.push(with_literal << LITERAL_BITS | literal);
        }
        (Some(literal), None) => {
            emit(tree, b as usize, need, code);
            code.push(with_literal << LITERAL_BITS | literal);
        }
        (None, None) => {
            let (first, second) = if need[a as usize] >= need[b as usize] {
                (a, b)
            } else {
                (b, a)
            };
            emit(tree, first as usize, need, code);
            emit(tree, second as usize, need, code);
            code.push(pop << LITERAL_BITS);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tree::{Function, Scratch, Tree, TreeSpec};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Random trees of 2 to 512 leaves, each node's function drawn
    /// uniformly, with 64·BLOCK + 5 samples.
    fn cases() -> Vec<(Tree, Vec<Vec<u64>>)> {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let functions = [Function::And, Function::Left, Function::Right, Function::Or];
        (0..40)
            .map(|case| {
                let spec = TreeSpec {
                    leaves: 1 << (1 + case % 9),
                    inputs: 1 + case % 70,
                    counter_bound: 7,
                    initial_spread: 1,
                };
                let leaves = Tree::new(&spec, &mut rng).literals().to_vec();
                let nodes: Vec<Function> = (1..spec.leaves)
                    .map(|_| functions[rng.random_range(0..4)])
                    .collect();
                let tree = Tree::from_functions(&nodes, leaves, spec.counter_bound);
                let samples: Vec<Vec<u64>> = (0..64 * BLOCK + 5)
                    .map(|_| vec![rng.random::<u64>(), rng.random::<u64>()])
                    .collect();
                (tree, samples)
            })
            .collect()
    }

    #[test]
    fn every_evaluation_path_gives_the_same_outputs() {
        let cases = cases();
        let pruned: Vec<Pruned> = cases.iter().map(|(tree, _)| tree.prune()).collect();
        let chains = Chains::new(&pruned);
        let programs = Programs::new(&pruned);
        let mut scratch = Scratch::default();
        let mut outputs = vec![false; cases.len()];
        for (t, (tree, samples)) in cases.iter().enumerate() {
            assert!(pruned[t].depth() <= tree.depth());
            // Input bit b of the two blocks of samples.
            let blocks: Vec<Vec<Block>> = (0..2)
                .map(|k| {
                    (0..128)
                        .map(|b| {
                            std::array::from_fn(|j| {
                                (0..64).fold(0, |word, i| {
                                    let s = (k * BLOCK + j) * 64 + i;
                                    let bit =
                                        samples.get(s).map_or(0, |x| x[b / 64] >> (b % 64) & 1);
                                    word | bit << i
                                })
                            })
                        })
                        .collect()
                })
                .collect();
            let mut batched = vec![[0u64; BLOCK]; cases.len()];
            let batched: Vec<Block> = blocks
                .iter()
                .map(|block| {
                    programs.evaluate_block(block, &mut batched);
                    batched[t]
                })
                .collect();
            for (s, sample) in samples.iter().enumerate() {
                let full = tree.evaluate(sample, &mut scratch);
                let (lazy, evaluated) = tree.evaluate_parsimonious(sample);
                assert!(evaluated < 2 * tree.leaves());
                assert_eq!(lazy, full, "tree {t}, sample {s}: parsimonious");
                chains.evaluate(sample, &mut outputs);
                assert_eq!(outputs[t], full, "tree {t}, sample {s}: chain");
                let word = batched[s / (64 * BLOCK)][s / 64 % BLOCK];
                assert_eq!(
                    word >> (s % 64) & 1 == 1,
                    full,
                    "tree {t}, sample {s}: batch"
                );
            }
        }
    }

    #[test]
    fn a_chain_tests_only_the_leaves_short_circuit_evaluation_reaches() {
        // (x0 AND x1) OR NOT x2: x0 = 0 skips x1; a true left side skips x2.
        let tree = Pruned {
            nodes: vec![
                Gate::Leaf(0),
                Gate::Leaf(2),
                Gate::And(0, 1),
                Gate::Leaf(5),
                Gate::Or(2, 3),
            ],
        };
        let chains = Chains::new([&tree]);
        let mut out = [false];
        for (input, expected, tested) in [
            (0b000, true, 2),
            (0b011, true, 2),
            (0b101, false, 3),
            (0b111, true, 2),
            (0b001, true, 3),
            (0b100, false, 2),
        ] {
            assert_eq!(
                chains.evaluate(&[input], &mut out),
                tested,
                "input {input:03b}"
            );
            assert_eq!(out[0], expected, "input {input:03b}");
        }
    }

    #[test]
    fn programs_fuse_leaf_operands_and_order_for_a_shallow_stack() {
        // ((x0 AND x1) OR (x2 AND x3)) AND x4: push x0, and x1, push x2,
        // and x3, pop-or, and x4; two stack slots.
        let tree = Pruned {
            nodes: vec![
                Gate::Leaf(0),
                Gate::Leaf(2),
                Gate::And(0, 1),
                Gate::Leaf(4),
                Gate::Leaf(6),
                Gate::And(3, 4),
                Gate::Or(2, 5),
                Gate::Leaf(8),
                Gate::And(6, 7),
            ],
        };
        let programs = Programs::new([&tree]);
        let ops: Vec<u32> = programs.code.iter().map(|i| i >> LITERAL_BITS).collect();
        assert_eq!(
            ops,
            [PUSH, AND_LITERAL, PUSH, AND_LITERAL, OR_POP, AND_LITERAL]
        );
        assert_eq!(programs.stack, 2);
    }
}
