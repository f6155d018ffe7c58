//! A piecewise-linear model made ready to predict: per output its tree,
//! compiled over boxes of input space, and how the change it computes
//! becomes the variable's next real value and level. The model reads the
//! current state's real values (the codebook's learned variables, in
//! order); each tree computes its variable's change in level spacings,
//! which is added to the current value (on the circle for an angle that
//! wraps) and quantized by the codebook.
//!
//! Three paths, one number: [`Path::Plain`] evaluates every piece,
//! [`Path::Lazy`] cuts off what cannot answer, [`Path::Compiled`] goes
//! through the [`DecisionTree`]; all agree to the bit (tested on real runs
//! by the test stage). One row at a time, nothing is allocated.

use alnlab_codes::{Entry, Quantizer};

use super::dtree::{self, DecisionTree};
use super::lazy::Lazy;
use super::{Node, Tree};
use crate::model::Reads;

/// How a tree is evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Path {
    /// Every piece, every node.
    Plain,
    /// MIN/MAX with cut-offs, children in the order of the last answer.
    Lazy,
    /// The decision tree over boxes, then the pieces left in the box.
    Compiled,
}

impl Path {
    /// Every path, the fastest last.
    pub const ALL: [Path; 3] = [Path::Plain, Path::Lazy, Path::Compiled];

    /// Its name in timing tables.
    pub fn name(self) -> &'static str {
        match self {
            Path::Plain => "pwl-plain",
            Path::Lazy => "pwl-lazy",
            Path::Compiled => "pwl-compiled",
        }
    }
}

/// One output: its tree compiled, what it reads and how its change
/// becomes a value.
struct Output<'m> {
    tree: &'m Tree,
    compiled: DecisionTree,
    /// The predicted variable's index in the state.
    variable: usize,
    /// The state indices the tree reads, in its input order.
    inputs: Vec<usize>,
    quantizer: Quantizer,
    /// One level spacing in the variable's unit.
    spacing: f64,
    /// Whether the variable is an angle that wraps on the circle.
    wraps: bool,
    /// The pieces' coefficients transposed — the biases, then each input's
    /// weights, piece by piece — for every piece of one row at once.
    by_input: Vec<f64>,
    /// The MIN/MAX nodes as a straight program over one row's values.
    program: Program,
    /// The tree's pieces padded to whole vectors, and one row's slots
    /// ([`Program`]): kept, not derived per row.
    padded: usize,
    slots: usize,
}

/// A tree's MIN and MAX nodes from the leaves up, over a row of slots: the
/// pieces' values first ([`padded_pieces`] of them), then each operation's
/// result in turn. Selecting instead of branching on the node's kind keeps
/// one row's evaluation free of branches the CPU cannot predict.
struct Program {
    /// (first child's slot, second child's slot, MAX?).
    ops: Vec<(u32, u32, bool)>,
    /// The root's slot.
    root: u32,
}

impl Program {
    fn of(tree: &Tree) -> Program {
        let padded = padded_pieces(tree) as u32;
        let nodes = tree.nodes();
        let mut slot = vec![0u32; nodes.len()];
        let mut ops = Vec::new();
        for (j, node) in nodes.iter().enumerate().rev() {
            slot[j] = match *node {
                Node::Piece(p) => p,
                Node::Min(a, b) | Node::Max(a, b) => {
                    ops.push((
                        slot[a as usize],
                        slot[b as usize],
                        matches!(node, Node::Max(..)),
                    ));
                    padded + ops.len() as u32 - 1
                }
            };
        }
        Program { ops, root: slot[0] }
    }

    /// Slots a row needs: the padded pieces and every result.
    fn slots(&self, tree: &Tree) -> usize {
        padded_pieces(tree) + self.ops.len()
    }

