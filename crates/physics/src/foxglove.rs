//! The viewing channels of a trajectory log (the simulate stage's runs, the
//! plan stage's executed episodes), in Foxglove's well-known schemas (JSON
//! encoding): `/tf` carries a `foxglove.FrameTransforms` with
//! every link's frame at the viewing rate, and `/scene` a
//! `foxglove.SceneUpdate` at the start of each run drawing the floor, the
//! arena wall and the links in their frames, so the motion can be watched in
//! Foxglove.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde_json::{Value, json};

use crate::Prepared;
use crate::dynamics::Kinematics;
use crate::scene::SceneKind;
use crate::urdf::Robot;

/// Topic of the frame transforms.
pub const TF_TOPIC: &str = "/tf";
/// Topic of the scene entities.
pub const SCENE_TOPIC: &str = "/scene";
/// Foxglove schema name of `/tf`.
pub const TF_SCHEMA: &str = "foxglove.FrameTransforms";
/// Foxglove schema name of `/scene`.
pub const SCENE_SCHEMA: &str = "foxglove.SceneUpdate";

fn time(ns: u64) -> Value {
    json!({ "sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000 })
}

fn vector(v: &Vector3<f64>) -> Value {
    json!({ "x": v.x, "y": v.y, "z": v.z })
}

fn quaternion(q: &UnitQuaternion<f64>) -> Value {
    json!({ "x": q.i, "y": q.j, "z": q.k, "w": q.w })
}

/// The unit quaternion of a rotation matrix, by Shepperd's method
/// (`from_rotation_matrix`), exact for every turn. nalgebra's `from_matrix`
/// searches iteratively from the identity and stalls at a turn of 180°,
/// where it answered (nearly) the identity.
fn rotation(rot: &Matrix3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*rot))
}

/// The frame id of link `i` (0-based) of a run.
pub fn link_frame(scene: &str, run: u32, i: usize) -> String {
    format!("{scene}/run{run}/link{}", i + 1)
}

/// The frame id of a robot's URDF link `name` in a run.
pub fn robot_frame(scene: &str, run: u32, name: &str) -> String {
    format!("{scene}/run{run}/{name}")
}

/// One `/tf` message: every link's pose in the `world` frame — for a robot,
/// every URDF link's frame, named after it.
pub fn transforms(p: &Prepared, run: u32, kin: &Kinematics, log_time_ns: u64) -> Vec<u8> {
    let scene = &p.scene.name;
    let entry = |id: String, rot: &Matrix3<f64>, pos: &Vector3<f64>| {
        json!({
            "timestamp": time(log_time_ns),
            "parent_frame_id": "world",
            "child_frame_id": id,
            "translation": vector(pos),
            "rotation": quaternion(&rotation(rot)),
        })
    };
    let transforms: Vec<Value> = match &p.robot {
        None => (0..kin.rot.len())
            .map(|i| entry(link_frame(scene, run, i), &kin.rot[i], &kin.pos[i]))
            .collect(),
        Some(robot) => robot
            .frames
            .iter()
            .map(|f| {
                let (b, placement) = (f.body, &f.placement);
                let rot = kin.rot[b] * placement.rotation.to_rotation_matrix().into_inner();
                let pos = kin.point_position(b, &placement.translation.vector);
                entry(robot_frame(scene, run, &f.name), &rot, &pos)
            })
            .collect(),
    };
    serde_json::to_vec(&json!({ "transforms": transforms })).expect("JSON serializes")
}

