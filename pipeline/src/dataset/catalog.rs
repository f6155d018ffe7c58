//! The catalog's content: `catalog.toml`'s entries — one per dataset
//! version, with its files, sizes, hashes, provenance, and the SHA-256 of
//! its own content, so that an edited entry is caught like a damaged file.

use alnlab_common::hash::sha256_hex;
use serde::{Deserialize, Serialize};

/// The catalog's file name in the archive folder.
pub const CATALOG_FILE: &str = "catalog.toml";
/// The roles a dataset always holds: the simulate and stride outputs.
pub const BASE_ROLES: [&str; 3] = ["trajectory", "stats", "pairs"];
/// The roles `--with-levels` adds: the quantize outputs.
pub const LEVEL_ROLES: [&str; 2] = ["codebook", "levels"];
/// The role of an imported table of a robot's samples (one a trajectory).
pub const TABLE_ROLE: &str = "table";
/// The role of an imported dataset's licence text.
pub const LICENCE_ROLE: &str = "licence";

/// `catalog.toml`: every archived dataset version.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Catalog {
    /// The entries, in the order they were archived.
    #[serde(default, rename = "dataset")]
    pub datasets: Vec<Entry>,
}

/// One dataset version.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Entry {
    /// Letters, digits, `-` and `_`.
    pub name: String,
    /// 1 for the first version of a name, then 2, 3, …
    pub version: u32,
    /// SHA-256 of every other field of the entry (canonical JSON): the
    /// dataset's identity, and the check that the entry was not edited.
    pub sha256: String,
    /// When it was archived (RFC 3339, UTC).
    pub created: String,
    /// Total size of its files.
    pub bytes: u64,
    /// The run it was archived from (none for imported recordings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<DatasetProvenance>,
    /// Where imported recordings were published, and on what terms (none
    /// for a run's data).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<ImportedSource>,
    /// Its files.
    pub files: Vec<FileEntry>,
}

/// Recordings made elsewhere and imported (`alnlab dataset import`): where
/// they were published, how to cite them and the licence they are kept
/// under (its text is the dataset's `licence` file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportedSource {
    /// Where they were published (a URL, with a commit or version where
    /// there is one).
    pub url: String,
    pub citation: String,
    /// The licence's SPDX identifier.
    pub licence: String,
    /// What else a user must know (what was converted, caveats).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub notes: String,
}

/// The run a dataset was archived from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetProvenance {
    pub experiment: String,
    pub variant: String,
    /// The producing manifest's path, as the run recorded it.
    pub manifest: String,
    pub manifest_sha256: String,
    /// Which replicate of the variant the data are (from 1); absent in
    /// entries archived before replicates were named.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replicate: Option<u32>,
    /// The seed that made the data: the replicate's own.
    pub seed: u64,
    pub alnlab_version: String,
    /// Empty when the run was not made in a git checkout.
    pub git_commit: String,
}

/// One file of a dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileEntry {
    /// Its role in the stage graph (`trajectory`, `stats`, `pairs`, …).
    pub role: String,
    /// Its file name when restored (`trajectory.mcap`, …).
    pub name: String,
    pub sha256: String,
    pub bytes: u64,
}

impl Entry {
    /// `name@version`.
    pub fn label(&self) -> String {
        format!("{}@{}", self.name, self.version)
    }

    /// The SHA-256 of every field but `sha256`, as canonical JSON (keys
    /// sorted).
    pub fn content_sha256(&self) -> String {
        let mut value = serde_json::to_value(self).expect("entries serialize");
        value
            .as_object_mut()
            .expect("an entry is an object")
            .remove("sha256");
        sha256_hex(canonical_json(&value).as_bytes())
    }

    /// The file with `role`, if the dataset has one.
    pub fn file(&self, role: &str) -> Option<&FileEntry> {
        self.files.iter().find(|f| f.role == role)
    }

    /// Whether the dataset holds the quantize outputs too.
    pub fn has_levels(&self) -> bool {
        LEVEL_ROLES.iter().all(|r| self.file(r).is_some())
    }

    /// The imported tables of samples, in order (none for a run's data).
    pub fn tables(&self) -> Vec<&FileEntry> {
        self.files.iter().filter(|f| f.role == TABLE_ROLE).collect()
    }
}

/// JSON with object keys sorted at every depth, so equal content always
/// hashes the same.
fn canonical_json(value: &serde_json::Value) -> String {
    match value {
        serde_json::Value::Object(map) => {
            let mut keys: Vec<&String> = map.keys().collect();
            keys.sort();
            let fields: Vec<String> = keys
                .iter()
                .map(|k| {
                    format!(
                        "{}:{}",
                        serde_json::Value::from(k.as_str()),
                        canonical_json(&map[*k])
                    )
                })
                .collect();
            format!("{{{}}}", fields.join(","))
        }
        serde_json::Value::Array(items) => {
            let items: Vec<String> = items.iter().map(canonical_json).collect();
            format!("[{}]", items.join(","))
        }
        other => other.to_string(),
    }
}
