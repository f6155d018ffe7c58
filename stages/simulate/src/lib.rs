//! The simulate stage (paper §2, §4.1–4.2; DESIGN.md §3): runs the scenes of
//! a manifest and writes
//! - `trajectory.mcap`: one `/state` message per logged frame (see
//!   [`alnlab_common::state_log`]) holding the generalized state and the
//!   paper's variables; `/tf` and `/scene` in Foxglove's schemas at the
//!   viewing rate; per scene an `alnlab.model` metadata record (the model)
//!   and an `alnlab.scene` record (what re-simulates it, see [`replay`]);
//! - `stats.parquet`: min, max, mean, std and n per variable over all runs of
//!   all scenes (paper §4.2).
//!
//! Dynamics: [`dynamics`] (articulated-body algorithm), [`integrate`]
//! (semi-implicit Euler, RK4), [`contact`] (floor and arena wall),
//! [`controller`] (hinge torques), [`scene`] (what a manifest describes).

pub mod bench;
pub mod contact;
pub mod controller;
pub mod dynamics;
mod foxglove;
pub mod integrate;
pub mod model;
#[cfg(test)]
mod reference;
pub mod replay;
pub mod scene;
pub mod spatial;
mod stats;
#[cfg(test)]
mod tests;
pub mod variables;

use std::path::Path;

use alnlab_common::params::{self, ParamError, Positive};
use alnlab_common::state_log::{StateFrame, StateLayout, StateLogWriter};
use alnlab_common::{Error, Progress, Provenance, Result};
use nalgebra::{Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::contact::{ContactPoint, Surfaces, contact_points};
use crate::controller::{Controller, ControllerKind};
use crate::dynamics::{Kinematics, State};
use crate::integrate::{Evaluation, Forces, Stepper};
use crate::model::{Model, Root};
use crate::variables::VariableSet;

pub use crate::scene::{Scene, SceneKind};

/// Version of what this stage writes; part of every cache key, bumped when the
/// same parameters would produce different bytes.
pub const FORMAT_VERSION: u32 = 4;

/// File name of the trajectory log.
pub const TRAJECTORY_FILE: &str = "trajectory.mcap";
/// File name of the statistics table.
pub const STATS_FILE: &str = "stats.parquet";
/// Name of the metadata records holding each scene's model.
pub const MODEL_RECORD: &str = "alnlab.model";
/// Name of the metadata records holding what re-simulates each scene: its
/// resolved parameters, its index and the experiment seed ([`replay`]).
pub const SCENE_RECORD: &str = "alnlab.scene";

/// The `[simulate]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The scenes (`[[simulate.scene]]`).
    #[serde(default = "default_scenes")]
    pub scene: Vec<Scene>,
    /// Rate of the `/tf` viewing channel (Hz); rounded to whole frames.
    #[serde(default = "default_view_rate")]
    pub view_rate: Positive,
}

fn default_scenes() -> Vec<Scene> {
    vec![Scene::default().resolve()]
}

fn default_view_rate() -> Positive {
    Positive(50.0)
}

impl Default for Params {
    fn default() -> Self {
        Params {
            scene: default_scenes(),
            view_rate: default_view_rate(),
        }
    }
}

/// The numerical integrator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Velocities first, then positions with the new velocities.
    #[default]
    SemiImplicitEuler,
    /// Classical fourth-order Runge–Kutta.
    Rk4,
}

impl Params {
    /// Fills every scene's kind defaults (so the resolved manifest shows them).
    pub fn resolve(mut self) -> Params {
        self.scene = self.scene.into_iter().map(Scene::resolve).collect();
        self
    }

    /// Checks what deserialization cannot: relations between fields.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        if self.scene.is_empty() {
            return Err((
                "scene".into(),
                "expected at least one [[simulate.scene]]".into(),
            ));
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, scene) in self.scene.iter().enumerate() {
            let at = |field: &str| format!("scene.{i}.{field}");
            let valid_name = !scene.name.is_empty()
                && scene
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
            if !valid_name {
                return Err((
                    at("name"),
                    format!(
                        "expected a name of letters, digits, `-` or `_`, found {:?}",
                        scene.name
                    ),
                ));
            }
            if !names.insert(scene.name.as_str()) {
                return Err((
                    at("name"),
                    format!("scene name {:?} is used twice", scene.name),
                ));
            }
            scene
                .clone()
                .resolve()
                .validate()
                .map_err(|(field, message)| (at(&field), message))?;
        }
        Ok(())
    }
}

