//! The workspace's layering, read from `cargo metadata`: a stage crate
//! (`stages/<name>/`) never depends on another stage crate — what several
//! stages need is a library crate under `crates/`; a view (`views/<name>/`,
//! the report) reads every stage's tables and only the pipeline uses it; the
//! Python package (`python/`) uses only libraries. A dev-dependency may
//! build a stage's test input with an upstream stage; nothing of it reaches
//! the stage's library.
//!
//! Beside the layering: the light libraries link no file format (read from
//! `Cargo.lock`); two rules read from the sources — a model kind is matched,
//! never compared, and every test the fast tier leaves out says that the
//! full suite runs it; and every model a committed report's tables name is
//! a `ModelId`.

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

/// The libraries a contributor tests alone after a one-line change build
/// without the file formats: neither they nor anything they (or their
/// tests) build on links Arrow, Parquet or MCAP, so a cold `cargo test -p`
/// of one of them takes about a minute, not the twenty of Arrow. Read from
/// `Cargo.lock` (every platform's packages, by name: stricter than one
/// build needs, and readable offline).
#[test]
fn light_libraries_link_no_file_format() {
    let lock = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.lock"))
        .expect("Cargo.lock is committed");
    let lock: toml::Table = toml::from_str(&lock).unwrap();
    // Each package's dependencies by name (an entry is "name", "name
    // version" or "name version (source)").
    let mut deps: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for package in lock["package"].as_array().unwrap() {
        let name = package["name"].as_str().unwrap();
        let entry = deps.entry(name).or_default();
        if let Some(list) = package.get("dependencies") {
            for dep in list.as_array().unwrap() {
                entry.push(dep.as_str().unwrap().split(' ').next().unwrap());
            }
        }
    }
    let heavy = |name: &str| name == "parquet" || name == "mcap" || name.starts_with("arrow");
    for light in [
        "alnlab-core",
        "alnlab-codes",
        "alnlab-physics",
        "alnlab-records",
    ] {
        let mut todo = vec![vec![light]];
        let mut seen = std::collections::BTreeSet::new();
        while let Some(path) = todo.pop() {
            let last = *path.last().unwrap();
            assert!(
                !heavy(last),
                "{light} links a file format: {}",
                path.join(" → ")
            );
            if seen.insert(last) {
                for dep in deps.get(last).into_iter().flatten() {
                    let mut longer = path.clone();
                    longer.push(dep);
                    todo.push(longer);
                }
            }
        }
        assert!(seen.len() > 5, "{light} reaches {} packages", seen.len());
    }
}

/// The workspace's own Rust sources (not `target/`, not the fuzz crate's
/// build), as (path relative to the root, text).
fn rust_sources() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    let mut todo: Vec<std::path::PathBuf> = ["crates", "stages", "views", "pipeline", "python"]
        .into_iter()
        .chain(["xtask", "tests", "fuzz/fuzz_targets"])
        .map(|d| root.join(d))
        .collect();
    while let Some(dir) = todo.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                if path.file_name().is_some_and(|n| n != "target") {
                    todo.push(path);
                }
            } else if path.extension().is_some_and(|e| e == "rs") {
                let relative = path.strip_prefix(root).unwrap().display().to_string();
                found.push((relative, std::fs::read_to_string(&path).unwrap()));
            }
        }
    }
    assert!(found.len() > 100, "{} Rust files", found.len());
    found
}

/// Whether `line` compares a model kind with `==` or `!=`.
fn compares_a_model_kind(line: &str) -> bool {
    let kind = concat!("Model", "Kind::");
    line.match_indices(kind).any(|(at, _)| {
        let path = |c: char| c.is_alphanumeric() || c == '_' || c == ':';
        let before = line[..at].trim_end_matches(path).trim_end();
        let after = line[at + kind.len()..]
            .trim_start_matches(path)
            .trim_start();
        ["==", "!="]
            .iter()
            .any(|op| before.ends_with(op) || after.starts_with(op))
    })
}

