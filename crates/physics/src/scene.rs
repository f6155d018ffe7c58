//! Scenes: what a manifest's `[[simulate.scene]]` entry describes, and how it
//! becomes a model, surfaces, a controller and seeded initial states.
//!
//! Kinds and their defaults (any default can be overridden):
//!
//! | kind | links | root | floor | arena wall | gravity | hinge damping | controller |
//! |---|---|---|---|---|---|---|---|
//! | `worm` | 3 capsules | free | yes | r = 2 m | −9.81 z | 1.0 | random |
//! | `chain` | 4 capsules | free | no | no | 0 | 0 | none |
//! | `pendulum` | 3 capsules | pinned | no | no | −9.81 z | 0 | none |
//! | `tumbler` | 1 box | free | no | no | 0 | 0 | none |
//! | `urdf` | the robot's | fixed (`base`) | no | no | −9.81 z | 0 (plus the URDF's) | random |
//!
//! A `urdf` scene reads its robot from `file` (a URDF, relative to the
//! manifest) when the manifest is read ([`Scene::read_description`]); the
//! description's text travels with the scene (not serialized: the log keeps
//! it in the scene's record) and its sha256 is a parameter, so an edited
//! description simulates afresh.

use std::sync::Arc;

use alnlab_core::bounded;
use alnlab_core::params::{Count, Positive};
use nalgebra::{UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::Integrator;
use crate::contact::{ContactParams, Surfaces};
use crate::controller::{Amplitude, ControllerKind, ControllerParams};
use crate::dynamics::{State, effective_inertias};
use crate::model::{Joint, Model, Root, Shape};
use crate::plant::Plant;
use crate::urdf::{self, Base, Robot};

/// What a scene simulates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    /// The paper's worm: a free chain rolling, jumping and falling in its arena.
    #[default]
    Worm,
    /// A free chain of links, tumbling.
    Chain,
    /// A chain hanging from a hinge fixed in the world.
    Pendulum,
    /// One free asymmetric box.
    Tumbler,
    /// A robot from a URDF description.
    Urdf,
}

/// One `[[simulate.scene]]` entry. Fields left out take the kind's defaults
/// (filled in by [`Scene::resolve`], so `alnlab check` shows them).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Unique name: letters, digits, `-`, `_`.
    pub name: String,
    /// What is simulated.
    #[serde(default)]
    pub kind: SceneKind,
    /// Runs, each with its own seeded initial state (and controller).
    #[serde(default = "two")]
    pub runs: Count,
    /// Simulated seconds per run.
    #[serde(default = "ten")]
    pub duration: Positive,
    /// Integration step (s).
    #[serde(default = "millisecond")]
    pub dt: Positive,
    /// Logged time slice (s), a whole multiple of `dt`.
    #[serde(default = "ten_milliseconds")]
    pub frame_dt: Positive,
    /// Integrator.
    #[serde(default)]
    pub integrator: Integrator,
    /// Number of links (1..=64) of a built-in kind.
    pub links: Option<Count>,
    /// Length of each link (m); for a tumbler, the box's x edge.
    pub link_length: Option<Positive>,
    /// Radius of each capsule link (m); for a tumbler, half the y edge.
    pub link_radius: Option<Positive>,
    /// Mass of each link (kg).
    pub link_mass: Option<Positive>,
    /// Gravity, inertial frame (m/s²).
    pub gravity: Option<[f64; 3]>,
    /// Whether the floor z = 0 is there.
    pub floor: Option<bool>,
    /// Radius of the arena wall (m); 0 for no wall.
    pub arena_radius: Option<f64>,
    /// Contact law.
    #[serde(default)]
    pub contact: ContactParams,
    /// Viscous damping at every hinge (N m s/rad): a torque −b·w against the
    /// hinge's relative rate, like a muscle's viscosity.
    pub hinge_damping: Option<f64>,
    /// Hinge controller.
    pub controller: Option<ControllerParams>,
    /// Initial height of the root hinge (m).
    pub initial_height: Option<f64>,
    /// Each run starts with a random linear velocity of up to this speed (m/s).
    pub initial_speed: Option<f64>,
    /// Each run starts with random angular rates of up to this (rad/s) per
    /// component, at the root and at every hinge (a robot: every joint's
    /// velocity, rad/s or m/s).
    pub initial_spin: Option<f64>,
    /// `urdf`: the robot description (URDF), relative to the manifest.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// `urdf`: the description's sha256, filled in when it is read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file_sha256: Option<String>,
    /// `urdf`: how the robot's root link is held (`fixed` or `free`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base: Option<Base>,
    /// `urdf`: links (URDF names) whose origin is a contact point, a sphere
    /// of `link_radius` (a foot).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_links: Option<Vec<String>>,
    /// `urdf`: links (URDF names, heads of moving bodies) whose v and ω
    /// (link frame) are variables, besides every joint's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_velocities: Option<Vec<String>>,
    /// How the plant the data are logged from departs from this scene (its
    /// nominal model); none when it is the scene as written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plant: Option<Plant>,
    /// `urdf`: the drives hold every joint within the description's
    /// velocity limit (soft bounds on the effort, as ros_control's) and
    /// each run starts within it, so the robot moves as a real one could.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub velocity_limits: bool,
    /// Integration steps a frame of the nominal model a user has — the
    /// scene as written, stepping the nominal stage's predictions and the
    /// hybrids' — when not the scene's own (`frame_dt / dt`): a coarser,
    /// cheaper simulator for a learned correction to mend.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_steps: Option<Count>,
    /// `urdf`: the description's text, read from `file`.
    #[serde(skip)]
    pub description: Option<Arc<str>>,
}

