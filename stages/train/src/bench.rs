//! `alnlab bench train` and `alnlab bench predict`: the paper's scale (§4.3):
//! 64 variables × 23-bit walk codes = 1472 trees of 8192 leaves over 1472
//! input bits, 1000 training samples, 10 epochs. The data has the paper's
//! shape: each variable a level in 0..214 that moves by a few levels per
//! step, the target its next level.

use std::time::Instant;

use alnlab_codes::bits::encode;
use alnlab_codes::codes::{Code, Codec};
use alnlab_codes::walk::WalkSpec;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use alnlab_aln::forest::Predictor;
use alnlab_aln::shard::Shard;
use alnlab_aln::tree::TreeSpec;
use alnlab_codes::bits::Columns;

use crate::forest;

/// The figures of `alnlab bench train`, with stable keys for `--json`.
#[derive(Debug, Serialize)]
pub struct TrainBench {
    pub seconds: f64,
    pub trees: usize,
    pub node_updates_per_s: f64,
    pub threads: usize,
}

/// The figures of `alnlab bench predict`, with stable keys for `--json`.
#[derive(Debug, Serialize)]
pub struct PredictBench {
    /// ns per full predicted state (all trees, votes and decoding), in
    /// bit-sliced batches of 1024 samples run on `threads` threads.
    pub batched_ns_per_state: f64,
    /// The same on one thread.
    pub batched_one_thread_ns_per_state: f64,
    /// ns per full predicted state, one sample at a time, parsimonious, on
    /// one thread.
    pub single_ns_per_state: f64,
    /// Of `batched_ns_per_state`, the decoding of the predicted codes.
    pub decode_ns_per_state: f64,
    /// Leaves the single-sample evaluation tests per state.
    pub leaves_tested_per_state: f64,
    /// Fraction of nodes the parsimonious evaluation visited.
    pub nodes_evaluated_fraction: f64,
    /// The paper's estimate ½·(3/4)^d (§3.2).
    pub estimated_fraction: f64,
    /// Threads of the batched evaluation.
    pub threads: usize,
}

const VARIABLES: usize = 64;
const LEVELS: usize = 214;

/// The paper-shaped data: (codecs, x bits, per-variable y bits) for `rows`.
fn data(rows: usize) -> (Vec<Codec>, Columns, Vec<Columns>) {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let codecs: Vec<Codec> = (0..VARIABLES as u64)
        .map(|v| {
            let spec = WalkSpec {
                levels: LEVELS,
                width: 23,
                step: 1,
                span: 7,
                seed: v,
            };
            Codec::new(Code::Walk, LEVELS, Some(spec)).expect("the paper's walk exists")
        })
        .collect();
    let mut x: Vec<Vec<u16>> = (0..VARIABLES).map(|_| Vec::with_capacity(rows)).collect();
    let mut y: Vec<Vec<u16>> = (0..VARIABLES).map(|_| Vec::with_capacity(rows)).collect();
    let mut level: Vec<i32> = (0..VARIABLES)
        .map(|_| rng.random_range(0..LEVELS as i32))
        .collect();
    let mut rate: Vec<i32> = (0..VARIABLES).map(|_| rng.random_range(-3..=3)).collect();
    for _ in 0..rows {
        for v in 0..VARIABLES {
            if rng.random_bool(0.05) {
                rate[v] = rng.random_range(-3..=3);
            }
            let next = (level[v] + rate[v]).clamp(0, LEVELS as i32 - 1);
            x[v].push(level[v] as u16);
            y[v].push(next as u16);
            level[v] = next;
        }
    }
    let refs: Vec<&Codec> = codecs.iter().collect();
    let all: Vec<usize> = (0..rows).collect();
    let x_columns: Vec<&[u16]> = x.iter().map(Vec::as_slice).collect();
    let inputs = Columns::from_rows(&encode(&refs, &x_columns), &all);
    let targets = codecs
        .iter()
        .zip(&y)
        .map(|(c, column)| Columns::from_rows(&encode(&[c], &[column]), &all))
        .collect();
    (codecs, inputs, targets)
}

fn spec(inputs: usize) -> TreeSpec {
    TreeSpec {
        leaves: 8192,
        inputs,
        counter_bound: 3,
        initial_spread: 1,
    }
}

