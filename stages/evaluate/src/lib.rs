//! The test stage (paper §4.5, §4.7; docs/design.md §6–7): loads the model,
//! predicts the next level of every variable it predicts (every learned
//! variable, or — a piecewise-linear model given the controls — all but
//! the controls) for every test row of `levels.parquet`, and scores it
//! beside the baselines on the same rows and variables. Writes
//! - `predictions.parquet`: per model (`aln`; `persistence`; `linear`, the
//!   robust linear fit of each variable's change from the real values
//!   the model reads, [`piecewise`]; and `simulator@<steps>/frame` for each
//!   re-simulation step of [`resimulate`]), variable and test row: the
//!   true level, the predicted level and the absolute error in levels, and
//!   whether the row was held out of training (with the paper's split, test
//!   rows include training rows);
//!   With `hybrids`, also `linear+nominal` and (with `peer`)
//!   `boosted+nominal`: the nominal simulator plus a learned correction
//!   ([`hybrid`]); a piecewise-linear model trained as that correction
//!   (`[train] base = "nominal"`) is itself a hybrid, and `aln` names it;
//! - `timings.parquet`: ns per predicted state for each model, evaluation
//!   path and thread count — every model on one thread, the ALN's batches
//!   also on all threads — as the median of 5 runs interleaved across the
//!   models ([`timing`]) with their range and the runs themselves, with the
//!   machine's cores and CPU model: a measurement, the one artifact that
//!   differs between equal runs;
//! - `rollout.parquet`: the closed-loop errors ([`rollout`]) per model,
//!   variable, horizon and start row;
//! - `linear.aln` and `boosted.parquet`: the robust linear fit as a
//!   piecewise-linear model of one piece per output, and the boosted trees
//!   ([`alnlab_aln::boosted`]; none without `peer`) — the baselines as
//!   models, loadable like the ALN (the Python package's `load`).

pub mod bench;
mod compared;
mod hybrid;
mod peer;
mod piecewise;
mod predict;
mod resimulate;
mod rollout;
pub mod timing;
pub mod timings;

use std::path::Path;

use alnlab_aln::boosted::Boosted;
use alnlab_aln::model::{Base, Header, Model, Reads};
use alnlab_aln::pwl::Tree;
use alnlab_aln::pwl::predict::{Path as Evaluation, Predictor, states};
use alnlab_aln::runtime::{Runtime, Trained};
use alnlab_aln::{ModelKind, Output, Target};
use alnlab_codes::codes::Codec;
use alnlab_codes::{Codebook, Entry};
use alnlab_common::params::{self, Count, Fraction, ParamError, Positive};
use alnlab_common::{Error, ModelId, Progress, Provenance, Result};
use alnlab_tables::levels::Levels;
use alnlab_tables::pairs::{Pairs, Side, Split};
use alnlab_tables::predictions::{self, Predictions};
use alnlab_tables::rollout::Rollout;
use serde::{Deserialize, Serialize};

use crate::compared::{
    BitAln, ClosedLoop, Compared, Dynamics, Hybrid, Learned, LevelColumns, Persistence, Simulator,
    TestSet,
};

/// Version of what this stage writes (part of every cache key; 5: the
/// robust linear baseline of the change, piecewise-linear models; 6: an
/// angle that wraps scored on the circle, its period in the predictions; 7:
/// the robust linear fit timed one state at a time too; 8: hybrids, the
/// nominal predictions an input; 9: the ALN as a hybrid, hybrids' closed
/// loops; 10: the linear and boosted baselines kept as models; 11: the
/// simulator's joint limits sized on what the joint moves; 12: its drives
/// implicit, mimic joints).
pub const FORMAT_VERSION: u32 = 12;

