//! `training.parquet`, the train stage's log: its rows, its writer and its
//! reader. A bit model logs one row per tree per epoch (the tree's errors
//! on the training rows); a piecewise-linear model one row per tree per
//! round of growth (its pieces and errors after the round).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array, UInt64Array};

/// One tree's epoch of a bit model's training.
#[derive(Clone, Debug, PartialEq)]
pub struct Epoch {
    pub variable: String,
    pub bit: u32,
    pub vote: u32,
    /// 1-based.
    pub epoch: u32,
    /// Training rows the tree got wrong in the epoch.
    pub errors: u64,
    /// Leaf updates the epoch made.
    pub updates: u64,
    pub seconds: f64,
}

/// One tree's round of a piecewise-linear model's growth.
#[derive(Clone, Debug, PartialEq)]
pub struct Round {
    pub variable: String,
    /// 1-based.
    pub round: u32,
    /// Pieces after the round, and how many split in it.
    pub pieces: u32,
    pub splits: u32,
    /// Root-mean-square and mean absolute error on the training rows, in
    /// level spacings.
    pub rms: f64,
    pub mean_absolute: f64,
}

/// A training log: epochs of a bit model or rounds of a piecewise-linear one.
#[derive(Clone, Debug, PartialEq)]
pub enum Log {
    Epochs(Vec<Epoch>),
    Rounds(Vec<Round>),
}

impl Log {
    /// A bit model's mean errors per tree, per epoch: (epoch, errors), in
    /// epoch order; empty for a piecewise-linear model's rounds.
    pub fn mean_errors_per_epoch(&self) -> Vec<(u32, f64)> {
        let Log::Epochs(rows) = self else {
            return Vec::new();
        };
        let mut per_epoch: BTreeMap<u32, (u64, u64)> = BTreeMap::new();
        for row in rows {
            let (errors, trees) = per_epoch.entry(row.epoch).or_default();
            *errors += row.errors;
            *trees += 1;
        }
        per_epoch
            .into_iter()
            .map(|(epoch, (errors, trees))| (epoch, errors as f64 / trees as f64))
            .collect()
    }
}

/// Writes `log` to `path`.
pub fn write(path: &Path, log: &Log, provenance: &Provenance) -> Result<()> {
    let text = |values: Vec<&str>| -> Arc<dyn Array> { Arc::new(StringArray::from(values)) };
    let count = |values: Vec<u32>| -> Arc<dyn Array> { Arc::new(UInt32Array::from(values)) };
    let real = |values: Vec<f64>| -> Arc<dyn Array> { Arc::new(Float64Array::from(values)) };
    let batch = match log {
        Log::Epochs(rows) => {
            let wide = |f: fn(&Epoch) -> u64| -> Arc<dyn Array> {
                Arc::new(UInt64Array::from_iter_values(rows.iter().map(f)))
            };
            table::batch(vec![
                (
                    "variable",
                    text(rows.iter().map(|r| r.variable.as_str()).collect()),
                ),
                ("bit", count(rows.iter().map(|r| r.bit).collect())),
                ("vote", count(rows.iter().map(|r| r.vote).collect())),
                ("epoch", count(rows.iter().map(|r| r.epoch).collect())),
                ("errors", wide(|r| r.errors)),
                ("updates", wide(|r| r.updates)),
                ("seconds", real(rows.iter().map(|r| r.seconds).collect())),
            ])
        }
        Log::Rounds(rows) => table::batch(vec![
            (
                "variable",
                text(rows.iter().map(|r| r.variable.as_str()).collect()),
            ),
            ("round", count(rows.iter().map(|r| r.round).collect())),
            ("pieces", count(rows.iter().map(|r| r.pieces).collect())),
            ("splits", count(rows.iter().map(|r| r.splits).collect())),
            ("rms", real(rows.iter().map(|r| r.rms).collect())),
            (
                "mean_absolute",
                real(rows.iter().map(|r| r.mean_absolute).collect()),
            ),
        ]),
    };
    table::write_parquet(path, &batch, provenance)
}

