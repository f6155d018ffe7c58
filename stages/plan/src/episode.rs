//! One episode of model-predictive control in the true simulator: from a
//! start state, every frame a policy chooses the controls ([`Controls`]),
//! the scene's own simulator — its plant, where it has one — executes them
//! for one frame at its own step, and the task's cost of the frame reached
//! is added up.
//!
//! Policies: zero torques, the scene's random controller and PD or PID
//! loops on the nominal model's gravity compensation (references), or a
//! planner with a forward model and a budget (sequences per decision).

use std::time::Instant;

use alnlab_common::state_log::StateFrame;
use alnlab_common::{Error, Result};
use alnlab_physics::dynamics::{Kinematics, State};
use alnlab_physics::{Prepared, Runner};
use nalgebra::Vector3;

use crate::controls::Controls;
use crate::feedback::Feedback;
use crate::forward::Model;
use crate::planner::Planner;
use crate::task::Cost;

/// What chooses the torques.
pub enum Policy<'m> {
    /// No torques.
    Zero,
    /// The scene's random controller: torques uniform in ±amplitude, held
    /// for `hold` seconds, seeded by the episode.
    Random,
    /// A PD or PID loop on the nominal model's gravity compensation.
    Feedback(Feedback<'m>),
    /// A planner searching `sequences` sequences per decision with `model`.
    Plan {
        planner: &'m mut Planner,
        model: &'m mut dyn Model,
        sequences: usize,
    },
}

/// One executed frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The frame reached (1 = one frame after the start).
    pub frame: u32,
    /// The controls executed on the way to it (as clamped; in the order of
    /// [`Controls::names`]).
    pub torques: Vec<f64>,
    /// The task's cost of the frame reached …
    pub cost: f64,
    /// … and its error in the task's unit ([`Cost::error`]).
    pub error: f64,
    /// The planner's predicted cost of the sequence it chose (summed over
    /// its horizon; NaN for the references).
    pub predicted: f64,
    /// The spread of the candidates' predicted costs at the decision (NaN
    /// for the references): 0 when the model cannot tell torques apart.
    pub spread: f64,
    /// Seconds the decision took (0 for the references).
    pub seconds: f64,
    /// The task's variables (in the order of [`Cost::variables`]) in the
    /// frame reached …
    pub reached: Vec<f64>,
    /// … and as the planner's model predicted them for the torques chosen
    /// (NaN for the references).
    pub expected: Vec<f64>,
}

/// What an episode came to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outcome {
    /// The task's cost summed over the frames.
    pub cost: f64,
    /// A planner's model fed its own predictions over `horizon` frames of
    /// the torques executed, from every frame the episode reached that has
    /// `horizon` more: the RMS over those windows of
    /// [`Cost::distance`] between its prediction and the frame reached —
    /// how wrong it is over the horizon it plans on, on the states its
    /// planner visited. +∞ if a prediction blew up; NaN for the references
    /// and episodes shorter than the horizon.
    pub horizon_rms: f64,
    /// How near the task it held, in the task's unit.
    pub settling: Settling,
}

/// What an episode came to against its task's tolerance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settling {
    /// The steady-state error: the mean of the frames' errors
    /// ([`Cost::error`]) over the episode's last quarter (at least its last
    /// frame), in the task's unit.
    pub final_error: f64,
    /// When the error came within the task's tolerance for good: the time
    /// (s) of the first frame reached from which every frame is within it
    /// (the first frame reached is at one frame's time; the start state is
    /// not counted); +∞ if the last frame is not.
    pub settle_s: f64,
    /// The fraction of the frames within the tolerance.
    pub within: f64,
}

impl Settling {
    /// Of an episode whose frames, `frame_dt` (s) apart, had `errors` (at
    /// least one), against `tolerance`.
    fn of(errors: &[f64], tolerance: f64, frame_dt: f64) -> Settling {
        let n = errors.len();
        let last = (n / 4).max(1);
        let final_error = errors[n - last..].iter().sum::<f64>() / last as f64;
        let inside = |e: f64| e <= tolerance;
        let settled = errors.iter().rposition(|&e| !inside(e));
        let settle_s = match settled {
            None => frame_dt,
            Some(k) if k + 1 < n => (k + 2) as f64 * frame_dt,
            Some(_) => f64::INFINITY,
        };
        let within = errors.iter().filter(|&&e| inside(e)).count() as f64 / n as f64;
        Settling {
            final_error,
            settle_s,
            within,
        }
    }
}

