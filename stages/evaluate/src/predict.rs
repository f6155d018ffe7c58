//! Predicting the test rows with a trained model, timed per evaluation path.
//!
//! A bit-forest predicts bit-sliced in batches (all rows at once, on all
//! threads — the levels come from this path) and one row at a time
//! (parsimonious chains), which must agree; a threshold model's binary
//! search runs for all rows at once, bit-sliced (`batched`), and one row at
//! a time (`threshold-search`), which must agree too. Times are for encoded inputs to decoded
//! levels: the trees, the votes and the decoding (with rate limiting, when
//! on, as `decode_near` around the current level).

use std::time::Instant;

use alnlab_aln::ModelKind;
use alnlab_aln::Output;
use alnlab_aln::forest::Predictor;
use alnlab_aln::model::Model;
use alnlab_aln::threshold;
use alnlab_aln::tree::Tree;
use alnlab_codes::bits::{BitMatrix, Columns, encode, encode_columns};
use alnlab_codes::codes::{Code, Codec};
use rayon::prelude::*;

use crate::baseline::Linear;

/// One measured evaluation path.
#[derive(Clone, Debug, PartialEq)]
pub struct Timing {
    pub model: String,
    /// `batched`, `single` or `threshold-search`.
    pub path: &'static str,
    pub ns_per_state: f64,
    /// States timed.
    pub states: usize,
    pub threads: usize,
    /// States the model could not predict (a re-simulation that blew up).
    pub failed: usize,
}

/// A trained model made ready to predict: a bit-forest compiled once, or a
/// threshold model's voters with the codes of its candidate levels; and its
/// outputs, which decode the trees' bits on every path.
pub struct Aln<'a> {
    /// The input variables' codes.
    codecs: &'a [Codec],
    outputs: &'a [Output],
    compiled: Compiled<'a>,
}

enum Compiled<'a> {
    BitForest(Predictor),
    Threshold {
        voters: Vec<Vec<&'a Tree>>,
        thermometers: Vec<Codec>,
        batched: threshold::Batched,
    },
}

/// How long `f` takes per state, as the timing of `path`: the fastest of
/// `repeats` runs, so that a short path is not timed cold (first touch of
/// the compiled trees, thread pool start).
fn timed<T>(
    path: &'static str,
    states: usize,
    threads: usize,
    repeats: usize,
    f: impl Fn() -> T,
) -> (T, Timing) {
    let mut fastest = f64::INFINITY;
    let mut out = None;
    for _ in 0..repeats.max(1) {
        let clock = Instant::now();
        out = Some(f());
        fastest = fastest.min(clock.elapsed().as_nanos() as f64);
    }
    let timing = Timing {
        model: "aln".into(),
        path,
        ns_per_state: fastest / states.max(1) as f64,
        states,
        threads,
        failed: 0,
    };
    (out.expect("at least one run"), timing)
}

impl<'a> Aln<'a> {
    /// Prepares `model`, whose inputs are coded by `codecs` and whose
    /// trees' bits `outputs` decode.
    pub fn new(model: &'a Model, codecs: &'a [Codec], outputs: &'a [Output]) -> Aln<'a> {
        let compiled = match model.header.model {
            ModelKind::BitForest => {
                let widths: Vec<usize> = model.header.outputs.iter().map(|(_, w)| *w).collect();
                let trees = model.trees.iter().map(|(id, tree)| (*id, tree));
                Compiled::BitForest(Predictor::new(trees, &widths, model.header.vote))
            }
            ModelKind::Threshold => {
                let voters: Vec<Vec<&Tree>> = model
                    .trees
                    .chunks(model.header.vote as usize)
                    .map(|chunk| chunk.iter().map(|(_, tree)| tree).collect())
                    .collect();
                let levels: Vec<usize> = outputs.iter().map(|o| o.codec().levels()).collect();
                Compiled::Threshold {
                    batched: threshold::Batched::new(&voters, &levels),
                    thermometers: levels
                        .iter()
                        .map(|&l| Codec::new(Code::Thermometer, l, None).expect("levels ≥ 2"))
                        .collect(),
                    voters,
                }
            }
        };
        Aln {
            codecs,
            outputs,
            compiled,
        }
    }

    /// The predicted levels `[variable][row]` for the current levels `x`
    /// (`[variable][row]`) by the fastest path; `windows` rate-limits each
    /// variable to within that many levels of its current one.
    pub fn levels(&self, x: &[Vec<u16>], windows: Option<&[usize]>) -> Vec<Vec<u16>> {
        match &self.compiled {
            Compiled::BitForest(predictor) => self.batched(predictor, x, windows),
            Compiled::Threshold { batched, .. } => self.batched_search(batched, x, windows),
        }
    }

    /// The same levels, with the timing of every evaluation path (a
    /// bit-forest's batched and single-row paths must agree).
    pub fn timed(&self, x: &[Vec<u16>], windows: Option<&[usize]>) -> (Vec<Vec<u16>>, Vec<Timing>) {
        let inputs = self.encode(x);
        let rows = inputs.rows();
        match &self.compiled {
            Compiled::BitForest(predictor) => {
                let threads = rayon::current_num_threads();
                let (levels, batched) = timed("batched", rows, threads, 3, || {
                    self.batched(predictor, x, windows)
                });
                let (single_levels, single) = timed("single", rows, 1, 1, || {
                    self.single(predictor, x, &inputs, windows)
                });
                assert_eq!(
                    single_levels, levels,
                    "parsimonious and bit-sliced evaluation disagree"
                );
                (levels, vec![batched, single])
            }
            Compiled::Threshold {
                voters,
                thermometers,
                batched,
            } => {
                let threads = rayon::current_num_threads();
                let (levels, batched) = timed("batched", rows, threads, 3, || {
                    self.batched_search(batched, x, windows)
                });
                let (single_levels, single) = timed("threshold-search", rows, 1, 1, || {
                    self.search(voters, thermometers, x, &inputs, windows)
                });
                assert_eq!(
                    single_levels, levels,
                    "the one-row and batched threshold searches disagree"
                );
                (levels, vec![batched, single])
            }
        }
    }

    fn encode(&self, x: &[Vec<u16>]) -> BitMatrix {
        let (codecs, columns) = self.inputs(x);
        encode(&codecs, &columns)
    }

    /// A bit-forest's compiled trees (none for a threshold model).
    pub(crate) fn bit_forest(&self) -> Option<&Predictor> {
        match &self.compiled {
            Compiled::BitForest(predictor) => Some(predictor),
            Compiled::Threshold { .. } => None,
        }
    }

    /// The input codecs and level columns, as the coders take them.
    pub(crate) fn inputs<'x>(&self, x: &'x [Vec<u16>]) -> (Vec<&'a Codec>, Vec<&'x [u16]>) {
        (
            self.codecs.iter().collect(),
            x.iter().map(Vec::as_slice).collect(),
        )
    }

