//! The dataset archive (docs/design.md §2): a run's
//! simulate and stride outputs (the trajectory log, its statistics and the
//! pairs table; optionally the quantize outputs too) kept for reuse, and
//! recordings of a robot imported from elsewhere (tables of samples, with
//! their source, citation and licence).
//!
//! Files are stored once each, content-addressed by SHA-256 under
//! `<archive>/objects/`; `<archive>/catalog.toml` lists every dataset
//! version with its files, sizes, hashes and provenance. Each catalog entry
//! carries the SHA-256 of its own content (every field but that one), so an
//! edited entry is caught like a corrupted file. Catalog updates happen under
//! an exclusive lock on `<archive>/.lock`; every file is written under a
//! temporary name, synced and renamed.

use std::fs::{self, File};
use std::path::{Path, PathBuf};

use alnlab_common::atomic;
use alnlab_common::hash::copy_hashing;
use alnlab_common::{Error, Result};

use crate::manifest::is_identifier;

mod catalog;
pub use catalog::{
    BASE_ROLES, CATALOG_FILE, Catalog, DatasetProvenance, Entry, FileEntry, ImportedSource,
    LEVEL_ROLES, LICENCE_ROLE, TABLE_ROLE,
};

/// Where a dataset comes from.
pub enum Origin {
    /// A run's data.
    Run(DatasetProvenance),
    /// Recordings made elsewhere.
    Imported(ImportedSource),
}

/// The folder of content-addressed files in the archive folder.
const OBJECTS_DIR: &str = "objects";

/// One thing `verify` found wrong with a dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// The dataset, `name@version`.
    pub dataset: String,
    /// The file (or `catalog.toml` for the entry itself).
    pub file: String,
    /// The SHA-256 the catalog records.
    pub expected: String,
    /// What was found: a hash, or why there is none (`missing`).
    pub found: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "dataset {}: {}: expected sha256 {}, found {}",
            self.dataset, self.file, self.expected, self.found
        )
    }
}

/// A file to archive: role, file name, where it is now, and the SHA-256
/// its record says it has (checked as it is copied: damaged bytes are
/// never archived).
pub struct Source {
    pub role: String,
    pub name: String,
    pub path: PathBuf,
    pub sha256: Option<String>,
}

/// The archive folder.
pub struct Archive {
    dir: PathBuf,
}

/// Holds the archive's lock while the catalog is read, changed and written.
struct CatalogLock {
    _file: File,
}

impl Archive {
    /// The archive in `dir` (which need not exist yet).
    pub fn new(dir: &Path) -> Archive {
        Archive {
            dir: dir.to_path_buf(),
        }
    }

