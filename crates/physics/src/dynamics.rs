//! Forward dynamics of the link tree in O(n): Featherstone's articulated-body
//! algorithm, which for ball hinges is the recursive method of Armstrong and
//! Green (1985) that the paper's simulator used, over any mix of ball hinges
//! and one-DOF (revolute, prismatic) joints.
//!
//! Generalized coordinates: the root hinge's position (inertial frame) and
//! each ball-hinged link's orientation quaternion — the root's relative to
//! the inertial frame, every other link's relative to its parent — and each
//! one-DOF joint's position. Generalized velocities: the root's linear hinge
//! velocity and angular velocity (root frame; a pinned root has only the
//! latter, a fixed one neither), each ball hinge's relative angular velocity
//! in the child's frame, and each one-DOF joint's velocity.

use nalgebra::{Matrix3, Matrix6, Quaternion, Rotation3, Unit, UnitQuaternion, Vector3, Vector6};

use crate::model::{Joint, Link, Model, Root};
use crate::spatial::{Transform, angular, cross_force, cross_motion, linear, spatial};

/// The state of the link tree. Every per-link list has one entry per link;
/// an entry a link's joint does not use stays at rest (identity, zero).
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// Root hinge position, inertial frame (fixed for a pinned or fixed root).
    pub root_p: Vector3<f64>,
    /// Root hinge velocity, root frame (zero unless the root is free).
    pub root_v: Vector3<f64>,
    /// Orientations: `[0]` root → inertial, `[i]` ball-hinged link i → its
    /// parent.
    pub orient: Vec<UnitQuaternion<f64>>,
    /// Angular rates: `[0]` the root's angular velocity (root frame), `[i]`
    /// ball hinge i's relative angular velocity (link i frame).
    pub rates: Vec<Vector3<f64>>,
    /// One-DOF joint positions (rad or m).
    pub q: Vec<f64>,
    /// One-DOF joint velocities (rad/s or m/s).
    pub qd: Vec<f64>,
}

impl State {
    /// The model at rest: every joint at zero, root at `root_p`.
    pub fn rest(model: &Model, root_p: Vector3<f64>) -> State {
        State {
            root_p,
            root_v: Vector3::zeros(),
            orient: vec![UnitQuaternion::identity(); model.len()],
            rates: vec![Vector3::zeros(); model.len()],
            q: vec![0.0; model.len()],
            qd: vec![0.0; model.len()],
        }
    }

    /// Whether every number in the state is finite.
    pub fn is_finite(&self) -> bool {
        self.root_p
            .iter()
            .chain(&self.root_v)
            .chain(&self.q)
            .chain(&self.qd)
            .all(|x| x.is_finite())
            && self
                .orient
                .iter()
                .all(|q| q.coords.iter().all(|x| x.is_finite()))
            && self.rates.iter().all(|w| w.iter().all(|x| x.is_finite()))
    }
}

/// Time derivative of a [`State`] (accelerations from the dynamics).
#[derive(Clone, Debug)]
pub struct Derivative {
    pub root_p: Vector3<f64>,
    pub root_v: Vector3<f64>,
    pub orient: Vec<Quaternion<f64>>,
    pub rates: Vec<Vector3<f64>>,
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
}

impl Derivative {
    /// A zero derivative for `model`.
    pub fn zeros(model: &Model) -> Derivative {
        Derivative {
            root_p: Vector3::zeros(),
            root_v: Vector3::zeros(),
            orient: vec![Quaternion::identity() * 0.0; model.len()],
            rates: vec![Vector3::zeros(); model.len()],
            q: vec![0.0; model.len()],
            qd: vec![0.0; model.len()],
        }
    }
}

/// The forces on the tree at one instant, besides gravity.
#[derive(Clone, Debug)]
pub struct Loads {
    /// Ball hinge torques, applied to link i by its parent (link i frame);
    /// `tau[0]` acts on a pinned root from the world.
    pub tau: Vec<Vector3<f64>>,
    /// One-DOF joint efforts: torque about (or force along) the axis,
    /// applied to link i by its parent.
    pub effort: Vec<f64>,
    /// External spatial forces, link frame, at the hinge.
    pub f_ext: Vec<Vector6<f64>>,
    /// How each one-DOF joint's effort falls as its velocity rises and as
    /// its position rises, −∂effort/∂q̇ and −∂effort/∂q (its viscous
    /// damping, friction's slope, an engaged limit's damper and spring), for
    /// an integrator that takes them implicitly.
    pub effort_damping: Vec<f64>,
    pub effort_stiffness: Vec<f64>,
    /// Inertia added to each one-DOF joint's diagonal of the mass matrix:
    /// the dynamics solve (M + diag(armature)) q̈ = … (an implicit step's
    /// h b + h² k; zero otherwise).
    pub armature: Vec<f64>,
}

impl Loads {
    /// No forces, for `model`.
    pub fn zeros(model: &Model) -> Loads {
        Loads {
            tau: vec![Vector3::zeros(); model.len()],
            effort: vec![0.0; model.len()],
            f_ext: vec![Vector6::zeros(); model.len()],
            effort_damping: vec![0.0; model.len()],
            effort_stiffness: vec![0.0; model.len()],
            armature: vec![0.0; model.len()],
        }
    }

    /// Sets every force, and how efforts change, to zero.
    pub fn clear(&mut self) {
        self.tau.fill(Vector3::zeros());
        self.effort.fill(0.0);
        self.f_ext.fill(Vector6::zeros());
        self.effort_damping.fill(0.0);
        self.effort_stiffness.fill(0.0);
        self.armature.fill(0.0);
    }
}

