//! Every model the test stage compares, behind one trait ([`Compared`]):
//! its name in every table ([`ModelId`]), its next levels on every test
//! row, the evaluation paths it is timed on, and its closed loop. The
//! stage makes the list ([`crate::run`]) and treats every entry alike, so
//! a new model is one implementation and one line where the list is made.
//!
//! The forms: [`Persistence`]; the trained bit model ([`BitAln`]); a model
//! of the dynamics from the current real values ([`Dynamics`]: a
//! piecewise-linear ALN, the robust linear fit, boosted trees); a hybrid,
//! the nominal simulator's prediction plus a learned correction
//! ([`Hybrid`]: an ALN trained as one, `linear+nominal`,
//! `boosted+nominal`); and the simulator re-stepping each logged frame
//! ([`Simulator`]).

use std::collections::BTreeMap;

use alnlab_aln::pwl::predict::{Path as Evaluation, Predictor};
use alnlab_aln::runtime::Runtime;
use alnlab_codes::Entry;
use alnlab_common::{ModelId, Result};
use alnlab_physics::replay::SceneReplay;

use crate::hybrid::{self, Restep};
use crate::peer::Peer;
use crate::resimulate::{self, Resimulated};
use crate::rollout::{self, LoggedFrames, Start};
use crate::timing::{self, Path};
use crate::{TestRows, pick, piecewise, predict};

/// LevelColumns `[variable][row]`.
pub type LevelColumns = Vec<Vec<u16>>;

/// What a model compared in the test stage does.
pub trait Compared {
    /// Its name in every table.
    fn id(&self) -> ModelId;

    /// The next level of each scored variable on every test row,
    /// `[variable][test row]`, the same on every evaluation path.
    fn one_step(&self, set: &TestSet) -> Result<LevelColumns>;

    /// Its evaluation paths to time: all test rows at once, one at a time
    /// (none for a model that computes nothing).
    fn paths<'s>(&'s self, set: &'s TestSet<'s>) -> Vec<Path<'s>>;

    /// Fed its own predictions for `run.horizon` frames from each of the
    /// closed loop's starts: the scored variables' levels after each step,
    /// `[step][variable][start]`; `None` where it has no closed loop (a
    /// hybrid on a scene whose state is not made of predicted variables).
    fn closed_loop(&self, set: &TestSet, run: &mut ClosedLoop)
    -> Result<Option<Vec<LevelColumns>>>;
}

/// The test rows every model predicts, in every form a model reads them.
pub struct TestSet<'a> {
    pub learned: &'a [&'a Entry],
    /// The variables scored (indices among `learned`).
    pub scored: &'a [usize],
    pub test: &'a TestRows,
    /// Every pair's current real values `[variable][pair]`.
    pub x: &'a [Vec<f64>],
    /// The test rows' real values: columns `[variable][test row]`, and
    /// rows of `learned.len()` values.
    pub columns: &'a [&'a [f64]],
    pub states: &'a [f64],
    /// Every pair's nominal prediction `[variable][pair]`, and a hybrid's
    /// inputs (the current values, then the nominal prediction; empty
    /// where no model compared is a hybrid).
    pub nominal: &'a [Vec<f64>],
    pub hybrid_x: &'a [Vec<f64>],
    /// The same on the test rows, as columns and rows.
    pub nominal_columns: &'a [&'a [f64]],
    pub nominal_states: &'a [f64],
    pub hybrid_columns: &'a [&'a [f64]],
    pub hybrid_states: &'a [f64],
    /// The trajectory log's frames, the scenes' simulators, and where each
    /// test row's frame is.
    pub frames: &'a LoggedFrames<'a>,
    pub replays: &'a BTreeMap<String, SceneReplay>,
    pub starts: &'a [Start<'a>],
    /// One thread: every model is timed on one.
    pub pool: &'a rayon::ThreadPool,
}

impl TestSet<'_> {
    /// The scored variables of levels of every learned variable, each
    /// step of a closed loop.
    pub fn scored_of(&self, levels: Vec<LevelColumns>) -> Vec<LevelColumns> {
        levels.iter().map(|h| pick(h, self.scored)).collect()
    }
}

/// The closed loops' starts: spread-out test rows, their true levels
/// after each frame, and the nominal simulator stepping predicted states.
pub struct ClosedLoop<'a> {
    pub horizon: usize,
    /// Where each start's frame is, its real values `[variable][start]`
    /// and its levels (every learned variable).
    pub starts: Vec<Start<'a>>,
    pub states: Vec<Vec<f64>>,
    pub levels: LevelColumns,
    /// The true levels `[step][variable][start]`.
    pub truth: Vec<LevelColumns>,
    /// `None` where a scene's state is not made of predicted variables.
    pub restep: Option<Restep<'a>>,
}

