//! The paper's variables (§4.1), all in the link's own frame, and which of
//! them a scene has ("model only what a scene needs"): a pinned root's hinge
//! never moves (no v, a for it), a scene without contacts has no f_E or g_E,
//! g_E exists only for links touched away from their hinge (the chain's free
//! end), g only with a controller, roll and pitch only at hinges.
//!
//! Names are stable identifiers: `<quantity>.<link>[.<axis>]`, links counted
//! from 1 (the root), e.g. `a.1.z`, `omega_dot.3.x`, `g.2.y`, `roll.2`.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::contact::ContactPoint;
use crate::dynamics::{Kinematics, State};
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
}

impl Quantity {
    /// The name prefix, which is also the variable group (DESIGN.md §6).
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
        }
    }
}

/// Which variables a scene logs, in log order.
#[derive(Clone, Debug, PartialEq)]
pub struct VariableSet {
    /// (quantity, link index) pairs; vectors stand for three variables.
    pub entries: Vec<(Quantity, usize)>,
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
        VariableSet { entries }
    }

    /// The variable names, in order.
    pub fn names(&self) -> Vec<String> {
        let mut names = Vec::new();
        for &(q, i) in &self.entries {
            let base = format!("{}.{}", q.name(), i + 1);
            match q {
                Quantity::Roll | Quantity::Pitch => names.push(base),
                _ => names.extend(["x", "y", "z"].map(|axis| format!("{base}.{axis}"))),
            }
        }
        names
    }

    /// Fills `out` (one value per name) from an evaluated state: kinematics,
    /// accelerations (link frame), control torques g per link (zero for the
    /// root) and external forces (link frame, at the hinge).
    pub fn values(
        &self,
        state: &State,
        kin: &Kinematics,
        accel: &[nalgebra::Vector6<f64>],
        g: &[Vector3<f64>],
        f_ext: &[nalgebra::Vector6<f64>],
        out: &mut Vec<f64>,
    ) {
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