    /// The archive folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn catalog_path(&self) -> PathBuf {
        self.dir.join(CATALOG_FILE)
    }

    /// The stored file with content `sha256`.
    pub fn object(&self, sha256: &str) -> PathBuf {
        self.dir.join(OBJECTS_DIR).join(sha256)
    }

    fn lock(&self) -> Result<CatalogLock> {
        fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        let path = self.dir.join(".lock");
        let file = File::options()
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        file.lock().map_err(|e| Error::io(&path, e))?;
        Ok(CatalogLock { _file: file })
    }

    /// The catalog (empty if the archive has none yet).
    pub fn catalog(&self) -> Result<Catalog> {
        let path = self.catalog_path();
        let text = match fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Catalog::default()),
            Err(e) => return Err(Error::io(&path, e)),
        };
        toml::from_str(&text)
            .map_err(|e| Error::bad_file(&path, format!("not a dataset catalog: {e}")))
    }

    fn write_catalog(&self, catalog: &Catalog) -> Result<()> {
        let body = toml::to_string(catalog).expect("catalogs serialize");
        let text = format!(
            "# The dataset archive's catalog, written by `alnlab dataset`: one [[dataset]] per\n\
             # archived version. Do not edit: each entry's sha256 covers its other fields.\n\n{body}"
        );
        atomic::write_bytes(&self.catalog_path(), text.as_bytes())
    }

    /// Archives `sources` as a version of `name`. Content already stored is
    /// not stored again, and if the latest version of `name` holds exactly
    /// these files, that entry is returned (with `false`) and nothing changes.
    pub fn archive(&self, name: &str, sources: &[Source], origin: Origin) -> Result<(Entry, bool)> {
        check_name(name)?;
        let _lock = self.lock()?;
        let mut files = Vec::new();
        for source in sources {
            let (sha256, bytes) = self.store(&source.path, source.sha256.as_deref())?;
            files.push(FileEntry {
                role: source.role.clone(),
                name: source.name.clone(),
                sha256,
                bytes,
            });
        }
        let mut catalog = self.catalog()?;
        let latest = catalog
            .datasets
            .iter()
            .filter(|e| e.name == name)
            .max_by_key(|e| e.version);
        let (provenance, source) = match origin {
            Origin::Run(p) => (Some(p), None),
            Origin::Imported(s) => (None, Some(s)),
        };
        // The same files are the same dataset, whichever run made them; but
        // imported files with a corrected source (a citation, a licence)
        // make a new version.
        if let Some(latest) = latest
            && latest.files == files
            && latest.source == source
        {
            return Ok((latest.clone(), false));
        }
        let mut entry = Entry {
            name: name.to_string(),
            version: latest.map_or(1, |e| e.version + 1),
            sha256: String::new(),
            created: humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string(),
            bytes: files.iter().map(|f| f.bytes).sum(),
            provenance,
            source,
            files,
        };
        entry.sha256 = entry.content_sha256();
        catalog.datasets.push(entry.clone());
        self.write_catalog(&catalog)?;
        Ok((entry, true))
    }

    /// Copies `path` into the objects folder under its SHA-256 (unless it is
    /// there already); returns the hash and size. A file whose hash is not
    /// `expected` is refused and nothing is stored.
    fn store(&self, path: &Path, expected: Option<&str>) -> Result<(String, u64)> {
        let objects = self.dir.join(OBJECTS_DIR);
        fs::create_dir_all(&objects).map_err(|e| Error::io(&objects, e))?;
        let staging = objects.join(format!(".incoming.tmp-{}", std::process::id()));
        let (sha256, bytes) = atomic::write_file(&staging, |out| {
            let (sha256, bytes) = copy_hashing(path, out)?;
            match expected {
                Some(expected) if expected != sha256 => Err(Error::Corrupt(format!(
                    "{}: damaged: its sha256 is {sha256}, its run record says {expected}; \
                     not archived (run the experiment again to remake it)",
                    path.display()
                ))),
                _ => Ok((sha256, bytes)),
            }
        })?;
        let target = self.object(&sha256);
        if target.exists() {
            fs::remove_file(&staging).map_err(|e| Error::io(&staging, e))?;
        } else {
            fs::rename(&staging, &target).map_err(|e| Error::io(&target, e))?;
        }
        Ok((sha256, bytes))
    }

    /// The entry `reference` names: `NAME@VERSION`, `NAME` (its latest
    /// version) or a prefix of at least 8 hex digits of an entry's sha256.
    pub fn find(&self, reference: &str) -> Result<Entry> {
        let catalog = self.catalog()?;
        let listing = || {
            let labels: Vec<String> = catalog.datasets.iter().map(Entry::label).collect();
            if labels.is_empty() {
                format!("the archive {} is empty", self.dir.display())
            } else {
                format!("the archive has: {}", labels.join(", "))
            }
        };
        let (name, version) = match reference.split_once('@') {
            Some((name, version)) => {
                let version: u32 = version.parse().map_err(|_| {
                    Error::Invalid(format!(
                        "dataset `{reference}`: expected NAME@VERSION with a whole version number"
                    ))
                })?;
                (name, Some(version))
            }
            None => (reference, None),
        };
        let named: Vec<&Entry> = catalog.datasets.iter().filter(|e| e.name == name).collect();
        if version.is_none() && named.is_empty() && is_hash_prefix(reference) {
            let matches: Vec<&Entry> = catalog
                .datasets
                .iter()
                .filter(|e| e.sha256.starts_with(&reference.to_ascii_lowercase()))
                .collect();
            return match matches.as_slice() {
                [one] => Ok((*one).clone()),
                [] => Err(Error::Invalid(format!(
                    "no dataset's sha256 starts with `{reference}`; {}",
                    listing()
                ))),
                many => Err(Error::Invalid(format!(
                    "`{reference}` is the start of several datasets' sha256 ({}); give more digits",
                    many.iter()
                        .map(|e| e.label())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))),
            };
        }
        check_name(name)?;
        let found = match version {
            Some(v) => named.iter().find(|e| e.version == v),
            None => named.iter().max_by_key(|e| e.version),
        };
        found
            .map(|e| (*e).clone())
            .ok_or_else(|| Error::Invalid(format!("no dataset `{reference}`; {}", listing())))
    }

    /// The entry a manifest's `[data] dataset` names: as [`Archive::find`],
    /// but a bare name is refused, so that a manifest always means the same
    /// data.
    pub fn find_pinned(&self, reference: &str) -> Result<Entry> {
        let entry = self.find(reference)?;
        if reference.contains('@') || entry.name != reference {
            return Ok(entry);
        }
        Err(Error::Invalid(format!(
            "dataset `{reference}`: name a version, e.g. `{}` (the latest)",
            entry.label()
        )))
    }

    /// Everything wrong with `entry`: an edited entry, missing files, files
    /// whose content is not what the catalog records. Empty when it is whole.
    pub fn verify(&self, entry: &Entry) -> Result<Vec<Problem>> {
        let mut problems = Vec::new();
        let found = entry.content_sha256();
        if found != entry.sha256 {
            problems.push(Problem {
                dataset: entry.label(),
                file: CATALOG_FILE.into(),
                expected: entry.sha256.clone(),
                found: format!("{found} (the entry was edited)"),
            });
        }
        for file in &entry.files {
            let path = self.object(&file.sha256);
            let found = match File::open(&path) {
                Ok(_) => copy_hashing(&path, &mut std::io::sink()).map(|(sha, _)| sha)?,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => "nothing (missing)".into(),
                Err(e) => return Err(Error::io(&path, e)),
            };
            if found != file.sha256 {
                problems.push(Problem {
                    dataset: entry.label(),
                    file: format!("{} ({})", file.name, path.display()),
                    expected: file.sha256.clone(),
                    found,
                });
            }
        }
        Ok(problems)
    }

    /// Fails, naming every problem, unless `entry` verifies.
    pub fn require_whole(&self, entry: &Entry) -> Result<()> {
        let problems = self.verify(entry)?;
        if problems.is_empty() {
            return Ok(());
        }
        let list: Vec<String> = problems.iter().map(Problem::to_string).collect();
        Err(Error::Corrupt(format!(
            "dataset {} is damaged; refusing to use it:\n  {}",
            entry.label(),
            list.join("\n  ")
        )))
    }

    /// Copies `entry`'s files into `to` under their names, after verifying
    /// the whole dataset (so a damaged one writes nothing). A file of that
    /// name already in `to` is never overwritten (unless it holds exactly
    /// the archived bytes), and the files appear together or not at all:
    /// they are copied into a hidden folder in `to` first, then moved.
    pub fn restore(&self, entry: &Entry, to: &Path) -> Result<()> {
        self.require_whole(entry)?;
        let mut wanted = Vec::new();
        for file in &entry.files {
            let target = to.join(&file.name);
            match fs::symlink_metadata(&target) {
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => wanted.push(file),
                Err(e) => return Err(Error::io(&target, e)),
                Ok(meta)
                    if meta.is_file()
                        && copy_hashing(&target, &mut std::io::sink())?.0 == file.sha256 => {}
                Ok(_) => {
                    return Err(Error::Invalid(format!(
                        "{}: exists and is not {}'s `{}`; restoring would overwrite it \
                         (move it away or restore into another folder)",
                        target.display(),
                        entry.label(),
                        file.name
                    )));
                }
            }
        }
        let staging = to.join(format!(".restore.tmp-{}", std::process::id()));
        let mut partial = entry.clone();
        partial.files = wanted.into_iter().cloned().collect();
        let copied = self.copy_out(&partial, &staging).and_then(|()| {
            for file in &partial.files {
                let target = to.join(&file.name);
                fs::rename(staging.join(&file.name), &target).map_err(|e| Error::io(&target, e))?;
            }
            Ok(())
        });
        let _ = fs::remove_dir_all(&staging);
        copied
    }

    /// Copies `entry`'s files into `to` under their names, each hashed as it
    /// is copied and written atomically: for a caller that has verified the
    /// dataset already (a run, before it starts) and removes `to` on failure.
    pub fn copy_out(&self, entry: &Entry, to: &Path) -> Result<()> {
        atomic::create_dir(to)?;
        for file in &entry.files {
            check_file_name(&entry.label(), &file.name)?;
            let source = self.object(&file.sha256);
            let target = to.join(&file.name);
            atomic::write_file(&target, |out| {
                let (sha256, _) = copy_hashing(&source, out)?;
                if sha256 == file.sha256 {
                    Ok(())
                } else {
                    Err(Error::Corrupt(format!(
                        "dataset {}: {} changed while it was restored (expected sha256 {}, found {sha256})",
                        entry.label(),
                        file.name,
                        file.sha256
                    )))
                }
            })?;
        }
        Ok(())
    }

    /// Removes the entry `reference` names, then every stored file no other
    /// entry uses. Refuses while a manifest in `experiments` refers to it,
    /// unless `force`.
    pub fn remove(&self, reference: &str, force: bool, experiments: &Path) -> Result<Entry> {
        if !reference.contains('@') {
            return Err(Error::Invalid(format!(
                "dataset `{reference}`: name the version to remove, as NAME@VERSION"
            )));
        }
        let _lock = self.lock()?;
        let entry = self.find(reference)?;
        if !force {
            let users = self.manifests_using(&entry, experiments)?;
            if !users.is_empty() {
                return Err(Error::Invalid(format!(
                    "dataset {} is used by {}; change those manifests, or remove it anyway with --force",
                    entry.label(),
                    users.join(", ")
                )));
            }
        }
        let mut catalog = self.catalog()?;
        catalog
            .datasets
            .retain(|e| !(e.name == entry.name && e.version == entry.version));
        self.write_catalog(&catalog)?;
        for file in &entry.files {
            let used = catalog
                .datasets
                .iter()
                .any(|e| e.files.iter().any(|f| f.sha256 == file.sha256));
            let path = self.object(&file.sha256);
            if !used && path.exists() {
                fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
            }
        }
        Ok(entry)
    }

    /// The manifests in `experiments` whose `[data] dataset` names `entry`.
    fn manifests_using(&self, entry: &Entry, experiments: &Path) -> Result<Vec<String>> {
        let Ok(dir) = fs::read_dir(experiments) else {
            return Ok(Vec::new());
        };
        let mut users = Vec::new();
        for path in dir.filter_map(|e| e.ok().map(|e| e.path())) {
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let Ok(text) = fs::read_to_string(&path) else {
                continue;
            };
            let Ok(document) = text.parse::<toml::Table>() else {
                continue;
            };
            let reference = document
                .get("data")
                .and_then(|d| d.get("dataset"))
                .and_then(toml::Value::as_str);
            if let Some(reference) = reference
                && self
                    .find(reference)
                    .is_ok_and(|e| e.name == entry.name && e.version == entry.version)
            {
                users.push(path.display().to_string());
            }
        }
        users.sort();
        Ok(users)
    }
}

