//! The summarize stage (paper §4.5–4.6; docs/design.md §6): reads
//! `predictions.parquet` and `rollout.parquet` and writes
//! - `summary.parquet` — per set of rows (all test rows, and the held-out
//!   ones alone: with the paper's split the test rows include training
//!   rows), model (the ALN and each baseline) and variable, the error
//!   statistics of [`stats`], and which variables are the best and the
//!   worst of their group;
//! - `comparisons.parquet` — per set of rows, the ALN against each other
//!   model on the same rows: the mean paired difference of their errors,
//!   per variable and averaged over the variables, with its confidence
//!   interval and verdict ([`paired`]);
//! - `horizons.parquet`, the closed-loop errors per set of rows (all
//!   starts, the held-out ones), model and horizon, over all variables.
//!
//! The report that reads these tables (and every other stage's) is a view
//! of its own, `alnlab-report` (`views/report`).

pub mod bench;
pub mod paired;
pub mod signed_rank;
pub mod stats;

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;

use alnlab_codes::group_of;
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, ModelId, Progress, Provenance, Result};
use alnlab_tables::rollout::Rollout;
use arrow_array::{
    Array, BooleanArray, Float64Array, StringArray, UInt16Array, UInt32Array, UInt64Array,
};

use crate::paired::Interval;
use crate::stats::{ErrorCounts, ErrorStats, HISTOGRAM_BINS};

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 5;
/// File name of the summary table.
pub const SUMMARY_FILE: &str = "summary.parquet";
/// File name of the paired-comparisons table.
pub const COMPARISONS_FILE: &str = "comparisons.parquet";
/// File name of the closed-loop table.
pub const HORIZONS_FILE: &str = "horizons.parquet";

/// Which test rows a figure is over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rows {
    /// Every test row.
    All,
    /// The test rows held out of training (all of them, unless the split
    /// lets test rows be training rows too, as the paper's does).
    HeldOut,
}

impl Rows {
    /// The name in the tables' `rows` column.
    pub fn as_str(self) -> &'static str {
        match self {
            Rows::All => "all",
            Rows::HeldOut => "held-out",
        }
    }

    fn parse(name: &str) -> Option<Rows> {
        [Rows::All, Rows::HeldOut]
            .into_iter()
            .find(|r| r.as_str() == name)
    }
}

/// One row of `summary.parquet`.
#[derive(Clone, Debug, PartialEq)]
pub struct SummaryRow {
    pub rows: Rows,
    pub model: ModelId,
    pub variable: String,
    pub group: String,
    pub stats: ErrorStats,
    /// The standard deviation (n − 1) of the variable's true levels over the
    /// rows: the scale of a normalized error (mean error / this), which
    /// compares across ranges, level counts and codes.
    pub true_std_dev: f64,
    /// The lowest mean error of its group, for its model.
    pub best_in_group: bool,
    /// The highest mean error of its group, for its model.
    pub worst_in_group: bool,
}

/// One row of `horizons.parquet`: a model's closed-loop errors after
/// `horizon` steps, over all variables and the starts of one set of rows
/// (all, or those held out of training).
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonRow {
    pub rows: Rows,
    pub model: ModelId,
    pub horizon: u16,
    pub stats: ErrorStats,
}

/// One row of `comparisons.parquet`: the ALN (`model`) against another
/// model on the same rows, the interval of the mean of their paired
/// differences in error (model − against; below zero, the ALN's errors are
/// lower).
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    pub rows: Rows,
    pub model: ModelId,
    pub against: ModelId,
    /// The variable, or `None` for the errors averaged over the variables
    /// (one difference per row: the mean over the variables of that row).
    pub variable: Option<String>,
    pub difference: Interval,
}

/// The files the stage reads.
pub struct Inputs<'a> {
    /// The test stage's predictions.
    pub predictions: &'a Path,
    /// Its closed-loop rollouts.
    pub rollout: &'a Path,
}

