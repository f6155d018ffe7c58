//! Running a scene: its model and variables built once ([`Prepared`]), the
//! moving parts of one run ([`Runner`]: controller, forces, integrator) and
//! [`simulate_run`], which steps a run and hands over every frame. What the
//! simulate stage logs and what the test stage re-simulates both come from
//! here.

use alnlab_core::Error;
use alnlab_core::Result;
use alnlab_core::state::{StateFrame, StateLayout};
use nalgebra::{Vector3, Vector6};

use crate::contact::{ContactPoint, Surfaces, contact_points};
use crate::controller::{Controller, ControllerKind};
use crate::dynamics::{Kinematics, Loads, State, effective_inertias};
use crate::integrate::{Evaluation, Forces, Integrator, Stepper};
use crate::joints::{DrivePiece, JointLaw};
use crate::model::{Model, Root};
use crate::plant::{Actuators, Plant};
use crate::scene::{self, Scene};
use crate::urdf::Robot;
use crate::variables::VariableSet;

/// Everything needed to simulate one scene, built once.
pub struct Prepared {
    pub scene: Scene,
    pub model: Model,
    /// A `urdf` scene's robot (names, joint specs, frames).
    pub robot: Option<Robot>,
    /// Per link, its one-DOF joint's law (`None` for the root and ball
    /// hinges).
    pub laws: Vec<Option<JointLaw>>,
    pub surfaces: Surfaces,
    pub points: Vec<ContactPoint>,
    pub variables: VariableSet,
    pub layout: StateLayout,
}

/// One component of what drives a scene: a torque about one axis of a
/// ball hinge, logged as `g.<link>.x|y|z`, or a robot's one-DOF joint's
/// effort, logged as `tau.<joint>` (in the hinge's x).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Control {
    /// The hinge (link index − 1).
    pub hinge: usize,
    /// The axis it turns (0 for a one-DOF joint).
    pub axis: usize,
    /// The variable that logs it.
    pub name: String,
}

impl Prepared {
    /// What drives the scene, component by component in link order: what
    /// a planner sets and [`Runner::drive`] takes.
    pub fn controls(&self) -> Vec<Control> {
        let mut controls = Vec::new();
        for i in 1..self.model.len() {
            match (self.model.links[i].joint.dof(), &self.robot) {
                // A follower has no drive of its own.
                (1, Some(_)) if self.model.coupling(i).is_some() => {}
                (1, Some(robot)) => controls.push(Control {
                    hinge: i - 1,
                    axis: 0,
                    name: format!("tau.{}", robot.joints[i]),
                }),
                (3, _) => {
                    for (axis, name) in ["x", "y", "z"].iter().enumerate() {
                        controls.push(Control {
                            hinge: i - 1,
                            axis,
                            name: format!("g.{}.{name}", i + 1),
                        });
                    }
                }
                _ => {}
            }
        }
        controls
    }

    /// The same scene with its plant's actuator noise taken out: what a
    /// forward model of the plant predicts, its mean response (a draw of
    /// the noise would be another plant's; a batch steps none).
    pub fn without_noise(&self) -> Prepared {
        let mut scene = self.scene.clone();
        if let Some(plant) = &mut scene.plant {
            plant.torque_noise = 0.0;
        }
        Prepared::new(&scene)
    }

