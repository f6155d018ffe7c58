//! Re-simulating logged frames, for the simulator baseline of the test
//! stage: a log is self-describing — its `alnlab.scene` records rebuild each
//! scene, its `/state` messages hold full generalized states — so any frame
//! can be stepped forward again, at the logged integration step or a
//! coarser one, to see what a cheaper simulator would have predicted.
//!
//! A re-simulation starts from the logged state with the run's controller
//! replayed to that instant; only the free root's tracked momentum starts
//! afresh there, so at the logged step it reproduces the next frame to
//! rounding — of a scene logged without a plant. A scene with a plant
//! (`crate::plant`) is re-simulated as written, its nominal model: the
//! simulator a user has.

use std::collections::BTreeMap;

use alnlab_core::state::{StateFrame, StateLog};
use alnlab_core::{Error, Result};

use crate::controller::ControllerKind;
use crate::model::{Joint, Root};
use crate::{Prepared, Runner, Scene, state_from_generalized};

pub use alnlab_core::state::SCENE_RECORD;

/// Name of the metadata records describing each scene's model.
pub const MODEL_RECORD: &str = "alnlab.model";

/// The `alnlab.scene` record of a scene; a robot's also holds its
/// description (`urdf`).
pub fn scene_record(scene: &Scene, index: usize, seed: u64) -> BTreeMap<String, String> {
    let json = serde_json::to_string(scene).expect("scenes serialize");
    let mut record = BTreeMap::from([
        ("scene".into(), scene.name.clone()),
        ("index".into(), index.to_string()),
        ("seed".into(), seed.to_string()),
        ("json".into(), json),
    ]);
    if let Some(text) = &scene.description {
        record.insert("urdf".into(), text.to_string());
    }
    record
}

/// The `alnlab.model` metadata record of a scene: the model as JSON, for
/// readers outside alnlab (`tests/robots.py` checks it with Pinocchio).
pub fn model_record(p: &Prepared) -> BTreeMap<String, String> {
    let scene = &p.scene;
    let links: Vec<serde_json::Value> = p
        .model
        .links
        .iter()
        .enumerate()
        .map(|(i, link)| {
            let mut entry = serde_json::json!({
                "parent": link.parent.map_or(-1, |p| p as i64),
                "joint": match (link.parent, p.model.root, link.joint) {
                    (None, Root::Free, _) => "free",
                    (None, Root::Fixed, _) => "fixed",
                    (Some(_), _, Joint::Revolute { .. }) => "revolute",
                    (Some(_), _, Joint::Prismatic { .. }) => "prismatic",
                    _ => "ball",
                },
                "mass": link.mass,
                "c": link.c.as_slice(),
                "J": link.inertia_hinge().transpose().as_slice(),
                "l": link.l.as_slice(),
            });
            if let Some(robot) = &p.robot {
                let fields = entry.as_object_mut().expect("object");
                fields.insert("link".into(), robot.links[i].clone().into());
                fields.insert("joint_name".into(), robot.joints[i].clone().into());
                if let Joint::Revolute { origin, axis } | Joint::Prismatic { origin, axis } =
                    link.joint
                {
                    fields.insert("axis".into(), axis.as_slice().into());
                    fields.insert("origin".into(), origin.transpose().as_slice().into());
                }
            }
            entry
        })
        .collect();
    let json = serde_json::json!({
        "scene": scene.name,
        "kind": scene.kind,
        "gravity": p.model.gravity.as_slice(),
        "dt": scene.dt,
        "frame_dt": scene.frame_dt,
        "integrator": scene.integrator,
        "floor": p.surfaces.floor,
        "arena_radius": p.surfaces.arena_radius,
        "contact": scene.contact,
        "contact_model": "penalty spring-damper N = max(0, k d + c d'), regularised Coulomb \
                          friction F_t = -mu N v_t / max(|v_t|, slip_speed)",
        "links": links,
        "conventions": {
            "units": "SI",
            "quaternion_order": ["x", "y", "z", "w"],
            "J": "inertia about the proximal hinge, link frame, row-major",
            "l": "hinge offset from the parent's hinge, parent frame (pinned root: the pivot, inertial frame)",
            "frames": {
                "root.p": "inertial", "root.v": "root link", "q.1": "root link to inertial",
                "q.i": "link i to its parent", "w.1": "root angular velocity, root link",
                "w.i": "hinge i relative angular velocity, link i",
                "v": "link", "a": "link", "omega": "link", "omega_dot": "link",
                "g": "link", "f_E": "link", "g_E": "link",
            },
            "g": "control torque the link exerts on its parent (paper §2); the link feels -g",
            "roll_pitch": "x and y angles of R = Rz(yaw) Ry(pitch) Rx(roll) of the hinge \
                           rotation; at pitch = ±90° roll is defined as 0",
        },
    });
    let mut json = json;
    if let Some(robot) = &p.robot {
        json["robot"] = robot.name.clone().into();
        json["base"] = serde_json::json!(scene.base);
        // Where the drives apply other than the command, the log says so.
        let total = match scene.logs_applied() {
            true => "applied + passive",
            false => "tau + passive",
        };
        json["robot_conventions"] = serde_json::json!({
            "origin": "the joint frame's rotation at q = 0 relative to the parent link, row-major",
            "axis": "unit joint axis, joint (= link) frame",
            "q": "joint position (rad or m)", "qd": "joint velocity", "qdd": "joint acceleration",
            "tau": "control effort, parent on child, clamped to the URDF's effort limit",
            "passive": format!("damping, friction and soft-limit effort at the frame's state; the \
                                joint's total effort is {total}"),
            "links": "model links are the URDF's moving bodies; links fixed to one are merged into it",
        });
        if scene.logs_applied() {
            json["robot_conventions"]["applied"] = "joint.<j>.applied: the effort the joint's \
                drive applied, where it differs from the command tau (drives holding the URDF's \
                velocity limits, a plant's actuators)"
                .into();
        }
    }
    if let Some(plant) = &scene.plant {
        json["plant"] = serde_json::json!({
            "departure": plant,
            "note": "the links' masses, centres and inertias above are the plant's, which the \
                     data come from; the scene as written (its description) is the nominal model",
            "applied": "where the actuators have a gain, joint.<j>.applied is the effort the \
                        actuator applied and the joint's total effort is applied + passive; \
                        tau stays the command",
        });
    }
    [
        ("scene".to_string(), scene.name.clone()),
        ("json".to_string(), json.to_string()),
    ]
    .into()
}