/// Reads the predictions and rollouts, summarizes them, writes
/// `summary.parquet`, `comparisons.parquet` and `horizons.parquet`.
pub fn run(
    inputs: &Inputs,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let Inputs {
        predictions: predictions_path,
        rollout: rollout_path,
    } = *inputs;
    progress.start("summarize", 3, "tables");
    let predictions = Predictions::read(predictions_path)?;
    write(
        &out_dir.join(SUMMARY_FILE),
        &predictions.summarize(),
        provenance,
    )?;
    progress.advance(1);
    write_comparisons(
        &out_dir.join(COMPARISONS_FILE),
        &predictions.compare(ModelId::Aln),
        provenance,
    )?;
    progress.advance(1);
    let horizons = summarize_horizons(rollout_path, &predictions.held_out_rows())?;
    write_horizons(&out_dir.join(HORIZONS_FILE), &horizons, provenance)?;
    progress.advance(1);
    Ok(())
}

/// The closed-loop rows of a rollout table, by set of rows (all starts,
/// then the starts among `held_out`, if any), model and horizon.
pub fn summarize_horizons(
    rollout_path: &Path,
    held_out: &BTreeSet<u32>,
) -> Result<Vec<HorizonRow>> {
    let rollout = Rollout::read(rollout_path)?;
    let held: Vec<bool> = rollout
        .starts()
        .iter()
        .map(|s| held_out.contains(s))
        .collect();
    let mut rows = Vec::new();
    for (set, rows_of) in [Rows::All, Rows::HeldOut].into_iter().enumerate() {
        for (m, model) in rollout.models().iter().enumerate() {
            for h in 1..=rollout.horizons() {
                let mut counts = ErrorCounts::default();
                for v in 0..rollout.variables().len() {
                    let errors = rollout.errors(m, v, h).iter().zip(&held);
                    for (&e, _) in errors.filter(|&(_, &held)| set == 0 || held) {
                        counts.add(u32::from(e), 1);
                    }
                }
                if let Some(stats) = counts.stats() {
                    rows.push(HorizonRow {
                        rows: rows_of,
                        model: *model,
                        horizon: h,
                        stats,
                    });
                }
            }
        }
    }
    Ok(rows)
}

fn write_horizons(path: &Path, rows: &[HorizonRow], provenance: &Provenance) -> Result<()> {
    let number = |f: fn(&ErrorStats) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(
            rows.iter().map(|r| f(&r.stats)),
        ))
    };
    let batch = table::batch(vec![
        (
            "rows",
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.rows.as_str()),
            )) as Arc<dyn Array>,
        ),
        ("model", names(rows.iter().map(|r| r.model))),
        (
            "horizon",
            Arc::new(UInt16Array::from_iter_values(
                rows.iter().map(|r| r.horizon),
            )),
        ),
        (
            "n",
            Arc::new(UInt64Array::from_iter_values(
                rows.iter().map(|r| r.stats.n),
            )),
        ),
        ("mean", number(|s| s.mean)),
        ("trimmed_mean", number(|s| s.trimmed_mean)),
        ("median", number(|s| s.median)),
        ("p95", number(|s| s.p95)),
        (
            "max",
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|r| r.stats.max),
            )),
        ),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// One row of `horizons.parquet` as read back.
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonFigures {
    pub rows: Rows,
    pub model: ModelId,
    /// Steps fed back (1 is the first prediction).
    pub horizon: u16,
    /// Errors pooled: one per start and variable.
    pub n: u64,
    pub mean: f64,
    /// The 95th percentile.
    pub p95: f64,
}

/// Reads `horizons.parquet` back.
pub fn read_horizons(path: &Path) -> Result<Vec<HorizonFigures>> {
    let table = Table::read(path)?;
    let sets = rows_column(&table, path)?;
    let models: Vec<ModelId> = table.parsed("model")?;
    let horizons = table.column::<UInt16Array>("horizon")?.values();
    let n = table.column::<UInt64Array>("n")?.values();
    let (mean, p95) = (
        table.f64_column("mean")?.values(),
        table.f64_column("p95")?.values(),
    );
    Ok((0..table.num_rows())
        .map(|i| HorizonFigures {
            rows: sets[i],
            model: models[i],
            horizon: horizons[i],
            n: n[i],
            mean: mean[i],
            p95: p95[i],
        })
        .collect())
}

