//! Models that predict from the current state's real values: a
//! piecewise-linear ALN, and the robust linear baseline — the strongest fair
//! linear form, which is a piecewise-linear model of one piece per output:
//! each variable's change, in level spacings, fitted by least absolute
//! deviations on the training rows from the inputs the model reads (every
//! learned variable when it reads them all), the variable itself always
//! among them.
//!
//! Both predict through [`Predictor`], whose three paths (every piece,
//! lazily with cut-offs, compiled over boxes) must give the same levels on
//! every test row; all three are timed, one row at a time and tree by tree
//! over all rows (`batched`), on one thread.

use alnlab_aln::linear::least_absolute;
use alnlab_aln::model::Reads;
use alnlab_aln::pwl::Tree;
use alnlab_aln::pwl::predict::{self, Path as Evaluation, Predictor};
use alnlab_codes::Entry;
use alnlab_common::ModelId;
use rayon::prelude::*;

use crate::rollout::{LoggedFrames, Start};
use crate::timing::Path;

/// The levels `[output][row]` of the test states — `columns`
/// (`[input][row]`) and the same as `states`, rows of the predictor's
/// width — each output advanced from its variable's value in `base`
/// (`[variable][row]` and rows of values, as `columns` and `states` for a
/// model of the dynamics, the nominal predictions for a hybrid), checked
/// equal on every evaluation path: tree by tree over blocks of rows, and
/// one row at a time by each evaluation.
pub fn checked_levels(
    model: ModelId,
    predictor: &Predictor,
    (columns, states): (&[&[f64]], &[f64]),
    (base_columns, base_states): (&[&[f64]], &[f64]),
) -> Vec<Vec<u16>> {
    let levels = predictor.levels_from(columns, base_columns, &mut predictor.scratch());
    let rows = levels.first().map_or(0, Vec::len);
    let base_width = base_states.len().checked_div(rows).unwrap_or(0);
    for evaluation in Evaluation::ALL {
        let mut scratch = predictor.scratch();
        let mut next = vec![0u16; levels.len()];
        let rows = states
            .chunks_exact(predictor.width())
            .zip(base_states.chunks_exact(base_width.max(1)));
        for (r, (state, base)) in rows.enumerate() {
            predictor.next_levels_from(state, base, evaluation, &mut scratch, &mut next);
            for (o, &level) in next.iter().enumerate() {
                assert_eq!(
                    level,
                    levels[o][r],
                    "{model}: the {} path disagrees with the compiled batch on test row {r}",
                    evaluation.name()
                );
            }
        }
    }
    levels
}

/// The paths to time of a model of the dynamics under `model`'s name: tree
/// by tree over blocks of rows (`batched`) and one row at a time by each
/// of `evaluations` (the levels were checked equal on every path by
/// [`checked_levels`]).
pub fn paths<'s, 'm: 's>(
    model: ModelId,
    predictor: &'s Predictor<'m>,
    evaluations: &[Evaluation],
    columns: &'s [&'s [f64]],
    states: &'s [f64],
    pool: &'s rayon::ThreadPool,
) -> Vec<Path<'s>> {
    let rows = states.len() / predictor.width().max(1);
    let outputs = predictor.variables().count();
    let one_row = move |evaluation: Evaluation| {
        let mut scratch = predictor.scratch();
        let mut levels = vec![Vec::with_capacity(rows); outputs];
        let mut next = vec![0u16; outputs];
        for state in states.chunks_exact(predictor.width()) {
            predictor.next_levels(state, evaluation, &mut scratch, &mut next);
            for (column, &level) in levels.iter_mut().zip(&next) {
                column.push(level);
            }
        }
        levels
    };
    let batched = move || predictor.levels(columns, &mut predictor.scratch());
    let path = |path, run: Box<dyn FnMut() + 's>| Path {
        model,
        path,
        threads: 1,
        states: rows,
        failed: 0,
        run,
    };
    let mut timed = vec![path(
        "batched",
        Box::new(move || {
            std::hint::black_box(pool.install(batched));
        }),
    )];
    for &evaluation in evaluations {
        timed.push(path(
            evaluation.name(),
            Box::new(move || {
                std::hint::black_box(pool.install(|| one_row(evaluation)));
            }),
        ));
    }
    timed
}

