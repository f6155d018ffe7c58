//! Parquet tables: every table alnlab writes is zstd-compressed, carries its
//! provenance as key-value metadata and a pinned `created_by`, and is written
//! atomically, so equal inputs give byte-identical files and no half-written
//! file ever looks finished.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use arrow_array::{Array, Float64Array, RecordBatch, StringArray};
use parquet::arrow::ArrowWriter;
use parquet::arrow::ProjectionMask;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;

use crate::{ALNLAB_VERSION, Error, Provenance, Result, atomic};

/// Writes `batch` to `path` (atomically) with `provenance` in the metadata.
pub fn write_parquet(path: &Path, batch: &RecordBatch, provenance: &Provenance) -> Result<()> {
    let metadata = provenance
        .key_values()
        .into_iter()
        .map(|(k, v)| KeyValue::new(k, v))
        .collect();
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(
            ZstdLevel::try_new(3).expect("level 3 is valid"),
        ))
        .set_created_by(format!("alnlab {ALNLAB_VERSION}"))
        .set_key_value_metadata(Some(metadata))
        .build();
    atomic::write_file(path, |out| {
        let mut writer = ArrowWriter::try_new(out, batch.schema(), Some(props))
            .map_err(|e| Error::bad_file(path, e))?;
        writer.write(batch).map_err(|e| Error::bad_file(path, e))?;
        writer.close().map_err(|e| Error::bad_file(path, e))?;
        Ok(())
    })
}

/// A whole Parquet table read into memory, with its key-value metadata.
#[derive(Debug)]
pub struct Table {
    /// All rows, in one batch.
    pub batch: RecordBatch,
    /// The file's key-value metadata (provenance and anything else).
    pub metadata: BTreeMap<String, String>,
    path: std::path::PathBuf,
}

impl Table {
    /// Reads the table at `path`. A missing, truncated or corrupt file is an
    /// error naming the file.
    pub fn read(path: &Path) -> Result<Table> {
        Table::read_projected(path, None)
    }

    /// Reads only the named columns of the table at `path` (the others are
    /// not decoded); a name the file lacks shows up as a missing column.
    pub fn read_columns(path: &Path, columns: &[&str]) -> Result<Table> {
        Table::read_projected(path, Some(columns))
    }

    fn read_projected(path: &Path, columns: Option<&[&str]>) -> Result<Table> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let mut builder = ParquetRecordBatchReaderBuilder::try_new(file)
            .map_err(|e| Error::bad_file(path, format!("not a readable Parquet file ({e})")))?;
        if let Some(columns) = columns {
            let mask = ProjectionMask::columns(builder.parquet_schema(), columns.iter().copied());
            builder = builder.with_projection(mask);
        }
        let metadata = builder
            .metadata()
            .file_metadata()
            .key_value_metadata()
            .map(|kvs| {
                kvs.iter()
                    .map(|kv| (kv.key.clone(), kv.value.clone().unwrap_or_default()))
                    .collect()
            })
            .unwrap_or_default();
        let rows = builder.metadata().file_metadata().num_rows().max(1) as usize;
        let schema = builder.schema().clone();
        let reader = builder
            .with_batch_size(rows)
            .build()
            .map_err(|e| Error::bad_file(path, e))?;
        let batches = reader
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|e| Error::bad_file(path, format!("corrupt Parquet data ({e})")))?;
        let batch = match batches.len() {
            0 => RecordBatch::new_empty(schema),
            1 => batches.into_iter().next().expect("one batch"),
            n => {
                return Err(Error::bad_file(
                    path,
                    format!("expected the rows in one batch, got {n}"),
                ));
            }
        };
        Ok(Table {
            batch,
            metadata,
            path: path.to_path_buf(),
        })
    }

    /// The number of rows.
    pub fn num_rows(&self) -> usize {
        self.batch.num_rows()
    }

    /// The column `name`, which must exist and be of type `A`.
    pub fn column<A: Array + 'static>(&self, name: &str) -> Result<&A> {
        let column = self
            .batch
            .column_by_name(name)
            .ok_or_else(|| Error::bad_file(&self.path, format!("has no column `{name}`")))?;
        column.as_any().downcast_ref::<A>().ok_or_else(|| {
            Error::bad_file(
                &self.path,
                format!(
                    "column `{name}` has type {}, expected {}",
                    column.data_type(),
                    std::any::type_name::<A>()
                        .rsplit("::")
                        .next()
                        .unwrap_or("?")
                ),
            )
        })
    }

    /// The string column `name`, as owned strings (nulls as empty).
    pub fn strings(&self, name: &str) -> Result<Vec<String>> {
        Ok(self
            .column::<StringArray>(name)?
            .iter()
            .map(|v| v.unwrap_or_default().to_string())
            .collect())
    }

    /// The f64 column `name`.
    pub fn f64_column(&self, name: &str) -> Result<&Float64Array> {
        self.column::<Float64Array>(name)
    }

    /// The path the table was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Builds a record batch from named, equally long columns; a column is
/// nullable when it holds a null.
pub fn batch(columns: Vec<(&str, Arc<dyn Array>)>) -> RecordBatch {
    let fields: Vec<arrow_schema::Field> = columns
        .iter()
        .map(|(name, array)| {
            arrow_schema::Field::new(*name, array.data_type().clone(), array.null_count() > 0)
        })
        .collect();
    let schema = Arc::new(arrow_schema::Schema::new(fields));
    RecordBatch::try_new(schema, columns.into_iter().map(|(_, a)| a).collect())
        .expect("columns of one table have equal lengths")
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::UInt32Array;

    fn sample() -> RecordBatch {
        batch(vec![
            ("name", Arc::new(StringArray::from(vec!["a", "b", "c"]))),
            ("n", Arc::new(UInt32Array::from(vec![1, 2, 3]))),
            ("x", Arc::new(Float64Array::from(vec![0.5, -1.0, 1e9]))),
        ])
    }

    fn provenance() -> Provenance {
        Provenance {
            stage: "test".into(),
            params: serde_json::json!({"k": 1}),
            inputs: [("pairs".to_string(), "ab".to_string())].into(),
        }
    }

    #[test]
    fn round_trip_with_metadata_and_identical_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.parquet"), dir.path().join("b.parquet"));
        write_parquet(&a, &sample(), &provenance()).unwrap();
        write_parquet(&b, &sample(), &provenance()).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        let t = Table::read(&a).unwrap();
        assert_eq!(t.num_rows(), 3);
        assert_eq!(t.f64_column("x").unwrap().value(2), 1e9);
        assert_eq!(t.metadata["alnlab.stage"], "test");
        assert_eq!(t.metadata["alnlab.inputs"], r#"{"pairs":"ab"}"#);
        let err = t.f64_column("n").unwrap_err().to_string();
        assert!(err.contains("column `n` has type UInt32"), "{err}");
        assert!(
            t.f64_column("zz")
                .unwrap_err()
                .to_string()
                .contains("no column `zz`")
        );
    }

    #[test]
    fn truncated_and_garbage_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        write_parquet(&path, &sample(), &provenance()).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        for cut in [0, 4, bytes.len() / 2, bytes.len() - 1] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let err = Table::read(&path).unwrap_err();
            assert!(err.to_string().contains("t.parquet"), "{err}");
            assert_eq!(err.exit_code(), 2);
        }
        // Corrupt the middle (the data pages) but keep the footer intact.
        let mut bad = bytes.clone();
        for b in &mut bad[8..bytes.len() / 3] {
            *b ^= 0x5a;
        }
        std::fs::write(&path, &bad).unwrap();
        assert!(Table::read(&path).is_err());
    }
}
