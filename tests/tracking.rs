//! Tracking across runs, on the real binary: records kept per run, `runs
//! list`, `show` and `diff`, filters, and records of the first format.

use std::path::Path;

use crate::common::{alnlab, stderr, write_manifest};
use serde_json::Value;

/// `alnlab <args>` in `dir`, which must succeed; its stdout.
fn ok(dir: &Path, args: &[&str]) -> String {
    let out = alnlab(dir, args);
    assert!(out.status.success(), "alnlab {args:?}: {}", stderr(&out));
    String::from_utf8(out.stdout).unwrap()
}

/// The quickstart's `gray` variant, and the same with `epochs` changed,
/// run into `dir/runs`; the two run ids.
fn two_quickstarts(dir: &Path) -> (String, String) {
    let quickstart = concat!(env!("CARGO_MANIFEST_DIR"), "/experiments/quickstart.toml");
    let text = std::fs::read_to_string(quickstart).unwrap();
    assert!(
        text.contains("\nepochs = 10\n"),
        "the quickstart trains 10 epochs"
    );
    // Timed runs as short as they come: no figure here is a speed.
    let text = format!("{text}\n[test]\nrun_seconds = 0.000001\n");
    let first = write_manifest(dir, "first.toml", &text);
    let changed = write_manifest(
        dir,
        "quickstart.toml",
        &text.replace("\nepochs = 10\n", "\nepochs = 6\n"),
    );
    let mut ids = Vec::new();
    for manifest in [first.as_path(), changed.as_path()] {
        ok(
            dir,
            &["-q", "run", manifest.to_str().unwrap(), "--variant", "gray"],
        );
        let latest: Value =
            serde_json::from_slice(&std::fs::read(dir.join("runs/quickstart/run.json")).unwrap())
                .unwrap();
        ids.push(latest["id"].as_str().unwrap().to_string());
    }
    (ids[0].clone(), ids[1].clone())
}