    /// The root's value, the pieces' values in `slots` already; ties to the
    /// first child as [`Tree::value`].
    #[inline(always)]
    fn run(&self, slots: &mut [f64], padded: usize) -> f64 {
        for (k, &(a, b, max)) in self.ops.iter().enumerate() {
            let (x, y) = (slots[a as usize], slots[b as usize]);
            let take = if max { y > x } else { y < x };
            slots[padded + k] = if take { y } else { x };
        }
        slots[self.root as usize]
    }
}

/// A piecewise-linear model made ready to predict.
pub struct Predictor<'m> {
    outputs: Vec<Output<'m>>,
    /// Inputs per state: the codebook's learned variables (and, for a
    /// hybrid, their nominal predictions after them).
    width: usize,
    /// The most inputs any tree reads (the size of the row buffer).
    most_inputs: usize,
    /// The vector instructions this CPU has.
    vectors: Vectors,
}

/// What prediction reuses: each tree's lazy evaluator (its child order), a
/// buffer of one tree's inputs, and a block's inputs and node values for
/// batches. Made once per thread.
pub struct Scratch<'m> {
    lazy: Vec<Lazy<'m>>,
    row: Vec<f64>,
    /// One row's slots: piece values, then node values ([`Program`]).
    pieces: Vec<f64>,
    block_inputs: Vec<f64>,
    block_nodes: Vec<f64>,
    /// One state's change per output.
    changes: Vec<f64>,
}

/// Rows a batch evaluates together: each piece's value for all of them in
/// one loop the compiler turns into vector instructions.
const BLOCK: usize = 32;