/// File name of the predictions table ([`alnlab_tables::predictions`]).
pub const PREDICTIONS_FILE: &str = alnlab_tables::predictions::FILE;
/// File name of the timings table.
pub const TIMINGS_FILE: &str = "timings.parquet";
/// File name of the closed-loop rollout table ([`alnlab_tables::rollout`]).
pub const ROLLOUT_FILE: &str = alnlab_tables::rollout::FILE;
/// File name of the robust linear fit as a model.
pub const LINEAR_FILE: &str = "linear.aln";
/// File name of the boosted trees ([`alnlab_aln::boosted`]).
pub const BOOSTED_FILE: &str = alnlab_aln::boosted::FILE;

/// The `[test]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Rate limiting (§4.7): each decoded variable moves at most this
    /// fraction of its levels from its current level. Off when absent.
    /// (Bit models only: a piecewise-linear model's change is not decoded.)
    pub rate_limit: Option<Fraction>,
    /// Closed-loop rollouts run this many steps (frames).
    pub horizon: Count,
    /// … from at most this many test rows, spread over the test set.
    pub rollout_starts: Count,
    /// The simulator as a baseline: each test row's frame re-simulated with
    /// this many integration steps per frame, for each number given (empty:
    /// no such baseline).
    pub resimulate_steps: Vec<Count>,
    /// The learned peer beside the ALN: gradient-boosted trees fitted to
    /// the same rows and target (`boosted`, [`peer`]; a minute or so of
    /// fitting on the paper's data).
    pub peer: bool,
    /// The hybrids beside them ([`hybrid`]): the nominal simulator — the
    /// nominal stage's prediction, the scene as written without its plant
    /// — plus a learned correction of what the plant did beyond it, by the
    /// robust linear fit (`linear+nominal`) and, with `peer`, by boosted
    /// trees (`boosted+nominal`).
    pub hybrids: bool,
    /// Each of a model's 5 timed runs repeats its evaluation until it has
    /// taken at least this long (s). Smaller is quicker and noisier: a
    /// trial run, or a test of the pipeline, needs no precise timing.
    pub run_seconds: Positive,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            rate_limit: None,
            horizon: Count(10),
            rollout_starts: Count(200),
            resimulate_steps: vec![Count(10), Count(5), Count(2), Count(1)],
            peer: false,
            hybrids: false,
            run_seconds: Positive(timing::RUN_SECONDS),
        }
    }
}

impl Params {
    /// Checks the parameters (every value the types admit is allowed).
    /// A horizon is counted in a table column of 16 bits.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        if self.horizon.get() > usize::from(u16::MAX) {
            return Err((
                "horizon".into(),
                format!("expected at most {} steps", u16::MAX),
            ));
        }
        Ok(())
    }

    /// The most levels each variable may move, if rate limited.
    fn windows(&self, codecs: &[Codec]) -> Option<Vec<usize>> {
        self.rate_limit.map(|f| {
            codecs
                .iter()
                .map(|c| (f.get() * (c.levels() - 1) as f64).ceil() as usize)
                .collect()
        })
    }
}

/// The test rows' levels: `x[v][k]` and `y[v][k]` for learned variable v and
/// the k-th test row.
pub struct TestRows {
    /// Row indices in `levels.parquet`.
    pub rows: Vec<usize>,
    /// Per row, whether it was held out of training (`split` is `test`,
    /// not `both`).
    pub held_out: Vec<bool>,
    pub x: Vec<Vec<u16>>,
    pub y: Vec<Vec<u16>>,
}

/// A model with what it was trained on: the codebook and its codecs, the
/// model's outputs, and the levels table whose test rows it predicts.
pub(crate) struct Data {
    pub model: Model,
    pub codebook: Codebook,
    pub codecs: Vec<Codec>,
    pub outputs: Vec<Output>,
    /// A piecewise-linear model's outputs (none for a bit model).
    pub reads: Vec<Reads>,
    pub levels: Levels,
}

