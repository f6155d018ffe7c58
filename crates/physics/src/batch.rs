//! Many states of one model at once, on one thread: the articulated-body
//! algorithm of [`crate::dynamics`] and the semi-implicit Euler step of
//! [`crate::integrate`], computed for [`LANES`] states together in
//! structure-of-arrays form — every number a SIMD vector holding that
//! number of each state — so one pass over the tree serves them all. The
//! loads are held ([`Batch::step`]) or computed from each state at every
//! step ([`Batch::step_under`] with [`LaneForces`], as
//! [`crate::batch_scene`] does a scene's).
//!
//! The tree's shape (parents, joint kinds) is the same for every state, so
//! the states never branch apart; only the numbers differ. A batch is
//! packed once ([`Batch::pack`]), stepped as often as wanted and unpacked.
//! Results equal the one-at-a-time path's to rounding (the tests hold them
//! to 1e-12 relative), not bit for bit: the SIMD sine and cosine, and a
//! Cholesky of its own for a free root, round differently.

use nalgebra::{
    Matrix3, Matrix6, Quaternion, Rotation3, SimdValue, Unit, UnitQuaternion, Vector3, Vector6,
};

use crate::dynamics::{Loads, State};
use crate::integrate::REFINEMENTS;
use crate::model::{Joint, Model, Root};
use crate::spatial::{Transform, angular, cross_force, cross_motion, linear, skew, spatial};

/// One SIMD vector of `f64`: a number of [`LANES`] states.
pub type Lanes = simba::simd::WideF64x4;

/// How many states one [`Lanes`] holds.
pub const LANES: usize = 4;

/// [`LANES`] states of one model, number by number (see [`State`]).
#[derive(Clone, Debug)]
pub struct StateLanes {
    pub root_p: Vector3<Lanes>,
    pub root_v: Vector3<Lanes>,
    pub orient: Vec<Quaternion<Lanes>>,
    pub rates: Vec<Vector3<Lanes>>,
    pub q: Vec<Lanes>,
    pub qd: Vec<Lanes>,
}

/// The loads on [`LANES`] states (see [`Loads`]).
#[derive(Clone, Debug)]
pub struct LoadsLanes {
    pub tau: Vec<Vector3<Lanes>>,
    pub effort: Vec<Lanes>,
    pub f_ext: Vec<Vector6<Lanes>>,
    /// How each one-DOF joint's effort falls with its velocity and its
    /// position (b, k ≥ 0), which an implicit step takes implicitly.
    pub effort_damping: Vec<Lanes>,
    pub effort_stiffness: Vec<Lanes>,
    /// Added to each one-DOF joint's diagonal of the mass matrix (an
    /// implicit step's h b + h² k).
    pub armature: Vec<Lanes>,
}

/// Accelerations of [`LANES`] states: the root's linear one (root frame),
/// each ball hinge's angular one and each one-DOF joint's.
#[derive(Clone, Debug)]
pub struct AccelLanes {
    pub root_v: Vector3<Lanes>,
    pub rates: Vec<Vector3<Lanes>>,
    pub qdd: Vec<Lanes>,
}

/// The kinematics of [`LANES`] states (see [`crate::dynamics::Kinematics`]).
#[derive(Clone, Debug)]
pub struct KinematicsLanes {
    /// Link → inertial rotation.
    pub rot: Vec<Matrix3<Lanes>>,
    /// Hinge position, inertial frame.
    pub pos: Vec<Vector3<Lanes>>,
    /// Spatial velocity, link frame.
    pub vel: Vec<Vector6<Lanes>>,
}

/// The loads on a group of states at one instant, from the states
/// themselves (as [`crate::integrate::Forces`] gives one state's).
pub trait LaneForces {
    /// Fills `loads` (every field; gravity excluded) for group `g`'s states
    /// `state`, whose kinematics are `kin`.
    fn apply(
        &mut self,
        model: &Model,
        g: usize,
        state: &StateLanes,
        kin: &KinematicsLanes,
        loads: &mut LoadsLanes,
    );

    /// As [`crate::integrate::Forces::refine`] for group `g`'s states
    /// `state`, their accelerations `qdd`: each one-DOF joint's effort that
    /// is piecewise affine in the velocity moved, lane by lane, to the piece
    /// holding at the step's end; whether any moved. None, by default.
    fn refine(
        &mut self,
        _g: usize,
        _state: &StateLanes,
        _qdd: &[Lanes],
        _h: f64,
        _loads: &mut LoadsLanes,
    ) -> bool {
        false
    }
}

/// The loads packed with the states, held.
struct Held;

impl LaneForces for Held {
    fn apply(
        &mut self,
        _: &Model,
        _: usize,
        _: &StateLanes,
        _: &KinematicsLanes,
        _: &mut LoadsLanes,
    ) {
    }
}