/// Everything needed to simulate one scene, built once.
pub struct Prepared {
    pub scene: Scene,
    pub model: Model,
    pub surfaces: Surfaces,
    pub points: Vec<ContactPoint>,
    pub variables: VariableSet,
    pub layout: StateLayout,
}

impl Prepared {
    /// Builds the model and variable set of a (resolved) scene.
    pub fn new(scene: &Scene) -> Prepared {
        let scene = scene.clone().resolve();
        let model = scene.model();
        let surfaces = scene.surfaces();
        let points = if surfaces.any() {
            contact_points(&model)
        } else {
            Vec::new()
        };
        let controlled = scene.controller().kind != ControllerKind::None;
        let variables = VariableSet::of(&model, surfaces.any().then_some(&points[..]), controlled);
        let layout = StateLayout {
            scene: scene.name.clone(),
            state: state_names(&model),
            variables: variables.names(),
        };
        Prepared {
            scene,
            model,
            surfaces,
            points,
            variables,
            layout,
        }
    }
}

/// Names of the generalized-state components in the log, in the order of
/// [`generalized_state`]: root hinge position (inertial) and, for a free root,
/// velocity (root frame); then per link its orientation quaternion `q.<i>`
/// (x, y, z, w; the root's to the inertial frame, others to the parent) and
/// its angular rate `w.<i>` (the root's ω, or the hinge's relative rate).
pub fn state_names(model: &Model) -> Vec<String> {
    let mut names: Vec<String> = ["x", "y", "z"]
        .iter()
        .map(|a| format!("root.p.{a}"))
        .collect();
    if model.root == Root::Free {
        names.extend(["x", "y", "z"].iter().map(|a| format!("root.v.{a}")));
    }
    for i in 1..=model.len() {
        names.extend(["x", "y", "z", "w"].iter().map(|a| format!("q.{i}.{a}")));
        names.extend(["x", "y", "z"].iter().map(|a| format!("w.{i}.{a}")));
    }
    names
}

/// The generalized state as logged (see [`state_names`]).
pub fn generalized_state(model: &Model, state: &State, out: &mut Vec<f64>) {
    out.clear();
    out.extend(state.root_p.iter());
    if model.root == Root::Free {
        out.extend(state.root_v.iter());
    }
    for (q, w) in state.orient.iter().zip(&state.rates) {
        out.extend([q.i, q.j, q.k, q.w]);
        out.extend(w.iter());
    }
}

/// The state a logged generalized state stands for (the inverse of
/// [`generalized_state`]); `None` if `values` has the wrong length.
pub fn state_from_generalized(model: &Model, values: &[f64]) -> Option<State> {
    let free = model.root == Root::Free;
    let expected = if free { 6 } else { 3 } + 7 * model.len();
    if values.len() != expected {
        return None;
    }
    let mut state = State::rest(model, Vector3::new(values[0], values[1], values[2]));
    let mut at = 3;
    if free {
        state.root_v = Vector3::new(values[3], values[4], values[5]);
        at = 6;
    }
    for (q, w) in state.orient.iter_mut().zip(state.rates.iter_mut()) {
        let v = &values[at..at + 7];
        *q = nalgebra::Unit::new_unchecked(nalgebra::Quaternion::new(v[3], v[0], v[1], v[2]));
        *w = Vector3::new(v[4], v[5], v[6]);
        at += 7;
    }
    Some(state)
}

/// The forces of a scene at one instant: control torques (held over a step)
/// and contacts.
pub struct SceneForces<'a> {
    /// The surfaces to touch.
    pub surfaces: &'a Surfaces,
    /// The contact points.
    pub points: &'a [ContactPoint],
    /// Control torque g of each link on its parent (index 0 unused).
    pub g: Vec<Vector3<f64>>,
    /// Viscous damping at every hinge (N m s/rad).
    pub hinge_damping: f64,
}

impl Forces for SceneForces<'_> {
    fn apply(
        &mut self,
        model: &Model,
        state: &State,
        kin: &Kinematics,
        tau: &mut [Vector3<f64>],
        f_ext: &mut [Vector6<f64>],
    ) {
        for ((t, g), w) in tau.iter_mut().zip(&self.g).zip(&state.rates) {
            *t = -g - w * self.hinge_damping;
        }
        if model.root == Root::Pinned {
            tau[0] = Vector3::zeros();
        }
        f_ext.fill(Vector6::zeros());
        if !self.points.is_empty() {
            self.surfaces.apply(model, self.points, kin, f_ext);
        }
    }
}

/// Values beyond this magnitude count as a blow-up even while finite.
const DIVERGED: f64 = 1e9;

