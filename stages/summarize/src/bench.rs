//! `alnlab bench summarize`: the summarize stage on 10⁷ one-step errors —
//! three models × 64 variables × 52 084 test rows, errors mostly small with
//! a long tail, as predictions are — plus closed-loop errors (10 horizons ×
//! 100 starts per model and variable): read, summarized and written.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use alnlab_common::table;
use alnlab_common::{Error, Provenance, Result, Silent};
use arrow_array::{Array, DictionaryArray, StringArray, UInt16Array, UInt32Array};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// The figures of `alnlab bench summarize`, with stable keys for `--json`.
#[derive(Debug, Serialize)]
pub struct SummarizeBench {
    pub seconds: f64,
    pub errors: u64,
    pub errors_per_s: f64,
}

const MODELS: [&str; 3] = ["aln", "persistence", "linear"];
const VARIABLES: usize = 64;
const ROWS: usize = 52_084;

/// Writes the predictions (untimed), then times the stage on them.
pub fn run() -> Result<SummarizeBench> {
    let temp = std::env::temp_dir();
    let dir = tempfile::tempdir().map_err(|e| Error::io(&temp, e))?;
    let provenance = Provenance {
        stage: "bench".into(),
        params: serde_json::Value::Null,
        inputs: BTreeMap::new(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let total = MODELS.len() * VARIABLES * ROWS;
    let (mut model, mut variable) = (Vec::with_capacity(total), Vec::with_capacity(total));
    let mut error = Vec::with_capacity(total);
    for m in 0..MODELS.len() {
        for v in 0..VARIABLES {
            for _ in 0..ROWS {
                model.push(m as u16);
                variable.push(v as u16);
                // Geometric-ish: each further level a third as likely.
                let mut e = 0u16;
                while e < 213 && rng.random_bool(1.0 / 3.0) {
                    e += 1;
                }
                error.push(e);
            }
        }
    }
    let names: Vec<String> = (0..VARIABLES).map(|v| format!("v.{v}.x")).collect();
    let dictionary = |keys: Vec<u16>, values: Vec<&str>| {
        DictionaryArray::new(UInt16Array::from(keys), Arc::new(StringArray::from(values)))
    };
    let rows: Vec<u32> = (0..total).map(|i| (i % ROWS) as u32).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    // The rollout: the first 1000 errors of each model and variable, as 10
    // horizons × 100 starts.
    let keep: Vec<usize> = (0..total).filter(|i| i % ROWS < 1000).collect();
    let pick = |column: &[u16]| -> Vec<u16> { keep.iter().map(|&i| column[i]).collect() };
    let horizons = keep.iter().map(|i| (i % ROWS / 100) as u16 + 1);
    let starts = keep.iter().map(|i| (i % 100) as u32);
    let rollout = table::batch(vec![
        (
            "model",
            Arc::new(dictionary(pick(&model), MODELS.to_vec())) as Arc<dyn Array>,
        ),
        (
            "variable",
            Arc::new(dictionary(pick(&variable), names.clone())),
        ),
        ("horizon", Arc::new(UInt16Array::from_iter_values(horizons))),
        ("start", Arc::new(UInt32Array::from_iter_values(starts))),
        ("error", Arc::new(UInt16Array::from(pick(&error)))),
    ]);
    let rollout_path = dir.path().join("rollout.parquet");
    table::write_parquet(&rollout_path, &rollout, &provenance)?;
    let batch = table::batch(vec![
        (
            "model",
            Arc::new(dictionary(model, MODELS.to_vec())) as Arc<dyn Array>,
        ),
        ("variable", Arc::new(dictionary(variable, names))),
        ("row", Arc::new(UInt32Array::from(rows))),
        ("error", Arc::new(UInt16Array::from(error))),
    ]);
    let predictions = dir.path().join("predictions.parquet");
    table::write_parquet(&predictions, &batch, &provenance)?;

    let clock = Instant::now();
    crate::run(
        &predictions,
        &rollout_path,
        &provenance,
        dir.path(),
        &Silent,
    )?;
    let seconds = clock.elapsed().as_secs_f64();
    let errors = (total + keep.len()) as u64;
    Ok(SummarizeBench {
        seconds,
        errors,
        errors_per_s: errors as f64 / seconds,
    })
}
