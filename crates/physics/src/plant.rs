//! The plant: the system the data are logged from, where it departs from
//! the scene as written — the *nominal model* a user has, as a robot's URDF
//! is never quite the robot. A scene's `plant` table declares the
//! departure; the simulate stage logs the plant, and a simulator used as a
//! baseline or a planner's model stays nominal ([`crate::scene::Scene::nominal`]).
//!
//! - **Masses**: every body's mass and rotational inertia scaled
//!   (`mass_scale`; each centre of mass kept), and a point mass fixed to a
//!   link (`payload`: a tool, a load).
//! - **Joint friction** beyond the description's: viscous at every joint
//!   (`viscous_friction`), Coulomb at every one-DOF joint
//!   (`coulomb_friction`), under the joint laws of [`crate::joints`].
//! - **Actuators**: the torque an actuator produces per unit of command
//!   (`actuator_gain`), a first-order lag (`actuator_lag`), a delay
//!   (`actuator_delay_frames`) and Gaussian noise (`torque_noise`, seeded by
//!   the run) — [`Actuators`]; the command stays what is logged as `tau`, and
//!   the torque applied is logged beside the state (`joint.<j>.applied`).
//! - **Contact**: a contact law of its own (`contact`).
//! - **Sensors**: a robot's logged joint positions and velocities are the
//!   truth plus Gaussian noise (`sensor_noise`), drawn every frame.
//!
//! A plant whose every value is nominal is no plant: [`Plant::is_nominal`],
//! and resolving a scene drops it, so its artifacts are bit for bit those of
//! the scene without one.

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::contact::ContactParams;
use crate::model::Model;
use crate::spatial::parallel_axis;

/// How a scene's plant differs from its description. Every field left out
/// is nominal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Plant {
    /// Every body's mass and rotational inertia times this (> 0), its
    /// centre of mass kept.
    #[serde(skip_serializing_if = "is_one")]
    pub mass_scale: f64,
    /// A point mass fixed to a link.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub payload: Option<Payload>,
    /// Viscous friction at every joint beyond the description's and the
    /// scene's `hinge_damping` (N m s/rad, or N s/m for a prismatic joint).
    #[serde(skip_serializing_if = "is_zero")]
    pub viscous_friction: f64,
    /// Coulomb friction at every one-DOF joint beyond the description's
    /// (N m or N).
    #[serde(skip_serializing_if = "is_zero")]
    pub coulomb_friction: f64,
    /// The torque (or force) an actuator produces per unit of command (> 0);
    /// the effort limit (a ball hinge's: the controller's torque limit) still
    /// caps what it applies.
    #[serde(skip_serializing_if = "is_one")]
    pub actuator_gain: f64,
    /// The actuators' first-order lag: the time constant (s) with which
    /// what they produce follows the command (0: none).
    #[serde(skip_serializing_if = "is_zero")]
    pub actuator_lag: f64,
    /// Frames before a command reaches the actuators (a bus, a controller
    /// cycle); until the first arrives they produce nothing but their noise.
    #[serde(skip_serializing_if = "is_zero_frames")]
    pub actuator_delay_frames: u64,
    /// The standard deviation of a Gaussian noise on every actuator's
    /// output (N m or N), drawn afresh each integration step, seeded by the
    /// run.
    #[serde(skip_serializing_if = "is_zero")]
    pub torque_noise: f64,
    /// The plant's contact law, in the scene's place (the scene's is the
    /// nominal model's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<ContactParams>,
    /// A robot's joint sensors: what is logged of each joint's position and
    /// velocity is the truth plus Gaussian noise, as an encoder and its
    /// differentiation report it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor_noise: Option<SensorNoise>,
}

/// The standard deviations of a robot's joint sensors' noise, drawn afresh
/// every logged frame, seeded by the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorNoise {
    /// On each joint position (rad or m).
    pub position: f64,
    /// On each joint velocity (rad/s or m/s).
    pub velocity: f64,
}

/// A point mass fixed to a link.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Payload {
    /// The link: a robot's URDF link name, or a chain's link number (`"1"`
    /// the root).
    pub link: String,
    /// Its mass (kg, > 0).
    pub mass: f64,
    /// Where it sits in the link's frame (m).
    #[serde(default)]
    pub offset: [f64; 3],
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn is_zero_frames(x: &u64) -> bool {
    *x == 0
}

