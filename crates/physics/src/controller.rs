//! Hinge controllers: the control torque g that each hinge's link exerts on
//! its parent (paper §2), clamped componentwise to the torque limit (paper:
//! ±150). The link itself feels −g. A one-DOF joint of a robot gets one
//! number instead, its effort (the first component of its g; the others are
//! zero), which acts the other way, as ROS's joint efforts do: from the
//! parent on the child, positive along the joint's axis. It is clamped to
//! the joint's own effort limit (its URDF's), not to the torque limit.

use alnlab_core::params::Positive;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Which controller.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerKind {
    /// No torques.
    #[default]
    None,
    /// `amplitude` at every hinge, always.
    Constant,
    /// `amplitude · sin(2π · frequency · t + phase)` per hinge.
    Sine,
    /// Piecewise-constant torques, uniform in ±`amplitude`, redrawn every
    /// `hold` seconds from a seeded generator.
    Random,
    /// The efforts a recording logged (a robot's data, not a simulation's):
    /// whoever steps the scene drives them ([`crate::Runner::drive`]); the
    /// controller itself gives none. Not for a manifest's scenes.
    Logged,
}

/// A hinge's torque amplitude: three components for a ball hinge, one number
/// for a one-DOF joint.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Amplitude {
    /// A one-DOF joint's effort amplitude (N m or N).
    Axis(f64),
    /// A ball hinge's torque amplitude per axis, link frame (N m).
    Ball([f64; 3]),
}

impl Amplitude {
    /// Component `k` (0..3) as a ball hinge's; a one-DOF amplitude is its
    /// first component.
    pub fn component(&self, k: usize) -> f64 {
        match *self {
            Amplitude::Ball(a) => a[k],
            Amplitude::Axis(a) if k == 0 => a,
            Amplitude::Axis(_) => 0.0,
        }
    }

    fn dof(&self) -> usize {
        match self {
            Amplitude::Axis(_) => 1,
            Amplitude::Ball(_) => 3,
        }
    }
}

/// The `controller = { … }` table of a scene. Per-hinge lists hold one entry
/// per hinge (a robot's joint), or one entry for all.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerParams {
    /// Which controller.
    pub kind: ControllerKind,
    /// Torque amplitude per hinge: `[x, y, z]` (link frame, N m) for a ball
    /// hinge, a number for a one-DOF joint.
    pub amplitude: Vec<Amplitude>,
    /// Frequency per hinge (Hz), for `sine`.
    pub frequency: Vec<f64>,
    /// Phase per hinge (rad), for `sine`.
    pub phase: Vec<f64>,
    /// Hold time (s), for `random`.
    pub hold: Positive,
    /// Componentwise limit of every ball hinge's torque (N m); a robot
    /// joint's effort is clamped to its own limit instead.
    pub torque_limit: Positive,
}

impl Default for ControllerParams {
    fn default() -> Self {
        ControllerParams {
            kind: ControllerKind::None,
            amplitude: vec![Amplitude::Ball([1.0, 10.0, 10.0])],
            frequency: vec![1.0],
            phase: vec![0.0],
            hold: Positive(0.25),
            torque_limit: Positive(150.0),
        }
    }
}

impl ControllerParams {
    /// Checks list lengths against the hinges, each given by its degrees of
    /// freedom (3 for a ball hinge, 1 for a one-DOF joint); on error, the
    /// field and the message.
    pub fn validate(&self, dofs: &[usize]) -> Result<(), (&'static str, String)> {
        let hinges = dofs.len();
        if self.kind != ControllerKind::None && hinges == 0 {
            return Err((
                "kind",
                "a controller needs hinges or joints; this scene has one moving body".into(),
            ));
        }
        let lists = [
            ("amplitude", self.amplitude.len()),
            ("frequency", self.frequency.len()),
            ("phase", self.phase.len()),
        ];
        for (field, len) in lists {
            if len != 1 && len != hinges {
                return Err((
                    field,
                    format!("expected 1 entry or one per hinge ({hinges}), found {len}"),
                ));
            }
        }
        let components = self
            .amplitude
            .iter()
            .flat_map(|a| (0..3).map(|k| a.component(k)));
        let numbers = components.chain(self.frequency.iter().chain(&self.phase).copied());
        if numbers.into_iter().any(|x| !x.is_finite()) {
            return Err(("amplitude", "expected finite numbers".into()));
        }
        if !matches!(self.kind, ControllerKind::None | ControllerKind::Logged) {
            for (h, &dof) in dofs.iter().enumerate() {
                let a = pick(&self.amplitude, h);
                if a.dof() != dof {
                    let expected = match dof {
                        1 => "a number (a one-DOF joint's effort)",
                        _ => "[x, y, z] (a ball hinge's torque)",
                    };
                    return Err(("amplitude", format!("hinge {}: expected {expected}", h + 1)));
                }
            }
        }
        Ok(())
    }
}

