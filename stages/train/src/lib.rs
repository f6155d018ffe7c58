//! The train stage (paper §3, §4.3, §4.7; docs/design.md §5): reads the codebook
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
pub mod log;
pub mod piecewise;
pub mod pwl;
pub mod select;
pub mod shard;
mod threshold;

use std::path::Path;

use alnlab_codes::bits::encode;
use alnlab_codes::codes::{Code, Codec};
use alnlab_codes::residual::{DeltaSpec, change};
use alnlab_common::hash::sha256_file;
use alnlab_common::params::{self, Count, Fraction, ParamError};
use alnlab_common::{Error, Progress, Provenance, Result};
use alnlab_tables::levels::Levels;
use alnlab_tables::pairs::{Pairs, Side};
use serde::{Deserialize, Serialize};

use alnlab_aln::model::{Base, Header, Model, nominal_input};
use alnlab_aln::shard::Shard;
use alnlab_aln::tree::TreeSpec;
use alnlab_aln::{ModelKind, Output, Target};
use alnlab_codes::bits::Columns;

/// Version of what this stage writes (part of every cache key; 6: model
/// format 5, piecewise-linear models; 7: a piecewise-linear tree's planes
/// fitted through QR, which moves their last bits).
pub const FORMAT_VERSION: u32 = 7;
/// File name of the model.
pub const MODEL_FILE: &str = "model.aln";
/// File name of the training log table.
pub const TRAINING_FILE: &str = "training.parquet";

/// The `[train]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// `bit-forest`, `threshold` or `piecewise-linear`.
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
    /// What the trees learn: each variable's next `level`, or its change
    /// (`delta`, clamped to ±k with k from the training rows).
    pub target: TargetKind,
    /// The code of the change (with `target = "delta"`).
    pub delta_code: Code,
    /// k of each variable is this quantile of |Δ| over the training rows
    /// (at least 1): changes beyond it are learned as ±k.
    pub delta_quantile: Fraction,
    /// Each output's trees read only this many input variables: those with
    /// the highest mutual information with its target on the training rows
    /// ([`select`]). Absent: every input.
    pub informative_inputs: Option<Count>,
    /// Whether the controller's torques g are `learned` like every other
    /// variable or `given`: read as inputs, never predicted (as a planner
    /// gives them). `given` needs the piecewise-linear model.
    pub controls: Controls,
    /// How a piecewise-linear model's trees are trained.
    pub pwl: piecewise::PwlParams,
    /// What a piecewise-linear model's changes advance from: the
    /// `current` state, or the `nominal` simulator's prediction (a hybrid,
    /// [`piecewise`]). Left out of the model's header when `current`, so
    /// a model trained without it is the same file.
    #[serde(skip_serializing_if = "Base::is_current")]
    pub base: Base,
}

/// Whether the controls are predicted (the `controls` key).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Controls {
    /// Every learned variable is predicted, the controls too.
    #[default]
    Learned,
    /// The controls are inputs only.
    Given,
}

/// What the trees learn (the `target` key).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TargetKind {
    /// Each variable's next level, in its codebook code.
    #[default]
    Level,
    /// Each variable's change of level, Δ = next − current.
    Delta,
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
            target: TargetKind::Level,
            delta_code: Code::Gray,
            delta_quantile: Fraction(0.99),
            informative_inputs: None,
            controls: Controls::Learned,
            pwl: piecewise::PwlParams::default(),
            base: Base::Current,
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
        let piecewise = match self.model {
            ModelKind::PiecewiseLinear => true,
            ModelKind::BitForest | ModelKind::Threshold => false,
        };
        if self.controls == Controls::Given && !piecewise {
            return Err((
                "controls".into(),
                format!(
                    "`given` needs model = \"piecewise-linear\"; a {} predicts every learned \
                     variable",
                    self.model.name()
                ),
            ));
        }
        if self.base == Base::Nominal && !piecewise {
            return Err((
                "base".into(),
                format!(
                    "`nominal` needs model = \"piecewise-linear\"; a {} learns levels, not a \
                     correction of real values",
                    self.model.name()
                ),
            ));
        }
        self.pwl.validate()?;
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

/// The files the stage reads.
pub struct Inputs<'a> {
    /// The codebook.
    pub codebook: &'a Path,
    /// The levels table to train on.
    pub levels: &'a Path,
    /// The pairs table the levels were made from (real values).
    pub pairs: &'a Path,
    /// The nominal stage's predictions of the same pairs.
    pub nominal: &'a Path,
}

