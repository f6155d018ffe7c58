//! The plan stage on the real binary: a small worm experiment with two
//! tasks, planned with every forward model and planner; the tables' shape,
//! and the same bytes again (decision times aside).

mod common;

use std::path::Path;

use common::{alnlab, stderr, table_without, write_manifest};

const PLANNED: &str = r#"
[experiment]
name = "planned"
seed = 5

[[simulate.scene]]
name = "worm"
kind = "worm"
runs = 2
duration = 4.0
dt = 0.001
frame_dt = 0.01
controller = { kind = "random" }

[stride]
n = 3
test_fraction = 0.5

[quantize]
levels = 16
code = "gray"

[train]
leaves = 64
epochs = 1

[test]
resimulate_steps = [10]
rollout_starts = 5

[plan]
episodes = 2
frames = 6
horizon = 3
budgets = [4, 8]
simulator_steps = [10]

[[plan.task]]
kind = "hold-angles"
name = "bend"
targets = { "pitch.2" = 0.6, "pitch.3" = -0.6 }

[[plan.task]]
kind = "spin"
name = "spin"
variable = "omega.1.x"
rate = 1.0
"#;

fn planned(dir: &Path, args: &[&str]) -> (std::path::PathBuf, std::path::PathBuf) {
    let mut full = vec!["-q", "run", "planned.toml"];
    full.extend_from_slice(args);
    let out = alnlab(dir, &full);
    assert!(out.status.success(), "{}", stderr(&out));
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("runs/planned/run.json")).unwrap()).unwrap();
    let path = |role: &str| {
        dir.join(
            record["variants"][0]["artifacts"][role]["path"]
                .as_str()
                .unwrap(),
        )
    };
    (path("plan"), path("planning"))
}

#[test]
fn the_plan_stage_plans_every_task_model_planner_and_budget_reproducibly() {
    let dir = tempfile::tempdir().unwrap();
    write_manifest(dir.path(), "planned.toml", PLANNED);
    let (plan, planning) = planned(dir.path(), &[]);
    let episodes = alnlab_common::table::Table::read(&planning).unwrap();
    // Per task: zero and random, then 2 planners × 3 models × 2 budgets;
    // each 2 episodes.
    assert_eq!(episodes.num_rows(), 2 * (2 + 2 * 3 * 2) * 2);
    let frames = alnlab_common::table::Table::read(&plan).unwrap();
    assert_eq!(frames.num_rows(), episodes.num_rows() * 6);
    let models = episodes.strings("model").unwrap();
    for model in ["zero", "random", "aln", "linear", "simulator@10"] {
        assert!(models.iter().any(|m| m == model), "{model}");
    }
    let evaluations = episodes
        .column::<arrow_array::UInt64Array>("evaluations")
        .unwrap();
    let budgets = episodes
        .column::<arrow_array::UInt32Array>("budget")
        .unwrap();
    for i in 0..episodes.num_rows() {
        assert_eq!(evaluations.value(i), u64::from(budgets.value(i)) * 3, "N·H");
    }

    // The report has the planning section, a chart per task.
    let report = std::fs::read_to_string(dir.path().join("runs/planned/report/report.md")).unwrap();
    assert!(
        report.contains("### Planning with the predictor"),
        "{report}"
    );
    for task in ["bend", "spin"] {
        assert!(report.contains(&format!("#### Task `{task}`")));
        let chart = dir
            .path()
            .join(format!("runs/planned/report/base-plan-{task}.svg"));
        assert!(chart.is_file(), "{}", chart.display());
    }

    // Again, forced: the same bytes but for the measured decision times.
    let measured = ["ms_per_decision", "ms_min", "ms_max"];
    let (plan_bytes, planning_columns) = (
        std::fs::read(&plan).unwrap(),
        table_without(&planning, &measured),
    );
    let (plan_again, planning_again) = planned(dir.path(), &["--force"]);
    assert_eq!(plan_bytes, std::fs::read(&plan_again).unwrap());
    assert_eq!(planning_columns, table_without(&planning_again, &measured));
}