/// Positions and velocities of every link, derived from a state.
#[derive(Clone, Debug)]
pub struct Kinematics {
    /// Link → inertial rotation.
    pub rot: Vec<Matrix3<f64>>,
    /// Hinge position, inertial frame.
    pub pos: Vec<Vector3<f64>>,
    /// Transform from the parent's frame (the inertial frame for the root).
    pub x: Vec<Transform>,
    /// Spatial velocity, link frame.
    pub vel: Vec<Vector6<f64>>,
}

impl Kinematics {
    /// Room for `model`.
    pub fn new(model: &Model) -> Kinematics {
        let n = model.len();
        Kinematics {
            rot: vec![Matrix3::identity(); n],
            pos: vec![Vector3::zeros(); n],
            x: vec![
                Transform {
                    e: Matrix3::identity(),
                    r: Vector3::zeros()
                };
                n
            ],
            vel: vec![Vector6::zeros(); n],
        }
    }

    /// Computes poses and velocities of every link of `state`.
    pub fn update(&mut self, model: &Model, state: &State) {
        for (i, link) in model.links.iter().enumerate() {
            match link.parent {
                None => {
                    let rel = state.orient[i].to_rotation_matrix().into_inner();
                    self.rot[i] = rel;
                    self.pos[i] = state.root_p;
                    self.x[i] = Transform {
                        e: rel.transpose(),
                        r: state.root_p,
                    };
                    self.vel[i] = match model.root {
                        Root::Free => spatial(&state.rates[i], &state.root_v),
                        Root::Pinned => spatial(&state.rates[i], &Vector3::zeros()),
                        Root::Fixed => Vector6::zeros(),
                    };
                }
                Some(p) => {
                    let (rel, r) = placement(link, state, i);
                    self.rot[i] = self.rot[p] * rel;
                    self.pos[i] = self.pos[p] + self.rot[p] * r;
                    self.x[i] = Transform {
                        e: rel.transpose(),
                        r,
                    };
                    self.vel[i] = self.x[i].motion(&self.vel[p]) + joint_velocity(link, state, i);
                }
            }
        }
    }

    /// Velocity of the point `d` (link `i` frame), inertial frame.
    pub fn point_velocity(&self, i: usize, d: &Vector3<f64>) -> Vector3<f64> {
        let v = &self.vel[i];
        self.rot[i] * (linear(v) + angular(v).cross(d))
    }

    /// Position of the point `d` (link `i` frame), inertial frame.
    pub fn point_position(&self, i: usize, d: &Vector3<f64>) -> Vector3<f64> {
        self.pos[i] + self.rot[i] * d
    }
}

/// A point fixed on one body of a model whose root is welded to the world,
/// placed from the one-DOF joint positions on the path from the root to the
/// body: the forward kinematics of one point, allocation-free, for a task's
/// cost evaluated at every predicted frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ChainPoint {
    /// The root's orientation and hinge position (inertial frame).
    root: (Matrix3<f64>, Vector3<f64>),
    /// The path's links, root's child first, and each one's joint and offset
    /// from its parent's hinge.
    path: Vec<(usize, Joint, Vector3<f64>)>,
    /// The point, in the body's frame.
    point: Vector3<f64>,
}

impl ChainPoint {
    /// The point `point` (frame of link `body`) of `model`, whose root is
    /// welded at `root_p` turned by `root_rot`. An error when a ball hinge
    /// lies on the path (its orientation is not one number).
    pub fn new(
        model: &Model,
        root_rot: Matrix3<f64>,
        root_p: Vector3<f64>,
        body: usize,
        point: Vector3<f64>,
    ) -> Result<ChainPoint, String> {
        let mut path = Vec::new();
        let mut i = body;
        while let Some(parent) = model.links[i].parent {
            let link = &model.links[i];
            if link.joint == Joint::Ball {
                return Err(format!("link {} hangs from a ball hinge", i + 1));
            }
            path.push((i, link.joint, link.l));
            i = parent;
        }
        path.reverse();
        Ok(ChainPoint {
            root: (root_rot, root_p),
            path,
            point,
        })
    }

    /// The links whose joint positions place the point, root's child first:
    /// the order [`ChainPoint::position`] reads them in.
    pub fn links(&self) -> impl Iterator<Item = usize> + '_ {
        self.path.iter().map(|p| p.0)
    }

    /// The point's position (inertial frame) when the `k`th link of
    /// [`ChainPoint::links`] has joint position `q(k)`.
    pub fn position(&self, q: impl Fn(usize) -> f64) -> Vector3<f64> {
        let (mut rot, mut pos) = self.root;
        for (k, (_, joint, l)) in self.path.iter().enumerate() {
            let (rel, r) = one_dof_placement(joint, l, q(k));
            pos += rot * r;
            rot *= rel;
        }
        pos + rot * self.point
    }

    /// A ball the point never leaves, whatever the joints do: its centre
    /// (the first joint's hinge, which no joint on the path moves) and
    /// radius (every later offset and the point's distance laid end to end,
    /// each prismatic joint stretched to `travel(link)`, its largest
    /// |position|). `None` when a prismatic joint's travel is unbounded.
    pub fn reach(&self, travel: impl Fn(usize) -> Option<f64>) -> Option<(Vector3<f64>, f64)> {
        let (rot, pos) = self.root;
        let Some((_, _, first)) = self.path.first() else {
            return Some((pos + rot * self.point, 0.0));
        };
        let mut radius = self.point.norm();
        for (k, (i, joint, l)) in self.path.iter().enumerate() {
            if k > 0 {
                radius += l.norm();
            }
            if let Joint::Prismatic { .. } = joint {
                radius += travel(*i)?;
            }
        }
        Some((pos + rot * first, radius))
    }
}

