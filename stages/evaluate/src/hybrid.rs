//! Hybrids (issue 43): the nominal simulator's prediction plus a learned
//! correction. The nominal prediction is the nominal stage's: each pair's
//! logged frame stepped one frame on by the scene as written, at its own
//! step. The correction is each variable's change, in level spacings, from
//! that prediction to the logged next value — what the plant did beyond its
//! nominal model — fitted on the training rows: `linear+nominal` by the
//! robust linear fit ([`crate::piecewise::robust_linear`]) from the real
//! values the linear baseline reads and the variable's nominal prediction,
//! `boosted+nominal` by the learned peer's trees ([`crate::peer`]) from every
//! current value and every nominal prediction. With the nominal prediction
//! among its inputs a correction can also undo it: the hybrid's fits nest
//! the learned model's (the same form, a superset of its inputs), so it is
//! the strongest fair form of the idea, not a handicapped one.
//!
//! A piecewise-linear ALN trained as the correction (`[train] base =
//! "nominal"`) is the ALN hybrid; its fits nest the `linear+nominal` one,
//! which then reads what the ALN's trees read.
//!
//! A hybrid is timed as a user would run one: each state's frame stepped by
//! the nominal simulator, then corrected, one state at a time. Its closed
//! loop ([`roll`]) steps the nominal simulator from the state the hybrid
//! predicted, which needs every coordinate of the scene's generalized state
//! among the predicted variables ([`Restep`]): a robot's joint positions
//! and velocities are, the worm's links' orientations are not.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use alnlab_codes::Entry;
use alnlab_common::state_log::StateFrame;
use alnlab_common::{Error, ModelId, Result};
use alnlab_physics::replay::{Replayer, SceneReplay};
use alnlab_tables::pairs::{Pairs, Side};

use alnlab_aln::model::Reads;
use alnlab_aln::pwl::Tree;
use alnlab_aln::pwl::predict::Predictor;

use crate::peer::Peer;
use crate::piecewise;
use crate::rollout::{LoggedFrames, Start};
use crate::timing;

/// The nominal simulator's next values `[variable][row]` of the `learned`
/// variables, read from `path` (`nominal.parquet`), which must hold the
/// rows of `pairs`.
pub fn base(path: &Path, pairs: &Pairs, learned: &[&Entry]) -> Result<Vec<Vec<f64>>> {
    let nominal = Pairs::read(path)?;
    if nominal.keys() != pairs.keys() {
        return Err(Error::bad_file(
            path,
            format!(
                "does not hold the nominal predictions of {} ({} rows against {})",
                pairs.path().display(),
                nominal.len(),
                pairs.len()
            ),
        ));
    }
    nominal.values(Side::Next, learned)
}

/// The hybrids' corrections, fitted, and what they read.
pub struct Hybrids<'e> {
    /// The entries of the inputs a correction reads: the learned
    /// variables, then the same again for their nominal predictions.
    pub inputs: Vec<&'e Entry>,
    /// The robust linear correction's reads (indices among `inputs`): the
    /// linear baseline's and the variable's own nominal prediction, or an
    /// ALN hybrid's.
    pub reads: Vec<Reads>,
    /// The robust linear correction: one piece per output.
    pub linear: Vec<Tree>,
    /// The boosted trees' correction, from every input (with the peer).
    pub peer: Option<Peer>,
}

impl<'e> Hybrids<'e> {
    /// Fits the corrections on the training `rows`: a hybrid's inputs `x`
    /// ([`columns`]: the current real values, then the nominal
    /// predictions, `[input][row]`), the nominal predictions `nominal` and
    /// the next real values `y` (`[variable][row]`); `reads`, what the robust linear
    /// correction reads ([`with_own_nominal`] of the linear baseline's, or
    /// an ALN hybrid's); the boosted trees (for the `scored` variables)
    /// with `peer`.
    #[allow(clippy::too_many_arguments)]
    pub fn fit(
        learned: &[&'e Entry],
        reads: Vec<Reads>,
        scored: &[usize],
        x: &[Vec<f64>],
        nominal: &[Vec<f64>],
        y: &[Vec<f64>],
        rows: &[usize],
        peer: bool,
    ) -> Hybrids<'e> {
        let inputs = alnlab_aln::model::Base::Nominal.inputs(learned);
        let linear = piecewise::robust_linear(&inputs, &reads, x, nominal, y, rows);
        let peer = peer.then(|| Peer::fit(learned, scored, x, nominal, y, rows));
        Hybrids {
            inputs,
            reads,
            linear,
            peer,
        }
    }
}