impl<'m> Predictor<'m> {
    /// Prepares `trees` (a model's, whose outputs read and predict
    /// `reads`, indices among `learned`: the entries of its inputs — the
    /// codebook's learned ones, then for a hybrid the same again for their
    /// nominal predictions), compiling each over the box of `points`:
    /// states, `learned.len()` real values a row (the training rows; where
    /// the cuts fall decides speed, never a value).
    pub fn new(
        trees: &'m [Tree],
        reads: &[Reads],
        learned: &[&Entry],
        points: &[f64],
    ) -> Predictor<'m> {
        let width = learned.len();
        let rows = points.len().checked_div(width).unwrap_or(0);
        let outputs: Vec<Output> = trees
            .iter()
            .zip(reads)
            .map(|(tree, r)| {
                let own: Vec<f64> = (0..rows)
                    .flat_map(|row| r.inputs.iter().map(move |&i| points[row * width + i]))
                    .collect();
                let entry = learned[r.variable];
                let q = entry.quantizer;
                let padded = padded_pieces(tree);
                let mut by_input = vec![0.0; padded * (r.inputs.len() + 1)];
                for p in 0..tree.pieces() {
                    let (bias, weights) = tree.piece(p);
                    for (i, &c) in std::iter::once(&bias).chain(weights).enumerate() {
                        by_input[i * padded + p] = c;
                    }
                }
                let program = Program::of(tree);
                Output {
                    tree,
                    by_input,
                    slots: program.slots(tree),
                    padded,
                    program,
                    compiled: DecisionTree::build(tree, &own, dtree::Settings::default()),
                    variable: r.variable,
                    inputs: r.inputs.clone(),
                    quantizer: q,
                    spacing: (q.max - q.min) / (q.levels - 1) as f64,
                    wraps: entry.period().is_some(),
                }
            })
            .collect();
        let most_inputs = outputs.iter().map(|o| o.inputs.len()).max().unwrap_or(0);
        Predictor {
            outputs,
            width,
            most_inputs,
            vectors: wide_vectors(),
        }
    }

    /// The buffers one-row prediction reuses.
    pub fn scratch(&self) -> Scratch<'m> {
        let most_nodes = self.outputs.iter().map(|o| o.tree.nodes().len()).max();
        Scratch {
            lazy: self.outputs.iter().map(|o| Lazy::new(o.tree)).collect(),
            row: vec![0.0; self.most_inputs],
            pieces: vec![0.0; self.outputs.iter().map(|o| o.slots).max().unwrap_or(0)],
            block_inputs: vec![0.0; self.most_inputs * BLOCK],
            block_nodes: vec![0.0; most_nodes.unwrap_or(0) * BLOCK],
            changes: vec![0.0; self.outputs.len()],
        }
    }

    /// Values per state.
    pub fn width(&self) -> usize {
        self.width
    }

    /// The predicted variables' indices in the state, in output order.
    pub fn variables(&self) -> impl Iterator<Item = usize> + '_ {
        self.outputs.iter().map(|o| o.variable)
    }

    /// Per output, the boxes its decision tree has and the mean number of
    /// pieces left in one.
    pub fn shapes(&self) -> Vec<(usize, f64)> {
        self.outputs.iter().map(|o| o.compiled.shape()).collect()
    }

    /// Output `o`'s change for `state`, in level spacings.
    fn change(&self, o: usize, state: &[f64], path: Path, scratch: &mut Scratch<'m>) -> f64 {
        let out = &self.outputs[o];
        let row = &mut scratch.row[..out.inputs.len()];
        for (slot, &i) in row.iter_mut().zip(&out.inputs) {
            *slot = state[i];
        }
        match path {
            Path::Plain => {
                let wide = self.vectors;
                row_value(out, row, wide, &mut scratch.pieces)
            }
            Path::Lazy => scratch.lazy[o].value(row),
            Path::Compiled => out.compiled.value(out.tree, row, &mut scratch.lazy[o]),
        }
    }

    /// The next real value of every output for one state (`width()`
    /// values), into `next` (one value per output).
    pub fn next_values(
        &self,
        state: &[f64],
        path: Path,
        scratch: &mut Scratch<'m>,
        next: &mut [f64],
    ) {
        self.next_values_from(state, state, path, scratch, next);
    }

    /// [`Predictor::next_values`] with each output advanced from its value
    /// in `base` (a value per learned variable) instead of `state`: a correction
    /// learned on top of another model's prediction `base` (a hybrid).
    pub fn next_values_from(
        &self,
        state: &[f64],
        base: &[f64],
        path: Path,
        scratch: &mut Scratch<'m>,
        next: &mut [f64],
    ) {
        for (o, value) in next.iter_mut().enumerate() {
            let change = self.change(o, state, path, scratch);
            *value = self.outputs[o].advance(base, change);
        }
    }

    /// The next level of every output for one state, into `levels`.
    pub fn next_levels(
        &self,
        state: &[f64],
        path: Path,
        scratch: &mut Scratch<'m>,
        levels: &mut [u16],
    ) {
        self.next_levels_from(state, state, path, scratch, levels);
    }

    /// [`Predictor::next_levels`] with each output advanced from its value
    /// in `base`, as [`Predictor::next_values_from`].
    pub fn next_levels_from(
        &self,
        state: &[f64],
        base: &[f64],
        path: Path,
        scratch: &mut Scratch<'m>,
        levels: &mut [u16],
    ) {
        if path == Path::Plain {
            return self.plain_levels(state, base, scratch, levels);
        }
        for (o, level) in levels.iter_mut().enumerate() {
            let change = self.change(o, state, path, scratch);
            let out = &self.outputs[o];
            *level = out.quantizer.level(out.advance(base, change)).0;
        }
    }

    /// [`Predictor::next_levels`] by the plain path, the whole state
    /// compiled for the widest vectors the CPU has.
    fn plain_levels(
        &self,
        state: &[f64],
        base: &[f64],
        scratch: &mut Scratch<'m>,
        levels: &mut [u16],
    ) {
        #[cfg(target_arch = "x86_64")]
        match self.vectors {
            // SAFETY: `wide_vectors` found the CPU's features.
            Vectors::Avx512 => {
                return unsafe { self.plain_levels_avx512(state, base, scratch, levels) };
            }
            Vectors::Avx2 => {
                return unsafe { self.plain_levels_avx2(state, base, scratch, levels) };
            }
            Vectors::Sse => {}
        }
        self.plain_levels_portable(state, base, scratch, levels);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn plain_levels_avx512(
        &self,
        state: &[f64],
        base: &[f64],
        scratch: &mut Scratch<'m>,
        levels: &mut [u16],
    ) {
        self.plain_levels_portable(state, base, scratch, levels);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn plain_levels_avx2(
        &self,
        state: &[f64],
        base: &[f64],
        scratch: &mut Scratch<'m>,
        levels: &mut [u16],
    ) {
        self.plain_levels_portable(state, base, scratch, levels);
    }

    /// Every tree's change first, then every variable advanced and
    /// quantized: kept apart, the quantizers' divisions are independent of
    /// one another and overlap instead of each waiting at the end of its
    /// tree's chain of selects.
    #[inline(always)]
    fn plain_levels_portable(
        &self,
        state: &[f64],
        base: &[f64],
        scratch: &mut Scratch<'m>,
        levels: &mut [u16],
    ) {
        for (out, change) in self.outputs.iter().zip(&mut scratch.changes) {
            let row = &mut scratch.row[..out.inputs.len()];
            for (slot, &i) in row.iter_mut().zip(&out.inputs) {
                *slot = state[i];
            }
            let padded = out.padded;
            let slots = &mut scratch.pieces[..out.slots];
            pieces_of_row_portable(&out.by_input, row, &mut slots[..padded]);
            *change = out.program.run(slots, padded);
        }
        for ((out, &change), level) in self.outputs.iter().zip(&scratch.changes).zip(levels) {
            *level = out.quantizer.level(out.advance(base, change)).0;
        }
    }

    /// The next levels `[output][row]` of the states whose values are
    /// `columns` (`[variable][row]`, the learned variables), tree by tree
    /// (each tree's pieces stay in cache), [`BLOCK`] rows at once: every
    /// piece's value for the block in one vectorized loop, summed in
    /// [`Tree::piece_value`]'s order, then the MIN/MAX nodes from the
    /// leaves up — the plain evaluation's numbers.
    pub fn levels(&self, columns: &[&[f64]], scratch: &mut Scratch<'m>) -> Vec<Vec<u16>> {
        self.levels_from(columns, columns, scratch)
    }

    /// [`Predictor::levels`] with each output advanced from its values in
    /// `base` (`[variable][row]`, as `columns`) instead of `columns`: a
    /// correction learned on top of another model's prediction `base` (a
    /// hybrid).
    pub fn levels_from(
        &self,
        columns: &[&[f64]],
        base: &[&[f64]],
        scratch: &mut Scratch<'m>,
    ) -> Vec<Vec<u16>> {
        let rows = columns.first().map_or(0, |c| c.len());
        let wide = self.vectors;
        (0..self.outputs.len())
            .map(|o| {
                let out = &self.outputs[o];
                let current = base[out.variable];
                let mut levels = Vec::with_capacity(rows);
                for start in (0..rows).step_by(BLOCK) {
                    let block = BLOCK.min(rows - start);
                    let values = self.block_values(o, columns, start, block, wide, scratch);
                    // Whole blocks of plain arithmetic, which vectorizes.
                    let mut next = [0.0f64; BLOCK];
                    for ((n, &x), &change) in next.iter_mut().zip(&current[start..]).zip(values) {
                        *n = out.advance_from(x, change);
                    }
                    let mut level = [0u16; BLOCK];
                    for (l, &n) in level.iter_mut().zip(&next) {
                        *l = out.quantizer.level(n).0;
                    }
                    levels.extend_from_slice(&level[..block]);
                }
                levels
            })
            .collect()
    }

    /// The next real values of the states whose values are `columns`
    /// (`[variable][row]`, the learned variables), into `next`
    /// (`[output][row]`, each as long as a column): [`Predictor::levels`]'
    /// batched evaluation, not quantized, nothing allocated — for a planner
    /// that advances every candidate of a decision together.
    pub fn values(&self, columns: &[&[f64]], scratch: &mut Scratch<'m>, next: &mut [Vec<f64>]) {
        self.values_from(columns, columns, scratch, next);
    }

    /// [`Predictor::values`] with each output advanced from its value in
    /// `base` (a column per learned variable) instead of `columns`: a
    /// correction on another model's predictions, as
    /// [`Predictor::next_values_from`] for one state.
    pub fn values_from(
        &self,
        columns: &[&[f64]],
        base: &[&[f64]],
        scratch: &mut Scratch<'m>,
        next: &mut [Vec<f64>],
    ) {
        let rows = columns.first().map_or(0, |c| c.len());
        let wide = self.vectors;
        for (o, next) in next.iter_mut().enumerate().take(self.outputs.len()) {
            let out = &self.outputs[o];
            let current = base[out.variable];
            for start in (0..rows).step_by(BLOCK) {
                let block = BLOCK.min(rows - start);
                let values = self.block_values(o, columns, start, block, wide, scratch);
                for ((n, &x), &change) in next[start..start + block]
                    .iter_mut()
                    .zip(&current[start..])
                    .zip(values)
                {
                    *n = out.advance_from(x, change);
                }
            }
        }
    }

    /// Output `o`'s change for the `rows` states from `start` of `columns`
    /// (at most [`BLOCK`]): the root's values among the scratch's node
    /// values. A whole block reads the columns in place; a part is copied
    /// into the scratch, padded.
    fn block_values<'s>(
        &self,
        o: usize,
        columns: &[&[f64]],
        start: usize,
        rows: usize,
        wide: Vectors,
        scratch: &'s mut Scratch<'m>,
    ) -> &'s [f64] {
        let out = &self.outputs[o];
        let tree = out.tree;
        // Each input's values for the block: in place for a whole block, a
        // part block copied into the scratch and padded with what was there.
        let padded = &mut scratch.block_inputs;
        if rows < BLOCK {
            for (i, &v) in out.inputs.iter().enumerate() {
                padded[i * BLOCK..i * BLOCK + rows]
                    .copy_from_slice(&columns[v][start..start + rows]);
            }
        }
        let padded = &*padded;
        let inputs = |i: usize| -> &[f64] {
            if rows < BLOCK {
                &padded[i * BLOCK..(i + 1) * BLOCK]
            } else {
                &columns[out.inputs[i]][start..start + BLOCK]
            }
        };
        let nodes = &mut scratch.block_nodes;
        for (j, node) in tree.nodes().iter().enumerate().rev() {
            // Children come after their parent: their values are in `tail`.
            let (head, tail) = nodes.split_at_mut((j + 1) * BLOCK);
            let value = &mut head[j * BLOCK..];
            let child = |c: u32| &tail[(c as usize - j - 1) * BLOCK..][..BLOCK];
            match *node {
                Node::Piece(p) => {
                    let (bias, weights) = tree.piece(p as usize);
                    piece_block(bias, weights, &inputs, &mut value[..BLOCK], wide);
                }
                // The ties of `Tree::value`: the first child's value.
                Node::Min(a, b) => {
                    for ((v, &x), &y) in value.iter_mut().zip(child(a)).zip(child(b)) {
                        *v = if y < x { y } else { x };
                    }
                }
                Node::Max(a, b) => {
                    for ((v, &x), &y) in value.iter_mut().zip(child(a)).zip(child(b)) {
                        *v = if y > x { y } else { x };
                    }
                }
            }
        }
        &nodes[..rows]
    }
}

