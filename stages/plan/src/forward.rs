//! Forward models a planner searches with. Each starts its predictions from
//! the state the true simulator is in at a decision ([`Model::start`]) and
//! predicts, for candidate torque sequences, the task's cost summed over
//! the frames ([`crate::planner::Forward`]).
//!
//! - [`Simulator`]: a simulator at k integration steps per frame — the
//!   scene as written (the nominal model; without a plant, k = the scene's
//!   own steps per frame is the true model; smaller k is cheaper and
//!   wronger), or a plant's own (the reference no user has). A candidate
//!   that blows up costs +∞.
//! - [`Learned`]: a model of levels — the trained ALN ([`Runtime`]) or the
//!   linear baseline ([`LinearStep`]) — fed the planner's controls as their
//!   variables' levels and its own predictions after that.
//! - [`Piecewise`]: a piecewise-linear ALN, which reads real values: fed the
//!   planner's torques as they are — so that its predictions move with
//!   every torque, not only with a torque's level — and its own predicted
//!   values after that; the cost read from those values directly.
//! - [`Hybrid`]: the simulator of the scene as written corrected by a
//!   piecewise-linear ALN trained as its correction, on a robot.

use alnlab_aln::linear::Linear;
use alnlab_aln::pwl::predict::{Path, Predictor, Scratch};
use alnlab_aln::runtime::Runtime;
use alnlab_codes::Entry;
use alnlab_common::state_log::StateFrame;
use alnlab_physics::batch_scene::SceneBatch;
use alnlab_physics::dynamics::State;
use alnlab_physics::{Prepared, Runner};
use nalgebra::Vector3;

use crate::controls::Controls;
use crate::planner::Forward;
use crate::task::Cost;

/// A forward model: a planner's [`Forward`] that can be started from the
/// true state.
pub trait Model: Forward {
    /// Starts the next predictions from `state` (whose variables, in the
    /// scene's layout order, are `variables`).
    fn start(&mut self, state: &State, variables: &[f64]);

    /// The task's variables (in the order of [`Cost::variables`]) `frames`
    /// frames on, predicted from the started state under `actions` (D
    /// torques a frame), the model fed its own predictions between: what
    /// the model expects the executed torques to do, to set beside what the
    /// simulator then did. NaN where the prediction blew up.
    fn predict(&mut self, actions: &[f64], frames: usize, out: &mut [f64]);
}

/// A simulator at `steps` integration steps per frame. It costs a
/// decision's candidates together, in SIMD lanes ([`SceneBatch`]), where
/// the scene allows — a plant's actuators' gain, lag and delay included;
/// one at a time otherwise (an RK4 scene, actuator noise, a robot's mimic
/// joints, a task reading a variable the state alone does not give).
pub struct Simulator<'a> {
    p: &'a Prepared,
    controls: Controls,
    runner: Runner<'a>,
    /// The batched path, where the scene allows it.
    lanes: Option<SceneBatch<'a>>,
    steps: u64,
    cost: Cost,
    start: State,
    state: State,
    /// Frames stepped since the start: time goes on from frame to frame, so
    /// that a plant's actuators update once an instant.
    stepped: u64,
    torques: Vec<Vector3<f64>>,
    frame: StateFrame,
    /// The scene's variables, of which the batched path fills the cost's.
    values: Vec<f64>,
}

impl<'a> Simulator<'a> {
    /// The simulator of scene `p` at `steps` steps per frame, set by
    /// `controls`, costing with `cost` (over the scene's variables).
    pub fn new(p: &'a Prepared, controls: &Controls, steps: u64, cost: Cost) -> Simulator<'a> {
        let hinges = p.model.len() - 1;
        let rest = State::rest(&p.model, Vector3::zeros());
        let read: Vec<usize> = cost.variables().collect();
        let steps = steps.max(1);
        let mut runner = Runner::new(p, 0, 0, 0);
        runner.pace(p.scene.step_dt(steps), steps);
        Simulator {
            controls: controls.clone(),
            runner,
            lanes: SceneBatch::new(p, &read),
            values: vec![0.0; p.layout.variables.len()],
            steps,
            cost,
            start: rest.clone(),
            state: rest,
            stepped: 0,
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

impl Simulator<'_> {
    /// [`Forward::costs`] with every candidate advanced together, frame by
    /// frame; false (nothing costed) where the scene has no batched path.
    fn batched_costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) -> bool {
        let Some(lanes) = &mut self.lanes else {
            return false;
        };
        let d = self.controls.dims();
        let dt = self.p.scene.step_dt(self.steps);
        lanes.start(&self.start, costs.len());
        costs.fill(0.0);
        for h in 0..horizon {
            for k in 0..costs.len() {
                let at = (k * horizon + h) * d;
                self.controls.set(&actions[at..at + d], &mut self.torques);
                lanes.drive(k, &self.torques);
            }
            lanes.advance(self.steps, dt);
            lanes.observe();
            for (k, cost) in costs.iter_mut().enumerate() {
                if *cost == f64::INFINITY {
                    continue;
                }
                match lanes.values(k) {
                    Some(read) => {
                        for (s, &x) in self.cost.variables().zip(read) {
                            self.values[s] = x;
                        }
                        *cost += self.cost.of(&self.values);
                    }
                    None => *cost = f64::INFINITY,
                }
            }
        }
        true
    }

    /// Starts again from the decision's state, its actuators at rest.
    fn restart(&mut self) {
        copy_state(&mut self.state, &self.start);
        self.runner.restart();
        self.stepped = 0;
    }

    /// Steps `self.state` one frame under `action`'s torques and observes
    /// the frame reached; false if it blew up.
    fn frame(&mut self, action: &[f64]) -> bool {
        self.controls.set(action, &mut self.torques);
        self.runner.drive(Some(&self.torques));
        let dt = self.p.scene.step_dt(self.steps);
        let first = self.stepped * self.steps;
        if self
            .runner
            .advance(&mut self.state, first, self.steps, dt)
            .is_err()
        {
            return false;
        }
        self.stepped += 1;
        let t = (first + self.steps) as f64 * dt;
        self.runner.observe(&self.state, t, &mut self.frame);
        true
    }
}

impl Model for Simulator<'_> {
    fn start(&mut self, state: &State, _variables: &[f64]) {
        copy_state(&mut self.start, state);
    }

    fn predict(&mut self, actions: &[f64], frames: usize, out: &mut [f64]) {
        self.restart();
        let d = actions.len() / frames.max(1);
        let reached = actions.chunks(d.max(1)).all(|action| self.frame(action));
        for (o, s) in out.iter_mut().zip(self.cost.variables()) {
            *o = if reached {
                self.frame.variables[s]
            } else {
                f64::NAN
            };
        }
    }
}

impl Forward for Simulator<'_> {
    fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) {
        if self.batched_costs(actions, horizon, costs) {
            return;
        }
        let d = self.controls.dims();
        for (sequence, cost) in actions.chunks(horizon * d).zip(costs.iter_mut()) {
            self.restart();
            *cost = 0.0;
            for frame in sequence.chunks(d) {
                if !self.frame(frame) {
                    *cost = f64::INFINITY;
                    break;
                }
                *cost += self.cost.of(&self.frame.variables);
            }
        }
    }
}

