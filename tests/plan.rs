//! The plan stage on the real binary: a small worm experiment with two
//! tasks, planned with every forward model and planner; the tables' shape,
//! and the same bytes again (decision times aside).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use alnlab_common::table::Table;
use arrow_array::{Array, Float64Array, ListArray, UInt32Array};

use crate::common::{alnlab, stderr, table_without, write_manifest};

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

fn planned(dir: &Path, args: &[&str]) -> [PathBuf; 3] {
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
    [path("plan"), path("planning"), path("episodes")]
}

#[test]
fn the_plan_stage_plans_every_task_model_planner_and_budget_reproducibly() {
    let dir = tempfile::tempdir().unwrap();
    write_manifest(dir.path(), "planned.toml", PLANNED);
    let [plan, planning, view] = planned(dir.path(), &[]);
    let episodes = Table::read(&planning).unwrap();
    // Per task: zero and random, then 2 planners × 3 models × 2 budgets;
    // each 2 episodes.
    assert_eq!(episodes.num_rows(), 2 * (2 + 2 * 3 * 2) * 2);
    let frames = Table::read(&plan).unwrap();
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

    // Beside each frame reached, the model's prediction of the task's
    // variables for the torques chosen: the simulator at the scene's own
    // steps predicts exactly what happens; the references predict nothing.
    let variables = frames.column::<ListArray>("variables").unwrap();
    let reached = frames.column::<ListArray>("reached").unwrap();
    let expected = frames.column::<ListArray>("expected").unwrap();
    let f64s = |list: &ListArray, i: usize| -> Vec<f64> {
        let values = list.value(i);
        let values = values.as_any().downcast_ref::<Float64Array>().unwrap();
        values.values().to_vec()
    };
    let tasks = frames.strings("task").unwrap();
    let frame_models = frames.strings("model").unwrap();
    for i in 0..frames.num_rows() {
        let names = variables.value(i);
        let names = names
            .as_any()
            .downcast_ref::<arrow_array::StringArray>()
            .unwrap();
        let want: &[&str] = if tasks[i] == "bend" {
            &["pitch.2", "pitch.3"]
        } else {
            &["omega.1.x"]
        };
        assert_eq!(names.iter().flatten().collect::<Vec<_>>(), want);
        let (r, e) = (f64s(reached, i), f64s(expected, i));
        assert_eq!(r.len(), want.len());
        match frame_models[i].as_str() {
            "zero" | "random" => assert!(e.iter().all(|x| x.is_nan())),
            "simulator@10" => {
                for (e, r) in e.iter().zip(&r) {
                    assert!((e - r).abs() <= 1e-9 * r.abs().max(1.0), "row {i}: {e} {r}");
                }
            }
            _ => assert!(e.iter().all(|x| x.is_finite()), "row {i}: {e:?}"),
        }
    }
    let rms = episodes.f64_column("prediction_rms").unwrap();
    for (model, &rms) in models.iter().zip(rms.values()) {
        match model.as_str() {
            "zero" | "random" => assert!(rms.is_nan()),
            "simulator@10" => assert!(rms < 1e-9, "{rms}"),
            _ => assert!(rms > 0.0, "{model}: {rms}"),
        }
    }

    // The first episode of every policy as a run of the trajectory log, its
    // frames those of the table.
    let log = alnlab_common::state_log::read(&view).unwrap();
    assert_eq!(log.scenes.len(), 1);
    let scene = &log.scenes[0];
    let per_task = 2 + 2 * 3 * 2;
    assert_eq!(
        scene.frames.len(),
        2 * per_task * 7,
        "frames 0 to 6 per run"
    );
    let bytes = std::fs::read(&view).unwrap();
    let mut runs = BTreeMap::new();
    let mut tf = 0;
    for record in mcap::read::LinearReader::new(&bytes).unwrap() {
        match record.unwrap() {
            mcap::records::Record::Metadata(m) if m.name == "alnlab.plan.episode" => {
                runs.insert(m.metadata["run"].parse::<u32>().unwrap(), m.metadata);
            }
            mcap::records::Record::Channel(c) if c.topic == "/tf" => tf += 1,
            _ => {}
        }
    }
    assert_eq!(runs.len(), 2 * per_task);
    assert_eq!(tf, 1, "one /tf channel");
    let column = |name: &str| frames.column::<UInt32Array>(name).unwrap().clone();
    let (budget, episode, frame) = (column("budget"), column("episode"), column("frame"));
    let planners = frames.strings("planner").unwrap();
    let pitch = scene
        .layout
        .variables
        .iter()
        .position(|v| v == "pitch.2")
        .unwrap();
    for logged in &scene.frames {
        let run = &runs[&logged.run];
        assert_eq!(run["episode"], "0");
        if logged.frame == 0 || run["task"] != "bend" {
            continue;
        }
        let row = (0..frames.num_rows())
            .find(|&i| {
                tasks[i] == run["task"]
                    && frame_models[i] == run["model"]
                    && planners[i] == run["planner"]
                    && budget.value(i).to_string() == run["budget"]
                    && episode.value(i) == 0
                    && frame.value(i) == logged.frame
            })
            .unwrap();
        assert_eq!(logged.variables[pitch], f64s(reached, row)[0]);
    }

    // The report has the planning section, a chart per task.
    let report = std::fs::read_to_string(dir.path().join("runs/planned/report/report.md")).unwrap();
    assert!(
        report.contains("### Planning with the predictor"),
        "{report}"
    );
    // Each task says what it was asked, read back from the record's typed
    // parameters.
    assert_eq!(report.matches("The task: ").count(), 2, "{report}");
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
    let view_bytes = std::fs::read(&view).unwrap();
    let [plan_again, planning_again, view_again] = planned(dir.path(), &["--force"]);
    assert_eq!(plan_bytes, std::fs::read(&plan_again).unwrap());
    assert_eq!(planning_columns, table_without(&planning_again, &measured));
    assert_eq!(view_bytes, std::fs::read(&view_again).unwrap());
}