/// Reads `training.parquet`: rounds if it has a `round` column, epochs
/// otherwise.
pub fn read(path: &Path) -> Result<Log> {
    let table = Table::read(path)?;
    let names = table.strings("variable")?;
    let count = |name: &str| table.column::<UInt32Array>(name).map(|c| c.values());
    let wide = |name: &str| table.column::<UInt64Array>(name).map(|c| c.values());
    let real = |name: &str| table.f64_column(name).map(|c| c.values());
    let counted_from_one = |name: &str, values: &[u32]| match values.iter().position(|&k| k == 0) {
        Some(row) => Err(Error::bad_file(
            path,
            format!("row {row}: `{name}` counts from 1; found 0"),
        )),
        None => Ok(()),
    };
    if table.column::<UInt32Array>("round").is_ok() {
        let round = count("round")?;
        counted_from_one("round", round)?;
        let (pieces, splits) = (count("pieces")?, count("splits")?);
        let (rms, mean_absolute) = (real("rms")?, real("mean_absolute")?);
        return Ok(Log::Rounds(
            names
                .into_iter()
                .enumerate()
                .map(|(i, variable)| Round {
                    variable,
                    round: round[i],
                    pieces: pieces[i],
                    splits: splits[i],
                    rms: rms[i],
                    mean_absolute: mean_absolute[i],
                })
                .collect(),
        ));
    }
    let (bit, vote, epoch) = (count("bit")?, count("vote")?, count("epoch")?);
    counted_from_one("epoch", epoch)?;
    let (errors, updates, seconds) = (wide("errors")?, wide("updates")?, real("seconds")?);
    Ok(Log::Epochs(
        names
            .into_iter()
            .enumerate()
            .map(|(i, variable)| Epoch {
                variable,
                bit: bit[i],
                vote: vote[i],
                epoch: epoch[i],
                errors: errors[i],
                updates: updates[i],
                seconds: seconds[i],
            })
            .collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn provenance() -> Provenance {
        Provenance {
            stage: "train".into(),
            params: serde_json::Value::Null,
            inputs: Default::default(),
        }
    }

    #[test]
    fn both_kinds_of_log_read_back_as_written() {
        let epoch = |variable: &str, epoch, errors| Epoch {
            variable: variable.into(),
            bit: 0,
            vote: 1,
            epoch,
            errors,
            updates: 7,
            seconds: 0.5,
        };
        let epochs = Log::Epochs(vec![
            epoch("v.1.x", 1, 10),
            epoch("v.1.y", 1, 20),
            epoch("v.1.x", 2, 4),
        ]);
        let rounds = Log::Rounds(vec![Round {
            variable: "a.2.z".into(),
            round: 1,
            pieces: 3,
            splits: 2,
            rms: 0.25,
            mean_absolute: 0.125,
        }]);
        let dir = tempfile::tempdir().unwrap();
        for log in [epochs.clone(), rounds] {
            let path = dir.path().join("training.parquet");
            write(&path, &log, &provenance()).unwrap();
            assert_eq!(read(&path).unwrap(), log);
        }
        assert_eq!(epochs.mean_errors_per_epoch(), vec![(1, 15.0), (2, 4.0)]);
    }

    #[test]
    fn an_epoch_counted_from_zero_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("training.parquet");
        let log = Log::Epochs(vec![Epoch {
            variable: "v.1.x".into(),
            bit: 0,
            vote: 0,
            epoch: 0,
            errors: 1,
            updates: 1,
            seconds: 0.0,
        }]);
        write(&path, &log, &provenance()).unwrap();
        let message = read(&path).unwrap_err().to_string();
        assert!(
            message.contains("row 0: `epoch` counts from 1"),
            "{message}"
        );
    }
}
