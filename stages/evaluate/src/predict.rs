//! Predicting the test rows with a trained model, timed per evaluation path.
//!
//! A bit-forest predicts bit-sliced in batches (all rows at once, on all
//! threads — the levels come from this path) and one row at a time
//! (parsimonious chains), which must agree; a threshold model's binary
//! search runs for all rows at once, bit-sliced (`batched`), and one row at
//! a time (`threshold-search`), which must agree too. Times are for encoded inputs to decoded
//! levels: the trees, the votes and the decoding (with rate limiting, when
//! on, as `decode_near` around the current level).

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
use crate::timing::Path;

/// A one-row evaluation path: the levels of every row, one row at a time.
type OneRow<'s> = dyn Fn() -> Vec<Vec<u16>> + 's;

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

    /// The same levels, and every evaluation path to time: the batched
    /// path on one thread (in `pool`) and, labelled, on all threads when
    /// there are more; the one-row path. Every path must give the same
    /// levels (a bit-forest's bit-sliced and parsimonious evaluation, a
    /// threshold model's batched and one-row searches).
    pub fn paths<'s>(
        &'s self,
        x: &'s [Vec<u16>],
        windows: Option<&'s [usize]>,
        pool: &'s rayon::ThreadPool,
    ) -> (Vec<Vec<u16>>, Vec<Path<'s>>) {
        let inputs = self.encode(x);
        let rows = inputs.rows();
        let levels = self.levels(x, windows);
        assert_eq!(
            pool.install(|| self.levels(x, windows)),
            levels,
            "batches on one and on all threads disagree"
        );
        let path = |path, threads, run: Box<dyn FnMut() + 's>| Path {
            model: "aln".into(),
            path,
            threads,
            states: rows,
            failed: 0,
            run,
        };
        let mut paths = vec![path(
            "batched",
            1,
            Box::new(move || {
                std::hint::black_box(pool.install(|| self.levels(x, windows)));
            }),
        )];
        let threads = rayon::current_num_threads();
        if threads > 1 {
            paths.push(path(
                "batched",
                threads,
                Box::new(move || {
                    std::hint::black_box(self.levels(x, windows));
                }),
            ));
        }
        let (name, single): (&'static str, Box<OneRow<'s>>) = match &self.compiled {
            Compiled::BitForest(predictor) => (
                "single",
                Box::new(move || self.single(predictor, x, &inputs, windows)),
            ),
            Compiled::Threshold {
                voters,
                thermometers,
                ..
            } => (
                "threshold-search",
                Box::new(move || self.search(voters, thermometers, x, &inputs, windows)),
            ),
        };
        assert_eq!(single(), levels, "the one-row and batched paths disagree");
        paths.push(path(
            name,
            1,
            Box::new(move || {
                std::hint::black_box(single());
            }),
        ));
        (levels, paths)
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

/// The linear baseline's levels `[variable][row]`, and its one-row path
/// to time.
pub fn linear<'s>(
    model: &'s Linear,
    x: &'s [Vec<u16>],
    levels: &'s [usize],
) -> (Vec<Vec<u16>>, Path<'s>) {
    let path = Path {
        model: "linear".into(),
        path: "single",
        threads: 1,
        states: x.first().map_or(0, Vec::len),
        failed: 0,
        run: Box::new(move || {
            std::hint::black_box(linear_levels(model, x, levels));
        }),
    };
    (linear_levels(model, x, levels), path)
}

/// The linear baseline's levels `[variable][row]`, one row at a time.
pub fn linear_levels(model: &Linear, x: &[Vec<u16>], levels: &[usize]) -> Vec<Vec<u16>> {
    let rows = x.first().map_or(0, Vec::len);
    let mut out = vec![Vec::with_capacity(rows); x.len()];
    let (mut row, mut predicted) = (vec![0u16; x.len()], vec![0u16; x.len()]);
    for r in 0..rows {
        for (v, column) in x.iter().enumerate() {
            row[v] = column[r];
        }
        model.predict(&row, levels, &mut predicted);
        for (v, &p) in predicted.iter().enumerate() {
            out[v].push(p);
        }
    }
    out
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
        let pool = crate::timing::one_thread();
        let (levels, paths) = aln.paths(&x, None, &pool);
        let timings = crate::timing::in_rounds(paths, 2);
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
        // Every path on one thread; the batches on all threads too, labelled.
        let paths: Vec<(&str, usize)> = timings.iter().map(|t| (t.path, t.threads)).collect();
        let threads = rayon::current_num_threads();
        let mut expected = vec![("batched", 1)];
        if threads > 1 {
            expected.push(("batched", threads));
        }
        expected.push(("single", 1));
        assert_eq!(paths, expected);
        assert!(
            timings
                .iter()
                .all(|t| t.runs.len() == 2 && t.runs.iter().all(|&ns| ns > 0.0) && t.states == 63)
        );

        // Rate limited to 0 levels: nothing moves.
        let (still, _) = aln.paths(&x, Some(&[0]), &pool);
        assert_eq!(
            aln.levels(&x, None),
            levels,
            "the fast path alone gives the same levels"
        );
        assert_eq!(still, x);
    }
}
