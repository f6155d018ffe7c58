//! What the tables' tests share: a provenance, a codebook entry, and a written table's rows
//! taken again or a column of it edited, as damage would.

use std::path::Path;
use std::sync::Arc;

use alnlab_common::Provenance;
use alnlab_common::table::{self, Table};
use arrow_array::{Array, RecordBatch, UInt16Array, UInt32Array};

/// A learned variable `variable` of 8 levels over [0, 1], binary-coded.
pub(crate) fn entry(variable: &str) -> alnlab_codes::Entry {
    alnlab_codes::Entry {
        variable: variable.into(),
        learned: true,
        note: String::new(),
        quantizer: alnlab_codes::Quantizer {
            min: 0.0,
            max: 1.0,
            levels: 8,
        },
        code: alnlab_codes::codes::Code::Binary,
        width: 3,
        walk_step: 0,
        walk_span: 0,
        seed: 0,
        clamped: 0,
    }
}

pub(crate) fn provenance() -> Provenance {
    Provenance {
        stage: "test".into(),
        params: serde_json::Value::Null,
        inputs: Default::default(),
    }
}

/// Writes the table at `path` back with only its rows `rows`, in that order.
pub(crate) fn take_rows(path: &Path, rows: &[u32]) {
    let table = Table::read(path).unwrap();
    let indices = UInt32Array::from(rows.to_vec());
    let columns = table
        .batch
        .columns()
        .iter()
        .map(|c| arrow_select::take::take(c, &indices, None).unwrap())
        .collect::<Vec<_>>();
    let batch = RecordBatch::try_new(table.batch.schema(), columns).unwrap();
    table::write_parquet(path, &batch, &provenance()).unwrap();
}

/// Writes the table at `path` back with its u16 columns, by position,
/// changed by `edit`.
pub(crate) fn edit_u16_columns(path: &Path, edit: impl FnOnce(&mut [Option<Vec<u16>>])) {
    let table = Table::read(path).unwrap();
    let mut values: Vec<Option<Vec<u16>>> = table
        .batch
        .columns()
        .iter()
        .map(|c| {
            c.as_any()
                .downcast_ref::<UInt16Array>()
                .map(|u| u.values().to_vec())
        })
        .collect();
    edit(&mut values);
    let columns: Vec<Arc<dyn Array>> = table
        .batch
        .columns()
        .iter()
        .zip(values)
        .map(|(c, v)| {
            v.map_or(c.clone(), |v| {
                Arc::new(UInt16Array::from(v)) as Arc<dyn Array>
            })
        })
        .collect();
    let batch = RecordBatch::try_new(table.batch.schema(), columns).unwrap();
    table::write_parquet(path, &batch, &provenance()).unwrap();
}

/// Three pairs' keys: two of one scene's runs, one of another; one of each
/// split.
pub(crate) fn keys() -> Vec<crate::pairs::Key> {
    use crate::pairs::{Key, Split};
    let key = |scene: &str, run, step, split| Key {
        scene: scene.into(),
        run,
        step,
        split,
    };
    vec![
        key("worm", 0, 3, Split::Train),
        key("worm", 1, 9, Split::Both),
        key("chain", 0, 0, Split::Test),
    ]
}
