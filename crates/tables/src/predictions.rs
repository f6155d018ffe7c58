//! `predictions.parquet`, written by the test stage and read by summarize:
//! every model's predicted level of every scored variable on every test row.
//!
//! One table row per model, variable and test row, in that order: `model`
//! and `variable` (dictionaries of names), `row` (the test row's row in
//! `levels.parquet`), `held_out` (whether training never saw it),
//! `true_level`, `predicted_level`, `period` (for an angle that wraps, the
//! circle in levels; 0 for every other variable) and `error`: the levels
//! between the two, the shorter way round the circle where the variable
//! wraps — a roll predicted at +179° for a true −179° is 2° off, not 358° —
//! kept so that a reader of the file need not recompute it.

use std::path::Path;
use std::sync::Arc;

use alnlab_codes::residual::change;
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, ModelId, Provenance, Result};
use arrow_array::{Array, BooleanArray, UInt16Array, UInt32Array};

use crate::dictionary;

/// The file's name in the test stage's artifact.
pub const FILE: &str = "predictions.parquet";

/// The largest circle in levels: levels are 16-bit.
const MAX_PERIOD: u32 = 1 << 16;

/// Every model's predictions on the same test rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Predictions {
    models: Vec<ModelId>,
    variables: Vec<String>,
    /// Per variable, the circle in levels for an angle that wraps.
    periods: Vec<Option<u32>>,
    rows: Vec<u32>,
    held_out: Vec<bool>,
    /// Variable v's true level on test row k at `[v * rows + k]`.
    truth: Vec<u16>,
    /// Model m's level of variable v on test row k at
    /// `[(m * variables + v) * rows + k]`.
    predicted: Vec<u16>,
}

impl Predictions {
    /// No model yet: the scored `variables` (`periods[v]`, the circle in
    /// levels of one that wraps, `Entry::period`), the test rows (`rows[k]`
    /// their rows in `levels.parquet`, `held_out[k]` whether training never
    /// saw them) and `truth[v][k]`, variable v's true level on test row k.
    ///
    /// # Panics
    /// When the lengths disagree: a caller's bug, not a file's.
    pub fn new(
        variables: &[&str],
        periods: &[Option<u32>],
        rows: &[u32],
        held_out: &[bool],
        truth: &[Vec<u16>],
    ) -> Self {
        assert_eq!(rows.len(), held_out.len(), "a held-out flag per test row");
        assert_eq!(truth.len(), variables.len(), "true levels per variable");
        assert_eq!(periods.len(), variables.len(), "a period per variable");
        assert!(
            truth.iter().all(|t| t.len() == rows.len()),
            "a true level per test row"
        );
        Predictions {
            models: Vec::new(),
            variables: variables.iter().map(|v| v.to_string()).collect(),
            periods: periods.to_vec(),
            rows: rows.to_vec(),
            held_out: held_out.to_vec(),
            truth: truth.concat(),
            predicted: Vec::new(),
        }
    }