impl Default for Plant {
    fn default() -> Self {
        Plant {
            mass_scale: 1.0,
            payload: None,
            viscous_friction: 0.0,
            coulomb_friction: 0.0,
            actuator_gain: 1.0,
            actuator_lag: 0.0,
            actuator_delay_frames: 0,
            torque_noise: 0.0,
            contact: None,
            sensor_noise: None,
        }
    }
}

impl Plant {
    /// Whether every value is nominal: the plant is the scene as written.
    pub fn is_nominal(&self) -> bool {
        let quiet = self
            .sensor_noise
            .as_ref()
            .is_none_or(|n| *n == SensorNoise::default());
        quiet
            && Plant {
                sensor_noise: None,
                ..self.clone()
            } == Plant::default()
    }

    /// The sensors' noise, where there is any.
    pub fn sensors(&self) -> Option<&SensorNoise> {
        self.sensor_noise
            .as_ref()
            .filter(|n| **n != SensorNoise::default())
    }

    /// Whether the actuators produce other than the command.
    pub fn has_actuators(&self) -> bool {
        self.actuator_gain != 1.0
            || self.actuator_lag != 0.0
            || self.actuator_delay_frames != 0
            || self.torque_noise != 0.0
    }

    /// Checks the values; on error, the field (within `plant`) and what is
    /// allowed.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let err = |field: &str, what: &str, v: f64| {
            Err((field.to_string(), format!("expected {what}, found {v}")))
        };
        for (field, v) in [
            ("mass_scale", self.mass_scale),
            ("actuator_gain", self.actuator_gain),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return err(field, "a finite number > 0 (1: as described)", v);
            }
        }
        for (field, v) in [
            ("viscous_friction", self.viscous_friction),
            ("coulomb_friction", self.coulomb_friction),
            ("actuator_lag", self.actuator_lag),
            ("torque_noise", self.torque_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return err(field, "a finite number ≥ 0 (0: as described)", v);
            }
        }
        if self.actuator_delay_frames > 1000 {
            return Err((
                "actuator_delay_frames".into(),
                format!(
                    "expected at most 1000 frames, found {}",
                    self.actuator_delay_frames
                ),
            ));
        }
        if let Some(n) = &self.sensor_noise {
            for (field, v) in [
                ("sensor_noise.position", n.position),
                ("sensor_noise.velocity", n.velocity),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return err(field, "a finite number ≥ 0 (0: exact)", v);
                }
            }
        }
        if let Some(c) = &self.contact {
            for (field, v) in [
                ("contact.damping", c.damping),
                ("contact.friction", c.friction),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return err(field, "a finite number ≥ 0", v);
                }
            }
        }
        if let Some(p) = &self.payload {
            if !(p.mass.is_finite() && p.mass > 0.0) {
                return err("payload.mass", "a finite mass > 0 (kg)", p.mass);
            }
            if let Some(v) = p.offset.iter().find(|v| !v.is_finite()) {
                return err("payload.offset", "three finite numbers (m)", *v);
            }
        }
        Ok(())
    }

    /// `model` as the plant has it: masses and inertias scaled, and the
    /// payload added to the body `payload_at.0` at the point `payload_at.1`
    /// of its frame (the payload's link placed on its body).
    pub fn perturb(&self, model: &mut Model, payload_at: Option<(usize, Isometry3<f64>)>) {
        if self.mass_scale != 1.0 {
            for link in &mut model.links {
                link.mass *= self.mass_scale;
                link.inertia_com *= self.mass_scale;
            }
        }
        if let (Some(payload), Some((body, placement))) = (&self.payload, payload_at) {
            let at = placement * Point3::from(Vector3::from(payload.offset));
            let link = &mut model.links[body];
            let (m, p) = (payload.mass, at.coords);
            let total = link.mass + m;
            let c = (link.c * link.mass + p * m) / total;
            // Both inertias moved to the new centre of mass (parallel axes).
            let inertia: Matrix3<f64> = link.inertia_com
                + parallel_axis(&(link.c - c)) * link.mass
                + parallel_axis(&(p - c)) * m;
            link.mass = total;
            link.c = c;
            link.inertia_com = (inertia + inertia.transpose()) * 0.5;
        }
    }
}

