//! A piecewise-linear model in fixed point: the integers a circuit computes
//! with, and the reference its hardware must equal bit for bit.
//!
//! Each output reads its inputs as signed words: a variable's value in its
//! own level coordinate, t = (x − min) / spacing (level k stands for t = k),
//! times 2^`frac`, rounded and saturated to `input_bits` — what a sensor
//! would hand the circuit. Written in that coordinate a piece's weights are
//! the changes (in the output's level spacings) per level spacing of an
//! input: w′ = w · spacing. Each weight becomes an integer at one scale per
//! tree, 2^`weight_frac` (the largest weight's full `weight_bits` and
//! [`GUARD_BITS`] more), rounded to `weight_bits` significant signed bits —
//! in shifts and adds a weight costs its significant digits, not its
//! position, and a tree's weights span four orders of magnitude — and the
//! bias to the products' scale 2^(frac + weight_frac), so that a piece is
//! B + Σ Wᵢ·Uᵢ, exact in integers. The MIN/MAX tree compares these sums
//! (ties to the first child, as [`super::Tree::value`]); the answer, a
//! change at that scale, is added to the current value's word, an angle
//! that wraps is brought back onto the circle once, and the sum rounded
//! half up to a level and clamped to the codebook's levels.
//!
//! Every sum's width follows from the word widths by interval arithmetic
//! over every input a word can hold, so no sum overflows on any input: the
//! evaluator below and the circuit agree on every row, not only on the
//! rows seen. The widths themselves are chosen on training rows
//! ([`choose`]): per output the narrowest inputs, then the narrowest
//! weights, whose levels differ from the floating-point model's by at most
//! a tolerance on average — which bounds the change of error the same.

use alnlab_codes::Entry;

use super::{Node, Tree};
use crate::model::Reads;

/// One output's word widths: its inputs' (sign, integer and fractional
/// bits) and its weights' significant bits (sign and the rest).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Widths {
    pub input_bits: u32,
    pub weight_bits: u32,
}

/// The widest sum an output may need: evaluation is in 64-bit integers.
pub const MAX_SUM_BITS: u32 = 62;
/// The widest input word.
pub const MAX_INPUT_BITS: u32 = 40;
/// The most fractional bits a weight takes (an output whose weights are
/// all zero would otherwise take any number).
pub const MAX_WEIGHT_FRAC: u32 = 32;
/// Fractional bits a product keeps below an input word's own: finer
/// ones are dropped as it is summed (shifts and adds as wide as they need
/// to be).
pub const SUM_GUARD_BITS: u32 = 3;
/// How much finer than the largest weight's the weights' scale is: a
/// weight 2^GUARD_BITS times smaller than a tree's largest still keeps all
/// its significant bits.
pub const GUARD_BITS: u32 = 12;
/// The widest weights [`choose`] tries.
pub const MAX_WEIGHT_BITS: u32 = 20;
/// The most fractional input bits [`choose`] tries.
pub const MAX_INPUT_FRAC: u32 = 16;

/// One output in fixed point.
#[derive(Clone, Debug, PartialEq)]
pub struct FixedOutput {
    /// The predicted variable's index among the learned ones.
    pub variable: usize,
    /// The variables it reads (indices among the learned ones), in the
    /// tree's input order.
    pub inputs: Vec<usize>,
    pub widths: Widths,
    /// Integer bits of an input word (beside its sign): the training rows'
    /// level coordinates lie in [−2^int, 2^int).
    pub input_int: u32,
    /// Fractional bits of an input word.
    pub input_frac: u32,
    /// Fractional bits of the weights' scale.
    pub weight_frac: u32,
    /// Fractional bits every product drops: a piece's value has
    /// `input_frac + weight_frac − dropped`.
    pub dropped: u32,
    /// Per piece its bias (at scale 2^(input_frac + weight_frac)) then its
    /// weights (at 2^weight_frac), as the tree's pieces.
    pub coefficients: Vec<i64>,
    /// The tree's nodes (root first), pieces indexing `coefficients`.
    pub nodes: Vec<Node>,
    /// The codebook's levels of the variable.
    pub levels: u32,
    /// For an angle that wraps, a turn at the sum's scale.
    pub turn: Option<i64>,
    /// Bits of every piece's value (signed), from the words' ranges.
    pub piece_bits: u32,
    /// Bits of the advanced value before rounding (signed).
    pub sum_bits: u32,
    /// Per input variable, the value its words count from (its origin
    /// level's) and its spacing.
    scales: Vec<(f64, f64)>,
    /// The predicted variable's own.
    own: (f64, f64),
    /// The predicted variable's origin level.
    own_origin: i64,
}

