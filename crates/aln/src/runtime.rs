//! A trained model made ready to predict: the runtime both the test stage
//! (which times it) and the plan stage (which plans with it) use. A
//! bit-forest is compiled once and predicts bit-sliced in batches — coding
//! only the input bits its trees read — or parsimoniously one row at a time;
//! a threshold model answers its binary search for all rows at once or one
//! row at a time. Every path decodes through the outputs' [`Output`], with
//! optional rate limiting.

use std::path::{Path, PathBuf};

use alnlab_codes::Codebook;
use alnlab_codes::bits::{BitMatrix, Columns, encode, encode_columns};
use alnlab_codes::codes::{Code, Codec};
use rayon::prelude::*;

use crate::forest::Predictor;
use crate::model::{Model, Reads};
use crate::threshold;
use crate::tree::Tree;
use crate::{ModelKind, Output};
use alnlab_common::hash::sha256_file;
use alnlab_common::{Error, Result};

/// A trained model with the codebook it was trained with, checked to
/// belong together: the codebook's hash is the one the model names, and
/// the model predicts the codebook's learned variables in its codes.
pub struct Trained {
    pub model: Model,
    pub codebook: Codebook,
    /// Where the codebook was read from.
    pub codebook_path: PathBuf,
    /// The learned variables' codecs, in the model's variable order.
    pub codecs: Vec<Codec>,
    /// What decodes each learned variable from its trees' bits (none for
    /// a piecewise-linear model).
    pub outputs: Vec<Output>,
    /// A piecewise-linear model's outputs: which variable each predicts and
    /// which it reads (none for other models).
    pub reads: Vec<Reads>,
}

impl Trained {
    /// Reads `model.aln` and `codebook.parquet`; an error names the file
    /// that does not fit.
    pub fn read(model_path: &Path, codebook_path: &Path) -> Result<Trained> {
        let model = Model::read(model_path)?;
        if model.header.codebook_sha256 != sha256_file(codebook_path)? {
            return Err(Error::bad_file(
                model_path,
                format!(
                    "was trained with another codebook than {}",
                    codebook_path.display()
                ),
            ));
        }
        let codebook = alnlab_tables::codebook::read(codebook_path)?;
        let codecs = codebook.learned_codecs(codebook_path)?;
        let learned: Vec<_> = codebook.learned().collect();
        let misfit = |m: String| {
            Error::bad_file(
                model_path,
                format!("does not fit the codebook {}: {m}", codebook_path.display()),
            )
        };
        let piecewise = match model.header.model {
            ModelKind::PiecewiseLinear => true,
            ModelKind::BitForest | ModelKind::Threshold => false,
        };
        let (outputs, reads) = if piecewise {
            let reads = model.header.piecewise_for(&learned).map_err(misfit)?;
            for (o, (r, tree)) in reads.iter().zip(&model.pieces).enumerate() {
                if r.inputs.len() != tree.inputs() {
                    return Err(Error::bad_file(
                        model_path,
                        format!(
                            "output {o}'s tree reads {} inputs, its header names {}",
                            tree.inputs(),
                            r.inputs.len()
                        ),
                    ));
                }
            }
            (Vec::new(), reads)
        } else {
            (
                model.header.outputs_for(&learned).map_err(misfit)?,
                Vec::new(),
            )
        };
        Ok(Trained {
            model,
            codebook,
            codebook_path: codebook_path.to_path_buf(),
            codecs,
            outputs,
            reads,
        })
    }

    /// The runtime that predicts with a bit-forest or threshold model
    /// (see [`Runtime::new`]); a piecewise-linear model is refused.
    pub fn runtime(&self) -> std::result::Result<Runtime<'_>, String> {
        Runtime::new(&self.model, &self.codecs, &self.outputs)
    }
}

/// A trained model made ready to predict: a bit-forest compiled once, or a
/// threshold model's voters with the codes of its candidate levels; and its
/// outputs, which decode the trees' bits on every path.
pub struct Runtime<'a> {
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

impl<'a> Runtime<'a> {
    /// Prepares `model`, whose inputs are coded by `codecs` and whose
    /// trees' bits `outputs` decode. A piecewise-linear model, which
    /// predicts from real values with [`crate::pwl::predict::Predictor`],
    /// is an error saying so.
    pub fn new(
        model: &'a Model,
        codecs: &'a [Codec],
        outputs: &'a [Output],
    ) -> std::result::Result<Runtime<'a>, String> {
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
            ModelKind::PiecewiseLinear => {
                return Err(
                    "a piecewise-linear model predicts from real values, not levels: \
                            it has no level runtime"
                        .into(),
                );
            }
        };
        Ok(Runtime {
            codecs,
            outputs,
            compiled,
        })
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

    /// The rows of `x` coded into every input bit.
    pub fn encode(&self, x: &[Vec<u16>]) -> BitMatrix {
        let (codecs, columns) = self.inputs(x);
        encode(&codecs, &columns)
    }

    /// A bit-forest's compiled trees (none for a threshold model).
    pub fn bit_forest(&self) -> Option<&Predictor> {
        match &self.compiled {
            Compiled::BitForest(predictor) => Some(predictor),
            Compiled::Threshold { .. } => None,
        }
    }

    /// The input codecs and level columns, as the coders take them.
    pub fn inputs<'x>(&self, x: &'x [Vec<u16>]) -> (Vec<&'a Codec>, Vec<&'x [u16]>) {
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
    pub fn decode(
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

    /// The levels one row at a time (`inputs`: `x` coded by
    /// [`Runtime::encode`]): a bit-forest's parsimonious chains, a threshold
    /// model's binary search.
    pub fn one_row(
        &self,
        x: &[Vec<u16>],
        inputs: &BitMatrix,
        windows: Option<&[usize]>,
    ) -> Vec<Vec<u16>> {
        match &self.compiled {
            Compiled::BitForest(predictor) => self.single(predictor, x, inputs, windows),
            Compiled::Threshold {
                voters,
                thermometers,
                ..
            } => self.search(voters, thermometers, x, inputs, windows),
        }
    }

    /// The name of the one-row path: `single` (a bit-forest's parsimonious
    /// chains) or `threshold-search`.
    pub fn one_row_path(&self) -> &'static str {
        match &self.compiled {
            Compiled::BitForest(_) => "single",
            Compiled::Threshold { .. } => "threshold-search",
        }
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
