//! The summarize stage (paper §4.5–4.6; DESIGN.md §6–7): reads
//! `predictions.parquet` and `rollout.parquet` and writes `summary.parquet` —
//! per model (the ALN and each baseline) and variable, the error statistics
//! of [`stats`], and which variables are the best and the worst of their
//! group — and `horizons.parquet`, the closed-loop errors per model and
//! horizon, over all variables and starts. [`report`]
//! renders a run's summaries, timings and training logs as Markdown and SVG.

pub mod bench;
mod charts;
pub mod report;
mod stats;

use std::path::Path;
use std::sync::Arc;

use alnlab_codes::group_of;
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Progress, Provenance, Result};
use arrow_array::cast::AsArray;
use arrow_array::types::UInt16Type;
use arrow_array::{
    Array, BooleanArray, DictionaryArray, Float64Array, StringArray, UInt16Array, UInt32Array,
    UInt64Array,
};

use crate::stats::{ErrorCounts, ErrorStats, HISTOGRAM_BINS};

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 2;
/// File name of the summary table.
pub const SUMMARY_FILE: &str = "summary.parquet";
/// File name of the closed-loop table.
pub const HORIZONS_FILE: &str = "horizons.parquet";
/// File name of the report.
pub const REPORT_FILE: &str = "report.md";

/// One row of `summary.parquet`.
#[derive(Clone, Debug, PartialEq)]
pub struct SummaryRow {
    pub model: String,
    pub variable: String,
    pub group: String,
    pub stats: ErrorStats,
    /// The lowest mean error of its group, for its model.
    pub best_in_group: bool,
    /// The highest mean error of its group, for its model.
    pub worst_in_group: bool,
}

/// One row of `horizons.parquet`: a model's closed-loop errors after
/// `horizon` steps, over all variables and starts.
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonRow {
    pub model: String,
    pub horizon: u16,
    pub stats: ErrorStats,
}

/// Reads the predictions and rollouts, summarizes them, writes
/// `summary.parquet` and `horizons.parquet`.
pub fn run(
    predictions_path: &Path,
    rollout_path: &Path,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    progress.start("summarize", 2, "tables");
    let rows = summarize(predictions_path)?;
    write(&out_dir.join(SUMMARY_FILE), &rows, provenance)?;
    progress.advance(1);
    let horizons = summarize_horizons(rollout_path)?;
    write_horizons(&out_dir.join(HORIZONS_FILE), &horizons, provenance)?;
    progress.advance(1);
    Ok(())
}

/// The closed-loop rows of a rollout table, by model then horizon.
pub fn summarize_horizons(rollout_path: &Path) -> Result<Vec<HorizonRow>> {
    let table = Table::read_columns(rollout_path, &["model", "horizon", "error"])?;
    let models = table.column::<DictionaryArray<UInt16Type>>("model")?;
    let horizons = table.column::<UInt16Array>("horizon")?.values();
    let errors = table.column::<UInt16Array>("error")?.values();
    let names = dictionary_names(models, rollout_path)?;
    let last = horizons.iter().copied().max().unwrap_or(0) as usize;
    let mut counts = vec![ErrorCounts::default(); names.len() * (last + 1)];
    for ((&m, &h), &e) in models.keys().values().iter().zip(horizons).zip(errors) {
        counts[usize::from(m) * (last + 1) + usize::from(h)].add(u32::from(e), 1);
    }
    let mut rows = Vec::new();
    for (m, model) in names.iter().enumerate() {
        for h in 0..=last {
            if let Some(stats) = counts[m * (last + 1) + h].stats() {
                rows.push(HorizonRow {
                    model: model.clone(),
                    horizon: h as u16,
                    stats,
                });
            }
        }
    }
    Ok(rows)
}

/// The strings of a dictionary column's values.
fn dictionary_names(column: &DictionaryArray<UInt16Type>, path: &Path) -> Result<Vec<String>> {
    let values = column
        .values()
        .as_string_opt::<i32>()
        .ok_or_else(|| Error::bad_file(path, "model and variable must be string dictionaries"))?;
    Ok(values
        .iter()
        .map(|v| v.unwrap_or_default().to_string())
        .collect())
}