/// `v` rounded to an integer of at most `bits` significant signed bits:
/// a mantissa of `bits` bits, shifted.
/// `v` must be below 2^62 in magnitude ([`FixedOutput::new`] checks).
fn significant(v: f64, bits: u32) -> i64 {
    let top = ((1i64 << (bits - 1)) - 1) as f64;
    let mut shift = 0;
    while shift < 62 && (v / (1u64 << shift) as f64).round().abs() > top {
        shift += 1;
    }
    ((v / (1u64 << shift) as f64).round() as i64) << shift
}

/// The least and greatest of [`product`]`(w, x, dropped)` over words `x`
/// in [lo, hi]: each signed digit's shifted copy is monotone in `x`, their
/// sum need not be (floored copies can move against the weight's sign),
/// so each digit is bounded at the word's ends apart.
fn product_bounds(w: i64, (lo, hi): (i64, i64), dropped: u32) -> (i128, i128) {
    signed_digits(w)
        .into_iter()
        .fold((0, 0), |(least, most), (k, negative)| {
            let by = k as i32 - dropped as i32;
            let term = |x: i64| -> i128 {
                if by >= 0 {
                    i128::from(x) << by
                } else {
                    i128::from(x >> (-by).min(63))
                }
            };
            let (a, b) = (term(lo), term(hi));
            if negative {
                (least - b, most - a)
            } else {
                (least + a, most + b)
            }
        })
}

/// Signed digits of `w` (least significant first: the bit and whether it
/// is subtracted), no two adjacent: the fewest shifted copies of a word
/// whose sum or difference is its product with `w`.
pub fn signed_digits(w: i64) -> Vec<(u32, bool)> {
    let mut digits = Vec::new();
    let mut w = i128::from(w);
    let mut k = 0;
    while w != 0 {
        if w & 1 == 1 {
            // +1 when the next bit is 0; −1, carrying, when it is 1.
            let negative = w & 2 == 2;
            digits.push((k, negative));
            w += if negative { 1 } else { -1 };
        }
        w >>= 1;
        k += 1;
    }
    digits
}

/// The product of a weight `w` and a word `x` as shifts and adds compute
/// it with `dropped` fractional bits fewer: each signed digit's shifted
/// copy of `x`, shifted down by `dropped` (floored), added or subtracted.
pub fn product(w: i64, x: i64, dropped: u32) -> i64 {
    signed_digits(w).into_iter().fold(0, |sum, (k, negative)| {
        let term = shifted(x, k as i32 - dropped as i32);
        if negative { sum - term } else { sum + term }
    })
}

/// `x` · 2^`by`, floored when `by` is negative (an arithmetic shift).
pub fn shifted(x: i64, by: i32) -> i64 {
    if by >= 0 { x << by } else { x >> (-by).min(63) }
}

/// Bits of a signed word holding every value in [lo, hi].
fn signed_bits(lo: i128, hi: i128) -> u32 {
    let magnitude = hi.max(-lo - 1).max(0) as u128;
    129 - magnitude.leading_zeros()
}

/// Smallest k ≥ 0 with every value of `t` in [−2^k, 2^k).
fn integer_bits(t: impl Iterator<Item = f64>) -> u32 {
    let (lo, hi) = t.fold((0.0f64, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let mut k = 0;
    while k < 62 && !(-((1u64 << k) as f64) <= lo && hi < (1u64 << k) as f64) {
        k += 1;
    }
    k
}

/// A variable's level coordinate counted from its level `origin`: the
/// value of that level and the spacing.
fn scale_of(entry: &Entry, origin: i64) -> (f64, f64) {
    let q = &entry.quantizer;
    let spacing = (q.max - q.min) / (q.levels - 1) as f64;
    (q.min + spacing * origin as f64, spacing)
}

/// Per learned variable, the level its words count from: the middle of its
/// training rows' levels, rounded — centred words keep every product of a
/// weight and a word small, and so its rounding error.
pub fn origins(learned: &[&Entry], train: &[&[f64]]) -> Vec<i64> {
    learned
        .iter()
        .zip(train)
        .map(|(entry, column)| {
            let (min, spacing) = scale_of(entry, 0);
            let (lo, hi) = column
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    let t = (x - min) / spacing;
                    (lo.min(t), hi.max(t))
                });
            if lo.is_finite() {
                ((lo + hi) / 2.0).round() as i64
            } else {
                0
            }
        })
        .collect()
}

