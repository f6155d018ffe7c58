//! Parquet tables: every table alnlab writes is zstd-compressed, carries its
//! provenance as key-value metadata and a pinned `created_by`, and is written
//! atomically, so equal inputs give byte-identical files and no half-written
//! file ever looks finished.
//!
//! Parquet's writer here stores no page checksums, so alnlab adds one of its
//! own over the whole file: the key `alnlab.crc32` holds the CRC-32 of every
//! byte of the file, computed with the key's own eight hex digits read as
//! `00000000`. Any damaged byte — in the data, the footer or the checksum —
//! is then noticed on read. The reader checks it in every file that has it,
//! and insists on it in a file whose `created_by` says it was written so
//! (one flipped byte cannot remove both). Tables from other writers (pyarrow,
//! polars) have neither and read as they are, their page checksums checked
//! where they wrote them; snappy, gzip, lz4 and zstd pages all decode.

use std::collections::BTreeMap;
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

thread_local! {
    /// Set while this thread decodes inside [`contained`].
    static CONTAINED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `decode` — parquet's decoder on bytes not yet known to be sound —
/// turning a panic inside it into an error carrying its message. The
/// decoder asserts on some malformed pages (fuzzing found one in its
/// definition-level reader) rather than returning an error; such a panic
/// is a damaged file, and no panic message reaches the terminal.
fn contained<T>(decode: impl FnOnce() -> T) -> std::result::Result<T, String> {
    static QUIET_HOOK: std::sync::Once = std::sync::Once::new();
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !CONTAINED.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    CONTAINED.with(|c| c.set(true));
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(decode));
    CONTAINED.with(|c| c.set(false));
    outcome.map_err(|panic| {
        let message = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "the decoder gave up".into());
        format!("the decoder failed: {message}")
    })
}

/// The four bytes every Parquet file starts (and ends) with.
const PARQUET_MAGIC: &[u8] = b"PAR1";

/// The key-value metadata key holding the file's checksum.
pub const CHECKSUM_KEY: &str = "alnlab.crc32";
/// The checksum's value while it is computed.
const CHECKSUM_PLACEHOLDER: &[u8; 8] = b"00000000";

/// The `created_by` of every table alnlab writes; it says the file carries
/// its checksum.
fn created_by() -> String {
    format!("alnlab {ALNLAB_VERSION} crc32")
}

/// Writes `batch` to `path` (atomically) with `provenance` in the metadata
/// and the whole file's checksum.
pub fn write_parquet(path: &Path, batch: &RecordBatch, provenance: &Provenance) -> Result<()> {
    let mut metadata: Vec<KeyValue> = provenance
        .key_values()
        .into_iter()
        .map(|(k, v)| KeyValue::new(k, v))
        .collect();
    metadata.push(KeyValue::new(
        CHECKSUM_KEY.to_string(),
        String::from_utf8(CHECKSUM_PLACEHOLDER.to_vec()).expect("ASCII"),
    ));
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(
            ZstdLevel::try_new(3).expect("level 3 is valid"),
        ))
        .set_created_by(created_by())
        .set_key_value_metadata(Some(metadata))
        .build();
    let mut writer = ArrowWriter::try_new(Vec::new(), batch.schema(), Some(props))
        .map_err(|e| Error::bad_file(path, e))?;
    writer.write(batch).map_err(|e| Error::bad_file(path, e))?;
    let mut bytes = writer.into_inner().map_err(|e| Error::bad_file(path, e))?;
    let at = checksum_position(&bytes).expect("the footer holds the placeholder just written");
    let crc = crc32fast::hash(&bytes);
    bytes[at..at + 8].copy_from_slice(format!("{crc:08x}").as_bytes());
    atomic::write_bytes(path, &bytes)
}

/// Where the eight hex digits of the checksum lie in a Parquet file's bytes:
/// just after the last `alnlab.crc32` of the footer (its key-value list,
/// Thrift compact: the key, then a field header byte and the length byte
/// 8). Only the footer is searched: the file's last eight bytes give its
/// length, so the data pages are not scanned.
fn checksum_position(bytes: &[u8]) -> Option<usize> {
    let key = CHECKSUM_KEY.as_bytes();
    let tail = bytes.len().checked_sub(8)?;
    let footer_len = u32::from_le_bytes(bytes[tail..tail + 4].try_into().ok()?) as usize;
    let footer = tail.saturating_sub(footer_len);
    let key_at = footer
        + bytes[footer..tail]
            .windows(key.len())
            .rposition(|w| w == key)?;
    let at = key_at + key.len() + 2;
    (at + 8 <= bytes.len() && bytes[at - 1] == 8).then_some(at)
}