    /// All rows bit-sliced, decoded in parallel by variable: from the
    /// levels to the levels, coding only the input bits the trees read.
    fn batched(
        &self,
        predictor: &Predictor,
        x: &[Vec<u16>],
        windows: Option<&[usize]>,
    ) -> Vec<Vec<u16>> {
        let (codecs, columns) = self.inputs(x);
        let out = predictor.predict_read(&encode_columns(&codecs, &columns, predictor.reads()));
        self.decode(&out, x, windows)
    }

    /// The levels the outputs' bits `out[v]` (bit-sliced) stand for, from
    /// the current levels `x`; in parallel by variable.
    pub(crate) fn decode(
        &self,
        out: &[Columns],
        x: &[Vec<u16>],
        windows: Option<&[usize]>,
    ) -> Vec<Vec<u16>> {
        out.par_iter()
            .zip(self.outputs)
            .enumerate()
            .map(|(v, (columns, output))| {
                let mut levels = Vec::with_capacity(columns.count);
                let window = windows.map(|w| w[v]);
                columns.for_each_row(|s, code| levels.push(output.decode(code, x[v][s], window)));
                levels
            })
            .collect()
    }

    /// One row at a time, parsimoniously.
    // A row index reads the inputs and the current levels at once.
    #[allow(clippy::needless_range_loop)]
    fn single(
        &self,
        predictor: &Predictor,
        x: &[Vec<u16>],
        inputs: &BitMatrix,
        windows: Option<&[usize]>,
    ) -> Vec<Vec<u16>> {
        let mut votes = Vec::new();
        let mut codes = vec![Vec::new(); self.outputs.len()];
        let mut levels = vec![Vec::with_capacity(inputs.rows()); self.outputs.len()];
        for r in 0..inputs.rows() {
            predictor.predict_one(inputs.row(r), &mut votes, &mut codes);
            for (v, (output, code)) in self.outputs.iter().zip(&codes).enumerate() {
                levels[v].push(output.decode(code, x[v][r], windows.map(|w| w[v])));
            }
        }
        levels
    }

    /// All rows at once, the binary search bit-sliced.
    fn batched_search(
        &self,
        batched: &threshold::Batched,
        x: &[Vec<u16>],
        windows: Option<&[usize]>,
    ) -> Vec<Vec<u16>> {
        let rows = x.first().map_or(0, Vec::len);
        let (codecs, columns) = self.inputs(x);
        batched
            .predict(&codecs, &columns)
            .iter()
            .zip(self.outputs)
            .enumerate()
            .map(|(v, (found, output))| {
                let window = windows.map(|w| w[v]);
                (0..rows)
                    .map(|r| output.settle(found[r], x[v][r], window))
                    .collect()
            })
            .collect()
    }

