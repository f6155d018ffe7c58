//! An independent formulation of the forward dynamics, for tests only: the
//! recursive Newton–Euler algorithm gives the generalized forces for given
//! accelerations; from it the joint-space mass matrix M and the bias C, and
//! the accelerations by solving M q̈ = τ − C densely.

use nalgebra::{DMatrix, DVector, Vector3, Vector6};

use crate::dynamics::{Kinematics, State};
use crate::model::{Model, Root};
use crate::spatial::{angular, cross_force, cross_motion, spatial};

/// Layout of the generalized velocity vector: for a free root, its angular
/// then linear velocity (6), then 3 per hinge; for a pinned root 3 per link.
fn offsets(model: &Model) -> Vec<usize> {
    let mut at = 0;
    (0..model.len())
        .map(|i| {
            let here = at;
            at += if i == 0 && model.root == Root::Free {
                6
            } else {
                3
            };
            here
        })
        .collect()
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
    let mut accel = vec![Vector6::zeros(); n];
    let mut force = vec![Vector6::zeros(); n];
    for i in 0..n {
        let link = &model.links[i];
        let a = match (link.parent, model.root) {
            (None, Root::Free) => {
                let q = qdd.fixed_rows::<6>(0);
                Vector6::new(q[0], q[1], q[2], q[3], q[4], q[5])
            }
            (parent, _) => {
                let qdd_i = Vector3::new(qdd[at[i]], qdd[at[i] + 1], qdd[at[i] + 2]);
                let from_parent = parent.map_or(Vector6::zeros(), |p| kin.x[i].motion(&accel[p]));
                let product = match parent {
                    Some(_) => {
                        cross_motion(&kin.vel[i], &spatial(&state.rates[i], &Vector3::zeros()))
                    }
                    None => Vector6::zeros(),
                };
                from_parent + spatial(&qdd_i, &Vector3::zeros()) + product
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
        match (model.links[i].parent, model.root) {
            (None, Root::Free) => tau.fixed_rows_mut::<6>(0).copy_from(&force[i]),
            _ => tau
                .fixed_rows_mut::<3>(at[i])
                .copy_from(&angular(&force[i])),
        }
        if let Some(p) = model.links[i].parent {
            let f = kin.x[i].force_to_parent(&force[i]);
            force[p] += f;
        }
    }
    tau
}

/// Generalized accelerations by M q̈ = τ − C, solved densely. `tau` holds the
/// hinge torques as in [`crate::dynamics::Workspace::forward`].
pub fn forward_dense(
    model: &Model,
    state: &State,
    kin: &Kinematics,
    tau: &[Vector3<f64>],
    f_ext: &[Vector6<f64>],
) -> DVector<f64> {
    let dof = model.dof();
    let at = offsets(model);
    let bias = inverse_dynamics(model, state, kin, &DVector::zeros(dof), f_ext);
    let mut mass = DMatrix::zeros(dof, dof);
    // M e_k = ID(e_k) − ID(0) with velocity-dependent terms cancelling.
    let still = State {
        root_v: nalgebra::Vector3::zeros(),
        rates: vec![Vector3::zeros(); model.len()],
        ..state.clone()
    };
    let mut kin_still = kin.clone();
    kin_still.update(model, &still);
    let no_force = vec![Vector6::zeros(); model.len()];
    let g0 = Model {
        gravity: Vector3::zeros(),
        ..model.clone()
    };
    for k in 0..dof {
        let mut e = DVector::zeros(dof);
        e[k] = 1.0;
        let column = inverse_dynamics(&g0, &still, &kin_still, &e, &no_force);
        mass.set_column(k, &column);
    }
    let mut applied = DVector::zeros(dof);
    for i in 0..model.len() {
        if !(i == 0 && model.root == Root::Free) {
            applied.fixed_rows_mut::<3>(at[i]).copy_from(&tau[i]);
        }
    }
    mass.lu()
        .solve(&(applied - bias))
        .expect("mass matrix is invertible")
}