/// One row's value of `out`'s tree, every piece evaluated: all pieces at
/// once (each summed in [`Tree::piece_value`]'s order, pieces side by side
/// in vector registers), then the MIN/MAX nodes from the leaves up, ties
/// to the first child as [`Tree::value`].
fn row_value(out: &Output, row: &[f64], wide: Vectors, slots: &mut [f64]) -> f64 {
    let padded = out.padded;
    let slots = &mut slots[..out.slots];
    pieces_of_row(&out.by_input, row, &mut slots[..padded], wide);
    out.program.run(slots, padded)
}

/// A tree's pieces rounded up to whole vectors of 8 (the padding pieces
/// are zero and never read), so that one row's loop over pieces has no
/// remainder.
fn padded_pieces(tree: &Tree) -> usize {
    tree.pieces().div_ceil(8) * 8
}

/// Every piece's value at `row`: `by_input` holds the biases, then each
/// input's weights, piece by piece ([`padded_pieces`] of them).
fn pieces_of_row(by_input: &[f64], row: &[f64], values: &mut [f64], wide: Vectors) {
    #[cfg(target_arch = "x86_64")]
    match wide {
        // SAFETY: `wide_vectors` found the CPU's features.
        Vectors::Avx512 => return unsafe { pieces_of_row_avx512(by_input, row, values) },
        Vectors::Avx2 => return unsafe { pieces_of_row_avx2(by_input, row, values) },
        Vectors::Sse => {}
    }
    let _ = wide;
    pieces_of_row_portable(by_input, row, values);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn pieces_of_row_avx2(by_input: &[f64], row: &[f64], values: &mut [f64]) {
    pieces_of_row_portable(by_input, row, values);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn pieces_of_row_avx512(by_input: &[f64], row: &[f64], values: &mut [f64]) {
    pieces_of_row_portable(by_input, row, values);
}

#[inline(always)]
fn pieces_of_row_portable(by_input: &[f64], row: &[f64], values: &mut [f64]) {
    let padded = values.len();
    for (chunk, out) in values.chunks_exact_mut(8).enumerate() {
        let column = |i: usize| -> &[f64; 8] {
            by_input[i * padded + chunk * 8..][..8]
                .try_into()
                .expect("8 values")
        };
        let mut sum = *column(0);
        for (i, &x) in row.iter().enumerate() {
            for (s, &w) in sum.iter_mut().zip(column(i + 1)) {
                *s += w * x;
            }
        }
        out.copy_from_slice(&sum);
    }
}

/// The widest vector instructions this CPU has: the same additions and
/// multiplications, two, four (AVX2) or eight (AVX-512) numbers at a time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Vectors {
    Sse,
    Avx2,
    Avx512,
}

fn wide_vectors() -> Vectors {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            return Vectors::Avx512;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            return Vectors::Avx2;
        }
    }
    Vectors::Sse
}