fn two() -> Count {
    Count(2)
}
fn ten() -> Positive {
    Positive(10.0)
}
fn millisecond() -> Positive {
    Positive(1e-3)
}
fn ten_milliseconds() -> Positive {
    Positive(1e-2)
}

impl Default for Scene {
    /// A worm scene with every kind-dependent field left to [`Scene::resolve`].
    fn default() -> Self {
        Scene {
            name: "worm".into(),
            kind: SceneKind::Worm,
            runs: two(),
            duration: ten(),
            dt: millisecond(),
            frame_dt: ten_milliseconds(),
            integrator: Integrator::default(),
            links: None,
            link_length: None,
            link_radius: None,
            link_mass: None,
            gravity: None,
            floor: None,
            arena_radius: None,
            contact: ContactParams::default(),
            hinge_damping: None,
            controller: None,
            initial_height: None,
            initial_speed: None,
            initial_spin: None,
            file: None,
            file_sha256: None,
            base: None,
            contact_links: None,
            link_velocities: None,
            velocity_limits: false,
            nominal_steps: None,
            plant: None,
            description: None,
        }
    }
}

/// That `robot` has no link `name`, and the links it has.
fn no_link(robot: &Robot, name: &str) -> String {
    let links: Vec<&str> = robot.frames.iter().map(|f| f.name.as_str()).collect();
    format!(
        "robot `{}` has no link `{name}`; its links: {}",
        robot.name,
        links.join(", ")
    )
}

/// A scene error: the field (within the scene) and what is wrong.
pub type SceneError = (String, String);

impl Scene {
    /// Fills every field left out with the kind's default; a plant that is
    /// the scene as written is dropped, so that the scene is the same one
    /// (its cache keys and artifacts) as without it.
    pub fn resolve(mut self) -> Scene {
        use SceneKind::*;
        if self.plant.as_ref().is_some_and(Plant::is_nominal) {
            self.plant = None;
        }
        let k = self.kind;
        if k == Urdf {
            return self.resolve_robot();
        }
        let default_links = match k {
            Worm | Pendulum => 3,
            Chain => 4,
            Tumbler | Urdf => 1,
        };
        self.links.get_or_insert(Count(default_links));
        self.link_length
            .get_or_insert(Positive(if k == Tumbler { 0.4 } else { 0.5 }));
        self.link_radius
            .get_or_insert(Positive(if k == Tumbler { 0.1 } else { 0.06 }));
        self.link_mass.get_or_insert(Positive(1.0));
        let g = if matches!(k, Worm | Pendulum) {
            -9.81
        } else {
            0.0
        };
        self.gravity.get_or_insert([0.0, 0.0, g]);
        self.floor.get_or_insert(k == Worm);
        self.arena_radius
            .get_or_insert(if k == Worm { 2.0 } else { 0.0 });
        self.hinge_damping
            .get_or_insert(if k == Worm { 0.3 } else { 0.0 });
        self.controller.get_or_insert_with(|| ControllerParams {
            kind: if k == Worm {
                ControllerKind::Random
            } else {
                ControllerKind::None
            },
            ..ControllerParams::default()
        });
        self.initial_height
            .get_or_insert(if k == Worm { 0.5 } else { 0.0 });
        self.initial_speed
            .get_or_insert(if k == Worm { 2.0 } else { 0.0 });
        self.initial_spin.get_or_insert(match k {
            Worm => 2.0,
            Chain => 3.0,
            Pendulum => 1.5,
            Tumbler | Urdf => 6.0,
        });
        self
    }

