//! The joint-space formulation of the forward dynamics: the recursive
//! Newton–Euler algorithm gives the generalized forces for given
//! accelerations; from it the joint-space mass matrix M and the bias C, and
//! the accelerations by solving M q̈ = τ − C densely. The simulator uses it
//! for a model whose joints are coupled ([`coupled_accelerations`]), which
//! the articulated-body algorithm cannot take; the tests check that
//! algorithm against it. A planner's PD baseline reads its holding efforts
//! and mass matrix diagonal ([`holding_efforts`]).

use nalgebra::{DMatrix, DVector, Vector3, Vector6};

use crate::dynamics::{Kinematics, Loads, State};
use crate::model::{Model, Root};
use crate::spatial::{cross_force, cross_motion, spatial};

/// The generalized velocity vector's layout: for each link, where its
/// entries start and how many there are — a free root's angular then linear
/// velocity (6), a pinned root's 3, a fixed root none; a ball hinge's 3, a
/// one-DOF joint's 1.
fn offsets(model: &Model) -> Vec<(usize, usize)> {
    let mut at = 0;
    (0..model.len())
        .map(|i| {
            let here = at;
            let width = match (i, model.root) {
                (0, Root::Free) => 6,
                (0, Root::Pinned) => 3,
                (0, Root::Fixed) => 0,
                _ => model.links[i].joint.dof(),
            };
            at += width;
            (here, width)
        })
        .collect()
}

/// The columns of link `i`'s motion subspace S (link frame): unit joint
/// velocities in the generalized vector's order.
fn subspace(model: &Model, i: usize) -> Vec<Vector6<f64>> {
    let unit = |k: usize| Vector6::from_fn(|r, _| if r == k { 1.0 } else { 0.0 });
    match (i, model.root) {
        (0, Root::Free) => (0..6).map(unit).collect(),
        (0, Root::Pinned) => (0..3).map(unit).collect(),
        (0, Root::Fixed) => Vec::new(),
        _ => match model.links[i].joint.axis_motion() {
            Some(s) => vec![s],
            None => (0..3).map(unit).collect(),
        },
    }
}

/// The generalized velocities of a state, in [`offsets`]' layout.
pub fn generalized_velocity(model: &Model, state: &State) -> DVector<f64> {
    let at = offsets(model);
    let mut v = DVector::zeros(model.dof());
    for (i, &(start, width)) in at.iter().enumerate() {
        let values: Vec<f64> = match width {
            6 => state.rates[0]
                .iter()
                .chain(&state.root_v)
                .copied()
                .collect(),
            3 => state.rates[i].iter().copied().collect(),
            1 => vec![state.qd[i]],
            _ => Vec::new(),
        };
        v.rows_mut(start, width).copy_from_slice(&values);
    }
    v
}

/// Generalized forces needed for accelerations `qdd` (recursive Newton–Euler).
fn inverse_dynamics(
    model: &Model,
    state: &State,
    kin: &Kinematics,
    qdd: &DVector<f64>,
    f_ext: &[Vector6<f64>],
) -> DVector<f64> {
    let n = model.len();
    let at = offsets(model);
    let v = generalized_velocity(model, state);
    let mut accel = vec![Vector6::zeros(); n];
    let mut force = vec![Vector6::zeros(); n];
    for i in 0..n {
        let link = &model.links[i];
        let s = subspace(model, i);
        let (start, _) = at[i];
        let joint_motion = |x: &DVector<f64>| -> Vector6<f64> {
            s.iter()
                .enumerate()
                .map(|(k, col)| col * x[start + k])
                .sum()
        };
        let a = match link.parent {
            None => joint_motion(qdd),
            Some(p) => {
                kin.x[i].motion(&accel[p])
                    + joint_motion(qdd)
                    + cross_motion(&kin.vel[i], &joint_motion(&v))
            }
        };
        accel[i] = a;
        let inertia = link.spatial_inertia();
        let gravity = link.mass * (kin.rot[i].transpose() * model.gravity);
        let f_gravity = spatial(&link.c.cross(&gravity), &gravity);
        force[i] =
            inertia * a + cross_force(&kin.vel[i], &(inertia * kin.vel[i])) - f_ext[i] - f_gravity;
    }
    let mut tau = DVector::zeros(model.dof());
    for i in (0..n).rev() {
        let (start, _) = at[i];
        for (k, col) in subspace(model, i).iter().enumerate() {
            tau[start + k] = col.dot(&force[i]);
        }
        if let Some(p) = model.links[i].parent {
            let f = kin.x[i].force_to_parent(&force[i]);
            force[p] += f;
        }
    }
    tau
}