/// Runs every scene of `params` and writes `trajectory.mcap` and
/// `stats.parquet` into `out_dir`. The result depends only on `params` and
/// `seed`.
pub fn run(
    params: &Params,
    seed: u64,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    params
        .validate()
        .map_err(|e| params::invalid("simulate", e))?;
    let prepared: Vec<Prepared> = params.scene.iter().map(Prepared::new).collect();
    let layouts: Vec<StateLayout> = prepared.iter().map(|p| p.layout.clone()).collect();
    let total_steps: u64 = prepared
        .iter()
        .map(|p| p.scene.runs.0 * (p.scene.frames_per_run() - 1) * p.scene.steps_per_frame())
        .sum();
    progress.start("simulate", total_steps, "steps");

    let mut log = StateLogWriter::create(&out_dir.join(TRAJECTORY_FILE), &layouts)?;
    let tf = log.add_json_channel(
        foxglove::TF_TOPIC,
        foxglove::TF_SCHEMA,
        &foxglove::tf_schema(),
    )?;
    let scene_channel = log.add_json_channel(
        foxglove::SCENE_TOPIC,
        foxglove::SCENE_SCHEMA,
        &foxglove::scene_schema(),
    )?;
    let mut stats = stats::VariableStats::default();
    let mut log_time_ns = 0u64;
    for (scene_index, p) in prepared.iter().enumerate() {
        log.metadata(MODEL_RECORD, model_record(p))?;
        log.metadata(
            SCENE_RECORD,
            replay::scene_record(&p.scene, scene_index, seed),
        )?;
        let frame_ns = (p.scene.frame_dt.get() * 1e9).round() as u64;
        let view_every = ((1.0 / params.view_rate.get()) / p.scene.frame_dt.get())
            .round()
            .max(1.0) as u32;
        for run in 0..p.scene.runs.0 as u32 {
            log.write_json(
                scene_channel,
                log_time_ns,
                &foxglove::scene_update(&p.scene, &p.model, run, log_time_ns),
            )?;
            simulate_run(p, seed, scene_index, run, |frame, kin| {
                stats.add(&p.layout.variables, &frame.variables);
                log.write(scene_index, log_time_ns, frame)?;
                if frame.frame % view_every == 0 {
                    log.write_json(
                        tf,
                        log_time_ns,
                        &foxglove::transforms(&p.scene.name, run, kin, log_time_ns),
                    )?;
                }
                log_time_ns += frame_ns;
                if frame.frame > 0 {
                    progress.advance(p.scene.steps_per_frame());
                }
                Ok(())
            })?;
        }
    }
    // Stats first: if it fails, no log is renamed into place either.
    stats.write(&out_dir.join(STATS_FILE), provenance)?;
    log.finish(provenance)
}

/// Simulates one run, handing every logged frame (and the kinematics of its
/// state) to `on_frame`. A blow-up (a non-finite or absurdly large value)
/// stops the run with an error naming scene, run, step and variable; no such
/// value ever reaches `on_frame`.
pub fn simulate_run(
    p: &Prepared,
    seed: u64,
    scene_index: usize,
    run: u32,
    mut on_frame: impl FnMut(&StateFrame, &Kinematics) -> Result<()>,
) -> Result<()> {
    let scene = &p.scene;
    let mut rng = scene::run_rng(seed, scene_index, run);
    let mut state = scene.initial_state(&p.model, &mut rng);
    let mut runner = Runner::new(p, seed, scene_index, run);
    let dt = scene.dt.get();
    let steps_per_frame = scene.steps_per_frame();
    let mut frame = StateFrame {
        time: 0.0,
        run,
        frame: 0,
        state: Vec::with_capacity(p.layout.state.len()),
        variables: Vec::with_capacity(p.layout.variables.len()),
    };
    let mut step = 0u64;
    for index in 0..scene.frames_per_run() {
        if index > 0 {
            runner
                .advance(&mut state, step, steps_per_frame, dt)
                .map_err(|at| {
                    let mut v = Vec::new();
                    generalized_state(&p.model, &state, &mut v);
                    blow_up(p, run, at, &p.layout.state, &v)
                })?;
            step += steps_per_frame;
        }
        runner.observe(&state, step as f64 * dt, &mut frame);
        if let Some(err) = check(p, run, step, &frame) {
            return Err(err);
        }
        frame.time = index as f64 * scene.frame_dt.get();
        frame.frame = index as u32;
        on_frame(&frame, &runner.eval.kin)?;
    }
    Ok(())
}

