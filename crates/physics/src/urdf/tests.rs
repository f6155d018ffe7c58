use nalgebra::{Matrix3, Vector3};

use super::*;
use crate::dynamics::{Derivative, Kinematics, Loads, State, Workspace};

/// A fixed base, an arm on a revolute joint (turned origin, unnormalised
/// axis, turned inertial) and a tool fixed to the arm's end.
const ARM: &str = r#"<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <link name="arm">
    <inertial>
      <origin xyz="0.5 0 0" rpy="0 0 1.5707963267948966"/>
      <mass value="2"/>
      <inertia ixx="1" ixy="0" ixz="0" iyy="2" iyz="0" izz="3"/>
    </inertial>
    <visual><geometry><mesh filename="package://arm/arm.stl"/></geometry></visual>
  </link>
  <link name="tool">
    <inertial>
      <mass value="1"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>
    </inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/>
    <child link="arm"/>
    <origin xyz="0 0 1" rpy="0 0 1.5707963267948966"/>
    <axis xyz="0 2 0"/>
    <limit lower="-1" upper="1.5" effort="40" velocity="3"/>
    <dynamics damping="0.5" friction="0.2"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="arm"/>
    <child link="tool"/>
    <origin xyz="1 0 0"/>
  </joint>
</robot>
"#;

fn close(a: &Matrix3<f64>, b: &Matrix3<f64>) -> bool {
    (a - b).abs().max() < 1e-12
}

#[test]
fn a_fixed_child_merges_into_its_body_with_inertia_in_the_link_frame() {
    let robot = parse(ARM, Base::Fixed).unwrap();
    assert_eq!(robot.name, "arm");
    assert_eq!(robot.links, ["base", "arm"]);
    assert_eq!(robot.joints, ["", "shoulder"]);
    let m = &robot.model;
    assert_eq!((m.root, m.len(), m.dof()), (Root::Fixed, 2, 1));
    let arm = &m.links[1];
    assert_eq!(arm.parent, Some(0));
    assert_eq!(arm.l, Vector3::new(0.0, 0.0, 1.0));
    match arm.joint {
        Joint::Revolute { origin, axis } => {
            assert!((axis - Vector3::y()).norm() < 1e-15, "axis normalised");
            let rz = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
            assert!(close(&origin, &rz), "{origin}");
        }
        other => panic!("{other:?}"),
    }
    // Arm: 2 kg at x = 0.5, inertia diag(1, 2, 3) turned 90° about z, so
    // diag(2, 1, 3); tool: 1 kg at x = 1. Merged: 3 kg at x = 2/3, each part
    // shifted to it (|d|² off the x axis).
    assert!((arm.mass - 3.0).abs() < 1e-15);
    assert!((arm.c - Vector3::new(2.0 / 3.0, 0.0, 0.0)).norm() < 1e-15);
    let shifted = 2.0 / 36.0 + 1.0 / 9.0;
    let expected = Matrix3::from_diagonal(&Vector3::new(2.1, 1.1 + shifted, 3.1 + shifted));
    assert!(close(&arm.inertia_com, &expected), "{}", arm.inertia_com);
    assert_eq!(
        robot.specs[1],
        JointSpec {
            range: Some((-1.0, 1.5)),
            effort: Some(40.0),
            velocity: Some(3.0),
            damping: 0.5,
            friction: 0.2,
        }
    );
    let tool = robot.frame("tool").unwrap();
    assert_eq!(tool.body, 1);
    assert_eq!(
        tool.placement.translation.vector,
        Vector3::new(1.0, 0.0, 0.0)
    );
}

