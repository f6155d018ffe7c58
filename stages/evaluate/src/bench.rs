//! `alnlab bench predict --run`: the test stage's prediction of full states
//! timed on a run's own data — its model, its test rows, its trajectory log
//! — on one thread and on all threads, beside the simulator re-stepping each
//! test row's frame once on one thread. Every figure is the spread of
//! `repeat` timed runs. A piecewise-linear model is timed from the rows'
//! real values, batched (tree by tree over all rows) and one row at a time
//! by each evaluation path.

use std::path::Path;

use alnlab_aln::ModelKind;
use alnlab_aln::pwl::predict::{self, Path as Evaluation, Predictor};
use alnlab_codes::bits::encode_columns;
use alnlab_common::{Error, Result};
use alnlab_tables::pairs::{Pairs, Side};
use rayon::prelude::*;
use serde::Serialize;

pub use crate::timing::Spread;
use crate::timing::{measure, one_thread};
use crate::{Data, resimulate, rollout};
use alnlab_aln::runtime::Runtime;

/// Where a bit-forest's batched time goes, on one thread (medians, ns per
/// state): coding the input bits the trees read from the levels, the trees
/// (bit-sliced programs and votes), and decoding the outputs.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Phases {
    pub code_inputs: f64,
    pub trees: f64,
    pub decode: f64,
}

/// The figures of `alnlab bench predict --run`.
#[derive(Debug, Serialize)]
pub struct OnData {
    /// `bit-forest` or `threshold`.
    pub model: &'static str,
    /// `level` or `delta`.
    pub target: &'static str,
    pub trees: usize,
    /// Distinct input bits the pruned trees read (bit-forests).
    pub input_bits_read: Option<usize>,
    /// Test rows, each a full state (every learned variable) predicted.
    pub states: usize,
    pub repeats: usize,
    /// Threads of "all threads".
    pub threads: usize,
    pub aln_batched_one_thread_ns: Spread,
    pub aln_batched_all_threads_ns: Spread,
    pub aln_phases_one_thread_ns: Option<Phases>,
    /// A piecewise-linear model: one row at a time on one thread by each
    /// evaluation path (`pwl-plain`, `pwl-lazy`, `pwl-compiled`), with its
    /// pieces in all and the mean pieces left in a compiled box.
    pub pwl_one_row_one_thread_ns: Option<Vec<(String, Spread)>>,
    pub pwl_pieces: Option<usize>,
    pub pwl_pieces_per_box: Option<f64>,
    pub simulator_one_step_one_thread_ns: Spread,
    /// The simulator's median over the ALN's, both on one thread.
    pub aln_speedup_one_thread: f64,
}