/// The errors of a predictions table, by model and variable.
pub struct Predictions {
    models: Vec<ModelId>,
    variables: Vec<String>,
    /// `errors[m * variables + v]`: model m's errors on variable v, one
    /// per test row, in the same row order for every model and variable.
    errors: Vec<Vec<u16>>,
    /// Per test row, whether it was held out of training.
    held_out: Vec<bool>,
    /// Per test row, its row in `levels.parquet`.
    row_ids: Vec<u32>,
    /// `truth[v]`: variable v's true levels, per test row.
    truth: Vec<Vec<u16>>,
}

impl Predictions {
    /// Reads `predictions.parquet` ([`alnlab_tables::predictions`]).
    pub fn read(path: &Path) -> Result<Predictions> {
        Ok(Predictions::of(
            &alnlab_tables::predictions::Predictions::read(path)?,
        ))
    }

    /// The errors of `table`'s predictions.
    pub fn of(table: &alnlab_tables::predictions::Predictions) -> Predictions {
        let (models, variables) = (table.models().len(), table.variables().len());
        Predictions {
            models: table.models().to_vec(),
            variables: table.variables().to_vec(),
            errors: (0..models * variables)
                .map(|k| table.errors(k / variables, k % variables).collect())
                .collect(),
            held_out: table.held_out().to_vec(),
            row_ids: table.rows().to_vec(),
            truth: (0..variables).map(|v| table.truth(v).to_vec()).collect(),
        }
    }

    /// The test rows (in `levels.parquet`) held out of training.
    pub fn held_out_rows(&self) -> BTreeSet<u32> {
        self.row_ids
            .iter()
            .zip(&self.held_out)
            .filter(|&(_, &h)| h)
            .map(|(&r, _)| r)
            .collect()
    }

    /// The sets of rows there are: all, and the held-out ones if any.
    fn row_sets(&self) -> Vec<(Rows, Vec<usize>)> {
        let all: Vec<usize> = (0..self.held_out.len()).collect();
        let held: Vec<usize> = all.iter().copied().filter(|&r| self.held_out[r]).collect();
        let mut sets = vec![(Rows::All, all)];
        if !held.is_empty() {
            sets.push((Rows::HeldOut, held));
        }
        sets
    }

    fn errors(&self, model: usize, variable: usize) -> &[u16] {
        &self.errors[model * self.variables.len() + variable]
    }

    /// The summary rows: per set of rows, model and variable, in the order
    /// of the table's dictionaries.
    pub fn summarize(&self) -> Vec<SummaryRow> {
        let mut out = Vec::new();
        let counts_of = |values: &[u16], set: &[usize]| {
            let mut counts = ErrorCounts::default();
            for &r in set {
                counts.add(u32::from(values[r]), 1);
            }
            counts
        };
        for (rows, set) in self.row_sets() {
            // The true levels' spread is the variable's, whichever model.
            let true_std_dev: Vec<f64> = self
                .truth
                .iter()
                .map(|truth| {
                    counts_of(truth, &set)
                        .stats()
                        .map_or(f64::NAN, |t| t.std_dev)
                })
                .collect();
            for (m, model) in self.models.iter().enumerate() {
                let first = out.len();
                for (v, variable) in self.variables.iter().enumerate() {
                    if let Some(stats) = counts_of(self.errors(m, v), &set).stats() {
                        out.push(SummaryRow {
                            rows,
                            model: *model,
                            variable: variable.clone(),
                            group: group_of(variable).to_string(),
                            true_std_dev: true_std_dev[v],
                            stats,
                            best_in_group: false,
                            worst_in_group: false,
                        });
                    }
                }
                mark_best_and_worst(&mut out[first..]);
            }
        }
        out
    }

