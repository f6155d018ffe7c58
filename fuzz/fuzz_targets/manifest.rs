//! The manifest reader: any text is parsed, validated and budgeted, or
//! refused with an error — never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|text: &str| {
    let _ = alnlab::manifest::Manifest::parse(text, std::path::Path::new("fuzz.toml"));
});