#[test]
fn runs_are_kept_listed_and_compared() {
    let dir = tempfile::tempdir().unwrap();
    let (first, second) = two_quickstarts(dir.path());
    assert_ne!(first, second);
    // Both records are kept; run.json is the latest.
    for id in [&first, &second] {
        let path = dir
            .path()
            .join(format!("runs/quickstart/records/{id}.json"));
        assert!(path.is_file(), "{} kept", path.display());
    }

    // `runs list --json` parses and lists both, with their metrics.
    let listed: Value = serde_json::from_str(&ok(dir.path(), &["runs", "list", "--json"])).unwrap();
    let runs = listed.as_array().unwrap();
    let ids: Vec<&str> = runs.iter().map(|r| r["id"].as_str().unwrap()).collect();
    assert_eq!(ids, [first.as_str(), second.as_str()], "oldest first");
    for run in runs {
        let variant = &run["variants"][0];
        assert_eq!(variant["name"], "gray");
        assert_eq!(
            variant["cached_files"], variant["files"],
            "all in the cache"
        );
        let aln = variant["metrics"]["error/aln"]["mean"].as_f64().unwrap();
        assert!(aln > 0.0 && aln < 5.0, "error/aln {aln}");
    }

    // `runs diff` shows exactly the parameter changed, and the metrics' changes.
    let diff: Value = serde_json::from_str(&ok(
        dir.path(),
        &["runs", "diff", &first, &second, "--json"],
    ))
    .unwrap();
    let d = &diff[0];
    assert_eq!(
        d["parameters"],
        serde_json::json!([{ "key": "train.epochs", "a": "10", "b": "6" }])
    );
    let metric = |name: &str| {
        d["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["name"] == name)
            .unwrap_or_else(|| panic!("{name} in the diff"))
            .clone()
    };
    // Training changed, the baselines' data did not.
    let aln = metric("error/aln");
    let (a, b) = (
        aln["a"]["mean"].as_f64().unwrap(),
        aln["b"]["mean"].as_f64().unwrap(),
    );
    assert_ne!(a, b, "fewer epochs, another forest");
    assert!((aln["change"].as_f64().unwrap() - (b - a)).abs() < 1e-12);
    assert_eq!(metric("error/persistence")["change"], 0.0);
    // --only-changed keeps the changed ones, drops persistence.
    let only: Value = serde_json::from_str(&ok(
        dir.path(),
        &[
            "runs",
            "diff",
            "quickstart~1",
            "quickstart",
            "--only-changed",
            "--json",
        ],
    ))
    .unwrap();
    let names: Vec<&str> = only[0]["metrics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert!(names.contains(&"error/aln") && !names.contains(&"error/persistence"));
    assert!(
        !names.iter().any(|n| n.starts_with("error_by_variable/")),
        "headline only"
    );
    // The text diff says it in words.
    let text = ok(dir.path(), &["runs", "diff", "quickstart~1", "quickstart"]);
    assert!(
        text.contains("parameters that differ (1 of ") && text.contains("train.epochs  10  6"),
        "{text}"
    );

    // Filters by parameter; the CSV has one row per variant.
    let csv = ok(
        dir.path(),
        &["runs", "list", "--csv", "--where", "train.epochs=6"],
    );
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "a header and the second run: {csv}");
    assert!(lines[1].starts_with(&second));
    let none = ok(dir.path(), &["runs", "list", "--where", "train.epochs=7"]);
    assert!(none.contains("no runs recorded"), "{none}");

    // `runs show` gives the resolved parameters, metrics and artifacts.
    let shown = ok(dir.path(), &["runs", "show", &second[..17], "--json"]);
    let shown: Value = serde_json::from_str(&shown).unwrap();
    assert_eq!(
        shown["id"],
        second.as_str(),
        "a unique prefix finds the run"
    );
    assert_eq!(shown["variants"][0]["parameters"]["quantize.code"], "gray");
    assert!(shown["artifacts_in_cache"][0]["files"]["model"].is_string());
    // A bad reference names what there is.
    let out = alnlab(dir.path(), &["runs", "show", "nosuch"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("quickstart"), "{}", stderr(&out));
    let out = alnlab(dir.path(), &["runs", "show", "quickstart:nosuch"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("it has: gray"), "{}", stderr(&out));
}

#[test]
fn first_format_records_still_list_and_newer_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = write_manifest(dir.path(), "tiny.toml", crate::common::TINY);
    ok(dir.path(), &["-q", "run", manifest.to_str().unwrap()]);
    let latest = dir.path().join("runs/tiny/run.json");
    let mut record: Value = serde_json::from_slice(&std::fs::read(&latest).unwrap()).unwrap();
    assert_eq!(record["format"], 3);
    assert_eq!(
        record["variants"][0]["resolved"]["train"]["leaves"],
        record["variants"][0]["parameters"]["train.leaves"]
            .as_str()
            .unwrap()
            .parse::<u64>()
            .unwrap(),
        "the typed parameters and the dotted ones agree"
    );
    let metrics = record["variants"][0]["metrics"]["values"]["error/aln"].clone();

    // A record as alnlab wrote it before format 2: no format, id, parameters
    // or metrics, and only run.json.
    let map = record.as_object_mut().unwrap();
    map.remove("format");
    map.remove("id");
    for v in map["variants"].as_array_mut().unwrap() {
        let v = v.as_object_mut().unwrap();
        v.remove("parameters");
        v.remove("resolved");
        v.remove("metrics");
    }
    std::fs::remove_dir_all(dir.path().join("runs/tiny/records")).unwrap();
    std::fs::write(&latest, serde_json::to_vec_pretty(&record).unwrap()).unwrap();
    let listed: Value = serde_json::from_str(&ok(dir.path(), &["runs", "--json"])).unwrap();
    let run = &listed[0];
    assert_eq!(run["format"], 1);
    assert!(
        run["id"].as_str().unwrap().len() == 22,
        "an id made up: {}",
        run["id"]
    );
    assert_eq!(
        run["variants"][0]["metrics"]["error/aln"]["mean"], metrics,
        "metrics read from the artifacts"
    );
    let shown = ok(dir.path(), &["runs", "show", "tiny"]);
    assert!(
        shown.contains("parameters: not recorded (a format-1 record)"),
        "{shown}"
    );
    // Its report needs the typed parameters of format 3: it says how to
    // get them, and re-running writes a record that has them.
    let run_dir = dir.path().join("runs/tiny");
    let out = alnlab(dir.path(), &["report", run_dir.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("before format 3")
            && stderr(&out).contains("run the experiment again"),
        "{}",
        stderr(&out)
    );

    // A newer format is refused by name, and skipped with a warning in lists.
    record["format"] = 9.into();
    std::fs::write(&latest, serde_json::to_vec_pretty(&record).unwrap()).unwrap();
    let out = alnlab(dir.path(), &["runs", "show", "tiny"]);
    assert_eq!(out.status.code(), Some(2));
    let says = stderr(&out);
    assert!(
        says.contains("run.json") && says.contains("run record format 9 is newer"),
        "{says}"
    );
    let out = alnlab(dir.path(), &["runs"]);
    assert!(out.status.success());
    assert!(
        stderr(&out).contains("warning: skipped"),
        "{}",
        stderr(&out)
    );
}
