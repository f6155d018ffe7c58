//! `pairs.parquet`, written by the stride stage and read by quantize, train
//! and test: the frame pairs (x, the current frame; y, the next) in real
//! values.
//!
//! One table row per pair: `scene`, `run`, `step` (the x frame's index in
//! its run) and `split` (`train`, `test` or `both`), then `x.<variable>` for
//! every variable of the log, then `y.<variable>` in the same order: f64,
//! null where the pair's scene has no such variable. The key columns are
//! [`Key`]; `levels.parquet` carries the same keys row for row.

use std::path::Path;
use std::sync::Arc;

use alnlab_codes::Entry;
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array};

/// The file's name in the stride stage's artifact.
pub const FILE: &str = "pairs.parquet";

/// A side of a pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The current frame (`x.` columns).
    Current,
    /// The next frame (`y.` columns).
    Next,
}

impl Side {
    /// The column of `variable` on this side: `x.v.1.x` or `y.v.1.x`.
    pub fn column(self, variable: &str) -> String {
        match self {
            Side::Current => format!("x.{variable}"),
            Side::Next => format!("y.{variable}"),
        }
    }
}

/// What a pair is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Training only.
    Train,
    /// Testing only: held out of training.
    Test,
    /// Both (the paper's split tests on a superset of the training rows).
    Both,
}

impl Split {
    /// The name in the `split` column.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
            Split::Both => "both",
        }
    }

    /// Whether the pair is trained on.
    pub fn trains(self) -> bool {
        self != Split::Test
    }

    /// Whether the pair is tested on.
    pub fn tests(self) -> bool {
        self != Split::Train
    }
}

/// A pair's identity and role: the key columns of `pairs.parquet` and
/// `levels.parquet`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Key {
    pub scene: String,
    pub run: u32,
    /// The x frame's index in its run.
    pub step: u32,
    pub split: Split,
}

/// The key columns of `keys`, for a table's first four columns.
pub(crate) fn key_columns(keys: &[Key]) -> Vec<(&'static str, Arc<dyn Array>)> {
    vec![
        (
            "scene",
            Arc::new(StringArray::from_iter_values(
                keys.iter().map(|k| k.scene.as_str()),
            )),
        ),
        (
            "run",
            Arc::new(UInt32Array::from_iter_values(keys.iter().map(|k| k.run))),
        ),
        (
            "step",
            Arc::new(UInt32Array::from_iter_values(keys.iter().map(|k| k.step))),
        ),
        (
            "split",
            Arc::new(StringArray::from_iter_values(
                keys.iter().map(|k| k.split.name()),
            )),
        ),
    ]
}

/// The key columns of `table`, every row checked: no nulls, a known split.
pub(crate) fn read_keys(table: &Table) -> Result<Vec<Key>> {
    let scene = table.column::<StringArray>("scene")?;
    let run = table.column::<UInt32Array>("run")?;
    let step = table.column::<UInt32Array>("step")?;
    let split = table.column::<StringArray>("split")?;
    (0..table.num_rows())
        .map(|r| {
            let bad = |what: String| Error::bad_file(table.path(), format!("row {r}: {what}"));
            let split = match split.is_valid(r).then(|| split.value(r)) {
                Some("train") => Split::Train,
                Some("test") => Split::Test,
                Some("both") => Split::Both,
                other => {
                    return Err(bad(format!(
                        "`split` is {}, expected train, test or both",
                        other.map_or("null".to_string(), |s| format!("`{s}`"))
                    )));
                }
            };
            if let Some(name) = [("scene", scene.is_null(r)), ("run", run.is_null(r))]
                .into_iter()
                .chain([("step", step.is_null(r))])
                .find_map(|(name, null)| null.then_some(name))
            {
                return Err(bad(format!("`{name}` is null")));
            }
            Ok(Key {
                scene: scene.value(r).to_string(),
                run: run.value(r),
                step: step.value(r),
                split,
            })
        })
        .collect()
}

/// Writes the pairs to `path` (atomically): `keys[r]` and, for variable
/// `k` of `variables`, `value(side, k, r)` (`None` where row r's scene has
/// no such variable).
pub fn write(
    path: &Path,
    keys: &[Key],
    variables: &[&str],
    value: impl Fn(Side, usize, usize) -> Option<f64>,
    provenance: &Provenance,
) -> Result<()> {
    let names: Vec<(Side, String)> = [Side::Current, Side::Next]
        .into_iter()
        .flat_map(|side| variables.iter().map(move |v| (side, side.column(v))))
        .collect();
    let mut columns = key_columns(keys)
        .into_iter()
        .map(|(n, a)| (n.to_string(), a))
        .collect::<Vec<_>>();
    for (k, (side, name)) in names.iter().enumerate() {
        let variable = k % variables.len();
        let values: Float64Array = (0..keys.len()).map(|r| value(*side, variable, r)).collect();
        columns.push((name.clone(), Arc::new(values)));
    }
    let columns = columns
        .iter()
        .map(|(n, a)| (n.as_str(), a.clone()))
        .collect();
    table::write_parquet(path, &table::batch(columns), provenance)
}

/// A pairs table read back.
pub struct Pairs {
    table: Table,
    keys: Vec<Key>,
    variables: Vec<String>,
}

impl Pairs {
    /// Reads the table at `path`: its keys checked row by row, its
    /// variables those of its `x.` columns.
    pub fn read(path: &Path) -> Result<Pairs> {
        let table = Table::read(path)?;
        let keys = read_keys(&table)?;
        let variables = table
            .batch
            .schema()
            .fields()
            .iter()
            .filter_map(|f| f.name().strip_prefix("x.").map(str::to_string))
            .collect();
        Ok(Pairs {
            table,
            keys,
            variables,
        })
    }

