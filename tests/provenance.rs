//! A published report names the commit it came from, and that commit must
//! reproduce it: publishing into a folder git would commit is refused while
//! the checkout differs from its commit; into an ignored folder it is done,
//! and the report lists what differed.

use std::path::Path;
use std::process::Command;

use crate::common::{TINY, alnlab, stderr, write_manifest};

/// `git ARGS` in `dir`, which must succeed (with an identity of its own: a
/// CI machine may have none).
fn git(dir: &Path, args: &[&str]) -> String {
    let out = Command::new("git")
        .current_dir(dir)
        .args([
            "-c",
            "user.name=alnlab tests",
            "-c",
            "user.email=tests@alnlab.invalid",
        ])
        .args(args)
        .output()
        .expect("git runs");
    assert!(out.status.success(), "git {args:?}: {}", stderr(&out));
    String::from_utf8(out.stdout).unwrap().trim().to_string()
}

#[test]
fn an_edited_manifest_is_not_published_into_a_committed_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    git(d, &["init", "-q"]);
    std::fs::write(d.join(".gitignore"), "runs/\npublished/\n").unwrap();
    write_manifest(d, "m.toml", TINY);
    git(d, &["add", "."]);
    git(d, &["commit", "-q", "-m", "the experiment"]);
    let commit = git(d, &["rev-parse", "HEAD"]);

    // Clean: published, naming the commit alone.
    let run = ["-q", "run", "m.toml", "--reports", "reports"];
    let out = alnlab(d, &run);
    assert!(out.status.success(), "{}", stderr(&out));
    let report = std::fs::read_to_string(d.join("reports/tiny/report.md")).unwrap();
    assert!(
        report.contains(&format!("| git commit | `{commit}` |")),
        "{report}"
    );
    // The report just written is not a change that blocks the next one.
    let out = alnlab(d, &run);
    assert!(out.status.success(), "{}", stderr(&out));

    // The manifest edited: refused, naming it, and nothing published.
    std::fs::remove_dir_all(d.join("reports")).unwrap();
    write_manifest(d, "m.toml", &TINY.replace("seed = 7", "seed = 8"));
    let out = alnlab(d, &run);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let said = stderr(&out);
    assert!(
        said.contains("refusing to publish a report into a folder git would commit")
            && said.contains(&format!(
                "the checkout differs from its commit ({commit}) in m.toml"
            )),
        "{said}"
    );
    assert!(!d.join("reports").exists());

    // Into an ignored folder: published, the difference named.
    let out = alnlab(d, &["-q", "run", "m.toml", "--reports", "published"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report = std::fs::read_to_string(d.join("published/tiny/report.md")).unwrap();
    assert!(
        report.contains(&format!(
            "| git commit | `{commit}`, with uncommitted changes to 1 path: `m.toml` |"
        )),
        "{report}"
    );

    // A manifest from outside the checkout: no commit could hold it.
    let elsewhere = tempfile::tempdir().unwrap();
    let outside = write_manifest(elsewhere.path(), "m.toml", TINY);
    let out = alnlab(
        d,
        &[
            "-q",
            "run",
            outside.to_str().unwrap(),
            "--reports",
            "reports",
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("is not in its checkout"),
        "{}",
        stderr(&out)
    );
    // … nor may its run, made outside any checkout, be published there.
    let runs = elsewhere.path().join("runs");
    let out = alnlab(
        elsewhere.path(),
        &["-q", "run", "m.toml", "--out", runs.to_str().unwrap()],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let run = runs.join("tiny");
    let out = alnlab(
        d,
        &["report", run.to_str().unwrap(), "--reports", "reports"],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("the run was not made in a git checkout"),
        "{}",
        stderr(&out)
    );

    // Re-rendering that run into the committed folder is refused even once
    // the checkout is clean again: the run itself came from the edit.
    git(d, &["checkout", "-q", "m.toml"]);
    let out = alnlab(d, &["report", "runs/tiny", "--reports", "reports"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("the run was made from a checkout that differed from its commit"),
        "{}",
        stderr(&out)
    );
}

/// Every committed report names a commit at which its manifest is the
/// one it printed: `git show <commit>:<manifest>` hashes to the report's
/// manifest sha256 (a report rendered from a tree that differed from its
/// commit would not).
#[test]
fn every_committed_report_names_a_commit_that_makes_its_manifest() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for dir in crate::common::committed_reports() {
        let name = dir.file_name().unwrap().to_string_lossy().to_string();
        let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
        let cell = |key: &str| -> String {
            report
                .lines()
                .find_map(|l| l.strip_prefix(&format!("| {key} | `")))
                .and_then(|rest| rest.split('`').next())
                .unwrap_or_else(|| panic!("{name}: no `{key}` in the Reproducibility table"))
                .to_string()
        };
        let (manifest, sha256, commit) = (
            cell("manifest"),
            cell("manifest sha256"),
            cell("git commit"),
        );
        let shown = std::process::Command::new("git")
            .current_dir(root)
            .args(["show", &format!("{commit}:{manifest}")])
            .output()
            .expect("git runs");
        assert!(
            shown.status.success(),
            "{name}: git show {commit}:{manifest}: {}",
            String::from_utf8_lossy(&shown.stderr)
        );
        assert_eq!(
            alnlab_common::hash::sha256_hex(&shown.stdout),
            sha256,
            "{name}: {manifest} at {commit} is not the manifest the report printed"
        );
    }
}
