//! The run-record reader (`alnlab runs`, `report`, `export mlflow`): any
//! bytes give a record whose names cannot lead out of a folder, or are
//! refused.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let _ = alnlab::records::from_bytes(std::path::Path::new("run.json"), bytes);
});