    /// The pairs' keys, row by row.
    pub fn keys(&self) -> &[Key] {
        &self.keys
    }

    /// How many pairs.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Whether there is no pair.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The variables, in the table's order.
    pub fn variables(&self) -> &[String] {
        &self.variables
    }

    /// The file read.
    pub fn path(&self) -> &Path {
        self.table.path()
    }

    /// `variable`'s values on `side`: null on every pair of a scene that
    /// has no such variable, finite on every pair of one that has it; a
    /// value that breaks this is refused naming its row.
    pub fn column(&self, side: Side, variable: &str) -> Result<&Float64Array> {
        let name = side.column(variable);
        let values = self.table.f64_column(&name)?;
        if let Some(r) =
            (0..values.len()).find(|&r| values.is_valid(r) && !values.value(r).is_finite())
        {
            return Err(Error::bad_file(
                self.path(),
                format!(
                    "row {r}, column `{name}`: {} is not a finite number",
                    values.value(r)
                ),
            ));
        }
        // The scenes with a value: a null in one of them is damage.
        let with_values: std::collections::BTreeSet<&str> = (0..values.len())
            .filter(|&r| values.is_valid(r))
            .map(|r| self.keys[r].scene.as_str())
            .collect();
        if let Some(r) = (0..values.len())
            .find(|&r| values.is_null(r) && with_values.contains(self.keys[r].scene.as_str()))
        {
            return Err(Error::bad_file(
                self.path(),
                format!(
                    "row {r}, column `{name}`: null where other pairs of scene `{}` have a value",
                    self.keys[r].scene
                ),
            ));
        }
        Ok(values)
    }

    /// The values `[variable][row]` of the `learned` variables on `side`:
    /// every one present (a learned variable is in every scene) and finite.
    pub fn values(&self, side: Side, learned: &[&Entry]) -> Result<Vec<Vec<f64>>> {
        learned
            .iter()
            .map(|e| {
                let column = self.column(side, &e.variable)?;
                if let Some(r) = (0..column.len()).find(|&r| column.is_null(r)) {
                    return Err(Error::bad_file(
                        self.path(),
                        format!(
                            "row {r}: `{}` is null, expected a value",
                            side.column(&e.variable)
                        ),
                    ));
                }
                Ok(column.values().to_vec())
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{keys, provenance};

    #[test]
    fn pairs_read_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let value = |side: Side, k: usize, r: usize| {
            (k == 0 || r != 2).then(|| r as f64 + 10.0 * k as f64 + f64::from(side == Side::Next))
        };
        write(
            &path,
            &keys(),
            &["v.1.x", "omega.2.z"],
            value,
            &provenance(),
        )
        .unwrap();
        let pairs = Pairs::read(&path).unwrap();
        assert_eq!(pairs.keys(), keys());
        assert_eq!(pairs.variables(), ["v.1.x", "omega.2.z"]);
        let next = pairs.column(Side::Next, "omega.2.z").unwrap();
        assert_eq!((next.value(1), next.is_null(2)), (12.0, true));
        let v = crate::testing::entry("v.1.x");
        assert_eq!(
            pairs.values(Side::Current, &[&v]).unwrap(),
            [vec![0.0, 1.0, 2.0]]
        );
        let omega = crate::testing::entry("omega.2.z");
        let message = pairs
            .values(Side::Current, &[&omega])
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("row 2: `x.omega.2.z` is null, expected a value"),
            "{message}"
        );
    }

    #[test]
    fn an_unknown_split_or_a_value_that_is_not_finite_is_refused_by_row() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let batch = table::batch(vec![
            ("scene", Arc::new(StringArray::from(vec!["worm", "worm"]))),
            ("run", Arc::new(UInt32Array::from(vec![0, 0]))),
            ("step", Arc::new(UInt32Array::from(vec![0, 1]))),
            ("split", Arc::new(StringArray::from(vec!["train", "valid"]))),
        ]);
        table::write_parquet(&path, &batch, &provenance()).unwrap();
        let message = Pairs::read(&path).err().unwrap().to_string();
        assert!(
            message.contains("row 1: `split` is `valid`, expected train, test or both"),
            "{message}"
        );
        write(
            &path,
            &keys(),
            &["a"],
            |_, _, r| Some(if r == 1 { f64::NAN } else { 0.0 }),
            &provenance(),
        )
        .unwrap();
        let pairs = Pairs::read(&path).unwrap();
        let message = pairs.column(Side::Current, "a").unwrap_err().to_string();
        assert!(message.contains("row 1, column `x.a`: NaN"), "{message}");
        // Rows 0 and 1 are both of scene `worm`.
        write(
            &path,
            &keys(),
            &["a"],
            |_, _, r| (r != 1).then_some(0.0),
            &provenance(),
        )
        .unwrap();
        let pairs = Pairs::read(&path).unwrap();
        let message = pairs.column(Side::Next, "a").unwrap_err().to_string();
        assert!(
            message.contains(
                "row 1, column `y.a`: null where other pairs of scene `worm` have a value"
            ),
            "{message}"
        );
        // The scene's first pair damaged: it is the one named.
        write(
            &path,
            &keys(),
            &["a"],
            |_, _, r| (r != 0).then_some(0.0),
            &provenance(),
        )
        .unwrap();
        let pairs = Pairs::read(&path).unwrap();
        let message = pairs.column(Side::Next, "a").unwrap_err().to_string();
        assert!(message.contains("row 0, column `y.a`: null"), "{message}");
    }
}
