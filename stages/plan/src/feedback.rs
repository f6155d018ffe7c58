//! The controls engineer's first tries, references beside the planners:
//! each joint the scene's controls drive held by the nominal model's
//! gravity effort plus a PD or a PID loop,
//!
//!   PD:  τ = g(q) + M_ii (ω² e − 2ω q̇),
//!   PID: τ = g(q) + M_ii (3ω² e + ω³ ∫e dt − 3ω q̇),  e = q* − q,
//!
//! with g and the mass matrix's diagonal M_ii those of the scene as written
//! (the model a user has, not the plant) in the current configuration, so
//! that each joint alone is critically damped at ω (PD) or has every pole
//! at −ω (PID); τ is clamped to the controls' box, and the integral stops
//! growing while the effort is clamped the way it pushes (anti-windup). The
//! integral takes up what the nominal gravity effort misses of the plant's
//! (a payload, heavier links, weaker actuators); the PD loop holds short of
//! the target by that shortfall over its stiffness. A joint the task sets
//! goes to its target — of a revolute joint, the turn of it nearest where
//! the episode started that its limits allow, since the task measures
//! angles on the circle — and every other driven joint is held where the
//! episode started. Each loop decides once a frame, as a planner does, from
//! the state the planners read: the true one.
//!
//! ω is not tuned on the episodes it is judged on: the plan stage picks it
//! among `[plan] feedback_frequencies` by the mean cost over tuning
//! episodes from other logged states ([`crate`]'s `TaskRun::feedback`).

use std::f64::consts::TAU;

use alnlab_common::PolicyId;
use alnlab_physics::Prepared;
use alnlab_physics::dynamics::State;
use alnlab_physics::joint_space::holding_efforts;
use alnlab_physics::model::Joint;

use crate::controls::Controls;
use crate::planner::Bounds;
use crate::task::Task;

/// The loop's law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// Proportional and derivative.
    Pd,
    /// With an integral too.
    Pid,
}

impl Law {
    /// Both, in the order the stage runs them.
    pub const ALL: [Law; 2] = [Law::Pd, Law::Pid];

    /// The policy it is in the tables: `gravity-pd`, `gravity-pid`.
    pub fn policy(self) -> PolicyId {
        match self {
            Law::Pd => PolicyId::GravityPd,
            Law::Pid => PolicyId::GravityPid,
        }
    }
}

/// One driven joint of the loop.
#[derive(Clone, Debug)]
struct Driven {
    /// Its link.
    link: usize,
    /// The task's target for it, if any.
    target: Option<f64>,
    /// Whether it turns (a target is then an angle, taken on the circle).
    revolute: bool,
    /// Its position limits, if any.
    range: Option<(f64, f64)>,
}

/// Gravity compensation by the nominal model with a PD or PID loop, at one
/// frequency.
#[derive(Clone)]
pub struct Feedback<'a> {
    /// The scene as written, whose gravity and inertia the loop is built on.
    nominal: &'a Prepared,
    law: Law,
    /// Per control component, its joint.
    joints: Vec<Driven>,
    bounds: Bounds,
    /// Per control component: where it is held — its target, or where the
    /// episode started …
    set_points: Vec<f64>,
    /// … and its error's integral since then (rad s).
    integrals: Vec<f64>,
    /// A decision's period: the frame (s).
    period: f64,
    /// The natural frequency ω (rad/s).
    omega: f64,
}

