//! Robots from URDF, end to end: a malformed description is refused by
//! `alnlab check` (exit 2) with its file, line and element; the vendored
//! UR5 runs through every stage, its variables named after its joints, and
//! the simulator re-stepping its logged frames reproduces them. (Every
//! logged frame checked against Pinocchio: `tests/robots.py`, in the
//! suite.)

use std::path::Path;

use crate::common::{alnlab, case, check_all, stderr};

const UR5: &str = include_str!("../robots/ur5/ur5_robot.urdf");

/// The UR5 with `from` replaced by `to` (which must be there).
fn edited(from: &str, to: &str) -> String {
    assert!(UR5.contains(from), "the UR5 description has no `{from}`");
    UR5.replacen(from, to, 1)
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
            "mimic joint",
            edited(
                elbow,
                &format!("{elbow}<mimic joint=\"shoulder_lift_joint\" multiplier=\"1\"/>"),
            ),
            "<joint name=\"elbow_joint\">",
            "mimic joint is refused",
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
            "a robot to plan",
            manifest(
                "ur5.urdf",
                "\n[[plan.task]]\nkind = \"hold-angles\"\nname = \"t\"\ntargets = { \"q.elbow_joint\" = 1.0 }\n",
            ),
            vec!["plan.scene", "a robot"],
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
    let dir = tempfile::tempdir().unwrap();
    let robots = dir.path().join("robots");
    std::fs::create_dir(&robots).unwrap();
    std::fs::write(robots.join("ur5.urdf"), UR5).unwrap();
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
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("runs/e2e/run.json")).unwrap())
            .unwrap();
    let artifact = |role: &str| {
        dir.path().join(
            record["variants"][0]["artifacts"][role]["path"]
                .as_str()
                .unwrap(),
        )
    };
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