/// The robust linear baseline of the variables `reads` names: per output
/// one piece, the least-absolute-deviations fit, from its inputs' real
/// values `x[variable][row]`, of its change from `base` (the current values
/// `x` themselves, or another model's prediction for a hybrid) to the next
/// values `y`, on `rows`.
pub fn robust_linear(
    learned: &[&Entry],
    reads: &[Reads],
    x: &[Vec<f64>],
    base: &[Vec<f64>],
    y: &[Vec<f64>],
    rows: &[usize],
) -> Vec<Tree> {
    reads
        .par_iter()
        .map(|r| {
            let inputs: Vec<f64> = rows
                .iter()
                .flat_map(|&row| r.inputs.iter().map(move |&i| x[i][row]))
                .collect();
            let v = r.variable;
            let target: Vec<f64> = rows
                .iter()
                .map(|&row| predict::change(learned[v], base[v][row], y[v][row]))
                .collect();
            let (bias, weights) = least_absolute(&inputs, &target, r.inputs.len());
            Tree::affine(bias, &weights)
        })
        .collect()
}

/// Closed loop from the real states `start` (`[variable][s]`, the learned
/// variables) of the rollout's `starts`: each step `step` maps the current
/// states to the next values of `variables` (`[output][s]`), which replace
/// theirs; the variables not predicted (the controls, when given) take
/// their logged values. Returns the predicted variables' levels after each
/// of `horizon` steps, `[h][output][s]`.
#[allow(clippy::too_many_arguments)]
pub fn roll(
    variables: &[usize],
    frames: &LoggedFrames,
    learned: &[&Entry],
    starts: &[Start],
    start: Vec<Vec<f64>>,
    horizon: usize,
    mut step: impl FnMut(&[Vec<f64>]) -> Vec<Vec<f64>>,
) -> Vec<Vec<Vec<u16>>> {
    let given: Vec<usize> = (0..learned.len())
        .filter(|v| !variables.contains(v))
        .collect();
    let mut state = start;
    (0..horizon)
        .map(|h| {
            let next = step(&state);
            for (&v, values) in variables.iter().zip(next) {
                state[v] = values;
            }
            for &v in &given {
                for (s, row) in starts.iter().enumerate() {
                    let frame = frames.get(row, h as u32 + 1).expect("a rollout start");
                    state[v][s] = frames.value(row.scene, frame, v).expect("a rollout start");
                }
            }
            variables
                .iter()
                .map(|&v| {
                    let q = &learned[v].quantizer;
                    state[v].iter().map(|&x| q.level(x).0).collect()
                })
                .collect()
        })
        .collect()
}

/// [`roll`]'s step for a [`Predictor`]: each state's next values.
pub fn step_of<'p>(predictor: &'p Predictor) -> impl FnMut(&[Vec<f64>]) -> Vec<Vec<f64>> + 'p {
    let mut scratch = predictor.scratch();
    let outputs = predictor.variables().count();
    let mut row = vec![0.0; predictor.width()];
    let mut next = vec![0.0; outputs];
    move |state: &[Vec<f64>]| {
        let starts = state.first().map_or(0, Vec::len);
        let mut values = vec![Vec::with_capacity(starts); outputs];
        for s in 0..starts {
            for (slot, column) in row.iter_mut().zip(state) {
                *slot = column[s];
            }
            predictor.next_values(&row, Evaluation::Plain, &mut scratch, &mut next);
            for (column, &n) in values.iter_mut().zip(&next) {
                column.push(n);
            }
        }
        values
    }
}