fn write_horizons(path: &Path, rows: &[HorizonRow], provenance: &Provenance) -> Result<()> {
    let number = |f: fn(&ErrorStats) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(
            rows.iter().map(|r| f(&r.stats)),
        ))
    };
    let batch = table::batch(vec![
        (
            "model",
            Arc::new(StringArray::from_iter_values(rows.iter().map(|r| &r.model)))
                as Arc<dyn Array>,
        ),
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

/// Reads `horizons.parquet` back: (model, horizon, mean, 95th percentile)
/// per row.
pub fn read_horizons(path: &Path) -> Result<Vec<(String, u16, f64, f64)>> {
    let table = Table::read(path)?;
    let models = table.strings("model")?;
    let horizons = table.column::<UInt16Array>("horizon")?.values();
    let (mean, p95) = (
        table.f64_column("mean")?.values(),
        table.f64_column("p95")?.values(),
    );
    Ok((0..table.num_rows())
        .map(|i| (models[i].clone(), horizons[i], mean[i], p95[i]))
        .collect())
}

/// The summary rows of a predictions table, by model and variable in the
/// order of their dictionaries.
pub fn summarize(predictions_path: &Path) -> Result<Vec<SummaryRow>> {
    let table = Table::read_columns(predictions_path, &["model", "variable", "error"])?;
    let models = table.column::<DictionaryArray<UInt16Type>>("model")?;
    let variables = table.column::<DictionaryArray<UInt16Type>>("variable")?;
    let errors = table.column::<UInt16Array>("error")?.values();
    let names = |d: &DictionaryArray<UInt16Type>| -> Result<Vec<String>> {
        let values = d.values().as_string_opt::<i32>().ok_or_else(|| {
            Error::bad_file(
                predictions_path,
                "model and variable must be string dictionaries",
            )
        })?;
        Ok(values
            .iter()
            .map(|v| v.unwrap_or_default().to_string())
            .collect())
    };
    let (model_names, variable_names) = (names(models)?, names(variables)?);
    let per_model = variable_names.len();
    let mut counts = vec![ErrorCounts::default(); model_names.len() * per_model];
    let (model_keys, variable_keys) = (models.keys().values(), variables.keys().values());
    for ((&m, &v), &e) in model_keys.iter().zip(variable_keys).zip(errors) {
        counts[usize::from(m) * per_model + usize::from(v)].add(u32::from(e), 1);
    }
    let mut rows = Vec::new();
    for (m, model) in model_names.iter().enumerate() {
        let first = rows.len();
        for (v, variable) in variable_names.iter().enumerate() {
            if let Some(stats) = counts[m * per_model + v].stats() {
                rows.push(SummaryRow {
                    model: model.clone(),
                    variable: variable.clone(),
                    group: group_of(variable).to_string(),
                    stats,
                    best_in_group: false,
                    worst_in_group: false,
                });
            }
        }
        mark_best_and_worst(&mut rows[first..]);
    }
    Ok(rows)
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
        ("model".into(), text(|r| &r.model)),
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
        ("p95".into(), number(|s| s.p95)),
        (
            "max".into(),
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|r| r.stats.max),
            )),
        ),
    ];
    for bin in 0..HISTOGRAM_BINS {
        let name = if bin + 1 == HISTOGRAM_BINS {
            format!("hist_{bin}_plus")
        } else {
            format!("hist_{bin}")
        };
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

/// Reads `summary.parquet` back.
pub fn read(path: &Path) -> Result<Vec<SummaryRow>> {
    let table = Table::read(path)?;
    let text = |name: &str| table.strings(name);
    let number = |name: &str| -> Result<&[f64]> { Ok(table.f64_column(name)?.values()) };
    let (models, variables, groups) = (text("model")?, text("variable")?, text("group")?);
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
            let name = if bin + 1 == HISTOGRAM_BINS {
                format!("hist_{bin}_plus")
            } else {
                format!("hist_{bin}")
            };
            Ok(table.column::<UInt64Array>(&name)?.values().as_ref())
        })
        .collect::<Result<_>>()?;
    let best = table.column::<BooleanArray>("best_in_group")?;
    let worst = table.column::<BooleanArray>("worst_in_group")?;
    Ok((0..table.num_rows())
        .map(|i| SummaryRow {
            model: models[i].clone(),
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
            best_in_group: best.value(i),
            worst_in_group: worst.value(i),
        })
        .collect())
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
        // Two models × three variables (two in group a, one in v), errors
        // (model, variable) → list.
        let errors: [(u16, u16, &[u16]); 6] = [
            (0, 0, &[0, 1, 2]),
            (0, 1, &[4, 4]),
            (0, 2, &[7]),
            (1, 0, &[3, 3, 3]),
            (1, 1, &[0, 0]),
            (1, 2, &[1]),
        ];
        let (mut m, mut v, mut e) = (Vec::new(), Vec::new(), Vec::new());
        for (model, variable, list) in errors {
            for &x in list {
                m.push(model);
                v.push(variable);
                e.push(x);
            }
        }
        let dictionary = |keys: Vec<u16>, values: Vec<&str>| {
            DictionaryArray::new(UInt16Array::from(keys), Arc::new(StringArray::from(values)))
        };
        let batch = table::batch(vec![
            (
                "model",
                Arc::new(dictionary(m, vec!["aln", "persistence"])) as Arc<dyn Array>,
            ),
            (
                "variable",
                Arc::new(dictionary(v, vec!["a.1.x", "a.2.x", "v.1.x"])),
            ),
            ("error", Arc::new(UInt16Array::from(e))),
        ]);
        let predictions = dir.path().join("predictions.parquet");
        table::write_parquet(&predictions, &batch, &provenance).unwrap();
        // The rollout: model 0 after 1 and 2 steps, model 1 after 1.
        let rollout = table::batch(vec![
            (
                "model",
                Arc::new(dictionary(vec![0, 0, 0, 1], vec!["aln", "persistence"]))
                    as Arc<dyn Array>,
            ),
            (
                "variable",
                Arc::new(dictionary(
                    vec![0, 1, 0, 0],
                    vec!["a.1.x", "a.2.x", "v.1.x"],
                )),
            ),
            ("horizon", Arc::new(UInt16Array::from(vec![1, 1, 2, 1]))),
            ("error", Arc::new(UInt16Array::from(vec![1, 3, 5, 0]))),
        ]);
        let rollout_path = dir.path().join("rollout.parquet");
        table::write_parquet(&rollout_path, &rollout, &provenance).unwrap();
        let silent = alnlab_common::Silent;
        run(
            &predictions,
            &rollout_path,
            &provenance,
            dir.path(),
            &silent,
        )
        .unwrap();
        let horizons = read_horizons(&dir.path().join(HORIZONS_FILE)).unwrap();
        assert_eq!(
            horizons,
            [
                ("aln".to_string(), 1, 2.0, 2.9),
                ("aln".to_string(), 2, 5.0, 5.0),
                ("persistence".to_string(), 1, 0.0, 0.0)
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
        let row = |model: &str, variable: &str| {
            rows.iter()
                .find(|r| r.model == model && r.variable == variable)
                .unwrap()
        };
        let first = row("aln", "a.1.x");
        assert_eq!(first.stats, ErrorCounts::of([0, 1, 2]).stats().unwrap());
        assert_eq!(first.group, "a");
        assert!(first.best_in_group && !first.worst_in_group);
        assert!(row("aln", "a.2.x").worst_in_group);
        let alone = row("aln", "v.1.x");
        assert!(
            alone.best_in_group && alone.worst_in_group,
            "alone in its group"
        );
        // Per model: for persistence a.2.x is the best of group a.
        assert!(row("persistence", "a.2.x").best_in_group);
        assert!(row("persistence", "a.1.x").worst_in_group);
    }
}
