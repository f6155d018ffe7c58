//! The paper's variables (§4.1), all in the link's own frame, and which of
//! them a scene has ("model only what a scene needs"): a pinned root's hinge
//! never moves (no v, a for it), a scene without contacts has no f_E or g_E,
//! g_E exists only for links touched away from their hinge (the chain's free
//! end), g only with a controller, roll and pitch only at hinges.
//!
//! Names are stable identifiers: `<quantity>.<link>[.<axis>]`, links counted
//! from 1 (the root), e.g. `a.1.z`, `omega_dot.3.x`, `g.2.y`, `roll.2`.
//!
//! A robot (a `urdf` scene) has, per joint, its position, velocity,
//! acceleration and (with a controller) the effort driving it, named after
//! the URDF's joint (`q.shoulder_pan_joint`, `qd.…`, `qdd.…`, `tau.…`); a
//! free base's v, a, ω and ω̇; v and ω of the links the scene names; and the
//! contact forces on the bodies that touch — links named after the URDF
//! (`v.wrist_3_link.x`, `f_E.FL_LOWER_LEG.z`).

use nalgebra::{Matrix3, Quaternion, SimdValue, UnitQuaternion, Vector3};

use crate::batch::{AccelLanes, KinematicsLanes, LANES, Lanes, StateLanes};
use crate::contact::ContactPoint;
use crate::dynamics::State;
use crate::integrate::Evaluation;
use crate::model::{Model, Root};
use crate::spatial::{angular, linear};

/// One quantity of one link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// Hinge velocity (m/s).
    V,
    /// Hinge acceleration (m/s²).
    A,
    /// Angular velocity (rad/s).
    Omega,
    /// Rate of change of ω's link-frame components (rad/s²).
    OmegaDot,
    /// Control torque the link exerts on its parent (N m).
    G,
    /// External force at the hinge (N).
    FE,
    /// External torque about the hinge (N m).
    GE,
    /// Roll of the hinge (rad).
    Roll,
    /// Pitch of the hinge (rad).
    Pitch,
    /// A one-DOF joint's position (rad or m).
    JointPosition,
    /// A one-DOF joint's velocity (rad/s or m/s).
    JointVelocity,
    /// A one-DOF joint's acceleration (rad/s² or m/s²).
    JointAcceleration,
    /// The control effort on a one-DOF joint, parent on child (N m or N).
    JointEffort,
}

impl Quantity {
    /// The name prefix, which is also the variable group (docs/design.md §3).
    pub fn name(self) -> &'static str {
        match self {
            Quantity::V => "v",
            Quantity::A => "a",
            Quantity::Omega => "omega",
            Quantity::OmegaDot => "omega_dot",
            Quantity::G => "g",
            Quantity::FE => "f_E",
            Quantity::GE => "g_E",
            Quantity::Roll => "roll",
            Quantity::Pitch => "pitch",
            Quantity::JointPosition => "q",
            Quantity::JointVelocity => "qd",
            Quantity::JointAcceleration => "qdd",
            Quantity::JointEffort => "tau",
        }
    }

    /// How many variables it stands for: a vector's three, one otherwise.
    fn width(self) -> usize {
        match self {
            Quantity::Roll | Quantity::Pitch => 1,
            _ if self.is_joint() => 1,
            _ => 3,
        }
    }

    /// Whether it is one number per joint (rather than a link's vector or
    /// angle).
    fn is_joint(self) -> bool {
        matches!(
            self,
            Quantity::JointPosition
                | Quantity::JointVelocity
                | Quantity::JointAcceleration
                | Quantity::JointEffort
        )
    }
}

/// Which variables a scene logs, in log order.
#[derive(Clone, Debug, PartialEq)]
pub struct VariableSet {
    /// (quantity, link index) pairs; vectors stand for three variables.
    pub entries: Vec<(Quantity, usize)>,
    /// Per link, what its variables' names call it (link quantities) and
    /// its joint (joint quantities): `1`, `2`, … for the paper's scenes,
    /// the URDF's names for a robot.
    link_labels: Vec<String>,
    joint_labels: Vec<String>,
}

/// Labels `1`, `2`, … for `n` links.
fn numbered(n: usize) -> Vec<String> {
    (1..=n).map(|i| i.to_string()).collect()
}

