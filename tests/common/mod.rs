//! What the end-to-end test files share: a small manifest and running the
//! real `alnlab` binary on it.
// Each test file uses its own subset of these.
#![allow(dead_code)]

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
"#;

/// A small, quick experiment: a tumbling box, tiny trees.
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
"#;

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
