//! Fixed-step integration of the link tree: semi-implicit Euler (velocities
//! first, then positions with the new velocities), the same with the joints'
//! damping, friction slope and limit springs taken implicitly, and classical
//! RK4. All keep the quaternions unit. All scratch space lives in the
//! [`Stepper`], so a step allocates nothing — but for a model with
//! couplings (a URDF's mimic joints), whose dense solve allocates
//! ([`crate::joint_space::coupled_accelerations`]).

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use serde::{Deserialize, Serialize};

use crate::dynamics::{Derivative, Kinematics, Loads, State, Workspace};
use crate::model::Model;

/// The numerical integrator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Velocities first, then positions with the new velocities; every
    /// effort explicit, so a scene's damping must be one its step resolves
    /// (the scene's check says which dt does).
    SemiImplicitEuler,
    /// Classical fourth-order Runge–Kutta.
    Rk4,
    /// Semi-implicit Euler with each one-DOF joint's passive efforts taken
    /// implicitly, as MuJoCo's implicit-in-velocity integrators take joint
    /// damping: with b = −∂effort/∂q̇ and k = −∂effort/∂q of the joint's
    /// damping, friction slope and engaged limit, a step of h solves
    /// (M + diag(h b + h² k)) q̈ = τ − C − h k q̇, the linearised backward
    /// Euler step, whatever b and k are: stable for damping and limit
    /// springs no explicit step of that h resolves. Ball hinges' damping
    /// and contacts stay explicit. Without damping, friction, a limit
    /// engaged or a velocity-limit drive (whose gain differs) it is
    /// semi-implicit Euler, bit for bit.
    /// The default, as MuJoCo's Euler integrator takes joint damping
    /// implicitly by default: a robot loaded as its description gives it
    /// runs at a real step.
    #[default]
    Implicit,
}

/// The forces acting at one instant: fills the loads (hinge torques, joint
/// efforts and external spatial forces, link frame, at the hinge; gravity
/// excluded) for a state whose kinematics are given.
pub trait Forces {
    fn apply(&mut self, model: &Model, state: &State, kin: &Kinematics, loads: &mut Loads);

    /// For an implicit step of `h` from `state`, whose accelerations under
    /// `loads` came out as `qdd`: moves each one-DOF joint's effort that is
    /// piecewise affine in the velocity to the piece holding at the step's
    /// end, q̇ + h q̈ (its value at `state` in `loads.effort`, its slope in
    /// `loads.effort_damping`); returns whether any moved, and the step is
    /// then solved again. None, by default.
    fn refine(&mut self, _state: &State, _qdd: &[f64], _h: f64, _loads: &mut Loads) -> bool {
        false
    }
}

/// How many times an implicit step solves again for efforts whose piece
/// changed at its end ([`Forces::refine`]): a drive's pieces are five, of
/// which a step crosses one or two (the command's to its band, the band to
/// the brake) — joints coupled through the mass matrix may take more.
pub(crate) const REFINEMENTS: usize = 4;

/// No torques, no external forces.
pub struct NoForces;

impl Forces for NoForces {
    fn apply(&mut self, _: &Model, _: &State, _: &Kinematics, loads: &mut Loads) {
        loads.clear();
    }
}

/// Everything one evaluation of the dynamics computes, kept for inspection:
/// kinematics, forces, accelerations and the state's derivative.
pub struct Evaluation {
    /// Kinematics of the state last evaluated.
    pub kin: Kinematics,
    /// The dynamics scratch space (its `accel` holds the last accelerations).
    pub ws: Workspace,
    /// The loads of the last evaluation.
    pub loads: Loads,
    /// The derivative of the last evaluation.
    pub deriv: Derivative,
    /// Sum of the external forces and gravity, inertial frame (the rate of
    /// change of the linear momentum).
    pub external_force: Vector3<f64>,
    /// Per link, what an implicit step changed its one-DOF joint's effort
    /// by: −h k q̇ − (h b + h² k) q̈ (zero for an explicit evaluation). The
    /// effort the dynamics applied is the forces' effort plus this.
    pub implicit_effort: Vec<f64>,
}

impl Evaluation {
    /// Buffers for `model`.
    pub fn new(model: &Model) -> Evaluation {
        Evaluation {
            kin: Kinematics::new(model),
            ws: Workspace::new(model),
            loads: Loads::zeros(model),
            deriv: Derivative::zeros(model),
            external_force: Vector3::zeros(),
            implicit_effort: vec![0.0; model.len()],
        }
    }