impl FixedOutput {
    /// `tree` (reading `reads`, indices among `learned`) at `widths`, the
    /// words counting from the levels `origins` (one per learned
    /// variable), their integer part `input_int` bits: an error says which
    /// width cannot hold what.
    pub fn new(
        tree: &Tree,
        reads: &Reads,
        learned: &[&Entry],
        origins: &[i64],
        input_int: u32,
        widths: Widths,
    ) -> Result<FixedOutput, String> {
        let Widths {
            input_bits,
            weight_bits,
        } = widths;
        if let Some(&i) = reads.inputs.iter().find(|&&i| i >= learned.len()) {
            return Err(format!(
                "reads input {i}, not a learned variable: a hybrid's nominal prediction has no \
                 circuit"
            ));
        }
        if input_bits > MAX_INPUT_BITS {
            return Err(format!(
                "input_bits = {input_bits}: an input word takes at most {MAX_INPUT_BITS} bits"
            ));
        }
        if input_bits < input_int + 1 {
            return Err(format!(
                "input_bits = {input_bits} cannot hold the training rows' levels of `{}`'s \
                 inputs: they need {} integer bits and a sign, at least {} bits",
                learned[reads.variable].variable,
                input_int,
                input_int + 1
            ));
        }
        if !(2..=32).contains(&weight_bits) {
            return Err(format!(
                "weight_bits = {weight_bits}: a signed weight takes from 2 to 32 bits"
            ));
        }
        let input_frac = input_bits - 1 - input_int;
        let scales: Vec<(f64, f64)> = reads
            .inputs
            .iter()
            .map(|&i| scale_of(learned[i], origins[i]))
            .collect();
        let own_origin = origins[reads.variable];
        let own = scale_of(learned[reads.variable], own_origin);
        // Each piece's bias and weights in the level coordinate.
        let pieces: Vec<(f64, Vec<f64>)> = (0..tree.pieces())
            .map(|p| {
                let (bias, weights) = tree.piece(p);
                let shifted = bias
                    + weights
                        .iter()
                        .zip(&scales)
                        .map(|(w, (min, _))| w * min)
                        .sum::<f64>();
                let scaled = weights.iter().zip(&scales).map(|(w, (_, s))| w * s);
                (shifted, scaled.collect())
            })
            .collect();
        let largest = pieces
            .iter()
            .flat_map(|(_, w)| w.iter().map(|w| w.abs()))
            .fold(0.0, f64::max);
        // The scale at which the largest weight takes all its bits, and
        // finer by the guard bits: each weight keeps `weight_bits`
        // significant bits down to weights 2^GUARD_BITS times smaller.
        let top = ((1i64 << (weight_bits - 1)) - 1) as f64;
        let mut weight_frac = 0;
        while weight_frac < MAX_WEIGHT_FRAC
            && (largest * (1u64 << (weight_frac + 1)) as f64).round() <= top
        {
            weight_frac += 1;
        }
        let weight_frac = (weight_frac + GUARD_BITS).min(MAX_WEIGHT_FRAC);
        // A weight so large that its products with a word leave 64-bit
        // integers is no circuit.
        let reach = largest * 2f64.powi((input_bits + SUM_GUARD_BITS) as i32);
        let bias_reach = pieces.iter().map(|(b, _)| b.abs()).fold(0.0, f64::max)
            * 2f64.powi((input_bits + SUM_GUARD_BITS) as i32);
        if !(reach < 2f64.powi(60) && bias_reach < 2f64.powi(60)) {
            return Err(format!(
                "a weight or bias of `{}` (up to {largest:.3e} level spacings per input level) is \
                 too large for {input_bits}-bit words in 62-bit sums",
                learned[reads.variable].variable
            ));
        }
        // Products keep SUM_GUARD fractional bits below the inputs' own:
        // finer ones are dropped term by term (each shifted term floored).
        let dropped = weight_frac.saturating_sub(SUM_GUARD_BITS);
        let scale = input_frac + weight_frac - dropped;
        if scale > MAX_SUM_BITS {
            return Err(format!("{scale} fractional bits is more than a sum holds"));
        }
        let mut coefficients = Vec::with_capacity(pieces.len() * (reads.inputs.len() + 1));
        for (bias, weights) in &pieces {
            coefficients.push((bias * (1u64 << scale) as f64).round() as i64);
            let unit = (1u64 << weight_frac) as f64;
            coefficients.extend(weights.iter().map(|w| significant(w * unit, weight_bits)));
        }
        // Every piece's range over every word an input can hold: each term
        // is monotone in its word, so its extremes are at the word's.
        let word = (-(1i64 << (input_bits - 1)), (1i64 << (input_bits - 1)) - 1);
        let (mut lo, mut hi) = (0i128, 0i128);
        for piece in coefficients.chunks_exact(reads.inputs.len() + 1) {
            let (mut p_lo, mut p_hi) = (piece[0] as i128, piece[0] as i128);
            for &w in &piece[1..] {
                // Sums wrap in the circuit's width: only the piece's value
                // must fit, not every partial sum.
                let (a, b) = product_bounds(w, word, dropped);
                p_lo += a;
                p_hi += b;
            }
            lo = lo.min(p_lo);
            hi = hi.max(p_hi);
        }
        // The circuit adds the origin and half a level (the rounding's) to
        // every piece.
        let offset =
            (i128::from(own_origin) << scale) + if scale > 0 { 1i128 << (scale - 1) } else { 0 };
        let piece_bits = signed_bits(lo + offset, hi + offset);
        let turn = learned[reads.variable]
            .period()
            .map(|_| (std::f64::consts::TAU / own.1 * (1u64 << scale) as f64).round() as i64);
        // The current word at the sum's scale, the change, the origin and
        // a half to round, then at most a turn either way.
        let up = weight_frac - dropped;
        let current = (i128::from(word.0) << up, i128::from(word.1) << up);
        let turn_span = turn.unwrap_or(0) as i128;
        let sum_bits = signed_bits(
            current.0 + lo + offset - turn_span,
            current.1 + hi + offset + turn_span,
        );
        if sum_bits.max(piece_bits) > MAX_SUM_BITS {
            return Err(format!(
                "input_bits = {input_bits} and weight_bits = {weight_bits} make sums of {} \
                 bits; at most {MAX_SUM_BITS}",
                sum_bits.max(piece_bits)
            ));
        }
        Ok(FixedOutput {
            variable: reads.variable,
            inputs: reads.inputs.clone(),
            widths,
            input_int,
            input_frac,
            weight_frac,
            dropped,
            coefficients,
            nodes: tree.nodes().to_vec(),
            levels: learned[reads.variable].quantizer.levels as u32,
            turn,
            piece_bits,
            sum_bits,
            scales,
            own,
            own_origin,
        })
    }