/// A piece's value for every row of a block (`inputs(i)`: input i's
/// [`BLOCK`] values; rows past a part block's end are computed and
/// ignored): bias + Σ wᵢxᵢ in input order, as [`Tree::piece_value`] sums,
/// rows side by side in registers — with the `wide` vectors (IEEE
/// additions and multiplications either way, never fused: the same
/// numbers).
fn piece_block<'x>(
    bias: f64,
    weights: &[f64],
    inputs: &impl Fn(usize) -> &'x [f64],
    value: &mut [f64],
    wide: Vectors,
) {
    #[cfg(target_arch = "x86_64")]
    match wide {
        // SAFETY: `wide_vectors` found the CPU's features.
        Vectors::Avx512 => return unsafe { piece_block_avx512(bias, weights, inputs, value) },
        Vectors::Avx2 => return unsafe { piece_block_avx2(bias, weights, inputs, value) },
        Vectors::Sse => {}
    }
    let _ = wide;
    piece_block_lanes::<8>(bias, weights, inputs, value);
}

/// [`piece_block`] compiled for AVX2: 32 rows in eight registers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn piece_block_avx2<'x>(
    bias: f64,
    weights: &[f64],
    inputs: &impl Fn(usize) -> &'x [f64],
    value: &mut [f64],
) {
    piece_block_lanes::<BLOCK>(bias, weights, inputs, value);
}

