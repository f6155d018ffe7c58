//! A run's scene in Python: `Scene(trajectory_path, scene=None,
//! plant=False)` rebuilt from its trajectory log (the nominal model as
//! written, or the plant where the scene declares one), its logged frames,
//! and `step`: many states advanced under torques held over the frames —
//! the simulator the test and plan stages compare the ALN with.

use std::path::PathBuf;

use alnlab_common::Error;
use alnlab_common::state_log::StateFrame;
use alnlab_physics::replay::SceneReplay;
use alnlab_physics::runner::Control;
use alnlab_physics::{Prepared, Runner, state_from_generalized};
use nalgebra::Vector3;
use numpy::ndarray::{Array1, Array2, ArrayView2, Ix2};
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::model::thread_count;
use crate::{arrays, invalid, raise, threads};

/// States a parallel task of [`Scene::step`] takes.
const TASK_ROWS: usize = 16;

/// A scene of a run, ready to step.
#[pyclass(module = "alnlab._alnlab", frozen)]
pub struct Scene {
    prepared: Prepared,
    plant: bool,
    controls: Vec<Control>,
    /// The log's frames of this scene.
    frames: Vec<StateFrame>,
    /// The experiment seed and the scene's index: what a runner's
    /// controller and noise are seeded from.
    seed: u64,
    index: usize,
}

/// A row of a NumPy array per state, and what was asked of it.
struct Rows {
    values: Vec<f64>,
    width: usize,
}

impl Rows {
    fn of(array: &ArrayView2<f64>) -> Rows {
        Rows {
            values: array.iter().copied().collect(),
            width: array.ncols(),
        }
    }

    fn row(&self, r: usize) -> &[f64] {
        &self.values[r * self.width..(r + 1) * self.width]
    }
}

impl Scene {
    fn state_width(&self) -> usize {
        self.prepared.layout.state.len()
    }

    /// One state stepped `frames` frames of `steps` steps under `torques`
    /// (one per control) into `out_state` and `out_variables`; NaN where
    /// it left the finite numbers. `runner` starts afresh for it.
    #[allow(clippy::too_many_arguments)]
    fn step_one(
        &self,
        runner: &mut Runner,
        start: &[f64],
        torques: &[f64],
        frames: u32,
        steps: u64,
        out_state: &mut [f64],
        out_variables: &mut [f64],
    ) -> Result<(), u64> {
        let p = &self.prepared;
        let mut state = state_from_generalized(&p.model, start).expect("checked to fit");
        runner.restart();
        let mut g = vec![Vector3::zeros(); p.model.len() - 1];
        for (c, &t) in self.controls.iter().zip(torques) {
            g[c.hinge][c.axis] = t;
        }
        runner.drive(Some(&g));
        let dt = p.scene.step_dt(steps);
        let mut first = 0;
        for _ in 0..frames {
            if let Err(step) = runner.advance(&mut state, first, steps, dt) {
                out_state.fill(f64::NAN);
                out_variables.fill(f64::NAN);
                return Err(step);
            }
            first += steps;
        }
        let mut frame = StateFrame::default();
        runner.observe(&state, 0.0, &mut frame);
        out_state.copy_from_slice(&frame.state);
        out_variables.copy_from_slice(&frame.variables);
        Ok(())
    }
}

#[pymethods]
impl Scene {
    /// Rebuilds scene `scene` (the log's only one by default) of the
    /// trajectory log `trajectory_path` (a run's `trajectory.mcap`): the
    /// model as written — the simulator a user has — or, with `plant`,
    /// the plant it was simulated as, where the scene declares one.
    #[new]
    #[pyo3(signature = (trajectory_path, scene = None, *, plant = false))]
    fn new(trajectory_path: PathBuf, scene: Option<&str>, plant: bool) -> PyResult<Scene> {
        let path = &trajectory_path;
        let log = alnlab_common::state_log::read(path).map_err(raise)?;
        let mut replays =
            SceneReplay::from_log(&log).map_err(|m| raise(Error::bad_file(path, m)))?;
        let names: Vec<String> = replays.keys().cloned().collect();
        let name = match (scene, names.as_slice()) {
            (Some(name), _) => name.to_string(),
            (None, [one]) => one.clone(),
            (None, _) => {
                return Err(invalid(format!(
                    "{}: holds scenes {}: name one (scene=)",
                    path.display(),
                    names.join(", ")
                )));
            }
        };
        let replay = replays.remove(&name).ok_or_else(|| {
            invalid(format!(
                "{}: has no scene `{name}`; it has {}",
                path.display(),
                names.join(", ")
            ))
        })?;
        let (index, seed) = (replay.index, replay.seed);
        let prepared = match (plant, replay.plant) {
            (false, _) => replay.prepared,
            (true, Some(plant)) => plant,
            (true, None) => {
                return Err(invalid(format!(
                    "{}: scene `{name}` declares no plant: its model as written is what was \
                     simulated (plant=False)",
                    path.display()
                )));
            }
        };
        let frames = log
            .scenes
            .into_iter()
            .find(|s| s.layout.scene == name)
            .map(|s| s.frames)
            .unwrap_or_default();
        Ok(Scene {
            controls: prepared.controls(),
            prepared,
            plant,
            frames,
            seed,
            index,
        })
    }