/// `*to = from.clone()` without allocating (a derived `clone_from` would).
fn copy_state(to: &mut State, from: &State) {
    to.root_p = from.root_p;
    to.root_v = from.root_v;
    to.orient.clone_from(&from.orient);
    to.rates.clone_from(&from.rates);
    to.q.clone_from(&from.q);
    to.qd.clone_from(&from.qd);
}

/// A model of the next levels from the current ones, both `[variable][row]`
/// over a codebook's learned variables: the trained ALN or the linear
/// baseline.
pub trait LevelStep {
    fn next(&self, x: &[Vec<u16>]) -> Vec<Vec<u16>>;
}

impl LevelStep for Runtime<'_> {
    fn next(&self, x: &[Vec<u16>]) -> Vec<Vec<u16>> {
        self.levels(x, None)
    }
}

/// The linear baseline with the level counts it clamps to.
pub struct LinearStep<'a> {
    pub linear: &'a Linear,
    pub levels: &'a [usize],
}

impl LevelStep for LinearStep<'_> {
    fn next(&self, x: &[Vec<u16>]) -> Vec<Vec<u16>> {
        self.linear.levels(x, self.levels)
    }
}

/// A forward model in levels: the true state quantized by the codebook,
/// each frame's controls set as their variables' levels, the next levels
/// predicted for every candidate at once
/// (the ALN bit-sliced), fed back, and the task's variables read back at
/// their levels' values to cost.
pub struct Learned<'a, S: LevelStep> {
    step: S,
    entries: Vec<&'a Entry>,
    /// Per learned variable, its index among the scene's variables.
    in_scene: Vec<usize>,
    /// (torque component in an action, learned variable) pairs.
    torques: Vec<(usize, usize)>,
    /// (learned variable, scene variable) of the variables the cost reads.
    costed: Vec<(usize, usize)>,
    cost: Cost,
    start: Vec<u16>,
    values: Vec<f64>,
}

impl<'a, S: LevelStep> Learned<'a, S> {
    /// `step` over the `learned` codebook entries, in scene `p` set by
    /// `controls`, costing with `cost`. An error names a task variable the
    /// codebook does not learn, or says it learns no control.
    pub fn new(
        step: S,
        learned: Vec<&'a Entry>,
        p: &Prepared,
        controls: &Controls,
        cost: Cost,
    ) -> Result<Learned<'a, S>, String> {
        let (in_scene, torques, costed) = wiring(&learned, p, controls, &cost)?;
        let names = &p.layout.variables;
        Ok(Learned {
            step,
            start: vec![0; learned.len()],
            entries: learned,
            in_scene,
            torques,
            costed,
            cost,
            values: vec![0.0; names.len()],
        })
    }
}

impl<S: LevelStep> Learned<'_, S> {
    /// Sets frame `h` of each of the `x[0].len()` sequences in `actions`
    /// (each `len` values, D per frame) as the torque variables' levels.
    fn set_torques(&self, x: &mut [Vec<u16>], actions: &[f64], len: usize, at: usize) {
        for &(k, v) in &self.torques {
            let q = &self.entries[v].quantizer;
            for (i, level) in x[v].iter_mut().enumerate() {
                *level = q.level(actions[i * len + at + k]).0;
            }
        }
    }
}

impl<S: LevelStep> Model for Learned<'_, S> {
    fn start(&mut self, _state: &State, variables: &[f64]) {
        for ((level, entry), &s) in self.start.iter_mut().zip(&self.entries).zip(&self.in_scene) {
            *level = entry.quantizer.level(variables[s]).0;
        }
    }

    fn predict(&mut self, actions: &[f64], frames: usize, out: &mut [f64]) {
        let mut x: Vec<Vec<u16>> = self.start.iter().map(|&l| vec![l]).collect();
        let d = actions.len() / frames.max(1);
        for h in 0..frames {
            self.set_torques(&mut x, actions, actions.len(), h * d);
            x = self.step.next(&x);
        }
        for (o, &(v, _)) in out.iter_mut().zip(&self.costed) {
            *o = self.entries[v].quantizer.value(usize::from(x[v][0]));
        }
    }
}