impl VariableSet {
    /// The variables of `model` with these contact points and control.
    pub fn of(model: &Model, contacts: Option<&[ContactPoint]>, controlled: bool) -> VariableSet {
        let n = model.len();
        let links = 0..n;
        let moving_hinge = |i: &usize| !(*i == 0 && model.root == Root::Pinned);
        let hinges = || (0..n).filter(|i| model.links[*i].parent.is_some());
        let mut entries = Vec::new();
        entries.extend(links.clone().filter(moving_hinge).map(|i| (Quantity::V, i)));
        entries.extend(links.clone().filter(moving_hinge).map(|i| (Quantity::A, i)));
        entries.extend(links.clone().map(|i| (Quantity::Omega, i)));
        entries.extend(links.clone().map(|i| (Quantity::OmegaDot, i)));
        if controlled {
            entries.extend(hinges().map(|i| (Quantity::G, i)));
        }
        if let Some(points) = contacts {
            let touched = |i: usize, off_hinge: bool| {
                points
                    .iter()
                    .any(|p| p.link == i && (!off_hinge || p.offset != Vector3::zeros()))
            };
            entries.extend(
                links
                    .clone()
                    .filter(|&i| touched(i, false))
                    .map(|i| (Quantity::FE, i)),
            );
            entries.extend(
                links
                    .clone()
                    .filter(|&i| touched(i, true))
                    .map(|i| (Quantity::GE, i)),
            );
        }
        entries.extend(hinges().map(|i| (Quantity::Roll, i)));
        entries.extend(hinges().map(|i| (Quantity::Pitch, i)));
        VariableSet {
            entries,
            link_labels: numbered(n),
            joint_labels: numbered(n),
        }
    }

    /// A robot's variables: its free base's v, a, ω, ω̇; v and ω of
    /// `link_velocities` (link indices); per joint q, q̇, q̈ and, if
    /// `controlled`, its effort; f_E (and g_E away from the origin) of the
    /// bodies the contact points touch. Named by `links` and `joints`
    /// (per link: its URDF link and joint names).
    pub fn of_robot(
        model: &Model,
        links: &[String],
        joints: &[String],
        link_velocities: &[usize],
        contacts: &[ContactPoint],
        controlled: bool,
    ) -> VariableSet {
        let n = model.len();
        let mut entries = Vec::new();
        if model.root == Root::Free {
            for q in [
                Quantity::V,
                Quantity::A,
                Quantity::Omega,
                Quantity::OmegaDot,
            ] {
                entries.push((q, 0));
            }
        }
        for &q in &[Quantity::V, Quantity::Omega] {
            entries.extend(link_velocities.iter().map(|&i| (q, i)));
        }
        let mut quantities = vec![
            Quantity::JointPosition,
            Quantity::JointVelocity,
            Quantity::JointAcceleration,
        ];
        if controlled {
            quantities.push(Quantity::JointEffort);
        }
        for q in quantities {
            // A follower of a coupling has no effort of its own.
            let driven = |i: &usize| q != Quantity::JointEffort || model.coupling(*i).is_none();
            entries.extend((1..n).filter(driven).map(|i| (q, i)));
        }
        let touched = |i: usize, off_origin: bool| {
            contacts
                .iter()
                .any(|p| p.link == i && (!off_origin || p.offset != Vector3::zeros()))
        };
        entries.extend(
            (0..n)
                .filter(|&i| touched(i, false))
                .map(|i| (Quantity::FE, i)),
        );
        entries.extend(
            (0..n)
                .filter(|&i| touched(i, true))
                .map(|i| (Quantity::GE, i)),
        );
        VariableSet {
            entries,
            link_labels: links.to_vec(),
            joint_labels: joints.to_vec(),
        }
    }

    /// Variable `index` (in log order), if a batch of states can give it
    /// ([`LaneVariable`]): not a link's acceleration or external force.
    pub fn lane_variable(&self, index: usize) -> Option<LaneVariable> {
        let mut at = 0;
        for &(quantity, link) in &self.entries {
            let width = quantity.width();
            if index < at + width {
                let batched = !matches!(
                    quantity,
                    Quantity::A | Quantity::OmegaDot | Quantity::FE | Quantity::GE
                );
                return batched.then_some(LaneVariable {
                    quantity,
                    link,
                    component: index - at,
                });
            }
            at += width;
        }
        None
    }

    /// The variable names, in order.
    pub fn names(&self) -> Vec<String> {
        let mut names = Vec::new();
        for &(q, i) in &self.entries {
            let label = match q.is_joint() {
                true => &self.joint_labels[i],
                false => &self.link_labels[i],
            };
            let base = format!("{}.{label}", q.name());
            match q.width() {
                1 => names.push(base),
                _ => names.extend(["x", "y", "z"].map(|axis| format!("{base}.{axis}"))),
            }
        }
        names
    }

    /// Fills `out` (one value per name) from an evaluation of `state`
    /// (kinematics, accelerations, external forces) and the control torques
    /// g per link (zero for the root; a one-DOF joint's effort is its x).
    pub fn values(&self, state: &State, eval: &Evaluation, g: &[Vector3<f64>], out: &mut Vec<f64>) {
        let (kin, accel, f_ext) = (&eval.kin, &eval.ws.accel, &eval.loads.f_ext);
        out.clear();
        for &(q, i) in &self.entries {
            let v = kin.vel[i];
            let vector = match q {
                Quantity::V => linear(&v),
                Quantity::A => linear(&accel[i]) + angular(&v).cross(&linear(&v)),
                Quantity::Omega => angular(&v),
                Quantity::OmegaDot => angular(&accel[i]),
                Quantity::G => g[i],
                Quantity::FE => linear(&f_ext[i]),
                Quantity::GE => angular(&f_ext[i]),
                Quantity::JointPosition => {
                    out.push(state.q[i]);
                    continue;
                }
                Quantity::JointVelocity => {
                    out.push(state.qd[i]);
                    continue;
                }
                Quantity::JointAcceleration => {
                    out.push(eval.deriv.qd[i]);
                    continue;
                }
                Quantity::JointEffort => {
                    out.push(g[i].x);
                    continue;
                }
                Quantity::Roll | Quantity::Pitch => {
                    let (roll, pitch) = roll_pitch(&state.orient[i]);
                    out.push(if q == Quantity::Roll { roll } else { pitch });
                    continue;
                }
            };
            out.extend(vector.iter());
        }
    }
}

