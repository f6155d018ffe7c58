//! The train stage (paper §3, §4.3, §4.7; DESIGN.md §5): reads the codebook
//! and `levels.parquet`, trains one ALN tree per output bit of every learned
//! variable (`vote` trees per bit) on the training rows, and writes the model
//! file and `training.parquet` (per tree per epoch: errors, counter updates,
//! seconds).
//!
//! What a model *is* — trees, predictors, the model file — lives in the
//! `alnlab-aln` library; this stage only trains: [`learn`] (one tree, §3.3),
//! `forest` (many, in parallel), `threshold` (the §6 predicate) and
//! [`shard`] (a part of the forest, and merging the parts).

pub mod bench;
pub mod forest;
pub mod learn;
pub mod shard;
mod threshold;

use std::path::Path;
use std::sync::Arc;

use alnlab_codes::bits::encode;
use alnlab_codes::codes::Codec;
use alnlab_codes::{Codebook, level_column, split_rows};
use alnlab_common::hash::sha256_file;
use alnlab_common::params::{self, Count, ParamError};
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Progress, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array, UInt64Array};
use serde::{Deserialize, Serialize};

use alnlab_aln::ModelKind;
use alnlab_aln::model::{Header, Model};
use alnlab_aln::shard::Shard;
use alnlab_aln::tree::TreeSpec;
use alnlab_codes::bits::Columns;

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 3;
/// File name of the model.
pub const MODEL_FILE: &str = "model.aln";
/// File name of the training log table.
pub const TRAINING_FILE: &str = "training.parquet";

/// The `[train]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// `bit-forest` or `threshold`.
    pub model: ModelKind,
    /// Leaves per tree, a power of two (paper: 8192).
    pub leaves: Count,
    /// Most epochs (presentations of the training set; paper: 10).
    pub epochs: Count,
    /// Trees per output bit, whose majority is the bit: 1, 3 or 5 (§4.7).
    pub vote: Count,
    /// Node counters stay within ±counter_bound.
    pub counter_bound: Count,
    /// Initial counters are uniform in −spread..spread − 1.
    pub initial_spread: Count,
    /// Threshold model: each training row is presented with the candidate
    /// levels within `threshold_near` of its true level …
    pub threshold_near: u32,
    /// … and `threshold_far` random candidate levels.
    pub threshold_far: u32,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            model: ModelKind::BitForest,
            leaves: Count(8192),
            epochs: Count(10),
            vote: Count(1),
            counter_bound: Count(3),
            initial_spread: Count(1),
            threshold_near: 2,
            threshold_far: 2,
        }
    }
}

impl Params {
    /// Checks the parameters; on error, the key and what is allowed.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        let leaves = self.leaves.0;
        if !(2..=1 << 24).contains(&leaves) || !leaves.is_power_of_two() {
            return Err((
                "leaves".into(),
                format!("expected a power of two from 2 to 2^24, found {leaves}"),
            ));
        }
        if ![1, 3, 5].contains(&self.vote.0) {
            return Err((
                "vote".into(),
                format!("expected 1, 3 or 5, found {}", self.vote.0),
            ));
        }
        if self.counter_bound.0 > 127 {
            return Err((
                "counter_bound".into(),
                format!("expected at most 127, found {}", self.counter_bound.0),
            ));
        }
        if self.initial_spread.0 > self.counter_bound.0 {
            return Err((
                "initial_spread".into(),
                format!(
                    "expected at most counter_bound = {}, found {}",
                    self.counter_bound.0, self.initial_spread.0
                ),
            ));
        }
        Ok(())
    }

    fn tree_spec(&self, inputs: usize) -> TreeSpec {
        TreeSpec {
            leaves: self.leaves.get(),
            inputs,
            counter_bound: self.counter_bound.0 as i8,
            initial_spread: self.initial_spread.0 as i8,
        }
    }
}

