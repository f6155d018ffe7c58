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
//!   long axis.

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};

use alnlab_physics::Prepared;
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
    },
    /// Spin at a rate.
    Spin {
        name: String,
        /// An angular velocity component, e.g. `omega.1.x`.
        variable: String,
        /// Target rate (rad/s).
        rate: f64,
    },
}

impl Task {
    /// The task's name.
    pub fn name(&self) -> &str {
        match self {
            Task::HoldAngles { name, .. } | Task::Spin { name, .. } => name,
        }
    }

    /// What the task asks and what a frame costs, in words with units:
    /// "pitch.2 to 0.6 rad and pitch.3 to -0.6 rad; a frame costs the sum of
    /// the squared angles to go (rad², on the circle)".
    pub fn describe(&self) -> String {
        match self {
            Task::HoldAngles { targets, .. } => {
                let each: Vec<String> = targets
                    .iter()
                    .map(|(v, t)| format!("`{v}` to {t} rad"))
                    .collect();
                format!(
                    "reach and hold {}; a frame costs the sum of the squared angles still to go \
                     (rad², on the circle)",
                    each.join(" and ")
                )
            }
            Task::Spin { variable, rate, .. } => format!(
                "spin `{variable}` at {rate} rad/s; a frame costs the squared difference from \
                 that rate ((rad/s)²)"
            ),
        }
    }

    /// The unit of a frame's cost, and so of an episode's.
    pub fn cost_unit(&self) -> &'static str {
        match self {
            Task::HoldAngles { .. } => "rad²",
            Task::Spin { .. } => "(rad/s)²",
        }
    }

    /// Checks the task on its own: targets named as angles, finite numbers.
    /// On error, the field and the message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        match self {
            Task::HoldAngles { targets, .. } => {
                if targets.is_empty() {
                    return Err(("targets", "expected at least one target angle".into()));
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
        }
        Ok(())
    }

    /// Checks the task against scene `p`: a joint's target within the
    /// joint's limits, where the robot description gives them. On error,
    /// the field and the message.
    pub fn within(&self, p: &Prepared) -> Result<(), (&'static str, String)> {
        let (Task::HoldAngles { targets, .. }, Some(robot)) = (self, &p.robot) else {
            return Ok(());
        };
        for (variable, &target) in targets {
            let Some(joint) = variable.strip_prefix("q.") else {
                continue;
            };
            let range = (1..p.model.len())
                .find(|&i| robot.joints[i] == joint)
                .and_then(|i| p.laws[i].as_ref()?.range);
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

    /// The task over variables in the order of `names` (a scene's learned
    /// or logged variables); an error names a variable the scene lacks.
    pub fn over(&self, names: &[String]) -> Result<Cost, String> {
        let index = |v: &str| {
            names.iter().position(|n| n == v).ok_or_else(|| {
                format!(
                    "task `{}`: the scene has no variable `{v}` (it has {})",
                    self.name(),
                    names.join(", ")
                )
            })
        };
        let terms = match self {
            Task::HoldAngles { targets, .. } => targets
                .iter()
                .map(|(v, &target)| Ok((index(v)?, target, true)))
                .collect::<Result<_, String>>()?,
            Task::Spin { variable, rate, .. } => vec![(index(variable)?, *rate, false)],
        };
        Ok(Cost { terms })
    }
}

/// A task's cost per frame over a scene's variables.
#[derive(Clone, Debug, PartialEq)]
pub struct Cost {
    /// (variable index, target, whether the difference is an angle's).
    terms: Vec<(usize, f64, bool)>,
}

impl Cost {
    /// The cost of one frame's variable values (SI).
    pub fn of(&self, values: &[f64]) -> f64 {
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
            .sum()
    }

    /// The variables the cost reads.
    pub fn variables(&self) -> impl Iterator<Item = usize> + '_ {
        self.terms.iter().map(|t| t.0)
    }

    /// The RMS distance of two sets of the task's variables' values (each in
    /// the order of [`Cost::variables`]), angles on the circle: how far a
    /// prediction is from what happened, in the task's own terms.
    pub fn distance(&self, a: &[f64], b: &[f64]) -> f64 {
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

    #[test]
    fn hold_angles_costs_squared_angles_on_the_circle() {
        let task = Task::HoldAngles {
            name: "hold".into(),
            targets: BTreeMap::from([("roll.2".into(), 0.5), ("pitch.2".into(), 3.0)]),
        };
        task.validate().unwrap();
        let cost = task.over(&names()).unwrap();
        // roll 0.5 on target; pitch −3.0 is 2π − 6 ≈ 0.283 from 3.0 the short way.
        let c = cost.of(&[9.0, 0.5, -3.0, 1.0]);
        let short = TAU - 6.0;
        assert!((c - short * short).abs() < 1e-12, "{c}");
        assert!((cost.of(&[0.0, 0.7, 3.0, 0.0]) - 0.04).abs() < 1e-12);
        assert_eq!(
            cost.variables().collect::<Vec<_>>(),
            [2, 1],
            "pitch.2 sorts first"
        );
    }

    #[test]
    fn spin_costs_the_squared_rate_error() {
        let task = Task::Spin {
            name: "spin".into(),
            variable: "omega.1.x".into(),
            rate: 3.0,
        };
        let cost = task.over(&names()).unwrap();
        assert_eq!(cost.of(&[1.0, 0.0, 0.0, 0.0]), 4.0);
        assert_eq!(cost.of(&[3.0, 9.0, 9.0, 9.0]), 0.0);
    }

    #[test]
    fn bad_tasks_are_named() {
        let wrong = Task::HoldAngles {
            name: "h".into(),
            targets: BTreeMap::from([("v.1.x".into(), 0.0)]),
        };
        assert_eq!(wrong.validate().unwrap_err().0, "targets");
        let missing = Task::Spin {
            name: "s".into(),
            variable: "omega.4.x".into(),
            rate: 1.0,
        };
        let e = missing.over(&names()).unwrap_err();
        assert!(e.contains("no variable `omega.4.x`"), "{e}");
        let parsed: Task =
            toml::from_str("kind = \"spin\"\nname = \"s\"\nvariable = \"omega.1.x\"\nrate = 2.0")
                .unwrap();
        assert_eq!(parsed.name(), "s");
    }
}