    /// Adds a model's predictions, `levels[v][k]` for variable v on test
    /// row k.
    ///
    /// # Panics
    /// When the shape is not that of the true levels.
    pub fn push_model(&mut self, model: ModelId, levels: &[Vec<u16>]) {
        assert_eq!(levels.len(), self.variables.len(), "levels per variable");
        assert!(
            levels.iter().all(|l| l.len() == self.rows.len()),
            "a level per test row"
        );
        self.models.push(model);
        for l in levels {
            self.predicted.extend_from_slice(l);
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

    /// Per test row, its row in `levels.parquet`.
    pub fn rows(&self) -> &[u32] {
        &self.rows
    }

    /// Per test row, whether it was held out of training.
    pub fn held_out(&self) -> &[bool] {
        &self.held_out
    }

    /// Variable `v`'s true level on every test row.
    pub fn truth(&self, v: usize) -> &[u16] {
        let n = self.rows.len();
        &self.truth[v * n..(v + 1) * n]
    }

    /// Model `m`'s level of variable `v` on every test row.
    pub fn predicted(&self, m: usize, v: usize) -> &[u16] {
        let n = self.rows.len();
        let start = (m * self.variables.len() + v) * n;
        &self.predicted[start..start + n]
    }

    /// Per variable, the circle in levels of an angle that wraps.
    pub fn periods(&self) -> &[Option<u32>] {
        &self.periods
    }

    /// Model `m`'s error in levels on variable `v`, per test row ([`error`]).
    pub fn errors(&self, m: usize, v: usize) -> impl ExactSizeIterator<Item = u16> + '_ {
        let period = self.periods[v];
        self.predicted(m, v)
            .iter()
            .zip(self.truth(v))
            .map(move |(&p, &t)| error(t, p, period))
    }

    /// Writes the table to `path` (atomically).
    pub fn write(&self, path: &Path, provenance: &Provenance) -> Result<()> {
        let (n, per_model) = (self.rows.len(), self.variables.len());
        let total = self.models.len() * per_model * n;
        let (mut model, mut variable) = (Vec::with_capacity(total), Vec::with_capacity(total));
        let (mut row, mut held_out) = (Vec::with_capacity(total), Vec::with_capacity(total));
        let (mut truth, mut error) = (Vec::with_capacity(total), Vec::with_capacity(total));
        let mut period = Vec::with_capacity(total);
        for m in 0..self.models.len() {
            for v in 0..per_model {
                model.extend(std::iter::repeat_n(m as u16, n));
                variable.extend(std::iter::repeat_n(v as u16, n));
                row.extend_from_slice(&self.rows);
                held_out.extend_from_slice(&self.held_out);
                truth.extend_from_slice(self.truth(v));
                period.extend(std::iter::repeat_n(self.periods[v].unwrap_or(0), n));
                error.extend(self.errors(m, v));
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
            ("row", Arc::new(UInt32Array::from(row))),
            ("held_out", Arc::new(BooleanArray::from(held_out))),
            ("true_level", Arc::new(UInt16Array::from(truth))),
            (
                "predicted_level",
                Arc::new(UInt16Array::from(self.predicted.clone())),
            ),
            ("period", Arc::new(UInt32Array::from(period))),
            ("error", Arc::new(UInt16Array::from(error))),
        ]);
        table::write_parquet(path, &batch, provenance)
    }

    /// Reads the table at `path`. Every model must predict every variable on
    /// the same test rows, with the same true levels, every row of a
    /// variable must give it the same period, and each `error` must be the
    /// distance of its levels ([`error`]); rows may come in any order.
    pub fn read(path: &Path) -> Result<Predictions> {
        let table = Table::read(path)?;
        table.require_no_nulls()?;
        let (models, model_keys) = dictionary::models(&table)?;
        let (variables, variable_keys) = dictionary::read(&table, "variable")?;
        let row_ids = table.column::<UInt32Array>("row")?.values();
        let held = table.column::<BooleanArray>("held_out")?;
        let true_levels = table.column::<UInt16Array>("true_level")?.values();
        let predicted_levels = table.column::<UInt16Array>("predicted_level")?.values();
        let period_column = table.column::<UInt32Array>("period")?.values();
        let errors = table.column::<UInt16Array>("error")?.values();
        let per_model = variables.len();
        let blocks = dictionary::blocks(
            &table,
            &[(models.len(), "models"), (per_model, "variables")],
        )?;
        if let Some(r) = period_column.iter().position(|&p| p > MAX_PERIOD) {
            return Err(Error::bad_file(
                path,
                format!(
                    "row {r}: period {}, expected at most {MAX_PERIOD} levels",
                    period_column[r]
                ),
            ));
        }
        let mut periods: Vec<Option<Option<u32>>> = vec![None; per_model];
        // Table rows of each (model, variable) block, in file order.
        let mut blocks = vec![Vec::new(); blocks];
        for i in 0..table.num_rows() {
            let v = usize::from(variable_keys[i]);
            let period = (period_column[i] > 0).then_some(period_column[i]);
            match periods[v] {
                None => periods[v] = Some(period),
                Some(seen) if seen != period => {
                    return Err(Error::bad_file(
                        path,
                        format!(
                            "row {i}: `{}` has period {}, where an earlier row gave it {}",
                            variables[v],
                            period_column[i],
                            seen.unwrap_or(0)
                        ),
                    ));
                }
                Some(_) => {}
            }
            if errors[i] != error(true_levels[i], predicted_levels[i], period) {
                return Err(Error::bad_file(
                    path,
                    format!(
                        "row {i}: error {} is not the distance of true level {} and predicted \
                         level {}{}",
                        errors[i],
                        true_levels[i],
                        predicted_levels[i],
                        period.map_or(String::new(), |p| format!(" on a circle of {p} levels"))
                    ),
                ));
            }
            blocks[usize::from(model_keys[i]) * per_model + usize::from(variable_keys[i])].push(i);
        }
        let first = blocks.first().cloned().unwrap_or_default();
        let name = |k: usize| {
            format!(
                "model `{}` on `{}`",
                models[k / per_model],
                variables[k % per_model]
            )
        };
        for (k, block) in blocks.iter().enumerate() {
            let same = block.len() == first.len()
                && block
                    .iter()
                    .zip(&first)
                    .all(|(&i, &j)| row_ids[i] == row_ids[j] && held.value(i) == held.value(j));
            if !same {
                return Err(Error::bad_file(
                    path,
                    format!(
                        "{} has other test rows than {}: every model must predict every \
                         variable on the same rows",
                        name(k),
                        name(0)
                    ),
                ));
            }
        }
        for (k, block) in blocks.iter().enumerate() {
            let truth = &blocks[k % per_model];
            if let Some(r) = block
                .iter()
                .zip(truth)
                .find_map(|(&i, &j)| (true_levels[i] != true_levels[j]).then_some(i))
            {
                return Err(Error::bad_file(
                    path,
                    format!(
                        "row {r}: {} disagrees with {} on the true level",
                        name(k),
                        name(k % per_model)
                    ),
                ));
            }
        }
        let truth = blocks[..per_model.min(blocks.len())].iter().flatten();
        let read = Predictions {
            rows: first.iter().map(|&i| row_ids[i]).collect(),
            held_out: first.iter().map(|&i| held.value(i)).collect(),
            truth: truth.map(|&i| true_levels[i]).collect(),
            predicted: blocks
                .iter()
                .flatten()
                .map(|&i| predicted_levels[i])
                .collect(),
            periods: periods.into_iter().map(Option::flatten).collect(),
            models,
            variables,
        };
        Ok(read)
    }
}

/// A prediction's error in levels: how far `predicted` is from `truth`, the
/// shorter way round the circle of `period` levels for an angle that wraps.
pub fn error(truth: u16, predicted: u16, period: Option<u32>) -> u16 {
    let steps = change(truth, predicted, period).unsigned_abs();
    u16::try_from(steps).expect("two levels are at most 65 535 apart")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{edit_u16_columns, provenance, take_rows};

    fn two_models() -> Predictions {
        let mut p = Predictions::new(
            &["a.x", "b.y"],
            &[None, None],
            &[4, 9, 11],
            &[true, false, true],
            &[vec![1, 2, 3], vec![10, 20, 30]],
        );
        p.push_model(ModelId::Aln, &[vec![1, 5, 3], vec![12, 20, 29]]);
        p.push_model(ModelId::Persistence, &[vec![0, 2, 3], vec![10, 10, 10]]);
        p
    }

    #[test]
    fn a_table_reads_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let written = two_models();
        written.write(&path, &provenance()).unwrap();
        let read = Predictions::read(&path).unwrap();
        assert_eq!(read, written);
        assert_eq!(read.errors(1, 1).collect::<Vec<_>>(), [0, 10, 20]);
        assert_eq!(read.predicted(0, 0), [1, 5, 3]);
        assert_eq!(read.truth(1), [10, 20, 30]);
    }