impl<'a> Feedback<'a> {
    /// The loop `law` for `task` on the joints `controls` drive in scene
    /// `nominal`; an error where there is none to build: controls that are
    /// no robot joint's effort, or a task other than target angles of the
    /// driven joints.
    pub fn new(
        nominal: &'a Prepared,
        controls: &Controls,
        task: &Task,
        law: Law,
    ) -> Result<Feedback<'a>, String> {
        let Task::HoldAngles { targets, .. } = task else {
            return Err(format!(
                "task `{}` sets no joint angles, and a feedback loop needs targets (it holds \
                 hold-angles tasks)",
                task.name()
            ));
        };
        let Some(robot) = &nominal.robot else {
            return Err(format!(
                "scene `{}` is no robot, and a feedback loop drives one-DOF joints (its controls \
                 are {})",
                nominal.scene.name,
                controls.names().join(", ")
            ));
        };
        let joints: Vec<Driven> = controls
            .links()
            .map(|link| Driven {
                link,
                target: targets.get(&format!("q.{}", robot.joints[link])).copied(),
                revolute: matches!(nominal.model.links[link].joint, Joint::Revolute { .. }),
                range: nominal.laws[link].as_ref().and_then(|law| law.range),
            })
            .collect();
        for variable in targets.keys() {
            let driven = joints
                .iter()
                .any(|j| variable.strip_prefix("q.") == Some(&robot.joints[j.link]));
            if !driven {
                return Err(format!(
                    "task `{}`: `{variable}` is no joint the controls drive ({})",
                    task.name(),
                    controls.names().join(", ")
                ));
            }
        }
        Ok(Feedback {
            nominal,
            law,
            set_points: vec![0.0; joints.len()],
            integrals: vec![0.0; joints.len()],
            joints,
            bounds: controls.bounds().clone(),
            period: nominal.scene.frame_dt.get(),
            omega: 1.0,
        })
    }

    /// The loop's law.
    pub fn law(&self) -> Law {
        self.law
    }

    /// Sets the natural frequency ω (rad/s).
    pub fn tune(&mut self, omega: f64) {
        self.omega = omega;
    }

    /// The natural frequency ω (rad/s).
    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// Starts an episode from `start`: the set points fixed (a joint
    /// without a target held there), the integrals emptied.
    pub fn begin(&mut self, start: &State) {
        for (point, j) in self.set_points.iter_mut().zip(&self.joints) {
            let now = start.q[j.link];
            *point = match j.target {
                None => now,
                Some(target) if j.revolute => nearest_turn(target, now, j.range),
                Some(target) => target,
            };
        }
        self.integrals.fill(0.0);
    }

    /// The efforts for `state`, one per control component; a decision of
    /// the loop, once a frame.
    pub fn act(&mut self, state: &State, action: &mut [f64]) {
        let held = holding_efforts(&self.nominal.model, state);
        let w = self.omega;
        for (k, (j, value)) in self.joints.iter().zip(action.iter_mut()).enumerate() {
            let hold = held[j.link].expect("a driven joint is a one-DOF leader");
            let (q, qd) = (state.q[j.link], state.qd[j.link]);
            let error = self.set_points[k] - q;
            let (low, high) = (self.bounds.low[k], self.bounds.high[k]);
            let effort = match self.law {
                Law::Pd => hold.effort + hold.inertia * (w * w * error - 2.0 * w * qd),
                Law::Pid => {
                    let integral = self.integrals[k] + error * self.period;
                    let effort = hold.effort
                        + hold.inertia
                            * (3.0 * w * w * error + w * w * w * integral - 3.0 * w * qd);
                    // Anti-windup: no integrating further into a clamped effort.
                    let pushing_past =
                        (effort > high && error > 0.0) || (effort < low && error < 0.0);
                    if !pushing_past {
                        self.integrals[k] = integral;
                    }
                    effort
                }
            };
            *value = effort.clamp(low, high);
        }
    }
}

