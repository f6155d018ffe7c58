//! The model-file reader: any bytes give a model whose every tree checks
//! out, or are refused.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let _ = alnlab_aln::model::Model::from_bytes(std::path::Path::new("model.aln"), bytes);
});