impl<S: LevelStep> Forward for Learned<'_, S> {
    fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) {
        let n = costs.len();
        let len = actions.len() / n.max(1);
        let d = len / horizon.max(1);
        let mut x: Vec<Vec<u16>> = self.start.iter().map(|&l| vec![l; n]).collect();
        costs.fill(0.0);
        for h in 0..horizon {
            self.set_torques(&mut x, actions, len, h * d);
            x = self.step.next(&x);
            for (i, cost) in costs.iter_mut().enumerate() {
                for &(v, s) in &self.costed {
                    self.values[s] = self.entries[v].quantizer.value(usize::from(x[v][i]));
                }
                *cost += self.cost.of(&self.values);
            }
        }
    }
}

/// The learned variables' indices in the scene, the (control component,
/// learned variable) pairs that take the planner's controls, and the
/// (learned variable, scene variable) pairs the cost reads; an error names
/// what the model lacks.
type Wiring = (Vec<usize>, Vec<(usize, usize)>, Vec<(usize, usize)>);

fn wiring(
    learned: &[&Entry],
    p: &Prepared,
    controls: &Controls,
    cost: &Cost,
) -> Result<Wiring, String> {
    let names = &p.layout.variables;
    let in_scene = learned
        .iter()
        .map(|e| {
            names
                .iter()
                .position(|n| *n == e.variable)
                .ok_or_else(|| format!("scene `{}` has no variable `{}`", p.scene.name, e.variable))
        })
        .collect::<Result<Vec<_>, String>>()?;
    let find = |name: &str| learned.iter().position(|e| e.variable == name);
    let torques = controls
        .names()
        .iter()
        .enumerate()
        .filter_map(|(k, name)| find(name).map(|v| (k, v)))
        .collect::<Vec<_>>();
    if torques.is_empty() {
        return Err(format!(
            "the model learns none of scene `{}`'s controls ({}): it cannot be told the \
             planner's torques",
            p.scene.name,
            controls.names().join(", ")
        ));
    }
    let costed = cost
        .variables()
        .map(|s| {
            let v = in_scene.iter().position(|&i| i == s).ok_or_else(|| {
                format!(
                    "the model does not learn `{}`, which the task reads",
                    names[s]
                )
            })?;
            Ok((v, s))
        })
        .collect::<Result<Vec<_>, String>>()?;
    Ok((in_scene, torques, costed))
}

/// The variables `predictor` predicts (indices among the learned ones); an
/// error names a variable the task reads (`costed`, as [`wiring`] pairs
/// them) that is neither predicted nor one of the planner's `torques`.
fn predicted_and_read(
    predictor: &Predictor,
    p: &Prepared,
    torques: &[(usize, usize)],
    costed: &[(usize, usize)],
) -> Result<Vec<usize>, String> {
    let predicted: Vec<usize> = predictor.variables().collect();
    if let Some(&(_, s)) = costed
        .iter()
        .find(|(v, _)| !predicted.contains(v) && !torques.iter().any(|(_, t)| t == v))
    {
        return Err(format!(
            "the model does not predict `{}`, which the task reads",
            p.layout.variables[s]
        ));
    }
    Ok(predicted)
}

/// A piecewise-linear ALN as a forward model, in real values: the true
/// state's learned variables, each frame's controls set as their
/// variables' values, the predicted variables advanced (every piece, all of
/// a decision's candidates together), and the task's variables costed at
/// the predicted values.
pub struct Piecewise<'a> {
    predictor: &'a Predictor<'a>,
    scratch: Scratch<'a>,
    /// Per learned variable, its index among the scene's variables.
    in_scene: Vec<usize>,
    torques: Vec<(usize, usize)>,
    costed: Vec<(usize, usize)>,
    /// The predicted variables' indices among the learned ones.
    predicted: Vec<usize>,
    cost: Cost,
    start: Vec<f64>,
    state: Vec<f64>,
    next: Vec<f64>,
    values: Vec<f64>,
    /// A decision's candidates' learned variables.
    columns: Columns,
}

impl<'a> Piecewise<'a> {
    /// `predictor` over the `learned` codebook entries, in scene `p` set
    /// by `controls`, costing with `cost`. An error names a task variable
    /// the model does not predict, or says it reads no control.
    pub fn new(
        predictor: &'a Predictor<'a>,
        learned: &[&Entry],
        p: &Prepared,
        controls: &Controls,
        cost: Cost,
    ) -> Result<Piecewise<'a>, String> {
        let (in_scene, torques, costed) = wiring(learned, p, controls, &cost)?;
        let predicted = predicted_and_read(predictor, p, &torques, &costed)?;
        Ok(Piecewise {
            scratch: predictor.scratch(),
            next: vec![0.0; predicted.len()],
            predicted,
            predictor,
            start: vec![0.0; learned.len()],
            state: vec![0.0; learned.len()],
            values: vec![0.0; p.layout.variables.len()],
            in_scene,
            torques,
            costed,
            cost,
            columns: Columns::default(),
        })
    }

    /// One frame from `self.state` under the torques `frame` (D values).
    fn step(&mut self, frame: &[f64]) {
        for &(k, v) in &self.torques {
            self.state[v] = frame[k];
        }
        self.predictor
            .next_values(&self.state, Path::Plain, &mut self.scratch, &mut self.next);
        for (&v, &x) in self.predicted.iter().zip(&self.next) {
            self.state[v] = x;
        }
    }
}

