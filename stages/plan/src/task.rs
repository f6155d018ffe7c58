//! Tasks, declared in the manifest in the learned variables, and their cost
//! per frame (summed over an episode):
//!
//! - `hold-angles`: reach and hold target angles — for each hinge angle
//!   `roll.N`/`pitch.N` or robot joint position `q.<joint>` named in
//!   `targets` (rad), the squared angle to its target, the difference taken
//!   on the circle (within ±π); a joint's target within its limits. Against
//!   gravity, holding a pose is reaching it;
//! - `spin`: spin about an axis at a target rate — the squared difference
//!   of an angular velocity component and `rate` (rad/s); components are in
//!   the link's own frame, so `omega.3.x` is the third link's spin about its
//!   long axis;
//! - `reach-point`: bring a robot's named URDF frame (a link's frame, as the
//!   log's `/tf` shows it) to a `target` point (m, world frame) — the squared
//!   distance still to go. The frame is placed from the positions of the
//!   joints between it and the robot's welded base, so each of those must
//!   be a variable.
//!
//! A hold-angles task of a robot's joints may start at its targets, at rest
//! (`start = "at-target"`: holding, not reaching — against a plant's
//! payload, say), and may weigh the joints' velocities too
//! (`velocity_weight`, s²: reach the angles and stop there).
//!
//! Beside the cost, each frame has an error in the task's physical unit
//! ([`Cost::error`]: the largest angle still to go, rad; the rate's miss,
//! rad/s; the distance, m), and each task a `tolerance` within which a frame
//! counts as there: an episode's steady-state error, time to settle and
//! fraction of frames within it are read from those ([`crate::episode`]).

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};

use alnlab_physics::Prepared;
use alnlab_physics::dynamics::{ChainPoint, State};
use alnlab_physics::model::Root;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// One `[[plan.task]]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "kebab-case")]
pub enum Task {
    /// Reach and hold hinge or joint angles.
    HoldAngles {
        /// The task's name in tables and the report.
        name: String,
        /// Target angle (rad) per `roll.N`, `pitch.N` or `q.<joint>`
        /// variable.
        targets: BTreeMap<String, f64>,
        /// Within this error a frame counts as there ([`Task::tolerance`]'s
        /// default where not given).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tolerance: Option<f64>,
        /// Where its episodes start ([`HoldStart`]): from the logged state,
        /// or at the targets, at rest — holding, not reaching.
        #[serde(default, skip_serializing_if = "HoldStart::is_logged")]
        start: HoldStart,
        /// Each frame also costs this (s²) times each target joint's
        /// squared velocity (q̇², `qd.<joint>`): reach the angles and stop
        /// there. None: the angles alone.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        velocity_weight: Option<f64>,
    },
    /// Spin at a rate.
    Spin {
        name: String,
        /// An angular velocity component, e.g. `omega.1.x`.
        variable: String,
        /// Target rate (rad/s).
        rate: f64,
        /// Within this error a frame counts as there ([`Task::tolerance`]'s
        /// default where not given).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tolerance: Option<f64>,
    },
    /// Bring a robot's URDF frame to a point.
    ReachPoint {
        name: String,
        /// The URDF link whose frame is brought there, e.g. `tool0`.
        frame: String,
        /// The point (m, world frame).
        target: [f64; 3],
        /// Within this error a frame counts as there ([`Task::tolerance`]'s
        /// default where not given).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tolerance: Option<f64>,
    },
}

/// Where a hold-angles task's episodes start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HoldStart {
    /// From the logged state the episode is drawn at (reach, then hold).
    #[default]
    Logged,
    /// From that state with each target joint at its target and every
    /// velocity zero: the arm at rest on target, so that what the episode
    /// measures is holding it there (under a plant's payload, say).
    AtTarget,
}

impl HoldStart {
    fn is_logged(&self) -> bool {
        *self == HoldStart::Logged
    }
}

