//! The git checkout a run comes from: the commit its record and report
//! name, the paths that differ from that commit, and whether a report may
//! be published into a folder — one git would commit must come from a clean
//! checkout, so that the commit a committed report names reproduces it.

use std::path::{Path, PathBuf};

use alnlab_common::{Error, Result};

/// The paths a refusal or a report lists, at most.
const SHOWN: usize = 10;

/// The commit checked out where `path` lies (a file or folder), if in a
/// git checkout.
pub fn commit(path: &Path) -> Option<String> {
    git(&existing_folder(path), &["rev-parse", "HEAD"])
}

/// The paths of the checkout holding `path` that differ from its commit —
/// modified, staged, deleted or new (untracked and not ignored) — relative
/// to the checkout's root and sorted; those under `except` (the reports
/// folder being written) left out. Empty outside a checkout.
pub fn changes(path: &Path, except: Option<&Path>) -> Vec<String> {
    let dir = existing_folder(path);
    // Raw, not trimmed: an entry's status may start with a space.
    let Some(listed) = git_raw(
        &dir,
        &["status", "--porcelain=v1", "-z", "--untracked-files=all"],
    ) else {
        return Vec::new();
    };
    let except = except.and_then(|e| relative_to_root(&dir, e));
    let mut paths = Vec::new();
    let mut entries = listed.split('\0');
    while let Some(entry) = entries.next() {
        let Some(path) = entry.get(3..).filter(|p| !p.is_empty()) else {
            continue;
        };
        // A rename or copy (in the index or the work tree) is followed by
        // the path it came from.
        if entry
            .get(..2)
            .is_some_and(|status| status.contains(['R', 'C']))
        {
            entries.next();
        }
        let excluded = except
            .as_deref()
            .is_some_and(|e| e.is_empty() || path == e || path.starts_with(&format!("{e}/")));
        if !excluded {
            paths.push(path.to_string());
        }
    }
    paths.sort();
    paths.dedup();
    paths
}

/// Whether `folder` lies in a git checkout and is not ignored there: a
/// report published into it can be committed.
pub fn committable(folder: &Path) -> bool {
    let dir = existing_folder(folder);
    let Some(relative) = relative_to_root(&dir, folder) else {
        return false;
    };
    let root = match git(&dir, &["rev-parse", "--show-toplevel"]) {
        Some(root) => PathBuf::from(root),
        None => return false,
    };
    // `check-ignore` exits 0 for an ignored path, 1 for one git would track;
    // the trailing `/` lets a pattern for folders (`runs/`) match a folder
    // not made yet.
    std::process::Command::new("git")
        .arg("-C")
        .arg(root)
        .args(["check-ignore", "-q", "--"])
        .arg(if relative.is_empty() {
            ".".into()
        } else {
            format!("{relative}/")
        })
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.code() == Some(1))
}

/// Refuses to publish the report of a run of `manifest` into `folder` when
/// git would commit it there and the commit the report names could not
/// reproduce it: the manifest lies outside that checkout, or the checkout
/// differs from its commit (the reports folder aside).
pub fn check_run_publishable(folder: &Path, manifest: &Path) -> Result<()> {
    if !committable(folder) {
        return Ok(());
    }
    let root = |path: &Path| {
        let root = git(&existing_folder(path), &["rev-parse", "--show-toplevel"])?;
        std::fs::canonicalize(root).ok()
    };
    if root(manifest) != root(folder) {
        return Err(refusal(
            folder,
            &format!(
                "the manifest {} is not in its checkout, so the report could name no commit \
                 that holds it",
                manifest.display()
            ),
        ));
    }
    check_clean(folder, &[])
}

/// Refuses to publish a recorded run's report into `folder` when git would
/// commit it there and the commit the report names could not reproduce it:
/// the run was made outside a checkout (`commit` is `None`) or from one that
/// differed from its commit (`run_changes`), or the checkout differs now.
pub fn check_record_publishable(
    folder: &Path,
    commit: Option<&str>,
    run_changes: &[String],
) -> Result<()> {
    if !committable(folder) {
        return Ok(());
    }
    if commit.is_none() {
        return Err(refusal(
            folder,
            "the run was not made in a git checkout, so the report could name no commit",
        ));
    }
    check_clean(folder, run_changes)
}