/// Many states packed in groups of [`LANES`], with their loads, and the
/// scratch space that steps them; allocates nothing after [`Batch::pack`].
pub struct Batch {
    /// How many states were packed (the last group is padded with copies of
    /// the last state).
    pub len: usize,
    pub states: Vec<StateLanes>,
    pub loads: Vec<LoadsLanes>,
    /// A free root's linear momentum per group, tracked across steps (as
    /// [`crate::integrate::Stepper`] tracks one state's) until the states
    /// are set again; `None` until the first step.
    momentum: Vec<Option<Vector3<Lanes>>>,
    accel: AccelLanes,
    ws: Scratch,
}

/// Per-link scratch of one group, and the model's constants splatted.
struct Scratch {
    inertia: Vec<Matrix6<Lanes>>,
    gravity: Vector3<Lanes>,
    kin: KinematicsLanes,
    x: Vec<Transform<Lanes>>,
    articulated: Vec<Matrix6<Lanes>>,
    bias: Vec<Vector6<Lanes>>,
    velocity_product: Vec<Vector6<Lanes>>,
    d_inv: Vec<Matrix3<Lanes>>,
    u: Vec<Vector3<Lanes>>,
    axis_u: Vec<Vector6<Lanes>>,
    axis_d_inv: Vec<Lanes>,
    axis_force: Vec<Lanes>,
    accel: Vec<Vector6<Lanes>>,
}

fn splat3(v: &Vector3<f64>) -> Vector3<Lanes> {
    v.map(Lanes::splat)
}

fn splat6(v: &Vector6<f64>) -> Vector6<Lanes> {
    v.map(Lanes::splat)
}

fn splat33(m: &Matrix3<f64>) -> Matrix3<Lanes> {
    m.map(Lanes::splat)
}

/// Gathers lane `j` of every state of a group from `field` of each state.
fn gather<const N: usize>(group: &[&State], field: impl Fn(&State) -> [f64; N]) -> [Lanes; N] {
    std::array::from_fn(|k| {
        let mut lanes = [0.0; LANES];
        for (j, state) in group.iter().enumerate() {
            lanes[j] = field(state)[k];
        }
        Lanes::from(lanes)
    })
}

impl StateLanes {
    fn pack(model: &Model, group: &[&State]) -> StateLanes {
        let v3 = |f: &dyn Fn(&State) -> Vector3<f64>| {
            let [x, y, z] = gather(group, |s| f(s).into());
            Vector3::new(x, y, z)
        };
        StateLanes {
            root_p: v3(&|s| s.root_p),
            root_v: v3(&|s| s.root_v),
            orient: (0..model.len())
                .map(|i| {
                    let [w, x, y, z] = gather(group, |s| {
                        let q = s.orient[i];
                        [q.w, q.i, q.j, q.k]
                    });
                    Quaternion::new(w, x, y, z)
                })
                .collect(),
            rates: (0..model.len()).map(|i| v3(&|s| s.rates[i])).collect(),
            q: (0..model.len())
                .map(|i| gather(group, |s| [s.q[i]])[0])
                .collect(),
            qd: (0..model.len())
                .map(|i| gather(group, |s| [s.qd[i]])[0])
                .collect(),
        }
    }

    /// Writes lane `j` into `state`.
    fn unpack(&self, j: usize, state: &mut State) {
        let v3 = |v: &Vector3<Lanes>| v.map(|x| x.extract(j));
        state.root_p = v3(&self.root_p);
        state.root_v = v3(&self.root_v);
        for i in 0..state.orient.len() {
            let q = &self.orient[i];
            state.orient[i] = UnitQuaternion::new_unchecked(Quaternion::new(
                q.w.extract(j),
                q.i.extract(j),
                q.j.extract(j),
                q.k.extract(j),
            ));
            state.rates[i] = v3(&self.rates[i]);
            state.q[i] = self.q[i].extract(j);
            state.qd[i] = self.qd[i].extract(j);
        }
    }
}

impl LoadsLanes {
    fn pack(model: &Model, group: &[&Loads]) -> LoadsLanes {
        let lanes = |f: &dyn Fn(&Loads) -> f64| {
            let mut values = [0.0; LANES];
            for (j, loads) in group.iter().enumerate() {
                values[j] = f(loads);
            }
            Lanes::from(values)
        };
        LoadsLanes {
            tau: (0..model.len())
                .map(|i| Vector3::from_fn(|k, _| lanes(&|l| l.tau[i][k])))
                .collect(),
            effort: (0..model.len()).map(|i| lanes(&|l| l.effort[i])).collect(),
            f_ext: (0..model.len())
                .map(|i| Vector6::from_fn(|k, _| lanes(&|l| l.f_ext[i][k])))
                .collect(),
            effort_damping: (0..model.len())
                .map(|i| lanes(&|l| l.effort_damping[i]))
                .collect(),
            effort_stiffness: (0..model.len())
                .map(|i| lanes(&|l| l.effort_stiffness[i]))
                .collect(),
            armature: (0..model.len())
                .map(|i| lanes(&|l| l.armature[i]))
                .collect(),
        }
    }
}