impl Task {
    /// The task's name.
    pub fn name(&self) -> &str {
        match self {
            Task::HoldAngles { name, .. }
            | Task::Spin { name, .. }
            | Task::ReachPoint { name, .. } => name,
        }
    }

    /// What the task asks and what a frame costs, in words with units:
    /// "pitch.2 to 0.6 rad and pitch.3 to -0.6 rad; a frame costs the sum of
    /// the squared angles to go (rad², on the circle)".
    pub fn describe(&self) -> String {
        match self {
            Task::HoldAngles {
                targets,
                start,
                velocity_weight,
                ..
            } => {
                let each: Vec<String> = targets
                    .iter()
                    .map(|(v, t)| format!("`{v}` to {t} rad"))
                    .collect();
                let asked = match start {
                    HoldStart::Logged => "reach and hold",
                    HoldStart::AtTarget => "starting there at rest, hold",
                };
                let rates = match velocity_weight {
                    Some(w) => format!(
                        ", plus {w} s² times each of those joints' squared velocity (stop there)"
                    ),
                    None => String::new(),
                };
                format!(
                    "{asked} {}; a frame costs the sum of the squared angles still to go \
                     (rad², on the circle){rates}",
                    each.join(" and ")
                )
            }
            Task::Spin { variable, rate, .. } => format!(
                "spin `{variable}` at {rate} rad/s; a frame costs the squared difference from \
                 that rate ((rad/s)²)"
            ),
            Task::ReachPoint { frame, target, .. } => format!(
                "bring frame `{frame}` to ({}, {}, {}) m; a frame costs the squared distance \
                 still to go (m²)",
                target[0], target[1], target[2]
            ),
        }
    }

    /// An episode's start state in scene `p` from the logged state `logged`:
    /// as logged, or for a hold-angles task that starts at its targets,
    /// each target joint there, every velocity zero (a mimic joint's
    /// followers moved with it).
    pub fn start_state(&self, p: &Prepared, logged: &State) -> State {
        let Task::HoldAngles {
            targets,
            start: HoldStart::AtTarget,
            ..
        } = self
        else {
            return logged.clone();
        };
        let mut state = State {
            root_v: Vector3::zeros(),
            rates: vec![Vector3::zeros(); p.model.len()],
            qd: vec![0.0; p.model.len()],
            ..logged.clone()
        };
        for (variable, &target) in targets {
            if let Some(link) = joint_link(p, variable) {
                state.q[link] = target;
            }
        }
        p.model.impose_couplings(&mut state);
        state
    }

    /// The error within which a frame counts as there, in
    /// [`Task::error_unit`]: as given, else 0.05 rad (about 3°) for
    /// angles, 0.2 rad/s for a rate, 2 cm for a point.
    pub fn tolerance(&self) -> f64 {
        match self {
            Task::HoldAngles { tolerance, .. } => tolerance.unwrap_or(0.05),
            Task::Spin { tolerance, .. } => tolerance.unwrap_or(0.2),
            Task::ReachPoint { tolerance, .. } => tolerance.unwrap_or(0.02),
        }
    }

