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
//!   (`actuator_gain`); the command stays what is logged as `tau`, and the
//!   torque applied is logged beside the state (`joint.<j>.applied`).
//!
//! A plant whose every value is nominal is no plant: [`Plant::is_nominal`],
//! and resolving a scene drops it, so its artifacts are bit for bit those of
//! the scene without one.

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use serde::{Deserialize, Serialize};

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
    /// the effort limit still caps what it produces.
    #[serde(skip_serializing_if = "is_one")]
    pub actuator_gain: f64,
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

impl Default for Plant {
    fn default() -> Self {
        Plant {
            mass_scale: 1.0,
            payload: None,
            viscous_friction: 0.0,
            coulomb_friction: 0.0,
            actuator_gain: 1.0,
        }
    }
}

impl Plant {
    /// Whether every value is nominal: the plant is the scene as written.
    pub fn is_nominal(&self) -> bool {
        *self == Plant::default()
    }

    /// Whether the actuators produce other than the command.
    pub fn has_actuators(&self) -> bool {
        self.actuator_gain != 1.0
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
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return err(field, "a finite number ≥ 0 (0: as described)", v);
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