/// The plant's actuators in one run: what they produce from the commands
/// over time — delayed, lagging, scaled and noisy — one update per
/// integration step, however often a step's torques are asked for.
#[derive(Clone)]
pub struct Actuators {
    gain: f64,
    /// The lag's weight of the new command in one step, 1 − e^(−dt/τ);
    /// `None`: no lag.
    follow: Option<f64>,
    /// Commands on their way, oldest first; `delay` steps long when full.
    queue: std::collections::VecDeque<Vec<Vector3<f64>>>,
    delay: usize,
    noise: Option<(rand_chacha::ChaCha8Rng, f64)>,
    /// What each produces now but for the noise (the lag's state).
    filtered: Vec<Vector3<f64>>,
    /// What each produces now.
    output: Vec<Vector3<f64>>,
    /// The instant of the last update.
    last: Option<f64>,
}

impl Actuators {
    /// The actuators of `plant` for `hinges` hinges, updated every `dt`
    /// with `steps_per_frame` steps a frame, their noise seeded by `seed`.
    pub fn new(plant: &Plant, hinges: usize, dt: f64, steps_per_frame: u64, seed: u64) -> Self {
        use rand::SeedableRng;
        Actuators {
            gain: plant.actuator_gain,
            follow: (plant.actuator_lag > 0.0).then(|| 1.0 - (-dt / plant.actuator_lag).exp()),
            queue: std::collections::VecDeque::new(),
            delay: (plant.actuator_delay_frames * steps_per_frame) as usize,
            noise: (plant.torque_noise > 0.0).then(|| {
                (
                    rand_chacha::ChaCha8Rng::seed_from_u64(seed),
                    plant.torque_noise,
                )
            }),
            filtered: vec![Vector3::zeros(); hinges],
            output: vec![Vector3::zeros(); hinges],
            last: None,
        }
    }

    /// Updates every `dt`, `steps_per_frame` a frame, from now on (a
    /// simulator stepping the plant coarser than its scene does): the lag's
    /// weight and the delay's length in updates follow; commands on their
    /// way are forgotten where the length changes.
    pub fn pace(&mut self, plant: &Plant, dt: f64, steps_per_frame: u64) {
        self.follow = (plant.actuator_lag > 0.0).then(|| 1.0 - (-dt / plant.actuator_lag).exp());
        let delay = (plant.actuator_delay_frames * steps_per_frame) as usize;
        if delay != self.delay {
            self.delay = delay;
            self.queue.clear();
        }
    }

    /// Forgets every command on its way and the lag's state, as at a run's
    /// start (the noise's stream goes on).
    pub fn reset(&mut self) {
        self.queue.clear();
        self.filtered.fill(Vector3::zeros());
        self.output.fill(Vector3::zeros());
        self.last = None;
    }

    /// What the actuators produce at the step starting at `t` under
    /// `command` (one per hinge): updated once per instant, so asking again
    /// at the same `t` (observing a frame, then stepping from it) changes
    /// nothing.
    pub fn update(&mut self, t: f64, command: &[Vector3<f64>]) -> &[Vector3<f64>] {
        if self.last == Some(t) {
            return &self.output;
        }
        self.last = Some(t);
        let arrived = if self.delay == 0 {
            Some(command.to_vec())
        } else {
            self.queue.push_back(command.to_vec());
            (self.queue.len() > self.delay).then(|| self.queue.pop_front().expect("queued"))
        };
        let target = arrived.unwrap_or_else(|| vec![Vector3::zeros(); command.len()]);
        for (y, u) in self.filtered.iter_mut().zip(&target) {
            *y = match self.follow {
                Some(follow) => *y + (u * self.gain - *y) * follow,
                None => u * self.gain,
            };
        }
        self.output.copy_from_slice(&self.filtered);
        if let Some((rng, sigma)) = &mut self.noise {
            use rand_distr::Distribution;
            for out in &mut self.output {
                for x in out.iter_mut() {
                    let z: f64 = rand_distr::StandardNormal.sample(rng);
                    *x += *sigma * z;
                }
            }
        }
        &self.output
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Joint, Link, Root};

    fn model() -> Model {
        let link = |parent| Link {
            parent,
            joint: Joint::Ball,
            mass: 2.0,
            c: Vector3::new(0.25, 0.0, 0.0),
            inertia_com: Matrix3::from_diagonal(&Vector3::new(0.01, 0.05, 0.05)),
            l: Vector3::new(0.5, 0.0, 0.0),
            tip: None,
        };
        Model {
            root: Root::Pinned,
            links: vec![link(None), link(Some(0))],
            gravity: Vector3::zeros(),
            couplings: Vec::new(),
        }
    }