    /// The unit of a frame's error ([`Cost::error`]) and of the tolerance.
    pub fn error_unit(&self) -> &'static str {
        match self {
            Task::HoldAngles { .. } => "rad",
            Task::Spin { .. } => "rad/s",
            Task::ReachPoint { .. } => "m",
        }
    }

    /// The unit of a frame's cost, and so of an episode's.
    pub fn cost_unit(&self) -> &'static str {
        match self {
            Task::HoldAngles { .. } => "rad²",
            Task::Spin { .. } => "(rad/s)²",
            Task::ReachPoint { .. } => "m²",
        }
    }

    /// Checks the task on its own: targets named as angles, finite numbers.
    /// On error, the field and the message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let tolerance = match self {
            Task::HoldAngles { tolerance, .. }
            | Task::Spin { tolerance, .. }
            | Task::ReachPoint { tolerance, .. } => tolerance,
        };
        if let Some(t) = tolerance.filter(|t| !(t.is_finite() && *t > 0.0)) {
            return Err((
                "tolerance",
                format!(
                    "expected a positive error in {}, found {t}",
                    self.error_unit()
                ),
            ));
        }
        match self {
            Task::HoldAngles {
                targets,
                start,
                velocity_weight,
                ..
            } => {
                if targets.is_empty() {
                    return Err(("targets", "expected at least one target angle".into()));
                }
                if let Some(w) = velocity_weight.filter(|w| !(w.is_finite() && *w > 0.0)) {
                    return Err((
                        "velocity_weight",
                        format!("expected a positive weight (s²), found {w}"),
                    ));
                }
                let hinge = targets.keys().find(|v| !v.starts_with("q."));
                if let Some(v) = hinge.filter(|_| velocity_weight.is_some()) {
                    return Err((
                        "velocity_weight",
                        format!(
                            "weighs joints' velocities `qd.<joint>`, and `{v}` is no robot joint's \
                             position"
                        ),
                    ));
                }
                if let Some(v) = hinge.filter(|_| *start == HoldStart::AtTarget) {
                    return Err((
                        "start",
                        format!(
                            "`at-target` sets robot joints' positions, and `{v}` is no robot \
                             joint's position (start = \"logged\" reaches it)"
                        ),
                    ));
                }
                for (variable, target) in targets {
                    let angle = ["roll.", "pitch.", "q."]
                        .iter()
                        .any(|prefix| variable.starts_with(prefix));
                    if !angle {
                        return Err((
                            "targets",
                            format!(
                                "`{variable}` is not a hinge angle (roll.N or pitch.N) or a \
                                 joint's position (q.<joint>)"
                            ),
                        ));
                    }
                    if !target.is_finite() {
                        return Err(("targets", format!("`{variable}`: expected a finite angle")));
                    }
                }
            }
            Task::Spin { variable, rate, .. } => {
                if !variable.starts_with("omega.") {
                    return Err((
                        "variable",
                        format!("`{variable}` is not an angular velocity (omega.N.x|y|z)"),
                    ));
                }
                if !rate.is_finite() {
                    return Err(("rate", "expected a finite rate".into()));
                }
            }
            Task::ReachPoint { target, .. } => {
                if !target.iter().all(|x| x.is_finite()) {
                    return Err(("target", "expected three finite coordinates (m)".into()));
                }
            }
        }
        Ok(())
    }

    /// Checks the task against scene `p`: a joint's target within the
    /// joint's limits, where the robot description gives them; a frame to
    /// reach that the robot has, on a welded base, and a target within the
    /// frame's reach. On error, the field and the message.
    pub fn within(&self, p: &Prepared) -> Result<(), (&'static str, String)> {
        match self {
            Task::HoldAngles { targets, .. } => within_limits(targets, p),
            Task::ReachPoint { frame, target, .. } => {
                let (chain, robot) = chain_point(frame, p).map_err(|m| ("frame", m))?;
                let travel = |i: usize| {
                    let (low, high) = robot.specs[i].range?;
                    Some(low.abs().max(high.abs()))
                };
                let target = Vector3::from(*target);
                match chain.reach(travel) {
                    Some((centre, radius)) if (target - centre).norm() > radius => Err((
                        "target",
                        format!(
                            "({}, {}, {}) m is out of `{frame}`'s reach: it is {:.3} m from the \
                             first joint's origin at ({:.3}, {:.3}, {:.3}) m, and the links \
                             between reach at most {radius:.3} m",
                            target.x,
                            target.y,
                            target.z,
                            (target - centre).norm(),
                            centre.x,
                            centre.y,
                            centre.z
                        ),
                    )),
                    _ => Ok(()),
                }
            }
            Task::Spin { .. } => Ok(()),
        }
    }

    /// The task over variables in the order of `names` (a scene's learned
    /// or logged variables) of scene `p`; an error names a variable the
    /// scene lacks.
    pub fn over(&self, names: &[String], p: &Prepared) -> Result<Cost, String> {
        let index = |v: &str| {
            names.iter().position(|n| n == v).ok_or_else(|| {
                format!(
                    "task `{}`: the scene has no variable `{v}` (it has {})",
                    self.name(),
                    names.join(", ")
                )
            })
        };
        let rates = match self {
            Task::HoldAngles {
                targets,
                velocity_weight: Some(weight),
                ..
            } => targets
                .keys()
                .map(|v| {
                    let joint = v.strip_prefix("q.").unwrap_or(v);
                    Ok((index(&format!("qd.{joint}"))?, *weight))
                })
                .collect::<Result<_, String>>()?,
            _ => Vec::new(),
        };
        let (terms, reach) = match self {
            Task::HoldAngles { targets, .. } => (
                targets
                    .iter()
                    .map(|(v, &target)| Ok((index(v)?, target, true)))
                    .collect::<Result<_, String>>()?,
                None,
            ),
            Task::Spin { variable, rate, .. } => (vec![(index(variable)?, *rate, false)], None),
            Task::ReachPoint { frame, target, .. } => {
                let (chain, robot) =
                    chain_point(frame, p).map_err(|m| format!("task `{}`: {m}", self.name()))?;
                let terms = chain
                    .links()
                    .map(|i| Ok((index(&format!("q.{}", robot.joints[i]))?, 0.0, true)))
                    .collect::<Result<_, String>>()?;
                (terms, Some((chain, Vector3::from(*target))))
            }
        };
        Ok(Cost {
            terms,
            rates,
            reach,
            tolerance: self.tolerance(),
        })
    }
}