    /// Builds the model and variable set of a (validated) scene.
    pub fn new(scene: &Scene) -> Prepared {
        let scene = scene.clone().resolve();
        let robot = scene.robot();
        let model = scene.plant_model();
        let surfaces = scene.surfaces();
        let controlled = scene.controller().kind != ControllerKind::None;
        let dt = scene.dt.get();
        let (points, variables, laws, labels) = match &robot {
            None => {
                let points = if surfaces.any() {
                    contact_points(&model)
                } else {
                    Vec::new()
                };
                let variables =
                    VariableSet::of(&model, surfaces.any().then_some(&points[..]), controlled);
                let numbered: Vec<String> = (1..=model.len()).map(|i| i.to_string()).collect();
                let laws = vec![None; model.len()];
                (points, variables, laws, (numbered.clone(), numbered))
            }
            Some(robot) => {
                let frame = |name: &String| robot.frame(name).expect("validated");
                let points: Vec<ContactPoint> = scene
                    .contact_links
                    .iter()
                    .flatten()
                    .map(|name| ContactPoint {
                        link: frame(name).body,
                        offset: frame(name).placement.translation.vector,
                    })
                    .collect();
                let watched: Vec<usize> = scene
                    .link_velocities
                    .iter()
                    .flatten()
                    .map(|name| frame(name).body)
                    .collect();
                let variables = VariableSet::of_robot(
                    &model,
                    &robot.links,
                    &robot.joints,
                    &watched,
                    &points,
                    controlled,
                );
                let added = scene.added_damping();
                let friction = scene.plant.as_ref().map(|p| p.coulomb_friction);
                // Sized on each joint's effective inertia with the robot at
                // rest (q = 0): it changes with the pose, which the margin
                // of joints::LIMIT_PERIOD_STEPS absorbs.
                let rest = State::rest(&model, Vector3::zeros());
                let laws = effective_inertias(&model, &rest)
                    .into_iter()
                    .zip(&model.links)
                    .zip(&robot.specs)
                    .map(|((effective, link), spec)| {
                        effective.map(|effective| {
                            let inertias = (link.axis_inertia(), effective);
                            JointLaw::new(
                                inertias,
                                spec,
                                added,
                                friction,
                                scene.velocity_limits,
                                (dt, scene.integrator == Integrator::Implicit),
                            )
                        })
                    })
                    .collect();
                (
                    points,
                    variables,
                    laws,
                    (robot.links.clone(), robot.joints.clone()),
                )
            }
        };
        let applied = scene.logs_applied();
        let layout = StateLayout {
            scene: scene.name.clone(),
            state: state_names(&model, &labels.0, &labels.1, applied),
            variables: variables.names(),
        };
        Prepared {
            scene,
            model,
            robot,
            laws,
            surfaces,
            points,
            variables,
            layout,
        }
    }
}

/// Names of the generalized-state components in the log, in the order of
/// [`generalized_state`]: root hinge position (inertial) and, for a free root,
/// velocity (root frame); then per link (named by `links`) its orientation
/// quaternion `q.<link>` (x, y, z, w; the root's to the inertial frame,
/// others to the parent) and its angular rate `w.<link>` (the root's ω, or
/// the hinge's relative rate) — none for a fixed root — or, for a one-DOF
/// joint (named by `joints`), its position `joint.<joint>.q` and velocity
/// `joint.<joint>.qd`; last, each one-DOF joint's passive effort
/// `joint.<joint>.passive` (damping, friction and limits at that instant,
/// as the step from it applies them — under the implicit integrator with
/// what taking the step implicitly changed, the drive's slope included —,
/// which replay the dynamics; not part of the state)
/// and, where the
/// effort applied differs from the command (`applied`: a plant's actuators,
/// drives holding velocity limits), each one-DOF joint's applied effort
/// `joint.<joint>.applied`.
pub fn state_names(
    model: &Model,
    links: &[String],
    joints: &[String],
    applied: bool,
) -> Vec<String> {
    let mut names: Vec<String> = ["x", "y", "z"]
        .iter()
        .map(|a| format!("root.p.{a}"))
        .collect();
    if model.root == Root::Free {
        names.extend(["x", "y", "z"].iter().map(|a| format!("root.v.{a}")));
    }
    for i in 0..model.len() {
        match logged(model, i) {
            Logged::Nothing => {}
            Logged::Rotation => {
                let l = &links[i];
                names.extend(["x", "y", "z", "w"].iter().map(|a| format!("q.{l}.{a}")));
                names.extend(["x", "y", "z"].iter().map(|a| format!("w.{l}.{a}")));
            }
            Logged::Axis => names.extend(["q", "qd"].map(|x| format!("joint.{}.{x}", joints[i]))),
        }
    }
    names.extend(one_dof(model).map(|i| format!("joint.{}.passive", joints[i])));
    if applied {
        names.extend(one_dof(model).map(|i| format!("joint.{}.applied", joints[i])));
    }
    names
}

