//! The findings' verdicts must not flip with noise: the quickstart run again
//! (every stage computed and timed afresh, in a debug build, on whatever
//! else the machine is doing) says the same accuracy words — better, worse,
//! indistinguishable, tied — in the same sentences as its committed report
//! (`reports/quickstart/`, made by a release build on a quiet machine).
//! Figures are masked, and so are speed verdicts: they rest on timings, and
//! a test must not pass or fail with how busy the machine is.

use std::path::Path;
use std::process::{Command, Stdio};

use crate::common::{stderr, write_manifest};

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

/// The accuracy verdicts of `findings` in order, each with the word after
/// it (`worse than persistence`, `indistinguishable from`, `tied on`).
fn verdict_words(findings: &str) -> Vec<String> {
    let words: Vec<&str> = findings.split_whitespace().collect();
    let mut said = Vec::new();
    for (i, word) in words.iter().enumerate() {
        let next = |k: usize| words.get(i + k).copied().unwrap_or("");
        match *word {
            "better" | "worse" if next(1) == "than" => {
                said.push(format!("{word} than {}", next(2)));
            }
            "indistinguishable" | "tied" => said.push(format!("{word} {}", next(1))),
            _ => {}
        }
    }
    said
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
#[ignore = "full suite: runs the quickstart (about a minute and a half)"]
fn quickstart_findings_say_what_its_committed_report_says() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let committed = root.join("experiments/quickstart.toml");
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
    let done = Command::new(env!("CARGO_BIN_EXE_alnlab"))
        .current_dir(dir.path())
        .args(["-q", "run", "quickstart.toml", "--reports", "reports"])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .output()
        .expect("alnlab runs");
    assert!(done.status.success(), "{}", stderr(&done));
    let again = std::fs::read_to_string(dir.path().join("reports/quickstart/report.md")).unwrap();
    let published = std::fs::read_to_string(root.join("reports/quickstart/report.md")).unwrap();
    // The words in order, not the sentences: the committed report's
    // wording may lag the code's.
    let (again, published) = (
        verdict_words(&verdicts(&again)),
        verdict_words(&verdicts(&published)),
    );
    assert!(again.len() >= 10, "the findings say something: {again:?}");
    assert_eq!(
        again, published,
        "a verdict of reports/quickstart/report.md changed on re-running"
    );
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

#[test]
fn verdict_words_keep_the_order_and_the_model_compared() {
    let text = "worse than persistence (#; +#); the ALN is better than linear, \
                indistinguishable from it; tied on #; better models";
    assert_eq!(
        verdict_words(text),
        [
            "worse than persistence",
            "better than linear,",
            "indistinguishable from",
            "tied on"
        ]
    );
}