/// Of the revolute joint's positions that are `target` on the circle
/// (target + 2πk), the nearest to `now` that `range` allows (the target as
/// given where none other does).
fn nearest_turn(target: f64, now: f64, range: Option<(f64, f64)>) -> f64 {
    let allowed = |q: f64| range.is_none_or(|(low, high)| (low..=high).contains(&q));
    let turns = ((now - target) / TAU).round();
    [turns, turns - 1.0, turns + 1.0]
        .into_iter()
        .map(|k| target + k * TAU)
        .filter(|&q| allowed(q))
        .min_by(|a, b| (a - now).abs().total_cmp(&(b - now).abs()))
        .unwrap_or(target)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use alnlab_physics::Scene;
    use alnlab_physics::plant::{Payload, Plant};

    use super::*;
    use crate::episode::{self, Policy, Settling};
    use crate::forward::tests::ur5;
    use crate::task::HoldStart;

    /// arm-plan's task: the shoulder up, the elbow bent.
    fn raise() -> Task {
        Task::HoldAngles {
            name: "raise".into(),
            targets: BTreeMap::from([
                ("q.shoulder_lift_joint".into(), -1.2),
                ("q.elbow_joint".into(), 1.0),
            ]),
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
        }
    }

    /// Two seconds of the loop `law` at `omega` on `plant`, built on
    /// `nominal`, from the UR5 at rest 0.2 rad from the task's targets (the
    /// shoulder lower, the elbow less bent), every other joint at zero.
    fn hold(nominal: &Prepared, plant: &Prepared, law: Law, omega: f64) -> Settling {
        let controls = Controls::of(plant).unwrap();
        let task = raise();
        let cost = task.over(&plant.layout.variables, plant).unwrap();
        let mut held = Feedback::new(nominal, &controls, &task, law).unwrap();
        held.tune(omega);
        let mut start = State::rest(&plant.model, nalgebra::Vector3::zeros());
        let robot = plant.robot.as_ref().unwrap();
        for (joint, q) in [("shoulder_lift_joint", -1.0), ("elbow_joint", 0.8)] {
            let link = robot.joints.iter().position(|j| j == joint).unwrap();
            start.q[link] = q;
        }
        let mut policy = Policy::Feedback(held);
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
        .settling
    }

    /// On the model it is built on, the PD loop brings the arm to its
    /// targets and holds it there: no error left. On a plant that departs
    /// (a payload, heavier links, weaker actuators) its gravity effort
    /// falls short, and the proportional gain holds the arm short of the
    /// targets by the shortfall over the gain; the PID loop's integral
    /// takes the shortfall up.
    #[test]
    fn pd_holds_its_own_model_on_target_a_heavier_plant_short_of_it_and_pid_on_it() {
        let nominal = ur5(Scene::default());
        let exact = hold(&nominal, &nominal, Law::Pd, 10.0);
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
        let short = hold(&nominal, &plant, Law::Pd, 10.0);
        // (0.10 rad here, against 3.5e-5 on its own model.)
        assert!(
            short.final_error > 0.05 && short.final_error > 100.0 * exact.final_error,
            "{short:?} against {exact:?}"
        );
        // A stiffer loop is held closer: the error falls as 1/ω² (3.97
        // times from ω = 10 to 20 rad/s).
        let stiff = hold(&nominal, &plant, Law::Pd, 20.0);
        let ratio = short.final_error / stiff.final_error;
        assert!((2.5..5.5).contains(&ratio), "{ratio}: {short:?} {stiff:?}");
        let integral = hold(&nominal, &plant, Law::Pid, 10.0);
        assert!(
            integral.final_error < 0.1 * short.final_error && integral.settle_s < 1.5,
            "{integral:?} against PD's {short:?}"
        );
    }

    /// A revolute joint's target is taken on the circle, as the task
    /// measures it: the turn of it nearest the start that the limits allow.
    #[test]
    fn a_target_angle_is_the_nearest_turn_the_limits_allow() {
        assert_eq!(nearest_turn(-1.2, 4.0, None), -1.2 + TAU);
        assert_eq!(nearest_turn(-1.2, 4.0, Some((-TAU, TAU))), -1.2 + TAU);
        assert_eq!(nearest_turn(-1.2, 4.0, Some((-3.2, 3.2))), -1.2);
        assert_eq!(nearest_turn(-1.2, -0.5, Some((-TAU, TAU))), -1.2);
        assert_eq!(nearest_turn(3.0, -3.0, None), 3.0 - TAU);
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
        let e = Feedback::new(&nominal, &controls, &spin, Law::Pd)
            .err()
            .unwrap();
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
            start: HoldStart::Logged,
            velocity_weight: None,
        };
        let e = Feedback::new(&worm, &worm_controls, &bend, Law::Pid)
            .err()
            .unwrap();
        assert!(e.contains("is no robot") && e.contains("g.2.x"), "{e}");
    }
}