impl Model for Piecewise<'_> {
    fn start(&mut self, _state: &State, variables: &[f64]) {
        for (value, &s) in self.start.iter_mut().zip(&self.in_scene) {
            *value = variables[s];
        }
    }

    fn predict(&mut self, actions: &[f64], frames: usize, out: &mut [f64]) {
        self.state.copy_from_slice(&self.start);
        for frame in actions.chunks((actions.len() / frames.max(1)).max(1)) {
            self.step(frame);
        }
        for (o, &(v, _)) in out.iter_mut().zip(&self.costed) {
            *o = self.state[v];
        }
    }
}

impl Forward for Piecewise<'_> {
    /// Every candidate advanced together, frame by frame, through the
    /// predictor's batched path ([`Predictor::values`]): the same numbers
    /// as stepping each alone, so the same plans, for a fraction of the
    /// time.
    fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) {
        let n = costs.len();
        costs.fill(0.0);
        if n == 0 || horizon == 0 {
            return;
        }
        let len = actions.len() / n;
        let d = len / horizon;
        let width = self.start.len();
        let columns = &mut self.columns;
        columns.reset(&self.start, width, self.predicted.len(), n);
        for h in 0..horizon {
            for &(k, v) in &self.torques {
                for (i, x) in columns.column_mut(v).iter_mut().enumerate() {
                    *x = actions[i * len + h * d + k];
                }
            }
            columns.advance(self.predictor, &mut self.scratch, &self.predicted, 0);
            for (i, cost) in costs.iter_mut().enumerate() {
                for &(v, s) in &self.costed {
                    self.values[s] = columns.at(v, i);
                }
                *cost += self.cost.of(&self.values);
            }
        }
    }
}

/// A decision's candidates' real values, `[variable][candidate]`, advanced
/// together through a piecewise-linear predictor's batched path: what
/// [`Piecewise`] and [`Hybrid`] cost their candidates with. Sized by the
/// largest budget, then allocation-free.
#[derive(Default)]
struct Columns {
    /// `[variable][candidate]`, flattened.
    values: Vec<f64>,
    /// The predicted variables' next values, `[output][candidate]`.
    next: Vec<Vec<f64>>,
    /// Candidates.
    n: usize,
}

impl Columns {
    /// `n` candidates of `variables` columns, the first `start.len()` of
    /// them each candidate's `start`, for `outputs` predicted variables.
    fn reset(&mut self, start: &[f64], variables: usize, outputs: usize, n: usize) {
        self.n = n;
        self.values.resize(variables * n, 0.0);
        for (column, &x) in self.values.chunks_mut(n).zip(start) {
            column.fill(x);
        }
        self.next.resize(outputs, Vec::new());
        for next in &mut self.next {
            next.resize(n, 0.0);
        }
    }

    /// Variable `v` of candidate `k`.
    fn at(&self, v: usize, k: usize) -> f64 {
        self.values[v * self.n + k]
    }

    fn at_mut(&mut self, v: usize, k: usize) -> &mut f64 {
        &mut self.values[v * self.n + k]
    }

    /// Variable `v` of every candidate.
    fn column_mut(&mut self, v: usize) -> &mut [f64] {
        &mut self.values[v * self.n..(v + 1) * self.n]
    }

    /// Advances the `predicted` variables one frame, each from its value
    /// in the columns from `base` on ([`Predictor::values_from`]): 0 for
    /// its current value, a hybrid's state width for its nominal
    /// prediction.
    fn advance<'m>(
        &mut self,
        predictor: &Predictor<'m>,
        scratch: &mut Scratch<'m>,
        predicted: &[usize],
        base: usize,
    ) {
        let n = self.n;
        let columns: Vec<&[f64]> = self.values.chunks(n).collect();
        predictor.values_from(&columns, &columns[base..], scratch, &mut self.next);
        for (&v, next) in predicted.iter().zip(&self.next) {
            self.values[v * n..(v + 1) * n].copy_from_slice(next);
        }
    }
}

/// A hybrid as a forward model: each frame the simulator of the scene as
/// written steps the state at the nominal model's step (the scene's own,
/// or its `nominal_steps`), and a piecewise-linear ALN
/// trained as its correction (`[train] base = "nominal"`) turns that
/// nominal prediction into the next values of the predicted variables,
/// from which the next frame's state is rebuilt — a robot's joint
/// positions and velocities are predicted variables, so its state is made
/// of them. Costed at the corrected values. A decision's candidates are
/// advanced together — the simulator in SIMD lanes ([`SceneBatch`]), the
/// correction through the predictor's batched path — where the scene
/// allows, one at a time otherwise.
pub struct Hybrid<'a> {
    nominal: Simulator<'a>,
    /// The nominal simulator's batched path, reading the learned variables.
    lanes: Option<SceneBatch<'a>>,
    predictor: &'a Predictor<'a>,
    scratch: Scratch<'a>,
    /// Per learned variable, its index among the scene's variables.
    in_scene: Vec<usize>,
    torques: Vec<(usize, usize)>,
    costed: Vec<(usize, usize)>,
    /// The predicted variables' indices among the learned ones.
    predicted: Vec<usize>,
    /// Per one-DOF joint: its link, and the learned variables that are its
    /// position and velocity.
    joints: Vec<(usize, usize, usize)>,
    cost: Cost,
    start: Vec<f64>,
    /// The learned variables now, then their nominal predictions.
    inputs: Vec<f64>,
    next: Vec<f64>,
    values: Vec<f64>,
    /// A decision's candidates' `inputs`.
    columns: Columns,
}