/// The rotation and hinge offset of a one-DOF joint's link at position `q`,
/// as [`placement`] gives them.
fn one_dof_placement(joint: &Joint, l: &Vector3<f64>, q: f64) -> (Matrix3<f64>, Vector3<f64>) {
    match *joint {
        Joint::Revolute { origin, axis } => {
            let turn = Rotation3::from_axis_angle(&Unit::new_unchecked(axis), q);
            (origin * turn.into_inner(), *l)
        }
        Joint::Prismatic { origin, axis } => (origin, l + origin * (axis * q)),
        Joint::Ball => unreachable!("a chain point's path has no ball hinge"),
    }
}

/// The rotation of link `i` relative to its parent (columns: its axes in
/// parent coordinates) and its hinge's position in the parent's frame.
fn placement(link: &Link, state: &State, i: usize) -> (Matrix3<f64>, Vector3<f64>) {
    match link.joint {
        Joint::Ball => (state.orient[i].to_rotation_matrix().into_inner(), link.l),
        _ => one_dof_placement(&link.joint, &link.l, state.q[i]),
    }
}

/// The spatial velocity of link `i` relative to its parent (link frame).
fn joint_velocity(link: &Link, state: &State, i: usize) -> Vector6<f64> {
    match link.joint.axis_motion() {
        None => spatial(&state.rates[i], &Vector3::zeros()),
        Some(s) => s * state.qd[i],
    }
}

/// Each one-DOF joint's effective inertia in `state`'s configuration: what
/// a torque on that joint alone meets with every other joint, and a free
/// base, free to move, 1 / (M⁻¹)ᵢᵢ. Where the joint's parent moves too it
/// is less than its link's own inertia about the axis (a humanoid's waist on
/// a floating base: 0.03 against 0.38 kg m²); where it carries more links,
/// more. None for a ball hinge or the root. One articulated-body pass per
/// joint, with no gravity and no velocity.
pub fn effective_inertias(model: &Model, state: &State) -> Vec<Option<f64>> {
    let mut still = model.clone();
    still.gravity = Vector3::zeros();
    // Each joint alone, a follower of a coupling too.
    still.couplings.clear();
    let at_rest = State {
        root_v: Vector3::zeros(),
        rates: vec![Vector3::zeros(); model.len()],
        qd: vec![0.0; model.len()],
        ..state.clone()
    };
    let mut kin = Kinematics::new(&still);
    kin.update(&still, &at_rest);
    let mut workspace = Workspace::new(&still);
    let mut loads = Loads::zeros(&still);
    let mut out = Derivative::zeros(&still);
    (0..model.len())
        .map(|i| {
            (i > 0 && model.links[i].joint.dof() == 1).then(|| {
                loads.clear();
                loads.effort[i] = 1.0;
                workspace.forward(&still, &at_rest, &kin, &loads, &mut out);
                1.0 / out.qd[i]
            })
        })
        .collect()
}

/// The parts of a state's derivative that are its pose's rates: each
/// orientation's, a free root's position's; and a held root's velocity
/// kept still.
fn pose_rates(model: &Model, state: &State, kin: &Kinematics, out: &mut Derivative) {
    for i in 0..model.len() {
        out.orient[i] = match (i, model.root) {
            // A welded root keeps its orientation whatever its rate says.
            (0, Root::Fixed) => Quaternion::identity() * 0.0,
            _ => *state.orient[i].quaternion() * Quaternion::from_imag(state.rates[i]) * 0.5,
        };
    }
    out.root_p = match model.root {
        Root::Free => kin.rot[0] * state.root_v,
        Root::Pinned | Root::Fixed => Vector3::zeros(),
    };
    if model.root_held() {
        out.root_v = Vector3::zeros();
    }
}

/// Scratch space of the articulated-body algorithm, allocated once per model
/// so that stepping allocates nothing.
#[derive(Clone, Debug)]
pub struct Workspace {
    inertia: Vec<Matrix6<f64>>,
    articulated: Vec<Matrix6<f64>>,
    bias: Vec<Vector6<f64>>,
    velocity_product: Vec<Vector6<f64>>,
    /// Ball hinges: D⁻¹ and u of the inward pass.
    d_inv: Vec<Matrix3<f64>>,
    u: Vec<Vector3<f64>>,
    /// One-DOF joints: U = IA s, 1/D and u of the inward pass.
    axis_u: Vec<Vector6<f64>>,
    axis_d_inv: Vec<f64>,
    axis_force: Vec<f64>,
    /// Spatial acceleration of every link, link frame (after [`Workspace::forward`]).
    pub accel: Vec<Vector6<f64>>,
}

impl Workspace {
    /// Scratch space for `model`.
    pub fn new(model: &Model) -> Workspace {
        let n = model.len();
        Workspace {
            inertia: model.links.iter().map(|l| l.spatial_inertia()).collect(),
            articulated: vec![Matrix6::zeros(); n],
            bias: vec![Vector6::zeros(); n],
            velocity_product: vec![Vector6::zeros(); n],
            d_inv: vec![Matrix3::zeros(); n],
            u: vec![Vector3::zeros(); n],
            axis_u: vec![Vector6::zeros(); n],
            axis_d_inv: vec![0.0; n],
            axis_force: vec![0.0; n],
            accel: vec![Vector6::zeros(); n],
        }
    }