    #[test]
    fn rows_in_another_order_read_the_same() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let written = two_models();
        written.write(&path, &provenance()).unwrap();
        let order: Vec<u32> = (0..12).rev().collect();
        take_rows(&path, &order);
        let read = Predictions::read(&path).unwrap();
        // Names come in the order the rows first give them, and each block's
        // rows in file order: here all reversed.
        assert_eq!(read.models(), [ModelId::Persistence, ModelId::Aln]);
        assert_eq!(read.variables(), ["b.y", "a.x"]);
        assert_eq!(read.rows(), [11, 9, 4]);
        assert_eq!(read.predicted(1, 1), [3, 5, 1]);
        assert_eq!(read.truth(0), [30, 20, 10]);
    }

    #[test]
    fn a_model_missing_a_row_is_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        two_models().write(&path, &provenance()).unwrap();
        // Drop persistence's last row of b.y.
        take_rows(&path, &(0..11).collect::<Vec<_>>());
        let message = Predictions::read(&path).unwrap_err().to_string();
        assert!(
            message.contains(
                "model `persistence` on `b.y` has other test rows than model `aln` on `a.x`"
            ),
            "{message}"
        );
    }

    #[test]
    fn an_error_that_is_not_the_distance_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        two_models().write(&path, &provenance()).unwrap();
        // Row 4 (aln on b.y, test row 9): true 20, predicted 20, error 0 → 1.
        edit_u16_columns(&path, |columns| columns[7].as_mut().unwrap()[4] += 1);
        let message = Predictions::read(&path).unwrap_err().to_string();
        assert!(
            message.contains(
                "row 4: error 1 is not the distance of true level 20 and predicted level 20"
            ),
            "{message}"
        );
    }

    #[test]
    fn models_disagreeing_on_the_truth_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        two_models().write(&path, &provenance()).unwrap();
        // Persistence's first row of a.x: another truth, its error consistent.
        edit_u16_columns(&path, |columns| {
            let predicted = columns[5].as_ref().unwrap()[6];
            let truth = &mut columns[4].as_mut().unwrap()[6];
            *truth += 1;
            let error = truth.abs_diff(predicted);
            columns[7].as_mut().unwrap()[6] = error;
        });
        let message = Predictions::read(&path).unwrap_err().to_string();
        assert!(
            message.contains("row 6: model `persistence` on `a.x` disagrees with model `aln` on `a.x` on the true level"),
            "{message}"
        );
    }

    /// A roll near ±π: with 214 levels over (−π, π], a period of 213 (the
    /// circle over the spacing). Level 1 is just above −π, level 211 just
    /// below +π: three levels apart round the circle, not 210.
    #[test]
    fn an_angle_predicted_across_the_wrap_is_off_by_the_short_way() {
        assert_eq!(error(1, 211, Some(213)), 3);
        assert_eq!(error(211, 1, Some(213)), 3);
        assert_eq!(error(1, 211, None), 210);
        assert_eq!(error(100, 100, Some(213)), 0);
        // Half the circle is the farthest an angle can be.
        assert_eq!(error(0, 106, Some(213)), 106);
        assert_eq!(error(0, 107, Some(213)), 106);

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let mut p = Predictions::new(
            &["roll.1", "v.1.x"],
            &[Some(213), None],
            &[0, 1],
            &[true, true],
            &[vec![1, 212], vec![1, 212]],
        );
        p.push_model(ModelId::Aln, &[vec![211, 2], vec![211, 2]]);
        p.write(&path, &provenance()).unwrap();
        let read = Predictions::read(&path).unwrap();
        assert_eq!(read, p);
        assert_eq!(read.errors(0, 0).collect::<Vec<_>>(), [3, 3]);
        assert_eq!(read.errors(0, 1).collect::<Vec<_>>(), [210, 210]);
    }
}