/// Runs `frames` frames of scene `p` (with its plant, if any) from `start`
/// under `controls`; hands each [`Step`], the frame reached (as seen before
/// the next torques are chosen), the frame it started from as the log
/// records frames (under the torques applied from it on: its accelerations
/// and efforts those torques'), and the reached frame's link poses to
/// `on_step`; returns the summed cost and, for a planner, its model's error
/// over `horizon` frames. `seed` seeds the random reference's torques (and a
/// plant's actuator noise).
#[allow(clippy::too_many_arguments)]
pub fn run(
    p: &Prepared,
    controls: &Controls,
    start: &State,
    frames: u32,
    horizon: usize,
    cost: &Cost,
    policy: &mut Policy,
    seed: u64,
    mut on_step: impl FnMut(&Step, &StateFrame, &StateFrame, &Kinematics) -> Result<()>,
) -> Result<Outcome> {
    let hinges = p.model.len() - 1;
    let mut runner = Runner::new(p, seed, 0, 0);
    let mut state = start.clone();
    let mut frame = StateFrame {
        time: 0.0,
        run: 0,
        frame: 0,
        state: Vec::with_capacity(p.layout.state.len()),
        variables: Vec::with_capacity(p.layout.variables.len()),
    };
    // Seen before the first torques are chosen; `applied`, as logged once
    // they are.
    runner.preview(&state, 0.0, &mut frame);
    let mut applied = frame.clone();
    let steps = p.scene.steps_per_frame();
    let dt = p.scene.dt.get();
    let mut action = vec![0.0; controls.dims()];
    let mut torques = vec![Vector3::zeros(); hinges];
    let mut total = 0.0;
    let mut step = Step {
        frame: 0,
        torques: vec![0.0; controls.dims()],
        cost: 0.0,
        error: 0.0,
        predicted: f64::NAN,
        spread: f64::NAN,
        seconds: 0.0,
        reached: vec![0.0; cost.variables().count()],
        expected: vec![f64::NAN; cost.variables().count()],
    };
    // Every state reached and the torques chosen after it, for the
    // planner's model to be replayed on once the episode is done.
    let planned = matches!(policy, Policy::Plan { .. });
    let mut visited: Vec<(State, Vec<f64>)> = Vec::new();
    let mut chosen: Vec<f64> = Vec::new();
    let mut errors = Vec::with_capacity(frames as usize);
    if let Policy::Feedback(pd) = policy {
        pd.begin(start);
    }
    if planned {
        visited.push((state.clone(), frame.variables.clone()));
    }
    for f in 0..frames {
        match policy {
            Policy::Zero => {
                action.fill(0.0);
                controls.set(&action, &mut torques);
                runner.drive(Some(&torques));
            }
            Policy::Random => runner.drive(None),
            Policy::Feedback(pd) => {
                pd.act(&state, &mut action);
                controls.set(&action, &mut torques);
                runner.drive(Some(&torques));
            }
            Policy::Plan {
                planner,
                model,
                sequences,
            } => {
                let clock = Instant::now();
                model.start(&state, &frame.variables);
                step.predicted = planner.decide(&mut **model, *sequences, &mut action);
                step.spread = planner.cost_spread();
                step.seconds = clock.elapsed().as_secs_f64();
                model.predict(&action, 1, &mut step.expected);
                chosen.extend_from_slice(&action);
                controls.set(&action, &mut torques);
                runner.drive(Some(&torques));
            }
        }
        let first = u64::from(f) * steps;
        runner.observe(&state, first as f64 * dt, &mut applied);
        runner.advance(&mut state, first, steps, dt).map_err(|at| {
            Error::Diverged(format!(
                "scene `{}`: the episode blew up at step {at} (frame {f})",
                p.scene.name
            ))
        })?;
        // What was executed: the planner's torques as clamped, or the
        // controller's.
        controls.read(runner.hinge_torques(), &mut step.torques);
        let t = (first + steps) as f64 * dt;
        runner.preview(&state, t, &mut frame);
        step.frame = f + 1;
        step.cost = cost.of(&frame.variables);
        step.error = cost.error(&frame.variables);
        errors.push(step.error);
        for (r, s) in step.reached.iter_mut().zip(cost.variables()) {
            *r = frame.variables[s];
        }
        total += step.cost;
        if planned {
            visited.push((state.clone(), frame.variables.clone()));
        }
        on_step(&step, &frame, &applied, runner.kinematics())?;
    }
    let horizon_rms = match policy {
        Policy::Plan { model, .. } if horizon > 0 && visited.len() > horizon => {
            horizon_error(&mut **model, &visited, &chosen, horizon, cost)
        }
        _ => f64::NAN,
    };
    if errors.is_empty() {
        return Err(Error::Invalid("an episode of no frames".into()));
    }
    Ok(Outcome {
        cost: total,
        horizon_rms,
        settling: Settling::of(&errors, cost.tolerance(), p.scene.frame_dt.get()),
    })
}