/// Reads the codebook and levels, trains `shard`'s trees ([`Shard::ALL`]
/// for the whole forest), writes the model (a partial one for a part) and
/// the log.
#[allow(clippy::too_many_arguments)]
pub fn run(
    params: &Params,
    seed: u64,
    shard: Shard,
    codebook_path: &Path,
    levels_path: &Path,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    params.validate().map_err(|e| params::invalid("train", e))?;
    let codebook = Codebook::read(codebook_path)?;
    let levels = Table::read(levels_path)?;
    let learned: Vec<_> = codebook.learned().collect();
    if learned.is_empty() {
        return Err(Error::bad_file(
            codebook_path,
            "has no learned variable: nothing to train",
        ));
    }
    let codecs = codebook.learned_codecs(codebook_path)?;
    let rows = split_rows(&levels, "train")?;
    if rows.is_empty() {
        return Err(Error::bad_file(levels_path, "has no training rows"));
    }
    let column = |side: &str, variable: &str| level_column(&levels, side, variable);
    let x_columns: Vec<&[u16]> = learned
        .iter()
        .map(|e| column("x", &e.variable))
        .collect::<Result<_>>()?;
    let y_columns: Vec<&[u16]> = learned
        .iter()
        .map(|e| column("y", &e.variable))
        .collect::<Result<_>>()?;
    let codec_refs: Vec<&Codec> = codecs.iter().collect();
    let x_bits = encode(&codec_refs, &x_columns);
    let inputs = x_bits.bits();

    let vote = params.vote.0 as u32;
    let tick = || progress.advance(1);
    let spec = params.tree_spec(inputs);
    let (trained, output_widths) = match params.model {
        ModelKind::BitForest => {
            let inputs = Columns::from_rows(&x_bits, &rows);
            let targets: Vec<Columns> = codecs
                .iter()
                .zip(&y_columns)
                .map(|(c, y)| Columns::from_rows(&encode(&[c], &[y]), &rows))
                .collect();
            let widths: Vec<usize> = targets.iter().map(|t| t.bits).collect();
            let total_trees = widths.iter().sum::<usize>() * vote as usize;
            let own = (0..total_trees).filter(|&p| shard.owns(p)).count();
            progress.start("train", own as u64, "trees");
            let trained = forest::train(
                &spec,
                params.epochs.get(),
                vote,
                seed,
                shard,
                &inputs,
                &targets,
                &tick,
            );
            (trained, widths)
        }
        ModelKind::Threshold => {
            // The training rows alone, in order, with their true levels.
            let x_train = encode(
                &codec_refs,
                &x_columns
                    .iter()
                    .map(|x| rows.iter().map(|&r| x[r]).collect())
                    .collect::<Vec<Vec<u16>>>()
                    .iter()
                    .map(Vec::as_slice)
                    .collect::<Vec<_>>(),
            );
            let y_train: Vec<Vec<u16>> = y_columns
                .iter()
                .map(|y| rows.iter().map(|&r| y[r]).collect())
                .collect();
            let targets: Vec<(&[u16], usize)> = y_train
                .iter()
                .zip(&codecs)
                .map(|(y, c)| (y.as_slice(), c.levels()))
                .collect();
            let total_trees = targets.len() * vote as usize;
            let own = (0..total_trees).filter(|&p| shard.owns(p)).count();
            progress.start("train", own as u64, "trees");
            let candidates = threshold::Candidates {
                near: params.threshold_near as usize,
                far: params.threshold_far as usize,
            };
            let trained = threshold::train_forest(
                &spec,
                params.epochs.get(),
                vote,
                seed,
                shard,
                candidates,
                &x_train,
                &targets,
                &tick,
            );
            // The candidate's thermometer code.
            (trained, codecs.iter().map(|c| c.levels() - 1).collect())
        }
    };

    let model = Model {
        header: Header {
            codebook_sha256: sha256_file(codebook_path)?,
            params: serde_json::to_value(params).expect("parameters serialize"),
            model: params.model,
            inputs,
            outputs: learned
                .iter()
                .zip(output_widths)
                .map(|(e, width)| (e.variable.clone(), width))
                .collect(),
            vote,
            counter_bound: spec.counter_bound,
            shard: shard.is_part().then_some(shard),
        },
        trees: trained.iter().map(|t| (t.id, t.tree.clone())).collect(),
    };
    model.write(&out_dir.join(MODEL_FILE))?;
    write_log(&out_dir.join(TRAINING_FILE), &trained, &learned, provenance)
}

/// `training.parquet`: one row per tree per epoch.
fn write_log(
    path: &Path,
    trained: &[forest::Trained],
    learned: &[&alnlab_codes::Entry],
    provenance: &Provenance,
) -> Result<()> {
    let rows = trained.iter().flat_map(|t| {
        t.epochs
            .iter()
            .zip(&t.seconds)
            .enumerate()
            .map(move |(k, e)| (t, k, e))
    });
    let (mut variable, mut bit, mut vote, mut epoch) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut errors, mut updates, mut seconds) = (Vec::new(), Vec::new(), Vec::new());
    for (t, k, (e, s)) in rows {
        variable.push(learned[t.id.variable as usize].variable.as_str());
        bit.push(t.id.bit);
        vote.push(t.id.vote);
        epoch.push(k as u32 + 1);
        errors.push(e.errors as u64);
        updates.push(e.updates as u64);
        seconds.push(*s);
    }
    let batch = table::batch(vec![
        (
            "variable",
            Arc::new(StringArray::from(variable)) as Arc<dyn Array>,
        ),
        ("bit", Arc::new(UInt32Array::from(bit))),
        ("vote", Arc::new(UInt32Array::from(vote))),
        ("epoch", Arc::new(UInt32Array::from(epoch))),
        ("errors", Arc::new(UInt64Array::from(errors))),
        ("updates", Arc::new(UInt64Array::from(updates))),
        ("seconds", Arc::new(Float64Array::from(seconds))),
    ]);
    table::write_parquet(path, &batch, provenance)
}