/// The `i`-th group of `items`, padded to [`LANES`] with its last item.
fn group<T>(items: &[T], g: usize) -> Vec<&T> {
    let last = items.len() - 1;
    (0..LANES)
        .map(|j| &items[(g * LANES + j).min(last)])
        .collect()
}

impl Batch {
    /// Packs `states` with their `loads` (one per state, held while
    /// stepping) for `model`. Panics if the two differ in length or are
    /// empty.
    pub fn pack(model: &Model, states: &[State], loads: &[Loads]) -> Batch {
        debug_assert!(
            model.couplings.is_empty(),
            "the batch's algorithm takes no couplings"
        );
        assert!(
            !states.is_empty() && states.len() == loads.len(),
            "a batch needs one load per state"
        );
        let groups = states.len().div_ceil(LANES);
        let n = model.len();
        let zero6 = Vector6::from_element(Lanes::splat(0.0));
        let zero3 = Vector3::from_element(Lanes::splat(0.0));
        let zero66 = Matrix6::from_element(Lanes::splat(0.0));
        let zero33 = Matrix3::from_element(Lanes::splat(0.0));
        Batch {
            len: states.len(),
            states: (0..groups)
                .map(|g| StateLanes::pack(model, &group(states, g)))
                .collect(),
            loads: (0..groups)
                .map(|g| LoadsLanes::pack(model, &group(loads, g)))
                .collect(),
            momentum: vec![None; groups],
            accel: AccelLanes {
                root_v: zero3,
                rates: vec![zero3; n],
                qdd: vec![Lanes::splat(0.0); n],
            },
            ws: Scratch {
                inertia: model
                    .links
                    .iter()
                    .map(|l| l.spatial_inertia().map(Lanes::splat))
                    .collect(),
                gravity: splat3(&model.gravity),
                kin: KinematicsLanes {
                    rot: vec![zero33; n],
                    pos: vec![zero3; n],
                    vel: vec![zero6; n],
                },
                x: vec![
                    Transform {
                        e: zero33,
                        r: zero3
                    };
                    n
                ],
                articulated: vec![zero66; n],
                bias: vec![zero6; n],
                velocity_product: vec![zero6; n],
                d_inv: vec![zero33; n],
                u: vec![zero3; n],
                axis_u: vec![zero6; n],
                axis_d_inv: vec![Lanes::splat(0.0); n],
                axis_force: vec![Lanes::splat(0.0); n],
                accel: vec![zero6; n],
            },
        }
    }

    /// Sets every state to `other`'s (a batch of the same model and size),
    /// allocating nothing; a free root's momentum is tracked afresh.
    pub fn copy_states_from(&mut self, other: &Batch) {
        for (to, from) in self.states.iter_mut().zip(&other.states) {
            to.root_p = from.root_p;
            to.root_v = from.root_v;
            to.orient.copy_from_slice(&from.orient);
            to.rates.copy_from_slice(&from.rates);
            to.q.copy_from_slice(&from.q);
            to.qd.copy_from_slice(&from.qd);
        }
        self.momentum.fill(None);
    }

    /// Sets every state to `state`, allocating nothing; a free root's
    /// momentum is tracked afresh.
    pub fn fill(&mut self, state: &State) {
        for to in &mut self.states {
            to.root_p = splat3(&state.root_p);
            to.root_v = splat3(&state.root_v);
            for (o, q) in to.orient.iter_mut().zip(&state.orient) {
                *o = Quaternion::from(q.coords.map(Lanes::splat));
            }
            for (r, w) in to.rates.iter_mut().zip(&state.rates) {
                *r = splat3(w);
            }
            for (q, x) in to.q.iter_mut().zip(&state.q) {
                *q = Lanes::splat(*x);
            }
            for (qd, x) in to.qd.iter_mut().zip(&state.qd) {
                *qd = Lanes::splat(*x);
            }
        }
        self.momentum.fill(None);
    }

    /// Writes every packed state back into `states` (as many as were packed).
    pub fn unpack(&self, states: &mut [State]) {
        for (k, state) in states.iter_mut().enumerate().take(self.len) {
            self.states[k / LANES].unpack(k % LANES, state);
        }
    }

