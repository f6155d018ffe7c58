//! A scene's many states stepped together ([`crate::batch`]), each under
//! torques of its own held over the steps: what a planner needs to try a
//! decision's candidate torque sequences at once. The forces are those
//! [`crate::runner::SceneForces`] gives one state — hinge torques and
//! damping, a robot's joint laws, contacts with floor and wall — computed
//! for every state at every step. A joint law and a contact branch on each
//! state's own numbers, so they are evaluated lane by lane; the tree's
//! dynamics, where the time goes, run in SIMD lanes.
//!
//! A plant's actuators — their gain, lag and delay — are tracked lane by
//! lane as [`crate::plant::Actuators`] tracks one state's, updated once an
//! instant: at each step's start, and when a frame is observed (the next
//! step from it then takes that update, as a [`crate::Runner`] stepped on
//! in time does). Their noise is not: a batch predicts the plant's mean.
//!
//! Results equal [`crate::Runner`]'s stepping to rounding, not bit for bit
//! (see [`crate::batch`]).

use nalgebra::{Matrix3, SimdPartialOrd, SimdValue, Vector3, Vector6};

use crate::Integrator;
use crate::batch::{Batch, KinematicsLanes, LANES, LaneForces, Lanes, LoadsLanes, StateLanes};
use crate::dynamics::{Loads, State};
use crate::joints::DrivePiece;
use crate::model::{Model, Root};
use crate::runner::Prepared;
use crate::spatial::{angular, linear, spatial};
use crate::variables::LaneVariable;

/// Many states of one scene, each driven by torques of its own, and the
/// variables read from them after a stretch of steps.
pub struct SceneBatch<'a> {
    p: &'a Prepared,
    batch: Option<Batch>,
    forces: BatchForces<'a>,
    /// The variables read ([`SceneBatch::observe`]), scene layout indices.
    read: Vec<LaneVariable>,
    /// Whether a variable read takes the accelerations.
    accelerations: bool,
    /// State by state, the values of the variables read.
    values: Vec<f64>,
    /// State by state, whether it stayed finite.
    finite: Vec<bool>,
    /// A plant's actuators, where it has them.
    actuators: Option<LaneActuators>,
}

