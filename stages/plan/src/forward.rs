//! Forward models a planner searches with. Each starts its predictions from
//! the state the true simulator is in at a decision ([`Model::start`]) and
//! predicts, for candidate torque sequences, the task's cost summed over
//! the frames ([`crate::planner::Forward`]).
//!
//! - [`Simulator`]: the simulator itself at k integration steps per frame
//!   (k = the scene's own steps per frame is the true model; smaller k is
//!   cheaper and wronger). A candidate that blows up costs +∞.

use alnlab_common::state_log::StateFrame;
use alnlab_physics::dynamics::State;
use alnlab_physics::{Prepared, Runner};
use nalgebra::Vector3;

use crate::planner::Forward;
use crate::task::Cost;

/// A forward model: a planner's [`Forward`] that can be started from the
/// true state.
pub trait Model: Forward {
    /// Starts the next predictions from `state` (whose variables, in the
    /// scene's layout order, are `variables`).
    fn start(&mut self, state: &State, variables: &[f64]);
}

/// The simulator at `steps` integration steps per frame.
pub struct Simulator<'a> {
    p: &'a Prepared,
    runner: Runner<'a>,
    steps: u64,
    cost: Cost,
    start: State,
    state: State,
    torques: Vec<Vector3<f64>>,
    frame: StateFrame,
}

impl<'a> Simulator<'a> {
    /// The simulator of scene `p` at `steps` steps per frame, costing with
    /// `cost` (over the scene's variables).
    pub fn new(p: &'a Prepared, steps: u64, cost: Cost) -> Simulator<'a> {
        let hinges = p.model.len() - 1;
        let rest = State::rest(&p.model, Vector3::zeros());
        Simulator {
            runner: Runner::new(p, 0, 0, 0),
            steps: steps.max(1),
            cost,
            start: rest.clone(),
            state: rest,
            torques: vec![Vector3::zeros(); hinges],
            frame: StateFrame {
                time: 0.0,
                run: 0,
                frame: 0,
                state: Vec::with_capacity(p.layout.state.len()),
                variables: Vec::with_capacity(p.layout.variables.len()),
            },
            p,
        }
    }
}

impl Model for Simulator<'_> {
    fn start(&mut self, state: &State, _variables: &[f64]) {
        copy_state(&mut self.start, state);
    }
}

impl Forward for Simulator<'_> {
    fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) {
        let d = 3 * self.torques.len();
        let dt = self.p.scene.frame_dt.get() / self.steps as f64;
        for (sequence, cost) in actions.chunks(horizon * d).zip(costs.iter_mut()) {
            copy_state(&mut self.state, &self.start);
            self.runner.restart();
            *cost = 0.0;
            for frame in sequence.chunks(d) {
                for (g, t) in self.torques.iter_mut().zip(frame.chunks(3)) {
                    *g = Vector3::new(t[0], t[1], t[2]);
                }
                self.runner.drive(Some(&self.torques));
                if self
                    .runner
                    .advance(&mut self.state, 0, self.steps, dt)
                    .is_err()
                {
                    *cost = f64::INFINITY;
                    break;
                }
                self.runner.observe(&self.state, 0.0, &mut self.frame);
                *cost += self.cost.of(&self.frame.variables);
            }
        }
    }
}

/// `*to = from.clone()` without allocating (a derived `clone_from` would).
pub(crate) fn copy_state(to: &mut State, from: &State) {
    to.root_p = from.root_p;
    to.root_v = from.root_v;
    to.orient.clone_from(&from.orient);
    to.rates.clone_from(&from.rates);
}
