//! The plan stage (paper §1: "based on iterated faster-than-real-time
//! prediction of what would happen given certain applied torques …, the
//! torques etc. can be changed until the predicted solution is
//! satisfactory"): model-predictive control of a scene in the true
//! simulator. Every frame a planner ([`planner`]: random shooting or the
//! cross-entropy method) searches sequences of the scene's controls
//! ([`controls`]) over a horizon with a forward model ([`forward`]: the
//! trained ALN — a hybrid, if it was trained as the nominal simulator's
//! correction — the linear baseline, the scene as written at k steps per
//! frame, or a plant's own simulator), the scene's own simulator — its
//! plant, where it has one — executes the first frame's controls, and the
//! task's cost ([`task`]) of the frame reached is added up ([`episode`]).
//! Zero torques and the scene's random controller are the references, and
//! for a robot, the controls engineer's first tries: PD and PID loops on the
//! nominal model's gravity compensation, each loop's frequency tuned on
//! episodes of its own ([`feedback`]).
//!
//! For every task, model, planner and budget (sequences per decision), the
//! same episodes — the same start states, taken from the trajectory log —
//! are run, one thread, one after another, so that decision times are one
//! thread's and episodes pair across models. Writes
//! - `plan.parquet`: per task, model, planner, budget, episode and frame,
//!   the torques executed, the task's cost of the frame reached, the cost
//!   the planner predicted for its plan and the spread of its candidates'
//!   predicted costs (0: the model cannot tell torques apart), and the task's variables in the
//!   frame reached beside those its model predicted for the torques chosen;
//! - `planning.parquet`: per task, model, planner, budget and episode, the
//!   summed cost, the evaluations per decision, the decision time in ms
//!   (median and range over the episode's decisions — measured, the one
//!   thing that differs between equal runs) and real time (the simulated
//!   time a decision stands for: one frame), the model's one-step error on
//!   the task's variables over the episode, and what the episode came to in
//!   the task's physical unit (steady-state error, time to settle, fraction
//!   of frames within the task's tolerance);
//! - `transitions.parquet` and `transitions-nominal.parquet`: every frame
//!   the ALN's planners executed, as training pairs, and the scene as
//!   written's prediction of each ([`transitions`]) — a next round's data;
//! - `episodes.mcap`: the first `view_episodes` episodes of every policy as
//!   a trajectory log (`/state`, and `/tf` and `/scene` to watch them in
//!   Foxglove), one run each, an `alnlab.plan.episode` metadata record per
//!   run saying which.

pub mod controls;
pub mod episode;
pub mod feedback;
pub mod forward;
pub mod planner;
pub mod planning;
pub mod task;
pub mod transitions;

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use alnlab_aln::ModelKind;
use alnlab_aln::linear::Linear;
use alnlab_aln::model::Base;
use alnlab_aln::pwl::predict::Predictor;
use alnlab_aln::runtime::Trained;
use alnlab_common::hash::mix_seed;
use alnlab_common::params::{self, Count, Fraction, ParamError};
use alnlab_common::state_log::{StateFrame, StateLayout, StateLogWriter};
use alnlab_common::table;
use alnlab_common::{Error, PolicyId, Progress, Provenance, Result};
use alnlab_physics::dynamics::{Kinematics, State};
use alnlab_physics::replay::SceneReplay;
use alnlab_physics::{Prepared, Runner, Scene, foxglove, state_from_generalized};
use alnlab_tables::levels::Levels;
use alnlab_tables::pairs::Side;
use arrow_array::builder::{ListBuilder, StringBuilder};
use arrow_array::types::Float64Type;
use arrow_array::{Array, Float64Array, ListArray, StringArray, UInt32Array};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::controls::Controls;
use crate::episode::Policy;
use crate::feedback::{Feedback, Law};
use crate::forward::{Hybrid, Learned, LinearStep, Model, Piecewise, Simulator};
use crate::planner::{Bounds, CemSettings, Planner, PlannerKind};
use crate::task::{Cost, Task};
use crate::transitions::Transitions;

/// Version of what this stage writes (part of every cache key; 4: the
/// spread of predicted costs; 5: robots, plants and hybrids, the ALN's
/// planned frames as pairs; 6: each model's error over the horizon on its
/// planner's states; 7: frames as the log records them, the plant's
/// actuators given each decision's torques from its first step; 8: the
/// simulator costs a decision's candidates together in SIMD lanes, which
/// round differently; 9: joint limits sized on what the joint moves; 10:
/// implicit drives, batched implicitly, mimic joints; 11: the plant's own
/// simulator predicts its mean, in SIMD lanes, time going on from frame to
/// frame; 12: each episode's steady-state error, time to settle and frames
/// within tolerance, and the PD and PID loops on gravity compensation).
pub const FORMAT_VERSION: u32 = 12;
/// File name of the per-frame table.
pub const PLAN_FILE: &str = "plan.parquet";
/// File name of the per-episode table.
pub const PLANNING_FILE: &str = "planning.parquet";
/// File name of the executed episodes' trajectory log.
pub const EPISODES_FILE: &str = "episodes.mcap";
/// Name of the metadata record that says which policy and episode a run of
/// `episodes.mcap` is.
pub const EPISODE_RECORD: &str = "alnlab.plan.episode";

