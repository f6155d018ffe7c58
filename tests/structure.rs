//! The workspace's layering, read from `cargo metadata`: a stage crate
//! (`stages/<name>/`) never depends on another stage crate — what several
//! stages need is a library crate under `crates/`; a view (`views/<name>/`,
//! the report) reads every stage's tables and only the pipeline uses it; the
//! Python package (`python/`) uses only libraries. A dev-dependency may
//! build a stage's test input with an upstream stage; nothing of it reaches
//! the stage's library.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// Every package of the workspace: name → (folder relative to the root,
/// its normal and build dependencies on workspace packages).
fn workspace() -> BTreeMap<String, (String, Vec<String>)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(root)
        .output()
        .expect("cargo metadata runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let metadata: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let names: Vec<&str> = metadata["packages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    metadata["packages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let manifest = Path::new(p["manifest_path"].as_str().unwrap());
            let folder = manifest
                .parent()
                .unwrap()
                .strip_prefix(root)
                .unwrap()
                .display()
                .to_string();
            let deps = p["dependencies"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|d| d["kind"].as_str() != Some("dev"))
                .map(|d| d["name"].as_str().unwrap().to_string())
                .filter(|d| names.contains(&d.as_str()))
                .collect();
            (p["name"].as_str().unwrap().to_string(), (folder, deps))
        })
        .collect()
}

/// The stage-to-stage dependencies of `packages`, as "a → b".
fn stage_to_stage(packages: &BTreeMap<String, (String, Vec<String>)>) -> Vec<String> {
    let is_stage = |name: &str| {
        packages
            .get(name)
            .is_some_and(|(folder, _)| folder.starts_with("stages/"))
    };
    packages
        .iter()
        .filter(|(name, _)| is_stage(name))
        .flat_map(|(name, (_, deps))| {
            deps.iter()
                .filter(|d| is_stage(d))
                .map(move |d| format!("{name} → {d}"))
        })
        .collect()
}

/// The dependencies on a view by anything but the pipeline (the root
/// package), as "a → b".
fn view_users(packages: &BTreeMap<String, (String, Vec<String>)>) -> Vec<String> {
    let is_view = |name: &str| {
        packages
            .get(name)
            .is_some_and(|(folder, _)| folder.starts_with("views/"))
    };
    packages
        .iter()
        .filter(|(_, (folder, _))| !folder.is_empty())
        .flat_map(|(name, (_, deps))| {
            deps.iter()
                .filter(|d| is_view(d))
                .map(move |d| format!("{name} → {d}"))
        })
        .collect()
}

#[test]
fn only_the_pipeline_uses_the_report() {
    let packages = workspace();
    let (folder, _) = packages.get("alnlab-report").expect("the report crate");
    assert_eq!(folder, "views/report");
    let users = view_users(&packages);
    assert!(
        users.is_empty(),
        "only the pipeline may use a view (a stage writes tables; the report reads them): \
         {users:?}"
    );
    let pipeline = packages.get("alnlab").expect("the pipeline package");
    assert!(pipeline.1.contains(&"alnlab-report".to_string()));
}

#[test]
fn the_check_sees_a_stage_using_the_report() {
    let mut packages = workspace();
    packages
        .get_mut("alnlab-summarize")
        .expect("the summarize stage")
        .1
        .push("alnlab-report".into());
    assert_eq!(view_users(&packages), ["alnlab-summarize → alnlab-report"]);
}

#[test]
fn no_stage_crate_depends_on_another() {
    let packages = workspace();
    let stages: Vec<&String> = packages
        .iter()
        .filter(|(_, (folder, _))| folder.starts_with("stages/"))
        .map(|(name, _)| name)
        .collect();
    assert!(stages.len() >= 6, "found the stage crates: {stages:?}");
    let links = stage_to_stage(&packages);
    assert!(
        links.is_empty(),
        "stage crates depend on stage crates (move the shared code into a library under \
         crates/): {links:?}"
    );
}

#[test]
fn the_check_sees_a_stage_to_stage_dependency() {
    let mut packages = workspace();
    packages
        .get_mut("alnlab-summarize")
        .expect("the summarize stage")
        .1
        .push("alnlab-train".into());
    assert_eq!(
        stage_to_stage(&packages),
        ["alnlab-summarize → alnlab-train"]
    );
}

#[test]
fn libraries_depend_only_on_libraries() {
    let packages = workspace();
    for (name, (folder, deps)) in &packages {
        if !folder.starts_with("crates/") {
            continue;
        }
        for dep in deps {
            let (dep_folder, _) = &packages[dep];
            assert!(
                dep_folder.starts_with("crates/"),
                "library {name} depends on {dep} in {dep_folder}"
            );
        }
    }
}

/// The Python package's native core (`python/`) predicts with the
/// libraries only: no stage, view or pipeline is compiled into it.
#[test]
fn the_python_package_uses_only_libraries() {
    let packages = workspace();
    let (folder, deps) = &packages["alnlab-python"];
    assert_eq!(folder, "python");
    assert!(!deps.is_empty());
    for dep in deps {
        let (dep_folder, _) = &packages[dep];
        assert!(
            dep_folder.starts_with("crates/"),
            "the Python package depends on {dep} in {dep_folder}"
        );
    }
}