impl Data {
    /// Reads the three files, checking that they belong together.
    pub fn read(model_path: &Path, codebook_path: &Path, levels_path: &Path) -> Result<Data> {
        let Trained {
            model,
            codebook,
            codecs,
            outputs,
            reads,
            ..
        } = Trained::read(model_path, codebook_path)?;
        Ok(Data {
            model,
            codecs,
            outputs,
            reads,
            levels: Levels::read(levels_path, codebook_path)?,
            codebook,
        })
    }

    /// The learned variables' codebook entries.
    pub fn learned(&self) -> Vec<&Entry> {
        self.codebook.learned().collect()
    }

    /// The learned variables' levels on `side` of `rows`, `[variable][row]`.
    pub fn select(&self, side: Side, rows: &[usize]) -> Result<Vec<Vec<u16>>> {
        self.levels.select(side, &self.learned(), rows)
    }

    /// The test rows (at least one).
    pub fn test_rows(&self) -> Result<TestRows> {
        let rows = self.levels.test_rows();
        if rows.is_empty() {
            return Err(Error::bad_file(self.levels.path(), "has no test rows"));
        }
        let keys = self.levels.keys();
        Ok(TestRows {
            held_out: rows.iter().map(|&r| keys[r].split == Split::Test).collect(),
            x: self.select(Side::Current, &rows)?,
            y: self.select(Side::Next, &rows)?,
            rows,
        })
    }

    /// Where each test row's frame is in the trajectory log.
    pub fn starts(&self, test: &TestRows) -> Vec<rollout::Start<'_>> {
        let keys = self.levels.keys();
        test.rows
            .iter()
            .map(|&r| rollout::Start {
                scene: &keys[r].scene,
                run: keys[r].run,
                frame: keys[r].step,
            })
            .collect()
    }
}

/// The files the stage reads.
pub struct Inputs<'a> {
    /// The trajectory log (MCAP) the pairs came from.
    pub trajectory: &'a Path,
    /// The trained model (`model.aln`).
    pub model: &'a Path,
    /// Its codebook.
    pub codebook: &'a Path,
    /// The levels table whose test rows are predicted.
    pub levels: &'a Path,
    /// The pairs table the levels were made from (real values).
    pub pairs: &'a Path,
    /// The nominal stage's predictions of the same pairs.
    pub nominal: &'a Path,
}