    /// One row at a time, by binary search over each variable's levels.
    #[allow(clippy::needless_range_loop)]
    fn search(
        &self,
        voters: &[Vec<&Tree>],
        thermometers: &[Codec],
        x: &[Vec<u16>],
        inputs: &BitMatrix,
        windows: Option<&[usize]>,
    ) -> Vec<Vec<u16>> {
        let mut levels = vec![Vec::with_capacity(inputs.rows()); self.outputs.len()];
        let mut scratch = Vec::new();
        for r in 0..inputs.rows() {
            for (v, trees) in voters.iter().enumerate() {
                let level = threshold::predict(
                    trees,
                    inputs.bits(),
                    &thermometers[v],
                    inputs.row(r),
                    &mut scratch,
                );
                let window = windows.map(|w| w[v]);
                levels[v].push(self.outputs[v].settle(level, x[v][r], window));
            }
        }
        levels
    }
}

/// The linear baseline's levels `[variable][row]`, timed one row at a time.
pub fn linear(model: &Linear, x: &[Vec<u16>], levels: &[usize]) -> (Vec<Vec<u16>>, Timing) {
    let rows = x.first().map_or(0, Vec::len);
    let mut out = vec![Vec::with_capacity(rows); x.len()];
    let (mut row, mut predicted) = (vec![0u16; x.len()], vec![0u16; x.len()]);
    let clock = Instant::now();
    for r in 0..rows {
        for (v, column) in x.iter().enumerate() {
            row[v] = column[r];
        }
        model.predict(&row, levels, &mut predicted);
        for (v, &p) in predicted.iter().enumerate() {
            out[v].push(p);
        }
    }
    let timing = Timing {
        model: "linear".into(),
        path: "single",
        ns_per_state: clock.elapsed().as_nanos() as f64 / rows.max(1) as f64,
        states: rows,
        threads: 1,
        failed: 0,
    };
    (out, timing)
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_aln::Target;
    use alnlab_aln::model::Header;
    use alnlab_aln::shard::Shard;
    use alnlab_aln::tree::TreeSpec;
    use alnlab_codes::walk::WalkSpec;
    use alnlab_train::forest;

    /// A forest (vote 3) trained on y = x + 1 over 64 walk-coded levels, and
    /// its codec.
    fn successor_model() -> (Model, Codec) {
        let spec = WalkSpec {
            levels: 64,
            width: 23,
            step: 1,
            span: 7,
            seed: 3,
        };
        let codec = Codec::new(Code::Walk, 64, Some(spec)).unwrap();
        let x: Vec<u16> = (0..800).map(|i| (i * 37 % 63) as u16).collect();
        let y: Vec<u16> = x.iter().map(|v| v + 1).collect();
        let all: Vec<usize> = (0..800).collect();
        let inputs = Columns::from_rows(&encode(&[&codec], &[&x]), &all);
        let targets = [Columns::from_rows(&encode(&[&codec], &[&y]), &all)];
        let tree = TreeSpec {
            leaves: 512,
            inputs: 23,
            counter_bound: 3,
            initial_spread: 1,
        };
        let trained = forest::train(
            &tree,
            10,
            3,
            1,
            Shard::ALL,
            &inputs,
            &targets,
            &forest::every_bit(23, 1),
            &|| {},
        );
        let header = Header {
            codebook_sha256: String::new(),
            params: serde_json::Value::Null,
            model: ModelKind::BitForest,
            target: Target::Level,
            inputs: 23,
            outputs: vec![("v".into(), 23)],
            reads: Vec::new(),
            vote: 3,
            counter_bound: 3,
            shard: None,
        };
        let trees = trained.into_iter().map(|t| (t.id, t.tree)).collect();
        (Model { header, trees }, codec)
    }

    #[test]
    fn both_paths_predict_the_successor_and_rate_limits_hold() {
        let (model, codec) = successor_model();
        let x = vec![(0..63u16).rev().collect::<Vec<_>>()];
        // (The two paths' levels are compared inside.)
        let codecs = std::slice::from_ref(&codec);
        let outputs = [Output::Level(codec.clone())];
        let aln = Aln::new(&model, codecs, &outputs);
        let (levels, timings) = aln.timed(&x, None);
        let error: usize = levels[0]
            .iter()
            .zip(&x[0])
            .map(|(&p, &c)| p.abs_diff(c + 1) as usize)
            .sum();
        assert!(
            error as f64 / 63.0 <= 1.0,
            "mean error {}",
            error as f64 / 63.0
        );
        let paths: Vec<&str> = timings.iter().map(|t| t.path).collect();
        assert_eq!(paths, ["batched", "single"]);
        assert!(
            timings
                .iter()
                .all(|t| t.ns_per_state > 0.0 && t.states == 63)
        );

        // Rate limited to 0 levels: nothing moves.
        let (still, _) = aln.timed(&x, Some(&[0]));
        assert_eq!(
            aln.levels(&x, None),
            levels,
            "the fast path alone gives the same levels"
        );
        assert_eq!(still, x);
    }
}
