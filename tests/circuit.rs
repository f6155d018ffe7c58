//! The circuit stage on the real binary with the real tools (Yosys, Icarus
//! Verilog, nextpnr-ice40): a small pendulum experiment (31 variables: a
//! quick circuit) with walk codes and three voters per bit, exported,
//! synthesized and simulated on its test rows, equal to the software on
//! every one; its figures in the report; every variable placed and routed
//! on an iCE40 with its critical path from timing analysis; `alnlab export
//! verilog` writing readable modules, and refusing what it cannot do.

mod common;

use std::path::Path;

use alnlab_common::table::Table;
use arrow_array::{UInt32Array, UInt64Array};

use common::{alnlab, stderr, write_manifest};

const CIRCUIT: &str = r#"
[experiment]
name = "circuit"
seed = 17

[[simulate.scene]]
name = "pendulum"
kind = "pendulum"
links = 3
runs = 2
duration = 4.0

[stride]
n = 3
test_fraction = 0.5

[quantize]
levels = 16
code = "walk"
width = 16

[train]
leaves = 64
epochs = 1
vote = 3

[circuit]
synthesize = true
"#;

fn artifact(dir: &Path, role: &str) -> std::path::PathBuf {
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("runs/circuit/run.json")).unwrap()).unwrap();
    dir.join(
        record["variants"][0]["artifacts"][role]["path"]
            .as_str()
            .unwrap(),
    )
}