/// A forward model learned from the data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LearnedKind {
    /// The trained model of the train stage.
    Aln,
    /// The linear baseline, fitted on the training rows.
    Linear,
}

/// The `[plan]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// The tasks (`[[plan.task]]`); none: the stage plans nothing and
    /// writes empty tables.
    pub task: Vec<Task>,
    /// The scene of the trajectory log to control (default: its first).
    pub scene: Option<String>,
    /// The planners.
    pub planners: Vec<PlannerKind>,
    /// The learned forward models.
    pub models: Vec<LearnedKind>,
    /// The simulator as forward model at these integration steps per frame:
    /// the scene as written (without a plant, the scene's own step count
    /// is the true model; with one, the nominal model a user has).
    pub simulator_steps: Vec<Count>,
    /// A plant's own simulator as forward model at these steps per frame
    /// (`plant@k`): the reference no user has, the plant's actuators
    /// started at rest at each decision. Only for a scene with a plant.
    pub plant_steps: Vec<Count>,
    /// Frames a plan looks ahead.
    pub horizon: Count,
    /// Candidate sequences per decision, each budget in turn (a decision
    /// costs budget × horizon model evaluations): each budget a point of a
    /// model's frontier of cost against time.
    pub budgets: Vec<Count>,
    /// The simulators' budgets (`simulator@k`, `plant@k`), where they
    /// differ from `budgets`: a simulator's decision costs many times a
    /// learned model's, and its frontier may stop sooner.
    pub simulator_budgets: Option<Vec<Count>>,
    /// Episodes per task, each from another logged state.
    pub episodes: Count,
    /// Frames per episode (one decision each).
    pub frames: Count,
    /// The cross-entropy method's rounds per decision.
    pub cem_iterations: Count,
    /// … and the fraction of a round's sequences it refits to.
    pub cem_elite: Fraction,
    /// Episodes per policy written to `episodes.mcap` (the first ones).
    pub view_episodes: usize,
    /// Rounds of the planner's own data (DAgger for models): after each,
    /// the frames the ALN's planners executed join the training rows, the
    /// learned models are trained again and plan the same episodes (the
    /// pipeline runs them; 0: none).
    pub rounds: usize,
    /// The PD and PID loops on the nominal model's gravity compensation
    /// (`gravity-pd`, `gravity-pid`: references for a robot's hold-angles
    /// tasks, [`feedback`]), each at the one of these natural frequencies
    /// (rad/s) of the lowest mean cost over the tuning episodes; none: no
    /// loops.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub feedback_frequencies: Vec<f64>,
    /// Episodes per task the loops' frequencies are tuned on, each from a
    /// logged state no judged episode's start is within an episode's frames
    /// of, in the same run (default: `episodes`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tuning_episodes: Option<Count>,
}

impl Params {
    /// The simulators' budgets: `simulator_budgets`, else `budgets`.
    pub fn simulator_budgets(&self) -> &[Count] {
        self.simulator_budgets.as_deref().unwrap_or(&self.budgets)
    }
}

/// The most rounds of the planner's own data a manifest may ask for.
pub const MOST_ROUNDS: usize = 20;

impl Default for Params {
    fn default() -> Self {
        Params {
            task: Vec::new(),
            scene: None,
            planners: vec![PlannerKind::RandomShooting, PlannerKind::Cem],
            models: vec![LearnedKind::Aln, LearnedKind::Linear],
            simulator_steps: vec![Count(10), Count(2)],
            plant_steps: Vec::new(),
            horizon: Count(10),
            budgets: vec![Count(8), Count(32), Count(128)],
            simulator_budgets: None,
            episodes: Count(3),
            frames: Count(100),
            cem_iterations: Count(3),
            cem_elite: Fraction(0.1),
            view_episodes: 1,
            rounds: 0,
            feedback_frequencies: Vec::new(),
            tuning_episodes: None,
        }
    }
}

