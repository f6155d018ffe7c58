//! The Parquet reader and the checks every table gets: any bytes read (and
//! every column is then asked for by name and type) or are refused.
#![no_main]

use alnlab_common::table::Table;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let path = std::path::Path::new("table.parquet");
    let Ok(table) = Table::from_bytes(path, bytes.to_vec(), None) else {
        return;
    };
    let _ = table.require_no_nulls();
    for field in table.batch.schema().fields() {
        let _ = table.f64_column(field.name());
        let _ = table.strings(field.name());
    }
});