/// Times the model at `model_path` on the test rows of `levels_path` (their
/// real values in `pairs_path`), and the simulator on the same rows' frames
/// of `trajectory_path`.
pub fn on_data(
    model_path: &Path,
    codebook_path: &Path,
    levels_path: &Path,
    pairs_path: &Path,
    trajectory_path: &Path,
    repeat: usize,
) -> Result<OnData> {
    let repeat = repeat.max(1);
    let data = Data::read(model_path, codebook_path, levels_path)?;
    let test = data.test_rows()?;
    let states = test.rows.len();
    let one_thread = one_thread();
    let simulator_one_step_one_thread_ns = simulator(&data, &test, trajectory_path, repeat)?;
    let piecewise = match data.model.header.model {
        ModelKind::PiecewiseLinear => true,
        ModelKind::BitForest | ModelKind::Threshold => false,
    };
    if piecewise {
        let learned = data.learned();
        let x = Pairs::read(pairs_path)?.values(Side::Current, &learned)?;
        let train = data.levels.train_rows();
        let predictor = Predictor::new(
            &data.model.pieces,
            &data.reads,
            &learned,
            &predict::states(&x, &train),
        );
        let rows = predict::states(&x, &test.rows);
        let columns: Vec<Vec<f64>> = x
            .iter()
            .map(|c| test.rows.iter().map(|&r| c[r]).collect())
            .collect();
        let columns: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        let width = predictor.width();
        let batched = || {
            std::hint::black_box(predictor.levels(&columns, &mut predictor.scratch()));
        };
        // All threads: the rows cut into one part per thread.
        let part = states.div_ceil(rayon::current_num_threads()).max(1);
        let parallel = || {
            (0..states).into_par_iter().step_by(part).for_each(|start| {
                let end = (start + part).min(states);
                let slice: Vec<&[f64]> = columns.iter().map(|c| &c[start..end]).collect();
                std::hint::black_box(predictor.levels(&slice, &mut predictor.scratch()));
            })
        };
        let one_row = |evaluation| {
            let mut scratch = predictor.scratch();
            let mut next = vec![0u16; predictor.variables().count()];
            one_thread.install(|| {
                measure(repeat, states, || {
                    for state in rows.chunks_exact(width) {
                        predictor.next_levels(state, evaluation, &mut scratch, &mut next);
                    }
                    std::hint::black_box(&next);
                })
                .1
            })
        };
        let aln_batched_one_thread_ns = one_thread.install(|| measure(repeat, states, batched).1);
        let shapes = predictor.shapes();
        return Ok(OnData {
            model: "piecewise-linear",
            target: data.model.header.target.kind(),
            trees: data.model.pieces.len(),
            input_bits_read: None,
            states,
            repeats: repeat,
            threads: rayon::current_num_threads(),
            aln_batched_one_thread_ns,
            aln_batched_all_threads_ns: measure(repeat, states, parallel).1,
            aln_phases_one_thread_ns: None,
            pwl_one_row_one_thread_ns: Some(
                Evaluation::ALL
                    .iter()
                    .map(|&e| (e.name().to_string(), one_row(e)))
                    .collect(),
            ),
            pwl_pieces: Some(data.model.pieces.iter().map(|t| t.pieces()).sum()),
            pwl_pieces_per_box: Some(
                shapes.iter().map(|s| s.1).sum::<f64>() / shapes.len().max(1) as f64,
            ),
            simulator_one_step_one_thread_ns,
            aln_speedup_one_thread: simulator_one_step_one_thread_ns.median
                / aln_batched_one_thread_ns.median,
        });
    }
    let aln = Runtime::new(&data.model, &data.codecs, &data.outputs)
        .map_err(|m| Error::bad_file(model_path, m))?;
    let predict = || {
        std::hint::black_box(aln.levels(&test.x, None));
    };
    let aln_batched_one_thread_ns = one_thread.install(|| measure(repeat, states, predict).1);
    let aln_batched_all_threads_ns = measure(repeat, states, predict).1;
    let aln_phases_one_thread_ns = aln.bit_forest().map(|predictor| {
        one_thread.install(|| {
            let (codecs, columns) = aln.inputs(&test.x);
            let code = || encode_columns(&codecs, &columns, predictor.reads());
            let code_inputs = measure(repeat, states, || {
                std::hint::black_box(code());
            })
            .1;
            let read = code();
            let trees = measure(repeat, states, || {
                std::hint::black_box(predictor.predict_read(&read));
            })
            .1;
            let bits = predictor.predict_read(&read);
            let decode = measure(repeat, states, || {
                std::hint::black_box(aln.decode(&bits, &test.x, None));
            })
            .1;
            Phases {
                code_inputs: code_inputs.median,
                trees: trees.median,
                decode: decode.median,
            }
        })
    });

    Ok(OnData {
        model: data.model.header.model.name(),
        target: data.model.header.target.kind(),
        trees: data.model.trees.len(),
        input_bits_read: aln.bit_forest().map(|p| p.reads().len()),
        states,
        repeats: repeat,
        threads: rayon::current_num_threads(),
        aln_batched_one_thread_ns,
        aln_batched_all_threads_ns,
        aln_phases_one_thread_ns,
        pwl_one_row_one_thread_ns: None,
        pwl_pieces: None,
        pwl_pieces_per_box: None,
        simulator_one_step_one_thread_ns,
        aln_speedup_one_thread: simulator_one_step_one_thread_ns.median
            / aln_batched_one_thread_ns.median,
    })
}

/// The simulator re-stepping each test row's logged frame once, on the
/// calling thread.
fn simulator(
    data: &Data,
    test: &crate::TestRows,
    trajectory_path: &Path,
    repeat: usize,
) -> Result<Spread> {
    let log = alnlab_common::state_log::read(trajectory_path)?;
    let learned = data.learned();
    let frames = rollout::LoggedFrames::new(&log, &learned);
    let replays = alnlab_physics::replay::SceneReplay::from_log(&log)
        .map_err(|m| Error::bad_file(trajectory_path, m))?;
    let starts = data.starts(test);
    let mut failed = Ok(());
    let spread = one_thread().install(|| {
        measure(repeat, test.rows.len(), || {
            if let Err(e) = resimulate::one_frame(&frames, &replays, &learned, &starts, &test.y, 1)
            {
                failed = Err(e);
            }
        })
        .1
    });
    failed.map(|_| spread)
}