/// Rounds of the planner's own data (`[plan] rounds`): each round the
/// frames the ALN's planners executed join the training pairs, levels and
/// nominal predictions, the model is trained again and the learned models
/// plan the same episodes; every round recorded, the same bytes on one
/// thread, and a second run re-runs nothing.
#[test]
fn rounds_of_the_planners_own_data_join_the_training_rows_deterministically() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = PLANNED.replace("budgets = [4, 8]", "budgets = [4]\nrounds = 2");
    write_manifest(dir.path(), "planned.toml", &manifest);
    let run = |extra: &[&str], threads: &str| -> serde_json::Value {
        let mut args = vec!["-q", "run", "planned.toml"];
        args.extend_from_slice(extra);
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_alnlab"))
            .current_dir(dir.path())
            .env("RAYON_NUM_THREADS", threads)
            .args(&args)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        let out_dir = match extra {
            ["--out", out] => dir.path().join(out),
            _ => dir.path().join("runs"),
        };
        serde_json::from_slice(&std::fs::read(out_dir.join("planned/run.json")).unwrap()).unwrap()
    };
    let record = run(&[], "2");
    let variant = &record["variants"][0];
    let path = |role: &str| {
        dir.path().join(
            variant["artifacts"][role]["path"]
                .as_str()
                .unwrap_or_else(|| panic!("{role} recorded")),
        )
    };
    let rows = |role: &str| Table::read(&path(role)).unwrap().num_rows();
    // 2 tasks × 2 planners × 1 budget × 2 episodes of the ALN, 6 frames
    // each: 5 pairs (the last frame has no torques after it).
    let planned = 2 * 2 * 2 * 5;
    assert_eq!(rows("transitions"), planned);
    assert_eq!(rows("transitions-nominal"), planned);
    assert_eq!(rows("pairs@1"), rows("pairs") + planned);
    assert_eq!(rows("pairs@2"), rows("pairs@1") + rows("transitions@1"));
    assert_eq!(rows("levels@2"), rows("pairs@2"));
    assert_eq!(rows("nominal@2"), rows("pairs@2"));
    let splits = Table::read(&path("pairs@1"))
        .unwrap()
        .strings("split")
        .unwrap();
    assert!(splits[rows("pairs")..].iter().all(|s| s == "train"));
    let stages: Vec<&str> = variant["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["stage"].as_str().unwrap())
        .collect();
    for stage in [
        "aggregate@1",
        "train@1",
        "plan@1",
        "aggregate@2",
        "train@2",
        "plan@2",
    ] {
        assert!(stages.contains(&stage), "{stage} in {stages:?}");
    }
    // Only the learned models plan again.
    let models = Table::read(&path("planning@2"))
        .unwrap()
        .strings("model")
        .unwrap();
    assert!(models.iter().any(|m| m == "aln") && models.iter().any(|m| m == "linear"));
    assert!(!models.iter().any(|m| m.starts_with("simulator@")));
    // A second run re-runs nothing; on one thread, the same bytes.
    let again = run(&[], "2");
    assert!(
        again["variants"][0]["stages"]
            .as_array()
            .unwrap()
            .iter()
            .all(|s| s["cached"] == true),
        "{}",
        again["variants"][0]["stages"]
    );
    let one = run(&["--out", "one-thread"], "1");
    for role in [
        "pairs@2",
        "levels@2",
        "nominal@2",
        "model@2",
        "transitions@2",
    ] {
        let other = dir.path().join(
            one["variants"][0]["artifacts"][role]["path"]
                .as_str()
                .unwrap(),
        );
        assert!(
            std::fs::read(path(role)).unwrap() == std::fs::read(other).unwrap(),
            "{role} differs on one thread"
        );
    }
}