/// Reads the model, codebook, levels and real values, predicts, writes the
/// three tables.
pub fn run(
    params: &Params,
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
        pairs: pairs_path,
        nominal: nominal_path,
    } = *inputs;
    params.validate().map_err(|e| params::invalid("test", e))?;
    let data = Data::read(model_path, codebook_path, levels_path)?;
    let pairs = Pairs::read(pairs_path)?;
    data.levels.check_made_from(&pairs)?;
    let codecs = &data.codecs;
    let learned = data.learned();
    let test = data.test_rows()?;
    let train_rows = data.levels.train_rows();
    let (real_x, real_y) = (
        pairs.values(Side::Current, &learned)?,
        pairs.values(Side::Next, &learned)?,
    );
    let piecewise = match data.model.header.model {
        ModelKind::PiecewiseLinear => true,
        ModelKind::BitForest | ModelKind::Threshold => false,
    };
    let width = learned.len();
    // The nominal simulator's predictions (read and checked either way: an
    // input given is an input verified), and a hybrid's inputs: the state,
    // then its nominal prediction.
    let nominal = hybrid::base(nominal_path, &pairs, &learned)?;
    // An ALN hybrid reads the state, then its nominal prediction, and
    // advances from that prediction; the inputs are made only where a
    // hybrid reads them.
    let aln_hybrid = piecewise && data.model.header.base == Base::Nominal;
    let hybrid_x = match aln_hybrid || params.hybrids {
        true => hybrid::columns(&real_x, &nominal),
        false => Vec::new(),
    };
    // Every model is scored on the variables the model predicts.
    let scored: Vec<usize> = if piecewise {
        data.reads.iter().map(|r| r.variable).collect()
    } else {
        (0..width).collect()
    };
    let names: Vec<&str> = scored
        .iter()
        .map(|&v| learned[v].variable.as_str())
        .collect();
    // An angle that wraps is scored on the circle: +179° for −179° is 2° off.
    let periods: Vec<Option<u32>> = scored.iter().map(|&v| learned[v].period()).collect();

    progress.start("test", 4, "steps");
    let log = alnlab_common::state_log::read(trajectory_path)?;
    let frames = rollout::LoggedFrames::new(&log, &learned);
    let replays = alnlab_physics::replay::SceneReplay::from_log(&log)
        .map_err(|m| Error::bad_file(trajectory_path, m))?;
    let starts = data.starts(&test);
    let on_test = |all: &[Vec<f64>]| (pick_rows(all, &test.rows), states(all, &test.rows));
    let (test_columns, test_states) = on_test(&real_x);
    let (nominal_columns, nominal_states) = on_test(&nominal);
    let (hybrid_columns, hybrid_states) = on_test(&hybrid_x);
    let (test_columns, nominal_columns, hybrid_columns) = (
        as_slices(&test_columns),
        as_slices(&nominal_columns),
        as_slices(&hybrid_columns),
    );
    let pool = timing::one_thread();
    let set = TestSet {
        learned: &learned,
        scored: &scored,
        test: &test,
        x: &real_x,
        columns: &test_columns,
        states: &test_states,
        nominal: &nominal,
        hybrid_x: &hybrid_x,
        nominal_columns: &nominal_columns,
        nominal_states: &nominal_states,
        hybrid_columns: &hybrid_columns,
        hybrid_states: &hybrid_states,
        frames: &frames,
        replays: &replays,
        starts: &starts,
        pool: &pool,
    };

    // The baselines, fitted on the training rows and kept as models.
    let linear_reads = linear_inputs(&data, &learned, &scored)?;
    let linear_trees = piecewise::robust_linear(
        &learned,
        &linear_reads,
        &real_x,
        &real_x,
        &real_y,
        &train_rows,
    );
    linear_model(&data, &learned, &linear_reads, &linear_trees)
        .write(&out_dir.join(LINEAR_FILE))?;
    let peer = params
        .peer
        .then(|| peer::Peer::fit(&learned, &scored, &real_x, &real_x, &real_y, &train_rows));
    let none = Boosted {
        outputs: Vec::new(),
        features: width,
    };
    peer.as_ref()
        .map_or(&none, |p| &p.boosted)
        .write(&out_dir.join(BOOSTED_FILE), provenance)?;
    // The hybrids: the nominal simulator's prediction, corrected. Beside an
    // ALN hybrid the linear correction reads what the ALN's trees read, so
    // that it is the ALN's one-piece form, as `linear` is beside a model of
    // the dynamics.
    let hybrids = params.hybrids.then(|| {
        hybrid::Hybrids::fit(
            &learned,
            match aln_hybrid {
                true => data.reads.clone(),
                false => hybrid::with_own_nominal(&linear_reads, width),
            },
            &scored,
            &hybrid_x,
            &nominal,
            &real_y,
            &train_rows,
            params.peer,
        )
    });

    // Every model compared, in the tables' order.
    let mut models: Vec<Box<dyn Compared + '_>> = Vec::new();
    let aln_entries = Base::Nominal.inputs(&learned);
    let fitted_on = |x: &[Vec<f64>]| states(x, &train_rows);
    models.push(match piecewise {
        true if aln_hybrid => Box::new(Hybrid {
            id: ModelId::Aln,
            learned: Learned::Piecewise(Predictor::new(
                &data.model.pieces,
                &data.reads,
                &aln_entries,
                &fitted_on(&hybrid_x),
            )),
        }),
        true => Box::new(Dynamics {
            id: ModelId::Aln,
            learned: Learned::Piecewise(Predictor::new(
                &data.model.pieces,
                &data.reads,
                &learned,
                &fitted_on(&real_x),
            )),
            evaluations: &Evaluation::ALL,
        }),
        false => Box::new(BitAln {
            runtime: Runtime::new(&data.model, codecs, &data.outputs)
                .map_err(|m| Error::bad_file(model_path, m))?,
            windows: params.windows(codecs),
        }),
    });
    models.push(Box::new(Persistence));
    models.push(Box::new(Dynamics {
        id: ModelId::Linear,
        learned: Learned::Piecewise(Predictor::new(
            &linear_trees,
            &linear_reads,
            &learned,
            &fitted_on(&real_x),
        )),
        evaluations: &[Evaluation::Plain],
    }));
    if let Some(peer) = &peer {
        models.push(Box::new(Dynamics {
            id: ModelId::Boosted,
            learned: Learned::Boosted(peer),
            evaluations: &[],
        }));
    }
    if let Some(h) = &hybrids {
        models.push(Box::new(Hybrid {
            id: ModelId::LinearNominal,
            learned: Learned::Piecewise(Predictor::new(
                &h.linear,
                &h.reads,
                &h.inputs,
                &fitted_on(&hybrid_x),
            )),
        }));
        if let Some(peer) = &h.peer {
            models.push(Box::new(Hybrid {
                id: ModelId::BoostedNominal,
                learned: Learned::Boosted(peer),
            }));
        }
    }
    for steps in &params.resimulate_steps {
        models.push(Box::new(Simulator::new(&set, steps.0)?));
    }
    progress.advance(1);

    let one_step: Vec<(ModelId, LevelColumns)> = models
        .iter()
        .map(|m| Ok((m.id(), m.one_step(&set)?)))
        .collect::<Result<_>>()?;
    progress.advance(1);
    let timings = timing::in_rounds(
        models.iter().flat_map(|m| m.paths(&set)).collect(),
        timing::REPEATS,
        params.run_seconds.get(),
    );
    progress.advance(1);

    // Closed loop, from the true levels (real values) of spread-out test
    // rows. A hybrid's closed loop steps the nominal simulator from the
    // state it predicted, where every scene's state is made of predicted
    // variables (a robot's; not the worm's, whose hybrids have no closed
    // loop).
    let horizon = params.horizon.get();
    let truth = rollout::truth(
        &frames,
        &learned,
        &starts,
        horizon,
        params.rollout_starts.get(),
    );
    let mut closed = ClosedLoop {
        horizon,
        starts: truth.starts.iter().map(|&k| starts[k]).collect(),
        states: pick_rows(
            &real_x,
            &truth
                .starts
                .iter()
                .map(|&k| test.rows[k])
                .collect::<Vec<_>>(),
        ),
        levels: test
            .x
            .iter()
            .map(|x| truth.starts.iter().map(|&k| x[k]).collect())
            .collect(),
        truth: truth.levels,
        restep: hybrid::Restep::new(&frames, &replays, &learned, &scored).ok(),
    };
    let mut rolled: Vec<(ModelId, Vec<LevelColumns>)> = Vec::new();
    for model in &models {
        if let Some(levels) = model.closed_loop(&set, &mut closed)? {
            rolled.push((model.id(), levels));
        }
    }
    progress.advance(1);

    let test_rows: Vec<u32> = test.rows.iter().map(|&r| r as u32).collect();
    let mut predictions = Predictions::new(
        &names,
        &periods,
        &test_rows,
        &test.held_out,
        &pick(&test.y, &scored),
    );
    for (model, levels) in &one_step {
        predictions.push_model(*model, levels);
    }
    predictions.write(&out_dir.join(PREDICTIONS_FILE), provenance)?;
    let start_rows: Vec<u32> = truth.starts.iter().map(|&k| test_rows[k]).collect();
    let true_levels = set.scored_of(closed.truth);
    // `validate` bounds the horizon to a u16.
    let mut rollout = Rollout::new(&names, &start_rows, horizon as u16);
    for (model, levels) in &rolled {
        let errors: Vec<Vec<Vec<u16>>> = levels
            .iter()
            .zip(&true_levels)
            .map(|(predicted, truth)| {
                predicted
                    .iter()
                    .zip(truth)
                    .zip(&periods)
                    .map(|((p, t), &period)| {
                        p.iter()
                            .zip(t)
                            .map(|(&p, &t)| predictions::error(t, p, period))
                            .collect()
                    })
                    .collect()
            })
            .collect();
        rollout.push_model(*model, &errors);
    }
    rollout.write(&out_dir.join(ROLLOUT_FILE), provenance)?;
    let rows: Vec<timings::Row> = timings.iter().map(timings::Row::measured).collect();
    timings::write(&out_dir.join(TIMINGS_FILE), &rows, provenance)
}