/// A logged scene, rebuilt.
pub struct SceneReplay {
    /// The scene as written — the nominal model a user has.
    pub prepared: Prepared,
    /// The scene as simulated, where it differs: with its plant.
    pub plant: Option<Prepared>,
    /// The scene's index in the experiment and the experiment's seed, which
    /// seed a runner of it ([`Runner::new`]).
    pub index: usize,
    pub seed: u64,
    /// A recorded scene's (controller `logged`): each control's index among
    /// the logged variables, whose values drive a re-simulated frame.
    pub logged_efforts: Option<Vec<usize>>,
}

impl SceneReplay {
    /// Every scene of a log, by name; an error if a record is missing or
    /// unreadable (logs written before format 3 have none).
    pub fn from_log(log: &StateLog) -> std::result::Result<BTreeMap<String, SceneReplay>, String> {
        let mut scenes = BTreeMap::new();
        for record in log.records(SCENE_RECORD) {
            let field = |key: &str| {
                record
                    .get(key)
                    .ok_or_else(|| format!("an {SCENE_RECORD} record lacks `{key}`"))
            };
            let mut scene: Scene = serde_json::from_str(field("json")?)
                .map_err(|e| format!("an {SCENE_RECORD} record does not hold a scene ({e})"))?;
            if let Some(expected) = &scene.file_sha256 {
                let text = field("urdf")?;
                let found = alnlab_core::hash::sha256_hex(text.as_bytes());
                if &found != expected {
                    return Err(format!(
                        "scene `{}`: the robot description in its {SCENE_RECORD} record has \
                         sha256 {found}, not the {expected} it was simulated from",
                        scene.name
                    ));
                }
                scene.description = Some(text.as_str().into());
            }
            // What the simulate stage checked, checked again: a record it
            // did not write must not reach the simulator.
            scene
                .clone()
                .resolve()
                .validate()
                .map_err(|(field, message)| {
                    format!(
                        "scene `{}` in an {SCENE_RECORD} record: `{field}`: {message}",
                        scene.name
                    )
                })?;
            let number = |key: &str| -> std::result::Result<u64, String> {
                field(key)?
                    .parse()
                    .map_err(|e| format!("{SCENE_RECORD} `{key}`: {e}"))
            };
            let prepared = Prepared::new(&scene.nominal());
            let logged_efforts = match prepared.scene.controller().kind {
                ControllerKind::Logged => Some(
                    prepared
                        .controls()
                        .iter()
                        .map(|c| {
                            prepared
                                .layout
                                .variables
                                .iter()
                                .position(|v| *v == c.name)
                                .ok_or_else(|| {
                                    format!(
                                        "scene `{}` logs no `{}` to drive it",
                                        scene.name, c.name
                                    )
                                })
                        })
                        .collect::<std::result::Result<Vec<usize>, String>>()?,
                ),
                _ => None,
            };
            let replay = SceneReplay {
                // The simulator a user has is the scene as written: a
                // plant's departure from it is what no nominal model knows.
                prepared,
                plant: scene.plant.is_some().then(|| Prepared::new(&scene)),
                index: number("index")? as usize,
                seed: number("seed")?,
                logged_efforts,
            };
            scenes.insert(scene.name.clone(), replay);
        }
        for scene in &log.scenes {
            if !scenes.contains_key(&scene.layout.scene) {
                return Err(format!(
                    "scene `{}` has no {SCENE_RECORD} record to re-simulate it from",
                    scene.layout.scene
                ));
            }
        }
        Ok(scenes)
    }