impl<'a> SceneBatch<'a> {
    /// A batch of scene `p` reading its variables `read` (indices into its
    /// layout's variables); `None` where the scene cannot be stepped in
    /// lanes: Runge–Kutta (a batch steps by semi-implicit Euler, its joints'
    /// slopes taken implicitly under the implicit integrator), coupled
    /// joints (a URDF's mimics, which the batch's algorithm cannot take), a
    /// plant whose actuators add noise (a draw per state and step, which
    /// [`crate::Runner`] takes state by state; a forward model predicts the
    /// mean, [`Prepared::without_noise`]), or a variable read that a batch
    /// does not give (a link's acceleration or external force).
    pub fn new(p: &'a Prepared, read: &[usize]) -> Option<SceneBatch<'a>> {
        let plant = p.scene.plant.as_ref().filter(|pl| pl.has_actuators());
        let noisy = plant.is_some_and(|pl| pl.torque_noise != 0.0);
        if p.scene.integrator == Integrator::Rk4 || noisy || !p.model.couplings.is_empty() {
            return None;
        }
        let read = read
            .iter()
            .map(|&v| p.variables.lane_variable(v))
            .collect::<Option<Vec<_>>>()?;
        let accelerations = read.iter().any(LaneVariable::needs_accelerations);
        Some(SceneBatch {
            p,
            batch: None,
            forces: BatchForces {
                p,
                g: Vec::new(),
                drive: Vec::new(),
                damping: Lanes::splat(p.scene.added_damping()),
                limit: p.scene.controller().torque_limit.get(),
                actuated: None,
            },
            read,
            accelerations,
            values: Vec::new(),
            finite: Vec::new(),
            actuators: plant.map(|pl| {
                let mut actuators = LaneActuators {
                    gain: pl.actuator_gain,
                    lag: pl.actuator_lag,
                    delay_frames: pl.actuator_delay_frames,
                    follow: None,
                    queue: Vec::new(),
                    head: 0,
                    full: false,
                    fresh: false,
                };
                // The scene's own pace until an advance says otherwise.
                actuators.time(p.scene.dt.get(), p.scene.steps_per_frame());
                actuators
            }),
        })
    }

    /// Starts `n` states from `state`, with no torques; allocates only when
    /// `n` differs from the last start's.
    pub fn start(&mut self, state: &State, n: usize) {
        let model = &self.p.model;
        match &mut self.batch {
            Some(batch) if batch.len == n => batch.fill(state),
            _ => {
                let states = vec![state.clone(); n];
                let loads = vec![Loads::zeros(model); n];
                let batch = Batch::pack(model, &states, &loads);
                let zero = Vector3::from_element(Lanes::splat(0.0));
                self.forces.g = vec![vec![zero; model.len()]; batch.states.len()];
                self.forces.drive =
                    vec![vec![[DrivePiece::default(); LANES]; model.len()]; batch.states.len()];
                self.values = vec![0.0; n * self.read.len()];
                self.finite = vec![true; n];
                if self.actuators.is_some() {
                    self.forces.actuated = Some(self.forces.g.clone());
                }
                self.batch = Some(batch);
            }
        }
        // The actuators at rest, their delay empty, as a restarted runner's.
        if let (Some(actuators), Some(actuated)) = (&mut self.actuators, &mut self.forces.actuated)
        {
            actuators.reset(actuated);
        }
    }

    /// Holds `torques` (one per hinge, as [`crate::Runner::drive`] takes
    /// them, clamped the same way) on state `k` from now on.
    pub fn drive(&mut self, k: usize, torques: &[Vector3<f64>]) {
        let (g, j) = (k / LANES, k % LANES);
        let limit = self.forces.limit;
        for (i, torque) in torques.iter().enumerate() {
            let link = i + 1;
            let mut t = torque.map(|x| x.clamp(-limit, limit));
            if let Some(law) = &self.p.laws[link] {
                t.x = law.clamp(t.x);
            }
            for (lanes, value) in self.forces.g[g][link].iter_mut().zip(t.iter()) {
                lanes.replace(j, *value);
            }
        }
    }

    /// Sets state `k`'s one-DOF joint at `link` to position `q` and velocity
    /// `qd`.
    pub fn set_joint(&mut self, k: usize, link: usize, q: f64, qd: f64) {
        let batch = self.batch.as_mut().expect("started");
        let s = &mut batch.states[k / LANES];
        s.q[link].replace(k % LANES, q);
        s.qd[link].replace(k % LANES, qd);
    }

    /// Advances every state `steps` steps of `dt`: a frame of `steps`
    /// steps (which a plant's actuator delay is counted in).
    pub fn advance(&mut self, steps: u64, dt: f64) {
        let batch = self.batch.as_mut().expect("started");
        let implicit = self.p.scene.integrator == Integrator::Implicit;
        if let Some(actuators) = &mut self.actuators {
            actuators.time(dt, steps);
        }
        for _ in 0..steps {
            if let (Some(actuators), Some(actuated)) =
                (&mut self.actuators, &mut self.forces.actuated)
            {
                actuators.update(&self.forces.g, actuated);
            }
            batch.step_under(&self.p.model, dt, implicit, &mut self.forces);
            if let Some(actuators) = &mut self.actuators {
                actuators.fresh = false;
            }
        }
    }

    /// Reads the variables of every state as it is now, under the torques
    /// driven now.
    pub fn observe(&mut self) {
        // The actuators updated at this instant, under the torques driven
        // now, as a runner's observation commits them.
        if let (Some(actuators), Some(actuated)) = (&mut self.actuators, &mut self.forces.actuated)
        {
            actuators.update(&self.forces.g, actuated);
        }
        let batch = self.batch.as_mut().expect("started");
        let (n, m) = (batch.len, self.read.len());
        for k in 0..n {
            self.finite[k] = batch.is_finite(k);
        }
        let model = &self.p.model;
        let implicit =
            (self.p.scene.integrator == Integrator::Implicit).then(|| self.p.scene.dt.get());
        for g in 0..batch.states.len() {
            let (state, kin, accel) = match self.accelerations {
                true => {
                    let (state, kin, accel) = batch.evaluate(model, g, implicit, &mut self.forces);
                    (state, kin, Some(accel))
                }
                false => {
                    let (state, kin) = batch.kinematics(model, g);
                    (state, kin, None)
                }
            };
            for (r, variable) in self.read.iter().enumerate() {
                let lanes = variable.lanes(state, kin, accel, &self.forces.g[g]);
                for j in 0..LANES.min(n - g * LANES) {
                    self.values[(g * LANES + j) * m + r] = lanes.extract(j);
                }
            }
        }
    }

    /// State `k`'s variables read at the last [`SceneBatch::observe`], in
    /// the order given to [`SceneBatch::new`]; `None` if it blew up (a
    /// number not finite) since its start.
    pub fn values(&self, k: usize) -> Option<&[f64]> {
        let m = self.read.len();
        self.finite[k].then(|| &self.values[k * m..(k + 1) * m])
    }
}

/// The scene's forces on a batch's states, per group of [`LANES`].
struct BatchForces<'a> {
    p: &'a Prepared,
    /// Per group, per link, the control torque g on its parent (a one-DOF
    /// joint's effort in x, already clamped to its limit).
    g: Vec<Vec<Vector3<Lanes>>>,
    /// Per group, per link, lane by lane, the piece of its one-DOF joint's
    /// drive the last evaluation took.
    drive: Vec<Vec<[DrivePiece; LANES]>>,
    /// Viscous damping at every ball hinge.
    damping: Lanes,
    /// The controller's torque limit.
    limit: f64,
    /// Per group, per link, what a plant's actuators produce, where they
    /// produce other than the command `g`.
    actuated: Option<Vec<Vec<Vector3<Lanes>>>>,
}