impl Params {
    /// Checks the tasks and the lists, and, given the scenes the simulate
    /// stage makes (`None` where an archived dataset holds the data), that
    /// the scene to control is one of them and has every variable a task
    /// names.
    pub fn validate(&self, scenes: Option<&[Scene]>) -> std::result::Result<(), ParamError> {
        let prepared = match scenes {
            Some(scenes) if !self.task.is_empty() => Some(self.prepared(scenes)?),
            _ => None,
        };
        for (i, task) in self.task.iter().enumerate() {
            task.validate()
                .map_err(|(field, m)| (format!("task.{i}.{field}"), m))?;
            if let Some(p) = &prepared {
                task.within(p)
                    .map_err(|(field, m)| (format!("task.{i}.{field}"), m))?;
                task.over(&p.variables.names(), p)
                    .map_err(|m| (format!("task.{i}"), m))?;
            }
            if self.task[..i].iter().any(|t| t.name() == task.name()) {
                return Err((
                    format!("task.{i}.name"),
                    format!("two tasks are named `{}`", task.name()),
                ));
            }
        }
        if !self.task.is_empty() && self.planners.is_empty() {
            return Err(("planners".into(), "expected at least one planner".into()));
        }
        if !self.task.is_empty() && self.budgets.is_empty() {
            return Err(("budgets".into(), "expected at least one budget".into()));
        }
        if self.simulator_budgets.as_ref().is_some_and(Vec::is_empty) {
            return Err((
                "simulator_budgets".into(),
                "expected at least one budget (leave it out for `budgets`)".into(),
            ));
        }
        let field = || "feedback_frequencies".to_string();
        if let Some(w) = self
            .feedback_frequencies
            .iter()
            .find(|w| !(w.is_finite() && **w > 0.0))
        {
            return Err((
                field(),
                format!("expected natural frequencies > 0 (rad/s), found {w}"),
            ));
        }
        if self.feedback_frequencies.is_empty() && self.tuning_episodes.is_some() {
            return Err((
                "tuning_episodes".into(),
                "tunes the feedback loops, which `feedback_frequencies` asks for: give both or \
                 neither"
                    .into(),
            ));
        }
        // A loop holds a hold-angles task of a robot's joints: at least one
        // task must be one (the others run without loops).
        if let Some(p) = prepared
            .as_ref()
            .filter(|_| !self.feedback_frequencies.is_empty())
        {
            let controls = Controls::of(p).map_err(|m| (field(), m))?;
            let built: Vec<_> = self
                .task
                .iter()
                .map(|task| Feedback::new(p, &controls, task, Law::Pd))
                .collect();
            if !built.iter().any(Result::is_ok) {
                let why = built.into_iter().find_map(Result::err).unwrap_or_default();
                return Err((field(), format!("no task takes a feedback loop: {why}")));
            }
        }
        if self.rounds > MOST_ROUNDS {
            return Err((
                "rounds".into(),
                format!("expected at most {MOST_ROUNDS}, found {}", self.rounds),
            ));
        }
        if self.rounds > 0 && (self.task.is_empty() || !self.models.contains(&LearnedKind::Aln)) {
            return Err((
                "rounds".into(),
                "rounds of the planner's own data need a task and the ALN among `models`: \
                 the ALN's planned frames are the data"
                    .into(),
            ));
        }
        Ok(())
    }
}

impl Params {
    /// The scene to control, among `scenes`, as its data are simulated
    /// (with its plant); an error if it is not there, or if `plant_steps`
    /// asks for a plant it does not have.
    fn prepared(&self, scenes: &[Scene]) -> std::result::Result<Prepared, ParamError> {
        let scene = match &self.scene {
            None => scenes.first(),
            Some(name) => scenes.iter().find(|s| &s.name == name),
        };
        let scene = scene.ok_or_else(|| {
            let names: Vec<&str> = scenes.iter().map(|s| s.name.as_str()).collect();
            (
                "scene".to_string(),
                format!(
                    "no scene `{}` is simulated (the scenes are {})",
                    self.scene.as_deref().unwrap_or_default(),
                    names.join(", ")
                ),
            )
        })?;
        if scene.plant.is_none() && !self.plant_steps.is_empty() {
            return Err((
                "plant_steps".to_string(),
                format!(
                    "scene `{}` has no plant: its own simulator is simulator_steps' (give the \
                     scene a [simulate.scene.plant], or leave plant_steps out)",
                    scene.name
                ),
            ));
        }
        Ok(Prepared::new(scene))
    }
}

/// The per-frame rows of `plan.parquet`, column by column.
#[derive(Default)]
struct FrameRows {
    task: Vec<String>,
    model: Vec<PolicyId>,
    planner: Vec<&'static str>,
    budget: Vec<u32>,
    episode: Vec<u32>,
    frame: Vec<u32>,
    torques: Vec<Vec<f64>>,
    cost: Vec<f64>,
    predicted: Vec<f64>,
    spread: Vec<f64>,
    variables: Vec<Vec<String>>,
    reached: Vec<Vec<f64>>,
    expected: Vec<Vec<f64>>,
}

/// Everything the stage writes, filled episode by episode.
struct Outputs<'a> {
    frames: FrameRows,
    episodes: Vec<planning::Episode>,
    view: View,
    /// The ALN's planned frames, for a next round's training.
    transitions: Option<Transitions<'a>>,
}

/// The executed episodes as a trajectory log to watch.
struct View {
    log: StateLogWriter,
    tf: u16,
    scene: u16,
    /// Runs written so far.
    runs: u32,
    log_time_ns: u64,
    frame: StateFrame,
}