    /// The scene as its data were simulated: the plant where it has one,
    /// else the scene as written.
    pub fn simulated(&self) -> &Prepared {
        self.plant.as_ref().unwrap_or(&self.prepared)
    }

    /// A re-simulator of this scene's frames.
    pub fn replayer(&self) -> Replayer<'_> {
        Replayer {
            scene: self,
            runner: None,
        }
    }
}

/// Re-simulates frames of one scene, keeping the run's controller between
/// frames asked for in order (each frame of a run later than the last).
pub struct Replayer<'a> {
    scene: &'a SceneReplay,
    /// The run and the frame last re-simulated, with its moving parts.
    runner: Option<(u32, u32, Runner<'a>)>,
}

impl Replayer<'_> {
    /// The frame after `from` (a logged frame of this scene), re-simulated
    /// from its state in `steps` steps of frame_dt / steps. An error says
    /// the simulation blew up (the step is too coarse) or the logged state
    /// does not fit the model.
    pub fn next_frame(
        &mut self,
        from: &StateFrame,
        steps: u64,
        next: &mut StateFrame,
    ) -> Result<()> {
        let replay = self.scene;
        let p = &replay.prepared;
        let mut state = state_from_generalized(&p.model, &from.state).ok_or_else(|| {
            Error::Invalid(format!(
                "scene `{}`: a logged state of {} numbers does not fit its model",
                p.scene.name,
                from.state.len()
            ))
        })?;
        // The controller only goes forward in time: a new one for another
        // run or an earlier frame.
        let reuse = matches!(&self.runner, Some((run, frame, _)) if *run == from.run && *frame <= from.frame);
        if !reuse {
            let runner = Runner::new(p, replay.seed, replay.index, from.run);
            self.runner = Some((from.run, from.frame, runner));
        }
        let (_, last, runner) = self.runner.as_mut().expect("just made");
        *last = from.frame;
        runner.restart();
        // A recording's efforts, held over the frame, stand in for the
        // controller's (the next frame is observed under them too: the
        // simulator does not know the next effort).
        if let Some(efforts) = &replay.logged_efforts {
            let mut g = vec![nalgebra::Vector3::zeros(); p.model.len() - 1];
            for (c, &v) in p.controls().iter().zip(efforts) {
                g[c.hinge][c.axis] = from.variables[v];
            }
            runner.drive(Some(&g));
        }
        let dt = p.scene.step_dt(steps);
        let first = u64::from(from.frame) * steps;
        runner.advance(&mut state, first, steps, dt).map_err(|_| {
            Error::Diverged(format!(
                "scene `{}`, run {}, frame {}: re-simulation at dt = {dt} blew up",
                p.scene.name, from.run, from.frame
            ))
        })?;
        runner.observe(&state, (first + steps) as f64 * dt, next);
        next.run = from.run;
        next.frame = from.frame + 1;
        next.time = f64::from(next.frame) * p.scene.frame_dt.get();
        Ok(())
    }
}