/// Checks the whole-file checksum of `bytes` if the file has one. Returns
/// whether it had one.
fn verify_checksum(path: &Path, bytes: &[u8]) -> Result<bool> {
    let Some(at) = checksum_position(bytes) else {
        return Ok(false);
    };
    // Fuzzing explores the decoder behind the checksum.
    if cfg!(fuzzing) {
        return Ok(true);
    }
    let stored = std::str::from_utf8(&bytes[at..at + 8])
        .ok()
        .and_then(|hex| u32::from_str_radix(hex, 16).ok());
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(&bytes[..at]);
    hasher.update(CHECKSUM_PLACEHOLDER);
    hasher.update(&bytes[at + 8..]);
    let computed = hasher.finalize();
    if stored != Some(computed) {
        return Err(Error::damaged(
            path,
            format!(
                "its checksum ({CHECKSUM_KEY}) does not match its bytes \
                 (stored {}, computed {computed:08x})",
                String::from_utf8_lossy(&bytes[at..at + 8])
            ),
        ));
    }
    Ok(true)
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
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Table::from_bytes(path, bytes, columns)
    }

    /// Reads a table held in `bytes` (`path` names it in errors), only the
    /// named columns when `columns` is given. The file's checksum is
    /// verified before anything in it is decoded.
    pub fn from_bytes(path: &Path, bytes: Vec<u8>, columns: Option<&[&str]>) -> Result<Table> {
        let checksummed = verify_checksum(path, &bytes)?;
        // A file that starts as Parquet does and then cannot be decoded is
        // damaged; one that does not is another kind of file.
        let parquet = bytes.starts_with(PARQUET_MAGIC);
        let undecodable = |what: String| {
            if parquet {
                Error::damaged(path, what)
            } else {
                Error::bad_file(path, format!("not a Parquet file ({what})"))
            }
        };
        let mut builder = ParquetRecordBatchReaderBuilder::try_new(bytes::Bytes::from(bytes))
            .map_err(|e| undecodable(format!("its footer cannot be read ({e})")))?;
        let written_with_checksum = builder
            .metadata()
            .file_metadata()
            .created_by()
            .is_some_and(|c| c == created_by());
        if written_with_checksum && !checksummed {
            return Err(Error::damaged(
                path,
                format!("alnlab wrote it with a checksum, but its `{CHECKSUM_KEY}` is gone"),
            ));
        }
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
            .map_err(|e| undecodable(e.to_string()))?;
        let batches = contained(|| reader.collect::<std::result::Result<Vec<_>, _>>())
            .map_err(|panic| undecodable(format!("its data cannot be decoded ({panic})")))?
            .map_err(|e| undecodable(format!("its data cannot be decoded ({e})")))?;
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

    /// An error naming the first null value's row and column, if any column
    /// holds one (for tables whose every value must be present).
    pub fn require_no_nulls(&self) -> Result<()> {
        let schema = self.batch.schema();
        for (field, column) in schema.fields().iter().zip(self.batch.columns()) {
            if let Some(r) = (0..column.len()).find(|&r| column.is_null(r)) {
                return Err(Error::bad_file(
                    &self.path,
                    format!("row {r}: `{}` is null, expected a value", field.name()),
                ));
            }
        }
        Ok(())
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

    /// The string column `name`, each value parsed as a `T` (a model's
    /// name as a [`crate::ModelId`]): a value that does not parse is an
    /// error naming its row and column.
    pub fn parsed<T: std::str::FromStr>(&self, name: &str) -> Result<Vec<T>>
    where
        T::Err: std::fmt::Display,
    {
        let column = self.column::<StringArray>(name)?;
        column
            .iter()
            .enumerate()
            .map(|(row, v)| {
                v.unwrap_or_default()
                    .parse()
                    .map_err(|e| Error::bad_file(&self.path, format!("row {row}: `{name}`: {e}")))
            })
            .collect()
    }

    /// The f64 column `name`.
    pub fn f64_column(&self, name: &str) -> Result<&Float64Array> {
        self.column::<Float64Array>(name)
    }

    /// The f64 column `name`, every value present and finite: a null, NaN or
    /// infinite value is an error naming its row and column.
    pub fn finite_f64_column(&self, name: &str) -> Result<&Float64Array> {
        let values = self.f64_column(name)?;
        match (0..values.len()).find(|&r| values.is_null(r) || !values.value(r).is_finite()) {
            Some(row) => Err(Error::bad_file(
                &self.path,
                format!(
                    "row {row}, column `{name}`: {} is not a finite number",
                    if values.is_null(row) {
                        "null".to_string()
                    } else {
                        values.value(row).to_string()
                    }
                ),
            )),
            None => Ok(values),
        }
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
    #[test]
    fn a_panic_while_decoding_is_an_error_and_later_panics_still_panic() {
        let err = super::contained(|| -> u8 { panic!("offset + len out of bounds") }).unwrap_err();
        assert_eq!(err, "the decoder failed: offset + len out of bounds");
        assert_eq!(super::contained(|| 7), Ok(7));
        assert!(std::panic::catch_unwind(|| panic!("outside")).is_err());
    }

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
    fn every_flipped_byte_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        write_parquet(&path, &sample(), &provenance()).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(Table::from_bytes(&path, bytes.clone(), None).is_ok());
        for at in 0..bytes.len() {
            let mut damaged = bytes.clone();
            damaged[at] ^= 0x04;
            let err = Table::from_bytes(&path, damaged, None)
                .err()
                .unwrap_or_else(|| panic!("a flip at byte {at} was not noticed"));
            assert!(err.to_string().contains("t.parquet"), "{err}");
        }
    }

    /// A table as another writer makes it: no alnlab checksum, `codec`
    /// compression, dictionary pages on or off.
    fn foreign(path: &Path, codec: Compression, dictionary: bool) {
        let props = WriterProperties::builder()
            .set_compression(codec)
            .set_dictionary_enabled(dictionary)
            .set_created_by("parquet-cpp-arrow version 21.0.0".into())
            .build();
        let file = std::fs::File::create(path).unwrap();
        let mut writer = ArrowWriter::try_new(file, sample().schema(), Some(props)).unwrap();
        writer.write(&sample()).unwrap();
        writer.close().unwrap();
    }

    #[test]
    fn tables_from_other_writers_read_in_every_common_codec() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        let codecs = [
            Compression::UNCOMPRESSED,
            Compression::SNAPPY,
            Compression::LZ4_RAW,
            Compression::GZIP(Default::default()),
            Compression::ZSTD(Default::default()),
        ];
        for codec in codecs {
            for dictionary in [false, true] {
                foreign(&path, codec, dictionary);
                let t = Table::read(&path).unwrap_or_else(|e| panic!("{codec:?}: {e}"));
                assert_eq!(t.strings("name").unwrap(), ["a", "b", "c"]);
                assert_eq!(t.f64_column("x").unwrap().value(2), 1e9);
            }
        }
    }

    #[test]
    fn a_checksummed_file_without_its_checksum_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        write_parquet(&path, &sample(), &provenance()).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        let at = checksum_position(&bytes).unwrap() - 3;
        bytes[at] = b'x'; // `alnlab.crc3x`: the key is gone, `created_by` remains
        let err = Table::from_bytes(&path, bytes, None)
            .unwrap_err()
            .to_string();
        assert!(err.contains("is gone"), "{err}");
    }

    #[test]
    fn fuzzings_slow_foreign_table_is_refused_as_damaged() {
        // A table the fuzzer made (fuzz/README.md): without alnlab's
        // checksum it reaches parquet's decoder, whose Thrift skipping
        // takes about a second over its crafted page headers, then fails.
        let bytes = include_bytes!("../tests/data/fuzz-slow-thrift.parquet").to_vec();
        let path = Path::new("fuzz-slow-thrift.parquet");
        let err = Table::from_bytes(path, bytes, None).unwrap_err();
        assert_eq!(err.exit_code(), 1, "{err}");
        assert!(err.to_string().contains("damaged"), "{err}");
    }

    #[test]
    fn truncated_and_garbage_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        write_parquet(&path, &sample(), &provenance()).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        // Empty: no Parquet file at all (the user's to fix); cut short after
        // its magic: a damaged one.
        for (cut, code) in [(0, 2), (4, 1), (bytes.len() / 2, 1), (bytes.len() - 1, 1)] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let err = Table::read(&path).unwrap_err();
            assert!(err.to_string().contains("t.parquet"), "{err}");
            assert_eq!(err.exit_code(), code, "cut at {cut}: {err}");
        }
        std::fs::write(&path, b"name,n\na,1\n").unwrap();
        let err = Table::read(&path).unwrap_err();
        assert!(err.to_string().contains("not a Parquet file"), "{err}");
        assert_eq!(err.exit_code(), 2);
        // Corrupt the middle (the data pages) but keep the footer intact.
        let mut bad = bytes.clone();
        for b in &mut bad[8..bytes.len() / 3] {
            *b ^= 0x5a;
        }
        std::fs::write(&path, &bad).unwrap();
        assert_eq!(Table::read(&path).unwrap_err().exit_code(), 1);
    }
}