    /// Whether every number of state `k` is finite.
    pub fn is_finite(&self, k: usize) -> bool {
        let (s, j) = (&self.states[k / LANES], k % LANES);
        let finite = |x: &Lanes| x.extract(j).is_finite();
        s.root_p.iter().chain(&s.root_v).all(finite)
            && s.orient.iter().all(|q| q.coords.iter().all(finite))
            && s.rates.iter().all(|w| w.iter().all(finite))
            && s.q.iter().chain(&s.qd).all(finite)
    }

    /// Group `g`'s states and their kinematics.
    pub fn kinematics(&mut self, model: &Model, g: usize) -> (&StateLanes, &KinematicsLanes) {
        self.ws.kinematics(model, &self.states[g]);
        (&self.states[g], &self.ws.kin)
    }

    /// Group `g`'s states, their kinematics and their accelerations under
    /// the loads `forces` gives them now — as a step of `implicit` (h)
    /// evaluates them ([`crate::Integrator::Implicit`]), or explicitly
    /// (`None`).
    pub fn evaluate(
        &mut self,
        model: &Model,
        g: usize,
        implicit: Option<f64>,
        forces: &mut impl LaneForces,
    ) -> (&StateLanes, &KinematicsLanes, &AccelLanes) {
        self.solve(model, g, implicit, forces);
        (&self.states[g], &self.ws.kin, &self.accel)
    }

    /// The accelerations of group `g`'s states under their loads
    /// (kinematics and the articulated-body algorithm, as
    /// [`crate::dynamics::Workspace::forward`] computes them).
    pub fn accelerations(&mut self, model: &Model, g: usize) -> &AccelLanes {
        self.evaluate(model, g, None, &mut Held).2
    }

    /// Group `g`'s kinematics, the loads `forces` gives its states and
    /// their accelerations; with `implicit` (h), each one-DOF joint's
    /// effort and armature as an implicit step takes them: −h k q̇ added,
    /// h b + h² k on the diagonal, efforts whose piece changes at the step's
    /// end solved again (as [`crate::integrate::Evaluation::run_for`] takes
    /// one state's). Explicitly (`None`) the loads' armature stays as it
    /// is: what was packed, for held loads.
    fn solve(
        &mut self,
        model: &Model,
        g: usize,
        implicit: Option<f64>,
        forces: &mut impl LaneForces,
    ) {
        self.ws.kinematics(model, &self.states[g]);
        let loads = &mut self.loads[g];
        forces.apply(model, g, &self.states[g], &self.ws.kin, loads);
        let Some(dt) = implicit else {
            self.ws
                .forward(model, &self.states[g], &self.loads[g], &mut self.accel);
            return;
        };
        let h = Lanes::splat(dt);
        let qd = &self.states[g].qd;
        for ((effort, k), qd) in loads.effort.iter_mut().zip(&loads.effort_stiffness).zip(qd) {
            *effort -= h * *k * *qd;
        }
        for pass in 0..=REFINEMENTS {
            let loads = &mut self.loads[g];
            if pass > 0 && !forces.refine(g, &self.states[g], &self.accel.qdd, dt, loads) {
                break;
            }
            for i in 0..model.len() {
                loads.armature[i] = h * loads.effort_damping[i] + h * h * loads.effort_stiffness[i];
            }
            self.ws
                .forward(model, &self.states[g], &self.loads[g], &mut self.accel);
        }
    }

    /// Advances every state by `dt` with semi-implicit Euler under its held
    /// loads, as [`crate::integrate::Stepper::step`] does one state's.
    pub fn step(&mut self, model: &Model, dt: f64) {
        self.step_under(model, dt, false, &mut Held);
    }

