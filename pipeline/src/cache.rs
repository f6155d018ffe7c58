//! The artifact cache: every stage output lives in its own folder,
//! `<out>/cache/<stage>/<key>/`, where the key is a hash of the stage's name,
//! format version, resolved parameters and its inputs' content hashes. A
//! folder is filled under a temporary name and renamed when complete, so a
//! folder under its final name is always whole; leftovers of killed runs are
//! swept at the start of the next run.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use alnlab_common::hash::{sha256_file, sha256_hex};
use alnlab_common::{Error, Provenance, Result, atomic};
use serde::{Deserialize, Serialize};

/// Name of the record inside every artifact folder.
const RECORD_FILE: &str = "artifact.json";

/// What one stage invocation is, for the purpose of caching.
#[derive(Debug, Serialize)]
pub struct StageKey<'a> {
    /// The stage's name.
    pub stage: &'a str,
    /// The stage's format version.
    pub format_version: u32,
    /// The resolved parameters (seed included).
    pub params: &'a serde_json::Value,
    /// Content hash of each input file, by role.
    pub inputs: BTreeMap<String, String>,
}

impl StageKey<'_> {
    /// The cache key of the artifact `provenance` describes: a stage's
    /// provenance holds exactly its key's name, parameters and input hashes.
    pub fn of(provenance: &Provenance, format_version: u32) -> String {
        StageKey {
            stage: &provenance.stage,
            format_version,
            params: &provenance.params,
            inputs: provenance.inputs.clone(),
        }
        .hash()
    }

    /// The cache key: SHA-256 of the canonical JSON of the whole key.
    pub fn hash(&self) -> String {
        sha256_hex(
            serde_json::to_string(self)
                .expect("keys serialize")
                .as_bytes(),
        )
    }
}

/// One output file of an artifact.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileRecord {
    /// File name inside the artifact folder.
    pub file: String,
    /// SHA-256 of its content.
    pub sha256: String,
    /// Its size in bytes.
    pub bytes: u64,
}

/// The record kept beside a finished artifact's files.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArtifactRecord {
    /// The stage that made it.
    pub stage: String,
    /// Its cache key.
    pub key: String,
    /// Its files, by role.
    pub files: BTreeMap<String, FileRecord>,
    /// How long the stage took to make it (s).
    pub compute_seconds: f64,
}

/// A finished artifact in the cache.
#[derive(Clone, Debug)]
pub struct Artifact {
    /// Its folder.
    pub dir: PathBuf,
    /// Its record.
    pub record: ArtifactRecord,
}

impl Artifact {
    /// The path of the file with `role`.
    pub fn path(&self, role: &str) -> PathBuf {
        self.dir.join(&self.record.files[role].file)
    }

    /// The content hash of the file with `role`.
    pub fn sha256(&self, role: &str) -> &str {
        &self.record.files[role].sha256
    }
}

/// The cache under `<out>/cache`.
pub struct Cache {
    root: PathBuf,
}

impl Cache {
    /// The cache of the output folder `out`.
    pub fn new(out: &Path) -> Cache {
        Cache {
            root: out.join("cache"),
        }
    }

    /// A store with the cache's layout rooted at `root` (for work kept
    /// apart from the cache, such as training shards).
    pub fn at(root: &Path) -> Cache {
        Cache {
            root: root.to_path_buf(),
        }
    }

