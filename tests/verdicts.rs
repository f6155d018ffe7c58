//! The findings' verdicts must not flip with noise: the quickstart run twice
//! (the second time with `--force`, every stage recomputed and re-timed)
//! says the same words — better, worse, indistinguishable, tied, faster,
//! slower — in the same sentences. Only figures may differ; they are masked.

mod common;

use std::path::Path;

use common::{alnlab, stderr};

/// The findings section of a report, every number replaced by `#`.
fn verdicts(report: &str) -> String {
    let start = report.find("## Findings").expect("a findings section");
    let end = report
        .find("## Notes from the experimenter")
        .unwrap_or(report.len());
    let mut masked = String::new();
    let mut in_number = false;
    for c in report[start..end].chars() {
        let numeric = c.is_ascii_digit() || (in_number && c == '.');
        if numeric && !in_number {
            masked.push('#');
        } else if !numeric {
            masked.push(c);
        }
        in_number = numeric;
    }
    masked
}

#[test]
fn quickstart_findings_say_the_same_when_run_again() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/quickstart.toml");
    let dir = tempfile::tempdir().unwrap();
    let mut said = Vec::new();
    for force in [false, true] {
        let mut args = vec!["-q", "run", manifest.to_str().unwrap(), "--out", "runs"];
        args.extend(["--reports", "reports"]);
        if force {
            args.push("--force");
        }
        let out = alnlab(dir.path(), &args);
        assert!(out.status.success(), "{}", stderr(&out));
        let report =
            std::fs::read_to_string(dir.path().join("reports/quickstart/report.md")).unwrap();
        said.push(verdicts(&report));
    }
    assert!(
        [
            "better than",
            "worse than",
            "faster",
            "slower",
            "indistinguishable"
        ]
        .iter()
        .any(|w| said[0].contains(w)),
        "the findings say something:\n{}",
        said[0]
    );
    assert_eq!(said[0], said[1], "a verdict changed on re-running");
}
