//! How an ALN learns (paper §3.3): on each sample, walk down from the root
//! marking the *heuristically responsible* nodes, and adapt each of them
//! ([`Tree::adapt`]). [`train_one`] does it for one sample, plainly — the
//! reference; [`train_epochs`] does exactly the same over a training set,
//! fast, with every node's value for every sample kept bit-sliced.

use alnlab_aln::tree::{Function, Tree};
use rand::Rng;
use rand::seq::SliceRandom;

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

/// Reusable buffers for [`train_one`] (no allocation per sample).
#[derive(Default)]
pub struct Scratch {
    values: Vec<bool>,
    stack: Vec<usize>,
}

/// Which children of a responsible node with function `f` and child outputs
/// (`a`, `b`) are responsible too, when the tree should output `desired`.
/// Rule 2: an input unequal to the desired output is an error; rule 3: the
/// child opposite an error is responsible; rule 4: a child whose change would
/// change this node's output is too.
#[inline]
fn responsible_children(f: Function, a: bool, b: bool, desired: bool) -> (bool, bool) {
    let out = f.apply(a, b);
    let left = b != desired || f.apply(!a, b) != out;
    let right = a != desired || f.apply(a, !b) != out;
    (left, right)
}

/// Trains on one sample: evaluates, marks the heuristically responsible
/// nodes by the rules of §3.3, and adapts each one (its (0,1) or (1,0)
/// counter one step toward `desired`, bounded). Returns whether the output
/// was already right.
pub fn train_one(tree: &mut Tree, input: &[u64], desired: bool, scratch: &mut Scratch) -> bool {
    tree.evaluate_all(input, &mut scratch.values);
    let values = &scratch.values;
    let correct = values[0] == desired;
    let internal = tree.internal();
    let stack = &mut scratch.stack;
    stack.clear();
    stack.push(0); // rule 1: the root is responsible
    while let Some(i) = stack.pop() {
        let (left, right) = (2 * i + 1, 2 * i + 2);
        let (a, b) = (values[left], values[right]);
        let (left_responsible, right_responsible) =
            responsible_children(tree.function(i), a, b, desired);
        tree.adapt(i, a, b, desired);
        if left_responsible && left < internal {
            stack.push(left);
        }
        if right_responsible && right < internal {
            stack.push(right);
        }
    }
    correct
}

/// Trains for up to `max_epochs` epochs, until an epoch presents every
/// sample right. Each epoch presents the samples in a fresh random order
/// drawn from `rng`: samples of a trajectory come in runs of similar
/// states, and presented in time order a tree would chase the latest run
/// (right on each sample as it comes, wrong on most of the set at the
/// end) instead of fitting the whole set. Exactly what [`train_one`] on each
/// sample in turn does, but fast: every node's value for every sample is
/// kept bit-sliced, and only when a node's function changes are that
/// node's values and its ancestors' recomputed.
pub fn train_epochs(
    tree: &mut Tree,
    samples: &Samples,
    max_epochs: usize,
    rng: &mut impl Rng,
) -> Vec<EpochLog> {
    let internal = tree.internal();
    let words = samples.words;
    let mut values = vec![0u64; (2 * internal + 1) * words];
    for (j, &literal) in tree.literals().iter().enumerate() {
        let bit = (literal / 2) as usize;
        let flip = if literal & 1 == 1 { u64::MAX } else { 0 };
        let column = &samples.columns[bit * words..(bit + 1) * words];
        for (v, c) in values[(internal + j) * words..].iter_mut().zip(column) {
            *v = c ^ flip;
        }
    }
    for i in (0..internal).rev() {
        recompute(tree, i, words, &mut values);
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
                let (left_responsible, right_responsible) =
                    responsible_children(tree.function(i), a, b, desired);
                let adapted = tree.adapt(i, a, b, desired);
                epoch.updates += usize::from(adapted.moved);
                if adapted.flipped {
                    flipped.push(i);
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
                recompute(tree, i, words, &mut values);
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
fn recompute(tree: &Tree, i: usize, words: usize, values: &mut [u64]) {
    let f = tree.function(i);
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

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_aln::tree::TreeSpec;
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
                .filter(|&x| train_one(&mut tree, &[x], target(x), &mut scratch))
                .count();
            if right == 256 || epochs == 60 {
                break;
            }
        }
        let errors = (0..256u64)
            .filter(|&x| {
                tree.evaluate(&[x], &mut alnlab_aln::tree::Scratch::default()) != target(x)
            })
            .count();
        assert_eq!(errors, 0, "after {epochs} epochs");
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
            let log = train_epochs(
                &mut fast,
                &samples,
                4,
                &mut ChaCha8Rng::seed_from_u64(case as u64),
            );
            // The same orders, drawn from the same seed.
            let mut order_rng = ChaCha8Rng::seed_from_u64(case as u64);
            let mut order: Vec<usize> = (0..n).collect();
            let mut slow = tree.clone();
            let mut scratch = Scratch::default();
            for epoch in &log {
                order.shuffle(&mut order_rng);
                let right = order
                    .iter()
                    .filter(|&&s| train_one(&mut slow, &[inputs[s]], targets[s], &mut scratch))
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
            let log = train_epochs(&mut tree, &samples, 40, &mut rng);
            assert_eq!(log.last().unwrap().errors, 0, "{name}: {log:?}");
        }
    }
}
