//! The controls engineer's first try, a reference beside the planners: each
//! joint the scene's controls drive held by the nominal model's gravity
//! effort plus a PD loop,
//!
//!   τ = g(q) + Kp (q* − q) − Kd q̇,  Kp = M_ii ω²,  Kd = 2 M_ii ω,
//!
//! with g and the mass matrix's diagonal M_ii those of the scene as written
//! (the model a user has, not the plant) in the current configuration, so
//! each joint alone is critically damped at natural frequency ω; τ is
//! clamped to the controls' box. A joint the task sets goes to its target;
//! every other driven joint is held where the episode started. The loop
//! reads the state the planners read: the true one, every frame.
//!
//! ω is not tuned on the episodes it is judged on: the plan stage picks it
//! among `[plan] pd_frequencies` by the mean cost over tuning episodes from
//! other logged states.

use alnlab_physics::Prepared;
use alnlab_physics::dynamics::State;
use alnlab_physics::joint_space::holding_efforts;

use crate::controls::Controls;
use crate::planner::Bounds;
use crate::task::Task;

/// Gravity compensation by the nominal model with PD, at one frequency.
#[derive(Clone)]
pub struct GravityPd<'a> {
    /// The scene as written, whose gravity and inertia the loop is built on.
    nominal: &'a Prepared,
    /// Per control component: its joint's link and the task's target for it.
    joints: Vec<(usize, Option<f64>)>,
    bounds: Bounds,
    /// Per control component: where it is held — its target, or where the
    /// episode started.
    set_points: Vec<f64>,
    /// The natural frequency ω (rad/s).
    omega: f64,
}