    /// `model` against every other model, per set of rows: per variable,
    /// then averaged over the variables.
    pub fn compare(&self, model: ModelId) -> Vec<Comparison> {
        let Some(a) = self.models.iter().position(|&m| m == model) else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for (rows, set) in self.row_sets() {
            for (b, against) in self.models.iter().enumerate().filter(|&(b, _)| b != a) {
                let mut per_row = vec![0.0; set.len()];
                for v in 0..self.variables.len() {
                    let (ea, eb) = (self.errors(a, v), self.errors(b, v));
                    let differences: Vec<f64> = set
                        .iter()
                        .map(|&r| f64::from(ea[r]) - f64::from(eb[r]))
                        .collect();
                    for (sum, d) in per_row.iter_mut().zip(&differences) {
                        *sum += d;
                    }
                    if let Some(difference) = Interval::of(&differences) {
                        out.push(Comparison {
                            rows,
                            model,
                            against: *against,
                            variable: Some(self.variables[v].clone()),
                            difference,
                        });
                    }
                }
                let variables = self.variables.len() as f64;
                for d in &mut per_row {
                    *d /= variables;
                }
                if let Some(difference) = Interval::of(&per_row) {
                    out.push(Comparison {
                        rows,
                        model,
                        against: *against,
                        variable: None,
                        difference,
                    });
                }
            }
        }
        out
    }
}

/// The summary rows of a predictions table (see [`Predictions::summarize`]).
pub fn summarize(predictions_path: &Path) -> Result<Vec<SummaryRow>> {
    Ok(Predictions::read(predictions_path)?.summarize())
}

/// Marks, per group, the variable of lowest and of highest mean error (the
/// first of equals).
fn mark_best_and_worst(rows: &mut [SummaryRow]) {
    let mut groups: Vec<String> = rows.iter().map(|r| r.group.clone()).collect();
    groups.sort();
    groups.dedup();
    for group in groups {
        let (mut best, mut worst) = (None::<usize>, None::<usize>);
        for (i, row) in rows.iter().enumerate().filter(|(_, r)| r.group == group) {
            let mean = row.stats.mean;
            if best.is_none_or(|b| mean < rows[b].stats.mean) {
                best = Some(i);
            }
            if worst.is_none_or(|w| mean > rows[w].stats.mean) {
                worst = Some(i);
            }
        }
        if let (Some(best), Some(worst)) = (best, worst) {
            rows[best].best_in_group = true;
            rows[worst].worst_in_group = true;
        }
    }
}

/// A text column of models' names.
fn names(models: impl Iterator<Item = ModelId>) -> Arc<dyn Array> {
    Arc::new(StringArray::from_iter_values(models.map(|m| m.to_string())))
}

fn write(path: &Path, rows: &[SummaryRow], provenance: &Provenance) -> Result<()> {
    let text = |f: fn(&SummaryRow) -> &str| -> Arc<dyn Array> {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
    };
    let number = |f: fn(&ErrorStats) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(
            rows.iter().map(|r| f(&r.stats)),
        ))
    };
    let flag = |f: fn(&SummaryRow) -> bool| -> Arc<dyn Array> {
        Arc::new(BooleanArray::from(rows.iter().map(f).collect::<Vec<_>>()))
    };
    let mut columns: Vec<(String, Arc<dyn Array>)> = vec![
        ("rows".into(), text(|r| r.rows.as_str())),
        ("model".into(), names(rows.iter().map(|r| r.model))),
        ("variable".into(), text(|r| &r.variable)),
        ("group".into(), text(|r| &r.group)),
        (
            "n".into(),
            Arc::new(UInt64Array::from_iter_values(
                rows.iter().map(|r| r.stats.n),
            )),
        ),
        ("mean".into(), number(|s| s.mean)),
        ("std_dev".into(), number(|s| s.std_dev)),
        ("std_err".into(), number(|s| s.std_err)),
        ("trimmed_mean".into(), number(|s| s.trimmed_mean)),
        ("median".into(), number(|s| s.median)),
        ("iqr".into(), number(|s| s.iqr)),
        (
            "true_std_dev".into(),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.true_std_dev),
            )),
        ),
        ("p95".into(), number(|s| s.p95)),
        (
            "max".into(),
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|r| r.stats.max),
            )),
        ),
    ];
    for bin in 0..HISTOGRAM_BINS {
        let name = histogram_column(bin);
        let counts = rows.iter().map(|r| r.stats.histogram[bin]);
        columns.push((name, Arc::new(UInt64Array::from_iter_values(counts))));
    }
    columns.push(("best_in_group".into(), flag(|r| r.best_in_group)));
    columns.push(("worst_in_group".into(), flag(|r| r.worst_in_group)));
    let batch = table::batch(
        columns
            .iter()
            .map(|(n, a)| (n.as_str(), a.clone()))
            .collect(),
    );
    table::write_parquet(path, &batch, provenance)
}