/// A model kind is decided by an exhaustive `match`, so that a new kind
/// makes the compiler name every place that must decide something about
/// it; a comparison with `==` or `!=` would quietly treat it as "not that
/// kind". (Assertions in tests compare freely.)
#[test]
fn model_kinds_are_matched_not_compared() {
    let compared: Vec<String> = rust_sources()
        .iter()
        .flat_map(|(path, text)| {
            text.lines()
                .enumerate()
                .filter(|(_, line)| compares_a_model_kind(line))
                .map(move |(n, line)| format!("{path}:{}: {}", n + 1, line.trim()))
        })
        .collect();
    assert!(compared.is_empty(), "{}", compared.join("\n"));
}

#[test]
fn the_check_sees_a_model_kind_compared() {
    let kind = concat!("Model", "Kind");
    for line in [
        format!("if m.header.model == {kind}::Threshold {{"),
        format!("let p = kind != alnlab_aln::{kind}::PiecewiseLinear;"),
        format!("if alnlab_aln::model::{kind}::BitForest == k {{"),
    ] {
        assert!(compares_a_model_kind(&line), "{line}");
    }
    for line in [
        format!("{kind}::Threshold => return nothing(),"),
        format!("assert_eq!(model.header.model, {kind}::PiecewiseLinear);"),
        format!("if self.base == Base::Nominal && {kind}::name(k) != \"x\""),
    ] {
        assert!(!compares_a_model_kind(&line), "{line}");
    }
}

/// The fast tier (`cargo test --workspace`) leaves out only what the full
/// suite (`cargo xtask test`, `--include-ignored`) runs, each with its
/// reason: no test is switched off for good.
#[test]
fn every_ignored_test_says_it_belongs_to_the_full_suite() {
    let ignore = concat!("#[", "ignore");
    let mut silent = Vec::new();
    let mut full = 0;
    for (path, text) in rust_sources() {
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.starts_with(ignore) {
                if line.starts_with(concat!("#[", "ignore = \"full suite: ")) {
                    full += 1;
                } else {
                    silent.push(format!("{path}:{}: {line}", n + 1));
                }
            }
        }
    }
    assert!(silent.is_empty(), "{}", silent.join("\n"));
    assert!(full >= 5, "{full} full-suite tests");
}

/// Every model a committed report's tables name is a `ModelId`: the type
/// covers the vocabulary the tool has written, so reading a table's
/// `model` column back as the type loses nothing.
#[test]
fn every_model_a_committed_table_names_is_a_model_id() {
    let reports = Path::new(env!("CARGO_MANIFEST_DIR")).join("reports");
    let mut named = std::collections::BTreeSet::new();
    for report in std::fs::read_dir(&reports).unwrap() {
        let report = report.unwrap().path();
        if !report.is_dir() {
            continue;
        }
        for file in std::fs::read_dir(&report).unwrap() {
            let file = file.unwrap().path();
            if file.extension().is_none_or(|e| e != "csv") {
                continue;
            }
            let mut reader = csv::Reader::from_path(&file).unwrap();
            let headers = reader.headers().unwrap().clone();
            let Some(column) = headers.iter().position(|h| h == "model") else {
                continue;
            };
            for row in reader.records() {
                let row = row.unwrap();
                let model = &row[column];
                let id: alnlab_common::ModelId = model
                    .parse()
                    .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
                assert_eq!(id.to_string(), model, "{}", file.display());
                named.insert(id);
            }
        }
    }
    assert!(named.len() >= 7, "{named:?}");
}

/// The string literals of `line` that name a compared model: a
/// [`alnlab_common::ModelId`]'s fixed name, or one that starts as a
/// simulator's or the plant's (`simulator@`, `plant@`).
fn model_names_in(line: &str) -> Vec<String> {
    let fixed: Vec<String> = alnlab_common::ModelId::FIXED
        .iter()
        .map(ToString::to_string)
        .collect();
    string_literals(line)
        .into_iter()
        .filter(|literal| {
            fixed.contains(literal)
                || ["simulator@", "plant@"]
                    .iter()
                    .any(|p| literal.starts_with(p))
        })
        .collect()
}