/// The moving parts of one run of a scene: its controller (seeded by the
/// run), forces, integrator and an evaluation for observing frames.
pub(crate) struct Runner<'a> {
    p: &'a Prepared,
    controller: Controller,
    forces: SceneForces<'a>,
    hinge_torques: Vec<Vector3<f64>>,
    stepper: Stepper,
    eval: Evaluation,
}

impl<'a> Runner<'a> {
    pub(crate) fn new(p: &'a Prepared, seed: u64, scene_index: usize, run: u32) -> Runner<'a> {
        let model = &p.model;
        let hinges = model.len() - 1;
        Runner {
            p,
            controller: Controller::new(
                p.scene.controller(),
                hinges,
                scene::run_seed(seed ^ 0xC0DE, scene_index, run),
            ),
            forces: SceneForces {
                surfaces: &p.surfaces,
                points: &p.points,
                g: vec![Vector3::zeros(); model.len()],
                hinge_damping: p.scene.hinge_damping.expect("resolved"),
            },
            hinge_torques: vec![Vector3::zeros(); hinges],
            stepper: Stepper::new(model),
            eval: Evaluation::new(model),
        }
    }

    /// Takes `steps` steps of `dt`, the first being step number `first` of
    /// the run (at time first·dt; the controller's torques are those of each
    /// step's start). On a non-finite state, the number of the step that
    /// made it.
    pub(crate) fn advance(
        &mut self,
        state: &mut State,
        first: u64,
        steps: u64,
        dt: f64,
    ) -> std::result::Result<(), u64> {
        let (model, scene) = (&self.p.model, &self.p.scene);
        for step in first..first + steps {
            self.controller
                .torques(step as f64 * dt, &mut self.hinge_torques);
            self.forces.g[1..].copy_from_slice(&self.hinge_torques);
            self.stepper
                .step(model, state, dt, scene.integrator, &mut self.forces);
            if !state.is_finite() {
                return Err(step + 1);
            }
        }
        Ok(())
    }

    /// Forgets what the integrator tracked, to step on from another state of
    /// the same run.
    pub(crate) fn restart(&mut self) {
        self.stepper.restart();
    }

    /// The frame of `state` at time `t`: its generalized state and variables.
    pub(crate) fn observe(&mut self, state: &State, t: f64, frame: &mut StateFrame) {
        let p = self.p;
        self.controller.torques(t, &mut self.hinge_torques);
        self.forces.g[1..].copy_from_slice(&self.hinge_torques);
        self.eval.run(&p.model, state, &mut self.forces);
        generalized_state(&p.model, state, &mut frame.state);
        p.variables.values(
            state,
            &self.eval.kin,
            &self.eval.ws.accel,
            &self.forces.g,
            &self.eval.f_ext,
            &mut frame.variables,
        );
    }
}

fn check(p: &Prepared, run: u32, step: u64, frame: &StateFrame) -> Option<Error> {
    let bad = |x: &f64| !x.is_finite() || x.abs() > DIVERGED;
    if frame.state.iter().any(bad) {
        return Some(blow_up(p, run, step, &p.layout.state, &frame.state));
    }
    if frame.variables.iter().any(bad) {
        return Some(blow_up(p, run, step, &p.layout.variables, &frame.variables));
    }
    None
}

fn blow_up(p: &Prepared, run: u32, step: u64, names: &[String], values: &[f64]) -> Error {
    let (name, value) = names
        .iter()
        .zip(values)
        .find(|(_, v)| !v.is_finite() || v.abs() > DIVERGED)
        .map_or(("?", f64::NAN), |(n, v)| (n.as_str(), *v));
    Error::Diverged(format!(
        "scene `{}`, run {run}, step {step}: {name} became {value:e}; the simulation is \
         unstable (try a smaller dt, or softer contacts)",
        p.scene.name
    ))
}

/// The `alnlab.model` metadata record of a scene: the model as JSON.
fn model_record(p: &Prepared) -> std::collections::BTreeMap<String, String> {
    let scene = &p.scene;
    let links: Vec<serde_json::Value> = p
        .model
        .links
        .iter()
        .map(|link| {
            serde_json::json!({
                "parent": link.parent.map_or(-1, |p| p as i64),
                "joint": match (link.parent, p.model.root) {
                    (None, Root::Free) => "free",
                    _ => "ball",
                },
                "mass": link.mass,
                "c": link.c.as_slice(),
                "J": link.inertia_hinge().transpose().as_slice(),
                "l": link.l.as_slice(),
            })
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
    [
        ("scene".to_string(), scene.name.clone()),
        ("json".to_string(), json.to_string()),
    ]
    .into()
}