/// The link whose joint a robot's `q.<joint>` variable is the position of;
/// None for any other variable, or a scene that is no robot.
fn joint_link(p: &Prepared, variable: &str) -> Option<usize> {
    let (robot, joint) = (p.robot.as_ref()?, variable.strip_prefix("q.")?);
    (1..p.model.len()).find(|&i| robot.joints[i] == joint)
}

/// A joint target's check against the joint's limits.
fn within_limits(
    targets: &BTreeMap<String, f64>,
    p: &Prepared,
) -> Result<(), (&'static str, String)> {
    for (variable, &target) in targets {
        let range = joint_link(p, variable).and_then(|i| p.laws[i].as_ref()?.range);
        if let Some((low, high)) = range.filter(|(l, h)| !(*l..=*h).contains(&target)) {
            return Err((
                "targets",
                format!(
                    "`{variable}` = {target} rad is out of the joint's reach: its limits \
                     are {low} to {high} rad"
                ),
            ));
        }
    }
    Ok(())
}

/// The point a `reach-point` task brings to its target — URDF frame
/// `frame`'s origin, placed from the joints between it and the welded base
/// — and the robot; an error when scene `p` has no such frame or its base
/// moves.
fn chain_point<'p>(
    frame: &str,
    p: &'p Prepared,
) -> Result<(ChainPoint, &'p alnlab_physics::urdf::Robot), String> {
    let Some(robot) = &p.robot else {
        return Err(format!(
            "scene `{}` is no robot (a urdf scene), so it has no frame `{frame}`",
            p.scene.name
        ));
    };
    let Some(f) = robot.frame(frame) else {
        let names: Vec<&str> = robot.frames.iter().map(|f| f.name.as_str()).collect();
        return Err(format!(
            "robot `{}` has no frame `{frame}` (its URDF links are {})",
            robot.name,
            names.join(", ")
        ));
    };
    if p.model.root != Root::Fixed {
        return Err(format!(
            "robot `{}`'s base is not welded to the world (the scene's `root`), so where \
             `{frame}` is depends on the base's motion too; reach-point plans arms on a fixed base",
            robot.name
        ));
    }
    // A urdf scene welds its base, unturned, at the initial height.
    let base = Vector3::new(0.0, 0.0, p.scene.initial_height.unwrap_or(0.0));
    let chain = ChainPoint::new(
        &p.model,
        Matrix3::identity(),
        base,
        f.body,
        f.placement.translation.vector,
    )?;
    Ok((chain, robot))
}

