//! `rollout.parquet`, written by the test stage and read by summarize: the
//! closed loop — each model fed its own predictions from a set of start
//! rows, its error at every step.
//!
//! One table row per model, variable, horizon and start, in that order:
//! `model` and `variable` (dictionaries of names), `horizon` (steps fed
//! back, from 1), `start` (the start's row in `levels.parquet`) and
//! `error` (levels from the logged trajectory, the shorter way round the
//! circle for an angle that wraps, as [`crate::predictions::error`]).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{Error, ModelId, Provenance, Result};
use arrow_array::{Array, UInt16Array, UInt32Array};

use crate::dictionary;

/// The file's name in the test stage's artifact.
pub const FILE: &str = "rollout.parquet";

/// Every model's closed-loop errors from the same starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Rollout {
    models: Vec<ModelId>,
    variables: Vec<String>,
    starts: Vec<u32>,
    horizons: u16,
    /// Model m's error on variable v after h steps from start s at
    /// `[((m * variables + v) * horizons + h - 1) * starts + s]`.
    errors: Vec<u16>,
}

impl Rollout {
    /// No model yet: the scored `variables`, the `starts` (their rows in
    /// `levels.parquet`) and how many steps each is fed back.
    pub fn new(variables: &[&str], starts: &[u32], horizons: u16) -> Self {
        Rollout {
            models: Vec::new(),
            variables: variables.iter().map(|v| v.to_string()).collect(),
            starts: starts.to_vec(),
            horizons,
            errors: Vec::new(),
        }
    }

    /// Adds a model's errors, `errors[h - 1][v][s]` after h steps on
    /// variable v from start s.
    ///
    /// # Panics
    /// When the shape is not horizons × variables × starts.
    pub fn push_model(&mut self, model: ModelId, errors: &[Vec<Vec<u16>>]) {
        assert_eq!(
            errors.len(),
            usize::from(self.horizons),
            "errors per horizon"
        );
        let shaped = errors.iter().all(|per_variable| {
            per_variable.len() == self.variables.len()
                && per_variable.iter().all(|e| e.len() == self.starts.len())
        });
        assert!(shaped, "an error per variable and start at every horizon");
        self.models.push(model);
        for v in 0..self.variables.len() {
            for per_variable in errors {
                self.errors.extend_from_slice(&per_variable[v]);
            }
        }
    }

    /// The models, in the order they were added.
    pub fn models(&self) -> &[ModelId] {
        &self.models
    }

    /// The scored variables.
    pub fn variables(&self) -> &[String] {
        &self.variables
    }

    /// The starts' rows in `levels.parquet`.
    pub fn starts(&self) -> &[u32] {
        &self.starts
    }

    /// How many steps every start is fed back.
    pub fn horizons(&self) -> u16 {
        self.horizons
    }

    /// Model `m`'s errors on variable `v` after `h` steps (1 ≤ h ≤
    /// horizons), per start.
    pub fn errors(&self, m: usize, v: usize, h: u16) -> &[u16] {
        assert!(
            (1..=self.horizons).contains(&h),
            "horizon {h} of 1..={}",
            self.horizons
        );
        let n = self.starts.len();
        let block =
            (m * self.variables.len() + v) * usize::from(self.horizons) + usize::from(h - 1);
        &self.errors[block * n..(block + 1) * n]
    }

    /// Writes the table to `path` (atomically).
    pub fn write(&self, path: &Path, provenance: &Provenance) -> Result<()> {
        let n = self.starts.len();
        let (mut model, mut variable, mut horizon) = (Vec::new(), Vec::new(), Vec::new());
        let mut start = Vec::new();
        for m in 0..self.models.len() {
            for v in 0..self.variables.len() {
                for h in 1..=self.horizons {
                    model.extend(std::iter::repeat_n(m as u16, n));
                    variable.extend(std::iter::repeat_n(v as u16, n));
                    horizon.extend(std::iter::repeat_n(h, n));
                    start.extend_from_slice(&self.starts);
                }
            }
        }
        let batch = table::batch(vec![
            (
                "model",
                Arc::new(dictionary::column(model, &self.models)) as Arc<dyn Array>,
            ),
            (
                "variable",
                Arc::new(dictionary::column(variable, &self.variables)),
            ),
            ("horizon", Arc::new(UInt16Array::from(horizon))),
            ("start", Arc::new(UInt32Array::from(start))),
            ("error", Arc::new(UInt16Array::from(self.errors.clone()))),
        ]);
        table::write_parquet(path, &batch, provenance)
    }