    /// The scene's name.
    #[getter]
    fn name(&self) -> String {
        self.prepared.scene.name.clone()
    }

    /// Whether this is the scene's plant rather than its model as written.
    #[getter]
    fn plant(&self) -> bool {
        self.plant
    }

    /// The generalized state's components (S), in the columns' order: the
    /// root's position (and velocity, if free), each ball hinge's
    /// orientation and rates, each one-DOF joint's position and velocity,
    /// then its passive (and, where logged, applied) effort.
    #[getter]
    fn state_names(&self) -> Vec<String> {
        self.prepared.layout.state.clone()
    }

    /// The variables (V) a step reads, in the columns' order: the names a
    /// model's `state_names` and `control_names` use.
    #[getter]
    fn variable_names(&self) -> Vec<String> {
        self.prepared.layout.variables.clone()
    }

    /// The controls (U): each ball hinge's torque about its axes
    /// (`g.<link>.x|y|z`), each robot joint's effort (`tau.<joint>`).
    #[getter]
    fn control_names(&self) -> Vec<String> {
        self.controls.iter().map(|c| c.name.clone()).collect()
    }

    /// Seconds per frame, and integration steps per frame as simulated.
    #[getter]
    fn frame_dt(&self) -> f64 {
        self.prepared.scene.frame_dt.get()
    }