    /// The store's root folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    fn dir(&self, stage: &str, key: &str) -> PathBuf {
        self.root.join(stage).join(key)
    }

    /// The finished artifact with this key, if there is one whose files are
    /// all present with their recorded sizes and content hashes. A damaged
    /// artifact is named on stderr and not used (the run makes it again).
    pub fn lookup(&self, stage: &str, key: &str) -> Option<Artifact> {
        let dir = self.dir(stage, key);
        let record: ArtifactRecord =
            serde_json::from_slice(&fs::read(dir.join(RECORD_FILE)).ok()?).ok()?;
        if record.key != key {
            return None;
        }
        for f in record.files.values() {
            let path = dir.join(&f.file);
            let intact = fs::metadata(&path).is_ok_and(|m| m.len() == f.bytes)
                && sha256_file(&path).is_ok_and(|sha256| sha256 == f.sha256);
            if !intact {
                eprintln!(
                    "warning: {} is missing or damaged (its size or sha256 is not the recorded one); \
                     making it again",
                    path.display()
                );
                return None;
            }
        }
        Some(Artifact { dir, record })
    }

    /// Makes the artifact: `make` writes the files named in `outputs`
    /// (role → file name) into a fresh temporary folder, which is renamed to
    /// the artifact's folder once every file and the record are written.
    pub fn make(
        &self,
        stage: &str,
        key: &str,
        outputs: &[(&str, &str)],
        make: impl FnOnce(&Path) -> Result<()>,
    ) -> Result<Artifact> {
        let dir = self.dir(stage, key);
        let tmp = atomic::temporary_name(&dir);
        if tmp.exists() {
            fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
        }
        fs::create_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let started = Instant::now();
        let result = make(&tmp).and_then(|()| {
            let mut files = BTreeMap::new();
            for (role, file) in outputs {
                let path = tmp.join(file);
                let bytes = fs::metadata(&path).map_err(|e| Error::io(&path, e))?.len();
                let sha256 = sha256_file(&path)?;
                files.insert(
                    role.to_string(),
                    FileRecord {
                        file: file.to_string(),
                        sha256,
                        bytes,
                    },
                );
            }
            let record = ArtifactRecord {
                stage: stage.into(),
                key: key.into(),
                files,
                compute_seconds: started.elapsed().as_secs_f64(),
            };
            let json = serde_json::to_vec_pretty(&record).expect("records serialize");
            atomic::write_bytes(&tmp.join(RECORD_FILE), &json)?;
            if dir.exists() {
                // A damaged artifact (lookup refused it): replace it whole.
                fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
            }
            fs::rename(&tmp, &dir).map_err(|e| Error::io(&dir, e))?;
            Ok(Artifact {
                dir: dir.clone(),
                record,
            })
        });
        if result.is_err() {
            let _ = fs::remove_dir_all(&tmp);
        }
        result
    }

    /// Removes the temporary folders and files that killed runs left behind.
    /// Only call while holding the output folder's lock.
    pub fn sweep_unfinished(&self) -> Result<usize> {
        let mut removed = 0;
        let Ok(stages) = fs::read_dir(&self.root) else {
            return Ok(0);
        };
        for stage in stages.flatten() {
            let Ok(entries) = fs::read_dir(stage.path()) else {
                continue;
            };
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                if name.starts_with('.') && name.contains(".tmp-") {
                    let path = entry.path();
                    let gone = if path.is_dir() {
                        fs::remove_dir_all(&path)
                    } else {
                        fs::remove_file(&path)
                    };
                    gone.map_err(|e| Error::io(&path, e))?;
                    removed += 1;
                }
            }
        }
        Ok(removed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(params: serde_json::Value) -> String {
        StageKey {
            stage: "s",
            format_version: 1,
            params: &params,
            inputs: BTreeMap::new(),
        }
        .hash()
    }

    #[test]
    fn keys_change_with_every_part() {
        let p = serde_json::json!({"n": 9});
        let base = key(p.clone());
        assert_eq!(base, key(p.clone()));
        assert_ne!(base, key(serde_json::json!({"n": 8})));
        let other_version = StageKey {
            stage: "s",
            format_version: 2,
            params: &p,
            inputs: BTreeMap::new(),
        };
        assert_ne!(base, other_version.hash());
        let with_input = StageKey {
            stage: "s",
            format_version: 1,
            params: &p,
            inputs: [("trajectory".into(), "ab".into())].into(),
        };
        assert_ne!(base, with_input.hash());
    }

    #[test]
    fn make_then_lookup_and_failed_make_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::new(dir.path());
        assert!(cache.lookup("s", "k").is_none());
        let failed = cache.make("s", "k", &[("x", "x.bin")], |d| {
            fs::write(d.join("x.bin"), b"half").unwrap();
            Err(Error::Invalid("no".into()))
        });
        assert!(failed.is_err());
        assert_eq!(fs::read_dir(dir.path().join("cache/s")).unwrap().count(), 0);
        let made = cache
            .make("s", "k", &[("x", "x.bin")], |d| {
                fs::write(d.join("x.bin"), b"whole").map_err(|e| Error::io(d, e))
            })
            .unwrap();
        assert_eq!(made.sha256("x"), sha256_hex(b"whole"));
        let found = cache.lookup("s", "k").unwrap();
        assert_eq!(found.record, made.record);
        // A changed byte (same size) makes the artifact unusable, as does a
        // truncated file.
        fs::write(found.path("x"), b"whale").unwrap();
        assert!(cache.lookup("s", "k").is_none());
        fs::write(found.path("x"), b"who").unwrap();
        assert!(cache.lookup("s", "k").is_none());
    }

    #[test]
    fn sweep_removes_only_unfinished() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::new(dir.path());
        fs::create_dir_all(dir.path().join("cache/s/.k.tmp-123")).unwrap();
        fs::create_dir_all(dir.path().join("cache/s/k")).unwrap();
        assert_eq!(cache.sweep_unfinished().unwrap(), 1);
        assert!(dir.path().join("cache/s/k").exists());
    }
}