    /// The fractional bits of a piece's value and of the advanced sum.
    pub fn scale(&self) -> u32 {
        self.input_frac + self.weight_frac - self.dropped
    }

    /// Half a level at the sum's scale (0 without fractional bits).
    pub fn half(&self) -> i64 {
        match self.scale() {
            0 => 0,
            scale => 1 << (scale - 1),
        }
    }

    /// What a circuit adds to every piece: the predicted variable's origin
    /// and half a level, so that the answer plus the current word is the
    /// next level's sum ready to round (adding a constant commutes with
    /// MIN and MAX).
    pub fn piece_offset(&self) -> i64 {
        (self.own_origin << self.scale()) + self.half()
    }

    /// The word a value `x` of a variable with quantizer (min, spacing)
    /// `scale` is at these widths: rounded, saturated.
    fn word(&self, x: f64, (min, spacing): (f64, f64)) -> i64 {
        let top = (1i64 << (self.widths.input_bits - 1)) - 1;
        let t = (x - min) / spacing * (1u64 << self.input_frac) as f64;
        (t.round() as i64).clamp(-top - 1, top)
    }

    /// The input words of a state (`state[v]`: learned variable v's real
    /// value), in the tree's input order, into `words`.
    pub fn words(&self, state: impl Fn(usize) -> f64, words: &mut [i64]) {
        for ((w, &i), &scale) in words.iter_mut().zip(&self.inputs).zip(&self.scales) {
            *w = self.word(state(i), scale);
        }
    }

    /// The word of the predicted variable's current value `x`.
    pub fn current_word(&self, x: f64) -> i64 {
        self.word(x, self.own)
    }

