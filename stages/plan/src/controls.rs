//! What a planner sets: a scene's controls, one number per component and
//! frame. A ball hinge (the worm's, the chain's) takes a torque about each
//! of its three axes, logged as `g.<link>.x|y|z`; a robot's one-DOF joint
//! takes its effort, logged as `tau.<joint>`. The search box of each
//! component is the range its training data saw — the controller's
//! amplitude — within the scene's torque limit and the joint's effort
//! limit, so a plan asks only for what the data covered and the robot can
//! do.

use alnlab_physics::Prepared;
use alnlab_physics::controller::ControllerKind;
use nalgebra::Vector3;

use crate::planner::Bounds;

/// A scene's controls.
#[derive(Clone, Debug, PartialEq)]
pub struct Controls {
    /// Per component: the hinge (link index − 1) and the axis it turns.
    components: Vec<(usize, usize)>,
    /// Per component: the variable that logs it.
    names: Vec<String>,
    bounds: Bounds,
}

impl Controls {
    /// The controls of scene `p`; an error when it has none to plan (no
    /// controller, so no range of torques its data saw).
    pub fn of(p: &Prepared) -> Result<Controls, String> {
        let controller = p.scene.controller();
        if controller.kind == ControllerKind::None {
            return Err(format!(
                "scene `{}` has no controller, so no torques to plan (give it one, e.g. \
                 controller = {{ kind = \"random\" }})",
                p.scene.name
            ));
        }
        let (components, names): (Vec<(usize, usize)>, Vec<String>) = p
            .controls()
            .into_iter()
            .map(|c| ((c.hinge, c.axis), c.name))
            .unzip();
        let limit = controller.torque_limit.get();
        let a = &controller.amplitude;
        let (low, high) = components
            .iter()
            .map(|&(hinge, axis)| {
                let amplitude = a[if a.len() == 1 { 0 } else { hinge }].component(axis);
                let high = amplitude.abs().min(limit);
                match &p.laws[hinge + 1] {
                    Some(law) => (law.clamp(-high), law.clamp(high)),
                    None => (-high, high),
                }
            })
            .unzip();
        Ok(Controls {
            components,
            names,
            bounds: Bounds { low, high },
        })
    }

    /// Components per frame.
    pub fn dims(&self) -> usize {
        self.components.len()
    }

    /// The link each component drives (a ball hinge's three share it).
    pub fn links(&self) -> impl Iterator<Item = usize> + '_ {
        self.components.iter().map(|&(hinge, _)| hinge + 1)
    }

    /// The variable that logs each component.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The box a planner searches.
    pub fn bounds(&self) -> &Bounds {
        &self.bounds
    }

    /// Sets `action` (one value per component) as the hinges' torques,
    /// every other axis zero.
    pub fn set(&self, action: &[f64], torques: &mut [Vector3<f64>]) {
        torques.fill(Vector3::zeros());
        for (&(hinge, axis), &value) in self.components.iter().zip(action) {
            torques[hinge][axis] = value;
        }
    }

    /// The components of the hinges' `torques` (as a runner executed them).
    pub fn read(&self, torques: &[Vector3<f64>], action: &mut [f64]) {
        for (&(hinge, axis), value) in self.components.iter().zip(action) {
            *value = torques[hinge][axis];
        }
    }
}

#[cfg(test)]
mod tests {
    use alnlab_physics::Scene;
    use alnlab_physics::controller::{Amplitude, ControllerParams};

    use super::*;

    #[test]
    fn a_worms_controls_are_its_hinges_torques_within_the_controllers_amplitude() {
        let p = Prepared::new(
            &Scene {
                controller: Some(ControllerParams {
                    kind: ControllerKind::Random,
                    amplitude: vec![Amplitude::Ball([1.0, 10.0, 10.0])],
                    ..ControllerParams::default()
                }),
                ..Scene::default()
            }
            .resolve(),
        );
        let controls = Controls::of(&p).unwrap();
        assert_eq!(controls.dims(), 6);
        assert_eq!(
            controls.names(),
            ["g.2.x", "g.2.y", "g.2.z", "g.3.x", "g.3.y", "g.3.z"]
        );
        assert_eq!(controls.bounds().high, [1.0, 10.0, 10.0, 1.0, 10.0, 10.0]);
        let mut torques = vec![Vector3::zeros(); 2];
        let action = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        controls.set(&action, &mut torques);
        assert_eq!(torques[1], Vector3::new(4.0, 5.0, 6.0));
        let mut back = [0.0; 6];
        controls.read(&torques, &mut back);
        assert_eq!(back, action);
    }
}