/// How to rebuild a logged generalized state (named by [`state_names`])
/// from the scene's `variables`: for each coordinate that changes, its
/// index in the state and the index of the variable that is it — a
/// one-DOF joint's position `joint.<j>.q` is the variable `q.<j>`, its
/// velocity `joint.<j>.qd` is `qd.<j>`. A fixed root's position never
/// changes, and the efforts after the state are not part of it, so they
/// are left as they are. An error names the first coordinate no variable
/// is (a ball hinge's or free root's orientation and rates, a free root's
/// motion): such a state cannot be rebuilt from the variables.
pub fn state_from_variables(
    state: &[String],
    variables: &[String],
) -> std::result::Result<Vec<(usize, usize)>, String> {
    let free_root = state.iter().any(|n| n.starts_with("root.v."));
    let mut filled = Vec::new();
    for (i, name) in state.iter().enumerate() {
        if name.starts_with("root.p.") && !free_root
            || name.ends_with(".passive") && name.starts_with("joint.")
            || name.ends_with(".applied") && name.starts_with("joint.")
        {
            continue;
        }
        let variable = name
            .strip_prefix("joint.")
            .and_then(|rest| {
                let (joint, part) = rest.rsplit_once('.')?;
                matches!(part, "q" | "qd").then(|| format!("{part}.{joint}"))
            })
            .and_then(|v| variables.iter().position(|n| *n == v));
        match variable {
            Some(v) => filled.push((i, v)),
            None => return Err(format!("the state's `{name}` is no logged variable")),
        }
    }
    Ok(filled)
}

/// What the logged state holds of a link.
#[derive(Clone, Copy)]
enum Logged {
    /// Nothing: a welded root.
    Nothing,
    /// Its orientation quaternion and angular rate (7 numbers): the root,
    /// a ball hinge.
    Rotation,
    /// Its one-DOF joint's position and velocity (2 numbers).
    Axis,
}

fn logged(model: &Model, i: usize) -> Logged {
    match (i, model.root, model.links[i].joint.dof()) {
        (0, Root::Fixed, _) => Logged::Nothing,
        (0, _, _) | (_, _, 3) => Logged::Rotation,
        _ => Logged::Axis,
    }
}

/// The links below the root with a one-DOF joint.
fn one_dof(model: &Model) -> impl Iterator<Item = usize> + '_ {
    (1..model.len()).filter(|&i| model.links[i].joint.dof() == 1)
}

/// The generalized state as logged (see [`state_names`]), without the
/// passive efforts, which the caller appends.
pub fn generalized_state(model: &Model, state: &State, out: &mut Vec<f64>) {
    out.clear();
    out.extend(state.root_p.iter());
    if model.root == Root::Free {
        out.extend(state.root_v.iter());
    }
    for i in 0..model.len() {
        match logged(model, i) {
            Logged::Nothing => {}
            Logged::Rotation => {
                let (q, w) = (&state.orient[i], &state.rates[i]);
                out.extend([q.i, q.j, q.k, q.w]);
                out.extend(w.iter());
            }
            Logged::Axis => out.extend([state.q[i], state.qd[i]]),
        }
    }
}