/// A pendulum swings as m g d sin q / (I_c + m d²) says.
#[test]
fn a_revolute_pendulum_accelerates_as_the_textbook_says() {
    let robot = parse(ARM, Base::Fixed).unwrap();
    let model = &robot.model;
    let arm = &model.links[1];
    // The arm's x (towards its centre of mass) starts horizontal; turning
    // by q about its y axis puts the centre of mass at height −d sin q, so
    // gravity's torque is −∂(m g z)/∂q = m g d cos q.
    let (m, d) = (arm.mass, arm.c.x);
    let moment = arm.inertia_com[(1, 1)] + m * d * d;
    let mut state = State::rest(model, Vector3::zeros());
    let mut kin = Kinematics::new(model);
    let mut ws = Workspace::new(model);
    let mut out = Derivative::zeros(model);
    let mut loads = Loads::zeros(model);
    for q in [-1.0, 0.0, 0.4, 2.5] {
        state.q[1] = q;
        loads.effort[1] = 1.5;
        kin.update(model, &state);
        ws.forward(model, &state, &kin, &loads, &mut out);
        let gravity_torque = m * 9.81 * d * q.cos();
        let expected = (gravity_torque + 1.5) / moment;
        assert!(
            (out.qd[1] - expected).abs() < 1e-12 * expected.abs().max(1.0),
            "q = {q}: {} vs {expected}",
            out.qd[1]
        );
    }
}

#[test]
fn links_are_numbered_depth_first_in_joint_order() {
    let text = r#"<robot name="tree">
      <link name="root"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <link name="a"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <link name="b"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <link name="a2"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <joint name="ja" type="continuous"><parent link="root"/><child link="a"/></joint>
      <joint name="jb" type="prismatic"><parent link="root"/><child link="b"/><limit lower="0" upper="0.2" effort="10" velocity="1"/></joint>
      <joint name="ja2" type="continuous"><parent link="a"/><child link="a2"/><axis xyz="0 0 1"/></joint>
    </robot>"#;
    let robot = parse(text, Base::Free).unwrap();
    assert_eq!(robot.links, ["root", "a", "a2", "b"]);
    assert_eq!(robot.joints, ["", "ja", "ja2", "jb"]);
    let parents: Vec<_> = robot.model.links.iter().map(|l| l.parent).collect();
    assert_eq!(parents, [None, Some(0), Some(1), Some(0)]);
    assert!(matches!(
        robot.model.links[3].joint,
        Joint::Prismatic { .. }
    ));
    assert_eq!(robot.model.dof(), 6 + 3);
    assert_eq!(robot.specs[1].range, None, "continuous");
}

