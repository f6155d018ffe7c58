//! `alnlab bench train` on real data: the paper's worm simulated, paired and
//! quantized by the stages themselves, then the train stage timed on it.

use std::path::Path;

use alnlab_aln::model::Model;
use alnlab_common::Result;
use alnlab_common::table::Table;
use alnlab_train::bench::TrainBench;
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
        reports: None,
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

/// `alnlab bench shards`: a manifest's forest trained in one process
/// against the same forest trained in N processes (one shard each) and
/// merged.
#[derive(Debug, serde::Serialize)]
pub struct ShardBench {
    pub shards: u32,
    pub trees: usize,
    /// The train stage in-process, all cores (s).
    pub in_process_seconds: f64,
    /// The N shard processes side by side, start to last exit (s).
    pub processes_seconds: f64,
    /// Merging the N partial models (s).
    pub merge_seconds: f64,
    /// (processes + merge) / in-process.
    pub ratio: f64,
    /// Whether the merged model file equals the in-process one byte for byte.
    pub identical: bool,
}

/// Brings `manifest`'s variant up to quantize in a temporary folder, then
/// trains its forest in-process and as `shards` processes of this binary
/// (`train --shard K/N`, each given its share of the cores), and merges.
pub fn shards(manifest_path: &Path, variant: &str, shards: u32) -> Result<ShardBench> {
    use alnlab_aln::shard::Shard;
    use alnlab_common::Error;
    use alnlab_train::shard;
    use std::time::Instant;

    let manifest = Manifest::load(manifest_path)?;
    let variant = manifest.variant(variant)?;
    let temp = std::env::temp_dir();
    let dir = tempfile::tempdir().map_err(|e| Error::io(&temp, e))?;
    let options = RunOptions {
        out: dir.path().join("runs"),
        force: false,
        variant: None,
        quiet: true,
        datasets: Path::new("datasets").to_path_buf(),
        until: None,
        reports: None,
    };
    let run::TrainInputs { inputs, provenance } = run::up_to_train(&manifest, &options, variant)?;
    let (codebook, levels) = (&inputs["codebook"], &inputs["levels"]);
    let seed = manifest.experiment.seed;

    let whole = dir.path().join("whole");
    let clock = Instant::now();
    alnlab_train::run(
        &variant.stages.train,
        seed,
        Shard::ALL,
        &alnlab_train::Inputs {
            codebook,
            levels,
            pairs: &inputs["pairs"],
            nominal: &inputs["nominal"],
        },
        &provenance,
        &whole,
        &alnlab_common::progress::Silent,
    )?;
    let in_process_seconds = clock.elapsed().as_secs_f64();

    let exe = std::env::current_exe().map_err(|e| Error::io(Path::new("alnlab"), e))?;
    let threads = (rayon::current_num_threads() / shards as usize).max(1);
    let parts: Vec<_> = (1..=shards)
        .map(|k| dir.path().join(format!("part-{k}")))
        .collect();
    let clock = Instant::now();
    let children = parts
        .iter()
        .zip(1..=shards)
        .map(|(out, k)| {
            std::process::Command::new(&exe)
                .env("RAYON_NUM_THREADS", threads.to_string())
                .arg("-q")
                .arg("train")
                .arg("--manifest")
                .arg(manifest_path)
                .args([
                    "--variant",
                    &variant.name,
                    "--shard",
                    &format!("{k}/{shards}"),
                ])
                .arg("--codebook")
                .arg(codebook)
                .arg("--levels")
                .arg(levels)
                .arg("--pairs")
                .arg(&inputs["pairs"])
                .arg("--nominal")
                .arg(&inputs["nominal"])
                .arg("--out")
                .arg(out)
                .stdout(std::process::Stdio::null())
                .spawn()
                .map_err(|e| Error::io(&exe, e))
        })
        .collect::<Result<Vec<_>>>()?;
    for (k, mut child) in (1..=shards).zip(children) {
        let status = child.wait().map_err(|e| Error::io(&exe, e))?;
        if !status.success() {
            return Err(Error::Invalid(format!(
                "bench: shard {k}/{shards} failed ({status})"
            )));
        }
    }
    let processes_seconds = clock.elapsed().as_secs_f64();
    let merged = dir.path().join("merged");
    let clock = Instant::now();
    shard::merge(&parts, &provenance, &merged)?;
    let merge_seconds = clock.elapsed().as_secs_f64();

    let model =
        |d: &Path| std::fs::read(d.join(alnlab_train::MODEL_FILE)).map_err(|e| Error::io(d, e));
    let identical = model(&whole)? == model(&merged)?;
    Ok(ShardBench {
        shards,
        trees: Model::read(&whole.join(alnlab_train::MODEL_FILE))?
            .trees
            .len(),
        in_process_seconds,
        processes_seconds,
        merge_seconds,
        ratio: (processes_seconds + merge_seconds) / in_process_seconds,
        identical,
    })
}