/// The state a logged generalized state stands for (the inverse of
/// [`generalized_state`], passive and applied efforts ignored); `None` if `values` has
/// the wrong length.
pub fn state_from_generalized(model: &Model, values: &[f64]) -> Option<State> {
    let free = model.root == Root::Free;
    let mut expected = if free { 6 } else { 3 };
    for i in 0..model.len() {
        expected += match logged(model, i) {
            Logged::Nothing => 0,
            Logged::Rotation => 7,
            Logged::Axis => 2,
        };
    }
    // Passive efforts follow the state, and applied ones where the scene
    // logs them.
    let efforts = one_dof(model).count();
    if values.len() != expected + efforts && values.len() != expected + 2 * efforts {
        return None;
    }
    let mut state = State::rest(model, Vector3::new(values[0], values[1], values[2]));
    let mut at = 3;
    if free {
        state.root_v = Vector3::new(values[3], values[4], values[5]);
        at = 6;
    }
    for i in 0..model.len() {
        match logged(model, i) {
            Logged::Nothing => {}
            Logged::Rotation => {
                let v = &values[at..at + 7];
                state.orient[i] = nalgebra::Unit::new_unchecked(nalgebra::Quaternion::new(
                    v[3], v[0], v[1], v[2],
                ));
                state.rates[i] = Vector3::new(v[4], v[5], v[6]);
                at += 7;
            }
            Logged::Axis => {
                (state.q[i], state.qd[i]) = (values[at], values[at + 1]);
                at += 2;
            }
        }
    }
    // A follower's logged values may be off its coupling (a sensor's
    // noise): the state is its leader's.
    model.impose_couplings(&mut state);
    Some(state)
}

/// The forces of a scene at one instant: control torques (held over a step),
/// a robot's joint laws, and contacts.
pub struct SceneForces<'a> {
    /// The surfaces to touch.
    pub surfaces: &'a Surfaces,
    /// The contact points.
    pub points: &'a [ContactPoint],
    /// Control torque g of each link on its parent (index 0 unused); a
    /// one-DOF joint's effort is its x, already clamped to its limit.
    pub g: Vec<Vector3<f64>>,
    /// Viscous damping at every ball hinge (N m s/rad).
    pub hinge_damping: f64,
    /// Per link, its one-DOF joint's law.
    pub laws: &'a [Option<JointLaw>],
    /// Per link, the passive effort of the last evaluation.
    pub passive: Vec<f64>,
    /// Where the plant's actuators produce other than the command: what
    /// each link's actuator produces (index 0 unused; a one-DOF joint's
    /// clamped to its effort limit when applied), set by the runner.
    pub actuated: Option<Vec<Vector3<f64>>>,
    /// Per link, the effort its one-DOF joint's actuator applied in the last
    /// evaluation (at the state evaluated: an implicit step's change is
    /// apart, see [`SceneForces::drive`]).
    pub applied: Vec<f64>,
    /// Per link, the command to its one-DOF joint's drive in the last
    /// evaluation, within the effort limit.
    pub commanded: Vec<f64>,
    /// Per link, the piece of its one-DOF joint's drive the last evaluation
    /// took (an implicit step's, the one holding at the step's end).
    pub drive: Vec<DrivePiece>,
    /// The controller's torque limit, which caps a ball hinge's actuator too.
    pub torque_limit: f64,
}