/// A table's `rows` column, parsed.
fn rows_column(table: &Table, path: &Path) -> Result<Vec<Rows>> {
    table
        .strings("rows")?
        .iter()
        .enumerate()
        .map(|(i, name)| {
            Rows::parse(name).ok_or_else(|| {
                Error::bad_file(
                    path,
                    format!("row {i}: rows `{name}` is neither `all` nor `held-out`"),
                )
            })
        })
        .collect()
}

/// The summary column of histogram bin `bin`: `hist_7`, `hist_10_19`,
/// `hist_100_plus`.
fn histogram_column(bin: usize) -> String {
    format!(
        "hist_{}",
        stats::histogram_bin_name(bin)
            .replace('–', "_")
            .replace('+', "_plus")
    )
}

/// Reads `summary.parquet` back.
pub fn read(path: &Path) -> Result<Vec<SummaryRow>> {
    let table = Table::read(path)?;
    let text = |name: &str| table.strings(name);
    let number = |name: &str| -> Result<&[f64]> { Ok(table.f64_column(name)?.values()) };
    let models: Vec<ModelId> = table.parsed("model")?;
    let (variables, groups) = (text("variable")?, text("group")?);
    let sets = rows_column(&table, path)?;
    let n = table.column::<UInt64Array>("n")?.values();
    let max = table.column::<UInt32Array>("max")?.values();
    let (mean, std_dev, std_err) = (number("mean")?, number("std_dev")?, number("std_err")?);
    let (trimmed, median, iqr, p95) = (
        number("trimmed_mean")?,
        number("median")?,
        number("iqr")?,
        number("p95")?,
    );
    let bins: Vec<&[u64]> = (0..HISTOGRAM_BINS)
        .map(|bin| {
            let name = histogram_column(bin);
            Ok(table.column::<UInt64Array>(&name)?.values().as_ref())
        })
        .collect::<Result<_>>()?;
    let true_std_dev = number("true_std_dev")?;
    let best = table.column::<BooleanArray>("best_in_group")?;
    let worst = table.column::<BooleanArray>("worst_in_group")?;
    Ok((0..table.num_rows())
        .map(|i| SummaryRow {
            rows: sets[i],
            model: models[i],
            variable: variables[i].clone(),
            group: groups[i].clone(),
            stats: ErrorStats {
                n: n[i],
                mean: mean[i],
                std_dev: std_dev[i],
                std_err: std_err[i],
                trimmed_mean: trimmed[i],
                median: median[i],
                iqr: iqr[i],
                p95: p95[i],
                max: max[i],
                histogram: std::array::from_fn(|bin| bins[bin][i]),
            },
            true_std_dev: true_std_dev[i],
            best_in_group: best.value(i),
            worst_in_group: worst.value(i),
        })
        .collect())
}

