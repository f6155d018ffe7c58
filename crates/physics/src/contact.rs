//! Contacts with the floor (the plane z = 0) and the wall of a circular arena
//! (a vertical cylinder of given radius about the z axis), as in the paper's
//! "worm in its lair".
//!
//! Model: each contact point (every free hinge, and the distal end of each
//! chain end) is a sphere of the links' radius; one that penetrates a surface
//! by depth d > 0 feels a normal force
//! N = max(0, k·d + c·ḋ) (a penalty spring–damper that never pulls) and a
//! regularised Coulomb friction F_t = −μ·N·v_t / max(|v_t|, v_s), which is
//! Coulomb friction above the slip speed v_s and viscous below it. The
//! viscous coefficient μ·N / max(|v_t|, v_s) is capped at m / (2·dt) (m the
//! touching link's mass): an explicit step cannot resolve stiffer friction,
//! which would chatter and pump energy into the links during hard impacts.

use alnlab_core::params::Positive;
use nalgebra::{Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::dynamics::Kinematics;
use crate::model::{Model, Root};
use crate::spatial::spatial;

/// Contact parameters (`contact = { … }` in a scene).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactParams {
    /// Normal stiffness k (N/m).
    pub stiffness: Positive,
    /// Normal damping c (N s/m).
    pub damping: f64,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// Slip speed v_s below which friction is viscous (m/s).
    pub slip_speed: Positive,
}

impl Default for ContactParams {
    /// Stable for the worm at dt = 1 ms (and up to 2 ms): the spring's period
    /// is ~28 steps for a 1 kg link at 1 ms.
    fn default() -> Self {
        ContactParams {
            stiffness: Positive(5e4),
            damping: 200.0,
            friction: 0.6,
            slip_speed: Positive(0.05),
        }
    }
}

/// Where contacts can happen.
#[derive(Clone, Debug, PartialEq)]
pub struct Surfaces {
    /// Whether the floor z = 0 is there.
    pub floor: bool,
    /// The arena wall's radius, if there is a wall.
    pub arena_radius: Option<f64>,
    /// The contact law.
    pub params: ContactParams,
    /// The integration step, which bounds the friction's stiffness.
    pub dt: f64,
    /// Contact points are the centres of spheres of this radius (the links'
    /// radius), so a chain rests on its surface rather than its axis.
    pub point_radius: f64,
}

/// A contact point: link and offset from its hinge (link frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactPoint {
    pub link: usize,
    pub offset: Vector3<f64>,
}

/// The contact points of a model: every hinge that can move (a joint point
/// counts once, for the child link) and every distal end point.
pub fn contact_points(model: &Model) -> Vec<ContactPoint> {
    let mut points = Vec::new();
    for (i, link) in model.links.iter().enumerate() {
        if !(i == 0 && model.root == Root::Pinned) {
            points.push(ContactPoint {
                link: i,
                offset: Vector3::zeros(),
            });
        }
        if let Some(tip) = link.tip {
            points.push(ContactPoint {
                link: i,
                offset: tip,
            });
        }
    }
    points
}

impl Surfaces {
    /// Whether there is any surface to touch.
    pub fn any(&self) -> bool {
        self.floor || self.arena_radius.is_some()
    }

    /// Adds the contact forces on every point to `f_ext` (link frame, at the
    /// hinge).
    pub fn apply(
        &self,
        model: &Model,
        points: &[ContactPoint],
        kin: &Kinematics,
        f_ext: &mut [Vector6<f64>],
    ) {
        for point in points {
            let x = kin.point_position(point.link, &point.offset);
            let force = self.point_force(model, point, &x, || {
                kin.point_velocity(point.link, &point.offset)
            });
            if force != Vector3::zeros() {
                let local = kin.rot[point.link].transpose() * force;
                f_ext[point.link] += spatial(&point.offset.cross(&local), &local);
            }
        }
    }

    /// The force of the surfaces on `point`, at `x` (inertial frame) and
    /// moving at `velocity()` (asked only when touching); zero when it
    /// touches none.
    pub fn point_force(
        &self,
        model: &Model,
        point: &ContactPoint,
        x: &Vector3<f64>,
        velocity: impl Fn() -> Vector3<f64>,
    ) -> Vector3<f64> {
        let max_viscosity = model.links[point.link].mass / (2.0 * self.dt);
        let mut force = Vector3::zeros();
        let reach = self.point_radius;
        if self.floor && x.z < reach {
            force += self.force(reach - x.z, &Vector3::z(), &velocity(), max_viscosity);
        }
        if let Some(radius) = self.arena_radius {
            let r = x.xy().norm();
            if r > radius - reach {
                let inward = Vector3::new(-x.x / r, -x.y / r, 0.0);
                force += self.force(r - (radius - reach), &inward, &velocity(), max_viscosity);
            }
        }
        force
    }

    /// The force of one surface with inward `normal` on a point penetrating it
    /// by `depth` and moving at `v` (inertial frame); friction's viscous
    /// coefficient is at most `max_viscosity`.
    fn force(
        &self,
        depth: f64,
        normal: &Vector3<f64>,
        v: &Vector3<f64>,
        max_viscosity: f64,
    ) -> Vector3<f64> {
        let p = &self.params;
        let v_n = v.dot(normal);
        let n = (p.stiffness.get() * depth - p.damping * v_n).max(0.0);
        let v_t = v - normal * v_n;
        let viscosity = (p.friction * n / v_t.norm().max(p.slip_speed.get())).min(max_viscosity);
        normal * n - v_t * viscosity
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn surfaces() -> Surfaces {
        Surfaces {
            floor: true,
            arena_radius: Some(2.0),
            params: ContactParams::default(),
            dt: 1e-3,
            point_radius: 0.0,
        }
    }

    #[test]
    fn floor_pushes_up_and_friction_opposes_sliding() {
        let s = surfaces();
        let free = f64::INFINITY;
        let f = s.force(0.01, &Vector3::z(), &Vector3::new(1.0, 0.0, 0.0), free);
        assert!((f.z - 500.0).abs() < 1e-9, "k d = 5e4 × 0.01");
        assert!(
            (f.x + 0.6 * 500.0).abs() < 1e-9,
            "Coulomb above the slip speed"
        );
        // Viscous below the slip speed.
        let slow = s.force(0.01, &Vector3::z(), &Vector3::new(0.01, 0.0, 0.0), free);
        assert!((slow.x + 0.6 * 500.0 * 0.01 / 0.05).abs() < 1e-9);
        // ... but never stiffer than the cap.
        let capped = s.force(0.01, &Vector3::z(), &Vector3::new(0.01, 0.0, 0.0), 100.0);
        assert!((capped.x + 100.0 * 0.01).abs() < 1e-12);
        // Separating fast: the damper would pull, the force is clamped to zero.
        let away = s.force(0.001, &Vector3::z(), &Vector3::new(0.0, 0.0, 5.0), free);
        assert_eq!(away, Vector3::zeros());
    }
}
