//! Robots from URDF, end to end: a malformed description is refused by
//! `alnlab check` (exit 2) with its file, line and element; the vendored
//! UR5 runs through every stage, its variables named after its joints, and
//! the simulator re-stepping its logged frames reproduces them. (Every
//! logged frame checked against Pinocchio: `tests/robots.py`, in the
//! suite.)

use std::path::Path;

use arrow_array::Array;

use crate::common::{alnlab, case, check_all, stderr};

const UR5: &str = include_str!("../robots/ur5/ur5_robot.urdf");

/// The UR5 with `from` replaced by `to` (which must be there).
fn edited(from: &str, to: &str) -> String {
    assert!(UR5.contains(from), "the UR5 description has no `{from}`");
    UR5.replacen(from, to, 1)
}

/// A folder holding the vendored UR5 as `robots/ur5.urdf`.
fn with_ur5() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let robots = dir.path().join("robots");
    std::fs::create_dir(&robots).unwrap();
    std::fs::write(robots.join("ur5.urdf"), UR5).unwrap();
    dir
}

/// The path of `role`'s artifact in the first variant of the run record
/// of the experiment `e2e` run in `dir`.
fn artifact(dir: &Path, role: &str) -> std::path::PathBuf {
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("runs/e2e/run.json")).unwrap()).unwrap();
    dir.join(
        record["variants"][0]["artifacts"][role]["path"]
            .as_str()
            .unwrap_or_else(|| panic!("{role} recorded")),
    )
}

fn manifest(urdf: &str, extra: &str) -> String {
    format!(
        "[experiment]\nname = \"e2e\"\nseed = 5\n\n[[simulate.scene]]\nname = \"arm\"\n\
         kind = \"urdf\"\nfile = \"{urdf}\"\nruns = 1\nduration = 1.0\n{extra}"
    )
}