/// One `/scene` message for the start of a run.
pub fn scene_update(p: &Prepared, run: u32, log_time_ns: u64) -> Vec<u8> {
    let (scene, model) = (&p.scene, &p.model);
    let pose = |p: Vector3<f64>, q: UnitQuaternion<f64>| json!({ "position": vector(&p), "orientation": quaternion(&q) });
    let colour = json!({ "r": 0.85, "g": 0.45, "b": 0.2, "a": 1.0 });
    let mut entities = Vec::new();
    let surfaces = scene.surfaces();
    if surfaces.floor {
        entities.push(json!({
            "timestamp": time(log_time_ns), "frame_id": "world", "id": "floor",
            "frame_locked": false,
            "cubes": [{
                "pose": pose(Vector3::new(0.0, 0.0, -0.005), UnitQuaternion::identity()),
                "size": { "x": 10.0, "y": 10.0, "z": 0.01 },
                "color": { "r": 0.6, "g": 0.6, "b": 0.6, "a": 1.0 },
            }],
        }));
    }
    if let Some(r) = surfaces.arena_radius {
        entities.push(json!({
            "timestamp": time(log_time_ns), "frame_id": "world", "id": "arena",
            "frame_locked": false,
            "cylinders": [{
                "pose": pose(Vector3::new(0.0, 0.0, 0.5), UnitQuaternion::identity()),
                "size": { "x": 2.0 * r, "y": 2.0 * r, "z": 1.0 },
                "bottom_scale": 1.0, "top_scale": 1.0,
                "color": { "r": 0.3, "g": 0.5, "b": 0.8, "a": 0.2 },
            }],
        }));
    }
    if let Some(robot) = &p.robot {
        entities.extend(robot_bones(p, robot, run, log_time_ns));
        return serde_json::to_vec(&json!({ "deletions": [], "entities": entities }))
            .expect("JSON serializes");
    }
    let along_x = UnitQuaternion::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0);
    for (i, link) in model.links.iter().enumerate() {
        let length = 2.0 * link.c.x;
        // A cylinder's axis is its z axis: turn it onto the link's x axis.
        let radius = scene.link_radius.expect("resolved").get();
        let shape = if scene.kind == SceneKind::Tumbler {
            json!({ "cubes": [{
                "pose": pose(link.c, UnitQuaternion::identity()),
                "size": { "x": length, "y": 2.0 * radius, "z": radius },
                "color": colour,
            }]})
        } else {
            json!({ "cylinders": [{
                "pose": pose(link.c, along_x),
                "size": { "x": 2.0 * radius, "y": 2.0 * radius, "z": length },
                "bottom_scale": 1.0, "top_scale": 1.0,
                "color": colour,
            }]})
        };
        let mut entity = json!({
            "timestamp": time(log_time_ns),
            "frame_id": link_frame(&scene.name, run, i),
            "id": format!("{}/run{run}/link{}", scene.name, i + 1),
            "frame_locked": true,
        });
        entity
            .as_object_mut()
            .expect("object")
            .extend(shape.as_object().expect("object").clone());
        entities.push(entity);
    }
    serde_json::to_vec(&json!({ "deletions": [], "entities": entities })).expect("JSON serializes")
}

/// A robot drawn as a stick figure: from each body's origin a cylinder of
/// the contact radius to each child body's joint, in the body's URDF frame.
fn robot_bones(p: &Prepared, robot: &Robot, run: u32, log_time_ns: u64) -> Vec<Value> {
    let radius = p.scene.link_radius.expect("resolved").get();
    let colour = json!({ "r": 0.85, "g": 0.45, "b": 0.2, "a": 1.0 });
    let mut entities = Vec::new();
    for (c, child) in p.model.links.iter().enumerate().skip(1) {
        let (b, l) = (child.parent.expect("not the root"), child.l);
        let length = l.norm();
        if length < 1e-9 {
            continue;
        }
        let turn = UnitQuaternion::rotation_between(&Vector3::z(), &l)
            .unwrap_or_else(|| UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0));
        entities.push(json!({
            "timestamp": time(log_time_ns),
            "frame_id": robot_frame(&p.scene.name, run, &robot.links[b]),
            "id": format!("{}/run{run}/{}", p.scene.name, robot.joints[c]),
            "frame_locked": true,
            "cylinders": [{
                "pose": { "position": vector(&(l / 2.0)), "orientation": quaternion(&turn) },
                "size": { "x": 2.0 * radius, "y": 2.0 * radius, "z": length },
                "bottom_scale": 1.0, "top_scale": 1.0,
                "color": colour,
            }],
        }));
    }
    entities
}

