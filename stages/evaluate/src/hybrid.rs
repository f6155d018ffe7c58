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
//! A hybrid is timed as a user would run one: each state's frame stepped by
//! the nominal simulator, then corrected, one state at a time. Its closed
//! loop is not run: the nominal simulator steps the whole generalized
//! state, which the learned variables a model predicts are not.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use alnlab_codes::Entry;
use alnlab_common::state_log::StateFrame;
use alnlab_common::{Error, Result};
use alnlab_physics::replay::{Replayer, SceneReplay};
use alnlab_tables::pairs::{Pairs, Side};

use alnlab_aln::model::Reads;
use alnlab_aln::pwl::Tree;

use crate::peer::Peer;
use crate::piecewise;
use crate::rollout::{LoggedFrames, Start};
use crate::timing;

/// The robust linear hybrid's model name.
pub const LINEAR: &str = "linear+nominal";
/// The boosted trees' hybrid's model name.
pub const PEER: &str = "boosted+nominal";

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
    /// Every pair's inputs `[input][row]`: the current real values, then
    /// the nominal predictions.
    pub x: Vec<Vec<f64>>,
    /// The nominal predictions `[variable][row]` each hybrid advances from.
    pub nominal: Vec<Vec<f64>>,
    /// The robust linear correction's reads (indices among `inputs`): the
    /// linear baseline's, and the variable's own nominal prediction.
    pub reads: Vec<Reads>,
    /// The robust linear correction: one piece per output.
    pub linear: Vec<Tree>,
    /// The boosted trees' correction, from every input (with the peer).
    pub peer: Option<Peer>,
}

impl<'e> Hybrids<'e> {
    /// Fits the corrections on the training `rows`: the learned variables'
    /// current and next real values `x`, `y` and nominal predictions
    /// `nominal` (`[variable][row]`); `linear_reads`, the linear baseline's
    /// reads; the boosted trees (for the `scored` variables) with `peer`.
    #[allow(clippy::too_many_arguments)]
    pub fn fit(
        learned: &[&'e Entry],
        linear_reads: &[Reads],
        scored: &[usize],
        x: &[Vec<f64>],
        nominal: Vec<Vec<f64>>,
        y: &[Vec<f64>],
        rows: &[usize],
        peer: bool,
    ) -> Hybrids<'e> {
        let width = learned.len();
        let inputs: Vec<&Entry> = learned.iter().chain(learned).copied().collect();
        let x: Vec<Vec<f64>> = x.iter().chain(&nominal).cloned().collect();
        let reads: Vec<Reads> = linear_reads
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
            .collect();
        let linear = piecewise::robust_linear(&inputs, &reads, &x, &nominal, y, rows);
        let peer = peer.then(|| Peer::fit(learned, scored, &x, &nominal, y, rows));
        Hybrids {
            inputs,
            x,
            nominal,
            reads,
            linear,
            peer,
        }
    }
}

/// The path to time of a hybrid under `model`'s name: each test row's frame
/// (`rows`, the states' frames in the log, in the order of `states`, rows of
/// `width` values, the learned variables) stepped by the nominal simulator
/// at the scene's own step, then `correct(inputs, nominal, next)` writing
/// the hybrid's next values from the state and its nominal prediction side
/// by side (`inputs`, as [`Hybrids::x`]'s columns), one state at a time on
/// one thread.
pub fn path<'a>(
    model: &str,
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
        model: model.into(),
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
                let steps = replays[row.scene].prepared.scene.steps_per_frame();
                if replayer.next_frame(from, steps, &mut next).is_err() {
                    continue;
                }
                let (current, nominal) = inputs.split_at_mut(width);
                current.copy_from_slice(state);
                for (v, value) in nominal.iter_mut().enumerate() {
                    *value = frames.value(row.scene, &next, v).unwrap_or(f64::NAN);
                }
                correct(&inputs, &inputs[width..], &mut corrected);
                std::hint::black_box(&corrected);
            }
        }),
    }
}