impl View {
    fn create(path: &Path, layouts: &[StateLayout]) -> Result<View> {
        let mut log = StateLogWriter::create(path, layouts)?;
        let [tf, scene] = log.add_json_channels(foxglove::channels())?;
        Ok(View {
            log,
            tf,
            scene,
            runs: 0,
            log_time_ns: 0,
            frame: StateFrame::default(),
        })
    }

    /// Starts the next run: its record, the scene's drawing and the start
    /// frame `start`.
    fn start_run(
        &mut self,
        p: &Prepared,
        record: BTreeMap<String, String>,
        start: &State,
    ) -> Result<()> {
        let run = self.runs;
        self.runs += 1;
        let mut record = record;
        record.insert("run".into(), run.to_string());
        self.log.metadata(EPISODE_RECORD, record)?;
        self.log.write_json(
            self.scene,
            self.log_time_ns,
            &foxglove::scene_update(p, run, self.log_time_ns),
        )?;
        let mut runner = Runner::new(p, 0, 0, 0);
        runner.observe(start, 0.0, &mut self.frame);
        self.write(p, 0, runner.kinematics())
    }

    /// Writes frame `index` of the current run (in `self.frame`).
    fn write(&mut self, p: &Prepared, index: u32, kin: &Kinematics) -> Result<()> {
        let run = self.runs - 1;
        self.frame.run = run;
        self.frame.frame = index;
        self.frame.time = f64::from(index) * p.scene.frame_dt.get();
        self.log.write(0, self.log_time_ns, &self.frame)?;
        self.log.write_json(
            self.tf,
            self.log_time_ns,
            &foxglove::transforms(p, run, kin, self.log_time_ns),
        )?;
        self.log_time_ns += (p.scene.frame_dt.get() * 1e9).round() as u64;
        Ok(())
    }
}

/// The files the stage reads.
pub struct Inputs<'a> {
    /// The trajectory log (MCAP): the scene, its plant and start states.
    pub trajectory: &'a Path,
    /// The trained model (`model.aln`).
    pub model: &'a Path,
    /// Its codebook.
    pub codebook: &'a Path,
    /// The levels table it was trained on.
    pub levels: &'a Path,
}

