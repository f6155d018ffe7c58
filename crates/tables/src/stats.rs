//! `stats.parquet`, written by the simulate stage and read by quantize:
//! each variable's statistics over every logged frame (paper §4.2).
//!
//! One table row per variable, in the order the log first gives them:
//! `variable`, `n` (frames), `min`, `max`, `mean` and `std` (the sample
//! standard deviation, n − 1; 0 for fewer than two frames).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt64Array};

/// The file's name in the simulate stage's artifact.
pub const FILE: &str = "stats.parquet";

/// One variable's statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub variable: String,
    pub n: u64,
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub std: f64,
}

/// Writes `rows` to `path` (atomically).
pub fn write(path: &Path, rows: &[Row], provenance: &Provenance) -> Result<()> {
    let real = |f: fn(&Row) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(rows.iter().map(f)))
    };
    let batch = table::batch(vec![
        (
            "variable",
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| &r.variable),
            )),
        ),
        (
            "n",
            Arc::new(UInt64Array::from_iter_values(rows.iter().map(|r| r.n))),
        ),
        ("min", real(|r| r.min)),
        ("max", real(|r| r.max)),
        ("mean", real(|r| r.mean)),
        ("std", real(|r| r.std)),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// Reads the table at `path`: every row names a variable, once, with a
/// finite `min` no greater than its finite `max`.
pub fn read(path: &Path) -> Result<Vec<Row>> {
    let table = Table::read(path)?;
    let names = table.column::<StringArray>("variable")?;
    let n = table.column::<UInt64Array>("n")?;
    let (min, max) = (
        table.finite_f64_column("min")?,
        table.finite_f64_column("max")?,
    );
    let (mean, std) = (table.f64_column("mean")?, table.f64_column("std")?);
    let mut rows: Vec<Row> = Vec::with_capacity(table.num_rows());
    let mut seen = std::collections::BTreeSet::new();
    for r in 0..table.num_rows() {
        let bad = |what: String| Err(Error::bad_file(path, format!("row {r}: {what}")));
        if names.is_null(r) {
            return bad("`variable` is null, expected a variable's name".into());
        }
        let (lo, hi) = (min.value(r), max.value(r));
        if lo > hi {
            return bad(format!("min {lo} is above max {hi}"));
        }
        let variable = names.value(r);
        if !seen.insert(variable) {
            return bad(format!("`{variable}` appears a second time"));
        }
        rows.push(Row {
            variable: variable.to_string(),
            n: n.value(r),
            min: lo,
            max: hi,
            mean: mean.value(r),
            std: std.value(r),
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::provenance;

    fn row(variable: &str, min: f64, max: f64) -> Row {
        Row {
            variable: variable.into(),
            n: 3,
            min,
            max,
            mean: (min + max) / 2.0,
            std: 0.5,
        }
    }

    #[test]
    fn rows_read_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let rows = vec![row("v.1.x", -1.0, 2.0), row("roll.2", -3.0, 3.0)];
        write(&path, &rows, &provenance()).unwrap();
        assert_eq!(read(&path).unwrap(), rows);
    }

    #[test]
    fn what_a_range_cannot_be_is_refused_by_row() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        for (rows, said) in [
            (
                vec![row("a", 0.0, 1.0), row("b", 2.0, 1.0)],
                "row 1: min 2 is above max 1",
            ),
            (
                vec![row("a", 0.0, 1.0), row("a", 0.0, 1.0)],
                "row 1: `a` appears a second time",
            ),
            (
                vec![row("a", f64::NAN, 1.0)],
                "row 0, column `min`: NaN is not a finite number",
            ),
            (
                vec![row("a", 0.0, f64::INFINITY)],
                "row 0, column `max`: inf is not a finite number",
            ),
        ] {
            write(&path, &rows, &provenance()).unwrap();
            let message = read(&path).unwrap_err().to_string();
            assert!(message.contains(said), "{message}");
        }
    }
}