impl<'a> Hybrid<'a> {
    /// The hybrid of `nominal` (the scene as written, at its nominal step,
    /// set by `controls`) and `predictor` (over the `learned` entries and
    /// their nominal predictions), costing with `cost`. An error says what
    /// the scene or model lacks for it.
    pub fn new(
        nominal: &'a Prepared,
        predictor: &'a Predictor<'a>,
        learned: &[&Entry],
        controls: &Controls,
        cost: Cost,
    ) -> Result<Hybrid<'a>, String> {
        let (in_scene, torques, costed) = wiring(learned, nominal, controls, &cost)?;
        let predicted = predicted_and_read(predictor, nominal, &torques, &costed)?;
        // The state the simulator re-steps must be made of predicted
        // variables: a fixed-root robot's joint positions and velocities.
        let refused = |why: String| {
            format!(
                "scene `{}`: a hybrid re-steps its nominal simulator from the state it \
                 predicted, and {why}",
                nominal.scene.name
            )
        };
        alnlab_physics::runner::state_from_variables(
            &nominal.layout.state,
            &nominal.layout.variables,
        )
        .map_err(|why| refused(why.replace("the state's", "its state's")))?;
        let Some(robot) = &nominal.robot else {
            return Err(refused("it is not a robot".into()));
        };
        let find = |name: String| {
            predicted
                .iter()
                .copied()
                .find(|&v| learned[v].variable == name)
                .ok_or_else(|| format!("the model does not predict `{name}`"))
        };
        let joints = (1..nominal.model.len())
            .filter(|&i| nominal.model.links[i].joint.dof() == 1)
            .map(|i| {
                let joint = &robot.joints[i];
                Ok((i, find(format!("q.{joint}"))?, find(format!("qd.{joint}"))?))
            })
            .collect::<Result<_, String>>()?;
        let width = learned.len();
        Ok(Hybrid {
            lanes: SceneBatch::new(nominal, &in_scene),
            columns: Columns::default(),
            nominal: Simulator::new(
                nominal,
                controls,
                nominal.scene.nominal_steps_per_frame(),
                cost.clone(),
            ),
            scratch: predictor.scratch(),
            next: vec![0.0; predicted.len()],
            predicted,
            predictor,
            joints,
            start: vec![0.0; width],
            inputs: vec![0.0; 2 * width],
            values: vec![0.0; nominal.layout.variables.len()],
            in_scene,
            torques,
            costed,
            cost,
        })
    }

    /// One frame under the controls `frame`: the simulator of the scene as
    /// written steps its state — the decision's at the first frame, then
    /// the state rebuilt from the hybrid's own predicted joint positions
    /// and velocities — and the correction advances the learned values in
    /// `self.inputs` from that nominal prediction. False if the simulator
    /// blew up.
    fn step(&mut self, frame: &[f64], first: bool) -> bool {
        let width = self.start.len();
        let sim = &mut self.nominal;
        if first {
            copy_state(&mut sim.state, &sim.start);
        } else {
            for &(link, q, qd) in &self.joints {
                sim.state.q[link] = self.inputs[q];
                sim.state.qd[link] = self.inputs[qd];
            }
        }
        for &(k, v) in &self.torques {
            self.inputs[v] = frame[k];
        }
        sim.runner.restart();
        if !sim.frame(frame) {
            return false;
        }
        for (k, &s) in self.in_scene.iter().enumerate() {
            self.inputs[width + k] = sim.frame.variables[s];
        }
        self.predictor.next_values_from(
            &self.inputs,
            &self.inputs[width..],
            Path::Plain,
            &mut self.scratch,
            &mut self.next,
        );
        for (&v, &x) in self.predicted.iter().zip(&self.next) {
            self.inputs[v] = x;
        }
        true
    }

    /// [`Forward::costs`] with every candidate advanced together, frame by
    /// frame, as [`Hybrid::step`] advances one; false (nothing costed)
    /// where the scene has no batched path.
    fn batched_costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) -> bool {
        let Some(lanes) = &mut self.lanes else {
            return false;
        };
        let n = costs.len();
        costs.fill(0.0);
        if n == 0 || horizon == 0 {
            return true;
        }
        let (len, width) = (actions.len() / n, self.start.len());
        let d = len / horizon;
        let sim = &mut self.nominal;
        let dt = sim.p.scene.step_dt(sim.steps);
        let columns = &mut self.columns;
        columns.reset(&self.start, 2 * width, self.predicted.len(), n);
        lanes.start(&sim.start, n);
        for h in 0..horizon {
            for k in 0..n {
                let frame = &actions[k * len + h * d..k * len + (h + 1) * d];
                if h > 0 {
                    for &(link, q, qd) in &self.joints {
                        lanes.set_joint(k, link, columns.at(q, k), columns.at(qd, k));
                    }
                }
                for &(c, v) in &self.torques {
                    *columns.at_mut(v, k) = frame[c];
                }
                sim.controls.set(frame, &mut sim.torques);
                lanes.drive(k, &sim.torques);
            }
            lanes.advance(sim.steps, dt);
            lanes.observe();
            for (k, cost) in costs.iter_mut().enumerate() {
                match lanes.values(k) {
                    Some(read) => {
                        for (v, &x) in read.iter().enumerate() {
                            *columns.at_mut(width + v, k) = x;
                        }
                    }
                    None => *cost = f64::INFINITY,
                }
            }
            columns.advance(self.predictor, &mut self.scratch, &self.predicted, width);
            for (k, cost) in costs.iter_mut().enumerate() {
                if *cost == f64::INFINITY {
                    continue;
                }
                for &(v, s) in &self.costed {
                    self.values[s] = columns.at(v, k);
                }
                *cost += self.cost.of(&self.values);
            }
        }
        true
    }
}

