//! `alnlab bench quantize`: quantization and coding speed on one core.

use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use alnlab_codes::Quantizer;
use alnlab_codes::bits::encode;
use alnlab_codes::codes::{Code, Codec};
use alnlab_codes::walk::WalkSpec;

/// The figures of `alnlab bench quantize`, with stable keys for `--json`.
#[derive(Debug, Serialize)]
pub struct QuantizeBench {
    /// Values quantized and encoded (walk, L = 214, W = 23) into a bit matrix per second.
    pub quantize_encode_values_per_s: f64,
    /// Nearest-code decodes of the walk code (W = 23, L = 214) per second.
    pub walk_decodes_per_s: f64,
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// Runs both benchmarks, `repeat` timed runs each.
pub fn run(repeat: usize) -> QuantizeBench {
    let walk = Codec::new(
        Code::Walk,
        214,
        Some(WalkSpec {
            levels: 214,
            width: 23,
            step: 1,
            span: 7,
            seed: 1,
        }),
    )
    .expect("the paper's walk exists");
    let (rows, vars) = (100_000, 16);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let data: Vec<Vec<f64>> = (0..vars)
        .map(|_| (0..rows).map(|_| rng.random_range(-600.0..600.0)).collect())
        .collect();
    let q = Quantizer {
        min: -500.0,
        max: 500.0,
        levels: 214,
    };
    let codecs = vec![&walk; vars];
    let mut levels: Vec<Vec<u16>> = vec![vec![0; rows]; vars];
    let encode_s = median(
        (0..repeat)
            .map(|_| {
                let clock = Instant::now();
                for (column, values) in levels.iter_mut().zip(&data) {
                    for (l, &x) in column.iter_mut().zip(values) {
                        *l = q.level(x).0;
                    }
                }
                let columns: Vec<&[u16]> = levels.iter().map(Vec::as_slice).collect();
                let matrix = encode(&codecs, &columns);
                std::hint::black_box(&matrix);
                clock.elapsed().as_secs_f64()
            })
            .collect(),
    );
    let patterns: Vec<u64> = (0..1_000_000)
        .map(|_| rng.random::<u64>() & ((1 << 23) - 1))
        .collect();
    let decode_s = median(
        (0..repeat)
            .map(|_| {
                let clock = Instant::now();
                let sum: usize = patterns
                    .iter()
                    .map(|p| walk.decode(std::slice::from_ref(p)))
                    .sum();
                std::hint::black_box(sum);
                clock.elapsed().as_secs_f64()
            })
            .collect(),
    );
    QuantizeBench {
        quantize_encode_values_per_s: (rows * vars) as f64 / encode_s,
        walk_decodes_per_s: patterns.len() as f64 / decode_s,
    }
}