/// A per-hinge list's entry for `hinge`: its own, or the one for all.
fn pick<T: Copy>(list: &[T], hinge: usize) -> T {
    list[if list.len() == 1 { 0 } else { hinge }]
}

/// A running controller for one run.
pub struct Controller {
    params: ControllerParams,
    rng: ChaCha8Rng,
    held: Vec<Vector3<f64>>,
    next_draw: f64,
}

impl Controller {
    /// The controller of one run, seeded.
    pub fn new(params: &ControllerParams, hinges: usize, seed: u64) -> Controller {
        Controller {
            params: params.clone(),
            rng: ChaCha8Rng::seed_from_u64(seed),
            held: vec![Vector3::zeros(); hinges],
            next_draw: 0.0,
        }
    }

    /// Fills `g` (one per hinge) for time `t`.
    pub fn torques(&mut self, t: f64, g: &mut [Vector3<f64>]) {
        let p = &self.params;
        match p.kind {
            ControllerKind::None | ControllerKind::Logged => g.fill(Vector3::zeros()),
            ControllerKind::Constant => {
                for (h, out) in g.iter_mut().enumerate() {
                    let a = pick(&p.amplitude, h);
                    *out = Vector3::from_fn(|k, _| a.component(k));
                }
            }
            ControllerKind::Sine => {
                for (h, out) in g.iter_mut().enumerate() {
                    let arg = std::f64::consts::TAU * pick(&p.frequency, h) * t + pick(&p.phase, h);
                    let a = pick(&p.amplitude, h);
                    *out = Vector3::from_fn(|k, _| a.component(k)) * arg.sin();
                }
            }
            ControllerKind::Random => {
                while t >= self.next_draw {
                    for (h, held) in self.held.iter_mut().enumerate() {
                        let a = pick(&p.amplitude, h);
                        *held = Vector3::from_fn(|k, _| match k < a.dof() {
                            true => a.component(k) * self.rng.random_range(-1.0..=1.0),
                            false => 0.0,
                        });
                    }
                    self.next_draw += p.hold.get();
                }
                g.copy_from_slice(&self.held);
            }
        }
        let limit = p.torque_limit.get();
        for (h, out) in g.iter_mut().enumerate() {
            if let Amplitude::Ball(_) = pick(&p.amplitude, h) {
                *out = out.map(|x| x.clamp(-limit, limit));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sine_and_clamp() {
        let params = ControllerParams {
            kind: ControllerKind::Sine,
            amplitude: vec![Amplitude::Ball([200.0, 10.0, 0.0])],
            frequency: vec![2.0],
            phase: vec![0.0, std::f64::consts::FRAC_PI_2],
            ..ControllerParams::default()
        };
        params.validate(&[3, 3]).unwrap();
        let mut c = Controller::new(&params, 2, 1);
        let mut g = [Vector3::zeros(); 2];
        c.torques(0.125, &mut g); // quarter period: sin = 1, second hinge cos = 0
        assert_eq!(g[0], Vector3::new(150.0, 10.0, 0.0));
        assert!(g[1].norm() < 1e-9);
    }

    #[test]
    fn random_holds_then_redraws_reproducibly() {
        let params = ControllerParams {
            kind: ControllerKind::Random,
            ..ControllerParams::default()
        };
        let sample = |t: f64| {
            let mut c = Controller::new(&params, 1, 7);
            let mut g = [Vector3::zeros()];
            let mut out = Vec::new();
            for k in 0..=(t / 0.05) as usize {
                c.torques(k as f64 * 0.05, &mut g);
                out.push(g[0]);
            }
            out
        };
        let a = sample(1.0);
        assert_eq!(a, sample(1.0));
        assert_eq!(a[0], a[4], "held for 0.25 s");
        assert_ne!(a[4], a[5], "redrawn after the hold");
        assert!(
            a.iter()
                .all(|g| g.x.abs() <= 1.0 && g.y.abs() <= 10.0 && g.z.abs() <= 10.0)
        );
    }

    #[test]
    fn list_lengths_are_checked() {
        let params = ControllerParams {
            kind: ControllerKind::Sine,
            phase: vec![0.0, 1.0, 2.0],
            ..ControllerParams::default()
        };
        assert_eq!(params.validate(&[3, 3]).unwrap_err().0, "phase");
        let constant = ControllerParams {
            kind: ControllerKind::Constant,
            ..ControllerParams::default()
        };
        assert_eq!(constant.validate(&[]).unwrap_err().0, "kind");
        let robot = ControllerParams {
            kind: ControllerKind::Random,
            amplitude: vec![Amplitude::Axis(5.0)],
            ..ControllerParams::default()
        };
        robot.validate(&[1, 1]).unwrap();
        assert_eq!(robot.validate(&[1, 3]).unwrap_err().0, "amplitude");
        let ball = ControllerParams {
            kind: ControllerKind::Random,
            ..ControllerParams::default()
        };
        assert!(
            ball.validate(&[1])
                .unwrap_err()
                .1
                .contains("expected a number")
        );
    }
}