/// [`piece_block`] compiled for AVX-512: 32 rows in four registers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn piece_block_avx512<'x>(
    bias: f64,
    weights: &[f64],
    inputs: &impl Fn(usize) -> &'x [f64],
    value: &mut [f64],
) {
    piece_block_lanes::<BLOCK>(bias, weights, inputs, value);
}

/// [`piece_block`], `LANES` rows at a time (`LANES` divides [`BLOCK`]).
#[inline(always)]
fn piece_block_lanes<'x, const LANES: usize>(
    bias: f64,
    weights: &[f64],
    inputs: &impl Fn(usize) -> &'x [f64],
    value: &mut [f64],
) {
    for (lane, out) in value.chunks_exact_mut(LANES).enumerate() {
        let mut sum = [bias; LANES];
        for (i, &w) in weights.iter().enumerate() {
            let x: &[f64; LANES] = inputs(i)[lane * LANES..][..LANES]
                .try_into()
                .expect("LANES values");
            for (s, &x) in sum.iter_mut().zip(x) {
                *s += w * x;
            }
        }
        out.copy_from_slice(&sum);
    }
}

impl Output<'_> {
    /// The variable's next value: its current one plus `change` spacings,
    /// an angle that wraps brought back onto the circle from its range's
    /// start.
    fn advance(&self, state: &[f64], change: f64) -> f64 {
        self.advance_from(state[self.variable], change)
    }

    /// [`Output::advance`] from the variable's current value `current`.
    fn advance_from(&self, current: f64, change: f64) -> f64 {
        let start = self.wraps.then_some(self.quantizer.min);
        step(current, change, self.spacing, start)
    }
}