/// A task's cost per frame over a scene's variables.
#[derive(Clone, Debug, PartialEq)]
pub struct Cost {
    /// (variable index, target, whether the difference is an angle's); for
    /// a point to reach, its joints' positions (their targets unused).
    terms: Vec<(usize, f64, bool)>,
    /// The point to reach and its target (m), placed from the terms'
    /// variables in order.
    reach: Option<(ChainPoint, Vector3<f64>)>,
    /// (velocity variable index, weight): each costs weight × its square
    /// on top of the terms (a task's `velocity_weight`); read after the
    /// terms' variables, never part of the error.
    rates: Vec<(usize, f64)>,
    /// The task's [`Task::tolerance`].
    tolerance: f64,
}

impl Cost {
    /// The cost of one frame's variable values (SI).
    pub fn of(&self, values: &[f64]) -> f64 {
        if let Some((chain, target)) = &self.reach {
            return (chain.position(|k| values[self.terms[k].0]) - target).norm_squared();
        }
        let rates: f64 = self
            .rates
            .iter()
            .map(|&(i, w)| w * values[i] * values[i])
            .sum();
        self.terms
            .iter()
            .map(|&(i, target, angle)| {
                let d = if angle {
                    on_circle(values[i] - target)
                } else {
                    values[i] - target
                };
                d * d
            })
            .sum::<f64>()
            + rates
    }

    /// A frame's error in the task's physical unit ([`Task::error_unit`]):
    /// the largest of its angles still to go (on the circle) or its rate's
    /// miss; for a point to reach, the distance still to go.
    pub fn error(&self, values: &[f64]) -> f64 {
        if self.reach.is_some() {
            return self.of(values).sqrt();
        }
        self.terms
            .iter()
            .map(|&(i, target, angle)| {
                let d = values[i] - target;
                if angle { on_circle(d) } else { d }.abs()
            })
            // A NaN (a lost state) is an error, not the smallest one.
            .fold(0.0, |a: f64, b| match a.is_nan() || b.is_nan() {
                true => f64::NAN,
                false => a.max(b),
            })
    }

    /// The error within which a frame counts as there.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// The variables the cost reads: its terms', then its rates'.
    pub fn variables(&self) -> impl Iterator<Item = usize> + '_ {
        self.terms
            .iter()
            .map(|t| t.0)
            .chain(self.rates.iter().map(|r| r.0))
    }

    /// The RMS distance of two sets of the task's variables' values (each in
    /// the order of [`Cost::variables`]), angles on the circle — for a point
    /// to reach, the distance between where each places it (m): how far a
    /// prediction is from what happened, in the task's own terms (the
    /// positions': velocities a task weighs are left out).
    pub fn distance(&self, a: &[f64], b: &[f64]) -> f64 {
        if let Some((chain, _)) = &self.reach {
            return (chain.position(|k| a[k]) - chain.position(|k| b[k])).norm();
        }
        let squares: f64 = self
            .terms
            .iter()
            .zip(a.iter().zip(b))
            .map(|(&(_, _, angle), (x, y))| {
                let d = if angle { on_circle(x - y) } else { x - y };
                d * d
            })
            .sum();
        (squares / self.terms.len().max(1) as f64).sqrt()
    }
}