    /// A robot's defaults: contact spheres of 2 cm, gravity, no floor or
    /// wall, no added damping, random efforts of up to 5 (N m or N) held
    /// for 0.25 s, a welded base at the origin, joints moving at up to
    /// 0.5 (rad/s or m/s). Its link count is the description's.
    fn resolve_robot(mut self) -> Scene {
        self.link_radius.get_or_insert(Positive(0.02));
        self.gravity.get_or_insert([0.0, 0.0, -9.81]);
        self.floor.get_or_insert(false);
        self.arena_radius.get_or_insert(0.0);
        self.hinge_damping.get_or_insert(0.0);
        self.controller.get_or_insert_with(|| ControllerParams {
            kind: ControllerKind::Random,
            amplitude: vec![Amplitude::Axis(5.0)],
            ..ControllerParams::default()
        });
        self.initial_height.get_or_insert(0.0);
        self.initial_speed.get_or_insert(0.0);
        self.initial_spin.get_or_insert(0.5);
        self.base.get_or_insert(Base::Fixed);
        self.contact_links.get_or_insert_with(Vec::new);
        self.link_velocities.get_or_insert_with(Vec::new);
        self
    }

    /// Reads a `urdf` scene's description from `file` (relative to `dir`,
    /// the manifest's folder): keeps its text, fills in its sha256 and the
    /// link count. Other kinds are left as they are. On error, the field
    /// and what is wrong.
    pub fn read_description(&mut self, dir: &std::path::Path) -> Result<(), SceneError> {
        if self.kind != SceneKind::Urdf {
            let robot_only = [
                ("file", self.file.is_some()),
                ("file_sha256", self.file_sha256.is_some()),
                ("base", self.base.is_some()),
                ("contact_links", self.contact_links.is_some()),
                ("link_velocities", self.link_velocities.is_some()),
                ("velocity_limits", self.velocity_limits),
            ];
            return match robot_only.iter().find(|(_, set)| *set) {
                None => Ok(()),
                Some((field, _)) => Err((
                    field.to_string(),
                    "only a `urdf` scene (a robot) has this".into(),
                )),
            };
        }
        for (field, set) in [
            ("file_sha256", self.file_sha256.is_some()),
            ("links", self.links.is_some()),
            ("link_length", self.link_length.is_some()),
            ("link_mass", self.link_mass.is_some()),
        ] {
            if set {
                return Err((
                    field.into(),
                    "a `urdf` scene takes this from its description; remove it".into(),
                ));
            }
        }
        let file = self.file.as_ref().ok_or_else(|| {
            (
                "file".to_string(),
                "expected the robot description, file = \"….urdf\" (relative to the manifest)"
                    .to_string(),
            )
        })?;
        let path = dir.join(file);
        let text =
            bounded::read_to_string(&path, bounded::DESCRIPTION_BYTES, "a robot description")
                .map_err(|e| {
                    (
                        "file".to_string(),
                        format!("cannot read {}: {e}", path.display()),
                    )
                })?;
        self.set_description(&text)
            .map_err(|e| ("file".to_string(), format!("{}: {e}", path.display())))
    }

    /// Gives a `urdf` scene its description's text (what
    /// [`Scene::read_description`] reads from the file): keeps it, fills in
    /// its sha256 and the link count; an error if the text is not a robot
    /// this simulator takes.
    pub fn set_description(&mut self, text: &str) -> Result<(), urdf::UrdfError> {
        let robot = urdf::parse(text, self.base.unwrap_or(Base::Fixed))?;
        self.links = Some(Count(robot.model.len() as u64));
        self.file_sha256 = Some(alnlab_core::hash::sha256_hex(text.as_bytes()));
        self.description = Some(text.into());
        Ok(())
    }