    #[test]
    fn a_nominal_plant_changes_nothing() {
        let mut m = model();
        let before = format!("{m:?}");
        Plant::default().perturb(&mut m, None);
        assert_eq!(format!("{m:?}"), before);
        assert!(Plant::default().is_nominal());
        let toml = "mass_scale = 1.0\nviscous_friction = 0.0";
        assert!(toml::from_str::<Plant>(toml).unwrap().is_nominal());
    }

    #[test]
    fn scaled_masses_and_a_payload_move_as_the_parallel_axes_say() {
        let mut m = model();
        let plant = Plant {
            mass_scale: 2.0,
            payload: Some(Payload {
                link: "2".into(),
                mass: 1.0,
                offset: [1.0, 0.0, 0.0],
            }),
            ..Plant::default()
        };
        plant.perturb(&mut m, Some((1, Isometry3::identity())));
        assert_eq!(m.links[0].mass, 4.0);
        assert_eq!(m.links[0].inertia_com[(1, 1)], 0.1);
        // Link 2: 4 kg at x = 0.25 and 1 kg at x = 1: 5 kg at x = 0.4.
        let l = &m.links[1];
        assert_eq!(l.mass, 5.0);
        assert!((l.c.x - 0.4).abs() < 1e-15);
        // About y: 0.1 + 4·0.15² + 1·0.6² = 0.55; about x unchanged (0.02).
        assert!((l.inertia_com[(1, 1)] - 0.55).abs() < 1e-14);
        assert!((l.inertia_com[(0, 0)] - 0.02).abs() < 1e-15);
        // The inertia about the hinge is the sum of the parts'.
        let hinge = l.inertia_hinge();
        assert!((hinge[(2, 2)] - (0.1 + 4.0 * 0.0625 + 1.0)).abs() < 1e-14);
    }

    #[test]
    fn actuators_delay_lag_and_scale_the_command_once_per_step() {
        let plant = Plant {
            actuator_gain: 0.5,
            actuator_lag: 0.01,
            actuator_delay_frames: 1,
            ..Plant::default()
        };
        // 2 steps a frame of 1 ms: the command arrives 2 steps late.
        let mut a = Actuators::new(&plant, 1, 1e-3, 2, 0);
        let u = [Vector3::new(4.0, 0.0, 0.0)];
        assert_eq!(a.update(0.0, &u)[0].x, 0.0);
        assert_eq!(a.update(0.0, &u)[0].x, 0.0, "the same instant again");
        assert_eq!(a.update(1e-3, &u)[0].x, 0.0);
        let follow = 1.0 - (-0.1f64).exp();
        let first = a.update(2e-3, &u)[0].x;
        assert!((first - 2.0 * follow).abs() < 1e-15, "{first}");
        let second = a.update(3e-3, &u)[0].x;
        assert!((second - (first + (2.0 - first) * follow)).abs() < 1e-15);
        // Noise: seeded, zero-mean, its spread as stated.
        let noisy = Plant {
            torque_noise: 0.3,
            ..Plant::default()
        };
        let draws = |seed| {
            let mut a = Actuators::new(&noisy, 1, 1e-3, 1, seed);
            (0..4000)
                .map(|k| a.update(k as f64, &[Vector3::zeros()])[0].y)
                .collect::<Vec<_>>()
        };
        let x = draws(5);
        assert_eq!(x, draws(5));
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let sd = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 3999.0).sqrt();
        assert!(mean.abs() < 0.02 && (sd - 0.3).abs() < 0.02, "{mean} {sd}");
    }

    #[test]
    fn values_a_plant_cannot_have_are_named() {
        for (toml, field) in [
            ("mass_scale = 0.0", "mass_scale"),
            ("actuator_gain = -1.0", "actuator_gain"),
            ("coulomb_friction = -0.1", "coulomb_friction"),
            ("payload = { link = \"tool0\", mass = 0.0 }", "payload.mass"),
        ] {
            let plant: Plant = toml::from_str(toml).unwrap();
            assert_eq!(plant.validate().unwrap_err().0, field, "{toml}");
        }
        assert!(toml::from_str::<Plant>("mass_scal = 2.0").is_err());
    }
}