/// The mass matrix with the armatures on its diagonal, M + diag(armature),
/// and the generalized forces less the bias, τ − C, in [`offsets`]' layout.
fn mass_and_forces(
    model: &Model,
    state: &State,
    kin: &Kinematics,
    loads: &Loads,
) -> (DMatrix<f64>, DVector<f64>) {
    let dof = model.dof();
    let at = offsets(model);
    let bias = inverse_dynamics(model, state, kin, &DVector::zeros(dof), &loads.f_ext);
    let (still, kin_still) = at_rest(model, state, kin);
    let mut mass = mass_matrix(model, &still, &kin_still);
    let mut applied = DVector::zeros(dof);
    for (i, &(start, width)) in at.iter().enumerate() {
        match width {
            3 => applied.rows_mut(start, 3).copy_from(&loads.tau[i]),
            1 => {
                applied[start] = loads.effort[i];
                mass[(start, start)] += loads.armature[i];
            }
            _ => {}
        }
    }
    (mass, applied - bias)
}

/// `state` with every velocity zero, and its kinematics.
fn at_rest(model: &Model, state: &State, kin: &Kinematics) -> (State, Kinematics) {
    let still = State {
        root_v: Vector3::zeros(),
        rates: vec![Vector3::zeros(); model.len()],
        qd: vec![0.0; model.len()],
        ..state.clone()
    };
    let mut kin_still = kin.clone();
    kin_still.update(model, &still);
    (still, kin_still)
}

/// The mass matrix M of a state at rest (`still`, its kinematics
/// `kin_still`): M e_k = ID(e_k) with no gravity, no velocity and no load.
fn mass_matrix(model: &Model, still: &State, kin_still: &Kinematics) -> DMatrix<f64> {
    let dof = model.dof();
    let no_force = vec![Vector6::zeros(); model.len()];
    let g0 = Model {
        gravity: Vector3::zeros(),
        ..model.clone()
    };
    let mut mass = DMatrix::zeros(dof, dof);
    for k in 0..dof {
        let mut e = DVector::zeros(dof);
        e[k] = 1.0;
        mass.set_column(k, &inverse_dynamics(&g0, still, kin_still, &e, &no_force));
    }
    mass
}

/// G, the map from the coordinates that remain once every follower's is
/// tied to its leader's ([`Model::couplings`]) to all (q̇ = G q̇ᵣ), and for
/// each generalized coordinate its column of G if it remains.
fn reduction(model: &Model) -> (DMatrix<f64>, Vec<Option<usize>>) {
    let at = offsets(model);
    let dof = model.dof();
    let mut column = vec![None; dof];
    let mut reduced = 0;
    for (i, &(start, width)) in at.iter().enumerate() {
        if model.coupling(i).is_none() {
            for slot in &mut column[start..start + width] {
                *slot = Some(reduced);
                reduced += 1;
            }
        }
    }
    let mut g = DMatrix::zeros(dof, reduced);
    for (i, &(start, width)) in at.iter().enumerate() {
        match model.coupling(i) {
            Some(c) => {
                let leader = column[at[c.leader].0].expect("a leader follows none");
                g[(start, leader)] = c.multiplier;
            }
            None => {
                for k in start..start + width {
                    g[(k, column[k].expect("remains"))] = 1.0;
                }
            }
        }
    }
    (g, column)
}

