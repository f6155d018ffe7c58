//! `alnlab bench train` and `alnlab bench predict`: the paper's scale (§4.3):
//! 64 variables × 23-bit walk codes = 1472 trees of 8192 leaves over 1472
//! input bits, 1000 training samples, 10 epochs. The data has the paper's
//! shape: each variable a level in 0..214 that moves by a few levels per
//! step, the target its next level.

use std::time::Instant;

use alnlab_quantize::bits::encode;
use alnlab_quantize::codes::{Code, Codec};
use alnlab_quantize::walk::WalkSpec;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::forest::{self, Columns, Predictor};
use crate::tree::TreeSpec;

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
    /// ns per full predicted state (all trees and decoding), bit-sliced batches of 64.
    pub batched_ns_per_state: f64,
    /// ns per full predicted state, one sample at a time, parsimonious.
    pub single_ns_per_state: f64,
    /// Fraction of nodes the parsimonious evaluation visited.
    pub nodes_evaluated_fraction: f64,
    /// The paper's estimate ½·(3/4)^d (§3.2).
    pub estimated_fraction: f64,
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

/// Trains the paper-scale forest once.
pub fn train() -> TrainBench {
    let (_, inputs, targets) = data(1000);
    let clock = Instant::now();
    let trained = forest::train(&spec(inputs.bits), 10, 1, 7, &inputs, &targets, &|| {});
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
/// states.
pub fn predict() -> PredictBench {
    let (codecs, inputs, targets) = data(1024);
    let trained = forest::train(&spec(inputs.bits), 10, 1, 7, &inputs, &targets, &|| {});
    let predictor = Predictor {
        trees: trained.iter().map(|t| (t.id, t.tree.prune())).collect(),
        vote: 1,
    };
    let widths = vec![23; VARIABLES];
    let decode_all = |out: &[Columns]| -> usize {
        let mut sum = 0;
        for s in 0..inputs.count {
            for (v, c) in out.iter().enumerate() {
                let bits = (0..23).fold(0u64, |acc, b| {
                    acc | (c.column(b)[s / 64] >> (s % 64) & 1) << b
                });
                sum += codecs[v].decode(&[bits]);
            }
        }
        sum
    };
    let clock = Instant::now();
    let out = predictor.predict(&inputs, &widths);
    std::hint::black_box(decode_all(&out));
    let batched_ns_per_state = clock.elapsed().as_nanos() as f64 / inputs.count as f64;

    // One sample at a time, parsimoniously, over 64 samples.
    let samples = 64;
    let mut visited = 0usize;
    let clock = Instant::now();
    for s in 0..samples {
        let row: Vec<u64> = {
            let mut row = vec![0u64; inputs.bits.div_ceil(64)];
            for b in 0..inputs.bits {
                row[b / 64] |= (inputs.column(b)[s / 64] >> (s % 64) & 1) << (b % 64);
            }
            row
        };
        for (v, codec) in codecs.iter().enumerate() {
            let mut bits = 0u64;
            for b in 0..23 {
                let (value, n) = trained[v * 23 + b].tree.evaluate_parsimonious(&row);
                visited += n;
                bits |= u64::from(value) << b;
            }
            std::hint::black_box(codec.decode(&[bits]));
        }
    }
    let single_ns_per_state = clock.elapsed().as_nanos() as f64 / samples as f64;
    let nodes = (2 * 8192 - 1) * trained.len() * samples;
    PredictBench {
        batched_ns_per_state,
        single_ns_per_state,
        nodes_evaluated_fraction: visited as f64 / nodes as f64,
        estimated_fraction: 0.5 * 0.75f64.powi(13),
    }
}