impl ClosedLoop<'_> {
    /// [`piecewise::roll`] of the scored variables under `step`.
    fn real(
        &self,
        set: &TestSet,
        step: impl FnMut(&[Vec<f64>]) -> Vec<Vec<f64>>,
    ) -> Vec<LevelColumns> {
        piecewise::roll(
            set.scored,
            set.frames,
            set.learned,
            &self.starts,
            self.states.clone(),
            self.horizon,
            step,
        )
    }

    /// [`hybrid::roll`] of the scored variables under `correct`.
    fn hybrid(
        &mut self,
        set: &TestSet,
        correct: impl FnMut(&[f64], &[f64], &mut [f64]),
    ) -> Result<Option<Vec<LevelColumns>>> {
        let Some(restep) = self.restep.as_mut() else {
            return Ok(None);
        };
        hybrid::roll(
            restep,
            set.learned,
            set.scored,
            &self.starts,
            &self.states,
            &self.truth,
            self.horizon,
            correct,
        )
        .map(Some)
    }
}

/// No change predicted: the next level is the current one.
pub struct Persistence;

impl Compared for Persistence {
    fn id(&self) -> ModelId {
        ModelId::Persistence
    }

    fn one_step(&self, set: &TestSet) -> Result<LevelColumns> {
        Ok(pick(&set.test.x, set.scored))
    }

    fn paths<'s>(&'s self, _: &'s TestSet<'s>) -> Vec<Path<'s>> {
        Vec::new()
    }

    fn closed_loop(
        &self,
        set: &TestSet,
        run: &mut ClosedLoop,
    ) -> Result<Option<Vec<LevelColumns>>> {
        let levels = rollout::roll(run.levels.clone(), run.horizon, |x| x.to_vec());
        Ok(Some(set.scored_of(levels)))
    }
}

/// A trained bit model (a bit-forest or a threshold model): levels in,
/// levels out, rate limited within `windows` when given.
pub struct BitAln<'m> {
    pub runtime: Runtime<'m>,
    pub windows: Option<Vec<usize>>,
}

impl Compared for BitAln<'_> {
    fn id(&self) -> ModelId {
        ModelId::Aln
    }

    fn one_step(&self, set: &TestSet) -> Result<LevelColumns> {
        let windows = self.windows.as_deref();
        Ok(predict::levels(
            &self.runtime,
            &set.test.x,
            windows,
            set.pool,
        ))
    }

    fn paths<'s>(&'s self, set: &'s TestSet<'s>) -> Vec<Path<'s>> {
        predict::paths(
            &self.runtime,
            &set.test.x,
            self.windows.as_deref(),
            set.pool,
        )
    }

    fn closed_loop(
        &self,
        set: &TestSet,
        run: &mut ClosedLoop,
    ) -> Result<Option<Vec<LevelColumns>>> {
        let windows = self.windows.as_deref();
        let levels = rollout::roll(run.levels.clone(), run.horizon, |x| {
            self.runtime.levels(x, windows)
        });
        Ok(Some(set.scored_of(levels)))
    }
}

/// A learned model of real values: a piecewise-linear model (an ALN, the
/// robust linear fit), or boosted trees.
pub enum Learned<'a> {
    Piecewise(Predictor<'a>),
    Boosted(&'a Peer),
}

/// Real values as a learned model reads them: every pair's columns
/// `[variable][pair]`, the test rows' columns, and the test rows as rows.
type Values<'s> = (&'s [Vec<f64>], &'s [&'s [f64]], &'s [f64]);

impl Learned<'_> {
    /// The next levels of the test rows from their inputs `x`, each output
    /// advanced from its value in `base` (`x` itself for a model of the
    /// dynamics), the same on every evaluation path.
    fn levels(&self, id: ModelId, set: &TestSet, x: Values, base: Values) -> LevelColumns {
        match self {
            Learned::Piecewise(predictor) => {
                piecewise::checked_levels(id, predictor, (x.1, x.2), (base.1, base.2))
            }
            Learned::Boosted(peer) => peer.levels(set.learned, x.0, base.0, &set.test.rows),
        }
    }
}

/// A model of the dynamics: the scored variables' next values from the
/// current real values.
pub struct Dynamics<'a> {
    pub id: ModelId,
    pub learned: Learned<'a>,
    /// A piecewise-linear model's one-row evaluations timed: every one for
    /// the ALN, the quickest (plain) for the linear fit, as a
    /// practitioner would run it.
    pub evaluations: &'static [Evaluation],
}