/// The paper-scale forest trained on `inputs` (10 epochs, one voter, a
/// fixed seed).
fn paper_forest(inputs: &Columns, targets: &[Columns]) -> Vec<forest::Trained> {
    forest::train(
        &spec(inputs.bits),
        10,
        1,
        7,
        Shard::ALL,
        inputs,
        targets,
        &forest::every_bit(inputs.bits, targets.len()),
        &|| {},
    )
}

/// Trains the paper-scale forest once.
pub fn train() -> TrainBench {
    let (_, inputs, targets) = data(1000);
    let clock = Instant::now();
    let trained = paper_forest(&inputs, &targets);
    let seconds = clock.elapsed().as_secs_f64();
    let updates: usize = trained
        .iter()
        .flat_map(|t| &t.epochs)
        .map(|e| e.updates)
        .sum();
    TrainBench {
        seconds,
        trees: trained.len(),
        node_updates_per_s: updates as f64 / seconds,
        threads: rayon::current_num_threads(),
    }
}

/// Trains a paper-scale forest (10 epochs), then times prediction of full
/// states: every tree, the votes and the decoding of every variable.
pub fn predict() -> PredictBench {
    let (codecs, inputs, targets) = data(1024);
    let trained = paper_forest(&inputs, &targets);
    let widths = vec![23; VARIABLES];
    let predictor = Predictor::new(trained.iter().map(|t| (t.id, &t.tree)), &widths, 1);
    let decode_all = |out: &[Columns]| -> usize {
        codecs
            .par_iter()
            .zip(out)
            .map(|(codec, columns)| {
                let mut sum = 0;
                columns.for_each_row(|_, code| sum += codec.decode(code));
                sum
            })
            .sum()
    };
    let batched = || {
        median_ns(5, inputs.count, || {
            std::hint::black_box(decode_all(&predictor.predict(&inputs)));
        })
    };
    let batched_ns_per_state = batched();
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a thread pool of one thread");
    let batched_one_thread_ns_per_state = one_thread.install(batched);
    let out = predictor.predict(&inputs);
    let decode_ns_per_state = median_ns(5, inputs.count, || {
        std::hint::black_box(decode_all(&out));
    });

    // One sample at a time, parsimoniously.
    let rows: Vec<Vec<u64>> = (0..inputs.count)
        .map(|s| {
            let mut row = vec![0u64; inputs.bits.div_ceil(64)];
            for b in 0..inputs.bits {
                row[b / 64] |= (inputs.column(b)[s / 64] >> (s % 64) & 1) << (b % 64);
            }
            row
        })
        .collect();
    let mut votes = Vec::new();
    let mut codes = vec![Vec::new(); VARIABLES];
    let mut tested = 0;
    let single_ns_per_state = median_ns(5, rows.len(), || {
        tested = 0;
        for row in &rows {
            tested += predictor.predict_one(row, &mut votes, &mut codes);
            for (codec, code) in codecs.iter().zip(&codes) {
                std::hint::black_box(codec.decode(code));
            }
        }
    });

    // The fraction of all nodes parsimonious evaluation of the unpruned
    // trees visits, over 64 samples.
    let visited: usize = rows[..64]
        .iter()
        .flat_map(|row| trained.iter().map(|t| t.tree.evaluate_parsimonious(row).1))
        .sum();
    let nodes = (2 * 8192 - 1) * trained.len() * 64;
    PredictBench {
        batched_ns_per_state,
        batched_one_thread_ns_per_state,
        single_ns_per_state,
        decode_ns_per_state,
        leaves_tested_per_state: tested as f64 / rows.len() as f64,
        nodes_evaluated_fraction: visited as f64 / nodes as f64,
        estimated_fraction: 0.5 * 0.75f64.powi(13),
        threads: rayon::current_num_threads(),
    }
}

/// The median over `runs` runs of `f`, in ns per each of `items`.
fn median_ns(runs: usize, items: usize, mut f: impl FnMut()) -> f64 {
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let clock = Instant::now();
            f();
            clock.elapsed().as_nanos() as f64 / items as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[runs / 2]
}