/// Plans every task with every model, planner and budget, and writes the
/// two tables.
pub fn run(
    params: &Params,
    seed: u64,
    inputs: &Inputs,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let Inputs {
        trajectory: trajectory_path,
        model: model_path,
        codebook: codebook_path,
        levels: levels_path,
    } = *inputs;
    params
        .validate(None)
        .map_err(|e| params::invalid("plan", e))?;
    let view_path = out_dir.join(EPISODES_FILE);
    if params.task.is_empty() {
        let out = Outputs {
            frames: FrameRows::default(),
            episodes: Vec::new(),
            view: View::create(&view_path, &[])?,
            transitions: None,
        };
        out.write(out_dir, provenance)
    } else {
        let log = alnlab_common::state_log::read(trajectory_path)?;
        let replays =
            SceneReplay::from_log(&log).map_err(|m| Error::bad_file(trajectory_path, m))?;
        let scene_name = match &params.scene {
            Some(name) => name.clone(),
            None => log
                .scenes
                .first()
                .map(|s| s.layout.scene.clone())
                .ok_or_else(|| Error::bad_file(trajectory_path, "holds no scene"))?,
        };
        let replay = replays.get(&scene_name).ok_or_else(|| {
            Error::Invalid(format!(
                "[plan] scene: the trajectory log has no scene `{scene_name}` (it has {})",
                replays.keys().cloned().collect::<Vec<_>>().join(", ")
            ))
        })?;
        if replay.logged_efforts.is_some() {
            return Err(Error::bad_file(
                trajectory_path,
                format!(
                    "scene `{scene_name}` comes from a recording: planning executes its torques \
                     in the plant the data come from, and a recording has none"
                ),
            ));
        }
        // Episodes execute in the plant (where the scene has one); the
        // simulators a user has run the scene as written.
        let (p, nominal) = (replay.simulated(), &replay.prepared);
        // The plant's own simulator as a forward model predicts its mean
        // response: a draw of its actuators' noise would be another plant's.
        let mean_plant = (!params.plant_steps.is_empty()).then(|| p.without_noise());
        let controls = Controls::of(p).map_err(|m| Error::Invalid(format!("[plan]: {m}")))?;
        let bounds = controls.bounds().clone();
        let mut out = Outputs {
            frames: FrameRows::default(),
            episodes: Vec::new(),
            view: View::create(&view_path, std::slice::from_ref(&p.layout))?,
            transitions: Some(Transitions::new(nominal, &controls)),
        };
        let logged = &log
            .scenes
            .iter()
            .find(|s| s.layout.scene == scene_name)
            .expect("a replay per logged scene")
            .frames;
        let (starts, taken) = start_states(
            p,
            logged,
            params.episodes.get(),
            (seed, EPISODE_STARTS),
            None,
            trajectory_path,
        )?;
        let tuning = match params.feedback_frequencies.is_empty() {
            true => Vec::new(),
            false => {
                let count = params.tuning_episodes.unwrap_or(params.episodes).get();
                let apart = Apart {
                    taken: &taken,
                    frames: params.frames.get() as u32,
                };
                let seed = (seed, TUNING_STARTS);
                start_states(p, logged, count, seed, Some(apart), trajectory_path)?.0
            }
        };
        let trained = Trained::read(model_path, codebook_path)?;
        let levels = Levels::read(levels_path, codebook_path)?;
        let learned: Vec<_> = trained.codebook.learned().collect();
        let train_rows = levels.train_rows();
        let x_train = levels.select(Side::Current, &learned, &train_rows)?;
        let linear = Linear::fit(&x_train, &levels.select(Side::Next, &learned, &train_rows)?);
        let level_counts: Vec<usize> = trained.codecs.iter().map(|c| c.levels()).collect();
        // A piecewise-linear model reads real values; its compiled boxes
        // are cut where the training rows lie (their levels' values: the
        // cuts decide speed, never a prediction).
        // A hybrid's trees read the nominal predictions too, after the
        // state: the state's values stand in for them in the cuts.
        let hybrid = trained.model.header.base == Base::Nominal;
        let inputs = trained.model.header.base.inputs(&learned);
        let piecewise = match trained.model.header.model {
            ModelKind::PiecewiseLinear => true,
            ModelKind::BitForest | ModelKind::Threshold => false,
        };
        let piecewise = piecewise.then(|| {
            let points: Vec<f64> = (0..train_rows.len())
                .flat_map(|r| {
                    inputs
                        .iter()
                        .zip(x_train.iter().cycle())
                        .map(move |(e, column)| e.quantizer.value(usize::from(column[r])))
                })
                .collect();
            Predictor::new(&trained.model.pieces, &trained.reads, &inputs, &points)
        });

        let simulators = params.simulator_steps.len() + params.plant_steps.len();
        let per_task = 2 + params.planners.len()
            * (params.models.len() * params.budgets.len()
                + simulators * params.simulator_budgets().len());
        // The feedback loops' episodes, tuning ones too, of the tasks that
        // take one.
        let held = match params.feedback_frequencies.is_empty() {
            true => 0,
            false => params
                .task
                .iter()
                .filter(|task| Feedback::new(nominal, &controls, task, Law::Pd).is_ok())
                .count(),
        };
        let loop_episodes = Law::ALL.len()
            * (params.episodes.get() + params.feedback_frequencies.len() * tuning.len());
        progress.start(
            "plan",
            (params.task.len() * per_task * params.episodes.get() + held * loop_episodes) as u64,
            "episodes",
        );
        // One thread: decision times are one thread's, whatever the machine.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("a thread pool of one thread");
        let context = Context {
            p,
            controls: &controls,
            params,
            seed,
            progress,
        };
        pool.install(|| -> Result<()> {
            for (t, task) in params.task.iter().enumerate() {
                let cost = task.over(&p.layout.variables, p).map_err(Error::Invalid)?;
                let at = |logged: &[State]| -> Vec<State> {
                    logged.iter().map(|s| task.start_state(p, s)).collect()
                };
                let task_starts = at(&starts);
                let task_run = TaskRun {
                    context: &context,
                    starts: &task_starts,
                    task: task.name(),
                    index: t,
                    variables: cost
                        .variables()
                        .map(|s| p.layout.variables[s].clone())
                        .collect(),
                    cost: &cost,
                };
                task_run.reference(PolicyId::Zero, &mut Policy::Zero, &mut out)?;
                task_run.reference(PolicyId::Random, &mut Policy::Random, &mut out)?;
                // The loops hold the tasks they can (validated: one at least).
                let loops = Law::ALL
                    .iter()
                    .filter(|_| !params.feedback_frequencies.is_empty());
                for &law in loops {
                    if let Ok(held) = Feedback::new(nominal, &controls, task, law) {
                        task_run.feedback(held, &at(&tuning), &mut out)?;
                    }
                }
                for &kind in &params.models {
                    let (name, model): (PolicyId, Box<dyn Model>) = match kind {
                        LearnedKind::Aln => (
                            PolicyId::Aln,
                            match &piecewise {
                                Some(predictor) if hybrid => Box::new(
                                    Hybrid::new(
                                        nominal,
                                        predictor,
                                        &learned,
                                        &controls,
                                        cost.clone(),
                                    )
                                    .map_err(|m| Error::Invalid(format!("[plan] aln: {m}")))?,
                                ),
                                Some(predictor) => Box::new(
                                    Piecewise::new(
                                        predictor,
                                        &learned,
                                        nominal,
                                        &controls,
                                        cost.clone(),
                                    )
                                    .map_err(|m| Error::Invalid(format!("[plan] aln: {m}")))?,
                                ),
                                None => Box::new(
                                    Learned::new(
                                        trained.runtime().map_err(|m| {
                                            Error::Invalid(format!("[plan] aln: {m}"))
                                        })?,
                                        learned.clone(),
                                        nominal,
                                        &controls,
                                        cost.clone(),
                                    )
                                    .map_err(|m| Error::Invalid(format!("[plan] aln: {m}")))?,
                                ),
                            },
                        ),
                        LearnedKind::Linear => (
                            PolicyId::Linear,
                            Box::new(
                                Learned::new(
                                    LinearStep {
                                        linear: &linear,
                                        levels: &level_counts,
                                    },
                                    learned.clone(),
                                    nominal,
                                    &controls,
                                    cost.clone(),
                                )
                                .map_err(|m| Error::Invalid(format!("[plan] linear: {m}")))?,
                            ),
                        ),
                    };
                    task_run.planned(name, model, &bounds, &params.budgets, &mut out)?;
                }
                let budgets = params.simulator_budgets();
                for steps in &params.simulator_steps {
                    let steps = steps.get() as u64;
                    let name = PolicyId::Simulator { steps };
                    let model = Box::new(Simulator::new(nominal, &controls, steps, cost.clone()));
                    task_run.planned(name, model, &bounds, budgets, &mut out)?;
                }
                let plant_steps = mean_plant.iter().flat_map(|plant| {
                    params
                        .plant_steps
                        .iter()
                        .map(move |k| (plant, k.get() as u64))
                });
                for (plant, steps) in plant_steps {
                    let name = PolicyId::Plant { steps };
                    let model = Box::new(Simulator::new(plant, &controls, steps, cost.clone()));
                    task_run.planned(name, model, &bounds, budgets, &mut out)?;
                }
            }
            Ok(())
        })?;
        out.write(out_dir, provenance)
    }
}

