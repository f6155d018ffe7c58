//! `alnlab bench summarize`: the summarize stage on 10⁷ one-step errors —
//! three models × 64 variables × 52 084 test rows, errors mostly small with
//! a long tail, as predictions are — plus closed-loop errors (10 horizons ×
//! 100 starts per model and variable): read, summarized and written.

use std::collections::BTreeMap;
use std::time::Instant;

use alnlab_common::{Error, ModelId, Provenance, Result, Silent};
use alnlab_tables::predictions::Predictions;
use alnlab_tables::rollout::Rollout;
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

const MODELS: [ModelId; 3] = [ModelId::Aln, ModelId::Persistence, ModelId::Linear];
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
    let names: Vec<String> = (0..VARIABLES).map(|v| format!("v.{v}.x")).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let rows: Vec<u32> = (0..ROWS as u32).collect();
    // Every row held out, every true level 100: a prediction's error is its
    // distance from 100.
    let mut predictions = Predictions::new(
        &names,
        &[None; VARIABLES],
        &rows,
        &[true; ROWS],
        &vec![vec![100; ROWS]; VARIABLES],
    );
    // The rollout: the first 1000 errors of each model and variable, as 10
    // horizons × 100 starts.
    let starts: Vec<u32> = (0..100).collect();
    let mut rollout = Rollout::new(&names, &starts, 10);
    for model in MODELS {
        let levels: Vec<Vec<u16>> = (0..VARIABLES)
            .map(|_| {
                (0..ROWS)
                    .map(|_| {
                        // Geometric-ish: each further level a third as likely.
                        let mut e = 0u16;
                        while e < 213 && rng.random_bool(1.0 / 3.0) {
                            e += 1;
                        }
                        if rng.random_bool(0.5) {
                            100 + e
                        } else {
                            100 - e.min(100)
                        }
                    })
                    .collect()
            })
            .collect();
        let errors: Vec<Vec<Vec<u16>>> = (0..10)
            .map(|h| {
                levels
                    .iter()
                    .map(|l| {
                        l[100 * h..100 * (h + 1)]
                            .iter()
                            .map(|&p| p.abs_diff(100))
                            .collect()
                    })
                    .collect()
            })
            .collect();
        predictions.push_model(model, &levels);
        rollout.push_model(model, &errors);
    }
    let rollout_path = dir.path().join(alnlab_tables::rollout::FILE);
    rollout.write(&rollout_path, &provenance)?;
    let predictions_path = dir.path().join(alnlab_tables::predictions::FILE);
    predictions.write(&predictions_path, &provenance)?;

    let clock = Instant::now();
    let inputs = crate::Inputs {
        predictions: &predictions_path,
        rollout: &rollout_path,
    };
    crate::run(&inputs, &provenance, dir.path(), &Silent)?;
    let seconds = clock.elapsed().as_secs_f64();
    let errors = (MODELS.len() * VARIABLES * (ROWS + 1000)) as u64;
    Ok(SummarizeBench {
        seconds,
        errors,
        errors_per_s: errors as f64 / seconds,
    })
}