impl BatchForces<'_> {
    /// The effort commanded to the one-DOF joint at `link` of state `j` of
    /// group `g`: what its actuator produces, within `law`'s limit, where a
    /// plant's actuators act, else the command.
    fn commanded(&self, g: usize, link: usize, j: usize, law: &crate::joints::JointLaw) -> f64 {
        match &self.actuated {
            Some(actuated) => law.clamp(actuated[g][link].x.extract(j)),
            None => self.g[g][link].x.extract(j),
        }
    }
}

/// A plant's actuators over a batch's states: [`crate::plant::Actuators`]
/// lane by lane, without the noise.
struct LaneActuators {
    gain: f64,
    /// The lag's time constant (s) and the delay in frames, as the plant
    /// gives them …
    lag: f64,
    delay_frames: u64,
    /// … and, for the steps being taken, the lag's weight of the new
    /// command in one step (`None`: no lag).
    follow: Option<f64>,
    /// The commands on their way, one per step of the delay: a ring, the
    /// oldest at `head` once `full`.
    queue: Vec<Vec<Vec<Vector3<Lanes>>>>,
    head: usize,
    full: bool,
    /// Whether this instant's update is done (by an observation): the
    /// step from it takes it, as a runner does.
    fresh: bool,
}

impl LaneActuators {
    /// At rest, their delay empty.
    fn reset(&mut self, actuated: &mut [Vec<Vector3<Lanes>>]) {
        let zero = Vector3::from_element(Lanes::splat(0.0));
        for group in actuated.iter_mut() {
            group.fill(zero);
        }
        (self.head, self.full, self.fresh) = (0, false, false);
    }

    /// Sets the lag's weight and the delay's length for steps of `dt`,
    /// `steps` a frame.
    fn time(&mut self, dt: f64, steps: u64) {
        self.follow = (self.lag > 0.0).then(|| 1.0 - (-dt / self.lag).exp());
        let delay = (self.delay_frames * steps) as usize;
        if self.queue.len() != delay {
            self.queue = Vec::new();
            (self.head, self.full) = (0, false);
            self.queue.resize_with(delay, Vec::new);
        }
    }

    /// Once an instant: what the actuators produce under `command`
    /// (per group, per link), into `actuated`, which holds what they
    /// produced.
    fn update(&mut self, command: &[Vec<Vector3<Lanes>>], actuated: &mut [Vec<Vector3<Lanes>>]) {
        if std::mem::replace(&mut self.fresh, true) {
            return;
        }
        let (gain, follow) = (Lanes::splat(self.gain), self.follow.map(Lanes::splat));
        let zero = Vector3::from_element(Lanes::splat(0.0));
        // What arrives: this command, or with a delay the one of `delay`
        // updates ago (none yet: zero), which this one replaces in the ring.
        let arrived = match self.queue.is_empty() {
            true => Some(command),
            false => self.full.then_some(&self.queue[self.head][..]),
        };
        for (g, out) in actuated.iter_mut().enumerate() {
            for (i, y) in out.iter_mut().enumerate() {
                let u = arrived.map_or(zero, |a| a[g][i]) * gain;
                *y = match follow {
                    Some(f) => *y + (u - *y) * f,
                    None => u,
                };
            }
        }
        if !self.queue.is_empty() {
            let slot = &mut self.queue[self.head];
            slot.resize_with(command.len(), Vec::new);
            for (kept, given) in slot.iter_mut().zip(command) {
                kept.clone_from(given);
            }
            self.head = (self.head + 1) % self.queue.len();
            self.full |= self.head == 0;
        }
    }
}

