//! Dictionary-encoded string columns: a model's or a variable's name stored
//! once, each row a small key — quick to write and to group by.

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::Table;
use alnlab_common::{Error, ModelId, Result};
use arrow_array::cast::AsArray;
use arrow_array::types::UInt16Type;
use arrow_array::{Array, DictionaryArray, StringArray, UInt16Array};

/// A column of `keys` into `names`.
pub(crate) fn column<T: ToString>(keys: Vec<u16>, names: &[T]) -> DictionaryArray<UInt16Type> {
    DictionaryArray::new(
        UInt16Array::from(keys),
        Arc::new(StringArray::from_iter_values(
            names.iter().map(T::to_string),
        )),
    )
}

/// The `model` column of `table`: the models it names ([`ModelId`]; a
/// name no model has is damage, named), and each row's key.
pub(crate) fn models(table: &Table) -> Result<(Vec<ModelId>, &[u16])> {
    let (names, keys) = read(table, "model")?;
    let models = names
        .iter()
        .map(|name| {
            name.parse()
                .map_err(|e| Error::bad_file(table.path(), format!("column `model`: {e}")))
        })
        .collect::<Result<_>>()?;
    Ok((models, keys))
}

/// The dictionary column `name` of `table`: its names, and each row's key
/// (checked to name one of them, with no nulls).
pub(crate) fn read<'t>(table: &'t Table, name: &str) -> Result<(Vec<String>, &'t [u16])> {
    let path = table.path();
    let column = table.column::<DictionaryArray<UInt16Type>>(name)?;
    let values = column.values().as_string_opt::<i32>().ok_or_else(|| {
        Error::bad_file(
            path,
            format!("column `{name}` must be a dictionary of strings"),
        )
    })?;
    let names: Vec<String> = values
        .iter()
        .map(|v| v.unwrap_or_default().to_string())
        .collect();
    if let Some(r) = (0..column.len()).find(|&r| column.is_null(r)) {
        return Err(null(path, r, name));
    }
    let keys = column.keys().values().as_ref();
    if let Some(r) = keys.iter().position(|&k| usize::from(k) >= names.len()) {
        return Err(Error::bad_file(
            path,
            format!(
                "row {r}: `{name}` key {} names none of its {} values",
                keys[r],
                names.len()
            ),
        ));
    }
    Ok((names, keys))
}

/// The error for a null where every row needs a value.
pub(crate) fn null(path: &Path, row: usize, column: &str) -> Error {
    Error::bad_file(
        path,
        format!("row {row}: `{column}` is null, expected a value"),
    )
}

/// How many blocks of rows `counts` (each a count and what it counts)
/// multiply to — every model's, variable's, … own rows. Every block holds a
/// row at least, so more blocks than `table` has rows is damage, refused
/// before it can size an allocation.
pub(crate) fn blocks(table: &Table, counts: &[(usize, &str)]) -> Result<usize> {
    counts
        .iter()
        .try_fold(1usize, |product, &(n, _)| product.checked_mul(n))
        .filter(|&b| b <= table.num_rows().max(1))
        .ok_or_else(|| {
            let what: Vec<String> = counts
                .iter()
                .map(|(n, what)| format!("{n} {what}"))
                .collect();
            Error::bad_file(
                table.path(),
                format!(
                    "{} cannot fit in {} rows",
                    what.join(" × "),
                    table.num_rows()
                ),
            )
        })
}
