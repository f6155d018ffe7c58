//! Write-then-rename: a file either exists complete under its final name or
//! not at all, even if the process is killed mid-write.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// The temporary name a file is written under before it is renamed to `path`.
/// Starts with a dot and carries the process id, so concurrent writers never
/// share one and a leftover is recognisable as unfinished.
pub fn temporary_name(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Removes from `dir` the temporary files ([`temporary_name`]) that writers
/// killed mid-write left behind: those of processes no longer running (as
/// `/proc` tells; where there is no `/proc`, those of any other process).
/// Returns how many it removed.
pub fn sweep_leftovers(dir: &Path) -> Result<usize> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(0);
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = name
            .strip_prefix('.')
            .and_then(|n| n.rsplit_once(".tmp-"))
            .and_then(|(_, pid)| pid.parse::<u32>().ok())
        else {
            continue;
        };
        let alive = pid == std::process::id() || Path::new("/proc").join(pid.to_string()).exists();
        if !alive && entry.file_type().is_ok_and(|t| t.is_file()) {
            fs::remove_file(entry.path()).map_err(|e| Error::io(&entry.path(), e))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Creates the folder `path` (and its parents) unless it exists. A path
/// that exists but is not a folder (or has a file among its parents) is an
/// error the user can fix, saying so.
pub fn create_dir(path: &Path) -> Result<()> {
    fs::create_dir_all(path).map_err(|e| {
        let blocked = path.ancestors().find(|p| p.is_file());
        match (e.kind(), blocked) {
            (_, Some(file)) => Error::Invalid(format!(
                "{}: {} is a file, expected a folder (or a path that does not exist yet)",
                path.display(),
                file.display()
            )),
            _ => Error::io(path, e),
        }
    })
}

/// Creates `path` atomically: `fill` writes the content into a buffered
/// temporary file, which is flushed, synced and renamed to `path`. On any
/// error the temporary file is removed and `path` is untouched.
pub fn write_file<T>(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> Result<T>,
) -> Result<T> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        create_dir(parent)?;
    }
    let tmp = temporary_name(path);
    let result = (|| {
        let file = File::create(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let mut out = BufWriter::new(file);
        let value = fill(&mut out)?;
        let file = out
            .into_inner()
            .map_err(|e| Error::io(&tmp, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&tmp, e))?;
        fs::rename(&tmp, path).map_err(|e| Error::io(path, e))?;
        Ok(value)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_file(path, |out| {
        out.write_all(bytes).map_err(|e| Error::io(path, e))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.bin");
        let err = write_file(&path, |out| {
            out.write_all(b"half").unwrap();
            Err::<(), _>(Error::Invalid("stop".into()))
        });
        assert!(err.is_err());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn a_file_where_a_folder_should_be_is_a_clear_user_error() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("taken");
        fs::write(&file, b"mine").unwrap();
        for path in [file.clone(), file.join("sub")] {
            let err = create_dir(&path).unwrap_err();
            assert_eq!(err.exit_code(), 2);
            assert!(
                err.to_string().contains("is a file, expected a folder"),
                "{err}"
            );
        }
        let err = write_bytes(&file.join("a.bin"), b"x").unwrap_err();
        assert_eq!(err.exit_code(), 2, "{err}");
        assert_eq!(fs::read(&file).unwrap(), b"mine");
    }

    #[test]
    fn leftovers_of_dead_writers_are_swept_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let keep = [
            "report.md",
            ".hidden",
            &format!(".a.svg.tmp-{}", std::process::id()),
        ];
        for name in keep.iter().chain(&[".speed.svg.tmp-4294967290"]) {
            fs::write(dir.path().join(name), b"x").unwrap();
        }
        assert_eq!(sweep_leftovers(dir.path()).unwrap(), 1);
        let mut left: Vec<String> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        let mut want: Vec<String> = keep.iter().map(|s| s.to_string()).collect();
        want.sort();
        assert_eq!(left, want);
    }

    #[test]
    fn successful_write_renames() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/a.bin");
        write_bytes(&path, b"whole").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"whole");
        assert_eq!(fs::read_dir(path.parent().unwrap()).unwrap().count(), 1);
    }
}
