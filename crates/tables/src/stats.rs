//! `stats.parquet`, written by the simulate and ingest stages and read by
//! quantize: each variable's statistics over every logged frame (paper
//! §4.2), by Welford's numerically stable running update
//! ([`VariableStats`]).
//!
//! One table row per variable, in the order the log first gives them:
//! `variable`, `n` (frames), `min`, `max`, `mean` and `std` (the sample
//! standard deviation, n − 1; 0 for fewer than two frames).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt64Array};

/// The file's name in the simulate (or ingest) stage's artifact.
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

#[derive(Clone, Copy, Debug)]
struct Running {
    n: u64,
    mean: f64,
    m2: f64,
    min: f64,
    max: f64,
}

impl Running {
    fn new() -> Self {
        Running {
            n: 0,
            mean: 0.0,
            m2: 0.0,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
        }
    }

    fn add(&mut self, x: f64) {
        self.n += 1;
        let delta = x - self.mean;
        self.mean += delta / self.n as f64;
        self.m2 += delta * (x - self.mean);
        self.min = self.min.min(x);
        self.max = self.max.max(x);
    }

    /// Sample standard deviation (n − 1); 0 for fewer than two values.
    fn std(&self) -> f64 {
        if self.n < 2 {
            0.0
        } else {
            (self.m2 / (self.n - 1) as f64).sqrt()
        }
    }
}

/// Running statistics per variable name, in first-seen order: what the
/// stages that write a trajectory log (simulate, ingest) keep beside it.
#[derive(Default)]
pub struct VariableStats {
    names: Vec<String>,
    running: Vec<Running>,
}

impl VariableStats {
    /// Adds one frame's values of the variables `names`.
    pub fn add(&mut self, names: &[String], values: &[f64]) {
        for (name, &x) in names.iter().zip(values) {
            let i = match self.names.iter().position(|n| n == name) {
                Some(i) => i,
                None => {
                    self.names.push(name.clone());
                    self.running.push(Running::new());
                    self.running.len() - 1
                }
            };
            self.running[i].add(x);
        }
    }

    /// Writes `stats.parquet`.
    pub fn write(&self, path: &Path, provenance: &Provenance) -> Result<()> {
        let rows: Vec<Row> = self
            .names
            .iter()
            .zip(&self.running)
            .map(|(name, r)| Row {
                variable: name.clone(),
                n: r.n,
                min: r.min,
                max: r.max,
                mean: r.mean,
                std: r.std(),
            })
            .collect();
        write(path, &rows, provenance)
    }
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

    #[test]
    fn welford_matches_two_pass_on_offset_data() {
        // A large offset defeats the naive sum-of-squares formula.
        // The reference works on the offsets, which are exact in f64.
        let offsets: Vec<f64> = (0..10_000).map(|i| (i % 7) as f64 * 0.5).collect();
        let mut r = Running::new();
        offsets.iter().for_each(|&d| r.add(1e9 + d));
        let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
        let var =
            offsets.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (offsets.len() - 1) as f64;
        assert!((r.mean - (1e9 + mean)).abs() < 1e-3, "1e-12 relative");
        assert!(
            (r.std() - var.sqrt()).abs() < 1e-9,
            "{} vs {}",
            r.std(),
            var.sqrt()
        );
        assert_eq!((r.min, r.max), (1e9, 1e9 + 3.0));
    }
}