/// A variable read from a batch's states ([`VariableSet::lane_variable`]):
/// a position, angle or velocity, a joint's acceleration, or a control
/// torque.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LaneVariable {
    quantity: Quantity,
    link: usize,
    /// The axis of a vector quantity (0 otherwise).
    component: usize,
}

impl LaneVariable {
    /// Whether reading it takes the states' accelerations.
    pub fn needs_accelerations(&self) -> bool {
        self.quantity == Quantity::JointAcceleration
    }

    /// Its value in each of a batch group's states, whose kinematics are
    /// `kin`, accelerations `accel` (needed only where
    /// [`LaneVariable::needs_accelerations`]) and control torques `g` (per
    /// link) — what [`VariableSet::values`] gives each one.
    pub fn lanes(
        &self,
        state: &StateLanes,
        kin: &KinematicsLanes,
        accel: Option<&AccelLanes>,
        g: &[Vector3<Lanes>],
    ) -> Lanes {
        let i = self.link;
        match self.quantity {
            Quantity::V => linear(&kin.vel[i])[self.component],
            Quantity::Omega => angular(&kin.vel[i])[self.component],
            Quantity::G => g[i][self.component],
            Quantity::JointPosition => state.q[i],
            Quantity::JointVelocity => state.qd[i],
            Quantity::JointAcceleration => accel.expect("accelerations evaluated").qdd[i],
            Quantity::JointEffort => g[i].x,
            Quantity::Roll | Quantity::Pitch => {
                let q = &state.orient[i];
                Lanes::from(std::array::from_fn::<f64, LANES, _>(|j| {
                    let lane = Quaternion::new(
                        q.w.extract(j),
                        q.i.extract(j),
                        q.j.extract(j),
                        q.k.extract(j),
                    );
                    let (roll, pitch) = roll_pitch(&UnitQuaternion::new_unchecked(lane));
                    if self.quantity == Quantity::Roll {
                        roll
                    } else {
                        pitch
                    }
                }))
            }
            Quantity::A | Quantity::OmegaDot | Quantity::FE | Quantity::GE => {
                unreachable!("not made a LaneVariable")
            }
        }
    }
}

/// Roll and pitch of a hinge's rotation (child → parent), as the x and y
/// angles of the intrinsic z-y-x (yaw, pitch, roll) decomposition
/// R = Rz(yaw)·Ry(pitch)·Rx(roll). Pitch is in [−π/2, π/2]. At pitch = ±π/2
/// (gimbal lock) roll is not determined; it is then defined as 0 (the whole
/// rotation about the vertical axis is taken as yaw).
pub fn roll_pitch(q: &UnitQuaternion<f64>) -> (f64, f64) {
    let r: Matrix3<f64> = q.to_rotation_matrix().into_inner();
    let sin_pitch = (-r[(2, 0)]).clamp(-1.0, 1.0);
    let pitch = sin_pitch.asin();
    let roll = if sin_pitch.abs() > 1.0 - 1e-12 {
        0.0
    } else {
        r[(2, 1)].atan2(r[(2, 2)])
    };
    (roll, pitch)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roll_pitch_recovers_the_angles() {
        let q = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.2); // roll, pitch, yaw
        let (roll, pitch) = roll_pitch(&q);
        assert!((roll - 0.3).abs() < 1e-12 && (pitch + 0.7).abs() < 1e-12);
    }

    /// Hard case 3: through pitch = ±90° nothing is NaN and roll is defined.
    #[test]
    fn pitch_through_ninety_degrees_is_well_defined() {
        for k in -2000..=2000 {
            let pitch = k as f64 * std::f64::consts::FRAC_PI_2 / 1000.0;
            let q = UnitQuaternion::from_euler_angles(0.4, pitch, -0.2);
            let (roll, p) = roll_pitch(&q);
            assert!(roll.is_finite() && p.is_finite(), "pitch {pitch}");
            assert!(p.abs() <= std::f64::consts::FRAC_PI_2 + 1e-12);
        }
        let lock = UnitQuaternion::from_euler_angles(0.4, std::f64::consts::FRAC_PI_2, -0.2);
        let (roll, pitch) = roll_pitch(&lock);
        assert_eq!(roll, 0.0);
        assert!((pitch - std::f64::consts::FRAC_PI_2).abs() < 1e-7);
    }
}
