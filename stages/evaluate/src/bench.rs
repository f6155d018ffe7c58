//! `alnlab bench predict --run`: the test stage's prediction of full states
//! timed on a run's own data — its model, its test rows, its trajectory log
//! — on one thread and on all threads, beside the simulator re-stepping each
//! test row's frame once on one thread. Every figure is the spread of
//! `repeat` timed runs.

use std::path::Path;

use alnlab_aln::ModelKind;
use alnlab_codes::bits::encode_columns;
use alnlab_common::{Error, Result};
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
    pub simulator_one_step_one_thread_ns: Spread,
    /// The simulator's median over the ALN's, both on one thread.
    pub aln_speedup_one_thread: f64,
}

/// Times the model at `model_path` on the test rows of `levels_path`, and
/// the simulator on the same rows' frames of `trajectory_path`.
pub fn on_data(
    model_path: &Path,
    codebook_path: &Path,
    levels_path: &Path,
    trajectory_path: &Path,
    repeat: usize,
) -> Result<OnData> {
    let repeat = repeat.max(1);
    let data = Data::read(model_path, codebook_path, levels_path)?;
    let test = data.test_rows()?;
    let states = test.rows.len();
    let aln = Runtime::new(&data.model, &data.codecs, &data.outputs);
    let one_thread = one_thread();
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

    let log = alnlab_common::state_log::StateLog::read(trajectory_path)?;
    let learned = data.learned();
    let frames = rollout::LoggedFrames::new(&log, &learned);
    let replays = alnlab_physics::replay::SceneReplay::from_log(&log)
        .map_err(|m| Error::bad_file(trajectory_path, m))?;
    let starts = data.starts(&test)?;
    let mut failed = Ok(());
    let simulator_one_step_one_thread_ns = measure(repeat, states, || {
        if let Err(e) = resimulate::one_frame(&frames, &replays, &learned, &starts, &test.y, 1) {
            failed = Err(e);
        }
    })
    .1;
    failed?;
    Ok(OnData {
        model: match data.model.header.model {
            ModelKind::BitForest => "bit-forest",
            ModelKind::Threshold => "threshold",
        },
        target: data.model.header.target.kind(),
        trees: data.model.trees.len(),
        input_bits_read: aln.bit_forest().map(|p| p.reads().len()),
        states,
        repeats: repeat,
        threads: rayon::current_num_threads(),
        aln_batched_one_thread_ns,
        aln_batched_all_threads_ns,
        aln_phases_one_thread_ns,
        simulator_one_step_one_thread_ns,
        aln_speedup_one_thread: simulator_one_step_one_thread_ns.median
            / aln_batched_one_thread_ns.median,
    })
}