    /// Piece `p` at the input words: bias + Σ weight·word.
    pub fn piece_value(&self, p: usize, words: &[i64]) -> i64 {
        let row = &self.coefficients[p * (self.inputs.len() + 1)..][..self.inputs.len() + 1];
        row[1..]
            .iter()
            .zip(words)
            .fold(row[0], |sum, (&w, &x)| sum + product(w, x, self.dropped))
    }

    /// The tree's answer at the input words: the change at 2^[`scale`].
    pub fn change(&self, words: &[i64]) -> i64 {
        self.answer(0, words)
    }

    fn answer(&self, node: usize, words: &[i64]) -> i64 {
        match self.nodes[node] {
            Node::Piece(p) => self.piece_value(p as usize, words),
            Node::Min(a, b) => {
                let (x, y) = (
                    self.answer(a as usize, words),
                    self.answer(b as usize, words),
                );
                if y < x { y } else { x }
            }
            Node::Max(a, b) => {
                let (x, y) = (
                    self.answer(a as usize, words),
                    self.answer(b as usize, words),
                );
                if y > x { y } else { x }
            }
        }
    }

    /// The next level from the current word and the change: the sum
    /// rounded half up, wrapped once onto the circle for an angle,
    /// clamped to the levels.
    pub fn next_level(&self, current: i64, change: i64) -> u16 {
        let scale = self.scale();
        let up = self.weight_frac - self.dropped;
        let mut sum = (current << up) + change + (self.own_origin << scale);
        if let Some(turn) = self.turn {
            if sum < 0 {
                sum += turn;
            } else if sum >= turn {
                sum -= turn;
            }
        }
        ((sum + self.half()) >> scale).clamp(0, i64::from(self.levels) - 1) as u16
    }

    /// The next level of the state `state[v]` (learned variable v's value).
    pub fn level(&self, state: impl Fn(usize) -> f64 + Copy, words: &mut [i64]) -> u16 {
        self.words(state, words);
        let change = self.change(words);
        self.next_level(self.current_word(state(self.variable)), change)
    }
}

/// A piecewise-linear model's outputs in fixed point.
#[derive(Clone, Debug, PartialEq)]
pub struct FixedModel {
    pub outputs: Vec<FixedOutput>,
}

impl FixedModel {
    /// Every output of `trees` (reading `reads` among `learned`) at its
    /// widths, the words' origins and integer bits chosen on the training
    /// rows `train` (`[variable][row]` real values of the learned
    /// variables).
    pub fn new(
        trees: &[Tree],
        reads: &[Reads],
        learned: &[&Entry],
        train: &[&[f64]],
        widths: &[Widths],
    ) -> Result<FixedModel, String> {
        let origins = origins(learned, train);
        let outputs = trees
            .iter()
            .zip(reads)
            .zip(widths)
            .map(|((tree, r), &w)| {
                let int = input_integer_bits(r, learned, &origins, train);
                FixedOutput::new(tree, r, learned, &origins, int, w)
                    .map_err(|e| format!("`{}`: {e}", learned[r.variable].variable))
            })
            .collect::<Result<_, _>>()?;
        Ok(FixedModel { outputs })
    }

    /// The next levels `[output][row]` of the states `columns`
    /// (`[variable][row]`, the learned variables' real values).
    pub fn levels(&self, columns: &[&[f64]]) -> Vec<Vec<u16>> {
        self.outputs
            .iter()
            .map(|o| output_levels(o, columns))
            .collect()
    }
}

/// `output`'s next level on every row of `columns`.
pub fn output_levels(output: &FixedOutput, columns: &[&[f64]]) -> Vec<u16> {
    let rows = columns.first().map_or(0, |c| c.len());
    let mut words = vec![0; output.inputs.len()];
    (0..rows)
        .map(|r| output.level(|v| columns[v][r], &mut words))
        .collect()
}

/// The integer bits of output `r`'s input words: its inputs' and its own
/// level coordinates from their `origins` on the training rows `train` lie
/// within them.
pub fn input_integer_bits(r: &Reads, learned: &[&Entry], origins: &[i64], train: &[&[f64]]) -> u32 {
    let own = std::iter::once(&r.variable);
    let ts = r.inputs.iter().chain(own).flat_map(|&i| {
        let (min, spacing) = scale_of(learned[i], origins[i]);
        train
            .get(i)
            .into_iter()
            .flat_map(move |c| c.iter().map(move |x| (x - min) / spacing))
    });
    integer_bits(ts)
}