/// Reads the codebook and levels (and, for a piecewise-linear model, the
/// real values in `pairs.parquet`), trains `shard`'s trees ([`Shard::ALL`]
/// for the whole forest), writes the model (a partial one for a part) and
/// the log.
pub fn run(
    params: &Params,
    seed: u64,
    shard: Shard,
    inputs: &Inputs,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let Inputs {
        codebook: codebook_path,
        levels: levels_path,
        pairs: pairs_path,
        nominal: nominal_path,
    } = *inputs;
    params.validate().map_err(|e| params::invalid("train", e))?;
    let codebook = alnlab_tables::codebook::read(codebook_path)?;
    let levels = Levels::read(levels_path, codebook_path)?;
    let learned: Vec<_> = codebook.learned().collect();
    if learned.is_empty() {
        return Err(Error::bad_file(
            codebook_path,
            "has no learned variable: nothing to train",
        ));
    }
    let codecs = codebook.learned_codecs(codebook_path)?;
    let rows = levels.train_rows();
    if rows.is_empty() {
        return Err(Error::bad_file(levels_path, "has no training rows"));
    }
    let piecewise = match params.model {
        ModelKind::PiecewiseLinear => true,
        ModelKind::BitForest | ModelKind::Threshold => false,
    };
    if piecewise {
        if shard.is_part() {
            return Err(Error::Invalid(
                "a piecewise-linear model trains in one process (its trees are few): it \
                 takes no shard"
                    .into(),
            ));
        }
        let pairs = Pairs::read(pairs_path)?;
        let nominal = match params.base {
            Base::Current => None,
            Base::Nominal => Some(Pairs::read(nominal_path)?),
        };
        let predicted = learned
            .iter()
            .filter(|e| {
                !(params.controls == Controls::Given
                    && alnlab_codes::codebook::is_control(&e.variable))
            })
            .count();
        progress.start("train", predicted as u64, "trees");
        let tick = || progress.advance(1);
        let trained = piecewise::train(
            &params.pwl,
            params.informative_inputs.map(|c| c.get()),
            params.controls == Controls::Given,
            seed,
            &learned,
            &levels,
            &pairs,
            nominal.as_ref(),
            &rows,
            &tick,
        )?;
        let width = learned.len();
        let input_name = |u: usize| match u.checked_sub(width) {
            None => learned[u].variable.clone(),
            Some(v) => nominal_input(&learned[v].variable),
        };
        let model = Model {
            header: Header {
                codebook_sha256: sha256_file(codebook_path)?,
                params: serde_json::to_value(params).expect("parameters serialize"),
                model: params.model,
                target: Target::Change,
                inputs: if nominal.is_some() { 2 * width } else { width },
                outputs: trained
                    .iter()
                    .map(|t| (learned[t.variable].variable.clone(), t.tree.pieces()))
                    .collect(),
                reads: trained
                    .iter()
                    .map(|t| t.reads.iter().map(|&u| input_name(u)).collect())
                    .collect(),
                vote: 1,
                counter_bound: 0,
                shard: None,
                base: params.base,
            },
            trees: Vec::new(),
            pieces: trained.iter().map(|t| t.tree.clone()).collect(),
        };
        model.write(&out_dir.join(MODEL_FILE))?;
        return write_rounds(&out_dir.join(TRAINING_FILE), &trained, &learned, provenance);
    }
    let x_columns: Vec<&[u16]> = learned
        .iter()
        .map(|e| levels.column(Side::Current, e))
        .collect::<Result<_>>()?;
    let y_columns: Vec<&[u16]> = learned
        .iter()
        .map(|e| levels.column(Side::Next, e))
        .collect::<Result<_>>()?;
    let codec_refs: Vec<&Codec> = codecs.iter().collect();
    let x_bits = encode(&codec_refs, &x_columns);
    let inputs = x_bits.bits();

    let target = match params.target {
        TargetKind::Level => Target::Level,
        TargetKind::Delta => Target::Delta(
            learned
                .iter()
                .zip(x_columns.iter().zip(&y_columns))
                .map(|(e, (x, y))| DeltaSpec {
                    k: change_limit(x, y, &rows, e.period(), params.delta_quantile),
                    period: e.period(),
                    code: params.delta_code,
                })
                .collect(),
        ),
    };
    let outputs = Output::for_entries(&target, &learned)
        .map_err(|m| Error::bad_file(codebook_path, format!("{} target: {m}", target.kind())))?;
    // What each variable's trees learn, on every row: its next level or its
    // change, as a level of the output's code.
    let y_targets: Vec<Vec<u16>> = outputs
        .iter()
        .zip(x_columns.iter().zip(&y_columns))
        .map(|(o, (x, y))| x.iter().zip(*y).map(|(&x, &y)| o.target(x, y)).collect())
        .collect();

    // The input variables each output's trees read, and their bits.
    let read_variables: Option<Vec<Vec<usize>>> = params.informative_inputs.map(|count| {
        let targets: Vec<&[u16]> = y_targets.iter().map(Vec::as_slice).collect();
        select::informative(&x_columns, &targets, &rows, count.get())
    });
    let mut offsets = vec![0u32];
    codecs
        .iter()
        .for_each(|c| offsets.push(offsets.last().unwrap() + c.width()));
    let reads: Vec<Vec<u32>> = match &read_variables {
        Some(chosen) => chosen
            .iter()
            .map(|vars| {
                vars.iter()
                    .flat_map(|&u| offsets[u]..offsets[u + 1])
                    .collect()
            })
            .collect(),
        None => forest::every_bit(inputs, learned.len()),
    };

    let vote = params.vote.0 as u32;
    let tick = || progress.advance(1);
    let spec = params.tree_spec(inputs);
    let (trained, output_widths) = match params.model {
        ModelKind::BitForest => {
            let inputs = Columns::from_rows(&x_bits, &rows);
            let targets: Vec<Columns> = outputs
                .iter()
                .zip(&y_targets)
                .map(|(o, y)| Columns::from_rows(&encode(&[o.codec()], &[y]), &rows))
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
                &reads,
                &tick,
            );
            (trained, widths)
        }
        ModelKind::PiecewiseLinear => unreachable!("trained above"),
        ModelKind::Threshold => {
            // The training rows alone, in order, with their targets.
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
            let y_train: Vec<Vec<u16>> = y_targets
                .iter()
                .map(|y| rows.iter().map(|&r| y[r]).collect())
                .collect();
            let targets: Vec<(&[u16], usize)> = y_train
                .iter()
                .zip(&outputs)
                .map(|(y, o)| (y.as_slice(), o.codec().levels()))
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
                &reads,
                &targets,
                &tick,
            );
            // The candidate's thermometer code.
            let widths = outputs.iter().map(|o| o.codec().levels() - 1).collect();
            (trained, widths)
        }
    };

    let model = Model {
        header: Header {
            codebook_sha256: sha256_file(codebook_path)?,
            params: serde_json::to_value(params).expect("parameters serialize"),
            model: params.model,
            target,
            inputs,
            reads: read_variables
                .iter()
                .flatten()
                .map(|vars| vars.iter().map(|&u| learned[u].variable.clone()).collect())
                .collect(),
            outputs: learned
                .iter()
                .zip(output_widths)
                .map(|(e, width)| (e.variable.clone(), width))
                .collect(),
            vote,
            counter_bound: spec.counter_bound,
            shard: shard.is_part().then_some(shard),
            base: Base::Current,
        },
        trees: trained.iter().map(|t| (t.id, t.tree.clone())).collect(),
        pieces: Vec::new(),
    };
    model.write(&out_dir.join(MODEL_FILE))?;
    write_log(&out_dir.join(TRAINING_FILE), &trained, &learned, provenance)
}