/// The refusal when the checkout differs from its commit now (the reports
/// folder aside), or the run was made from one that did (`run_changes`).
fn check_clean(folder: &Path, run_changes: &[String]) -> Result<()> {
    let now = changes(folder, Some(folder));
    let (when, paths) = match (now.is_empty(), run_changes.is_empty()) {
        (true, true) => return Ok(()),
        (false, _) => ("the checkout differs from its commit", now),
        (true, false) => (
            "the run was made from a checkout that differed from its commit",
            run_changes.to_vec(),
        ),
    };
    let commit = commit(folder).unwrap_or_else(|| "(no commit yet)".into());
    Err(refusal(
        folder,
        &format!(
            "{when} ({commit}) in {}. A published report names its commit, which must \
             reproduce it: commit (or stash) these and run again",
            list(&paths)
        ),
    ))
}

/// Why a report is not published into `folder`, and where it could go.
fn refusal(folder: &Path, why: &str) -> Error {
    Error::Invalid(format!(
        "{}: refusing to publish a report into a folder git would commit: {why}; or publish into \
         a folder git ignores, where the report says what it came from",
        folder.display()
    ))
}

/// `paths` for people: the first few, then how many more.
pub fn list(paths: &[String]) -> String {
    let shown: Vec<&str> = paths.iter().take(SHOWN).map(String::as_str).collect();
    match paths.len().saturating_sub(SHOWN) {
        0 => shown.join(", "),
        more => format!("{} and {more} more", shown.join(", ")),
    }
}

/// `path` relative to the root of the git checkout holding it (so a record
/// reads the same on every checkout), or as given outside one.
pub fn repository_path(path: &Path) -> String {
    relative_to_root(&existing_folder(path), path).unwrap_or_else(|| path.display().to_string())
}

/// `path` relative to the root of the checkout `dir` is in (`""` for the
/// root itself); `None` outside a checkout or outside that root.
fn relative_to_root(dir: &Path, path: &Path) -> Option<String> {
    let root = std::fs::canonicalize(git(dir, &["rev-parse", "--show-toplevel"])?).ok()?;
    let absolute = std::fs::canonicalize(path)
        .or_else(|_| {
            // Not there yet (a reports folder about to be made): its
            // nearest existing ancestor, canonical, and the rest as given.
            let parent = existing_folder(path);
            let rest = std::path::absolute(path)?;
            let parent_absolute = std::path::absolute(&parent)?;
            let tail = rest
                .strip_prefix(&parent_absolute)
                .unwrap_or(&rest)
                .to_path_buf();
            std::fs::canonicalize(&parent).map(|p| p.join(tail))
        })
        .ok()?;
    let relative = absolute.strip_prefix(root).ok()?;
    Some(relative.to_string_lossy().into_owned())
}

/// `path` if it is a folder, else its nearest existing ancestor folder (the
/// working folder for a relative path with none).
fn existing_folder(path: &Path) -> PathBuf {
    let mut folder = path.to_path_buf();
    loop {
        if folder.is_dir() {
            return folder;
        }
        if !folder.pop() || folder.as_os_str().is_empty() {
            return PathBuf::from(".");
        }
    }
}

/// What `git -C dir args` prints, trimmed, if it succeeds and prints
/// something.
fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let text = git_raw(dir, args)?.trim().to_string();
    (!text.is_empty()).then_some(text)
}

/// What `git -C dir args` prints, as it is, if it succeeds.
fn git_raw(dir: &Path, args: &[&str]) -> Option<String> {
    let output = std::process::Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(args)
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    // Lossy: a path that is not UTF-8 is still a change.
    output
        .status
        .success()
        .then(|| String::from_utf8_lossy(&output.stdout).into_owned())
}