impl Compared for Dynamics<'_> {
    fn id(&self) -> ModelId {
        self.id
    }

    fn one_step(&self, set: &TestSet) -> Result<LevelColumns> {
        let current = (set.x, set.columns, set.states);
        Ok(self.learned.levels(self.id, set, current, current))
    }

    fn paths<'s>(&'s self, set: &'s TestSet<'s>) -> Vec<Path<'s>> {
        match &self.learned {
            Learned::Piecewise(predictor) => piecewise::paths(
                self.id,
                predictor,
                self.evaluations,
                set.columns,
                set.states,
                set.pool,
            ),
            Learned::Boosted(peer) => {
                let (learned, x, rows, pool) = (set.learned, set.x, &set.test.rows, set.pool);
                vec![timing::Path {
                    model: self.id,
                    path: "batched",
                    threads: 1,
                    states: rows.len(),
                    failed: 0,
                    run: Box::new(move || {
                        std::hint::black_box(pool.install(|| peer.levels(learned, x, x, rows)));
                    }),
                }]
            }
        }
    }

    fn closed_loop(
        &self,
        set: &TestSet,
        run: &mut ClosedLoop,
    ) -> Result<Option<Vec<LevelColumns>>> {
        Ok(Some(match &self.learned {
            Learned::Piecewise(predictor) => run.real(set, piecewise::step_of(predictor)),
            Learned::Boosted(peer) => {
                let every: Vec<usize> = (0..run.starts.len()).collect();
                run.real(set, |state| {
                    peer.next_values(set.learned, state, state, &every)
                })
            }
        }))
    }
}

/// The nominal simulator's prediction, corrected by a learned model that
/// reads the state and that prediction side by side.
pub struct Hybrid<'a> {
    pub id: ModelId,
    pub learned: Learned<'a>,
}

impl Hybrid<'_> {
    /// The correction as [`hybrid::path`]'s and [`hybrid::roll`]'s
    /// `correct`.
    fn correct<'s>(&'s self, set: &'s TestSet<'s>) -> Box<hybrid::Correct<'s>> {
        match &self.learned {
            Learned::Piecewise(predictor) => Box::new(hybrid::correction(predictor)),
            Learned::Boosted(peer) => Box::new(hybrid::peer_correction(peer, set.learned)),
        }
    }
}

impl Compared for Hybrid<'_> {
    fn id(&self) -> ModelId {
        self.id
    }

    fn one_step(&self, set: &TestSet) -> Result<LevelColumns> {
        let inputs = (set.hybrid_x, set.hybrid_columns, set.hybrid_states);
        let nominal = (set.nominal, set.nominal_columns, set.nominal_states);
        Ok(self.learned.levels(self.id, set, inputs, nominal))
    }

    fn paths<'s>(&'s self, set: &'s TestSet<'s>) -> Vec<Path<'s>> {
        vec![hybrid::path(
            self.id,
            set.frames,
            set.replays,
            set.starts,
            set.states,
            set.learned.len(),
            self.correct(set),
        )]
    }

    fn closed_loop(
        &self,
        set: &TestSet,
        run: &mut ClosedLoop,
    ) -> Result<Option<Vec<LevelColumns>>> {
        run.hybrid(set, self.correct(set))
    }
}

/// The simulator re-stepping each test row's logged frame, `steps`
/// integration steps a frame.
pub struct Simulator {
    resimulated: Resimulated,
}

impl Simulator {
    /// Re-simulates every test row's frame (an error names the steps).
    pub fn new(set: &TestSet, steps: u64) -> Result<Simulator> {
        let resimulated = resimulate::baseline(
            set.frames,
            set.replays,
            set.learned,
            set.starts,
            &set.test.y,
            steps,
        )
        .map_err(|e| e.context(&format!("re-simulating with {steps} steps per frame")))?;
        Ok(Simulator { resimulated })
    }
}

impl Compared for Simulator {
    fn id(&self) -> ModelId {
        self.resimulated.model
    }

    fn one_step(&self, set: &TestSet) -> Result<LevelColumns> {
        Ok(pick(&self.resimulated.levels, set.scored))
    }

    fn paths<'s>(&'s self, set: &'s TestSet<'s>) -> Vec<Path<'s>> {
        vec![resimulate::path(
            &self.resimulated,
            set.frames,
            set.replays,
            set.learned,
            set.starts,
            &set.test.y,
        )]
    }

    fn closed_loop(
        &self,
        set: &TestSet,
        run: &mut ClosedLoop,
    ) -> Result<Option<Vec<LevelColumns>>> {
        let levels = resimulate::rollout(
            set.frames,
            set.replays,
            set.learned,
            &run.starts,
            &run.truth,
            self.resimulated.steps,
        )?;
        Ok(Some(set.scored_of(levels)))
    }
}