    /// Advances every state by `dt` with semi-implicit Euler under the loads
    /// `forces` gives at the step's start — with `implicit`, the one-DOF
    /// joints' effort slopes taken implicitly, as
    /// [`crate::Integrator::Implicit`] takes them — as
    /// [`crate::integrate::Stepper::step`] does one state's (a free root's
    /// linear momentum tracked across steps, from the first after the
    /// states were set).
    pub fn step_under(
        &mut self,
        model: &Model,
        dt: f64,
        implicit: bool,
        forces: &mut impl LaneForces,
    ) {
        let h = Lanes::splat(dt);
        for g in 0..self.states.len() {
            self.solve(model, g, implicit.then_some(dt), forces);
            if model.root == Root::Free && self.momentum[g].is_none() {
                self.momentum[g] = Some(self.ws.linear_momentum(model));
            }
            let external = self.ws.external_force(model, &self.loads[g]);
            let (s, a) = (&mut self.states[g], &self.accel);
            s.root_v += a.root_v * h;
            for (w, wd) in s.rates.iter_mut().zip(&a.rates) {
                *w += wd * h;
            }
            for (qd, qdd) in s.qd.iter_mut().zip(&a.qdd) {
                *qd += *qdd * h;
            }
            for (q, qd) in s.q.iter_mut().zip(&s.qd) {
                *q += *qd * h;
            }
            if model.root == Root::Free {
                s.root_p += self.ws.kin.rot[0] * s.root_v * h;
            }
            for (q, w) in s.orient.iter_mut().zip(&s.rates) {
                let turn = UnitQuaternion::from_scaled_axis(w * h);
                let turned = *q * turn.into_inner();
                *q = turned / turned.norm();
            }
            if let Some(momentum) = &mut self.momentum[g] {
                *momentum += external * h;
                let target = *momentum;
                self.ws.kinematics(model, &self.states[g]);
                let error = target - self.ws.linear_momentum(model);
                let s = &mut self.states[g];
                s.root_v +=
                    self.ws.kin.rot[0].transpose() * error / Lanes::splat(model.total_mass());
            }
        }
    }
}

impl Scratch {
    /// Link rotations and positions, joint transforms and spatial
    /// velocities.
    fn kinematics(&mut self, model: &Model, s: &StateLanes) {
        for (i, link) in model.links.iter().enumerate() {
            match link.parent {
                None => {
                    let rel = rotation(&s.orient[i]);
                    self.kin.rot[i] = rel;
                    self.kin.pos[i] = s.root_p;
                    self.x[i] = Transform {
                        e: rel.transpose(),
                        r: s.root_p,
                    };
                    let zero = Vector3::from_element(Lanes::splat(0.0));
                    self.kin.vel[i] = match model.root {
                        Root::Free => spatial(&s.rates[i], &s.root_v),
                        Root::Pinned => spatial(&s.rates[i], &zero),
                        Root::Fixed => Vector6::from_element(Lanes::splat(0.0)),
                    };
                }
                Some(p) => {
                    let (rel, r) = match link.joint {
                        Joint::Ball => (rotation(&s.orient[i]), splat3(&link.l)),
                        Joint::Revolute { origin, axis } => {
                            let turn = Rotation3::from_axis_angle(
                                &Unit::new_unchecked(splat3(&axis)),
                                s.q[i],
                            );
                            (splat33(&origin) * turn.into_inner(), splat3(&link.l))
                        }
                        Joint::Prismatic { origin, axis } => (
                            splat33(&origin),
                            splat3(&link.l) + splat33(&origin) * (splat3(&axis) * s.q[i]),
                        ),
                    };
                    self.kin.rot[i] = self.kin.rot[p] * rel;
                    self.kin.pos[i] = self.kin.pos[p] + self.kin.rot[p] * r;
                    self.x[i] = Transform {
                        e: rel.transpose(),
                        r,
                    };
                    self.kin.vel[i] =
                        self.x[i].motion(&self.kin.vel[p]) + joint_velocity(&link.joint, s, i);
                }
            }
        }
    }

    /// The system's linear momentum, inertial frame.
    fn linear_momentum(&self, model: &Model) -> Vector3<Lanes> {
        let mut sum = Vector3::from_element(Lanes::splat(0.0));
        for (i, link) in model.links.iter().enumerate() {
            let v = &self.kin.vel[i];
            let point = linear(v) + angular(v).cross(&splat3(&link.c));
            sum += self.kin.rot[i] * point * Lanes::splat(link.mass);
        }
        sum
    }

    /// Gravity and the external forces, inertial frame: the rate of the
    /// linear momentum.
    fn external_force(&self, model: &Model, loads: &LoadsLanes) -> Vector3<Lanes> {
        let mut sum = self.gravity * Lanes::splat(model.total_mass());
        for (rot, f) in self.kin.rot.iter().zip(&loads.f_ext) {
            sum += rot * linear(f);
        }
        sum
    }