/// The k of a variable's change: the `quantile` of |Δ| over the training
/// `rows` (the ⌈q·n⌉-th smallest), at least 1.
fn change_limit(
    x: &[u16],
    y: &[u16],
    rows: &[usize],
    period: Option<u32>,
    quantile: Fraction,
) -> u32 {
    let mut sizes: Vec<u32> = rows
        .iter()
        .map(|&r| change(x[r], y[r], period).unsigned_abs())
        .collect();
    let rank = ((quantile.get() * sizes.len() as f64).ceil() as usize).clamp(1, sizes.len());
    let (_, kth, _) = sizes.select_nth_unstable(rank - 1);
    (*kth).max(1)
}

/// A bit model's log: one row per tree per epoch.
fn write_log(
    path: &Path,
    trained: &[forest::Trained],
    learned: &[&alnlab_codes::Entry],
    provenance: &Provenance,
) -> Result<()> {
    let rows = trained
        .iter()
        .flat_map(|t| {
            t.epochs
                .iter()
                .zip(&t.seconds)
                .enumerate()
                .map(move |(k, (e, s))| log::Epoch {
                    variable: learned[t.id.variable as usize].variable.clone(),
                    bit: t.id.bit,
                    vote: t.id.vote,
                    epoch: k as u32 + 1,
                    errors: e.errors as u64,
                    updates: e.updates as u64,
                    seconds: *s,
                })
        })
        .collect();
    log::write(path, &log::Log::Epochs(rows), provenance)
}

/// A piecewise-linear model's log: one row per tree per round of growth.
fn write_rounds(
    path: &Path,
    trained: &[piecewise::TrainedTree],
    learned: &[&alnlab_codes::Entry],
    provenance: &Provenance,
) -> Result<()> {
    let rows = trained
        .iter()
        .flat_map(|t| {
            t.rounds.iter().enumerate().map(move |(k, r)| log::Round {
                variable: learned[t.variable].variable.clone(),
                round: k as u32 + 1,
                pieces: r.pieces as u32,
                splits: r.splits as u32,
                rms: r.rms,
                mean_absolute: r.mean_absolute,
            })
        })
        .collect();
    log::write(path, &log::Log::Rounds(rows), provenance)
}