/// A hybrid's input columns `[input][row]`: the current values `x`, then
/// the nominal predictions.
pub fn columns(x: &[Vec<f64>], nominal: &[Vec<f64>]) -> Vec<Vec<f64>> {
    x.iter().chain(nominal).cloned().collect()
}

/// The linear baseline's reads (among `width` learned variables) with each
/// output's own nominal prediction added: what `linear+nominal` reads
/// beside a model of the dynamics.
pub fn with_own_nominal(linear: &[Reads], width: usize) -> Vec<Reads> {
    linear
        .iter()
        .map(|r| Reads {
            variable: r.variable,
            inputs: r
                .inputs
                .iter()
                .copied()
                .chain([width + r.variable])
                .collect(),
        })
        .collect()
}

/// The path to time of a hybrid under `model`'s name: each test row's frame
/// (`rows`, the states' frames in the log, in the order of `states`, rows of
/// `width` values, the learned variables) stepped by the nominal simulator
/// at the nominal step (the scene's own, or its `nominal_steps`), then
/// `correct(inputs, nominal, next)` writing
/// the hybrid's next values from the state and its nominal prediction side
/// by side (`inputs`, as [`Hybrids::x`]'s columns), one state at a time on
/// one thread.
pub fn path<'a>(
    model: ModelId,
    frames: &'a LoggedFrames<'a>,
    replays: &'a BTreeMap<String, SceneReplay>,
    rows: &'a [Start<'a>],
    states: &'a [f64],
    width: usize,
    mut correct: impl FnMut(&[f64], &[f64], &mut [f64]) + 'a,
) -> timing::Path<'a> {
    let mut replayers: HashMap<&str, Replayer> = replays
        .iter()
        .map(|(name, r)| (name.as_str(), r.replayer()))
        .collect();
    let mut next = StateFrame::default();
    let (mut inputs, mut corrected) = (vec![0.0; 2 * width], vec![0.0; width]);
    // In time order within each run, as the simulator baselines step them,
    // so each run's controller mostly moves forward.
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by_key(|&k| (rows[k].scene, rows[k].run, rows[k].frame));
    timing::Path {
        model,
        path: "single",
        threads: 1,
        states: rows.len(),
        failed: 0,
        run: Box::new(move || {
            for &k in &order {
                let (row, state) = (&rows[k], &states[k * width..(k + 1) * width]);
                // Every row was stepped so by the nominal stage: a row it
                // could not step failed the run there.
                let (Some(from), Some(replayer)) =
                    (frames.get(row, 0), replayers.get_mut(row.scene))
                else {
                    continue;
                };
                let (current, nominal) = inputs.split_at_mut(width);
                let replay = &replays[row.scene];
                if step_nominal(
                    frames, replay, replayer, row.scene, from, &mut next, nominal,
                )
                .is_err()
                {
                    continue;
                }
                current.copy_from_slice(state);
                correct(&inputs, &inputs[width..], &mut corrected);
                std::hint::black_box(&corrected);
            }
        }),
    }
}

/// A hybrid's correction: from its inputs (the state, then its nominal
/// prediction) and the nominal prediction alone, the predicted variables'
/// next values.
pub type Correct<'a> = dyn FnMut(&[f64], &[f64], &mut [f64]) + 'a;

