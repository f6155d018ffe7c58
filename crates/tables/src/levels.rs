//! `levels.parquet`, written by the quantize stage and read by train, test,
//! plan and circuit: every learned variable's level on both sides of every
//! pair.
//!
//! One table row per pair of `pairs.parquet`, in its order: the same key
//! columns ([`Key`]: `scene`, `run`, `step`, `split`), then `x.<variable>`
//! for every learned variable in codebook order, then `y.<variable>`: u16
//! levels, never null, each below its variable's level count (checked
//! against the codebook as a column is read).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use alnlab_codes::Entry;
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, UInt16Array};

use crate::pairs::{Key, Pairs, Side, key_columns, read_keys};

/// The file's name in the quantize stage's artifact.
pub const FILE: &str = "levels.parquet";

/// Writes the levels to `path` (atomically): `keys[r]` and, for variable
/// `k` of `variables`, `x[k][r]` and `y[k][r]`.
///
/// # Panics
/// When the lengths disagree: a caller's bug, not a file's.
pub fn write(
    path: &Path,
    keys: &[Key],
    variables: &[&str],
    x: &[Vec<u16>],
    y: &[Vec<u16>],
    provenance: &Provenance,
) -> Result<()> {
    assert!(x.len() == variables.len() && y.len() == variables.len());
    let names: Vec<String> = [Side::Current, Side::Next]
        .into_iter()
        .flat_map(|side| variables.iter().map(move |v| side.column(v)))
        .collect();
    let mut columns = key_columns(keys);
    for (name, levels) in names.iter().zip(x.iter().chain(y)) {
        assert_eq!(levels.len(), keys.len(), "a level per pair");
        columns.push((name, Arc::new(UInt16Array::from(levels.clone()))));
    }
    table::write_parquet(path, &table::batch(columns), provenance)
}

/// A levels table read back.
pub struct Levels {
    table: Table,
    keys: Vec<Key>,
    /// The codebook the levels are read against, named where they disagree.
    codebook: PathBuf,
}

impl Levels {
    /// Reads the table at `path`, its keys checked row by row, for reading
    /// against the codebook at `codebook` (which a level it does not give
    /// names with the levels file).
    pub fn read(path: &Path, codebook: &Path) -> Result<Levels> {
        let table = Table::read(path)?;
        let keys = read_keys(&table)?;
        Ok(Levels {
            table,
            keys,
            codebook: codebook.to_path_buf(),
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

    /// The file read.
    pub fn path(&self) -> &Path {
        self.table.path()
    }

    /// Checks that `pairs` are the pairs these levels were made from (the
    /// same keys, row for row): an error names the pairs' file.
    pub fn check_made_from(&self, pairs: &Pairs) -> Result<()> {
        if pairs.keys() == self.keys() {
            return Ok(());
        }
        Err(Error::bad_file(
            pairs.path(),
            format!(
                "does not hold the pairs {} was made from ({} rows against {})",
                self.path().display(),
                pairs.len(),
                self.len()
            ),
        ))
    }

    /// The rows trained on (split `train` or `both`).
    pub fn train_rows(&self) -> Vec<usize> {
        self.rows_where(|k| k.split.trains())
    }

    /// The rows tested on (split `test` or `both`).
    pub fn test_rows(&self) -> Vec<usize> {
        self.rows_where(|k| k.split.tests())
    }

    fn rows_where(&self, keep: impl Fn(&Key) -> bool) -> Vec<usize> {
        (0..self.keys.len())
            .filter(|&r| keep(&self.keys[r]))
            .collect()
    }

    /// The levels of `entry`'s variable on `side`, checked against the
    /// codebook: no nulls, every level below the entry's level count.
    pub fn column(&self, side: Side, entry: &Entry) -> Result<&[u16]> {
        let name = side.column(&entry.variable);
        let column = self.table.column::<UInt16Array>(&name)?;
        if let Some(r) = (0..column.len()).find(|&r| column.is_null(r)) {
            return Err(Error::bad_file(
                self.path(),
                format!("row {r}: `{name}` is null, expected a level"),
            ));
        }
        let count = entry.quantizer.levels;
        if let Some(r) = column
            .values()
            .iter()
            .position(|&l| usize::from(l) >= count)
        {
            return Err(Error::bad_file(
                self.path(),
                format!(
                    "row {r}: `{name}` is level {}, but the codebook {} gives `{}` {count} levels \
                     (0…{})",
                    column.value(r),
                    self.codebook.display(),
                    entry.variable,
                    count - 1
                ),
            ));
        }
        Ok(column.values())
    }

    /// The levels of `entries`' variables on `side` of `rows`,
    /// `[variable][row]`, each column checked as [`Levels::column`] checks it.
    pub fn select(&self, side: Side, entries: &[&Entry], rows: &[usize]) -> Result<Vec<Vec<u16>>> {
        entries
            .iter()
            .map(|e| {
                let column = self.column(side, e)?;
                Ok(rows.iter().map(|&r| column[r]).collect())
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{edit_u16_columns, entry, keys, provenance};

    #[test]
    fn levels_read_back_as_written_and_split_by_role() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let (x, y) = (vec![vec![0, 1, 2]], vec![vec![1, 2, 7]]);
        write(&path, &keys(), &["a"], &x, &y, &provenance()).unwrap();
        let levels = Levels::read(&path, Path::new("codebook.parquet")).unwrap();
        assert_eq!(levels.keys(), keys());
        assert_eq!(
            (levels.train_rows(), levels.test_rows()),
            (vec![0, 1], vec![1, 2])
        );
        let a = entry("a");
        assert_eq!(levels.column(Side::Next, &a).unwrap(), [1, 2, 7]);
        assert_eq!(
            levels.select(Side::Current, &[&a], &[2, 0]).unwrap(),
            [vec![2, 0]]
        );
    }

    #[test]
    fn a_level_beyond_the_codebook_is_refused_by_row() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        write(
            &path,
            &keys(),
            &["a"],
            &[vec![0, 1, 2]],
            &[vec![1, 2, 3]],
            &provenance(),
        )
        .unwrap();
        edit_u16_columns(&path, |columns| columns[5].as_mut().unwrap()[2] = 8);
        let levels = Levels::read(&path, Path::new("cb/codebook.parquet")).unwrap();
        let message = levels
            .column(Side::Next, &entry("a"))
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("row 2: `y.a` is level 8, but the codebook cb/codebook.parquet gives `a` 8 levels (0…7)"),
            "{message}"
        );
    }
}
