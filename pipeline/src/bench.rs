//! `alnlab bench train` on real data: the paper's worm simulated, paired and
//! quantized by the stages themselves, then the train stage timed on it.

use std::path::Path;

use alnlab_common::Result;
use alnlab_common::table::Table;
use alnlab_train::bench::TrainBench;
use alnlab_train::model::Model;
use arrow_array::UInt64Array;

use crate::manifest::Manifest;
use crate::run::{self, RunOptions};

/// The experiment whose train stage is timed.
const MANIFEST: &str = include_str!("bench_worm.toml");

/// Runs the worm experiment in a temporary folder and returns the train
/// stage's figures (the stage's own wall time, model writing included).
pub fn worm_training() -> Result<TrainBench> {
    let temp = std::env::temp_dir();
    let dir = tempfile::tempdir().map_err(|e| alnlab_common::Error::io(&temp, e))?;
    let path = dir.path().join("bench-worm.toml");
    let manifest = Manifest::parse(MANIFEST, &path).expect("the embedded manifest is valid");
    let options = RunOptions {
        out: dir.path().join("runs"),
        force: false,
        variant: None,
        quiet: true,
        datasets: dir.path().join("datasets"),
        until: None,
    };
    let record = run::run(&manifest, &options)?;
    let variant = &record.variants[0];
    let train = variant
        .stages
        .iter()
        .find(|s| s.stage == "train")
        .expect("the experiment trains");
    let artifact = |role: &str| Path::new(&variant.artifacts[role].path).to_path_buf();
    let model = Model::read(&artifact("model"))?;
    let log = Table::read(&artifact("training"))?;
    let updates: u64 = log.column::<UInt64Array>("updates")?.values().iter().sum();
    Ok(TrainBench {
        seconds: train.compute_seconds,
        trees: model.trees.len(),
        node_updates_per_s: updates as f64 / train.compute_seconds,
        threads: rayon::current_num_threads(),
    })
}