/// `current` moved by `change` level spacings of `spacing`, brought back
/// onto the circle from `wrap_start` when the variable wraps.
#[inline]
fn step(current: f64, change: f64, spacing: f64, wrap_start: Option<f64>) -> f64 {
    let next = current + change * spacing;
    let Some(start) = wrap_start else {
        return next;
    };
    let (d, tau) = (next - start, std::f64::consts::TAU);
    // rem_euclid's value without its division where d is within a turn of
    // the range (exact either way: Sterbenz).
    let turned = if (0.0..tau).contains(&d) {
        d
    } else if (tau..2.0 * tau).contains(&d) {
        d - tau
    } else if (-tau..0.0).contains(&d) {
        d + tau
    } else {
        d.rem_euclid(tau)
    };
    turned + start
}

/// A variable of `entry` at `current` moved by `change` level spacings (on
/// the circle for an angle that wraps): the inverse of [`change`], as every
/// model that predicts a change advances its variable.
pub fn advance(entry: &Entry, current: f64, change: f64) -> f64 {
    let q = &entry.quantizer;
    let spacing = (q.max - q.min) / (q.levels - 1) as f64;
    step(current, change, spacing, entry.period().map(|_| q.min))
}

/// The change from `x` to `y` in level spacings of `entry`, on the circle
/// for an angle that wraps: what a piecewise-linear tree learns, the
/// inverse of how its output advances the variable.
pub fn change(entry: &Entry, x: f64, y: f64) -> f64 {
    let q = &entry.quantizer;
    let spacing = (q.max - q.min) / (q.levels - 1) as f64;
    let mut d = y - x;
    if entry.period().is_some() {
        let pi = std::f64::consts::PI;
        d = (d + pi).rem_euclid(std::f64::consts::TAU) - pi;
    }
    d / spacing
}

