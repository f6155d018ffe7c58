//! Provenance: where an artifact came from. Written as key-value metadata into
//! every Parquet file and as a metadata record into every MCAP log.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::ALNLAB_VERSION;

/// The origin of one artifact. Every field is deterministic (no clock, no
/// host name) and follows from the stage's cache key alone (not the manifest
/// that happened to ask for it), so equal inputs give byte-identical
/// artifacts whichever manifest — or archived dataset — they came from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The stage that wrote the artifact (`simulate`, `stride`, …).
    pub stage: String,
    /// The stage's resolved parameters, as canonical JSON.
    pub params: serde_json::Value,
    /// SHA-256 of each input file, by role (`trajectory`, `stats`, …).
    pub inputs: BTreeMap<String, String>,
}

impl Provenance {
    /// The provenance written by [`Provenance::key_values`] into a file's
    /// metadata, read back; `None` if the metadata does not hold one.
    pub fn from_key_values(metadata: &BTreeMap<String, String>) -> Option<Provenance> {
        Some(Provenance {
            stage: metadata.get("alnlab.stage")?.clone(),
            params: serde_json::from_str(metadata.get("alnlab.params")?).ok()?,
            inputs: serde_json::from_str(metadata.get("alnlab.inputs")?).ok()?,
        })
    }

    /// The key-value pairs written into a file's metadata, keys prefixed
    /// `alnlab.`.
    pub fn key_values(&self) -> Vec<(String, String)> {
        vec![
            ("alnlab.stage".into(), self.stage.clone()),
            ("alnlab.version".into(), ALNLAB_VERSION.into()),
            ("alnlab.params".into(), self.params.to_string()),
            (
                "alnlab.inputs".into(),
                serde_json::to_string(&self.inputs).expect("a string map serializes"),
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_values_read_back() {
        let provenance = Provenance {
            stage: "train".into(),
            params: serde_json::json!({ "seed": 3, "params": { "leaves": 64 } }),
            inputs: BTreeMap::from([("levels".to_string(), "ab".to_string())]),
        };
        let metadata: BTreeMap<String, String> = provenance.key_values().into_iter().collect();
        assert_eq!(Provenance::from_key_values(&metadata), Some(provenance));
        assert_eq!(Provenance::from_key_values(&BTreeMap::new()), None);
    }
}
