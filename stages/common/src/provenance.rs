//! Provenance: where an artifact came from. Written as key-value metadata into
//! every Parquet file and as a metadata record into every MCAP log.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::ALNLAB_VERSION;

/// The origin of one artifact. Every field is deterministic (no clock, no
/// host name), so equal inputs give byte-identical artifacts.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The stage that wrote the artifact (`simulate`, `stride`, …).
    pub stage: String,
    /// SHA-256 of the manifest of the run that first produced the artifact
    /// (empty when the stage ran alone, without a manifest).
    pub manifest_sha256: String,
    /// The stage's resolved parameters, as canonical JSON.
    pub params: serde_json::Value,
    /// SHA-256 of each input file, by role (`trajectory`, `stats`, …).
    pub inputs: BTreeMap<String, String>,
}

impl Provenance {
    /// The key-value pairs written into a file's metadata, keys prefixed
    /// `alnlab.`.
    pub fn key_values(&self) -> Vec<(String, String)> {
        vec![
            ("alnlab.stage".into(), self.stage.clone()),
            ("alnlab.version".into(), ALNLAB_VERSION.into()),
            (
                "alnlab.manifest_sha256".into(),
                self.manifest_sha256.clone(),
            ),
            ("alnlab.params".into(), self.params.to_string()),
            (
                "alnlab.inputs".into(),
                serde_json::to_string(&self.inputs).expect("a string map serializes"),
            ),
        ]
    }
}