#[test]
fn the_circuit_equals_the_software_on_every_test_row_and_its_figures_reach_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_manifest(d, "circuit.toml", CIRCUIT);
    let out = alnlab(d, &["-q", "run", "circuit.toml", "--reports", "reports"]);
    assert!(out.status.success(), "{}", stderr(&out));

    // Three parts per learned variable; every test row simulated equal
    // (the stage fails otherwise).
    let figures = Table::read(&artifact(d, "circuit")).unwrap();
    let levels = Table::read(&artifact(d, "levels")).unwrap();
    let test_rows = alnlab_codes::split_rows(&levels, "test").unwrap().len() as u64;
    let variables = figures.strings("variable").unwrap();
    let parts = figures.strings("part").unwrap();
    assert_eq!(figures.num_rows() % 3, 0);
    assert!(figures.num_rows() >= 3 * 20, "{}", figures.num_rows());
    let cells = figures.column::<UInt64Array>("cells").unwrap();
    let depth = figures.column::<UInt32Array>("depth").unwrap();
    let equal = figures.column::<UInt64Array>("rows_equal").unwrap();
    for r in 0..figures.num_rows() {
        assert_eq!(parts[r], ["trees", "votes", "decode"][r % 3]);
        assert_eq!(variables[r], variables[r - r % 3]);
        assert_eq!(equal.value(r), test_rows);
        match parts[r].as_str() {
            // Three voters: a majority gate per code bit, 16 bits.
            "votes" => assert!(cells.value(r) >= 16 && depth.value(r) >= 2, "row {r}"),
            // 16 distances and a 4-round tournament.
            "decode" => assert!(depth.value(r) >= 8, "row {r}: {}", depth.value(r)),
            // 64-leaf trees: at most 6 AND/OR levels, plus inverters.
            _ => assert!(depth.value(r) <= 12, "row {r}"),
        }
    }

    let report = std::fs::read_to_string(d.join("reports/circuit/report.md")).unwrap();
    assert!(report.contains("**Measured**"), "{report}");
    assert!(
        report.contains(&format!("on every one of the {test_rows} test rows")),
        "{report}"
    );
    assert!(report.contains("beside the paper's estimate of 59"));

    // The Verilog a user exports: one file per variable, a tree's ports
    // named after the variables and the bits of their codes.
    let model = artifact(d, "model");
    let codebook = artifact(d, "codebook");
    let export = |to: &str| {
        alnlab(
            d,
            &[
                "export",
                "verilog",
                model.to_str().unwrap(),
                "--codebook",
                codebook.to_str().unwrap(),
                "-o",
                to,
            ],
        )
    };
    let out = export("verilog");
    assert!(out.status.success(), "{}", stderr(&out));
    let pitch = std::fs::read_to_string(d.join("verilog/pitch_3.v")).unwrap();
    let tree = &pitch[..pitch.find("endmodule").unwrap()];
    assert!(tree.starts_with("// `pitch.3`, code bit 0, voter 0: 64 leaves pruned to "));
    assert!(tree.contains("module tree_pitch_3_b0_v0 (\n"), "{tree}");
    let known: Vec<String> = std::fs::read_to_string(d.join("verilog/top.v"))
        .unwrap()
        .lines()
        .filter_map(|l| l.trim().strip_prefix("input wire ["))
        .map(|l| {
            l.split_once("] ")
                .unwrap()
                .1
                .trim_end_matches(',')
                .to_string()
        })
        .collect();
    assert!(known.contains(&"roll_2".to_string()), "{known:?}");
    let ports: Vec<&str> = tree
        .lines()
        .filter_map(|l| l.trim().strip_prefix("input wire "))
        .map(|l| l.trim_end_matches(','))
        .collect();
    assert!(!ports.is_empty());
    for port in ports {
        let (bus, bit) = port.rsplit_once("_b").unwrap();
        assert!(known.iter().any(|k| k == bus), "{port}");
        assert!(bit.parse::<u32>().unwrap() < 16, "{port}");
    }
    for file in ["common.v", "top.v", "v_2_x.v", "roll_2.v"] {
        assert!(d.join("verilog").join(file).exists(), "{file}");
    }

    // Placed and routed on an iCE40 HX8K: every variable fits and has a
    // critical path; the state waits for the slowest.
    let out = alnlab(
        d,
        &[
            "-q",
            "bench",
            "circuit",
            "--run",
            "runs/circuit",
            "--rows",
            "4",
            "--fpga",
            "ice40-hx8k",
            "--json",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let bench: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let state = &bench["fpga"];
    let placed = state["variables"].as_array().unwrap();
    assert_eq!(placed.len() * 3, figures.num_rows());
    let mut slowest = 0f64;
    for p in placed {
        let ns = p["critical_ns"].as_f64().unwrap();
        // A register-to-register path through LUT levels: more than one
        // LUT's delay, far less than the 1 µs clock asked for.
        assert!(ns > 1.0 && ns < 200.0, "{p}");
        assert!((p["max_mhz"].as_f64().unwrap() * ns - 1000.0).abs() < 1e-6);
        let cells = p["logic_cells"].as_u64().unwrap();
        assert!(
            cells > 0 && cells <= p["available"].as_u64().unwrap(),
            "{p}"
        );
        assert!(p["luts"].as_u64().unwrap() > 0, "{p}");
        slowest = slowest.max(ns);
    }
    assert_eq!(state["device"], "ice40-hx8k");
    assert!(state["tools"].as_str().unwrap().contains("nextpnr-ice40"));
    assert_eq!(bench["fpga_ns_per_state"].as_f64(), Some(slowest));

    // A folder that holds files is refused, and nothing is written into it.
    let out = export("verilog");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("holds files already"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn a_threshold_model_is_not_exported_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let manifest = CIRCUIT
        .replace("vote = 3", "model = \"threshold\"")
        .replace("synthesize = true", "synthesize = false");
    write_manifest(d, "circuit.toml", &manifest);
    let out = alnlab(d, &["-q", "run", "circuit.toml", "--reports", "reports"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = alnlab(
        d,
        &[
            "export",
            "verilog",
            artifact(d, "model").to_str().unwrap(),
            "--codebook",
            artifact(d, "codebook").to_str().unwrap(),
            "-o",
            "verilog",
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("binary search"), "{}", stderr(&out));
    assert!(!d.join("verilog").exists());
}