impl<'a> SceneForces<'a> {
    /// The forces of scene `p` with no control torques yet.
    pub fn new(p: &'a Prepared) -> SceneForces<'a> {
        SceneForces {
            surfaces: &p.surfaces,
            points: &p.points,
            g: vec![Vector3::zeros(); p.model.len()],
            hinge_damping: p.scene.added_damping(),
            laws: &p.laws,
            passive: vec![0.0; p.model.len()],
            actuated: p
                .scene
                .plant
                .as_ref()
                .is_some_and(Plant::has_actuators)
                .then(|| vec![Vector3::zeros(); p.model.len()]),
            applied: vec![0.0; p.model.len()],
            commanded: vec![0.0; p.model.len()],
            drive: vec![DrivePiece::default(); p.model.len()],
            torque_limit: p.scene.controller().torque_limit.get(),
        }
    }
}

impl Forces for SceneForces<'_> {
    fn apply(&mut self, model: &Model, state: &State, kin: &Kinematics, loads: &mut Loads) {
        match &self.actuated {
            // What the actuators produce, capped by the torque limit as the
            // command is (a one-DOF joint's by its effort limit, below).
            Some(actuated) => {
                let limit = self.torque_limit;
                for ((t, a), w) in loads.tau.iter_mut().zip(actuated).zip(&state.rates) {
                    *t = -a.map(|x| x.clamp(-limit, limit)) - w * self.hinge_damping;
                }
            }
            None => {
                for ((t, g), w) in loads.tau.iter_mut().zip(&self.g).zip(&state.rates) {
                    *t = -g - w * self.hinge_damping;
                }
            }
        }
        if model.root == Root::Pinned {
            loads.tau[0] = Vector3::zeros();
        }
        loads.effort.fill(0.0);
        loads.effort_damping.fill(0.0);
        loads.effort_stiffness.fill(0.0);
        for (i, law) in self.laws.iter().enumerate() {
            if let Some(law) = law {
                self.passive[i] = law.passive(state.q[i], state.qd[i]);
                (loads.effort_damping[i], loads.effort_stiffness[i]) =
                    law.slopes(state.q[i], state.qd[i]);
                let commanded = match &self.actuated {
                    Some(actuated) => law.clamp(actuated[i].x),
                    None => self.g[i].x,
                };
                let drive = law.drive_piece(commanded, state.qd[i]);
                loads.effort_damping[i] += drive.slope;
                (self.commanded[i], self.drive[i]) = (commanded, drive);
                self.applied[i] = drive.at(state.qd[i]);
                loads.effort[i] = self.applied[i] + self.passive[i];
            }
        }
        loads.f_ext.fill(Vector6::zeros());
        if !self.points.is_empty() {
            self.surfaces
                .apply(model, self.points, kin, &mut loads.f_ext);
        }
    }

    /// A drive holding a velocity limit is piecewise affine in the velocity:
    /// each joint's piece moves to the one holding at the step's end.
    fn refine(&mut self, state: &State, qdd: &[f64], h: f64, loads: &mut Loads) -> bool {
        let mut moved = false;
        for (i, law) in self.laws.iter().enumerate() {
            let Some(law) = law.filter(|l| l.velocity.is_finite()) else {
                continue;
            };
            let qd = state.qd[i];
            let now = self.drive[i];
            let end = law.drive_toward(self.commanded[i], now, qd + h * qdd[i]);
            if end != now {
                loads.effort[i] += end.at(qd) - now.at(qd);
                loads.effort_damping[i] += end.slope - now.slope;
                self.applied[i] = end.at(qd);
                self.drive[i] = end;
                moved = true;
            }
        }
        moved
    }
}

/// Values beyond this magnitude count as a blow-up even while finite.
const DIVERGED: f64 = 1e9;

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
    let mut sensors = Sensors::new(p, seed, scene_index, run);
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
        if let Some(sensors) = &mut sensors {
            sensors.read(&mut frame);
        }
        frame.time = index as f64 * scene.frame_dt.get();
        frame.frame = index as u32;
        on_frame(&frame, &runner.eval.kin)?;
    }
    Ok(())
}

/// A plant's joint sensors in one run: the logged joint positions and
/// velocities (in the state and as variables) made what noisy sensors
/// report.
struct Sensors {
    /// (index in the state, index among the variables if one, its noise).
    read: Vec<(usize, Option<usize>, f64)>,
    rng: rand_chacha::ChaCha8Rng,
}

impl Sensors {
    /// The sensors of `p`'s plant, if it has noisy ones, seeded by the run.
    fn new(p: &Prepared, seed: u64, scene_index: usize, run: u32) -> Option<Sensors> {
        use rand::SeedableRng;
        let noise = p.scene.plant.as_ref()?.sensors()?;
        let robot = p.robot.as_ref()?;
        let at = |names: &[String], name: &str| names.iter().position(|n| n == name);
        let mut read = Vec::new();
        for i in one_dof(&p.model) {
            let joint = &robot.joints[i];
            for (suffix, variable, sigma) in
                [("q", "q", noise.position), ("qd", "qd", noise.velocity)]
            {
                let state = at(&p.layout.state, &format!("joint.{joint}.{suffix}"))
                    .expect("every one-DOF joint's q and qd are logged");
                if sigma > 0.0 {
                    let variable = at(&p.layout.variables, &format!("{variable}.{joint}"));
                    read.push((state, variable, sigma));
                }
            }
        }
        Some(Sensors {
            read,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(scene::run_seed(
                seed ^ 0x5E45,
                scene_index,
                run,
            )),
        })
    }

