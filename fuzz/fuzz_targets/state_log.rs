//! The trajectory-log reader: any bytes decode or are refused.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let _ = alnlab_common::state_log::from_bytes(
        std::path::Path::new("trajectory.mcap"),
        bytes,
    );
});