    /// The articulated-body algorithm (see `Workspace::forward`).
    #[allow(clippy::needless_range_loop)]
    fn forward(&mut self, model: &Model, s: &StateLanes, loads: &LoadsLanes, out: &mut AccelLanes) {
        let n = model.len();
        let zero3 = Vector3::from_element(Lanes::splat(0.0));
        for i in 0..n {
            let link = &model.links[i];
            let v = self.kin.vel[i];
            let inertia = &self.inertia[i];
            self.velocity_product[i] = match link.parent {
                Some(_) => cross_motion(&v, &joint_velocity(&link.joint, s, i)),
                None => Vector6::from_element(Lanes::splat(0.0)),
            };
            self.articulated[i] = *inertia;
            let gravity = self.kin.rot[i].transpose() * self.gravity * Lanes::splat(link.mass);
            let f_gravity = spatial(&splat3(&link.c).cross(&gravity), &gravity);
            self.bias[i] = cross_force(&v, &(inertia * v)) - loads.f_ext[i] - f_gravity;
        }
        for i in (0..n).rev() {
            if i == 0 && model.root != Root::Pinned {
                continue;
            }
            match model.links[i].joint.axis_motion().filter(|_| i > 0) {
                None => self.ball_inward(model, loads, i),
                Some(axis) => self.axis_inward(model, loads, i, &splat6(&axis)),
            }
        }
        for i in 0..n {
            let link = &model.links[i];
            out.qdd[i] = Lanes::splat(0.0);
            let a = match (link.parent, model.root) {
                (None, Root::Free) => {
                    let a = -solve_spd6(&mut self.articulated[i], &self.bias[i]);
                    out.root_v = linear(&a);
                    out.rates[i] = angular(&a);
                    a
                }
                (None, Root::Fixed) => {
                    out.rates[i] = zero3;
                    Vector6::from_element(Lanes::splat(0.0))
                }
                (parent, _) => {
                    let a_in = match parent {
                        Some(p) => self.x[i].motion(&self.accel[p]),
                        None => Vector6::from_element(Lanes::splat(0.0)),
                    } + self.velocity_product[i];
                    match link.joint.axis_motion().filter(|_| parent.is_some()) {
                        None => {
                            let big_u = self.articulated[i].fixed_view::<6, 3>(0, 0);
                            let qdd = self.d_inv[i] * (self.u[i] - big_u.tr_mul(&a_in));
                            out.rates[i] = qdd;
                            a_in + spatial(&qdd, &zero3)
                        }
                        Some(axis) => {
                            let qdd = self.axis_d_inv[i]
                                * (self.axis_force[i] - self.axis_u[i].dot(&a_in));
                            out.rates[i] = zero3;
                            out.qdd[i] = qdd;
                            a_in + splat6(&axis) * qdd
                        }
                    }
                }
            };
            self.accel[i] = a;
        }
        if model.root_held() {
            out.root_v = zero3;
        }
    }

    fn ball_inward(&mut self, model: &Model, loads: &LoadsLanes, i: usize) {
        let (before, rest) = self.articulated.split_at_mut(i);
        let ia = &rest[0];
        let d_inv = inverse3(&ia.fixed_view::<3, 3>(0, 0).into_owned());
        let u = loads.tau[i] - angular(&self.bias[i]);
        self.d_inv[i] = d_inv;
        self.u[i] = u;
        if let Some(p) = model.links[i].parent {
            let l = ia.fixed_view::<3, 3>(3, 0).into_owned();
            let k = ia.fixed_view::<3, 3>(3, 3) - l * d_inv * l.transpose();
            let k = (k + k.transpose()) * Lanes::splat(0.5);
            let zero3 = Vector3::from_element(Lanes::splat(0.0));
            let reduced_product = spatial(&zero3, &(k * linear(&self.velocity_product[i])));
            let pa = self.bias[i] + reduced_product + ia.fixed_view::<6, 3>(0, 0) * (d_inv * u);
            let zero33 = Matrix3::from_element(Lanes::splat(0.0));
            add_to_parent(&mut before[p], &self.x[i], &zero33, &zero33, &k);
            let f = self.x[i].force_to_parent(&pa);
            self.bias[p] += f;
        }
    }

    fn axis_inward(&mut self, model: &Model, loads: &LoadsLanes, i: usize, s: &Vector6<Lanes>) {
        let (before, rest) = self.articulated.split_at_mut(i);
        let ia = &rest[0];
        let big_u = ia * s;
        let d_inv = Lanes::splat(1.0) / (s.dot(&big_u) + loads.armature[i]);
        let u = loads.effort[i] - s.dot(&self.bias[i]);
        self.axis_u[i] = big_u;
        self.axis_d_inv[i] = d_inv;
        self.axis_force[i] = u;
        let p = model.links[i].parent.expect("a one-DOF joint has a parent");
        let reduced = ia - big_u * big_u.transpose() * d_inv;
        let reduced = (reduced + reduced.transpose()) * Lanes::splat(0.5);
        let pa = self.bias[i] + reduced * self.velocity_product[i] + big_u * (d_inv * u);
        add_to_parent(
            &mut before[p],
            &self.x[i],
            &reduced.fixed_view::<3, 3>(0, 0).into_owned(),
            &reduced.fixed_view::<3, 3>(0, 3).into_owned(),
            &reduced.fixed_view::<3, 3>(3, 3).into_owned(),
        );
        let f = self.x[i].force_to_parent(&pa);
        self.bias[p] += f;
    }
}