    /// Reads the table at `path`. Every model, variable and horizon from 1
    /// to the largest must hold an error for the same starts; rows may come
    /// in any order.
    pub fn read(path: &Path) -> Result<Rollout> {
        let table = Table::read(path)?;
        table.require_no_nulls()?;
        let (models, model_keys) = dictionary::models(&table)?;
        let (variables, variable_keys) = dictionary::read(&table, "variable")?;
        let horizon = table.column::<UInt16Array>("horizon")?.values();
        let start = table.column::<UInt32Array>("start")?.values();
        let error = table.column::<UInt16Array>("error")?.values();
        if let Some(r) = horizon.iter().position(|&h| h == 0) {
            return Err(Error::bad_file(
                path,
                format!("row {r}: horizon 0, expected a step count from 1"),
            ));
        }
        let horizons = horizon.iter().copied().max().unwrap_or(0);
        let per_model = variables.len() * usize::from(horizons);
        let blocks = dictionary::blocks(
            &table,
            &[
                (models.len(), "models"),
                (variables.len(), "variables"),
                (usize::from(horizons), "horizons"),
            ],
        )?;
        let mut blocks = vec![Vec::new(); blocks];
        for i in 0..table.num_rows() {
            let k = (usize::from(model_keys[i]) * variables.len() + usize::from(variable_keys[i]))
                * usize::from(horizons)
                + usize::from(horizon[i] - 1);
            blocks[k].push(i);
        }
        let first = blocks.first().cloned().unwrap_or_default();
        for (k, block) in blocks.iter().enumerate() {
            let same = block.len() == first.len()
                && block
                    .iter()
                    .zip(&first)
                    .all(|(&i, &j)| start[i] == start[j]);
            if !same {
                let h = usize::from(horizons);
                return Err(Error::bad_file(
                    path,
                    format!(
                        "model `{}` on `{}` at horizon {} has other starts than the first \
                         model, variable and horizon: every one must be fed back from the same \
                         starts for every horizon up to {horizons}",
                        models[k / per_model],
                        variables[k / h % variables.len()],
                        k % h + 1,
                    ),
                ));
            }
        }
        Ok(Rollout {
            starts: first.iter().map(|&i| start[i]).collect(),
            errors: blocks.iter().flatten().map(|&i| error[i]).collect(),
            models,
            variables,
            horizons,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{provenance, take_rows};

    /// Two models, two variables, three horizons, two starts: every error
    /// a different number, 100 m + 10 v + h, plus the start.
    fn rolled() -> Rollout {
        let mut r = Rollout::new(&["a", "b"], &[3, 8], 3);
        for (m, model) in [ModelId::Aln, ModelId::Linear].into_iter().enumerate() {
            let errors: Vec<Vec<Vec<u16>>> = (1..=3u16)
                .map(|h| {
                    (0..2u16)
                        .map(|v| (0..2u16).map(|s| 100 * m as u16 + 10 * v + h + s).collect())
                        .collect()
                })
                .collect();
            r.push_model(model, &errors);
        }
        r
    }

    #[test]
    fn a_table_reads_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let written = rolled();
        written.write(&path, &provenance()).unwrap();
        let read = Rollout::read(&path).unwrap();
        assert_eq!(read, written);
        assert_eq!(read.errors(1, 1, 3), [113, 114]);
        assert_eq!(read.errors(0, 0, 1), [1, 2]);
        assert_eq!(read.horizons(), 3);
    }

    #[test]
    fn an_empty_table_reads_as_no_models() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        Rollout::new(&["a"], &[], 0)
            .write(&path, &provenance())
            .unwrap();
        let read = Rollout::read(&path).unwrap();
        assert!(read.models().is_empty() && read.starts().is_empty());
    }

    #[test]
    fn a_missing_horizon_is_refused_naming_the_block() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        rolled().write(&path, &provenance()).unwrap();
        // Every row but linear's on `b` at horizon 2 (rows 20 and 21).
        let keep: Vec<u32> = (0..24).filter(|r| !(20..22).contains(r)).collect();
        take_rows(&path, &keep);
        let message = Rollout::read(&path).unwrap_err().to_string();
        assert!(
            message.contains("model `linear` on `b` at horizon 2 has other starts"),
            "{message}"
        );
    }

    /// Names that promise more blocks than there are rows are damage: they
    /// are refused before any block is allocated.
    #[test]
    fn more_blocks_than_rows_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        rolled().write(&path, &provenance()).unwrap();
        // Linear's last row alone (the file keeps only the names its rows
        // use): one model and variable, but horizon 3 asks for three blocks.
        take_rows(&path, &[23]);
        let message = Rollout::read(&path).unwrap_err().to_string();
        assert!(
            message.contains("1 models × 1 variables × 3 horizons cannot fit in 1 rows"),
            "{message}"
        );
    }
}