/// What a one-DOF joint's gravity-compensated feedback loop is built from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Holding {
    /// The effort (N m or N) that holds the tree still against gravity.
    pub effort: f64,
    /// The joint's diagonal entry of the mass matrix (kg m² or kg): the
    /// inertia its own gains are sized on.
    pub inertia: f64,
}

/// Per link, in `state`'s configuration, for a one-DOF joint that follows
/// no other: the effort that holds the tree still there against gravity
/// (recursive Newton–Euler with no velocity and no acceleration, the root
/// held where it is, so for a free or pinned root what the joints need
/// while something holds the base; a leader carries its followers' share,
/// Gᵀ g) and its diagonal entry of the (reduced) mass matrix Gᵀ M G. None
/// for the root, a ball hinge and a follower.
pub fn holding_efforts(model: &Model, state: &State) -> Vec<Option<Holding>> {
    let mut kin = Kinematics::new(model);
    kin.update(model, state);
    let (still, kin_still) = at_rest(model, state, &kin);
    let dof = model.dof();
    let no_force = vec![Vector6::zeros(); model.len()];
    let gravity = inverse_dynamics(model, &still, &kin_still, &DVector::zeros(dof), &no_force);
    let mass = mass_matrix(model, &still, &kin_still);
    let (g, column) = reduction(model);
    let (gravity, mass) = (g.transpose() * gravity, g.transpose() * mass * &g);
    offsets(model)
        .iter()
        .enumerate()
        .map(|(i, &(start, width))| {
            let joint = i > 0 && width == 1 && model.coupling(i).is_none();
            let k = column[start].filter(|_| joint)?;
            Some(Holding {
                effort: gravity[k],
                inertia: mass[(k, k)],
            })
        })
        .collect()
}

/// Generalized accelerations by (M + diag(armature)) q̈ = τ − C, solved
/// densely, in [`offsets`]' layout.
#[cfg(test)]
pub fn forward_dense(
    model: &Model,
    state: &State,
    kin: &Kinematics,
    loads: &Loads,
) -> DVector<f64> {
    let (mass, forces) = mass_and_forces(model, state, kin, loads);
    mass.lu().solve(&forces).expect("mass matrix is invertible")
}

/// Generalized accelerations, in [`offsets`]' layout, of a model whose
/// followers' coordinates are tied to their leaders' ([`Model::couplings`]):
/// with G the map from the coordinates that remain (every one but the
/// followers') to all, q̇ = G q̇ᵣ, the reduced equations Gᵀ (M +
/// diag(armature)) G q̈ᵣ = Gᵀ (τ − C) — a leader carries its followers'
/// inertia and efforts — then q̈ = G q̈ᵣ. (A coupling is linear, so G is
/// constant and adds no velocity term.) NaN where the reduced mass matrix
/// is singular.
pub fn coupled_accelerations(
    model: &Model,
    state: &State,
    kin: &Kinematics,
    loads: &Loads,
) -> DVector<f64> {
    let (mass, forces) = mass_and_forces(model, state, kin, loads);
    let (g, _) = reduction(model);
    let reduced = g.ncols();
    let reduced_mass = g.transpose() * &mass * &g;
    let reduced_forces = g.transpose() * forces;
    let qdd = match reduced_mass.clone().cholesky() {
        Some(c) => c.solve(&reduced_forces),
        None => reduced_mass
            .lu()
            .solve(&reduced_forces)
            .unwrap_or_else(|| DVector::from_element(reduced, f64::NAN)),
    };
    g * qdd
}

/// The accelerations of a derivative, in [`offsets`]' layout.
#[cfg(test)]
pub fn generalized_acceleration(model: &Model, d: &crate::dynamics::Derivative) -> DVector<f64> {
    let at = offsets(model);
    let mut a = DVector::zeros(model.dof());
    for (i, &(start, width)) in at.iter().enumerate() {
        let values: Vec<f64> = match width {
            6 => d.rates[0].iter().chain(&d.root_v).copied().collect(),
            3 => d.rates[i].iter().copied().collect(),
            1 => vec![d.qd[i]],
            _ => Vec::new(),
        };
        a.rows_mut(start, width).copy_from_slice(&values);
    }
    a
}