/// Every malformed description is refused with its line, element and what
/// was expected.
#[test]
fn malformed_descriptions_name_the_element() {
    let inertial = r#"<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>"#;
    let robot =
        |links: &str, joints: &str| format!("<robot name=\"r\">\n{links}\n{joints}\n</robot>");
    let link = |name: &str| format!("<link name=\"{name}\">{inertial}</link>");
    let joint = |name: &str, kind: &str, parent: &str, child: &str, extra: &str| {
        format!(
            "<joint name=\"{name}\" type=\"{kind}\"><parent link=\"{parent}\"/><child link=\"{child}\"/>{extra}</joint>"
        )
    };
    let two = format!("{}{}", link("a"), link("b"));
    let cases: Vec<(String, &str, &str)> = vec![
        (
            robot(&two, &joint("j", "ball", "a", "b", "")),
            "<joint name=\"j\">",
            "unknown joint type `ball`",
        ),
        (
            robot(&two, &joint("j", "floating", "a", "b", "")),
            "<joint name=\"j\">",
            "joint type `floating` is not supported",
        ),
        (
            robot(
                &two,
                &joint("j", "continuous", "a", "b", "<mimic joint=\"k\"/>"),
            ),
            "<mimic>",
            "follows joint `k`, which is not a joint of this robot",
        ),
        (
            robot(
                &format!("{two}{}", link("c")),
                &format!(
                    "{}{}",
                    joint("j", "continuous", "a", "b", "<mimic joint=\"k\"/>"),
                    joint("k", "continuous", "b", "c", "<mimic joint=\"j\"/>")
                ),
            ),
            "<joint name=\"j\">",
            "its mimics form a cycle",
        ),
        (
            robot(
                &format!("{two}{}", link("c")),
                &format!(
                    "{}{}",
                    joint("j", "fixed", "a", "b", ""),
                    joint("k", "continuous", "b", "c", "<mimic joint=\"j\"/>")
                ),
            ),
            "<mimic>",
            "follows `j`, a fixed joint",
        ),
        (
            robot(
                &two,
                &joint("j", "continuous", "a", "b", "<axis xyz=\"0 0 0\"/>"),
            ),
            "<joint name=\"j\">",
            "a zero vector",
        ),
        (
            robot(&two, &joint("j", "revolute", "a", "b", "")),
            "<joint name=\"j\">",
            "needs a <limit",
        ),
        (
            robot(&two, &joint("j", "continuous", "c", "b", "")),
            "<joint name=\"j\">",
            "parent link `c` is not a <link>",
        ),
        (robot(&two, ""), "<link name=\"b\">", "a second root"),
        (
            robot(
                &format!("{}{}", two, link("c")),
                &format!(
                    "{}{}{}",
                    joint("ab", "continuous", "a", "b", ""),
                    joint("bc", "continuous", "b", "c", ""),
                    joint("cb", "continuous", "c", "b", "")
                ),
            ),
            "<joint name=\"cb\">",
            "already has a parent joint",
        ),
        (
            robot(
                &format!("{}{}{}", link("a"), link("b"), link("c")),
                &format!(
                    "{}{}",
                    joint("bc", "continuous", "b", "c", ""),
                    joint("cb", "continuous", "c", "b", "")
                ),
            ),
            "<link name=\"b\">",
            "joints form a cycle",
        ),
        (
            robot(
                &format!("{}<link name=\"b\"/>", link("a")),
                &joint("j", "continuous", "a", "b", ""),
            ),
            "<link name=\"b\">",
            "has mass 0",
        ),
        (
            robot(
                &format!(
                    "{}<link name=\"b\"><inertial><mass value=\"-1\"/><inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>",
                    link("a")
                ),
                &joint("j", "continuous", "a", "b", ""),
            ),
            "<link name=\"b\">",
            "expected a mass ≥ 0",
        ),
        (
            robot(
                &format!(
                    "{}<link name=\"b\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"2\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>",
                    link("a")
                ),
                &joint("j", "continuous", "a", "b", ""),
            ),
            "<link name=\"b\">",
            "not positive semi-definite",
        ),
        (
            robot(
                &format!(
                    "{}<link name=\"b\"><inertial><mass value=\"1\"/><inertia ixx=\"0\" ixy=\"0\" ixz=\"0\" iyy=\"0\" iyz=\"0\" izz=\"0\"/></inertial></link>",
                    link("a")
                ),
                &joint("j", "continuous", "a", "b", ""),
            ),
            "<link name=\"b\">",
            "has no inertia about its joint",
        ),
        (
            robot(
                &format!(
                    "{}<link name=\"b\"><inertial><origin xyz=\"1e200 0 0\"/><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>",
                    link("a")
                ),
                &joint("j", "continuous", "a", "b", ""),
            ),
            "<link name=\"b\">",
            "beyond floating point",
        ),
        (
            robot(
                &format!("{}{}", two, link("a")),
                &joint("j", "continuous", "a", "b", ""),
            ),
            "<link name=\"a\">",
            "a second link named `a`",
        ),
        (
            robot(
                &two,
                &joint(
                    "j",
                    "revolute",
                    "a",
                    "b",
                    "<limit lower=\"1\" upper=\"-1\" effort=\"1\" velocity=\"1\"/>",
                ),
            ),
            "<limit>",
            "upper -1 is below lower 1",
        ),
        (
            robot(
                &two,
                &joint("j", "continuous", "a", "b", "<origin xyz=\"0 zero 0\"/>"),
            ),
            "<origin>",
            "expected three numbers",
        ),
    ];
    for (text, element, message) in &cases {
        let error = parse(text, Base::Fixed).expect_err(message);
        assert_eq!(&error.element, element, "{error}");
        assert!(error.message.contains(message), "{error}");
        assert!(error.line >= 1, "{error}");
    }
    let not_xml = parse("<robot><link name=\"a\"></robot>", Base::Fixed).unwrap_err();
    assert!(
        not_xml.message.starts_with("not well-formed XML"),
        "{not_xml}"
    );
    // A moving base needs a mass; a welded one does not.
    let massless_root = robot(
        &format!("<link name=\"world\"/>{}", link("b")),
        &joint("j", "continuous", "world", "b", ""),
    );
    assert!(parse(&massless_root, Base::Fixed).is_ok());
    let error = parse(&massless_root, Base::Free).unwrap_err();
    assert_eq!(error.element, "<link name=\"world\">");
    assert_eq!(error.line, 2, "{error}");
}