/// The controls engineer's baselines on a robot (`[plan]
/// feedback_frequencies`): the UR5 under a payload its description lacks,
/// held by the nominal model's gravity effort plus PD or PID, each loop's
/// frequency tuned on episodes of its own, beside a planner on the same
/// episodes; every episode's outcome in the task's unit. On the worm, which
/// has no joints of one degree of freedom to drive, the manifest is refused
/// by the field's name.
#[test]
fn a_robots_feedback_loops_are_tuned_apart_and_their_episodes_pair_with_the_planners() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/ur5/ur5_robot.urdf");
    let manifest = format!(
        r#"
[experiment]
name = "planned"
seed = 5

[[simulate.scene]]
name = "ur5"
kind = "urdf"
file = "{}"
runs = 2
duration = 2.0
dt = 0.001
frame_dt = 0.01
controller = {{ kind = "random", amplitude = [40.0, 60.0, 30.0, 8.0, 8.0, 2.0], hold = 0.25 }}

[simulate.scene.plant]
mass_scale = 1.1
payload = {{ link = "tool0", mass = 1.5, offset = [0.0, 0.0, 0.05] }}

[stride]
n = 3
test_fraction = 0.5

[quantize]
levels = 16
code = "gray"

[train]
leaves = 64
epochs = 1

[plan]
episodes = 2
frames = 30
horizon = 3
budgets = [4]
models = []
planners = ["cem"]
simulator_steps = [1]
feedback_frequencies = [5.0, 20.0]
tuning_episodes = 3

[[plan.task]]
kind = "hold-angles"
name = "raise"
targets = {{ "q.shoulder_lift_joint" = -1.2, "q.elbow_joint" = 1.0 }}
tolerance = 0.1
"#,
        urdf.display()
    );
    write_manifest(dir.path(), "planned.toml", &manifest);
    let [_, planning, _] = planned(dir.path(), &[]);
    let episodes = alnlab_plan::planning::read(&planning).unwrap();
    let models: Vec<String> = episodes.iter().map(|e| e.model.to_string()).collect();
    assert_eq!(
        models,
        ["zero", "random", "gravity-pd", "gravity-pid"]
            .into_iter()
            .flat_map(|m| [m, m])
            .chain(["simulator@1"; 2])
            .collect::<Vec<_>>()
    );
    for e in &episodes {
        assert!(
            e.final_error.is_finite() && e.final_error >= 0.0,
            "{e:?}: the largest angle to go, rad"
        );
        assert!((0.0..=1.0).contains(&e.within_tolerance), "{e:?}");
        assert!(e.settle_s > 0.0, "{e:?}");
        match e.model {
            alnlab_common::PolicyId::GravityPd | alnlab_common::PolicyId::GravityPid => {
                assert!([5.0, 20.0].contains(&e.feedback_frequency), "{e:?}")
            }
            _ => assert!(e.feedback_frequency.is_nan(), "{e:?}"),
        }
    }
    let report = std::fs::read_to_string(dir.path().join("runs/planned/report/report.md")).unwrap();
    assert!(
        report.contains("gravity-pd and gravity-pid, the controls engineer's first tries")
            && report.contains("lowest mean cost among 5, 20 rad/s over 3 tuning episodes")
            && report.contains("tolerance (0.100 rad here)"),
        "{report}"
    );

    let worm = PLANNED.replace(
        "budgets = [4, 8]",
        "budgets = [4]\nfeedback_frequencies = [5.0]",
    );
    write_manifest(dir.path(), "worm.toml", &worm);
    let out = alnlab(dir.path(), &["-q", "run", "worm.toml"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let message = stderr(&out);
    assert!(
        message.contains("feedback_frequencies")
            && message.contains("no task takes a feedback loop")
            && message.contains("is no robot"),
        "{message}"
    );
}
