//! The findings' verdicts must not flip with noise: the quickstart run twice
//! (the second time with `--force`, every stage recomputed and re-timed)
//! says the same accuracy words — better, worse, indistinguishable, tied —
//! in the same sentences. Figures are masked, and so are speed verdicts:
//! they rest on timings, and a test must not pass or fail with how busy the
//! machine is.

use std::path::Path;

use crate::common::{alnlab, stderr, write_manifest};

/// The findings section of a report, every number replaced by `#` and
/// every speed verdict by `<speed>`.
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
    mask_speed(&masked)
}

/// `text` with each speed verdict the report can give (`#× faster`, `#×
/// slower`, `indistinguishable in speed (…)`, `not comparable in speed
/// (…)`) replaced by `<speed>` — with the " than it" a ratio takes where
/// the indistinguishable form has none.
fn mask_speed(text: &str) -> String {
    let mut out = text.to_string();
    for word in [
        "#× faster than it",
        "#× slower than it",
        "#× faster",
        "#× slower",
    ] {
        out = out.replace(word, "<speed>");
    }
    for opening in ["indistinguishable in speed (", "not comparable in speed ("] {
        while let Some(start) = out.find(opening) {
            let end = out[start..].find(')').map_or(out.len(), |e| start + e + 1);
            out.replace_range(start..end, "<speed>");
        }
    }
    out
}

#[test]
#[ignore = "full suite: runs the quickstart twice (about 2 minutes)"]
fn quickstart_findings_say_the_same_when_run_again() {
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/quickstart.toml");
    let dir = tempfile::tempdir().unwrap();
    // The quickstart as committed but for the time each timed run takes:
    // the speed verdicts, which rest on it, are masked.
    let mut manifest: toml::Table = std::fs::read_to_string(&committed)
        .unwrap()
        .parse()
        .unwrap();
    let test = manifest
        .entry("test")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    test.as_table_mut()
        .unwrap()
        .insert("run_seconds".into(), toml::Value::Float(1e-6));
    write_manifest(
        dir.path(),
        "quickstart.toml",
        &toml::to_string(&manifest).unwrap(),
    );
    let mut said = Vec::new();
    for force in [false, true] {
        let mut args = vec!["-q", "run", "quickstart.toml", "--out", "runs"];
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
        ["better than", "worse than", "indistinguishable", "tied"]
            .iter()
            .any(|w| said[0].contains(w)),
        "the findings say something:\n{}",
        said[0]
    );
    assert_eq!(said[0], said[1], "a verdict changed on re-running");
}

#[test]
fn speed_verdicts_are_masked_whole() {
    let text = "the ALN is #× faster than sim, #× slower than x, and indistinguishable in speed \
                (its time over the simulator's ranges from # to # across the rounds); tied; \
                one state at a time, the ALN is #× slower than it.";
    assert_eq!(
        mask_speed(text),
        "the ALN is <speed> than sim, <speed> than x, and <speed>; tied; one state at a time, \
         the ALN is <speed>."
    );
}