/// A catalog's file name must be a plain name: restoring it must not write
/// outside the folder it restores into.
fn check_file_name(dataset: &str, name: &str) -> Result<()> {
    let plain =
        !name.is_empty() && name != "." && name != ".." && !name.contains(['/', '\\', '\0']);
    if plain {
        Ok(())
    } else {
        Err(Error::Corrupt(format!(
            "dataset {dataset}: the catalog names a file `{name}`, which is not a plain file name"
        )))
    }
}

/// Whether `s` could be a sha256 prefix: 8 to 64 hex digits.
fn is_hash_prefix(s: &str) -> bool {
    (8..=64).contains(&s.len()) && s.chars().all(|c| c.is_ascii_hexdigit())
}

/// Dataset names are plain identifiers: no path separators, no `..`.
pub fn check_name(name: &str) -> Result<()> {
    if is_identifier(name) {
        Ok(())
    } else {
        Err(Error::Invalid(format!(
            "dataset name {name:?}: expected letters, digits, `-` or `_` (no paths)"
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn provenance() -> Origin {
        Origin::Run(DatasetProvenance {
            experiment: "e".into(),
            variant: "base".into(),
            manifest: "m.toml".into(),
            manifest_sha256: "00".repeat(32),
            replicate: Some(1),
            seed: 7,
            alnlab_version: "0.1.0".into(),
            git_commit: String::new(),
        })
    }

    /// Three data files with the given contents, as sources.
    fn sources(dir: &Path, contents: [&str; 3]) -> Vec<Source> {
        BASE_ROLES
            .iter()
            .zip(contents)
            .map(|(role, content)| {
                let path = dir.join(format!("{role}.bin"));
                fs::write(&path, content).unwrap();
                Source {
                    role: role.to_string(),
                    name: format!("{role}.bin"),
                    path,
                    sha256: None,
                }
            })
            .collect()
    }

    fn objects(archive: &Archive) -> usize {
        fs::read_dir(archive.dir().join(OBJECTS_DIR))
            .unwrap()
            .count()
    }

    #[test]
    fn the_same_content_is_stored_once_and_new_content_makes_a_new_version() {
        let dir = tempfile::tempdir().unwrap();
        let archive = Archive::new(&dir.path().join("datasets"));
        let files = sources(dir.path(), ["log", "stats", "log"]);
        let (first, new) = archive.archive("worm", &files, provenance()).unwrap();
        assert!(new && first.version == 1);
        assert_eq!(objects(&archive), 2, "two distinct contents");
        let (again, new) = archive.archive("worm", &files, provenance()).unwrap();
        assert!(!new);
        assert_eq!(again, first);
        assert_eq!(archive.catalog().unwrap().datasets.len(), 1);

        let changed = sources(dir.path(), ["log", "stats", "pairs"]);
        let (second, new) = archive.archive("worm", &changed, provenance()).unwrap();
        assert!(new && second.version == 2);
        assert_eq!(objects(&archive), 3);
        assert_eq!(archive.find("worm").unwrap(), second);
        assert_eq!(archive.find("worm@1").unwrap(), first);
        assert_eq!(archive.find(&first.sha256[..10]).unwrap(), first);
        assert!(archive.verify(&first).unwrap().is_empty());
        assert!(archive.verify(&second).unwrap().is_empty());
        // The catalog reads back as written.
        let text = fs::read_to_string(archive.dir().join(CATALOG_FILE)).unwrap();
        assert!(text.contains("name = \"worm\"") && text.contains("version = 2"));
    }

    #[test]
    fn concurrent_archiving_of_the_same_content_makes_one_entry() {
        let dir = tempfile::tempdir().unwrap();
        let files = sources(dir.path(), ["a", "b", "c"]);
        let root = dir.path().join("datasets");
        let results: Vec<(Entry, bool)> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|_| s.spawn(|| Archive::new(&root).archive("x", &files, provenance())))
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap().unwrap())
                .collect()
        });
        assert_eq!(results.iter().filter(|(_, new)| *new).count(), 1);
        assert!(results.iter().all(|(e, _)| e.version == 1));
        let archive = Archive::new(&root);
        assert_eq!(archive.catalog().unwrap().datasets.len(), 1);
        assert_eq!(objects(&archive), 3, "no staging file left behind");
    }

    #[test]
    fn damage_of_every_kind_is_found_and_named() {
        let dir = tempfile::tempdir().unwrap();
        let archive = Archive::new(&dir.path().join("datasets"));
        let (entry, _) = archive
            .archive(
                "d",
                &sources(dir.path(), ["trajectory bytes", "stats", "pairs"]),
                provenance(),
            )
            .unwrap();
        let (other, _) = archive
            .archive("other", &sources(dir.path(), ["1", "2", "3"]), provenance())
            .unwrap();
        let object = |role: &str| archive.object(&entry.file(role).unwrap().sha256);

        // A flipped byte.
        let mut bytes = fs::read(object("trajectory")).unwrap();
        bytes[3] ^= 0x01;
        fs::write(object("trajectory"), &bytes).unwrap();
        // A truncated file.
        fs::write(object("stats"), "sta").unwrap();
        // A missing file.
        fs::remove_file(object("pairs")).unwrap();
        let problems = archive.verify(&entry).unwrap();
        assert_eq!(problems.len(), 3, "{problems:?}");
        for (problem, role) in problems.iter().zip(BASE_ROLES) {
            let file = entry.file(role).unwrap();
            assert_eq!(problem.dataset, "d@1");
            assert!(problem.file.starts_with(&file.name), "{problem}");
            assert_eq!(problem.expected, file.sha256);
            assert_ne!(problem.found, file.sha256);
        }
        assert!(problems[2].found.contains("missing"));
        // The other dataset is untouched and whole.
        assert!(archive.verify(&other).unwrap().is_empty());

        // Restoring refuses, and writes nothing.
        let to = dir.path().join("restored");
        let err = archive.restore(&entry, &to).unwrap_err();
        assert_eq!(err.exit_code(), 1);
        assert!(err.to_string().contains("dataset d@1 is damaged"), "{err}");
        assert!(!to.exists());
    }

    #[test]
    fn an_edited_catalog_entry_is_found() {
        let dir = tempfile::tempdir().unwrap();
        let archive = Archive::new(&dir.path().join("datasets"));
        archive
            .archive("d", &sources(dir.path(), ["a", "b", "c"]), provenance())
            .unwrap();
        let path = archive.dir().join(CATALOG_FILE);
        let text = fs::read_to_string(&path).unwrap();
        fs::write(&path, text.replace("seed = 7", "seed = 8")).unwrap();
        let entry = archive.find("d@1").unwrap();
        let problems = archive.verify(&entry).unwrap();
        assert_eq!(problems.len(), 1);
        assert_eq!(problems[0].file, CATALOG_FILE);
        assert_eq!(problems[0].expected, entry.sha256);
        assert!(problems[0].found.contains("edited"));
    }

    #[test]
    fn restore_copies_every_file_as_archived() {
        let dir = tempfile::tempdir().unwrap();
        let archive = Archive::new(&dir.path().join("datasets"));
        let files = sources(dir.path(), ["log", "stats", "pairs"]);
        let (entry, _) = archive.archive("d", &files, provenance()).unwrap();
        let to = dir.path().join("out");
        archive.restore(&entry, &to).unwrap();
        for source in &files {
            assert_eq!(
                fs::read(to.join(&source.name)).unwrap(),
                fs::read(&source.path).unwrap()
            );
        }
    }

    #[test]
    fn bad_references_are_user_errors() {
        let dir = tempfile::tempdir().unwrap();
        let archive = Archive::new(&dir.path().join("datasets"));
        archive
            .archive("d", &sources(dir.path(), ["a", "b", "c"]), provenance())
            .unwrap();
        for (reference, says) in [
            ("nope@1", "no dataset `nope@1`; the archive has: d@1"),
            ("d@2", "no dataset `d@2`"),
            ("d@x", "whole version number"),
            ("../d", "no paths"),
            ("a/b@1", "no paths"),
            ("abcdef0123", "no dataset's sha256 starts with"),
        ] {
            let err = archive.find(reference).unwrap_err();
            assert_eq!(err.exit_code(), 2, "{reference}");
            assert!(err.to_string().contains(says), "{reference}: {err}");
        }
        let err = archive
            .archive(
                "../evil",
                &sources(dir.path(), ["a", "b", "c"]),
                provenance(),
            )
            .unwrap_err();
        assert!(err.to_string().contains("no paths"), "{err}");
        let err = archive.find_pinned("d").unwrap_err();
        assert!(
            err.to_string().contains("name a version, e.g. `d@1`"),
            "{err}"
        );
        assert!(archive.find_pinned("d@1").is_ok());
    }

    #[test]
    fn remove_refuses_while_a_manifest_uses_it_and_keeps_shared_files() {
        let dir = tempfile::tempdir().unwrap();
        let archive = Archive::new(&dir.path().join("datasets"));
        let (first, _) = archive
            .archive("d", &sources(dir.path(), ["a", "b", "c"]), provenance())
            .unwrap();
        archive
            .archive("d", &sources(dir.path(), ["a", "b", "z"]), provenance())
            .unwrap();
        let experiments = dir.path().join("experiments");
        fs::create_dir_all(&experiments).unwrap();
        fs::write(
            experiments.join("uses.toml"),
            format!("[data]\ndataset = \"{}\"\n", &first.sha256[..12]),
        )
        .unwrap();
        let err = archive.remove("d@1", false, &experiments).unwrap_err();
        assert_eq!(err.exit_code(), 2);
        assert!(err.to_string().contains("uses.toml"), "{err}");
        assert!(
            archive.remove("d", false, &experiments).is_err(),
            "a version is required"
        );

        archive.remove("d@1", true, &experiments).unwrap();
        assert_eq!(archive.catalog().unwrap().datasets.len(), 1);
        assert_eq!(objects(&archive), 3, "a and b are still used by d@2");
        let second = archive.find("d@2").unwrap();
        assert!(archive.verify(&second).unwrap().is_empty());
    }
}