/// A piecewise-linear correction (the ALN hybrid's, `linear+nominal`'s) as
/// [`path`]'s and [`roll`]'s `correct`: each output advanced from its
/// nominal prediction, by the plain evaluation.
pub fn correction<'p>(predictor: &'p Predictor<'p>) -> impl FnMut(&[f64], &[f64], &mut [f64]) + 'p {
    let mut scratch = predictor.scratch();
    let outputs = predictor.variables().count();
    move |inputs, nominal, next| {
        let plain = alnlab_aln::pwl::predict::Path::Plain;
        predictor.next_values_from(inputs, nominal, plain, &mut scratch, &mut next[..outputs]);
    }
}

/// The boosted trees' correction as [`path`]'s and [`roll`]'s `correct`,
/// one state as the crate's one-row table.
pub fn peer_correction<'p>(
    peer: &'p Peer,
    learned: &'p [&'p Entry],
) -> impl FnMut(&[f64], &[f64], &mut [f64]) + 'p {
    move |inputs, nominal, next| {
        let column =
            |values: &[f64]| -> Vec<Vec<f64>> { values.iter().map(|&v| vec![v]).collect() };
        let values = peer.next_values(learned, &column(inputs), &column(nominal), &[0]);
        for (n, v) in next.iter_mut().zip(values) {
            *n = v[0];
        }
    }
}

/// The nominal simulator stepping a state a model predicted: the logged
/// frame the state stands in for, its generalized state rebuilt from the
/// predicted variables, re-simulated one frame at the nominal step (the
/// scene's own, or its `nominal_steps`).
pub struct Restep<'a> {
    frames: &'a LoggedFrames<'a>,
    replays: &'a BTreeMap<String, SceneReplay>,
    replayers: HashMap<&'a str, Replayer<'a>>,
    /// Per scene: each changing coordinate of its generalized state, and
    /// the learned variable that is it.
    fills: HashMap<&'a str, Vec<(usize, usize)>>,
    from: StateFrame,
    next: StateFrame,
}

impl<'a> Restep<'a> {
    /// The nominal simulator of every scene of `replays`, whose states are
    /// rebuilt from the `predicted` learned variables (indices among
    /// `learned`); an error says which scene's state cannot be, and why.
    pub fn new(
        frames: &'a LoggedFrames<'a>,
        replays: &'a BTreeMap<String, SceneReplay>,
        learned: &[&Entry],
        predicted: &[usize],
    ) -> std::result::Result<Restep<'a>, String> {
        let mut fills = HashMap::new();
        for (name, replay) in replays {
            let layout = &replay.prepared.layout;
            let refused = |why: String| format!("scene `{name}`: {why}");
            let filled =
                alnlab_physics::runner::state_from_variables(&layout.state, &layout.variables)
                    .map_err(refused)?;
            let fill = filled
                .into_iter()
                .map(|(state, variable)| {
                    let name = &layout.variables[variable];
                    predicted
                        .iter()
                        .copied()
                        .find(|&v| learned[v].variable == *name)
                        .map(|v| (state, v))
                        .ok_or_else(|| refused(format!("the model does not predict `{name}`")))
                })
                .collect::<std::result::Result<_, _>>()?;
            fills.insert(name.as_str(), fill);
        }
        Ok(Restep {
            frames,
            replays,
            replayers: replays
                .iter()
                .map(|(name, r)| (name.as_str(), r.replayer()))
                .collect(),
            fills,
            from: StateFrame::default(),
            next: StateFrame::default(),
        })
    }

    /// The nominal simulator's prediction `nominal` (every learned
    /// variable) one frame after the state `values` (the learned
    /// variables), which stands in for the frame `h` frames after `row`.
    /// An error if that frame is not logged, or [`Error::Diverged`] if the
    /// simulation blew up.
    pub fn step(&mut self, row: &Start, h: u32, values: &[f64], nominal: &mut [f64]) -> Result<()> {
        let missing = || {
            Error::Invalid(format!(
                "scene `{}`, run {}: frame {} is not in the trajectory log",
                row.scene,
                row.run,
                row.frame + h
            ))
        };
        let logged = self.frames.get(row, h).ok_or_else(missing)?;
        let (Some(replayer), Some(fill)) =
            (self.replayers.get_mut(row.scene), self.fills.get(row.scene))
        else {
            return Err(missing());
        };
        self.from.clone_from(logged);
        for &(state, v) in fill {
            self.from.state[state] = values[v];
        }
        let replay = &self.replays[row.scene];
        step_nominal(
            self.frames,
            replay,
            replayer,
            row.scene,
            &self.from,
            &mut self.next,
            nominal,
        )
    }
}