/// Mean of |a − b| in levels, on the circle of `period` levels for an
/// angle that wraps.
pub fn mean_level_difference(a: &[u16], b: &[u16], period: Option<u32>) -> f64 {
    if a.is_empty() {
        return 0.0;
    }
    let total: u64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = u64::from(x.abs_diff(y));
            period.map_or(d, |p| d.min(u64::from(p).saturating_sub(d)))
        })
        .sum();
    total as f64 / a.len() as f64
}

/// Per output, the narrowest widths whose error in levels on the training
/// rows `train` (against `truth`, their next levels `[variable][row]`)
/// is at most `tolerance` above the floating-point model's (`float`, its
/// levels there, `[output][row]`): first the inputs with generous weights
/// (within half the tolerance), then the weights. An output no width meets
/// takes the widest tried.
pub fn choose(
    trees: &[Tree],
    reads: &[Reads],
    learned: &[&Entry],
    (train, truth): (&[&[f64]], &[Vec<u16>]),
    float: &[Vec<u16>],
    tolerance: f64,
) -> Result<Vec<Widths>, String> {
    let origins = origins(learned, train);
    trees
        .iter()
        .zip(reads)
        .zip(float)
        .map(|((tree, r), float)| {
            let int = input_integer_bits(r, learned, &origins, train);
            let period = learned[r.variable].period();
            let truth = &truth[r.variable];
            let float_error = mean_level_difference(float, truth, period);
            let differs = |widths: Widths| -> Result<f64, String> {
                let fixed = FixedOutput::new(tree, r, learned, &origins, int, widths)?;
                let error = mean_level_difference(&output_levels(&fixed, train), truth, period);
                Ok(error - float_error)
            };
            let narrowest = |widths: &mut dyn Iterator<Item = Widths>, within: f64| {
                let mut last = None;
                for w in widths {
                    match differs(w) {
                        Ok(d) if d <= within => return Ok(w),
                        Ok(_) => last = Some(w),
                        // Too narrow for a weight: wider ones may fit.
                        Err(_) => {}
                    }
                }
                last.ok_or_else(|| "no width holds its weights".to_string())
            };
            let inputs = narrowest(
                &mut (int + 1..=int + 1 + MAX_INPUT_FRAC).map(|input_bits| Widths {
                    input_bits,
                    weight_bits: MAX_WEIGHT_BITS,
                }),
                tolerance / 2.0,
            )?;
            narrowest(
                &mut (2..=MAX_WEIGHT_BITS).map(|weight_bits| Widths {
                    weight_bits,
                    ..inputs
                }),
                tolerance,
            )
            .map_err(|e| format!("`{}`: {e}", learned[r.variable].variable))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pwl::lazy::tests::random_tree;
    use crate::pwl::predict::{Path, Predictor};

    fn entry(variable: &str, min: f64, max: f64, levels: usize) -> Entry {
        crate::output::tests::entry_of(variable, min, max, levels)
    }

    /// The significant bits of `v`: its bits without trailing zeros.
    fn signed_digits_bound(v: i64) -> u32 {
        let m = v.abs() >> v.abs().trailing_zeros();
        64 - m.leading_zeros() + 1
    }

    #[test]
    fn signed_digits_sum_to_the_weight_with_no_two_adjacent() {
        for w in -300i64..=300 {
            let digits = signed_digits(w);
            let sum: i64 = digits
                .iter()
                .map(|&(k, neg)| if neg { -(1i64 << k) } else { 1i64 << k })
                .sum();
            assert_eq!(sum, w);
            assert!(
                digits.windows(2).all(|p| p[1].0 > p[0].0 + 1),
                "{w}: {digits:?}"
            );
            assert_eq!(product(w, 13, 0), 13 * w);
        }
        assert_eq!(signed_digits(7), vec![(0, true), (3, false)]);
        // 7·5 with two bits dropped: (5 << 3) >> 2 − 5 >> 2 = 10 − 1.
        assert_eq!(product(7, 5, 2), 9);
        assert_eq!(product(7, -5, 2), -10 + 2);
    }

    #[test]
    fn product_bounds_hold_every_word_though_a_product_is_not_monotone() {
        // The reviewer's case: −43 with twelve bits dropped on 8-bit words
        // is −1 at both ends and −2 at −64.
        assert_eq!(product(-43, -128, 12), -1);
        assert_eq!(product(-43, 127, 12), -1);
        assert_eq!(product(-43, -64, 12), -2);
        for w in [-300i64, -43, -7, 5, 43, 1000] {
            for dropped in [0, 3, 7, 12] {
                let (lo, hi) = product_bounds(w, (-128, 127), dropped);
                for x in -128..=127 {
                    let p = i128::from(product(w, x, dropped));
                    assert!(
                        lo <= p && p <= hi,
                        "{w}·{x} >> {dropped}: {p} not in [{lo}, {hi}]"
                    );
                }
            }
        }
    }

    #[test]
    fn bits_and_words() {
        assert_eq!(significant(300.7, 8), 300);
        assert_eq!(significant(-1000.0, 4), -1024);
        assert_eq!(significant(5.4, 8), 5);
        assert_eq!(signed_bits(-128, 127), 8);
        assert_eq!(signed_bits(-129, 0), 9);
        assert_eq!(signed_bits(0, 128), 9);
        assert_eq!(signed_bits(0, 0), 1);
        assert_eq!(integer_bits([0.0, 213.0].into_iter()), 8);
        assert_eq!(integer_bits([-0.5, 255.9].into_iter()), 8);
        assert_eq!(integer_bits([256.0].into_iter()), 9);
        assert_eq!(integer_bits([-1.0].into_iter()), 0);
    }

    /// A state of two variables (one an angle that wraps) and a model of
    /// two random trees, with its real values for `rows` states.
    fn two_outputs(rows: usize) -> (Vec<Entry>, Vec<Tree>, Vec<Reads>, Vec<Vec<f64>>) {
        let tau = std::f64::consts::TAU;
        let entries = vec![
            entry("a.1.x", -4.0, 4.0, 101),
            entry("roll.2", -tau / 2.0, tau / 2.0, 64),
        ];
        let trees = vec![random_tree(2, 12, 5), random_tree(2, 7, 9)];
        let reads = vec![
            Reads {
                variable: 0,
                inputs: vec![0, 1],
            },
            Reads {
                variable: 1,
                inputs: vec![1, 0],
            },
        ];
        let columns = (0..2)
            .map(|v| {
                (0..rows)
                    .map(|r| ((r * (v + 3)) as f64 * 0.618_033_988_7).fract() * 2.0 - 1.0)
                    .map(|u| u * if v == 0 { 3.9 } else { 3.1 })
                    .collect()
            })
            .collect();
        (entries, trees, reads, columns)
    }

    #[test]
    fn wide_words_give_the_floating_point_levels_and_narrow_ones_differ() {
        let (entries, trees, reads, columns) = two_outputs(500);
        let learned: Vec<&Entry> = entries.iter().collect();
        let cols: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        let states = super::super::predict::states(&columns, &(0..500).collect::<Vec<_>>());
        let predictor = Predictor::new(&trees, &reads, &learned, &states);
        let mut float = vec![vec![0u16; 500]; 2];
        let mut next = [0u16; 2];
        let mut scratch = predictor.scratch();
        for (r, state) in states.chunks_exact(2).enumerate() {
            predictor.next_levels(state, Path::Plain, &mut scratch, &mut next);
            float[0][r] = next[0];
            float[1][r] = next[1];
        }
        let wide = [Widths {
            input_bits: 26,
            weight_bits: 20,
        }; 2];
        let fixed = FixedModel::new(&trees, &reads, &learned, &cols, &wide).unwrap();
        let levels = fixed.levels(&cols);
        for o in 0..2 {
            let d = mean_level_difference(&levels[o], &float[o], learned[o].period());
            assert!(d < 0.005, "output {o}: {d}");
        }
        // The roll wraps: some rows cross the seam and land on the far side.
        assert!(fixed.outputs[1].turn.is_some());
        let narrow = [Widths {
            input_bits: 9,
            weight_bits: 3,
        }; 2];
        let coarse = FixedModel::new(&trees, &reads, &learned, &cols, &narrow).unwrap();
        let d = mean_level_difference(&coarse.levels(&cols)[0], &float[0], None);
        assert!(d > 0.05, "{d}");
        // Chosen within the tolerance on these rows, narrower than the wide:
        // against the floating-point levels as the truth, the error is the
        // difference.
        let chosen = choose(&trees, &reads, &learned, (&cols, &float), &float, 0.01).unwrap();
        let fixed = FixedModel::new(&trees, &reads, &learned, &cols, &chosen).unwrap();
        for (o, levels) in fixed.levels(&cols).iter().enumerate() {
            let d = mean_level_difference(levels, &float[o], learned[o].period());
            assert!(d <= 0.01, "output {o}: {d} at {:?}", chosen[o]);
            assert!(chosen[o].input_bits < 26 && chosen[o].weight_bits < 20);
        }
    }

    #[test]
    fn no_word_overflows_its_sum_and_the_arithmetic_is_exact() {
        let (entries, trees, reads, columns) = two_outputs(10);
        let learned: Vec<&Entry> = entries.iter().collect();
        let cols: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        let w = [Widths {
            input_bits: 12,
            weight_bits: 10,
        }; 2];
        let fixed = FixedModel::new(&trees, &reads, &learned, &cols, &w).unwrap();
        for o in &fixed.outputs {
            let (lo, hi) = (-(1i64 << 11), (1i64 << 11) - 1);
            // Every corner of the input box: each piece within its bits.
            for corner in 0..4 {
                let words = [
                    if corner & 1 == 0 { lo } else { hi },
                    if corner & 2 == 0 { lo } else { hi },
                ];
                for p in 0..o.coefficients.len() / 3 {
                    let v = (o.piece_value(p, &words) + o.piece_offset()) as i128;
                    assert!(signed_bits(v, v) <= o.piece_bits);
                }
            }
            // A saturated word, and a value exactly on a level.
            assert_eq!(o.current_word(1e9), hi);
            assert_eq!(o.current_word(-1e9), lo);
            let at_level = |k: f64| o.own.0 + o.own.1 * k;
            // Words count from the origin: level origin + 7 is 7.
            assert_eq!(o.current_word(at_level(7.0)), 7 << o.input_frac);
            let seven = (o.own_origin + 7) as u16;
            assert_eq!(o.next_level(7 << o.input_frac, 0), seven);
            let half = o.half();
            assert_eq!(
                o.next_level(7 << o.input_frac, half),
                seven + 1,
                "half rounds up"
            );
            assert_eq!(o.next_level(7 << o.input_frac, half - 1), seven);
        }
        // The roll (64 levels over a turn) wraps: from level 62, +3 is 1.
        let roll = &fixed.outputs[1];
        let three = 3i64 << roll.scale();
        let turned = roll.next_level((62 - roll.own_origin) << roll.input_frac, three);
        assert!(turned <= 2, "{turned}");
    }

    #[test]
    fn widths_too_narrow_are_named() {
        let (entries, trees, reads, columns) = two_outputs(10);
        let learned: Vec<&Entry> = entries.iter().collect();
        let cols: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        let error = |w: Widths| FixedModel::new(&trees, &reads, &learned, &cols, &[w; 2]);
        let e = error(Widths {
            input_bits: 4,
            weight_bits: 10,
        })
        .unwrap_err();
        assert!(e.contains("`a.1.x`") && e.contains("input_bits = 4"), "{e}");
        let e = error(Widths {
            input_bits: 12,
            weight_bits: 1,
        })
        .unwrap_err();
        assert!(e.contains("weight_bits = 1"), "{e}");
        // A weight so large its products leave 64-bit integers is refused,
        // not wrapped.
        let huge = [Tree::affine(0.0, &[1e30, 0.0]), trees[1].clone()];
        let e = FixedModel::new(
            &huge,
            &reads,
            &learned,
            &cols,
            &[Widths {
                input_bits: 12,
                weight_bits: 8,
            }; 2],
        )
        .unwrap_err();
        assert!(e.contains("too large for 12-bit words"), "{e}");
        // A steep weight beside a shallow one: each keeps 8 significant bits.
        let steep = [
            Tree::affine(0.0, &[300.7 / 0.08, 0.5123 / 0.08]),
            trees[1].clone(),
        ];
        let w = Widths {
            input_bits: 12,
            weight_bits: 8,
        };
        let fixed = FixedModel::new(&steep, &reads, &learned, &cols, &[w; 2]).unwrap();
        let o = &fixed.outputs[0];
        let unit = (1u64 << o.weight_frac) as f64;
        for (&got, want) in o.coefficients[1..]
            .iter()
            .zip([300.7, 0.5123 / 0.08 * o.scales[1].1])
        {
            let relative = (got as f64 / unit - want).abs() / want;
            assert!(relative <= 1.0 / 128.0, "{got} for {want}: {relative}");
            assert!(signed_digits_bound(got) <= 8, "{got}");
        }
    }
}