/// Adds `Xᵀ [A B; Bᵀ C] X` (a symmetric inertia in the child's frame) to
/// `parent` by its 3×3 blocks, not 6×6 products: with A', B', C' turned
/// into the parent's axes (`Eᵀ · E`) and r× the skew matrix of the child's
/// origin, it is [A' − B' r× + r× B'ᵀ − r× C' r×, B' + r× C'; (·)ᵀ, C'].
fn add_to_parent(
    parent: &mut Matrix6<Lanes>,
    x: &Transform<Lanes>,
    a: &Matrix3<Lanes>,
    b: &Matrix3<Lanes>,
    c: &Matrix3<Lanes>,
) {
    let turn = |m: &Matrix3<Lanes>| x.e.transpose() * m * x.e;
    let (a, b, c) = (turn(a), turn(b), turn(c));
    let rx = skew(&x.r);
    let rx_c = rx * c;
    let upper_right = b + rx_c;
    let upper_left = a - b * rx + rx * b.transpose() - rx_c * rx;
    let mut block = |row: usize, col: usize, m: &Matrix3<Lanes>| {
        let mut view = parent.fixed_view_mut::<3, 3>(row, col);
        view += m;
    };
    block(0, 0, &upper_left);
    block(0, 3, &upper_right);
    block(3, 0, &upper_right.transpose());
    block(3, 3, &c);
}

/// The rotation matrix of a unit quaternion.
fn rotation(q: &Quaternion<Lanes>) -> Matrix3<Lanes> {
    UnitQuaternion::new_unchecked(*q)
        .to_rotation_matrix()
        .into_inner()
}

/// The spatial velocity of link `i` relative to its parent (link frame).
fn joint_velocity(joint: &Joint, s: &StateLanes, i: usize) -> Vector6<Lanes> {
    match joint.axis_motion() {
        None => spatial(&s.rates[i], &Vector3::from_element(Lanes::splat(0.0))),
        Some(axis) => splat6(&axis) * s.qd[i],
    }
}

/// The inverse of a 3×3 matrix by its adjugate (the ball hinge's D, positive
/// definite for any finite state).
fn inverse3(m: &Matrix3<Lanes>) -> Matrix3<Lanes> {
    let c = |r0: usize, c0: usize, r1: usize, c1: usize| {
        m[(r0, c0)] * m[(r1, c1)] - m[(r0, c1)] * m[(r1, c0)]
    };
    let adj = Matrix3::new(
        c(1, 1, 2, 2),
        -c(0, 1, 2, 2),
        c(0, 1, 1, 2),
        -c(1, 0, 2, 2),
        c(0, 0, 2, 2),
        -c(0, 0, 1, 2),
        c(1, 0, 2, 1),
        -c(0, 0, 2, 1),
        c(0, 0, 1, 1),
    );
    let det = m[(0, 0)] * adj[(0, 0)] + m[(0, 1)] * adj[(1, 0)] + m[(0, 2)] * adj[(2, 0)];
    adj / det
}