/// The nominal simulator's prediction `nominal` (every learned variable)
/// one frame after `from`, a frame of `scene` (whose replay is `replay`),
/// stepped by `replayer` at the nominal step (the scene's own, or its
/// `nominal_steps`) into `next`; NaN for a variable the frame lacks.
fn step_nominal(
    frames: &LoggedFrames,
    replay: &SceneReplay,
    replayer: &mut Replayer,
    scene: &str,
    from: &StateFrame,
    next: &mut StateFrame,
    nominal: &mut [f64],
) -> Result<()> {
    replayer.next_frame(from, replay.prepared.scene.nominal_steps_per_frame(), next)?;
    for (v, value) in nominal.iter_mut().enumerate() {
        *value = frames.value(scene, next, v).unwrap_or(f64::NAN);
    }
    Ok(())
}

/// A hybrid's closed loop from the real states `start` (`[variable][s]`,
/// the learned variables) of `starts`: each step the nominal simulator
/// steps the current state ([`Restep::step`]), then `correct(inputs,
/// nominal, next)` — as in [`path`] — gives the `variables`' next values,
/// which replace theirs; the other variables (the controls, when given)
/// take their logged values. Returns the `variables`' levels after each of
/// `horizon` steps, `[h][output][s]`; a start whose simulation blew up
/// scores from then on the level farthest from the truth `truth`
/// (`[h][variable][s]`), as a simulator's blow-up does.
#[allow(clippy::too_many_arguments)]
pub fn roll(
    restep: &mut Restep,
    learned: &[&Entry],
    variables: &[usize],
    starts: &[Start],
    start: &[Vec<f64>],
    truth: &[Vec<Vec<u16>>],
    horizon: usize,
    mut correct: impl FnMut(&[f64], &[f64], &mut [f64]),
) -> Result<Vec<Vec<Vec<u16>>>> {
    let width = learned.len();
    let mut levels = vec![vec![vec![0u16; starts.len()]; variables.len()]; horizon];
    let (mut inputs, mut next) = (vec![0.0; 2 * width], vec![0.0; variables.len()]);
    // In time order within each run, so each run's controller mostly moves
    // forward.
    let mut order: Vec<usize> = (0..starts.len()).collect();
    order.sort_by_key(|&k| (starts[k].scene, starts[k].run, starts[k].frame));
    for s in order {
        let row = &starts[s];
        for (slot, column) in inputs[..width].iter_mut().zip(start) {
            *slot = column[s];
        }
        let mut blown = false;
        for (h, at_h) in levels.iter_mut().enumerate() {
            if !blown {
                let (current, nominal) = inputs.split_at_mut(width);
                match restep.step(row, h as u32, current, nominal) {
                    Ok(()) => {}
                    Err(Error::Diverged(_)) => blown = true,
                    Err(e) => return Err(e),
                }
            }
            if !blown {
                correct(&inputs, &inputs[width..], &mut next);
                for (&v, &value) in variables.iter().zip(&next) {
                    inputs[v] = value;
                }
                let logged = restep.frames.get(row, h as u32 + 1);
                for v in (0..width).filter(|v| !variables.contains(v)) {
                    inputs[v] = logged
                        .and_then(|f| restep.frames.value(row.scene, f, v))
                        .unwrap_or(f64::NAN);
                }
            }
            for (o, &v) in variables.iter().enumerate() {
                let levels = learned[v].quantizer.levels;
                at_h[o][s] = if blown {
                    crate::resimulate::farthest(truth[h][v][s], levels)
                } else {
                    learned[v].quantizer.level(inputs[v]).0
                };
            }
        }
    }
    Ok(levels)
}