    /// The articulated-body algorithm: from the kinematics and the `loads`
    /// (gravity is added here; a ball hinge torque on a free root is
    /// ignored), writes the state's derivative into `out`. A model with
    /// couplings goes to the dense joint-space solve instead
    /// ([`Workspace::forward_coupled`]), which allocates.
    // The three passes index several per-link arrays by link number.
    #[allow(clippy::needless_range_loop)]
    pub fn forward(
        &mut self,
        model: &Model,
        state: &State,
        kin: &Kinematics,
        loads: &Loads,
        out: &mut Derivative,
    ) {
        if !model.couplings.is_empty() {
            return self.forward_coupled(model, state, kin, loads, out);
        }
        let n = model.len();
        // Outward: velocity-product accelerations and bias forces.
        for i in 0..n {
            let link = &model.links[i];
            let v = kin.vel[i];
            let inertia = &self.inertia[i];
            self.velocity_product[i] = match link.parent {
                Some(_) => cross_motion(&v, &joint_velocity(link, state, i)),
                None => Vector6::zeros(),
            };
            self.articulated[i] = *inertia;
            let gravity = link.mass * (kin.rot[i].transpose() * model.gravity);
            let f_gravity = spatial(&link.c.cross(&gravity), &gravity);
            self.bias[i] = cross_force(&v, &(inertia * v)) - loads.f_ext[i] - f_gravity;
        }
        // Inward: articulated inertias and bias forces. A free root is
        // solved whole on the way out; a fixed one does not move.
        for i in (0..n).rev() {
            if i == 0 && model.root != Root::Pinned {
                continue;
            }
            match model.links[i].joint.axis_motion().filter(|_| i > 0) {
                None => self.ball_inward(model, kin, loads, i),
                Some(s) => self.axis_inward(model, kin, loads, i, &s),
            }
        }
        // Outward: accelerations.
        for i in 0..n {
            let link = &model.links[i];
            out.q[i] = 0.0;
            out.qd[i] = 0.0;
            let a = match (link.parent, model.root) {
                (None, Root::Free) => {
                    let a = match self.articulated[i].cholesky() {
                        Some(c) => -c.solve(&self.bias[i]),
                        None => Vector6::from_element(f64::NAN),
                    };
                    out.root_v = linear(&a);
                    out.rates[i] = angular(&a);
                    a
                }
                (None, Root::Fixed) => {
                    out.rates[i] = Vector3::zeros();
                    Vector6::zeros()
                }
                (parent, _) => {
                    let a_in = match parent {
                        Some(p) => kin.x[i].motion(&self.accel[p]),
                        None => Vector6::zeros(),
                    } + self.velocity_product[i];
                    match link.joint.axis_motion().filter(|_| parent.is_some()) {
                        None => {
                            let big_u = self.articulated[i].fixed_view::<6, 3>(0, 0).into_owned();
                            let qdd = self.d_inv[i] * (self.u[i] - big_u.transpose() * a_in);
                            out.rates[i] = qdd;
                            a_in + spatial(&qdd, &Vector3::zeros())
                        }
                        Some(s) => {
                            let qdd = self.axis_d_inv[i]
                                * (self.axis_force[i] - self.axis_u[i].dot(&a_in));
                            out.rates[i] = Vector3::zeros();
                            out.q[i] = state.qd[i];
                            out.qd[i] = qdd;
                            a_in + s * qdd
                        }
                    }
                }
            };
            self.accel[i] = a;
        }
        pose_rates(model, state, kin, out);
    }

    /// [`Workspace::forward`] for a model with couplings, which the
    /// articulated-body algorithm cannot take: the accelerations of the
    /// joint-space formulation in the coordinates that remain
    /// ([`crate::joint_space::coupled_accelerations`]), then each link's
    /// spatial acceleration from them as the algorithm's last pass gives it.
    fn forward_coupled(
        &mut self,
        model: &Model,
        state: &State,
        kin: &Kinematics,
        loads: &Loads,
        out: &mut Derivative,
    ) {
        let qdd = crate::joint_space::coupled_accelerations(model, state, kin, loads);
        let mut at = 0;
        for i in 0..model.len() {
            let link = &model.links[i];
            out.q[i] = 0.0;
            out.qd[i] = 0.0;
            out.rates[i] = Vector3::zeros();
            let a = match (link.parent, model.root) {
                (None, Root::Free) => {
                    out.rates[i] = Vector3::new(qdd[0], qdd[1], qdd[2]);
                    out.root_v = Vector3::new(qdd[3], qdd[4], qdd[5]);
                    at = 6;
                    spatial(&out.rates[i], &out.root_v)
                }
                (None, Root::Fixed) => Vector6::zeros(),
                (parent, _) => {
                    let a_in = match parent {
                        Some(p) => {
                            kin.x[i].motion(&self.accel[p])
                                + cross_motion(&kin.vel[i], &joint_velocity(link, state, i))
                        }
                        None => Vector6::zeros(),
                    };
                    match link.joint.axis_motion().filter(|_| parent.is_some()) {
                        None => {
                            out.rates[i] = Vector3::new(qdd[at], qdd[at + 1], qdd[at + 2]);
                            at += 3;
                            a_in + spatial(&out.rates[i], &Vector3::zeros())
                        }
                        Some(s) => {
                            out.q[i] = state.qd[i];
                            out.qd[i] = qdd[at];
                            at += 1;
                            a_in + s * out.qd[i]
                        }
                    }
                }
            };
            self.accel[i] = a;
        }
        pose_rates(model, state, kin, out);
    }