/// Rows `rows` of `columns` (`[variable][row]`) as states, one after
/// another: the layout [`Predictor`] reads.
pub fn states(columns: &[Vec<f64>], rows: &[usize]) -> Vec<f64> {
    rows.iter()
        .flat_map(|&r| columns.iter().map(move |c| c[r]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pwl::lazy::tests::random_tree;

    fn entry(variable: &str, min: f64, max: f64) -> Entry {
        crate::output::tests::entry_of(variable, min, max, 101)
    }

    #[test]
    fn every_path_and_the_blocked_batch_give_the_same_levels_and_values() {
        let tau = std::f64::consts::TAU;
        let (a, roll) = (
            entry("a.1.x", -4.0, 4.0),
            entry("roll.2", -tau / 2.0, tau / 2.0),
        );
        let learned = [&a, &roll];
        let trees = [random_tree(2, 24, 5), random_tree(1, 9, 6)];
        let reads = [
            Reads {
                variable: 0,
                inputs: vec![0, 1],
            },
            Reads {
                variable: 1,
                inputs: vec![1],
            },
        ];
        // 77 states (two blocks and a part), some outside the compiled box.
        let states: Vec<f64> = (0..154)
            .map(|i| ((i as f64 * 0.618_033_988_7).fract() * 2.0 - 1.0) * 3.0)
            .collect();
        let predictor = Predictor::new(&trees, &reads, &learned, &states[..100]);
        let mut scratch = predictor.scratch();
        let columns: Vec<Vec<f64>> = (0..2)
            .map(|v| states.chunks_exact(2).map(|s| s[v]).collect())
            .collect();
        let columns: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        let batch = predictor.levels(&columns, &mut scratch);
        let mut next = [0u16; 2];
        for path in Path::ALL {
            for (r, state) in states.chunks_exact(2).enumerate() {
                predictor.next_levels(state, path, &mut scratch, &mut next);
                assert_eq!(next, [batch[0][r], batch[1][r]], "{path:?}, row {r}");
            }
        }
        // The batched real values are the plain path's, number for number.
        let mut values = vec![vec![0.0; 77]; 2];
        predictor.values(&columns, &mut scratch, &mut values);
        let mut next = [0.0; 2];
        for (r, state) in states.chunks_exact(2).enumerate() {
            predictor.next_values(state, Path::Plain, &mut scratch, &mut next);
            assert_eq!(next, [values[0][r], values[1][r]], "row {r}");
        }
    }

    #[test]
    fn a_change_goes_the_short_way_round_and_advances_back() {
        let tau = std::f64::consts::TAU;
        let roll = entry("roll.2", -tau / 2.0, tau / 2.0);
        let spacing = tau / 100.0;
        let across = change(&roll, 3.1, -3.1);
        assert!((across - (tau - 6.2) / spacing).abs() < 1e-9, "{across}");
        let tree = [Tree::affine(across, &[0.0])];
        let reads = [Reads {
            variable: 0,
            inputs: vec![0],
        }];
        let predictor = Predictor::new(&tree, &reads, &[&roll], &[3.1]);
        let mut next = [0.0];
        predictor.next_values(&[3.1], Path::Plain, &mut predictor.scratch(), &mut next);
        assert!((next[0] + 3.1).abs() < 1e-9, "{}", next[0]);
        let plain = entry("a.1.x", -4.0, 4.0);
        assert!((change(&plain, 3.1, -3.1) + 6.2 / 0.08).abs() < 1e-9);
    }

    #[test]
    fn a_hybrid_advances_from_its_base_on_both_paths() {
        // A constant change of 2 spacings (0.08 each) from a base 1.0 above
        // the state: the state decides nothing but the change.
        let a = entry("a.1.x", -4.0, 4.0);
        let tree = [Tree::affine(2.0, &[0.0])];
        let reads = [Reads {
            variable: 0,
            inputs: vec![0],
        }];
        let states = [-1.0, 0.0, 0.5];
        let base: Vec<f64> = states.iter().map(|x| x + 1.0).collect();
        let predictor = Predictor::new(&tree, &reads, &[&a], &states);
        let mut scratch = predictor.scratch();
        let batch = predictor.levels_from(&[&states], &[&base], &mut scratch);
        let mut next = [0.0];
        for (r, (&x, &b)) in states.iter().zip(&base).enumerate() {
            predictor.next_values_from(&[x], &[b], Path::Plain, &mut scratch, &mut next);
            assert!((next[0] - (b + 0.16)).abs() < 1e-12, "row {r}: {}", next[0]);
            assert_eq!(batch[0][r], a.quantizer.level(next[0]).0, "row {r}");
        }
        assert_ne!(batch, predictor.levels(&[&states], &mut scratch));
    }
}