/// The `/tf` and `/scene` channels of a trajectory log, each as (topic,
/// schema name, JSON schema), for the log writer's `add_json_channels`.
pub fn channels() -> [(&'static str, &'static str, String); 2] {
    [
        (TF_TOPIC, TF_SCHEMA, tf_schema()),
        (SCENE_TOPIC, SCENE_SCHEMA, scene_schema()),
    ]
}

/// JSON schema of `foxglove.FrameTransforms` (the fields alnlab writes).
pub fn tf_schema() -> String {
    let vec3 = json!({ "type": "object", "properties": {
        "x": { "type": "number" }, "y": { "type": "number" }, "z": { "type": "number" } } });
    let quat = json!({ "type": "object", "properties": {
        "x": { "type": "number" }, "y": { "type": "number" },
        "z": { "type": "number" }, "w": { "type": "number" } } });
    json!({
        "title": TF_SCHEMA,
        "description": "An array of FrameTransform messages",
        "type": "object",
        "properties": { "transforms": { "type": "array", "items": {
            "title": "foxglove.FrameTransform",
            "type": "object",
            "properties": {
                "timestamp": time_schema(),
                "parent_frame_id": { "type": "string" },
                "child_frame_id": { "type": "string" },
                "translation": vec3,
                "rotation": quat,
            },
        }}},
    })
    .to_string()
}

/// JSON schema of `foxglove.SceneUpdate` (the fields alnlab writes).
pub fn scene_schema() -> String {
    json!({
        "title": SCENE_SCHEMA,
        "description": "An update to the entities displayed in a 3D scene",
        "type": "object",
        "properties": {
            "deletions": { "type": "array", "items": { "type": "object" } },
            "entities": { "type": "array", "items": {
                "title": "foxglove.SceneEntity",
                "type": "object",
                "properties": {
                    "timestamp": time_schema(),
                    "frame_id": { "type": "string" },
                    "id": { "type": "string" },
                    "frame_locked": { "type": "boolean" },
                    "cubes": { "type": "array", "items": { "title": "foxglove.CubePrimitive", "type": "object" } },
                    "cylinders": { "type": "array", "items": { "title": "foxglove.CylinderPrimitive", "type": "object" } },
                },
            }},
        },
    })
    .to_string()
}

fn time_schema() -> Value {
    json!({ "type": "object", "title": "time", "properties": {
        "sec": { "type": "integer", "minimum": 0 },
        "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 } } })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every turn converts exactly, half turns too — the frame fixed with
    /// `rpy="π 0 π"` among them, which `/tf` once logged as the identity
    /// (`from_matrix` answered it 2 off in a matrix entry).
    #[test]
    // 3.14159265 is what URDF files write, not π.
    #[allow(clippy::approx_constant)]
    fn a_half_turn_is_a_half_turn() {
        let axes = [
            Vector3::x(),
            Vector3::y(),
            Vector3::z(),
            Vector3::new(0.3, -0.5, 0.8).normalize(),
        ];
        let mut turns: Vec<Matrix3<f64>> = axes
            .iter()
            .flat_map(|axis| {
                [std::f64::consts::PI, 3.14159265, 2.0, 0.1].map(|angle| {
                    Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(*axis), angle)
                        .into_inner()
                })
            })
            .collect();
        let pi = std::f64::consts::PI;
        for (roll, yaw) in [(3.14159265, 3.14159265), (pi, pi)] {
            turns.push(Rotation3::from_euler_angles(roll, 0.0, yaw).into_inner());
        }
        for rot in turns {
            let back = rotation(&rot).to_rotation_matrix().into_inner();
            let error = (back - rot).abs().max();
            assert!(error < 1e-15, "{rot}: off by {error:e}");
        }
    }
}