    /// The inward step of a ball hinge (or a pinned root).
    fn ball_inward(&mut self, model: &Model, kin: &Kinematics, loads: &Loads, i: usize) {
        let ia = self.articulated[i];
        let d = ia.fixed_view::<3, 3>(0, 0).into_owned();
        // Positive definite for any finite state; a blown-up (non-finite)
        // state yields NaN accelerations, which the caller reports.
        let d_inv = d.try_inverse().unwrap_or(Matrix3::from_element(f64::NAN));
        let u = loads.tau[i] - angular(&self.bias[i]);
        self.d_inv[i] = d_inv;
        self.u[i] = u;
        if let Some(p) = model.links[i].parent {
            // A ball hinge passes on no rotational inertia: the reduced
            // inertia IA − U D⁻¹ Uᵀ is zero but for its linear block,
            // the Schur complement K = C − L D⁻¹ Lᵀ of IA = [D Lᵀ; L C].
            // Forming only K (exactly symmetric) avoids the cancellation
            // that, for thin links, grows into an indefinite root inertia
            // along long chains.
            let l = ia.fixed_view::<3, 3>(3, 0).into_owned();
            let c = ia.fixed_view::<3, 3>(3, 3).into_owned();
            let k = c - l * d_inv * l.transpose();
            let k = (k + k.transpose()) * 0.5;
            let big_u = ia.fixed_view::<6, 3>(0, 0).into_owned();
            let reduced_product =
                spatial(&Vector3::zeros(), &(k * linear(&self.velocity_product[i])));
            let pa = self.bias[i] + reduced_product + big_u * (d_inv * u);
            let x = kin.x[i];
            add_linear_inertia_to_parent(&mut self.articulated[p], &x, &k);
            self.bias[p] += x.force_to_parent(&pa);
        }
    }

    /// The inward step of a one-DOF joint with motion subspace `s`.
    fn axis_inward(
        &mut self,
        model: &Model,
        kin: &Kinematics,
        loads: &Loads,
        i: usize,
        s: &Vector6<f64>,
    ) {
        let ia = self.articulated[i];
        let big_u = ia * s;
        // Positive for any finite state (s ≠ 0 and a positive mass on the
        // joint's side); NaN otherwise, which the caller reports. Armature
        // adds to the mass matrix's diagonal exactly here, as a motor's
        // rotor inertia does.
        let d_inv = 1.0 / (s.dot(&big_u) + loads.armature[i]);
        let u = loads.effort[i] - s.dot(&self.bias[i]);
        self.axis_u[i] = big_u;
        self.axis_d_inv[i] = d_inv;
        self.axis_force[i] = u;
        let p = model.links[i].parent.expect("a one-DOF joint has a parent");
        let reduced = ia - big_u * big_u.transpose() * d_inv;
        let reduced = (reduced + reduced.transpose()) * 0.5;
        let pa = self.bias[i] + reduced * self.velocity_product[i] + big_u * (d_inv * u);
        let x = kin.x[i];
        let xm = x.matrix();
        self.articulated[p] += xm.transpose() * reduced * xm;
        self.bias[p] += x.force_to_parent(&pa);
    }
}

/// Adds `Xᵀ [0 0; 0 K] X` to `parent`: an inertia with only a linear block
/// `K` (child frame) moved to the parent's frame. With K' = Eᵀ K E and
/// r× the skew matrix of the child's origin, it is [−r× K' r×, r× K'; −K' r×, K'].
fn add_linear_inertia_to_parent(parent: &mut Matrix6<f64>, x: &Transform, k: &Matrix3<f64>) {
    let k_parent = x.e.transpose() * k * x.e;
    let rx = crate::spatial::skew(&x.r);
    let upper_right = rx * k_parent;
    let mut block = |row: usize, col: usize, m: &Matrix3<f64>| {
        let mut view = parent.fixed_view_mut::<3, 3>(row, col);
        view += m;
    };
    block(0, 0, &(-upper_right * rx));
    block(0, 3, &upper_right);
    block(3, 0, &upper_right.transpose());
    block(3, 3, &k_parent);
}

/// Total energy: kinetic plus gravitational potential (zero at z = 0 for
/// gravity along −z).
pub fn energy(model: &Model, kin: &Kinematics) -> f64 {
    model
        .links
        .iter()
        .enumerate()
        .map(|(i, link)| {
            let v = kin.vel[i];
            let kinetic = 0.5 * v.dot(&(link.spatial_inertia() * v));
            let com = kin.point_position(i, &link.c);
            kinetic - link.mass * model.gravity.dot(&com)
        })
        .sum()
}

/// Linear momentum, inertial frame.
pub fn linear_momentum(model: &Model, kin: &Kinematics) -> Vector3<f64> {
    (0..model.len())
        .map(|i| kin.point_velocity(i, &model.links[i].c) * model.links[i].mass)
        .sum()
}

