//! What the end-to-end test files share: a small manifest and running the
//! real `alnlab` binary on it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use alnlab::records::RunRecord;

/// A small experiment: half a second of pendulum, tiny trees (files of a
/// few kilobytes, a run of about a second).
pub const TINY: &str = r#"
[experiment]
name = "tiny"
seed = 7

[[simulate.scene]]
name = "pendulum"
kind = "pendulum"
runs = 2
duration = 0.5
dt = 0.01
frame_dt = 0.01

[stride]
n = 1
split = "disjoint"
test_fraction = 0.5

[quantize]
levels = 8
code = "gray"

[train]
leaves = 8
epochs = 1

[test]
resimulate_steps = [1]
rollout_starts = 1
horizon = 2
run_seconds = 0.000001
"#;

/// A small, quick experiment: a tumbling box, tiny trees, timing runs as
/// short as they come (one evaluation each).
pub const MANIFEST: &str = r#"
[experiment]
name = "e2e"
seed = 11

[[simulate.scene]]
name = "box"
runs = 2
duration = 3.0
dt = 0.001
frame_dt = 0.01

[stride]
n = 5
test_fraction = 0.4

[train]
leaves = 64
epochs = 2

[test]
run_seconds = 0.000001
"#;

/// The UR5's moving joints, as its URDF names them.
pub const UR5_JOINTS: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

/// The header of a CSV table of the UR5's samples: a time column `t`,
/// then each joint's position, velocity and effort (the table source's
/// default columns).
pub fn ur5_table_header() -> String {
    let mut text = String::from("t");
    for j in UR5_JOINTS {
        text += &format!(",{j}.position,{j}.velocity,{j}.effort");
    }
    text
}

pub fn alnlab(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_alnlab"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("alnlab runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn write_manifest(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

pub fn run_ok(dir: &Path, args: &[&str]) -> RunRecord {
    let mut full = vec!["-q", "run"];
    full.extend_from_slice(args);
    let out = alnlab(dir, &full);
    assert!(
        out.status.success(),
        "alnlab {full:?} failed: {}",
        stderr(&out)
    );
    let out_dir = args
        .iter()
        .position(|a| *a == "--out")
        .map_or("runs", |i| args[i + 1]);
    let json = std::fs::read(dir.join(out_dir).join("e2e/run.json")).unwrap();
    serde_json::from_slice(&json).unwrap()
}

/// Bytes of every artifact file of the first variant, by role; the training
/// log as its columns less `seconds`, the timings less `ns_per_state`,
/// `ns_min`, `ns_max` and `ns_runs`, and the planning table less its
/// decision times (measurements, the only values in artifacts that differ
/// between equal runs).
pub fn artifact_bytes(dir: &Path, record: &RunRecord) -> Vec<(String, Vec<u8>)> {
    record.variants[0]
        .artifacts
        .iter()
        .map(|(role, a)| {
            let path = dir.join(&a.path);
            let bytes = match role.as_str() {
                "training" => table_without(&path, &["seconds"]),
                "timings" => table_without(&path, &["ns_per_state", "ns_min", "ns_max", "ns_runs"]),
                "planning" => table_without(&path, &["ms_per_decision", "ms_min", "ms_max"]),
                _ => std::fs::read(&path).unwrap(),
            };
            (role.clone(), bytes)
        })
        .collect()
}

/// A table's columns but the `measured` ones, as text.
pub fn table_without(path: &Path, measured: &[&str]) -> Vec<u8> {
    let table = alnlab_common::table::Table::read(path).unwrap();
    let schema = table.batch.schema();
    let mut text = String::new();
    for (field, column) in schema.fields().iter().zip(table.batch.columns()) {
        if !measured.contains(&field.name().as_str()) {
            text.push_str(&format!("{}: {:?}\n", field.name(), column));
        }
    }
    for name in measured {
        assert!(schema.field_with_name(name).is_ok(), "{name} is a column");
    }
    text.into_bytes()
}

/// One bad input: the command, and what its error must mention.
pub struct Case {
    pub name: String,
    pub args: Vec<String>,
    pub mentions: Vec<String>,
    /// The folder that must hold no finished file afterwards.
    pub out: Option<PathBuf>,
    /// The exit code it must have: 2 (the user's to fix) or 1 (damaged
    /// data); `None`: either.
    pub exit: Option<i32>,
}

pub fn case(name: &str, args: &[&str], mentions: &[&str], out: Option<&Path>) -> Case {
    Case {
        name: name.into(),
        args: args.iter().map(|s| s.to_string()).collect(),
        mentions: mentions.iter().map(|s| s.to_string()).collect(),
        out: out.map(Path::to_path_buf),
        exit: None,
    }
}

impl Case {
    /// The same case, which must exit with `code`.
    pub fn exits(self, code: i32) -> Case {
        Case {
            exit: Some(code),
            ..self
        }
    }
}

/// Runs every case, collecting every failure before reporting them: each
/// must exit with its code (1 or 2), without a panic, its error mentioning
/// what it should, its output folder empty.
pub fn check_all(dir: &Path, cases: &[Case]) {
    let mut failures = Vec::new();
    for c in cases {
        let args: Vec<&str> = c.args.iter().map(String::as_str).collect();
        let out: Output = alnlab(dir, &args);
        let err = stderr(&out);
        let code = out.status.code();
        let wanted = c
            .exit
            .map_or(matches!(code, Some(1 | 2)), |e| code == Some(e));
        if !wanted {
            let want = c.exit.map_or("1 or 2".to_string(), |e| e.to_string());
            failures.push(format!("{}: exit {code:?} (want {want}): {err}", c.name));
            continue;
        }
        if err.contains("panicked") {
            failures.push(format!("{}: panicked: {err}", c.name));
        }
        for m in &c.mentions {
            if !err.contains(m.as_str()) {
                failures.push(format!(
                    "{}: the error does not mention `{m}`: {err}",
                    c.name
                ));
            }
        }
        if let Some(folder) = &c.out {
            let finished: Vec<String> = std::fs::read_dir(folder)
                .into_iter()
                .flatten()
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            if !finished.is_empty() {
                failures.push(format!("{}: left {finished:?} in its output", c.name));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    assert!(!cases.is_empty());
}

/// The committed reports' folders (each holding a `report.md`), sorted.
pub fn committed_reports() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("reports");
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("report.md").exists())
        .collect();
    dirs.sort();
    assert!(dirs.len() >= 7, "{dirs:?}");
    dirs
}