fn write_comparisons(path: &Path, rows: &[Comparison], provenance: &Provenance) -> Result<()> {
    let text = |f: fn(&Comparison) -> &str| -> Arc<dyn Array> {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
    };
    let number = |f: fn(&Interval) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(
            rows.iter().map(|r| f(&r.difference)),
        ))
    };
    let batch = table::batch(vec![
        ("rows", text(|r| r.rows.as_str())),
        ("model", names(rows.iter().map(|r| r.model))),
        ("against", names(rows.iter().map(|r| r.against))),
        (
            "variable",
            Arc::new(StringArray::from(
                rows.iter()
                    .map(|r| r.variable.as_deref())
                    .collect::<Vec<_>>(),
            )),
        ),
        (
            "n",
            Arc::new(UInt64Array::from_iter_values(
                rows.iter().map(|r| r.difference.n),
            )),
        ),
        ("mean_difference", number(|i| i.mean)),
        ("std_dev", number(|i| i.std_dev)),
        ("ci_low", number(|i| i.low)),
        ("ci_high", number(|i| i.high)),
        ("verdict", text(|r| r.difference.verdict().as_str())),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// Reads `comparisons.parquet` back.
pub fn read_comparisons(path: &Path) -> Result<Vec<Comparison>> {
    let table = Table::read(path)?;
    let number = |name: &str| -> Result<&[f64]> { Ok(table.f64_column(name)?.values()) };
    let sets = rows_column(&table, path)?;
    let (models, against): (Vec<ModelId>, Vec<ModelId>) =
        (table.parsed("model")?, table.parsed("against")?);
    let variables = table.column::<StringArray>("variable")?;
    let n = table.column::<UInt64Array>("n")?.values();
    let (mean, std_dev, low, high) = (
        number("mean_difference")?,
        number("std_dev")?,
        number("ci_low")?,
        number("ci_high")?,
    );
    (0..table.num_rows())
        .map(|i| {
            Ok(Comparison {
                rows: sets[i],
                model: models[i],
                against: against[i],
                variable: variables
                    .is_valid(i)
                    .then(|| variables.value(i).to_string()),
                difference: Interval {
                    n: n[i],
                    mean: mean[i],
                    std_dev: std_dev[i],
                    low: low[i],
                    high: high[i],
                },
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[test]
    fn summaries_per_model_and_variable_with_group_extremes_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let provenance = Provenance {
            stage: "test".into(),
            params: serde_json::Value::Null,
            inputs: BTreeMap::new(),
        };
        // Two models × three variables (two in group a, one in v) × three
        // test rows, the first a training row too: errors (model, variable)
        // → per row.
        let errors: [(u16, u16, [u16; 3]); 6] = [
            (0, 0, [0, 1, 2]),
            (0, 1, [4, 4, 4]),
            (0, 2, [7, 7, 7]),
            (1, 0, [3, 3, 3]),
            (1, 1, [0, 0, 0]),
            (1, 2, [1, 1, 1]),
        ];
        let mut table = alnlab_tables::predictions::Predictions::new(
            &["a.1.x", "a.2.x", "v.1.x"],
            &[None; 3],
            &[10, 11, 12],
            &[false, true, true],
            &vec![vec![20, 22, 24]; 3],
        );
        for (m, model) in [ModelId::Aln, ModelId::Persistence].into_iter().enumerate() {
            // Predicted above the truth by the error.
            let levels: Vec<Vec<u16>> = errors[3 * m..3 * m + 3]
                .iter()
                .map(|(_, _, list)| list.iter().zip([20, 22, 24]).map(|(e, t)| t + e).collect())
                .collect();
            table.push_model(model, &levels);
        }
        let predictions = dir.path().join("predictions.parquet");
        table.write(&predictions, &provenance).unwrap();
        // The rollout, two steps from starts 10 and 11 (held out): errors
        // by model, then step, then variable.
        let mut rollout = Rollout::new(&["a.1.x", "a.2.x", "v.1.x"], &[10, 11], 2);
        rollout.push_model(
            ModelId::Aln,
            &[
                vec![vec![3, 1], vec![0, 0], vec![2, 2]],
                vec![vec![9, 5], vec![0, 0], vec![0, 0]],
            ],
        );
        rollout.push_model(
            ModelId::Persistence,
            &[vec![vec![0, 0]; 3], vec![vec![1, 1]; 3]],
        );
        let rollout_path = dir.path().join("rollout.parquet");
        rollout.write(&rollout_path, &provenance).unwrap();
        let silent = alnlab_common::Silent;
        run(
            &Inputs {
                predictions: &predictions,
                rollout: &rollout_path,
            },
            &provenance,
            dir.path(),
            &silent,
        )
        .unwrap();
        let horizons = read_horizons(&dir.path().join(HORIZONS_FILE)).unwrap();
        // Over all starts' variables (six errors a step); over the held-out
        // start's (row 11, not 10: three errors a step).
        let figures: Vec<_> = horizons
            .iter()
            .map(|h| (h.rows, h.model, h.horizon, h.n, h.mean))
            .collect();
        assert_eq!(
            figures,
            [
                (Rows::All, ModelId::Aln, 1, 6, 8.0 / 6.0),
                (Rows::All, ModelId::Aln, 2, 6, 14.0 / 6.0),
                (Rows::All, ModelId::Persistence, 1, 6, 0.0),
                (Rows::All, ModelId::Persistence, 2, 6, 1.0),
                (Rows::HeldOut, ModelId::Aln, 1, 3, 1.0),
                (Rows::HeldOut, ModelId::Aln, 2, 3, 5.0 / 3.0),
                (Rows::HeldOut, ModelId::Persistence, 1, 3, 0.0),
                (Rows::HeldOut, ModelId::Persistence, 2, 3, 1.0),
            ]
        );
        let rows = read(&dir.path().join(SUMMARY_FILE)).unwrap();
        // (Compared as text: std dev is NaN for n = 1, and NaN ≠ NaN.)
        let computed = summarize(&predictions).unwrap();
        assert_eq!(
            format!("{rows:?}"),
            format!("{computed:?}"),
            "written = computed"
        );
        let row = |model: ModelId, variable: &str| {
            rows.iter()
                .find(|r| r.rows == Rows::All && r.model == model && r.variable == variable)
                .unwrap()
        };
        let first = row(ModelId::Aln, "a.1.x");
        assert_eq!(first.stats, ErrorCounts::of([0, 1, 2]).stats().unwrap());
        assert_eq!(first.group, "a");
        assert!(first.best_in_group && !first.worst_in_group);
        assert!(row(ModelId::Aln, "a.2.x").worst_in_group);
        let alone = row(ModelId::Aln, "v.1.x");
        assert!(
            alone.best_in_group && alone.worst_in_group,
            "alone in its group"
        );
        // The held-out rows alone: the last two.
        let held = rows
            .iter()
            .find(|r| r.rows == Rows::HeldOut && r.model == ModelId::Aln && r.variable == "a.1.x")
            .unwrap();
        assert_eq!(held.stats, ErrorCounts::of([1, 2]).stats().unwrap());
        // True levels 20, 22, 24: std dev 2; held out, 22 and 24: √2.
        assert_eq!(first.true_std_dev, 2.0);
        assert_eq!(held.true_std_dev, 2f64.sqrt());
        assert_eq!(
            rows.len(),
            2 * 2 * 3,
            "two sets of rows × two models × three variables"
        );

        // The ALN against persistence, paired on the same rows.
        let comparisons = read_comparisons(&dir.path().join(COMPARISONS_FILE)).unwrap();
        let find = |set: Rows, variable: Option<&str>| {
            comparisons
                .iter()
                .find(|c| c.rows == set && c.variable.as_deref() == variable)
                .unwrap()
                .difference
        };
        // a.1.x: −3, −2, −1: mean −2, s = 1, t(0.975, 2) = 4.3027.
        let a1 = find(Rows::All, Some("a.1.x"));
        assert_eq!((a1.n, a1.mean, a1.std_dev), (3, -2.0, 1.0));
        assert!((a1.high - (-2.0 + 4.302652729749464 / 3f64.sqrt())).abs() < 1e-9);
        assert_eq!(a1.verdict(), crate::paired::Verdict::Indistinguishable);
        // a.2.x: always 4 higher.
        assert_eq!(
            find(Rows::All, Some("a.2.x")).verdict(),
            crate::paired::Verdict::Higher
        );
        // Averaged over the variables, per row: 7/3, 8/3, 3; held out: 8/3, 3.
        let mean = find(Rows::All, None);
        assert!((mean.mean - 8.0 / 3.0).abs() < 1e-12 && (mean.std_dev - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(find(Rows::HeldOut, None).n, 2);
        assert!(
            comparisons
                .iter()
                .all(|c| c.model == ModelId::Aln && c.against == ModelId::Persistence)
        );
        assert_eq!(comparisons.len(), 2 * (3 + 1));
        // Per model: for persistence a.2.x is the best of group a.
        assert!(row(ModelId::Persistence, "a.2.x").best_in_group);
        assert!(row(ModelId::Persistence, "a.1.x").worst_in_group);
    }
}