/// Solves `a x = b` for a symmetric positive definite 6×6 `a` (a free root's
/// articulated inertia, scratch no longer needed) by Cholesky, overwriting
/// `a`'s lower triangle with the factor.
fn solve_spd6(l: &mut Matrix6<Lanes>, b: &Vector6<Lanes>) -> Vector6<Lanes> {
    use nalgebra::SimdComplexField;
    for j in 0..6 {
        let mut d = l[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        let d = d.simd_sqrt();
        l[(j, j)] = d;
        for i in j + 1..6 {
            let mut x = l[(i, j)];
            for k in 0..j {
                x -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = x / d;
        }
    }
    let mut y = *b;
    for i in 0..6 {
        for k in 0..i {
            let yk = y[k];
            y[i] -= l[(i, k)] * yk;
        }
        y[i] /= l[(i, i)];
    }
    for i in (0..6).rev() {
        for k in i + 1..6 {
            let yk = y[k];
            y[i] -= l[(k, i)] * yk;
        }
        y[i] /= l[(i, i)];
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::tests::{random_loads, random_mixed};
    use crate::dynamics::{Derivative, Kinematics, Workspace};
    use crate::integrate::{Forces, Stepper};
    use crate::{Integrator, dynamics};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Random trees of every joint and root kind, each with seven states
    /// (so the last group is padded) of its own loads.
    fn cases() -> Vec<(Model, Vec<State>, Vec<Loads>)> {
        let mut rng = ChaCha8Rng::seed_from_u64(46);
        (0..60)
            .map(|case| {
                let n = 1 + case % 10;
                let root = [Root::Free, Root::Pinned, Root::Fixed][case % 3];
                let (model, _) = random_mixed(&mut ChaCha8Rng::seed_from_u64(case as u64), n, root);
                let states = (0..7)
                    .map(|_| {
                        let (other, state) = random_mixed(&mut rng, n, root);
                        // The same tree, another state: keep the joints of `model`.
                        let mut state = state;
                        for i in 0..n {
                            if model.links[i].joint != other.links[i].joint {
                                state.orient[i] = UnitQuaternion::identity();
                                state.rates[i] = Vector3::zeros();
                                state.q[i] = 0.3 * i as f64;
                                state.qd[i] = -0.2 * i as f64;
                            }
                        }
                        if root != Root::Free {
                            state.root_v = Vector3::zeros();
                        }
                        state
                    })
                    .collect();
                let loads = (0..7).map(|_| random_loads(&mut rng, n, false)).collect();
                (model, states, loads)
            })
            .collect()
    }

    fn relative(a: f64, b: f64, scale: f64) -> f64 {
        (a - b).abs() / scale.max(1e-12)
    }

    /// Every state's accelerations equal the one-at-a-time algorithm's.
    #[test]
    fn accelerations_equal_one_at_a_time() {
        let mut worst: f64 = 0.0;
        for (case, (model, states, loads)) in cases().into_iter().enumerate() {
            let mut batch = Batch::pack(&model, &states, &loads);
            let (mut kin, mut ws) = (Kinematics::new(&model), Workspace::new(&model));
            let mut out = Derivative::zeros(&model);
            for (k, (state, load)) in states.iter().zip(&loads).enumerate() {
                kin.update(&model, state);
                ws.forward(&model, state, &kin, load, &mut out);
                let a = batch.accelerations(&model, k / LANES);
                let j = k % LANES;
                let mut expected: Vec<f64> = out.root_v.iter().copied().collect();
                let mut got: Vec<f64> = a.root_v.iter().map(|x| x.extract(j)).collect();
                for i in 0..model.len() {
                    expected.extend(out.rates[i].iter().chain([&out.qd[i]]));
                    got.extend(a.rates[i].iter().chain([&a.qdd[i]]).map(|x| x.extract(j)));
                }
                let scale = expected.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                for (e, g) in expected.iter().zip(&got) {
                    let error = relative(*e, *g, scale);
                    worst = worst.max(error);
                    assert!(error <= 1e-12, "case {case}, state {k}: {g} against {e}");
                }
            }
        }
        eprintln!("batched accelerations: worst relative difference {worst:e}");
    }

    /// Held loads, as the batch steps with.
    struct Held(Loads);

    impl Forces for Held {
        fn apply(&mut self, _: &Model, _: &State, _: &Kinematics, loads: &mut Loads) {
            loads.clone_from(&self.0);
        }
    }

    /// Ten semi-implicit Euler steps of every state equal the one-at-a-time
    /// stepper's, a free root's momentum tracking included.
    #[test]
    fn steps_equal_one_at_a_time() {
        let dt = 1e-3;
        for (case, (model, states, loads)) in cases().into_iter().enumerate() {
            let mut batch = Batch::pack(&model, &states, &loads);
            for _ in 0..10 {
                batch.step(&model, dt);
            }
            let mut stepped = states.clone();
            batch.unpack(&mut stepped);
            for (k, (state, load)) in states.iter().zip(&loads).enumerate() {
                let mut expected = state.clone();
                let mut stepper = Stepper::new(&model);
                let mut held = Held(load.clone());
                for _ in 0..10 {
                    stepper.step(
                        &model,
                        &mut expected,
                        dt,
                        Integrator::SemiImplicitEuler,
                        &mut held,
                    );
                }
                let got = &stepped[k];
                let mut kin = Kinematics::new(&model);
                kin.update(&model, &expected);
                let scale = 1.0 + dynamics::linear_momentum(&model, &kin).norm();
                let pairs = expected
                    .root_p
                    .iter()
                    .zip(got.root_p.iter())
                    .chain(expected.root_v.iter().zip(got.root_v.iter()))
                    .chain(expected.q.iter().zip(&got.q))
                    .chain(expected.qd.iter().zip(&got.qd))
                    .chain(
                        expected
                            .rates
                            .iter()
                            .zip(&got.rates)
                            .flat_map(|(a, b)| a.iter().zip(b.iter())),
                    )
                    .chain(expected.orient.iter().zip(&got.orient).flat_map(|(a, b)| {
                        a.coords.iter().zip(b.coords.iter()).collect::<Vec<_>>()
                    }));
                for (e, g) in pairs {
                    assert!(
                        relative(*e, *g, scale.max(e.abs())) <= 1e-10,
                        "case {case}, state {k}: {g} against {e}"
                    );
                }
            }
        }
    }
}