impl LaneForces for BatchForces<'_> {
    fn apply(
        &mut self,
        model: &Model,
        g: usize,
        state: &StateLanes,
        kin: &KinematicsLanes,
        loads: &mut LoadsLanes,
    ) {
        let torques = match &self.actuated {
            // What the actuators produce, capped by the torque limit as the
            // command is (a one-DOF joint's by its effort limit, below).
            Some(actuated) => &actuated[g],
            None => &self.g[g],
        };
        let limit = Lanes::splat(self.limit);
        for ((tau, t), w) in loads.tau.iter_mut().zip(torques).zip(&state.rates) {
            let t = match self.actuated {
                Some(_) => t.map(|x| x.simd_clamp(-limit, limit)),
                None => *t,
            };
            *tau = -t - w * self.damping;
        }
        if model.root == Root::Pinned {
            loads.tau[0] = Vector3::from_element(Lanes::splat(0.0));
        }
        let zero = Lanes::splat(0.0);
        for (i, law) in self.p.laws.iter().enumerate() {
            let Some(law) = law else {
                (loads.effort[i], loads.effort_damping[i]) = (zero, zero);
                loads.effort_stiffness[i] = zero;
                continue;
            };
            for j in 0..LANES {
                let (q, qd) = (state.q[i].extract(j), state.qd[i].extract(j));
                let drive = law.drive_piece(self.commanded(g, i, j, law), qd);
                self.drive[g][i][j] = drive;
                let (b, k) = law.slopes(q, qd);
                loads.effort[i].replace(j, drive.at(qd) + law.passive(q, qd));
                loads.effort_damping[i].replace(j, b + drive.slope);
                loads.effort_stiffness[i].replace(j, k);
            }
        }
        loads.f_ext.fill(Vector6::from_element(Lanes::splat(0.0)));
        for point in &self.p.points {
            let i = point.link;
            for j in 0..LANES {
                let rot: Matrix3<f64> = kin.rot[i].map(|x| x.extract(j));
                let x = kin.pos[i].map(|x| x.extract(j)) + rot * point.offset;
                let force = self.p.surfaces.point_force(model, point, &x, || {
                    let v: Vector6<f64> = kin.vel[i].map(|x| x.extract(j));
                    rot * (linear(&v) + angular(&v).cross(&point.offset))
                });
                if force != Vector3::zeros() {
                    let local = rot.transpose() * force;
                    let f = spatial(&point.offset.cross(&local), &local);
                    for (lanes, value) in loads.f_ext[i].iter_mut().zip(f.iter()) {
                        lanes.replace(j, lanes.extract(j) + value);
                    }
                }
            }
        }
    }

    /// As [`crate::runner::SceneForces`] refines one state's drives.
    fn refine(
        &mut self,
        g: usize,
        state: &StateLanes,
        qdd: &[Lanes],
        h: f64,
        loads: &mut LoadsLanes,
    ) -> bool {
        let mut moved = false;
        for (i, law) in self.p.laws.iter().enumerate() {
            let Some(law) = law.filter(|l| l.velocity.is_finite()) else {
                continue;
            };
            for j in 0..LANES {
                let qd = state.qd[i].extract(j);
                let now = self.drive[g][i][j];
                let effort = self.commanded(g, i, j, &law);
                let end = law.drive_toward(effort, now, qd + h * qdd[i].extract(j));
                if end != now {
                    let effort = loads.effort[i].extract(j) + end.at(qd) - now.at(qd);
                    loads.effort[i].replace(j, effort);
                    let slope = loads.effort_damping[i].extract(j) + end.slope - now.slope;
                    loads.effort_damping[i].replace(j, slope);
                    self.drive[g][i][j] = end;
                    moved = true;
                }
            }
        }
        moved
    }
}