/// An angle difference brought within [−π, π).
fn on_circle(d: f64) -> f64 {
    (d + PI).rem_euclid(TAU) - PI
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_task_says_what_it_asks_and_in_what_unit_it_costs() {
        let bend = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "bend".into(),
            targets: BTreeMap::from([("pitch.2".into(), 0.6), ("pitch.3".into(), -0.6)]),
        };
        assert_eq!(
            bend.describe(),
            "reach and hold `pitch.2` to 0.6 rad and `pitch.3` to -0.6 rad; a frame costs the \
             sum of the squared angles still to go (rad², on the circle)"
        );
        assert_eq!(bend.cost_unit(), "rad²");
        let spin = Task::Spin {
            tolerance: None,
            name: "spin".into(),
            variable: "omega.3.x".into(),
            rate: 2.0,
        };
        assert!(spin.describe().starts_with("spin `omega.3.x` at 2 rad/s"));
        assert_eq!(spin.cost_unit(), "(rad/s)²");
    }

    fn names() -> Vec<String> {
        ["omega.1.x", "roll.2", "pitch.2", "v.1.x"]
            .map(String::from)
            .to_vec()
    }

    /// A worm, for tasks that need no robot.
    fn worm() -> Prepared {
        Prepared::new(&alnlab_physics::Scene::default())
    }

    /// The UR5 of the workspace's `robots/`, welded at the initial height.
    fn ur5() -> Prepared {
        let mut scene = alnlab_physics::Scene {
            name: "ur5".into(),
            kind: alnlab_physics::SceneKind::Urdf,
            file: Some("robots/ur5/ur5_robot.urdf".into()),
            ..alnlab_physics::Scene::default()
        };
        let workspace = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        scene.read_description(&workspace).unwrap();
        Prepared::new(&scene)
    }

    fn reach(frame: &str, target: [f64; 3]) -> Task {
        Task::ReachPoint {
            tolerance: None,
            name: "reach".into(),
            frame: frame.into(),
            target,
        }
    }

    #[test]
    fn reach_point_costs_the_squared_distance_of_the_frame_from_its_target() {
        let p = ur5();
        let names = p.variables.names();
        let task = reach("tool0", [0.3, 0.2, 0.5]);
        task.validate().unwrap();
        task.within(&p).unwrap();
        let cost = task.over(&names, &p).unwrap();
        let joints: Vec<&str> = cost.variables().map(|i| names[i].as_str()).collect();
        assert_eq!(joints.len(), 6, "{joints:?}");
        assert!(joints.iter().all(|j| j.starts_with("q.")), "{joints:?}");
        // At every joint zero, tool0 is where the physics places it; the
        // cost is its squared distance from the target, the one-step
        // distance of two poses the distance between their tool points.
        let zero = vec![0.0; names.len()];
        let (chain, _) = chain_point("tool0", &p).unwrap();
        let at_zero = chain.position(|_| 0.0);
        let to_go = (at_zero - Vector3::new(0.3, 0.2, 0.5)).norm_squared();
        assert!((cost.of(&zero) - to_go).abs() < 1e-12);
        let mut bent = zero.clone();
        let first = cost.variables().next().unwrap();
        bent[first] = 0.5;
        let moved = chain.position(|k| if k == 0 { 0.5 } else { 0.0 });
        let d = cost.distance(&[0.0; 6], &[0.5, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert!((d - (moved - at_zero).norm()).abs() < 1e-12, "{d}");
        assert!(d > 0.01, "turning the base joint moves the tool: {d}");
        assert_eq!(task.cost_unit(), "m²");
        assert!(
            task.describe()
                .starts_with("bring frame `tool0` to (0.3, 0.2, 0.5) m")
        );
    }

    #[test]
    fn reach_point_refuses_unknown_frames_unreachable_targets_and_non_robots() {
        let p = ur5();
        let (field, message) = reach("gripper", [0.3, 0.0, 0.5]).within(&p).unwrap_err();
        assert_eq!(field, "frame");
        assert!(
            message.contains("no frame `gripper`") && message.contains("tool0"),
            "{message}"
        );
        let (field, message) = reach("tool0", [3.0, 0.0, 0.5]).within(&p).unwrap_err();
        assert_eq!(field, "target");
        assert!(message.contains("out of `tool0`'s reach"), "{message}");
        let (field, message) = reach("tool0", [0.3, 0.0, 0.5]).within(&worm()).unwrap_err();
        assert_eq!(field, "frame");
        assert!(message.contains("is no robot"), "{message}");
        let (field, _) = reach("tool0", [f64::NAN, 0.0, 0.0]).validate().unwrap_err();
        assert_eq!(field, "target");
    }

    #[test]
    fn hold_angles_costs_squared_angles_on_the_circle() {
        let task = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "hold".into(),
            targets: BTreeMap::from([("roll.2".into(), 0.5), ("pitch.2".into(), 3.0)]),
        };
        task.validate().unwrap();
        let cost = task.over(&names(), &worm()).unwrap();
        // roll 0.5 on target; pitch −3.0 is 2π − 6 ≈ 0.283 from 3.0 the short way.
        let c = cost.of(&[9.0, 0.5, -3.0, 1.0]);
        let short = TAU - 6.0;
        assert!((c - short * short).abs() < 1e-12, "{c}");
        assert!((cost.of(&[0.0, 0.7, 3.0, 0.0]) - 0.04).abs() < 1e-12);
        // Its error is the largest angle still to go, in rad; within the
        // default tolerance of 0.05 rad a frame counts as there.
        assert!((cost.error(&[9.0, 0.5, -3.0, 1.0]) - short).abs() < 1e-12);
        assert!((cost.error(&[0.0, 0.7, 3.0, 0.0]) - 0.2).abs() < 1e-12);
        assert_eq!((task.tolerance(), task.error_unit()), (0.05, "rad"));
        assert_eq!(cost.tolerance(), 0.05);
        assert_eq!(
            cost.variables().collect::<Vec<_>>(),
            [2, 1],
            "pitch.2 sorts first"
        );
    }

    /// Holding from rest on target, and stopping there: the start state
    /// has the target joints at their targets and nothing moving; each
    /// frame costs the velocities too, which the error leaves out.
    #[test]
    fn a_hold_may_start_on_target_at_rest_and_weigh_the_joints_velocities() {
        let p = ur5();
        let names = p.variables.names();
        let task = Task::HoldAngles {
            name: "hold".into(),
            targets: BTreeMap::from([
                ("q.shoulder_lift_joint".into(), -1.2),
                ("q.elbow_joint".into(), 1.0),
            ]),
            tolerance: None,
            start: HoldStart::AtTarget,
            velocity_weight: Some(0.01),
        };
        task.validate().unwrap();
        assert!(
            task.describe()
                .starts_with("starting there at rest, hold `q.elbow_joint`")
        );
        assert!(
            task.describe().ends_with("(stop there)"),
            "{}",
            task.describe()
        );
        let mut logged = State::rest(&p.model, Vector3::zeros());
        logged.q.iter_mut().for_each(|q| *q = 0.3);
        logged.qd.iter_mut().for_each(|qd| *qd = 2.0);
        let start = task.start_state(&p, &logged);
        let robot = p.robot.as_ref().unwrap();
        for i in 1..p.model.len() {
            let expected = match robot.joints[i].as_str() {
                "shoulder_lift_joint" => -1.2,
                "elbow_joint" => 1.0,
                _ => 0.3,
            };
            assert_eq!(
                (start.q[i], start.qd[i]),
                (expected, 0.0),
                "{}",
                robot.joints[i]
            );
        }
        let cost = task.over(&names, &p).unwrap();
        let read: Vec<&str> = cost.variables().map(|i| names[i].as_str()).collect();
        assert_eq!(
            read,
            [
                "q.elbow_joint",
                "q.shoulder_lift_joint",
                "qd.elbow_joint",
                "qd.shoulder_lift_joint"
            ]
        );
        let mut values = vec![0.0; names.len()];
        let at = |name: &str| names.iter().position(|n| n == name).unwrap();
        values[at("q.elbow_joint")] = 1.1;
        values[at("q.shoulder_lift_joint")] = -1.2;
        values[at("qd.elbow_joint")] = 3.0;
        // 0.1² for the angle, 0.01 × 3² for the velocity.
        assert!((cost.of(&values) - (0.01 + 0.09)).abs() < 1e-12);
        assert!((cost.error(&values) - 0.1).abs() < 1e-12);
        // The distance of two predictions is the angles' alone.
        let (a, b) = ([1.0, -1.2, 0.0, 0.0], [1.0, -1.2, 5.0, 5.0]);
        assert_eq!(cost.distance(&a, &b), 0.0);

        // A hinge angle cannot be set, nor its velocity weighed; a weight
        // must be positive.
        let hinge = |start, velocity_weight| Task::HoldAngles {
            name: "bend".into(),
            targets: BTreeMap::from([("pitch.2".into(), 0.6)]),
            tolerance: None,
            start,
            velocity_weight,
        };
        assert_eq!(
            hinge(HoldStart::AtTarget, None).validate().unwrap_err().0,
            "start"
        );
        let (field, message) = hinge(HoldStart::Logged, Some(1.0)).validate().unwrap_err();
        assert_eq!(field, "velocity_weight");
        assert!(message.contains("`pitch.2`"), "{message}");
        let parsed: Task = toml::from_str(
            "kind = \"hold-angles\"\nname = \"h\"\ntargets = { \"q.elbow_joint\" = 1.0 }\n\
             start = \"at-target\"\nvelocity_weight = -1.0",
        )
        .unwrap();
        assert_eq!(parsed.validate().unwrap_err().0, "velocity_weight");
    }

    #[test]
    fn spin_costs_the_squared_rate_error() {
        let task = Task::Spin {
            tolerance: None,
            name: "spin".into(),
            variable: "omega.1.x".into(),
            rate: 3.0,
        };
        let cost = task.over(&names(), &worm()).unwrap();
        assert_eq!(cost.of(&[1.0, 0.0, 0.0, 0.0]), 4.0);
        assert_eq!(cost.of(&[3.0, 9.0, 9.0, 9.0]), 0.0);
    }

    #[test]
    fn bad_tasks_are_named() {
        let wrong = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "h".into(),
            targets: BTreeMap::from([("v.1.x".into(), 0.0)]),
        };
        assert_eq!(wrong.validate().unwrap_err().0, "targets");
        let missing = Task::Spin {
            tolerance: None,
            name: "s".into(),
            variable: "omega.4.x".into(),
            rate: 1.0,
        };
        let e = missing.over(&names(), &worm()).unwrap_err();
        assert!(e.contains("no variable `omega.4.x`"), "{e}");
        let parsed: Task =
            toml::from_str("kind = \"spin\"\nname = \"s\"\nvariable = \"omega.1.x\"\nrate = 2.0")
                .unwrap();
        assert_eq!(parsed.name(), "s");
        assert_eq!(parsed.tolerance(), 0.2);
        let given: Task = toml::from_str(
            "kind = \"spin\"\nname = \"s\"\nvariable = \"omega.1.x\"\nrate = 2.0\n\
             tolerance = 0.5",
        )
        .unwrap();
        assert_eq!(given.tolerance(), 0.5);
        let Task::Spin {
            name,
            variable,
            rate,
            ..
        } = given
        else {
            unreachable!("parsed as a spin")
        };
        for bad in [0.0, -1.0, f64::INFINITY] {
            let task = Task::Spin {
                name: name.clone(),
                variable: variable.clone(),
                rate,
                tolerance: Some(bad),
            };
            let (field, message) = task.validate().unwrap_err();
            assert_eq!(field, "tolerance");
            assert!(message.contains("rad/s"), "{message}");
        }
    }
}