    /// Integration steps per frame as the scene was simulated.
    #[getter]
    fn steps_per_frame(&self) -> u64 {
        self.prepared.scene.steps_per_frame()
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({}{}, {} state components, {} variables, {} controls)",
            self.prepared.scene.name,
            if self.plant { ", plant" } else { "" },
            self.state_width(),
            self.prepared.layout.variables.len(),
            self.controls.len()
        )
    }

    /// The log's frames of this scene: (runs F, frames F, states F×S,
    /// variables F×V), runs one after another.
    #[allow(clippy::type_complexity)]
    fn logged<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray1<u32>>,
        Bound<'py, PyArray1<u32>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
    )> {
        let n = self.frames.len();
        let (s, v) = (self.state_width(), self.prepared.layout.variables.len());
        let shaped = |e: numpy::ndarray::ShapeError| invalid(format!("internal shape error: {e}"));
        let runs = Array1::from_iter(self.frames.iter().map(|f| f.run));
        let frames = Array1::from_iter(self.frames.iter().map(|f| f.frame));
        let states = Array2::from_shape_vec(
            (n, s),
            self.frames
                .iter()
                .flat_map(|f| f.state.iter().copied())
                .collect(),
        )
        .map_err(shaped)?;
        let variables = Array2::from_shape_vec(
            (n, v),
            self.frames
                .iter()
                .flat_map(|f| f.variables.iter().copied())
                .collect(),
        )
        .map_err(shaped)?;
        Ok((
            runs.into_pyarray(py),
            frames.into_pyarray(py),
            states.into_pyarray(py),
            variables.into_pyarray(py),
        ))
    }

    /// Each of `states` (B×S) advanced `frames` frames under `controls`
    /// (B×U, held), at `steps` integration steps a frame (the scene's own
    /// by default; fewer is a cheaper simulator): the states (B×S) and
    /// their variables (B×V) after; one state (S) and its controls (U)
    /// give one of each. Any array-like of real numbers. A row that is not
    /// a state (not finite, or an orientation that is no unit quaternion)
    /// is an `InputError` naming it; so is a state that leaves the finite
    /// numbers, unless `allow_nan` (a planner's candidate that blew up
    /// comes back as NaN). Each state steps on its own, as the
    /// test stage's simulator does, from rest of whatever the scene tracks
    /// besides the state (a plant's actuators' lag and delay start at rest,
    /// so a plant stepped from mid-run does not reproduce its run); the
    /// states are split among threads.
    #[pyo3(signature = (states, controls, *, frames = None, steps = None, threads = None, allow_nan = false))]
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
        controls: &Bound<'py, PyAny>,
        frames: Option<&Bound<'py, PyAny>>,
        steps: Option<&Bound<'py, PyAny>>,
        threads: Option<&Bound<'py, PyAny>>,
        allow_nan: bool,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let (s, u) = (self.state_width(), self.controls.len());
        let states = arrays::floats(states, "states", 2, || format!("(B, {s})"))?;
        let controls = arrays::floats(controls, "controls", 2, || format!("(B, {u})"))?;
        let frames = match arrays::count(frames, "frames", 1)? {
            None => 1,
            Some(n) => u32::try_from(n).map_err(|_| invalid(format!("frames: {n} is too many")))?,
        };
        let steps = arrays::count(steps, "steps", 1)?;
        let threads = thread_count(threads)?;
        let single = states.single;
        let (x, c) = (states.view::<Ix2>()?, controls.view::<Ix2>()?);
        let b = x.nrows();
        // Shapes and rows as the caller wrote them: one item, no batch.
        let batch = if single {
            String::new()
        } else {
            format!("{b}, ")
        };
        // "states: row 3 is not finite", or of one state "states: not
        // finite".
        let row_is = |r: usize| match single {
            true => String::new(),
            false => format!("row {r} is "),
        };
        let controls_single = controls.single;
        if x.ncols() != s {
            return Err(invalid(format!(
                "states: expected shape ({}{s}{}), a value per state component ({}), got {}",
                if single { "" } else { "B, " },
                if single { "," } else { "" },
                self.prepared.layout.state.join(", "),
                arrays::tuple(x.shape(), single)
            )));
        }
        if c.dim() != (b, u) {
            return Err(invalid(format!(
                "controls: expected shape ({batch}{u}{}), a value per control ({}), got {}",
                if single { "," } else { "" },
                self.control_names().join(", "),
                arrays::tuple(c.shape(), controls_single)
            )));
        }
        let steps = steps.unwrap_or_else(|| self.steps_per_frame());
        let (x, c) = (Rows::of(&x), Rows::of(&c));
        for r in 0..b {
            let row = x.row(r);
            let state = match row.iter().all(|v| v.is_finite()) {
                true => state_from_generalized(&self.prepared.model, row),
                false => None,
            };
            let Some(state) = state else {
                return Err(invalid(format!("states: {}not finite", row_is(r))));
            };
            // Loose enough for a float32 state of unit quaternions.
            if let Some((i, q)) = state
                .orient
                .iter()
                .enumerate()
                .find(|(_, q)| (q.as_ref().norm() - 1.0).abs() > 1e-3)
            {
                return Err(invalid(format!(
                    "states: {}not a state: link {}'s orientation is no unit quaternion \
                     (norm {:.3e})",
                    row_is(r),
                    i + 1,
                    q.as_ref().norm()
                )));
            }
            if let Some(k) = c.row(r).iter().position(|v| !v.is_finite()) {
                return Err(invalid(format!(
                    "controls: not a finite number at index {} (`{}`)",
                    arrays::tuple(&[r, k], controls_single),
                    self.controls[k].name
                )));
            }
        }
        let v = self.prepared.layout.variables.len();
        let (mut out_states, mut out_variables) = (vec![0.0; b * s], vec![0.0; b * v]);
        // Each row's step (counted from the call's first) that left the
        // finite numbers, if one did.
        let mut failed: Vec<Option<u64>> = vec![None; b];
        py.detach(|| {
            threads::run(threads, || {
                // Tasks of a fixed size, each with a runner of its own,
                // restarted for every state: the same numbers on any
                // number of threads.
                out_states
                    .par_chunks_mut(s * TASK_ROWS)
                    .zip(out_variables.par_chunks_mut(v * TASK_ROWS))
                    .zip(failed.par_chunks_mut(TASK_ROWS))
                    .enumerate()
                    .for_each(|(t, ((states, variables), failed))| {
                        let p = &self.prepared;
                        let mut runner = Runner::new(p, self.seed, self.index, 0);
                        for (k, ((state, variables), failed)) in states
                            .chunks_mut(s)
                            .zip(variables.chunks_mut(v))
                            .zip(failed.iter_mut())
                            .enumerate()
                        {
                            let r = t * TASK_ROWS + k;
                            *failed = self
                                .step_one(
                                    &mut runner,
                                    x.row(r),
                                    c.row(r),
                                    frames,
                                    steps,
                                    state,
                                    variables,
                                )
                                .err();
                        }
                    });
            })
        })?;
        // A result that is not a number is an error, not a value: the step
        // that left the finite numbers where the simulator saw it, else
        // the observation (an acceleration) that did.
        let left = out_states
            .chunks(s.max(1))
            .zip(out_variables.chunks(v.max(1)))
            .position(|(x, y)| x.iter().chain(y).any(|z| !z.is_finite()));
        if let Some(r) = left.filter(|_| !allow_nan) {
            // The runner counts steps from 1.
            let when = match failed[r] {
                Some(step) => format!(
                    "at step {step} of {} ({steps} a frame)",
                    u64::from(frames) * steps,
                ),
                None => format!("in its observation after {frames} frame(s)"),
            };
            return Err(invalid(format!(
                "states: {}left the finite numbers {when}: the simulator cannot step it (a state \
                 far outside what the scene can reach, or controls too large for its step; \
                 allow_nan=True returns NaN instead)",
                match single {
                    true => String::new(),
                    false => format!("row {r} "),
                }
            )));
        }
        let shaped = |e: numpy::ndarray::ShapeError| invalid(format!("internal shape error: {e}"));
        let states = Array2::from_shape_vec((b, s), out_states)
            .map_err(shaped)?
            .into_pyarray(py)
            .into_any();
        let variables = Array2::from_shape_vec((b, v), out_variables)
            .map_err(shaped)?
            .into_pyarray(py)
            .into_any();
        Ok((unbatched(states, single)?, unbatched(variables, single)?))
    }
}

/// `out`'s one item where the call was given one item, not a batch.
fn unbatched<'py>(out: Bound<'py, PyAny>, single: bool) -> PyResult<Bound<'py, PyAny>> {
    match single {
        true => out.get_item(0),
        false => Ok(out),
    }
}