    /// Evaluates kinematics, forces and accelerations of `state`.
    pub fn run(&mut self, model: &Model, state: &State, forces: &mut impl Forces) {
        self.run_for(model, state, forces, None);
    }

    /// [`Evaluation::run`] as a step of `implicit` (h) by
    /// [`Integrator::Implicit`] evaluates it, or explicitly (`None`).
    pub fn run_for(
        &mut self,
        model: &Model,
        state: &State,
        forces: &mut impl Forces,
        implicit: Option<f64>,
    ) {
        self.kin.update(model, state);
        forces.apply(model, state, &self.kin, &mut self.loads);
        let loads = &mut self.loads;
        match implicit {
            Some(h) => {
                for i in 0..model.len() {
                    let (b, k) = (loads.effort_damping[i], loads.effort_stiffness[i]);
                    let shift = -h * k * state.qd[i];
                    loads.effort[i] += shift;
                    loads.armature[i] = h * b + h * h * k;
                    self.implicit_effort[i] = shift;
                }
            }
            None => {
                loads.armature.fill(0.0);
                self.implicit_effort.fill(0.0);
            }
        }
        self.ws
            .forward(model, state, &self.kin, &self.loads, &mut self.deriv);
        if let Some(h) = implicit {
            for _ in 0..REFINEMENTS {
                if !forces.refine(state, &self.deriv.qd, h, &mut self.loads) {
                    break;
                }
                let loads = &mut self.loads;
                for i in 0..model.len() {
                    loads.armature[i] =
                        h * loads.effort_damping[i] + h * h * loads.effort_stiffness[i];
                }
                self.ws
                    .forward(model, state, &self.kin, &self.loads, &mut self.deriv);
            }
            for (i, effort) in self.implicit_effort.iter_mut().enumerate() {
                *effort -= self.loads.armature[i] * self.deriv.qd[i];
            }
        }
        self.external_force = model.gravity * model.total_mass();
        for (rot, f) in self.kin.rot.iter().zip(&self.loads.f_ext) {
            self.external_force += rot * f.fixed_rows::<3>(3);
        }
    }
}

/// Steps a model forward; owns every buffer a step needs.
///
/// With a free root, each step ends with a momentum projection: the system's
/// linear momentum is integrated on its own (its rate is the total external
/// force, so without one it is constant) and the root's linear velocity is
/// shifted so that the state carries exactly that momentum. Integrating the
/// generalized coordinates alone lets it drift by the truncation error.
pub struct Stepper {
    /// The last evaluation of the dynamics (at the start of the last step for
    /// semi-implicit Euler, at its last RK4 stage otherwise).
    pub eval: Evaluation,
    k: [Derivative; 3],
    stage: State,
    /// The tracked linear momentum (free root), set from the first state.
    momentum: Option<Vector3<f64>>,
}

impl Stepper {
    /// Buffers for `model`.
    pub fn new(model: &Model) -> Stepper {
        Stepper {
            eval: Evaluation::new(model),
            k: std::array::from_fn(|_| Derivative::zeros(model)),
            stage: State::rest(model, Vector3::zeros()),
            momentum: None,
        }
    }

    /// Forgets the tracked momentum: the next step tracks it afresh from its
    /// state (for stepping on from a state of another trajectory).
    pub fn restart(&mut self) {
        self.momentum = None;
    }

    /// Advances `state` by `dt`.
    pub fn step(
        &mut self,
        model: &Model,
        state: &mut State,
        dt: f64,
        integrator: Integrator,
        forces: &mut impl Forces,
    ) {
        // A state set from outside (a hybrid's prediction) may be off its
        // couplings: each step starts on them.
        model.impose_couplings(state);
        let momentum_rate = match integrator {
            Integrator::SemiImplicitEuler | Integrator::Implicit => {
                let implicit = (integrator == Integrator::Implicit).then_some(dt);
                self.eval.run_for(model, state, forces, implicit);
                self.start_momentum(model);
                let d = &self.eval.deriv;
                state.root_v += d.root_v * dt;
                for (w, wd) in state.rates.iter_mut().zip(&d.rates) {
                    *w += wd * dt;
                }
                for (qd, qdd) in state.qd.iter_mut().zip(&d.qd) {
                    *qd += qdd * dt;
                }
                for (q, qd) in state.q.iter_mut().zip(&state.qd) {
                    *q += qd * dt;
                }
                if model.root == crate::model::Root::Free {
                    state.root_p += self.eval.kin.rot[0] * state.root_v * dt;
                }
                for (q, w) in state.orient.iter_mut().zip(&state.rates) {
                    *q *= UnitQuaternion::from_scaled_axis(w * dt);
                    q.renormalize();
                }
                self.eval.external_force
            }
            Integrator::Rk4 => self.rk4(model, state, dt, forces),
        };
        // Followers' coordinates move with their leaders' to rounding;
        // imposed, they stay on the coupling exactly.
        model.impose_couplings(state);
        if let Some(momentum) = &mut self.momentum {
            *momentum += momentum_rate * dt;
            let kin = &mut self.eval.kin;
            kin.update(model, state);
            let error = *momentum - crate::dynamics::linear_momentum(model, kin);
            state.root_v += kin.rot[0].transpose() * error / model.total_mass();
        }
    }