/// The string literals of one line of code, up to a comment: each between
/// unescaped quotes (a raw string's text or a literal spanning lines is
/// not seen; none names a model).
fn string_literals(line: &str) -> Vec<String> {
    let (mut found, mut literal) = (Vec::new(), None::<String>);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (&mut literal, c) {
            (Some(text), '\\') => {
                text.push(c);
                text.extend(chars.next());
            }
            (Some(_), '"') => found.extend(literal.take()),
            (Some(text), _) => text.push(c),
            (None, '"') => literal = Some(String::new()),
            (None, '/') if chars.peek() == Some(&'/') => break,
            // A char literal's quote: `'"'`.
            (None, '\'') if chars.peek() == Some(&'"') => {
                chars.next();
            }
            (None, _) => {}
        }
    }
    found
}

/// Literals that spell a model's name and mean something else, with why.
const NOT_MODEL_NAMES: &[(&str, &str)] = &[
    // The test stage's artifacts `linear.aln` and `boosted.parquet`, by
    // role in the run record.
    (
        "pipeline/src/stages.rs",
        "(\"linear\", alnlab_evaluate::LINEAR_FILE)",
    ),
    (
        "pipeline/src/stages.rs",
        "(\"boosted\", alnlab_evaluate::BOOSTED_FILE)",
    ),
    // The Python `Model.kind` of a boosted-trees file: a kind of model
    // file, as `ModelKind::name` gives an ALN's, not a compared model.
    ("python/src/model.rs", "Files::Boosted(_) => \"boosted\","),
];

/// No code outside `alnlab_core::model_id` names a compared model by its
/// text: tables are written and read through `ModelId` and `PolicyId`, so a
/// new model is a new variant the compiler follows, not a string to find.
/// (Tests — `tests/` and each file's `#[cfg(test)]` module — assert the
/// tables' text freely.)
#[test]
fn no_code_names_a_compared_model_by_its_text() {
    let mut named = Vec::new();
    for (path, text) in rust_sources() {
        if path.starts_with("tests/") || path == "crates/core/src/model_id.rs" {
            continue;
        }
        let code = text.split("#[cfg(test)]").next().unwrap_or_default();
        for (n, line) in code.lines().enumerate() {
            let allowed = NOT_MODEL_NAMES
                .iter()
                .any(|(file, what)| *file == path && line.contains(what));
            let trimmed = line.trim_start();
            if allowed || trimmed.starts_with("//") {
                continue;
            }
            for name in model_names_in(line) {
                named.push(format!("{path}:{}: \"{name}\": {}", n + 1, line.trim()));
            }
        }
    }
    assert!(named.is_empty(), "{}", named.join("\n"));
}

#[test]
fn the_check_sees_a_model_named_by_its_text() {
    let q = '"';
    for (line, name) in [
        (format!("if r.model == {q}aln{q} {{"), "aln"),
        (format!("let m = {q}linear+nominal{q};"), "linear+nominal"),
        (
            format!("t.model.starts_with({q}simulator@{q})"),
            "simulator@",
        ),
        (format!("format!({q}plant@{{}}{q}, k)"), "plant@{}"),
    ] {
        assert_eq!(model_names_in(&line), [name], "{line}");
    }
    for line in [
        format!("format!({q}aln · {{}}{q}, name)"),
        format!("Axis::linear({q}steps{q})"),
        format!("let aln = {q}x{q}; // {q}aln{q} in a comment"),
        format!("let q = '{q}'; let s = {q}a \\{q}aln\\{q} b{q};"),
        format!("let url = {q}https://aln{q}; ModelId::Aln"),
    ] {
        assert!(model_names_in(&line).is_empty(), "{line}");
    }
}