/// The RMS over every window of `horizon` frames of the distance between
/// `model`'s prediction of the window's end, from its start under the
/// torques `chosen`, and the frame `visited` there; +∞ if one blew up.
fn horizon_error(
    model: &mut dyn Model,
    visited: &[(State, Vec<f64>)],
    chosen: &[f64],
    horizon: usize,
    cost: &Cost,
) -> f64 {
    let d = chosen.len() / (visited.len() - 1).max(1);
    let (mut predicted, mut reached) = (vec![0.0; cost.variables().count()], Vec::new());
    let mut squares = 0.0;
    let windows = visited.len() - horizon;
    for t in 0..windows {
        let (state, variables) = &visited[t];
        model.start(state, variables);
        model.predict(&chosen[t * d..(t + horizon) * d], horizon, &mut predicted);
        reached.clear();
        reached.extend(cost.variables().map(|s| visited[t + horizon].1[s]));
        let distance = cost.distance(&predicted, &reached);
        if !distance.is_finite() {
            return f64::INFINITY;
        }
        squares += distance * distance;
    }
    (squares / windows as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use alnlab_physics::Scene;
    use alnlab_physics::controller::{ControllerKind, ControllerParams};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::forward::Simulator;
    use crate::planner::{CemSettings, PlannerKind};
    use crate::task::{HoldStart, Task};

    /// The steady-state error is the last quarter's mean error; an
    /// episode settles at the first frame from which it stays within
    /// tolerance, never if its last frame is out.
    #[test]
    fn an_episodes_outcomes_are_read_from_its_frames_errors() {
        let errors = [0.9, 0.5, 0.04, 0.2, 0.03, 0.01, 0.02, 0.01];
        let o = Settling::of(&errors, 0.05, 0.01);
        assert!((o.final_error - 0.015).abs() < 1e-15, "{o:?}");
        // Frame 5 (the fifth frame reached, at 0.05 s) is the first of the
        // run within tolerance to the end.
        assert!((o.settle_s - 0.05).abs() < 1e-15, "{o:?}");
        assert_eq!(o.within, 5.0 / 8.0);
        let never = Settling::of(&[0.01, 0.01, 0.3], 0.05, 0.01);
        assert_eq!(never.settle_s, f64::INFINITY);
        let always = Settling::of(&[0.01], 0.05, 0.01);
        assert_eq!(
            (always.settle_s, always.within, always.final_error),
            (0.01, 1.0, 0.01)
        );
        // A NaN error is not within tolerance.
        let lost = Settling::of(&[0.01, f64::NAN], 0.05, 0.01);
        assert_eq!((lost.settle_s, lost.within), (f64::INFINITY, 0.5));
    }

    /// Every step's prediction is the frame then reached, to 1e-9.
    fn predicted_as_reached(steps: &[Step]) {
        for s in steps {
            for (e, r) in s.expected.iter().zip(&s.reached) {
                assert!(
                    (e - r).abs() <= 1e-9 * r.abs().max(1.0),
                    "frame {}: {e} {r}",
                    s.frame
                );
            }
        }
    }

    fn worm() -> Prepared {
        worm_with(None)
    }

    /// The worm, as the plant `plant` where one is given.
    fn worm_with(plant: Option<alnlab_physics::plant::Plant>) -> Prepared {
        Prepared::new(&Scene {
            plant,
            controller: Some(ControllerParams {
                kind: ControllerKind::Random,
                amplitude: vec![alnlab_physics::controller::Amplitude::Ball([
                    1.0, 10.0, 10.0,
                ])],
                ..ControllerParams::default()
            }),
            ..Scene::default()
        })
    }

    #[test]
    fn planning_with_the_simulator_beats_zero_and_random_torques() {
        let p = worm();
        let task = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "bend".into(),
            targets: BTreeMap::from([("pitch.2".into(), 0.6), ("pitch.3".into(), -0.6)]),
        };
        let cost = task.over(&p.layout.variables, &p).unwrap();
        let controls = Controls::of(&p).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let start = p.scene.initial_state(&p.model, &mut rng);
        let frames = 60;
        let episode = |policy: &mut Policy| {
            let mut steps = Vec::new();
            let total = run(
                &p,
                &controls,
                &start,
                frames,
                10,
                &cost,
                policy,
                9,
                |s, _, _, _| {
                    steps.push(s.clone());
                    Ok(())
                },
            )
            .unwrap();
            (total, steps)
        };
        let (zero, _) = episode(&mut Policy::Zero);
        let (random, random_steps) = episode(&mut Policy::Random);
        assert!(zero.horizon_rms.is_nan() && random.horizon_rms.is_nan());
        let (zero, random) = (zero.cost, random.cost);
        let bounds = controls.bounds().clone();
        assert_eq!(bounds.high, [1.0, 10.0, 10.0, 1.0, 10.0, 10.0]);
        let cem = CemSettings {
            iterations: 3,
            elite: 0.1,
        };
        let mut planner = Planner::new(PlannerKind::Cem, cem, 10, bounds, 60, 1);
        let mut model = Simulator::new(&p, &controls, p.scene.steps_per_frame(), cost.clone());
        let (outcome, steps) = episode(&mut Policy::Plan {
            planner: &mut planner,
            model: &mut model,
            sequences: 60,
        });
        // The true model, fed its own predictions over the horizon, lands
        // where the simulator did.
        assert!(outcome.horizon_rms < 1e-9, "{}", outcome.horizon_rms);
        let planned = outcome.cost;
        assert!(
            planned < 0.5 * zero.min(random),
            "planned {planned}, zero {zero}, random {random}"
        );
        assert_eq!(steps.len(), frames as usize);
        assert!(
            steps
                .iter()
                .all(|s| s.seconds > 0.0 && s.predicted.is_finite())
        );
        // The true model predicts the frame the simulator then reaches.
        predicted_as_reached(&steps);
        assert!(
            random_steps
                .iter()
                .all(|s| s.expected.iter().all(|e| e.is_nan()))
        );
        assert!(
            random_steps
                .iter()
                .any(|s| s.torques.iter().any(|&g| g != 0.0))
        );
        assert!(random_steps.iter().all(|s| s.torques[0].abs() <= 1.0));
    }

    /// A plant's actuators take each decision's torques from the frame's
    /// first step: its own simulator, which starts them afresh, then
    /// predicts every frame it reaches, and every frame the episode hands on
    /// as the log records it carries the torques applied from it.
    #[test]
    fn a_plants_actuators_execute_each_decision_from_its_first_step() {
        let p = worm_with(Some(alnlab_physics::plant::Plant {
            actuator_gain: 0.5,
            ..Default::default()
        }));
        let task = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "bend".into(),
            targets: BTreeMap::from([("pitch.2".into(), 0.6)]),
        };
        let cost = task.over(&p.layout.variables, &p).unwrap();
        let controls = Controls::of(&p).unwrap();
        let start = p
            .scene
            .initial_state(&p.model, &mut ChaCha8Rng::seed_from_u64(5));
        let cem = CemSettings {
            iterations: 2,
            elite: 0.25,
        };
        let mut planner = Planner::new(PlannerKind::Cem, cem, 3, controls.bounds().clone(), 8, 1);
        let mut model = Simulator::new(&p, &controls, p.scene.steps_per_frame(), cost.clone());
        let tau = p
            .layout
            .variables
            .iter()
            .position(|n| n == "g.2.y")
            .unwrap();
        let mut steps = Vec::new();
        run(
            &p,
            &controls,
            &start,
            12,
            3,
            &cost,
            &mut Policy::Plan {
                planner: &mut planner,
                model: &mut model,
                sequences: 8,
            },
            9,
            |s, _, applied, _| {
                let k = controls.names().iter().position(|n| n == "g.2.y").unwrap();
                assert_eq!(
                    applied.variables[tau],
                    s.torques[k],
                    "frame {}",
                    s.frame - 1
                );
                steps.push(s.clone());
                Ok(())
            },
        )
        .unwrap();
        predicted_as_reached(&steps);
    }
}