#[test]
fn malformed_robot_descriptions_are_refused_naming_file_and_element() {
    let dir = tempfile::tempdir().unwrap();
    let elbow = "<joint name=\"elbow_joint\" type=\"revolute\">";
    let forearm_mass = "<mass value=\"2.275\"/>";
    let forearm_inertia = "ixx=\"0.049443313556\" ixy=\"0.0\"";
    let bad: Vec<(&str, String, &str, &str)> = vec![
        (
            "unknown joint type",
            edited(elbow, "<joint name=\"elbow_joint\" type=\"ball\">"),
            "<joint name=\"elbow_joint\">",
            "unknown joint type `ball`",
        ),
        (
            "floating joint",
            edited(elbow, "<joint name=\"elbow_joint\" type=\"floating\">"),
            "<joint name=\"elbow_joint\">",
            "not supported",
        ),
        (
            "mimic of no joint",
            edited(
                elbow,
                &format!("{elbow}<mimic joint=\"shoulder_joint\" multiplier=\"1\"/>"),
            ),
            "<mimic>",
            "follows joint `shoulder_joint`, which is not a joint of this robot",
        ),
        (
            "zero axis",
            edited(
                "<axis xyz=\"0 1 0\"/>\n    <limit effort=\"150.0\" lower=\"-3.14159265359\"",
                "<axis xyz=\"0 0 0\"/>\n    <limit effort=\"150.0\" lower=\"-3.14159265359\"",
            ),
            "<joint name=\"elbow_joint\">",
            "a zero vector",
        ),
        (
            "missing parent",
            edited(
                "<parent link=\"upper_arm_link\"/>\n    <child link=\"forearm_link\"/>",
                "<parent link=\"upper_arm\"/>\n    <child link=\"forearm_link\"/>",
            ),
            "<joint name=\"elbow_joint\">",
            "parent link `upper_arm` is not a <link>",
        ),
        (
            "two roots",
            edited(
                "  <joint name=\"world_joint\" type=\"fixed\">\n    <parent link=\"world\"/>\n    \
                 <child link=\"base_link\"/>\n    <origin rpy=\"0.0 0.0 0.0\" xyz=\"0.0 0.0 0.0\"/>\n  \
                 </joint>\n",
                "",
            ),
            "<link name=\"world\">",
            "a second root",
        ),
        (
            "a link with two parents",
            edited(
                "<link name=\"world\"/>",
                "<link name=\"world\"/><joint name=\"loop\" type=\"fixed\"><parent \
                 link=\"wrist_3_link\"/><child link=\"shoulder_link\"/></joint>",
            ),
            "<joint name=\"loop\">",
            "already has a parent joint",
        ),
        (
            "cycle",
            edited(
                "<link name=\"world\"/>",
                "<link name=\"world\"/><link name=\"a\"/><link name=\"b\"/><joint name=\"ab\" \
                 type=\"fixed\"><parent link=\"a\"/><child link=\"b\"/></joint><joint \
                 name=\"ba\" type=\"fixed\"><parent link=\"b\"/><child link=\"a\"/></joint>",
            ),
            "<link name=\"a\">",
            "joints form a cycle",
        ),
        (
            "zero mass",
            edited(forearm_mass, "<mass value=\"0\"/>"),
            "<link name=\"forearm_link\">",
            "has mass 0",
        ),
        (
            "negative mass",
            edited(forearm_mass, "<mass value=\"-2.275\"/>"),
            "<link name=\"forearm_link\">",
            "expected a mass ≥ 0",
        ),
        (
            "inertia not positive definite",
            edited(forearm_inertia, "ixx=\"0.049443313556\" ixy=\"0.2\""),
            "<link name=\"forearm_link\">",
            "not positive semi-definite",
        ),
        (
            "not XML",
            UR5.replacen("</robot>", "", 1),
            "",
            "not well-formed XML",
        ),
    ];
    let mut cases = Vec::new();
    for (k, (name, text, element, message)) in bad.iter().enumerate() {
        let urdf = format!("bad{k}.urdf");
        std::fs::write(dir.path().join(&urdf), text).unwrap();
        let toml = format!("bad{k}.toml");
        std::fs::write(dir.path().join(&toml), manifest(&urdf, "")).unwrap();
        let mut mentions = vec![urdf.as_str(), "simulate.scene.0.file", *message];
        if !element.is_empty() {
            mentions.push(element);
        }
        cases.push(case(name, &["check", &toml], &mentions, None).exits(2));
    }
    // A good description, wrongly used.
    std::fs::write(dir.path().join("ur5.urdf"), UR5).unwrap();
    let misuse = [
        (
            "no such file",
            manifest("missing.urdf", ""),
            vec!["missing.urdf", "simulate.scene.0.file"],
        ),
        (
            "an unknown link",
            manifest("ur5.urdf", "link_velocities = [\"wrist_9_link\"]\n"),
            vec!["simulate.scene.0.link_velocities", "no link `wrist_9_link`"],
        ),
        (
            "an amplitude per ball hinge",
            manifest(
                "ur5.urdf",
                "controller = { kind = \"random\", amplitude = [[1.0, 2.0, 3.0]] }\n",
            ),
            vec!["simulate.scene.0.controller.amplitude", "expected a number"],
        ),
        (
            "links given by hand",
            manifest("ur5.urdf", "links = 3\n"),
            vec!["simulate.scene.0.links", "takes this from its description"],
        ),
        (
            "a robot task naming a joint it lacks",
            manifest(
                "ur5.urdf",
                "\n[[plan.task]]\nkind = \"hold-angles\"\nname = \"t\"\ntargets = { \"q.knee_joint\" = 1.0 }\n",
            ),
            vec!["plan.task.0", "no variable `q.knee_joint`"],
        ),
    ];
    for (k, (name, text, mentions)) in misuse.iter().enumerate() {
        let toml = format!("misuse{k}.toml");
        std::fs::write(dir.path().join(&toml), text).unwrap();
        cases.push(case(name, &["check", &toml], mentions, None).exits(2));
    }
    check_all(dir.path(), &cases);
}