    /// Sets the tracked momentum from the state just evaluated, on the first
    /// step of a free-root model.
    fn start_momentum(&mut self, model: &Model) {
        if self.momentum.is_none() && model.root == crate::model::Root::Free {
            self.momentum = Some(crate::dynamics::linear_momentum(model, &self.eval.kin));
        }
    }

    /// One RK4 step; returns the RK4-weighted mean external force.
    fn rk4(
        &mut self,
        model: &Model,
        state: &mut State,
        dt: f64,
        forces: &mut impl Forces,
    ) -> Vector3<f64> {
        // k1..k3 are kept; k4 is the last evaluation's derivative.
        let mut force = Vector3::zeros();
        for stage in 0..4 {
            if stage == 0 {
                self.stage.clone_from(state);
            } else {
                let h = if stage == 3 { dt } else { dt / 2.0 };
                offset(&mut self.stage, state, &self.k[stage - 1], h);
            }
            self.eval.run(model, &self.stage, forces);
            if stage == 0 {
                self.start_momentum(model);
            }
            force += self.eval.external_force * [1.0, 2.0, 2.0, 1.0][stage] / 6.0;
            if stage < 3 {
                clone_derivative(&mut self.k[stage], &self.eval.deriv);
            }
        }
        let [k1, k2, k3] = &self.k;
        let k4 = &self.eval.deriv;
        let h = dt / 6.0;
        state.root_p += (k1.root_p + k2.root_p * 2.0 + k3.root_p * 2.0 + k4.root_p) * h;
        state.root_v += (k1.root_v + k2.root_v * 2.0 + k3.root_v * 2.0 + k4.root_v) * h;
        for i in 0..state.rates.len() {
            state.rates[i] +=
                (k1.rates[i] + k2.rates[i] * 2.0 + k3.rates[i] * 2.0 + k4.rates[i]) * h;
            let dq: Quaternion<f64> =
                (k1.orient[i] + k2.orient[i] * 2.0 + k3.orient[i] * 2.0 + k4.orient[i]) * h;
            state.orient[i] = UnitQuaternion::new_normalize(state.orient[i].into_inner() + dq);
            state.q[i] += (k1.q[i] + k2.q[i] * 2.0 + k3.q[i] * 2.0 + k4.q[i]) * h;
            state.qd[i] += (k1.qd[i] + k2.qd[i] * 2.0 + k3.qd[i] * 2.0 + k4.qd[i]) * h;
        }
        force
    }
}

/// `out = base + h · d`, quaternions renormalised.
fn offset(out: &mut State, base: &State, d: &Derivative, h: f64) {
    out.root_p = base.root_p + d.root_p * h;
    out.root_v = base.root_v + d.root_v * h;
    for i in 0..base.rates.len() {
        out.rates[i] = base.rates[i] + d.rates[i] * h;
        out.orient[i] =
            UnitQuaternion::new_normalize(base.orient[i].into_inner() + d.orient[i] * h);
        out.q[i] = base.q[i] + d.q[i] * h;
        out.qd[i] = base.qd[i] + d.qd[i] * h;
    }
}

fn clone_derivative(out: &mut Derivative, from: &Derivative) {
    out.root_p = from.root_p;
    out.root_v = from.root_v;
    out.orient.copy_from_slice(&from.orient);
    out.rates.copy_from_slice(&from.rates);
    out.q.copy_from_slice(&from.q);
    out.qd.copy_from_slice(&from.qd);
}