/// The robust linear fit's `trees` (one piece each, reading `reads`) as a
/// piecewise-linear model of the dynamics, trained with the model's
/// codebook.
fn linear_model(data: &Data, learned: &[&Entry], reads: &[Reads], trees: &[Tree]) -> Model {
    let name = |v: usize| learned[v].variable.clone();
    Model {
        header: Header {
            codebook_sha256: data.model.header.codebook_sha256.clone(),
            params: serde_json::json!({
                "fit": "least absolute deviations of each variable's change in level spacings",
            }),
            model: ModelKind::PiecewiseLinear,
            target: Target::Change,
            inputs: learned.len(),
            outputs: reads.iter().map(|r| (name(r.variable), 1)).collect(),
            reads: reads
                .iter()
                .map(|r| r.inputs.iter().map(|&i| name(i)).collect())
                .collect(),
            vote: 1,
            counter_bound: 0,
            shard: None,
            base: Base::Current,
        },
        trees: Vec::new(),
        pieces: trees.to_vec(),
    }
}

/// Every column of `columns` as a slice.
fn as_slices(columns: &[Vec<f64>]) -> Vec<&[f64]> {
    columns.iter().map(Vec::as_slice).collect()
}

/// The rows `rows` of every column of `all`.
fn pick_rows(all: &[Vec<f64>], rows: &[usize]) -> Vec<Vec<f64>> {
    all.iter()
        .map(|column| rows.iter().map(|&r| column[r]).collect())
        .collect()
}