/// Angular momentum about the inertial origin, inertial frame.
pub fn angular_momentum(model: &Model, kin: &Kinematics) -> Vector3<f64> {
    (0..model.len())
        .map(|i| {
            let link = &model.links[i];
            let com = kin.point_position(i, &link.c);
            let v_com = kin.point_velocity(i, &link.c);
            let spin = kin.rot[i] * (link.inertia_com * angular(&kin.vel[i]));
            spin + com.cross(&v_com) * link.mass
        })
        .sum()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::Integrator;
    use crate::integrate::{Evaluation, Forces, NoForces, Stepper};
    use crate::joint_space::{forward_dense, generalized_acceleration};
    use crate::model::{Link, Shape};
    use rand::{Rng, RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn vec3(rng: &mut impl Rng, scale: f64) -> Vector3<f64> {
        Vector3::new(
            rng.random_range(-scale..scale),
            rng.random_range(-scale..scale),
            rng.random_range(-scale..scale),
        )
    }

    fn random_model(rng: &mut ChaCha8Rng, n: usize, root: Root) -> Model {
        let links = (0..n)
            .map(|i| {
                let a = Matrix3::from_fn(|_, _| rng.random_range(-0.3..0.3));
                Link {
                    parent: (i > 0).then(|| rng.random_range(0..i)),
                    joint: Joint::Ball,
                    mass: rng.random_range(0.2..5.0),
                    c: vec3(rng, 0.5),
                    inertia_com: a * a.transpose() + Matrix3::identity() * 0.01,
                    l: vec3(rng, 1.0),
                    tip: None,
                }
            })
            .collect();
        Model {
            root,
            links,
            gravity: vec3(rng, 10.0),
            couplings: Vec::new(),
        }
    }

    fn random_state(rng: &mut ChaCha8Rng, model: &Model) -> State {
        State {
            root_p: vec3(rng, 2.0),
            root_v: if model.root == Root::Free {
                vec3(rng, 2.0)
            } else {
                Vector3::zeros()
            },
            orient: (0..model.len())
                .map(|_| UnitQuaternion::from_scaled_axis(vec3(rng, 3.0)))
                .collect(),
            rates: (0..model.len()).map(|_| vec3(rng, 2.0)).collect(),
            q: vec![0.0; model.len()],
            qd: vec![0.0; model.len()],
        }
    }

    /// A random tree of ball, revolute and prismatic joints with turned
    /// joint frames, and a state with every joint moving.
    pub(crate) fn random_mixed(rng: &mut ChaCha8Rng, n: usize, root: Root) -> (Model, State) {
        let mut model = random_model(rng, n, root);
        for link in model.links.iter_mut().skip(1) {
            let origin = *nalgebra::Rotation3::from_scaled_axis(vec3(rng, 3.0)).matrix();
            let axis = vec3(rng, 1.0).normalize();
            link.joint = match rng.random_range(0..3) {
                0 => Joint::Ball,
                1 => Joint::Revolute { origin, axis },
                _ => Joint::Prismatic { origin, axis },
            };
        }
        let mut state = random_state(rng, &model);
        for i in 1..n {
            if model.links[i].joint != Joint::Ball {
                state.orient[i] = UnitQuaternion::identity();
                state.rates[i] = Vector3::zeros();
                state.q[i] = rng.random_range(-3.0..3.0);
                state.qd[i] = rng.random_range(-2.0..2.0);
            }
        }
        if root == Root::Fixed {
            state.rates[0] = Vector3::zeros();
        }
        (model, state)
    }

    /// Random torques, efforts and external forces; with `armature`,
    /// random armatures up to 0.5 on every one-DOF joint too.
    pub(crate) fn random_loads(rng: &mut ChaCha8Rng, n: usize, armature: bool) -> Loads {
        let mut loads = Loads {
            tau: (0..n).map(|_| vec3(rng, 20.0)).collect(),
            effort: (0..n).map(|_| rng.random_range(-20.0..20.0)).collect(),
            f_ext: (0..n)
                .map(|_| spatial(&vec3(rng, 10.0), &vec3(rng, 50.0)))
                .collect(),
            effort_damping: vec![0.0; n],
            effort_stiffness: vec![0.0; n],
            armature: vec![0.0; n],
        };
        if armature {
            loads.armature = (0..n).map(|_| rng.random_range(0.0..0.5)).collect();
        }
        loads
    }

    /// The kinematics of `state` and its derivative by the articulated-body
    /// algorithm under `loads`.
    fn articulated(model: &Model, state: &State, loads: &Loads) -> (Kinematics, Derivative) {
        let mut kin = Kinematics::new(model);
        kin.update(model, state);
        let mut out = Derivative::zeros(model);
        Workspace::new(model).forward(model, state, &kin, loads, &mut out);
        (kin, out)
    }

    /// The relative error of the articulated-body algorithm's accelerations
    /// against the dense formulation's.
    fn error_against_dense(model: &Model, state: &State, loads: &Loads) -> f64 {
        let (kin, out) = articulated(model, state, loads);
        let dense = forward_dense(model, state, &kin, loads);
        let aba = generalized_acceleration(model, &out);
        (&aba - &dense).norm() / dense.norm().max(1e-12)
    }

    /// The articulated-body algorithm over mixed joints and every kind of
    /// root against M q̈ = τ − C, every other case with armatures on the
    /// one-DOF joints, (M + diag(armature)) q̈ = τ − C.
    #[test]
    fn mixed_joints_match_the_dense_formulation() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut worst: f64 = 0.0;
        for case in 0..150 {
            let n = 1 + case % 12;
            let root = [Root::Free, Root::Pinned, Root::Fixed][case % 3];
            let (model, state) = random_mixed(&mut rng, n, root);
            let loads = random_loads(&mut rng, n, case % 2 == 1);
            let error = error_against_dense(&model, &state, &loads);
            worst = worst.max(error);
            assert!(
                error <= 1e-9,
                "case {case} ({n} links, {root:?}): relative error {error:e}"
            );
        }
        eprintln!("mixed joints: worst relative error over 150 random trees: {worst:e}");
    }

    /// The holding efforts hold a tree of one-DOF joints still against
    /// gravity (its accelerations zero, within rounding of gravity's), a
    /// coupled one's leaders carrying their followers; each joint's mass
    /// matrix entry is twice the kinetic energy of a unit velocity of that
    /// joint alone (its leader's, with its followers, where coupled).
    #[test]
    fn holding_efforts_hold_a_tree_still_and_its_inertias_are_its_energy() {
        use crate::joint_space::holding_efforts;
        use crate::model::Coupling;
        let mut rng = ChaCha8Rng::seed_from_u64(62);
        for case in 0..80 {
            let n = 2 + case % 9;
            let (mut model, mut state) = random_mixed(&mut rng, n, Root::Fixed);
            for i in 1..n {
                if model.links[i].joint == Joint::Ball {
                    let axis = vec3(&mut rng, 1.0).normalize();
                    let origin = Matrix3::identity();
                    model.links[i].joint = Joint::Revolute { origin, axis };
                    state.orient[i] = UnitQuaternion::identity();
                    state.rates[i] = Vector3::zeros();
                }
            }
            if case % 2 == 1 && n >= 3 {
                model.couplings.push(Coupling {
                    follower: n - 1,
                    leader: 1,
                    multiplier: rng.random_range(-2.0..2.0),
                    offset: rng.random_range(-0.5..0.5),
                });
                model.impose_couplings(&mut state);
            }
            state.qd.fill(0.0);
            let held = holding_efforts(&model, &state);
            assert_eq!(held[0], None);
            let mut loads = Loads::zeros(&model);
            for (i, &h) in held.iter().enumerate().skip(1) {
                match (h, model.coupling(i)) {
                    (Some(hold), None) => loads.effort[i] = hold.effort,
                    (None, Some(_)) => {}
                    other => panic!("case {case}, link {i}: {other:?}"),
                }
            }
            let (_, still) = articulated(&model, &state, &loads);
            let scale = model.gravity.norm();
            for i in 1..n {
                assert!(
                    still.qd[i].abs() <= 1e-9 * scale,
                    "case {case}, link {i}: held, it accelerates at {}",
                    still.qd[i]
                );
            }
            let kinetic = |qd: &[f64]| {
                let mut moving = State {
                    qd: qd.to_vec(),
                    ..state.clone()
                };
                model.impose_couplings(&mut moving);
                let mut kin = Kinematics::new(&model);
                kin.update(&model, &moving);
                (0..n)
                    .map(|i| {
                        let v = kin.vel[i];
                        0.5 * v.dot(&(model.links[i].spatial_inertia() * v))
                    })
                    .sum::<f64>()
            };
            for (i, h) in held.iter().enumerate() {
                if let Some(crate::joint_space::Holding { inertia, .. }) = h {
                    let mut unit = vec![0.0; n];
                    unit[i] = 1.0;
                    let expected = 2.0 * kinetic(&unit);
                    assert!(
                        (inertia - expected).abs() <= 1e-9 * expected.max(1.0),
                        "case {case}, link {i}: {inertia} against {expected}"
                    );
                }
            }
        }
    }

    /// Issue 45, precision at speed: the joints' accelerations do not
    /// depend on a uniform velocity of the whole robot (Galilean
    /// invariance), so a free-based tree falling at 100 m/s should give the
    /// joint accelerations it gives at rest. Over these trees they move by
    /// up to 1.1e-12 of their scale: the digits lost at speed, as the
    /// velocity-product and bias terms of every link carry the base's
    /// 100 m/s and cancel. (Pinocchio's `aba` loses as many: 6e-11 on g1
    /// at 98 m/s.) Evaluating in a frame moving with the base would keep
    /// them; it would change every free-rooted scene's bits, so this test
    /// guards what is kept now.
    #[test]
    fn a_free_base_at_100_m_per_s_moves_its_joint_accelerations_by_about_a_trillionth() {
        let mut rng = ChaCha8Rng::seed_from_u64(45);
        let mut worst: f64 = 0.0;
        for case in 0..60 {
            let n = 2 + case % 12;
            let (model, state) = random_mixed(&mut rng, n, Root::Free);
            let loads = Loads {
                f_ext: vec![Vector6::zeros(); n],
                ..random_loads(&mut rng, n, false)
            };
            let at_rest = articulated(&model, &state, &loads).1;
            let mut falling = state.clone();
            // 100 m/s downwards in the world, in the root's frame.
            falling.root_v += state.orient[0].inverse() * Vector3::new(0.0, 0.0, -100.0);
            let fast = articulated(&model, &falling, &loads).1;
            let scale = at_rest
                .qd
                .iter()
                .chain(at_rest.rates.iter().flat_map(|r| r.iter()))
                .fold(1.0f64, |m, x| m.max(x.abs()));
            for i in 1..n {
                worst = worst.max((fast.qd[i] - at_rest.qd[i]).abs() / scale);
                worst = worst.max((fast.rates[i] - at_rest.rates[i]).amax() / scale);
            }
            worst = worst.max((fast.rates[0] - at_rest.rates[0]).amax() / scale);
        }
        eprintln!("at 100 m/s, joint accelerations move by at most {worst:e} of their scale");
        assert!(worst <= 5e-12, "{worst:e}");
    }

    /// Hard case 1: the articulated-body algorithm against M q̈ = τ − C.
    #[test]
    fn articulated_body_algorithm_matches_the_dense_formulation() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut worst: f64 = 0.0;
        for case in 0..120 {
            let n = 1 + case % 16;
            let root = if case % 3 == 0 {
                Root::Pinned
            } else {
                Root::Free
            };
            let model = random_model(&mut rng, n, root);
            let state = random_state(&mut rng, &model);
            let loads = Loads {
                tau: (0..n).map(|_| vec3(&mut rng, 20.0)).collect(),
                effort: vec![0.0; n],
                f_ext: (0..n)
                    .map(|_| spatial(&vec3(&mut rng, 10.0), &vec3(&mut rng, 50.0)))
                    .collect(),
                ..Loads::zeros(&model)
            };
            let error = error_against_dense(&model, &state, &loads);
            worst = worst.max(error);
            assert!(
                error <= 1e-9,
                "case {case} ({n} links, {root:?}): relative error {error:e}"
            );
        }
        eprintln!("worst relative error over 120 random trees: {worst:e}");
    }

    fn free_chain(n: usize) -> Model {
        let shapes: Vec<(Shape, f64)> = (0..n)
            .map(|i| {
                (
                    Shape::Box([0.4 + 0.1 * i as f64, 0.15, 0.1]),
                    1.0 + 0.5 * i as f64,
                )
            })
            .collect();
        Model::chain(Root::Free, &shapes, Vector3::zeros())
    }

    fn tumbling(model: &Model, seed: u64) -> State {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        State {
            root_p: Vector3::zeros(),
            ..random_state(&mut rng, model)
        }
    }

    struct Drift {
        momentum: f64,
        angular: f64,
        energy: f64,
    }

    fn drift(model: &Model, dt: f64, seconds: f64, integrator: Integrator) -> Drift {
        let mut state = tumbling(model, 9);
        let mut stepper = Stepper::new(model);
        let mut eval = Evaluation::new(model);
        eval.run(model, &state, &mut NoForces);
        let (p0, l0, e0) = (
            linear_momentum(model, &eval.kin),
            angular_momentum(model, &eval.kin),
            energy(model, &eval.kin),
        );
        for _ in 0..(seconds / dt).round() as usize {
            stepper.step(model, &mut state, dt, integrator, &mut NoForces);
        }
        eval.run(model, &state, &mut NoForces);
        Drift {
            momentum: (linear_momentum(model, &eval.kin) - p0).norm() / p0.norm(),
            angular: (angular_momentum(model, &eval.kin) - l0).norm() / l0.norm(),
            energy: ((energy(model, &eval.kin) - e0) / e0).abs(),
        }
    }

    /// Hard case 2: a free chain without gravity conserves momentum and energy.
    #[test]
    fn free_chain_conserves_momentum_and_energy() {
        let model = free_chain(4);
        let euler = drift(&model, 1e-3, 10.0, Integrator::SemiImplicitEuler);
        assert!(
            euler.momentum <= 1e-9,
            "semi-implicit Euler momentum drift {:e}",
            euler.momentum
        );
        let rk4 = drift(&model, 1e-3, 10.0, Integrator::Rk4);
        assert!(
            rk4.momentum <= 1e-9,
            "RK4 momentum drift {:e}",
            rk4.momentum
        );
        assert!(
            rk4.angular <= 1e-6,
            "RK4 angular momentum drift {:e}",
            rk4.angular
        );
        assert!(rk4.energy <= 1e-6, "RK4 energy drift {:e}", rk4.energy);
        let half = drift(&model, 5e-4, 10.0, Integrator::Rk4);
        assert!(
            rk4.energy >= 10.0 * half.energy,
            "energy drift {:e} at dt = 1 ms, {:e} at 0.5 ms: not fourth order",
            rk4.energy,
            half.energy
        );
        eprintln!(
            "free chain, 10 s: RK4 energy drift {:e} (dt 1 ms), {:e} (0.5 ms); angular {:e}",
            rk4.energy, half.energy, rk4.angular
        );
    }

    /// A torque between two links is internal: it changes no momentum.
    #[test]
    fn hinge_torques_are_internal() {
        struct Twist;
        impl Forces for Twist {
            fn apply(&mut self, _: &Model, _: &State, _: &Kinematics, loads: &mut Loads) {
                loads.clear();
                loads.tau.fill(Vector3::new(0.02, -0.01, 0.01));
            }
        }
        let model = free_chain(3);
        let mut state = tumbling(&model, 4);
        let mut stepper = Stepper::new(&model);
        let mut eval = Evaluation::new(&model);
        eval.run(&model, &state, &mut NoForces);
        let (p0, l0) = (
            linear_momentum(&model, &eval.kin),
            angular_momentum(&model, &eval.kin),
        );
        for _ in 0..2000 {
            stepper.step(&model, &mut state, 1e-3, Integrator::Rk4, &mut Twist);
        }
        eval.run(&model, &state, &mut NoForces);
        let dp = (linear_momentum(&model, &eval.kin) - p0).norm() / p0.norm();
        assert!(dp < 1e-9, "linear momentum drift {dp:e}");
        let dl = (angular_momentum(&model, &eval.kin) - l0).norm() / l0.norm();
        assert!(dl < 1e-6, "angular momentum drift {dl:e}");
    }

    /// Hard case 4: an asymmetric body spinning at 100 rad/s.
    #[test]
    fn fast_tumbler_stays_finite_with_bounded_energy_drift() {
        let model = Model::chain(
            Root::Free,
            &[(Shape::Box([0.4, 0.2, 0.1]), 1.0)],
            Vector3::zeros(),
        );
        for integrator in [Integrator::SemiImplicitEuler, Integrator::Rk4] {
            let mut state = State::rest(&model, Vector3::zeros());
            state.rates[0] = Vector3::new(1.0, 100.0, 0.5);
            let mut stepper = Stepper::new(&model);
            stepper.eval.run(&model, &state, &mut NoForces);
            let e0 = energy(&model, &stepper.eval.kin);
            for _ in 0..100_000 {
                stepper.step(&model, &mut state, 1e-4, integrator, &mut NoForces);
            }
            assert!(state.is_finite(), "{integrator:?}");
            assert!((state.orient[0].quaternion().norm() - 1.0).abs() < 1e-12);
            stepper.eval.run(&model, &state, &mut NoForces);
            let drift = ((energy(&model, &stepper.eval.kin) - e0) / e0).abs();
            if integrator == Integrator::Rk4 {
                assert!(drift < 1e-6, "RK4 energy drift {drift:e} over 1e5 steps");
                eprintln!("tumbler at 100 rad/s, 1e5 RK4 steps of 0.1 ms: energy drift {drift:e}");
            }
        }
    }
}