impl Outputs<'_> {
    /// Writes every output into `out_dir`.
    fn write(self, out_dir: &Path, provenance: &Provenance) -> Result<()> {
        match &self.transitions {
            Some(t) => t.write(out_dir, provenance)?,
            None => transitions::write_none(out_dir, provenance)?,
        }
        write_frames(&out_dir.join(PLAN_FILE), &self.frames, provenance)?;
        planning::write(&out_dir.join(PLANNING_FILE), &self.episodes, provenance)?;
        self.view.log.finish(provenance)
    }
}

/// What every episode of a run shares.
struct Context<'a> {
    /// The scene episodes execute in: with its plant, if any.
    p: &'a Prepared,
    controls: &'a Controls,
    params: &'a Params,
    seed: u64,
    progress: &'a dyn Progress,
}

/// One task's episodes.
struct TaskRun<'a> {
    context: &'a Context<'a>,
    /// Its episodes' start states: the logged ones, as the task starts
    /// from them ([`Task::start_state`]).
    starts: &'a [State],
    task: &'a str,
    index: usize,
    /// The names of the task's variables, in the order of [`Cost::variables`].
    variables: Vec<String>,
    cost: &'a Cost,
}

impl TaskRun<'_> {
    /// Every episode under a reference policy.
    fn reference(&self, name: PolicyId, policy: &mut Policy, out: &mut Outputs) -> Result<()> {
        for e in 0..self.starts.len() {
            self.episode(name, "", 0, e, policy, out)?;
        }
        Ok(())
    }

    /// The loop's frequency picked by the lowest mean cost over the
    /// `tuning` episodes (a frequency whose episode blows up is not
    /// picked; an error if every one does), then every episode with it.
    fn feedback(&self, mut held: Feedback, tuning: &[State], out: &mut Outputs) -> Result<()> {
        let c = self.context;
        let mut best: Option<(f64, f64)> = None;
        for &omega in &c.params.feedback_frequencies {
            held.tune(omega);
            let mut policy = Policy::Feedback(held.clone());
            let mut total = 0.0;
            for (e, start) in tuning.iter().enumerate() {
                let seed = mix_seed(c.seed, TUNING_EPISODES ^ e as u64);
                let frames = c.params.frames.get() as u32;
                let ran = episode::run(
                    c.p,
                    c.controls,
                    start,
                    frames,
                    0,
                    self.cost,
                    &mut policy,
                    seed,
                    |_, _, _, _| Ok(()),
                );
                c.progress.advance(1);
                match ran {
                    Ok(outcome) => total += outcome.cost,
                    Err(Error::Diverged(_)) => total = f64::INFINITY,
                    Err(e) => return Err(e),
                }
            }
            let mean = total / tuning.len() as f64;
            if mean.is_finite() && best.is_none_or(|(lowest, _)| mean < lowest) {
                best = Some((mean, omega));
            }
        }
        let name = held.law().policy();
        let Some((_, omega)) = best else {
            return Err(Error::Diverged(format!(
                "task `{}`: {name} blew up at every frequency of `feedback_frequencies` on its \
                 tuning episodes",
                self.task
            )));
        };
        held.tune(omega);
        let mut policy = Policy::Feedback(held);
        for e in 0..self.starts.len() {
            self.episode(name, "", 0, e, &mut policy, out)?;
        }
        Ok(())
    }

    /// Every episode with `model`, for every planner and each of `budgets`.
    fn planned(
        &self,
        name: PolicyId,
        mut model: Box<dyn Model + '_>,
        bounds: &Bounds,
        budgets: &[Count],
        out: &mut Outputs,
    ) -> Result<()> {
        let params = self.context.params;
        let cem = CemSettings {
            iterations: params.cem_iterations.get(),
            elite: params.cem_elite.get(),
        };
        for &kind in &params.planners {
            for budget in budgets {
                for e in 0..self.starts.len() {
                    let seed = mix_seed(
                        self.context.seed,
                        (self.index as u64) << 40 ^ (budget.get() as u64) << 20 ^ e as u64,
                    );
                    let mut planner = Planner::new(
                        kind,
                        cem,
                        params.horizon.get(),
                        bounds.clone(),
                        budget.get(),
                        seed,
                    );
                    let mut policy = Policy::Plan {
                        planner: &mut planner,
                        model: &mut *model,
                        sequences: budget.get(),
                    };
                    self.episode(name, kind.name(), budget.get() as u32, e, &mut policy, out)?;
                }
            }
        }
        Ok(())
    }

    /// One episode from start state `e`, recorded.
    fn episode(
        &self,
        model: PolicyId,
        planner: &'static str,
        budget: u32,
        e: usize,
        policy: &mut Policy,
        out: &mut Outputs,
    ) -> Result<()> {
        let c = self.context;
        let mut times = Vec::with_capacity(c.params.frames.get());
        let mut squared_error = 0.0;
        let seed = mix_seed(c.seed, e as u64);
        let viewed = e < c.params.view_episodes;
        if viewed {
            let record = BTreeMap::from([
                ("task".to_string(), self.task.to_string()),
                ("model".to_string(), model.to_string()),
                ("planner".to_string(), planner.to_string()),
                ("budget".to_string(), budget.to_string()),
                ("episode".to_string(), e.to_string()),
            ]);
            out.view.start_run(c.p, record, &self.starts[e])?;
        }
        // The ALN's planned frames are the next round's training pairs, each
        // frame as the log records it (under the torques applied from it
        // on), so a pair is complete once the next frame's are chosen.
        let mut recorded = match &mut out.transitions {
            Some(t) if model == PolicyId::Aln && !planner.is_empty() => {
                t.start_episode();
                Some((t, None::<(StateFrame, Vec<f64>)>))
            }
            _ => None,
        };
        let Outputs { frames, view, .. } = out;
        let outcome = episode::run(
            c.p,
            c.controls,
            &self.starts[e],
            c.params.frames.get() as u32,
            c.params.horizon.get(),
            self.cost,
            policy,
            seed,
            |step, frame, applied, kin| {
                frames.task.push(self.task.to_string());
                frames.model.push(model);
                frames.planner.push(planner);
                frames.budget.push(budget);
                frames.episode.push(e as u32);
                frames.frame.push(step.frame);
                frames.torques.push(step.torques.clone());
                frames.cost.push(step.cost);
                frames.predicted.push(step.predicted);
                frames.spread.push(step.spread);
                frames.variables.push(self.variables.clone());
                frames.reached.push(step.reached.clone());
                frames.expected.push(step.expected.clone());
                squared_error += self.cost.distance(&step.expected, &step.reached).powi(2);
                if let Some((transitions, before)) = &mut recorded {
                    match before {
                        Some((x, torques)) => {
                            transitions.record(
                                step.frame - 2,
                                x,
                                applied,
                                torques,
                                &step.torques,
                            )?;
                            x.clone_from(applied);
                            torques.clone_from(&step.torques);
                        }
                        None => *before = Some((applied.clone(), step.torques.clone())),
                    }
                }
                times.push(step.seconds * 1e3);
                if viewed {
                    view.frame.clone_from(frame);
                    view.write(c.p, step.frame, kin)?;
                }
                Ok(())
            },
        )
        .map_err(|err| {
            err.context(&format!(
                "task `{}`, {model} {planner} budget {budget}, episode {e}",
                self.task
            ))
        })?;
        times.sort_by(f64::total_cmp);
        let (ms_per_decision, ms_min, ms_max) = match times.as_slice() {
            [] => (0.0, 0.0, 0.0),
            t => (t[t.len() / 2], t[0], t[t.len() - 1]),
        };
        let frames_run = c.params.frames.get() as f64;
        let feedback_frequency = match policy {
            Policy::Feedback(held) => held.omega(),
            _ => f64::NAN,
        };
        out.episodes.push(planning::Episode {
            task: self.task.to_string(),
            model,
            round: 0,
            planner: planner.to_string(),
            budget,
            episode: e as u32,
            evaluations: u64::from(budget) * c.params.horizon.get() as u64,
            cost: outcome.cost,
            ms_per_decision,
            ms_min,
            ms_max,
            real_time_ms: c.p.scene.frame_dt.get() * 1e3,
            prediction_rms: (squared_error / frames_run).sqrt(),
            horizon_rms: outcome.horizon_rms,
            final_error: outcome.settling.final_error,
            settle_s: outcome.settling.settle_s,
            within_tolerance: outcome.settling.within,
            feedback_frequency,
        });
        c.progress.advance(1);
        Ok(())
    }
}