/// The columns `scored` of `all`, in that order.
fn pick<T: Clone>(all: &[Vec<T>], scored: &[usize]) -> Vec<Vec<T>> {
    scored.iter().map(|&v| all[v].clone()).collect()
}

/// What the robust linear baseline of each scored variable reads: what
/// the model's tree for it reads of the state (a piecewise-linear model),
/// or the
/// variables a bit model's trees for it read when it reads a few, or
/// every learned variable — the variable itself always among them.
fn linear_inputs(data: &Data, learned: &[&Entry], scored: &[usize]) -> Result<Vec<Reads>> {
    if !data.reads.is_empty() {
        // An ALN hybrid's nominal predictions are not the linear fit's.
        let state = |&i: &usize| i < learned.len();
        return Ok(data
            .reads
            .iter()
            .map(|r| Reads {
                variable: r.variable,
                inputs: r.inputs.iter().copied().filter(state).collect(),
            })
            .collect());
    }
    let index = |name: &String| learned.iter().position(|e| e.variable == *name);
    scored
        .iter()
        .enumerate()
        .map(|(o, &v)| {
            let mut inputs: Vec<usize> = match data.model.header.reads.get(o) {
                Some(names) => names.iter().filter_map(index).collect(),
                None => (0..learned.len()).collect(),
            };
            if !inputs.contains(&v) {
                inputs.push(v);
            }
            inputs.sort_unstable();
            Ok(Reads {
                variable: v,
                inputs,
            })
        })
        .collect()
}