    /// A `urdf` scene's robot (after [`Scene::read_description`] and
    /// [`Scene::resolve`]), with the scene's gravity.
    pub fn robot(&self) -> Option<Robot> {
        let text = self.description.as_ref()?;
        let mut robot = urdf::parse(text, self.base.unwrap_or(Base::Fixed)).ok()?;
        robot.model.gravity = Vector3::from(self.gravity.expect("resolved"));
        Some(robot)
    }

    fn links_n(&self) -> usize {
        self.links.expect("resolved").get()
    }

    /// The scene as written, without its plant: the nominal model a user
    /// has, which a simulator baseline and a planner's model run.
    pub fn nominal(&self) -> Scene {
        Scene {
            plant: None,
            ..self.clone()
        }
    }

    /// Whether a frame logs each one-DOF joint's applied effort
    /// (`joint.<joint>.applied`): where it differs from the command, by a
    /// plant's actuators or drives holding velocity limits.
    pub fn logs_applied(&self) -> bool {
        self.plant.as_ref().is_some_and(Plant::has_actuators) || self.velocity_limits
    }

    /// The viscous damping added at every joint: the scene's
    /// `hinge_damping`, and the plant's friction beyond it.
    pub fn added_damping(&self) -> f64 {
        let damping = self.hinge_damping.expect("resolved");
        match &self.plant {
            Some(plant) => damping + plant.viscous_friction,
            None => damping,
        }
    }

    /// The body the plant's payload is fixed to and its link's placement on
    /// that body (`robot`: a `urdf` scene's); `None` without a payload.
    fn payload_at(
        &self,
        robot: Option<&Robot>,
    ) -> Result<Option<(usize, nalgebra::Isometry3<f64>)>, SceneError> {
        let Some(payload) = self.plant.as_ref().and_then(|p| p.payload.as_ref()) else {
            return Ok(None);
        };
        let field = "plant.payload.link".to_string();
        match robot {
            Some(robot) => match robot.frame(&payload.link) {
                Some(frame) => Ok(Some((frame.body, frame.placement))),
                None => Err((field, no_link(robot, &payload.link))),
            },
            None => {
                let n = self.links_n();
                match payload.link.parse::<usize>() {
                    Ok(k) if (1..=n).contains(&k) => {
                        Ok(Some((k - 1, nalgebra::Isometry3::identity())))
                    }
                    _ => Err((
                        field,
                        format!(
                            "expected a link number from 1 (the root) to {n}, found `{}`",
                            payload.link
                        ),
                    )),
                }
            }
        }
    }

    /// The link tree the plant has: [`Scene::model`] with the plant's masses
    /// and payload (the same tree without a plant).
    pub fn plant_model(&self) -> Model {
        let robot = self.robot();
        let mut model = match &robot {
            Some(robot) => robot.model.clone(),
            None => self.model(),
        };
        if let Some(plant) = &self.plant {
            let at = self.payload_at(robot.as_ref()).expect("validated");
            plant.perturb(&mut model, at);
        }
        model
    }

    /// The plant's own checks: its values, its payload's link, and no
    /// Coulomb friction where the joints are ball hinges.
    fn validate_plant(&self) -> Result<(), SceneError> {
        let Some(plant) = &self.plant else {
            return Ok(());
        };
        plant
            .validate()
            .map_err(|(field, message)| (format!("plant.{field}"), message))?;
        if self.kind != SceneKind::Urdf && plant.sensors().is_some() {
            return Err((
                "plant.sensor_noise".into(),
                "joint sensors are a robot's: its joint positions and velocities; a ball-hinged \
                 chain has none"
                    .into(),
            ));
        }
        if self.kind != SceneKind::Urdf && plant.coulomb_friction != 0.0 {
            return Err((
                "plant.coulomb_friction".into(),
                "a ball hinge has no Coulomb friction law; it applies to a robot's one-DOF \
                 joints"
                    .into(),
            ));
        }
        self.payload_at(self.robot().as_ref()).map(|_| ())
    }