impl Model for Hybrid<'_> {
    fn start(&mut self, state: &State, variables: &[f64]) {
        for (value, &s) in self.start.iter_mut().zip(&self.in_scene) {
            *value = variables[s];
        }
        copy_state(&mut self.nominal.start, state);
    }

    fn predict(&mut self, actions: &[f64], frames: usize, out: &mut [f64]) {
        let width = self.start.len();
        self.inputs[..width].copy_from_slice(&self.start);
        let d = (actions.len() / frames.max(1)).max(1);
        let reached = (0..frames).all(|h| self.step(&actions[h * d..(h + 1) * d], h == 0));
        for (o, &(v, _)) in out.iter_mut().zip(&self.costed) {
            *o = if reached { self.inputs[v] } else { f64::NAN };
        }
    }
}

impl Forward for Hybrid<'_> {
    fn costs(&mut self, actions: &[f64], horizon: usize, costs: &mut [f64]) {
        if self.batched_costs(actions, horizon, costs) {
            return;
        }
        let width = self.start.len();
        let len = actions.len() / costs.len().max(1);
        let d = len / horizon.max(1);
        for (sequence, cost) in actions.chunks(len.max(1)).zip(costs.iter_mut()) {
            self.inputs[..width].copy_from_slice(&self.start);
            *cost = 0.0;
            for (h, frame) in sequence.chunks(d.max(1)).take(horizon).enumerate() {
                if !self.step(frame, h == 0) {
                    *cost = f64::INFINITY;
                    break;
                }
                for &(v, s) in &self.costed {
                    self.values[s] = self.inputs[v];
                }
                *cost += self.cost.of(&self.values);
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use std::collections::BTreeMap;

    use alnlab_codes::Code;
    use alnlab_codes::codebook::Quantizer;
    use alnlab_physics::Scene;
    use alnlab_physics::controller::{ControllerKind, ControllerParams};

    use super::*;
    use crate::task::{HoldStart, Task};

    fn entry(variable: &str, min: f64, max: f64, levels: usize) -> Entry {
        Entry {
            variable: variable.into(),
            learned: true,
            note: String::new(),
            quantizer: Quantizer { min, max, levels },
            code: Code::Gray,
            width: 0,
            walk_step: 1,
            walk_span: 1,
            seed: 0,
            clamped: 0,
        }
    }

    /// A controlled worm and codebook entries of its `pitch.2` and `g.2.y`:
    /// pitch.2 in 41 levels over [−2, 2] (0.1 rad each), g.2.y in 21 levels
    /// over [−10, 10] (1 N m each).
    fn worm_pitch_and_torque() -> (Prepared, [Entry; 2]) {
        let p = Prepared::new(&Scene {
            controller: Some(ControllerParams {
                kind: ControllerKind::Random,
                ..ControllerParams::default()
            }),
            ..Scene::default()
        });
        let entries = [
            entry("pitch.2", -2.0, 2.0, 41),
            entry("g.2.y", -10.0, 10.0, 21),
        ];
        (p, entries)
    }

    /// The repository's UR5 as `scene` otherwise gives it (its plant, its
    /// drives), under a random controller of ±60 N·m.
    pub(crate) fn ur5(scene: Scene) -> Prepared {
        use alnlab_physics::SceneKind;
        use alnlab_physics::controller::Amplitude;
        let mut scene = Scene {
            name: "ur5".into(),
            kind: SceneKind::Urdf,
            file: Some("robots/ur5/ur5_robot.urdf".into()),
            controller: Some(ControllerParams {
                kind: ControllerKind::Random,
                amplitude: vec![Amplitude::Axis(60.0)],
                ..ControllerParams::default()
            }),
            ..scene
        };
        let workspace = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        scene.read_description(&workspace).unwrap();
        Prepared::new(&scene)
    }

    /// pitch.2 (learned variable 0) moves by g.2.y's level − 10 per frame.
    struct Nudge;

    impl LevelStep for Nudge {
        fn next(&self, x: &[Vec<u16>]) -> Vec<Vec<u16>> {
            let pitch = x[0]
                .iter()
                .zip(&x[1])
                .map(|(&p, &g)| (i32::from(p) + i32::from(g) - 10).clamp(0, 40) as u16)
                .collect();
            vec![pitch, x[1].clone()]
        }
    }

    #[test]
    fn learned_models_take_torques_as_levels_and_cost_their_predictions() {
        let (p, entries) = worm_pitch_and_torque();
        let task = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "hold".into(),
            targets: BTreeMap::from([("pitch.2".into(), 0.5)]),
        };
        let cost = task.over(&p.layout.variables, &p).unwrap();
        let controls = Controls::of(&p).unwrap();
        let mut model =
            Learned::new(Nudge, entries.iter().collect(), &p, &controls, cost.clone()).unwrap();
        let mut variables = vec![0.0; p.layout.variables.len()];
        let pitch = p
            .layout
            .variables
            .iter()
            .position(|n| n == "pitch.2")
            .unwrap();
        variables[pitch] = 0.0; // level 20
        let rest = State::rest(&p.model, Vector3::zeros());
        model.start(&rest, &variables);
        // Two candidates over 2 frames, 6 torque components each (2 hinges):
        // g.2.y = +2 N m (level 12: +2 levels, +0.2 rad per frame), or 0.
        let d = 6;
        let mut actions = vec![0.0; 2 * 2 * d];
        actions[1] = 2.0;
        actions[d + 1] = 2.0;
        let mut costs = [0.0; 2];
        model.costs(&actions, 2, &mut costs);
        // Pushed: pitch 0.2 then 0.4 → (0.3² + 0.1²); left alone: 0.5² twice.
        assert!((costs[0] - (0.09 + 0.01)).abs() < 1e-9, "{costs:?}");
        assert!((costs[1] - 0.5).abs() < 1e-9, "{costs:?}");

        // A task variable the model does not learn is refused by name.
        let other = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "h".into(),
            targets: BTreeMap::from([("roll.3".into(), 0.0)]),
        };
        let cost = other.over(&p.layout.variables, &p).unwrap();
        let e = Learned::new(Nudge, entries.iter().collect(), &p, &controls, cost)
            .err()
            .unwrap();
        assert!(e.contains("does not learn `roll.3`"), "{e}");
    }

    /// The piecewise forward model costs all candidates together through
    /// the batched path, and its costs are, number for number, those of
    /// stepping each candidate alone.
    #[test]
    fn piecewise_candidates_batched_cost_what_each_alone_costs() {
        use alnlab_aln::model::Reads;
        use alnlab_aln::pwl::{Node, Tree};
        let (p, entries) = worm_pitch_and_torque();
        let learned: Vec<&Entry> = entries.iter().collect();
        // pitch.2's change in levels: max(min(0.3 p + g, 4 − p), −2 + 0.1 g).
        let tree = Tree::from_parts(
            2,
            vec![
                Node::Max(1, 2),
                Node::Min(3, 4),
                Node::Piece(0),
                Node::Piece(1),
                Node::Piece(2),
            ],
            vec![-2.0, 0.0, 0.1, 0.0, 0.3, 1.0, 4.0, -1.0, 0.0],
        )
        .unwrap();
        let trees = [tree];
        let reads = [Reads {
            variable: 0,
            inputs: vec![0, 1],
        }];
        let box_points = [-1.0, -5.0, 1.0, 5.0];
        let predictor = Predictor::new(&trees, &reads, &learned, &box_points);
        let task = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "hold".into(),
            targets: BTreeMap::from([("pitch.2".into(), 0.5)]),
        };
        let cost = task.over(&p.layout.variables, &p).unwrap();
        let controls = Controls::of(&p).unwrap();
        let mut model = Piecewise::new(&predictor, &learned, &p, &controls, cost.clone()).unwrap();
        let mut variables = vec![0.0; p.layout.variables.len()];
        let pitch = p.layout.variables.iter().position(|n| n == "pitch.2");
        variables[pitch.unwrap()] = -0.3;
        let rest = State::rest(&p.model, Vector3::zeros());
        model.start(&rest, &variables);
        // 70 candidates (a whole block and a part) over 4 frames.
        let (n, horizon, d) = (70, 4, controls.dims());
        let actions: Vec<f64> = (0..n * horizon * d)
            .map(|i| ((i as f64 * 0.618_033_988_7).fract() * 2.0 - 1.0) * 8.0)
            .collect();
        let mut costs = vec![0.0; n];
        model.costs(&actions, horizon, &mut costs);
        for (i, &batched) in costs.iter().enumerate() {
            model.state.copy_from_slice(&model.start);
            let mut alone = 0.0;
            for frame in actions[i * horizon * d..(i + 1) * horizon * d].chunks(d) {
                model.step(frame);
                let mut values = vec![0.0; p.layout.variables.len()];
                for &(v, s) in &model.costed {
                    values[s] = model.state[v];
                }
                alone += cost.of(&values);
            }
            assert_eq!(batched, alone, "candidate {i}");
        }
        assert!(
            costs.iter().any(|&c| c != costs[0]),
            "torques move the costs"
        );
    }

    /// The simulator costs a decision's candidates together in SIMD lanes,
    /// equal to stepping each alone to rounding: on the worm landed on its
    /// floor (contacts), for a task on angles and one on a rate, at two and
    /// ten steps a frame, torques past the limit included.
    #[test]
    fn simulator_candidates_batched_cost_what_each_alone_costs() {
        let (p, _) = worm_pitch_and_torque();
        let mut start = p
            .scene
            .initial_state(&p.model, &mut alnlab_physics::scene::run_rng(1, 0, 0));
        Runner::new(&p, 1, 0, 0)
            .advance(&mut start, 0, 1000, p.scene.dt.get())
            .unwrap();
        let controls = Controls::of(&p).unwrap();
        let tasks = [
            Task::HoldAngles {
                tolerance: None,
                start: HoldStart::Logged,
                velocity_weight: None,
                name: "bend".into(),
                targets: BTreeMap::from([("pitch.2".into(), 0.6), ("pitch.3".into(), -0.6)]),
            },
            Task::Spin {
                tolerance: None,
                name: "spin".into(),
                variable: "omega.3.x".into(),
                rate: 2.0,
            },
        ];
        let (n, horizon, d) = (9, 5, controls.dims());
        let actions: Vec<f64> = (0..n * horizon * d)
            .map(|i| ((i as f64 * 0.618_033_988_7).fract() * 2.0 - 1.0) * 40.0)
            .collect();
        for task in &tasks {
            for steps in [2, 10] {
                let cost = task.over(&p.layout.variables, &p).unwrap();
                let mut batched = Simulator::new(&p, &controls, steps, cost.clone());
                let mut alone = Simulator::new(&p, &controls, steps, cost);
                assert!(batched.lanes.is_some());
                alone.lanes = None;
                let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
                for (model, costs) in [(&mut batched, &mut a), (&mut alone, &mut b)] {
                    model.start(&start, &[]);
                    model.costs(&actions, horizon, costs);
                }
                for (k, (x, y)) in a.iter().zip(&b).enumerate() {
                    assert!(
                        (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                        "{}, {steps} steps, candidate {k}: {x} against {y}",
                        task.name()
                    );
                }
                assert!(a.iter().any(|&c| c != a[0]), "torques move the costs");
            }
        }
    }

    /// The plant's own simulator as forward model costs a decision's
    /// candidates together in SIMD lanes — its actuators' gain, lag and
    /// delay tracked lane by lane — equal to stepping each alone, with time
    /// going on from frame to frame, to rounding; at one step a frame (where
    /// every step is an observation's instant) and at ten. Its noise is
    /// taken out first: a noisy plant has no batched path.
    #[test]
    fn a_plants_own_candidates_batched_cost_what_each_alone_costs() {
        use alnlab_physics::plant::Plant;
        let noisy = ur5(Scene {
            velocity_limits: true,
            plant: Some(Plant {
                mass_scale: 1.1,
                coulomb_friction: 1.5,
                actuator_gain: 0.95,
                actuator_lag: 0.005,
                actuator_delay_frames: 1,
                torque_noise: 0.2,
                ..Plant::default()
            }),
            ..Scene::default()
        });
        let task = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "raise".into(),
            targets: BTreeMap::from([
                ("q.shoulder_lift_joint".into(), -1.2),
                ("q.elbow_joint".into(), 0.8),
            ]),
        };
        let controls = Controls::of(&noisy).unwrap();
        let cost = task.over(&noisy.layout.variables, &noisy).unwrap();
        assert!(
            Simulator::new(&noisy, &controls, 10, cost.clone())
                .lanes
                .is_none()
        );
        let p = noisy.without_noise();
        let start = p
            .scene
            .initial_state(&p.model, &mut alnlab_physics::scene::run_rng(3, 0, 0));
        let (n, horizon, d) = (9, 4, controls.dims());
        let actions: Vec<f64> = (0..n * horizon * d)
            .map(|i| ((i as f64 * 0.618_033_988_7).fract() * 2.0 - 1.0) * 60.0)
            .collect();
        for steps in [1, 10] {
            let mut batched = Simulator::new(&p, &controls, steps, cost.clone());
            let mut alone = Simulator::new(&p, &controls, steps, cost.clone());
            assert!(batched.lanes.is_some());
            alone.lanes = None;
            let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
            for (model, costs) in [(&mut batched, &mut a), (&mut alone, &mut b)] {
                model.start(&start, &[]);
                model.costs(&actions, horizon, costs);
            }
            for (k, (x, y)) in a.iter().zip(&b).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                    "{steps} steps, candidate {k}: {x} against {y}"
                );
            }
            assert!(a.iter().any(|&c| c != a[0]), "torques move the costs");
        }
    }

    /// The hybrid costs a decision's candidates together — its simulator
    /// in SIMD lanes, its correction batched — equal to advancing each
    /// alone to rounding: on the UR5, every joint's position and velocity
    /// corrected from its own value and nominal prediction, efforts past the
    /// wrists' limits clamped.
    #[test]
    fn hybrid_candidates_batched_cost_what_each_alone_costs() {
        use alnlab_aln::model::Reads;
        use alnlab_aln::pwl::Tree;
        let p = ur5(Scene::default());
        let entries: Vec<Entry> = p
            .layout
            .variables
            .iter()
            .map(|v| entry(v, -10.0, 10.0, 201))
            .collect();
        let learned: Vec<&Entry> = entries.iter().collect();
        let width = learned.len();
        let predicted: Vec<usize> = (0..width)
            .filter(|&v| entries[v].variable.starts_with("q"))
            .filter(|&v| !entries[v].variable.starts_with("qdd"))
            .collect();
        assert_eq!(predicted.len(), 12, "six joints' q and qd");
        let trees: Vec<Tree> = predicted
            .iter()
            .map(|_| Tree::affine(0.3, &[0.02, -0.01]))
            .collect();
        let reads: Vec<Reads> = predicted
            .iter()
            .map(|&v| Reads {
                variable: v,
                inputs: vec![v, width + v],
            })
            .collect();
        let inputs = alnlab_aln::model::Base::Nominal.inputs(&learned);
        let points = vec![0.0; 2 * width];
        let predictor = Predictor::new(&trees, &reads, &inputs, &points);
        let task = Task::HoldAngles {
            tolerance: None,
            start: HoldStart::Logged,
            velocity_weight: None,
            name: "raise".into(),
            targets: BTreeMap::from([
                ("q.shoulder_lift_joint".into(), -1.2),
                ("q.elbow_joint".into(), 0.8),
            ]),
        };
        let cost = task.over(&p.layout.variables, &p).unwrap();
        let controls = Controls::of(&p).unwrap();
        let start = p
            .scene
            .initial_state(&p.model, &mut alnlab_physics::scene::run_rng(2, 0, 0));
        let mut frame = StateFrame::default();
        Runner::new(&p, 2, 0, 0).observe(&start, 0.0, &mut frame);
        let (n, horizon, d) = (9, 4, controls.dims());
        let actions: Vec<f64> = (0..n * horizon * d)
            .map(|i| ((i as f64 * 0.618_033_988_7).fract() * 2.0 - 1.0) * 60.0)
            .collect();
        let hybrid = || Hybrid::new(&p, &predictor, &learned, &controls, cost.clone()).unwrap();
        let (mut batched, mut alone) = (hybrid(), hybrid());
        assert!(batched.lanes.is_some());
        alone.lanes = None;
        let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
        for (model, costs) in [(&mut batched, &mut a), (&mut alone, &mut b)] {
            model.start(&start, &frame.variables);
            model.costs(&actions, horizon, costs);
        }
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(
                (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                "candidate {k}: {x} against {y}"
            );
        }
        assert!(a.iter().any(|&c| c != a[0]), "torques move the costs");
    }
}