/// The vendored UR5 through every stage: variables named after its
/// joints; re-stepping a logged frame at the logged step reproduces the
/// next, so that simulator errs 0 levels.
#[test]
fn the_vendored_arm_runs_through_every_stage() {
    let dir = with_ur5();
    let text = manifest(
        "robots/ur5.urdf",
        "controller = { kind = \"random\", amplitude = [20.0, 20.0, 10.0, 2.0, 2.0, 0.5] }\n\
         link_velocities = [\"wrist_3_link\"]\nruns = 2\n\n[stride]\nn = 5\n\n[quantize]\n\
         levels = 16\ncode = \"gray\"\n\n[train]\nleaves = 16\nepochs = 1\n\n[test]\n\
         resimulate_steps = [10, 1]\nrollout_starts = 2\nhorizon = 2\n",
    )
    .replace("runs = 1\n", "");
    std::fs::write(dir.path().join("arm.toml"), &text).unwrap();
    let out = alnlab(
        dir.path(),
        &["-q", "run", "arm.toml", "--reports", "reports"],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let artifact = |role: &str| artifact(dir.path(), role);
    let codebook = alnlab_common::table::Table::read(&artifact("codebook")).unwrap();
    let names = codebook.strings("variable").unwrap();
    for name in [
        "q.elbow_joint",
        "qd.wrist_1_joint",
        "qdd.shoulder_pan_joint",
        "tau.wrist_3_joint",
    ] {
        assert!(names.iter().any(|n| n == name), "{name} in {names:?}");
    }
    let summary = alnlab_common::table::Table::read(&artifact("summary")).unwrap();
    let models = summary.strings("model").unwrap();
    let means = summary.f64_column("mean").unwrap();
    let exact: Vec<f64> = (0..summary.num_rows())
        .filter(|&r| models[r] == "simulator@10/frame")
        .map(|r| means.value(r))
        .collect();
    assert!(
        !exact.is_empty() && exact.iter().all(|&e| e == 0.0),
        "{exact:?}"
    );
    let report = std::fs::read_to_string(dir.path().join("reports/e2e/report.md")).unwrap();
    assert!(report.contains("`q.elbow_joint`") || report.contains("q.elbow_joint"));
    assert!(Path::new(&dir.path().join("reports/e2e/report.html")).exists());
}

/// The ALN trained as the correction of an arm's nominal simulator (`base
/// = "nominal"`): its trees read the nominal predictions, it is more
/// accurate than that simulator, it is timed with the simulator's step, and
/// its closed loop — the nominal simulator stepping the state the hybrid
/// predicted, rebuilt from the joints' positions and velocities — starts
/// where its one-step prediction is.
#[test]
fn an_aln_hybrid_corrects_an_arms_nominal_simulator_one_step_and_closed_loop() {
    let dir = with_ur5();
    let text = manifest(
        "robots/ur5.urdf",
        "controller = { kind = \"random\", amplitude = [40.0, 60.0, 30.0, 8.0, 8.0, 2.0], \
         hold = 0.25 }\nhinge_damping = 2.0\nduration = 6.0\nruns = 2\n\n\
         [simulate.scene.plant]\nmass_scale = 1.2\n\
         payload = { link = \"tool0\", mass = 2.0, offset = [0.0, 0.0, 0.05] }\n\
         viscous_friction = 1.0\n\n[stride]\nn = 2\n\n[quantize]\nlevels = 100\n\n\
         [train]\nmodel = \"piecewise-linear\"\ncontrols = \"given\"\ninformative_inputs = 4\n\
         base = \"nominal\"\npwl.max_pieces = 4\n\n[test]\nresimulate_steps = [10]\n\
         rollout_starts = 5\nhorizon = 3\nhybrids = true\n",
    )
    .replace("runs = 1\nduration = 1.0\n", "");
    std::fs::write(dir.path().join("arm.toml"), &text).unwrap();
    let out = alnlab(dir.path(), &["-q", "run", "arm.toml"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let artifact = |role: &str| artifact(dir.path(), role);
    let model = alnlab_aln::model::Model::read(&artifact("model")).unwrap();
    assert_eq!(model.header.base, alnlab_aln::model::Base::Nominal);
    assert!(
        model
            .header
            .reads
            .iter()
            .all(|reads| reads.iter().any(|r| r.starts_with("nominal("))),
        "every tree reads its variable's nominal prediction: {:?}",
        model.header.reads
    );
    let predictions =
        alnlab_tables::predictions::Predictions::read(&artifact("predictions")).unwrap();
    let model_index = |name: &str| {
        let models = predictions.models();
        models
            .iter()
            .position(|m| m.to_string() == name)
            .unwrap_or_else(|| panic!("{name} in {models:?}"))
    };
    let held_out_mean = |name: &str| {
        let m = model_index(name);
        let held_out = predictions.held_out();
        let (mut sum, mut count) = (0.0, 0.0);
        for v in 0..predictions.variables().len() {
            for (e, &h) in predictions.errors(m, v).zip(held_out) {
                if h {
                    sum += f64::from(e);
                    count += 1.0;
                }
            }
        }
        sum / count
    };
    let (aln, nominal) = (held_out_mean("aln"), held_out_mean("simulator@10/frame"));
    assert!(
        aln < 0.5 * nominal,
        "the ALN hybrid errs {aln} levels, the nominal simulator {nominal}"
    );
    let timings = alnlab_common::table::Table::read(&artifact("timings")).unwrap();
    let (models, paths) = (
        timings.strings("model").unwrap(),
        timings.strings("path").unwrap(),
    );
    let timed: Vec<(&str, &str)> = models
        .iter()
        .zip(&paths)
        .filter(|(m, _)| *m == "aln")
        .map(|(m, p)| (m.as_str(), p.as_str()))
        .collect();
    assert_eq!(timed, [("aln", "single")], "with the nominal step only");
    let rollout = alnlab_tables::rollout::Rollout::read(&artifact("rollout")).unwrap();
    assert_eq!(rollout.variables(), predictions.variables());
    for name in ["aln", "linear+nominal"] {
        let r = rollout
            .models()
            .iter()
            .position(|m| m.to_string() == name)
            .unwrap_or_else(|| panic!("{name}'s closed loop in {:?}", rollout.models()));
        let m = model_index(name);
        for v in 0..rollout.variables().len() {
            let one_step: Vec<u16> = predictions.errors(m, v).collect();
            for (s, &row) in rollout.starts().iter().enumerate() {
                let k = predictions.rows().iter().position(|&t| t == row).unwrap();
                assert_eq!(
                    rollout.errors(r, v, 1)[s],
                    one_step[k],
                    "{name}, {}, start row {row}: the closed loop's first step is its \
                     one-step prediction",
                    rollout.variables()[v]
                );
            }
        }
    }
}

/// Planning an arm that is a plant: episodes execute in the plant (its own
/// simulator predicts each frame exactly, the nominal one does not), the
/// planner's torques stay within the controller's amplitude and the
/// joints' effort limits, the ALN hybrid plans a joint target and a point
/// for the tool, and a joint target beyond the joint's limits, a frame the
/// robot lacks or a point beyond the tool's reach is refused by `alnlab
/// check` with its key.
#[test]
fn an_arm_plant_is_planned_in_the_plant_within_its_limits() {
    let dir = with_ur5();
    let text = manifest(
        "robots/ur5.urdf",
        "controller = { kind = \"random\", amplitude = [40.0, 60.0, 30.0, 8.0, 8.0, 2.0], \
         hold = 0.25 }\nhinge_damping = 2.0\nduration = 3.0\nruns = 2\n\n\
         [simulate.scene.plant]\nmass_scale = 1.2\n\
         payload = { link = \"tool0\", mass = 2.0, offset = [0.0, 0.0, 0.05] }\n\n\
         [quantize]\nlevels = 64\n\n\
         [train]\nmodel = \"piecewise-linear\"\ncontrols = \"given\"\ninformative_inputs = 3\n\
         base = \"nominal\"\npwl.max_pieces = 2\npwl.read_controls = true\n\
         pwl.never_read = [\"qdd\"]\n\n\
         [test]\nresimulate_steps = [10]\nrollout_starts = 2\nhorizon = 2\n\n\
         [plan]\nmodels = [\"aln\"]\nplanners = [\"cem\"]\nbudgets = [8]\nhorizon = 3\n\
         episodes = 2\nframes = 5\nsimulator_steps = [10]\nplant_steps = [10]\n\n\
         [[plan.task]]\nkind = \"hold-angles\"\nname = \"raise\"\n\
         targets = { \"q.shoulder_lift_joint\" = -1.2, \"q.elbow_joint\" = 0.8 }\n\n\
         [[plan.task]]\nkind = \"reach-point\"\nname = \"point\"\nframe = \"tool0\"\n\
         target = [0.3, 0.2, 0.6]\n",
    )
    .replace("runs = 1\nduration = 1.0\n", "");
    std::fs::write(dir.path().join("arm.toml"), &text).unwrap();
    let reach = text.replace("\"q.elbow_joint\" = 0.8", "\"q.elbow_joint\" = 4.0");
    std::fs::write(dir.path().join("reach.toml"), reach).unwrap();
    let frame = text.replace("frame = \"tool0\"", "frame = \"gripper\"");
    std::fs::write(dir.path().join("frame.toml"), frame).unwrap();
    let far = text.replace("[0.3, 0.2, 0.6]", "[0.3, 0.2, 2.6]");
    std::fs::write(dir.path().join("far.toml"), far).unwrap();
    check_all(
        dir.path(),
        &[
            case(
                "a joint target out of reach",
                &["check", "reach.toml"],
                &[
                    "plan.task.0.targets",
                    "q.elbow_joint",
                    "out of the joint's reach",
                    "reach.toml",
                ],
                None,
            )
            .exits(2),
            case(
                "a frame the robot lacks",
                &["check", "frame.toml"],
                &["plan.task.1.frame", "no frame `gripper`", "frame.toml"],
                None,
            )
            .exits(2),
            case(
                "a point out of the frame's reach",
                &["check", "far.toml"],
                &["plan.task.1.target", "out of `tool0`'s reach", "far.toml"],
                None,
            )
            .exits(2),
        ],
    );
    let out = alnlab(dir.path(), &["-q", "run", "arm.toml"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let artifact = |role: &str| artifact(dir.path(), role);
    // No tree reads a current acceleration but its own.
    let model = alnlab_aln::model::Model::read(&artifact("model")).unwrap();
    for ((output, _), reads) in model.header.outputs.iter().zip(&model.header.reads) {
        assert!(
            reads.iter().all(|r| !r.starts_with("qdd.") || r == output),
            "{output} reads {reads:?}"
        );
    }
    let planning = alnlab_common::table::Table::read(&artifact("planning")).unwrap();
    let models = planning.strings("model").unwrap();
    let rms = planning.f64_column("prediction_rms").unwrap();
    let rms_of = |model: &str| -> Vec<f64> {
        (0..planning.num_rows())
            .filter(|&r| models[r] == model)
            .map(|r| rms.value(r))
            .collect()
    };
    for model in ["zero", "random", "aln", "simulator@10", "plant@10"] {
        assert!(models.iter().any(|m| m == model), "{model} in {models:?}");
    }
    assert!(
        rms_of("plant@10").iter().all(|&e| e < 1e-9),
        "the plant's own simulator predicts the plant: {:?}",
        rms_of("plant@10")
    );
    assert!(
        rms_of("simulator@10").iter().all(|&e| e > 1e-6),
        "the nominal simulator does not: {:?}",
        rms_of("simulator@10")
    );
    assert!(rms_of("aln").iter().all(|e| e.is_finite()));
    let tasks = planning.strings("task").unwrap();
    let cost = planning.f64_column("cost").unwrap();
    assert!(
        (0..planning.num_rows())
            .filter(|&r| tasks[r] == "point")
            .all(|r| cost.value(r).is_finite() && cost.value(r) > 0.0),
        "the point task is planned and costs its squared distances (m²)"
    );
    assert!(tasks.iter().any(|t| t == "point"), "{tasks:?}");
    // Every planned torque within the controller's amplitude and the
    // UR5's effort limits (150, 150, 150, 28, 28, 28 N m).
    let plan = alnlab_common::table::Table::read(&artifact("plan")).unwrap();
    let lists = plan.column::<arrow_array::ListArray>("torques").unwrap();
    let torques: Vec<Vec<f64>> = (0..lists.len())
        .map(|i| {
            let values = lists.value(i);
            let values = values
                .as_any()
                .downcast_ref::<arrow_array::Float64Array>()
                .unwrap();
            values.values().to_vec()
        })
        .collect();
    assert!(!torques.is_empty());
    let bound = [40.0, 60.0, 30.0, 8.0, 8.0, 2.0];
    for row in &torques {
        assert_eq!(row.len(), 6, "one effort per joint: {row:?}");
        for (t, b) in row.iter().zip(bound) {
            assert!(t.abs() <= b + 1e-12, "{row:?}");
        }
    }
}