    /// Checks the scene (after [`Scene::resolve`]); on error, the field and
    /// what is allowed.
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.plant.is_some() {
            // The scene as written is a simulator that runs too (the
            // baselines' and planners'): it must pass on its own.
            self.nominal().validate()?;
        }
        let err = |field: &str, message: String| Err((field.to_string(), message));
        let n = self.links_n();
        // A URDF robot is as large as its description (the parser bounds
        // it); the built-in kinds are sized by `links`.
        if n > 64 && self.kind != SceneKind::Urdf {
            return err("links", format!("expected 1 to 64 links, found {n}"));
        }
        if self.kind == SceneKind::Tumbler && n != 1 {
            return err("links", format!("a tumbler is one body, found links = {n}"));
        }
        if self.kind == SceneKind::Worm && n < 2 {
            return err("links", "a worm needs at least 2 links".into());
        }
        let ratio = self.frame_dt.get() / self.dt.get();
        if ratio.round() < 1.0 || (ratio - ratio.round()).abs() > 1e-9 * ratio {
            return err(
                "frame_dt",
                format!(
                    "expected a whole multiple of dt = {}, found {} ({ratio} steps)",
                    self.dt.get(),
                    self.frame_dt.get()
                ),
            );
        }
        if self.frame_dt.get() > self.duration.get() {
            return err(
                "duration",
                "expected a duration of at least one frame_dt".into(),
            );
        }
        // Runs and frames are numbered in 32 bits in the log.
        if self.runs.0 > u64::from(u32::MAX) {
            return err(
                "runs",
                format!("expected at most {} runs, found {}", u32::MAX, self.runs.0),
            );
        }
        if self.duration.get() / self.frame_dt.get() >= f64::from(u32::MAX) {
            return err(
                "duration",
                format!(
                    "expected fewer than {} frames per run, found duration / frame_dt = {:.3e}",
                    u32::MAX,
                    self.duration.get() / self.frame_dt.get()
                ),
            );
        }
        let arena = self.arena_radius.expect("resolved");
        if !(arena >= 0.0 && arena.is_finite()) {
            return err(
                "arena_radius",
                format!("expected a radius ≥ 0 (0: no wall), found {arena}"),
            );
        }
        for (field, value) in [
            ("initial_height", self.initial_height),
            ("initial_speed", self.initial_speed),
            ("initial_spin", self.initial_spin),
            ("hinge_damping", self.hinge_damping),
            ("contact.damping", Some(self.contact.damping)),
            ("contact.friction", Some(self.contact.friction)),
        ] {
            let v = value.expect("resolved");
            let ok = v.is_finite() && (field == "initial_height" || v >= 0.0);
            if !ok {
                return err(field, format!("expected a finite number ≥ 0, found {v}"));
            }
        }
        if self
            .gravity
            .expect("resolved")
            .iter()
            .any(|g| !g.is_finite())
        {
            return err("gravity", "expected three finite numbers".into());
        }
        if self.kind == SceneKind::Urdf {
            return self.validate_robot();
        }
        self.validate_plant()?;
        // Damping is integrated explicitly: b·dt must stay below the smallest
        // rotational inertia of a link, or the hinge's rate overshoots.
        let damping = self.added_damping();
        let model = self.plant_model();
        let smallest = model
            .links
            .iter()
            .map(|l| l.inertia_com.symmetric_eigenvalues().min())
            .fold(f64::INFINITY, f64::min);
        let limit = smallest / self.dt.get();
        if damping > limit {
            // The scene as written passed: what fails is the plant's.
            let (field, whose) = match self.plant {
                Some(_) => (
                    "plant",
                    "the damping with the plant (its friction and masses)",
                ),
                None => ("hinge_damping", "the damping"),
            };
            return err(
                field,
                format!(
                    "{whose}: expected at most {limit:.3} N m s/rad with dt = {} (the links' \
                     smallest inertia is {smallest:.2e} kg m²), found {damping}; lower it or dt",
                    self.dt.get()
                ),
            );
        }
        self.controller
            .as_ref()
            .expect("resolved")
            .validate(&vec![3; n - 1])
            .map_err(|(field, message)| (format!("controller.{field}"), message))
    }

    /// The checks of a `urdf` scene: its description read, its named links
    /// there, its controller's amplitudes one per joint, and every joint's
    /// damping within what explicit integration resolves.
    fn validate_robot(&self) -> Result<(), SceneError> {
        let robot = self.robot().ok_or_else(|| {
            (
                "file".to_string(),
                "the robot description was not read (expected file = \"….urdf\")".to_string(),
            )
        })?;
        for (field, names) in [
            ("contact_links", self.contact_links.as_deref()),
            ("link_velocities", self.link_velocities.as_deref()),
        ] {
            for name in names.unwrap_or_default() {
                let Some(frame) = robot.frame(name) else {
                    return Err((field.into(), no_link(&robot, name)));
                };
                if field == "link_velocities" && robot.links[frame.body] != *name {
                    return Err((
                        field.into(),
                        format!(
                            "link `{name}` is fixed to `{}`, which moves with it; name the body's \
                             head, `{}`",
                            robot.links[frame.body], robot.links[frame.body]
                        ),
                    ));
                }
            }
        }
        let watched = self.link_velocities.as_deref().unwrap_or_default();
        if let Some(twice) = watched
            .iter()
            .enumerate()
            .find(|(k, n)| watched[..*k].contains(n))
        {
            return Err((
                "link_velocities".into(),
                format!("link `{}` is named twice", twice.1),
            ));
        }
        if self.base == Some(Base::Free) && watched.contains(&robot.links[0]) {
            return Err((
                "link_velocities".into(),
                format!(
                    "`{}` is the free base, whose v and ω are variables already",
                    robot.links[0]
                ),
            ));
        }
        self.validate_plant()?;
        let dt = self.dt.get();
        let added = self.added_damping();
        // Every joint whose damping explicit integration cannot resolve at
        // this dt, so that one edit of dt settles them all: (joint,
        // damping, the smaller of its link's own inertia about the axis and
        // its effective inertia with the robot at rest, on which the
        // simulator sizes its limits too). The implicit integrator resolves
        // any damping.
        let explicit = self.integrator != Integrator::Implicit;
        let model = self.plant_model();
        let inertias = effective_inertias(&model, &State::rest(&model, Vector3::zeros()));
        let limiting: Vec<(&str, f64, f64)> = inertias
            .iter()
            .enumerate()
            .filter_map(|(i, effective)| {
                let damping = robot.specs[i].damping + added;
                let inertia = model.links[i].axis_inertia().min((*effective)?);
                Some((robot.joints[i].as_str(), damping, inertia))
            })
            .filter(|&(_, damping, inertia)| explicit && damping * dt > inertia)
            .collect();
        if !limiting.is_empty() {
            let (field, whose) = match self.plant {
                Some(_) => ("plant", "the plant's damping"),
                None => ("dt", "damping"),
            };
            let each: Vec<String> = limiting
                .iter()
                .map(|(joint, damping, inertia)| {
                    format!(
                        "`{joint}` (damping {damping} on {inertia:.3e} kg m²: dt ≤ {:.2e})",
                        down_to_3_digits(inertia / damping)
                    )
                })
                .collect();
            let bound = limiting
                .iter()
                .map(|(_, damping, inertia)| inertia / damping)
                .fold(f64::INFINITY, f64::min);
            return Err((
                field.into(),
                format!(
                    "{whose} with dt = {dt} is more than explicit integration resolves on {} \
                     joint{} (each on the smaller of its link's own inertia about the axis and \
                     its effective inertia, the rest of the robot free to move, at rest): {}; \
                     {}",
                    limiting.len(),
                    if limiting.len() == 1 { "" } else { "s" },
                    each.join(", "),
                    match down_to_3_digits(bound) {
                        bound if bound > 0.0 => format!(
                            "expected dt ≤ {bound:.2e}, which holds for all of them, or \
                             `integrator = \"implicit\"`, which takes damping implicitly"
                        ),
                        _ => "no dt resolves a damped joint that moves no inertia: lower its \
                              damping, or set `integrator = \"implicit\"`"
                            .to_string(),
                    }
                ),
            ));
        }
        let dofs: Vec<usize> = robot.model.links[1..]
            .iter()
            .map(|l| l.joint.dof())
            .collect();
        if dofs.is_empty() && self.base != Some(Base::Free) {
            return Err((
                "base".into(),
                format!(
                    "robot `{}` has no joint that moves (every link is fixed to `{}`) and its \
                     base is welded: nothing would move and there would be nothing to learn; \
                     set `base = \"free\"` for a body that flies or falls",
                    robot.name, robot.links[0]
                ),
            ));
        }
        self.controller
            .as_ref()
            .expect("resolved")
            .validate(&dofs)
            .map_err(|(field, message)| (format!("controller.{field}"), message))?;
        // The log's fields are the names as `field_name` makes them: two
        // names of the robot must not become one.
        let layout = crate::Prepared::new(self).layout;
        let mut fields = std::collections::BTreeMap::new();
        for name in layout.state.iter().chain(&layout.variables) {
            let field = alnlab_core::state::field_name(name);
            if let Some(other) = fields.insert(field.clone(), name) {
                return Err((
                    "file".into(),
                    format!(
                        "`{other}` and `{name}` would both be the log's field `{field}` (names \
                         are lower-cased, other characters than letters and digits become \
                         `_`, runs of `_` one and none at either end); rename a link or joint"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Integration steps per logged frame.
    pub fn steps_per_frame(&self) -> u64 {
        (self.frame_dt.get() / self.dt.get()).round() as u64
    }

    /// Integration steps a frame of the nominal model: `nominal_steps`, or
    /// the scene's own.
    pub fn nominal_steps_per_frame(&self) -> u64 {
        self.nominal_steps
            .map_or_else(|| self.steps_per_frame(), |k| k.0)
    }

    /// The integration step (s) of `steps` steps a frame: the one place a
    /// stepper at another rate than the scene's (the nominal model, the
    /// planner's simulator@k) derives its `dt`.
    pub fn step_dt(&self, steps: u64) -> f64 {
        self.frame_dt.get() / steps as f64
    }

    /// Logged frames per run (the initial state included).
    pub fn frames_per_run(&self) -> u64 {
        (self.duration.get() / self.frame_dt.get() + 1e-9).floor() as u64 + 1
    }

    /// The link tree.
    pub fn model(&self) -> Model {
        if self.kind == SceneKind::Urdf {
            return self
                .robot()
                .expect("a validated urdf scene has its description")
                .model;
        }
        let n = self.links_n();
        let (length, radius) = (
            self.link_length.expect("resolved").get(),
            self.link_radius.expect("resolved").get(),
        );
        let shape = match self.kind {
            SceneKind::Tumbler => Shape::Box([length, 2.0 * radius, radius]),
            _ => Shape::Capsule { length, radius },
        };
        let root = if self.kind == SceneKind::Pendulum {
            Root::Pinned
        } else {
            Root::Free
        };
        let mass = self.link_mass.expect("resolved").get();
        Model::chain(
            root,
            &vec![(shape, mass); n],
            Vector3::from(self.gravity.expect("resolved")),
        )
    }

    /// The floor and wall, if any.
    pub fn surfaces(&self) -> Surfaces {
        let arena = self.arena_radius.expect("resolved");
        Surfaces {
            floor: self.floor.expect("resolved"),
            arena_radius: (arena > 0.0).then_some(arena),
            // The plant's contact law where it has one of its own.
            params: self
                .plant
                .as_ref()
                .and_then(|p| p.contact.clone())
                .unwrap_or_else(|| self.contact.clone()),
            dt: self.dt.get(),
            point_radius: match self.kind {
                SceneKind::Tumbler => 0.0,
                SceneKind::Urdf => self.link_radius.expect("resolved").get(),
                _ => self.link_radius.expect("resolved").get(),
            },
        }
    }

    /// The controller parameters.
    pub fn controller(&self) -> &ControllerParams {
        self.controller.as_ref().expect("resolved")
    }

    /// The seeded initial state of one run: the root at the initial height
    /// (for a worm: anywhere in the inner half of the arena, turned about the
    /// vertical), every hinge slightly bent, random velocities within the
    /// initial speed and spin.
    pub fn initial_state(&self, model: &Model, rng: &mut ChaCha8Rng) -> State {
        let mut uniform = |scale: f64| {
            Vector3::new(
                rng.random_range(-1.0..=1.0),
                rng.random_range(-1.0..=1.0),
                rng.random_range(-1.0..=1.0),
            ) * scale
        };
        let mut state = State::rest(model, Vector3::zeros());
        let height = self.initial_height.expect("resolved");
        let spin = self.initial_spin.expect("resolved");
        match self.kind {
            SceneKind::Worm => {
                let r = self.arena_radius.expect("resolved") / 2.0;
                let place = uniform(r);
                state.root_p = Vector3::new(place.x, place.y, height);
                let yaw = uniform(std::f64::consts::PI).z;
                state.orient[0] = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
                for q in state.orient.iter_mut().skip(1) {
                    *q = UnitQuaternion::from_scaled_axis(uniform(0.3));
                }
            }
            SceneKind::Chain | SceneKind::Tumbler => {
                state.root_p = Vector3::new(0.0, 0.0, height);
                for q in state.orient.iter_mut() {
                    *q = UnitQuaternion::from_scaled_axis(uniform(std::f64::consts::PI));
                }
            }
            SceneKind::Urdf => {
                state.root_p = Vector3::new(0.0, 0.0, height);
                let robot = self
                    .robot()
                    .expect("a validated urdf scene has its description");
                for (i, link) in model.links.iter().enumerate().skip(1) {
                    let (low, high) = match (robot.specs[i].range, link.joint) {
                        (Some(range), _) => range,
                        (None, Joint::Revolute { .. }) => {
                            (-std::f64::consts::PI, std::f64::consts::PI)
                        }
                        (None, _) => (0.0, 0.0),
                    };
                    // A wide revolute range is narrowed to one turn about 0,
                    // unless that leaves nothing of it.
                    let pi = std::f64::consts::PI;
                    let (low, high) = match link.joint {
                        Joint::Revolute { .. } if low.max(-pi) < high.min(pi) => {
                            (low.max(-pi), high.min(pi))
                        }
                        _ => (low, high),
                    };
                    let u = (uniform(1.0).x + 1.0) / 2.0;
                    state.q[i] = low + (high - low) * u;
                    state.qd[i] = uniform(spin).x;
                    if let Some(v) = robot.specs[i].velocity.filter(|_| self.velocity_limits) {
                        state.qd[i] = state.qd[i].clamp(-v, v);
                    }
                }
                if model.root == Root::Free {
                    state.rates[0] = uniform(spin);
                    state.root_v = uniform(self.initial_speed.expect("resolved"));
                }
                model.impose_couplings(&mut state);
                return state;
            }
            SceneKind::Pendulum => {
                state.root_p = Vector3::new(0.0, 0.0, height);
                // Hanging down (link x along −z), swung out a little.
                let down = UnitQuaternion::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0);
                state.orient[0] = down * UnitQuaternion::from_scaled_axis(uniform(0.6));
                for q in state.orient.iter_mut().skip(1) {
                    *q = UnitQuaternion::from_scaled_axis(uniform(0.4));
                }
            }
        }
        for w in state.rates.iter_mut() {
            *w = uniform(spin);
        }
        if model.root == Root::Free {
            let mut v = uniform(self.initial_speed.expect("resolved"));
            if self.kind == SceneKind::Worm {
                v.z = v.z.abs();
            }
            state.root_v = state.orient[0].inverse() * v;
        }
        state
    }
}

/// The seed of one run, mixed from the experiment seed, scene and run so that
/// runs are independent and reproducible.
pub fn run_seed(seed: u64, scene_index: usize, run: u32) -> u64 {
    alnlab_core::hash::mix_seed(seed, ((scene_index as u64) << 32) | u64::from(run))
}

/// A generator seeded for one run.
pub fn run_rng(seed: u64, scene_index: usize, run: u32) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(run_seed(seed, scene_index, run))
}

/// `x` (positive) rounded down to three significant digits: a bound shown
/// to a user that, typed back, still holds.
fn down_to_3_digits(x: f64) -> f64 {
    if !(x.is_normal() && x > 0.0) {
        return x;
    }
    let scale = 10f64.powi(2 - x.log10().floor() as i32);
    (x * scale).floor() / scale
}