impl<'a> GravityPd<'a> {
    /// The loop for `task` on the joints `controls` drive in scene
    /// `nominal`; an error where there is none to build: controls that are
    /// no robot joint's effort, or a task other than target angles of the
    /// driven joints.
    pub fn new(
        nominal: &'a Prepared,
        controls: &Controls,
        task: &Task,
    ) -> Result<GravityPd<'a>, String> {
        let Task::HoldAngles { targets, .. } = task else {
            return Err(format!(
                "task `{}` sets no joint angles, and a PD loop needs targets (gravity-pd plans \
                 hold-angles tasks)",
                task.name()
            ));
        };
        let Some(robot) = &nominal.robot else {
            return Err(format!(
                "scene `{}` is no robot, and the PD loop drives one-DOF joints (its controls \
                 are {})",
                nominal.scene.name,
                controls.names().join(", ")
            ));
        };
        let joints: Vec<(usize, Option<f64>)> = controls
            .links()
            .map(|link| {
                let target = targets.get(&format!("q.{}", robot.joints[link])).copied();
                (link, target)
            })
            .collect();
        for variable in targets.keys() {
            let driven = joints
                .iter()
                .any(|&(link, _)| variable.strip_prefix("q.") == Some(&robot.joints[link]));
            if !driven {
                return Err(format!(
                    "task `{}`: `{variable}` is no joint the controls drive ({})",
                    task.name(),
                    controls.names().join(", ")
                ));
            }
        }
        Ok(GravityPd {
            nominal,
            set_points: vec![0.0; joints.len()],
            joints,
            bounds: controls.bounds().clone(),
            omega: 1.0,
        })
    }

    /// Sets the natural frequency ω (rad/s).
    pub fn tune(&mut self, omega: f64) {
        self.omega = omega;
    }

    /// The natural frequency ω (rad/s).
    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// Starts an episode from `start`: a joint without a target is held
    /// there.
    pub fn begin(&mut self, start: &State) {
        for (point, &(link, target)) in self.set_points.iter_mut().zip(&self.joints) {
            *point = target.unwrap_or(start.q[link]);
        }
    }

    /// The efforts for `state`, one per control component.
    pub fn act(&self, state: &State, action: &mut [f64]) {
        let held = holding_efforts(&self.nominal.model, state);
        let w = self.omega;
        for (k, (&(link, _), value)) in self.joints.iter().zip(action.iter_mut()).enumerate() {
            let (gravity, inertia) = held[link].expect("a driven joint is a one-DOF leader");
            let effort = gravity
                + inertia
                    * (w * w * (self.set_points[k] - state.q[link]) - 2.0 * w * state.qd[link]);
            *value = effort.clamp(self.bounds.low[k], self.bounds.high[k]);
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use alnlab_physics::Scene;
    use alnlab_physics::plant::{Payload, Plant};

    use super::*;
    use crate::episode::{self, Outcome, Policy};
    use crate::forward::tests::ur5;

    /// arm-plan's task: the shoulder up, the elbow bent.
    fn raise() -> Task {
        Task::HoldAngles {
            name: "raise".into(),
            targets: BTreeMap::from([
                ("q.shoulder_lift_joint".into(), -1.2),
                ("q.elbow_joint".into(), 1.0),
            ]),
            tolerance: None,
        }
    }

    /// Two seconds of the loop at `omega` on `plant`, built on `nominal`,
    /// from the UR5 at rest 0.2 rad from the task's targets (the shoulder
    /// lower, the elbow less bent), every other joint at zero.
    fn hold(nominal: &Prepared, plant: &Prepared, omega: f64) -> Outcome {
        let controls = Controls::of(plant).unwrap();
        let task = raise();
        let cost = task.over(&plant.layout.variables, plant).unwrap();
        let mut pd = GravityPd::new(nominal, &controls, &task).unwrap();
        pd.tune(omega);
        let mut start = State::rest(&plant.model, nalgebra::Vector3::zeros());
        let robot = plant.robot.as_ref().unwrap();
        for (joint, q) in [("shoulder_lift_joint", -1.0), ("elbow_joint", 0.8)] {
            let link = robot.joints.iter().position(|j| j == joint).unwrap();
            start.q[link] = q;
        }
        let mut policy = Policy::Feedback(pd);
        episode::run(
            plant,
            &controls,
            &start,
            200,
            0,
            &cost,
            &mut policy,
            1,
            |_, _, _, _| Ok(()),
        )
        .unwrap()
    }

    /// On the model it is built on, the loop brings the arm to its targets
    /// and holds it there: no error left. On a plant that departs (a
    /// payload, heavier links, weaker actuators) its gravity effort falls
    /// short, and the proportional gain holds the arm short of the targets
    /// by the shortfall over the gain: the steady-state error the planners
    /// are measured against.
    #[test]
    fn the_loop_holds_its_own_model_on_target_and_a_heavier_plant_short_of_it() {
        let nominal = ur5(Scene::default());
        let exact = hold(&nominal, &nominal, 10.0);
        assert!(exact.final_error < 1e-3, "{exact:?}");
        assert!(exact.settle_s < 1.0 && exact.within > 0.6, "{exact:?}");
        let plant = ur5(Scene {
            plant: Some(Plant {
                mass_scale: 1.1,
                payload: Some(Payload {
                    link: "tool0".into(),
                    mass: 1.5,
                    offset: [0.0, 0.0, 0.05],
                }),
                actuator_gain: 0.95,
                ..Plant::default()
            }),
            ..Scene::default()
        });
        let short = hold(&nominal, &plant, 10.0);
        // (0.10 rad here, against 3.5e-5 on its own model.)
        assert!(
            short.final_error > 0.05 && short.final_error > 100.0 * exact.final_error,
            "{short:?} against {exact:?}"
        );
        // A stiffer loop is held closer: the error falls as 1/ω² (3.97
        // times from ω = 10 to 20 rad/s).
        let stiff = hold(&nominal, &plant, 20.0);
        let ratio = short.final_error / stiff.final_error;
        assert!((2.5..5.5).contains(&ratio), "{ratio}: {short:?} {stiff:?}");
    }

    #[test]
    fn a_loop_is_refused_where_there_is_none_to_build() {
        let nominal = ur5(Scene::default());
        let controls = Controls::of(&nominal).unwrap();
        let spin = Task::Spin {
            name: "spin".into(),
            variable: "omega.7.x".into(),
            rate: 1.0,
            tolerance: None,
        };
        let e = GravityPd::new(&nominal, &controls, &spin).err().unwrap();
        assert!(e.contains("sets no joint angles"), "{e}");
        let worm = Prepared::new(&Scene {
            controller: Some(alnlab_physics::controller::ControllerParams {
                kind: alnlab_physics::controller::ControllerKind::Random,
                ..Default::default()
            }),
            ..Scene::default()
        });
        let worm_controls = Controls::of(&worm).unwrap();
        let bend = Task::HoldAngles {
            name: "bend".into(),
            targets: BTreeMap::from([("pitch.2".into(), 0.6)]),
            tolerance: None,
        };
        let e = GravityPd::new(&worm, &worm_controls, &bend).err().unwrap();
        assert!(e.contains("is no robot") && e.contains("g.2.x"), "{e}");
    }
}