    /// Adds each sensor's noise to what `frame` logs of its joint.
    fn read(&mut self, frame: &mut StateFrame) {
        use rand_distr::Distribution;
        for &(state, variable, sigma) in &self.read {
            let z: f64 = rand_distr::StandardNormal.sample(&mut self.rng);
            let measured = frame.state[state] + sigma * z;
            frame.state[state] = measured;
            if let Some(v) = variable {
                frame.variables[v] = measured;
            }
        }
    }
}

/// The moving parts of one run of a scene: its controller (seeded by the
/// run), forces, integrator and an evaluation for observing frames.
pub struct Runner<'a> {
    p: &'a Prepared,
    controller: Controller,
    /// Torques set from outside (a planner's), standing in for the
    /// controller's while set.
    driven: Option<Vec<Vector3<f64>>>,
    forces: SceneForces<'a>,
    hinge_torques: Vec<Vector3<f64>>,
    /// The plant's actuators, where they produce other than the command.
    actuators: Option<Actuators>,
    stepper: Stepper,
    eval: Evaluation,
}

impl<'a> Runner<'a> {
    pub fn new(p: &'a Prepared, seed: u64, scene_index: usize, run: u32) -> Runner<'a> {
        let model = &p.model;
        let hinges = model.len() - 1;
        Runner {
            p,
            controller: Controller::new(
                p.scene.controller(),
                hinges,
                scene::run_seed(seed ^ 0xC0DE, scene_index, run),
            ),
            driven: None,
            forces: SceneForces::new(p),
            hinge_torques: vec![Vector3::zeros(); hinges],
            actuators: p
                .scene
                .plant
                .as_ref()
                .filter(|plant| plant.has_actuators())
                .map(|plant| {
                    Actuators::new(
                        plant,
                        hinges,
                        p.scene.dt.get(),
                        p.scene.steps_per_frame(),
                        scene::run_seed(seed ^ 0xAC7, scene_index, run),
                    )
                }),
            stepper: Stepper::new(model),
            eval: Evaluation::new(model),
        }
    }

    /// Takes `steps` steps of `dt`, the first being step number `first` of
    /// the run (at time first·dt; the controller's torques are those of each
    /// step's start). On a non-finite state, the number of the step that
    /// made it.
    pub fn advance(
        &mut self,
        state: &mut State,
        first: u64,
        steps: u64,
        dt: f64,
    ) -> std::result::Result<(), u64> {
        let (model, scene) = (&self.p.model, &self.p.scene);
        for step in first..first + steps {
            self.torques(step as f64 * dt);
            self.stepper
                .step(model, state, dt, scene.integrator, &mut self.forces);
            if !state.is_finite() {
                return Err(step + 1);
            }
        }
        Ok(())
    }

    /// Sets the hinge torques (one per hinge, clamped componentwise to the
    /// scene's torque limit) that stand in for the controller's from now
    /// on, or hands control back to the controller (`None`).
    pub fn drive(&mut self, g: Option<&[Vector3<f64>]>) {
        let limit = self.p.scene.controller().torque_limit.get();
        match g {
            Some(g) => {
                let driven = self.driven.get_or_insert_with(Vec::new);
                driven.clear();
                driven.extend(g.iter().map(|t| t.map(|x| x.clamp(-limit, limit))));
            }
            None => self.driven = None,
        }
    }

    /// The hinge torques of the last step taken or frame observed (one per
    /// hinge, after clamping).
    pub fn hinge_torques(&self) -> &[Vector3<f64>] {
        &self.hinge_torques
    }

    /// The link poses of the last frame observed.
    pub fn kinematics(&self) -> &Kinematics {
        &self.eval.kin
    }

    /// Puts the torques of time `t` into the forces: the driven ones, or
    /// the controller's.
    fn torques(&mut self, t: f64) {
        match &self.driven {
            Some(g) => self.hinge_torques.copy_from_slice(g),
            None => self.controller.torques(t, &mut self.hinge_torques),
        }
        for (torque, law) in self.hinge_torques.iter_mut().zip(&self.p.laws[1..]) {
            if let Some(law) = law {
                torque.x = law.clamp(torque.x);
            }
        }
        // A follower has no drive of its own: its leader's moves it.
        for c in &self.p.model.couplings {
            self.hinge_torques[c.follower - 1] = Vector3::zeros();
        }
        self.forces.g[1..].copy_from_slice(&self.hinge_torques);
        if let (Some(actuators), Some(actuated)) = (&mut self.actuators, &mut self.forces.actuated)
        {
            actuated[1..].copy_from_slice(actuators.update(t, &self.hinge_torques));
            // Nor does an actuator's noise drive a follower.
            for c in &self.p.model.couplings {
                actuated[c.follower] = Vector3::zeros();
            }
        }
    }

    /// Steps of `dt`, `steps_per_frame` a frame, from now on, where the
    /// scene's own are not what this runner takes (a coarser simulator of
    /// a plant): a plant's actuators lag and wait in those steps.
    pub fn pace(&mut self, dt: f64, steps_per_frame: u64) {
        if let (Some(actuators), Some(plant)) = (&mut self.actuators, &self.p.scene.plant) {
            actuators.pace(plant, dt, steps_per_frame);
        }
    }

    /// Forgets what the integrator (and a plant's actuators) tracked, to
    /// step on from another state of the same run. A plant's actuators start
    /// again at rest, their delay empty, so stepping on from a mid-run state
    /// of a plant does not reproduce its run (replay and planning run the
    /// nominal scene, which has none).
    pub fn restart(&mut self) {
        self.stepper.restart();
        if let Some(actuators) = &mut self.actuators {
            actuators.reset();
        }
    }

    /// [`Runner::observe`] without committing a plant's actuators to the
    /// torques driven now: a look at the frame before the torques to apply
    /// from it are chosen, after which observing or stepping at `t` takes
    /// the torques then driven.
    pub fn preview(&mut self, state: &State, t: f64, frame: &mut StateFrame) {
        let actuators = self.actuators.clone();
        self.observe(state, t, frame);
        self.actuators = actuators;
    }

    /// The frame of `state` at time `t`: its generalized state and
    /// variables, under the torques driven now (or the controller's), to
    /// which a plant's actuators are committed at `t`.
    pub fn observe(&mut self, state: &State, t: f64, frame: &mut StateFrame) {
        let p = self.p;
        self.torques(t);
        let implicit = (p.scene.integrator == Integrator::Implicit).then(|| p.scene.dt.get());
        self.eval
            .run_for(&p.model, state, &mut self.forces, implicit);
        generalized_state(&p.model, state, &mut frame.state);
        // The efforts the step from this frame applies: an implicit step's
        // include what taking it implicitly changed, the drive's part
        // (−h k q̈ of its piece's slope k) in the applied effort, the rest
        // in the passive one.
        let eval = &self.eval;
        let forces = &self.forces;
        let drive_change =
            |i: usize| -implicit.unwrap_or(0.0) * forces.drive[i].slope * eval.deriv.qd[i];
        frame.state.extend(
            one_dof(&p.model)
                .map(|i| forces.passive[i] + eval.implicit_effort[i] - drive_change(i)),
        );
        if p.scene.logs_applied() {
            frame
                .state
                .extend(one_dof(&p.model).map(|i| forces.applied[i] + drive_change(i)));
        }
        p.variables
            .values(state, &self.eval, &self.forces.g, &mut frame.variables);
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