/// A chain of `links` links, every other joint fixed.
fn chain(links: usize) -> String {
    let inertial = r#"<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>"#;
    let mut text = String::from(r#"<robot name="chain">"#);
    for i in 0..links {
        text += &format!(r#"<link name="l{i}">{inertial}</link>"#);
    }
    for i in 1..links {
        let kind = if i == 1 { "continuous" } else { "fixed" };
        text += &format!(
            r#"<joint name="j{i}" type="{kind}"><parent link="l{}"/><child link="l{i}"/><origin xyz="0 0 0.1"/></joint>"#,
            i - 1
        );
    }
    text + "</robot>"
}

/// The walk from the root keeps its own stack: thousands of links fixed
/// in a chain (which overflowed the call stack at 20 000) merge into one
/// body; past the stated limit a robot is refused, naming it.
#[test]
fn long_chains_are_walked_without_the_call_stack_and_bounded() {
    let robot = parse(&chain(MAX_LINKS), Base::Fixed).unwrap();
    assert_eq!(robot.model.links.len(), 2);
    assert_eq!(robot.frames.len(), MAX_LINKS);
    assert!((robot.model.links[1].mass - (MAX_LINKS - 1) as f64).abs() < 1e-9);
    let error = parse(&chain(20_000), Base::Fixed).unwrap_err().to_string();
    assert!(
        error.contains("has 20000 links; alnlab takes robots of at most 10000"),
        "{error}"
    );
}

/// A xacro file is refused as one, not read as the one link its macros
/// leave out (whose error then blamed the controller).
#[test]
fn a_xacro_file_is_refused_as_one() {
    let text = r#"<?xml version="1.0"?>
<robot name="arm" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="segment" params="n parent">
    <link name="l${n}"/>
  </xacro:macro>
  <link name="base"/>
  <xacro:segment n="1" parent="base"/>
</robot>"#;
    let error = parse(text, Base::Fixed).unwrap_err().to_string();
    assert!(
        error.contains("line 3, <macro name=\"segment\">: a xacro element: this is a xacro file")
            && error.contains("expand it to URDF first"),
        "{error}"
    );
}

/// Inertias are judged by the body's scale: a point mass off its axis whose
/// inertia is round-off (iCub's head: all zero but ixz = 2.4e-35) moves; a
/// link welded to a fixed base (TIAGo's antennas, whose inertias are not
/// positive semi-definite) is not checked, as it never moves.
#[test]
fn inertias_are_judged_by_the_bodys_scale_and_only_where_they_move() {
    let text = r#"<robot name="r">
      <link name="base"/>
      <link name="antenna"><inertial><mass value="0.000001"/><inertia ixx="0.00000002371" ixy="0.00000006119" ixz="0.00000001179" iyy="0.00000002833" iyz="0.00000000774" izz="0.00000003849"/></inertial></link>
      <link name="head"><inertial><origin xyz="0.0185 -0.1108 0"/><mass value="1.33687"/><inertia ixx="0" ixy="0" ixz="2.40741e-35" iyy="0" iyz="0" izz="0"/></inertial></link>
      <joint name="weld" type="fixed"><parent link="base"/><child link="antenna"/></joint>
      <joint name="neck" type="continuous"><parent link="base"/><child link="head"/><axis xyz="0 0 1"/></joint>
    </robot>"#;
    let robot = parse(text, Base::Fixed).unwrap();
    let head = &robot.model.links[1];
    assert!(
        (head.axis_inertia() - 1.33687 * (0.0185f64.powi(2) + 0.1108f64.powi(2))).abs() < 1e-12
    );
    // On a free base the antenna moves with the base, and is judged.
    let error = parse(text, Base::Free).unwrap_err().to_string();
    assert!(
        error.contains("link `base`") && error.contains("not positive semi-definite"),
        "{error}"
    );
}

/// A `<mimic>` makes a coupling to the joint that follows none: a mimic of
/// a mimic composes the two (q_c = 2 (3 q_a + 1) − 0.5), and a fixed
/// joint's `<mimic>` is moot.
#[test]
fn mimics_couple_a_follower_to_its_leader() {
    let inertial = r#"<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>"#;
    let link = |name: &str| format!("<link name=\"{name}\">{inertial}</link>");
    let text = format!(
        r#"<robot name="hand">{}{}{}{}{}
          <joint name="ja" type="continuous"><parent link="base"/><child link="a"/></joint>
          <joint name="jb" type="continuous"><parent link="base"/><child link="b"/><mimic joint="ja" multiplier="3" offset="1"/></joint>
          <joint name="jc" type="continuous"><parent link="base"/><child link="c"/><mimic joint="jb" multiplier="2" offset="-0.5"/></joint>
          <joint name="jd" type="fixed"><parent link="c"/><child link="d"/><mimic joint="ja"/></joint>
        </robot>"#,
        link("base"),
        link("a"),
        link("b"),
        link("c"),
        link("d")
    );
    let robot = parse(&text, Base::Fixed).unwrap();
    assert_eq!(robot.joints, ["", "ja", "jb", "jc"]);
    assert_eq!(
        robot.model.couplings,
        [
            Coupling {
                follower: 2,
                leader: 1,
                multiplier: 3.0,
                offset: 1.0
            },
            Coupling {
                follower: 3,
                leader: 1,
                multiplier: 6.0,
                offset: 1.5
            },
        ]
    );
}

/// A body that follows another about the same axis, one for one, moves as
/// if welded to it: the coupled model's accelerations (the joint-space
/// formulation in the leader's coordinate) equal the welded model's (the
/// articulated-body algorithm), and the follower's are the leader's.
#[test]
fn a_follower_one_for_one_on_the_same_axis_moves_as_if_welded() {
    let text = |second: &str| {
        format!(
            r#"<robot name="pair">
              <link name="base"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
              <link name="a"><inertial><origin xyz="0 0.2 0.1"/><mass value="2"/><inertia ixx="0.1" ixy="0.01" ixz="0" iyy="0.2" iyz="0" izz="0.3"/></inertial></link>
              <link name="b"><inertial><origin xyz="0.1 -0.3 0.05"/><mass value="0.5"/><inertia ixx="0.02" ixy="0" ixz="0.003" iyy="0.04" iyz="0" izz="0.05"/></inertial></link>
              <joint name="ja" type="continuous"><parent link="base"/><child link="a"/><origin xyz="0 0 0.5"/><axis xyz="1 0 0"/></joint>
              {second}
            </robot>"#
        )
    };
    let coupled = text(
        r#"<joint name="jb" type="continuous"><parent link="base"/><child link="b"/><origin xyz="0 0 0.5"/><axis xyz="1 0 0"/><mimic joint="ja"/></joint>"#,
    );
    let welded =
        text(r#"<joint name="jb" type="fixed"><parent link="a"/><child link="b"/></joint>"#);
    let accelerate = |text: &str| {
        let model = parse(text, Base::Fixed).unwrap().model;
        let mut state = State::rest(&model, Vector3::zeros());
        state.q[1] = 0.7;
        state.qd[1] = -1.3;
        model.impose_couplings(&mut state);
        let mut kin = Kinematics::new(&model);
        kin.update(&model, &state);
        let mut loads = Loads::zeros(&model);
        loads.effort[1] = 2.0;
        let mut out = Derivative::zeros(&model);
        Workspace::new(&model).forward(&model, &state, &kin, &loads, &mut out);
        out.qd
    };
    let (coupled, welded) = (accelerate(&coupled), accelerate(&welded));
    assert_eq!(coupled.len(), 3);
    assert!(
        (coupled[1] - welded[1]).abs() < 1e-12 * welded[1].abs().max(1.0),
        "{coupled:?} against {welded:?}"
    );
    assert_eq!(coupled[2], coupled[1]);
}