/// The stream of random numbers the judged episodes' start states are
/// drawn from …
const EPISODE_STARTS: u64 = 0x504C_414E;
/// … the feedback loops' tuning episodes' …
const TUNING_STARTS: u64 = 0x5455_4E45 << 32;
/// … and the seeds of those episodes (a plant's actuator noise).
const TUNING_EPISODES: u64 = (0x5455_4E45 << 32) | 1 << 31;

/// The judged episodes' start states (indices of logged frames) that other
/// episodes keep away from: none starts within `frames` frames of one of
/// them in the same run, so no tuning episode retraces a judged one.
struct Apart<'a> {
    taken: &'a [usize],
    frames: u32,
}

/// `count` episodes' start states, and the indices of the logged frames
/// they are: frames drawn from the scene's runs with the random numbers of
/// `(seed, stream)` — with `apart`, each a frame of its own, away from the
/// judged ones.
fn start_states(
    p: &Prepared,
    logged: &[StateFrame],
    count: usize,
    (seed, stream): (u64, u64),
    apart: Option<Apart>,
    path: &Path,
) -> Result<(Vec<State>, Vec<usize>)> {
    if logged.is_empty() {
        return Err(Error::bad_file(
            path,
            format!("scene `{}` has no frames", p.scene.name),
        ));
    }
    let away = |index: usize| {
        let here = &logged[index];
        apart.as_ref().is_none_or(|a| {
            a.taken.iter().all(|&t| {
                logged[t].run != here.run || logged[t].frame.abs_diff(here.frame) > a.frames
            })
        })
    };
    let free = (0..logged.len()).filter(|&i| away(i)).count();
    if apart.is_some() && free < count {
        return Err(Error::bad_file(
            path,
            format!(
                "scene `{}` has {free} frames away from the judged episodes' starts, fewer than \
                 the {count} tuning episodes to start from them",
                p.scene.name
            ),
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, stream));
    let mut taken = Vec::with_capacity(count);
    while taken.len() < count {
        let index = rng.random_range(0..logged.len());
        if away(index) && !(apart.is_some() && taken.contains(&index)) {
            taken.push(index);
        }
    }
    let states = taken
        .iter()
        .map(|&index| {
            let frame = &logged[index];
            state_from_generalized(&p.model, &frame.state).ok_or_else(|| {
                Error::bad_file(
                    path,
                    format!(
                        "scene `{}`, run {}, frame {}: the state does not fit the model",
                        p.scene.name, frame.run, frame.frame
                    ),
                )
            })
        })
        .collect::<Result<_>>()?;
    Ok((states, taken))
}

fn write_frames(path: &Path, rows: &FrameRows, provenance: &Provenance) -> Result<()> {
    let batch = table::batch(vec![
        (
            "task",
            Arc::new(StringArray::from_iter_values(&rows.task)) as Arc<dyn Array>,
        ),
        (
            "model",
            Arc::new(StringArray::from_iter_values(
                rows.model.iter().map(PolicyId::to_string),
            )),
        ),
        (
            "planner",
            Arc::new(StringArray::from_iter_values(&rows.planner)),
        ),
        ("budget", Arc::new(UInt32Array::from(rows.budget.clone()))),
        ("episode", Arc::new(UInt32Array::from(rows.episode.clone()))),
        ("frame", Arc::new(UInt32Array::from(rows.frame.clone()))),
        ("torques", Arc::new(f64_lists(&rows.torques))),
        ("cost", Arc::new(Float64Array::from(rows.cost.clone()))),
        (
            "predicted",
            Arc::new(Float64Array::from(rows.predicted.clone())),
        ),
        (
            "predicted_spread",
            Arc::new(Float64Array::from(rows.spread.clone())),
        ),
        ("variables", Arc::new(string_lists(&rows.variables))),
        ("reached", Arc::new(f64_lists(&rows.reached))),
        ("expected", Arc::new(f64_lists(&rows.expected))),
    ]);
    table::write_parquet(path, &batch, provenance)
}

fn f64_lists(rows: &[Vec<f64>]) -> ListArray {
    ListArray::from_iter_primitive::<Float64Type, _, _>(
        rows.iter().map(|t| Some(t.iter().map(|&x| Some(x)))),
    )
}

fn string_lists(rows: &[Vec<String>]) -> ListArray {
    let mut lists = ListBuilder::new(StringBuilder::new());
    for row in rows {
        for s in row {
            lists.values().append_value(s);
        }
        lists.append(true);
    }
    lists.finish()
}
