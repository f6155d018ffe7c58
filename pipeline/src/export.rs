//! `alnlab export snakemake`: an experiment as a Snakemake workflow, for
//! running its stages as separate jobs — on one machine or a cluster.
//!
//! Every rule calls the `alnlab` binary on the same output folder `alnlab
//! run` uses, one stage at a time (`run --until STAGE`), training in N
//! shards (`run --train-shard K/N`) that the train rule merges (a
//! piecewise-linear variant's few trees in one job: `unsharded`); the last
//! rule is `alnlab run` itself, which finds every artifact cached and writes
//! the run record and report. So a workflow run and `alnlab run` share the
//! cache and the run record. Rules mark their completion with empty files
//! under `<out>/<experiment>/snakemake/<variant>/`, which is how Snakemake
//! knows what is done and resumes a failed workflow without redoing it.

use std::path::{Path, PathBuf};

use alnlab_aln::ModelKind;
use alnlab_common::{Error, Result, atomic};

use crate::manifest::Manifest;
use crate::stages::{self, Hints, STAGES};

/// What to export.
pub struct Export<'a> {
    pub manifest: &'a Manifest,
    /// The `alnlab` binary the rules call.
    pub alnlab: PathBuf,
    /// Training shards per variant (1: train in one job).
    pub shards: u32,
    /// The output folder, reports folder and dataset archive of the run.
    pub out: PathBuf,
    pub reports: PathBuf,
    pub datasets: PathBuf,
}

/// The Snakefile; everything that varies is in `config.yaml`.
const SNAKEFILE: &str = include_str!("Snakefile");

/// Writes `Snakefile` and `config.yaml` into `dir`.
pub fn snakemake(export: &Export, dir: &Path) -> Result<()> {
    let absolute = |path: &Path| -> Result<String> {
        let path = std::path::absolute(path).map_err(|e| Error::io(path, e))?;
        Ok(path.display().to_string())
    };
    let manifest = export.manifest;
    let variants: Vec<&str> = manifest.variants.iter().map(|v| v.name.as_str()).collect();
    // A piecewise-linear model's few trees train in one process: never
    // sharded (`run --train-shard` refuses it).
    let unsharded: Vec<&str> = manifest
        .variants
        .iter()
        .filter(|v| match v.stages.train.model {
            ModelKind::PiecewiseLinear => true,
            ModelKind::BitForest | ModelKind::Threshold => false,
        })
        .map(|v| v.name.as_str())
        .collect();
    // A hint, generous: the trees of the paper's forest (8192 leaves, one
    // voter) take 62 MiB while training, and the data less.
    let leaves = manifest
        .variants
        .iter()
        .map(|v| v.stages.train.leaves.get() * v.stages.train.vote.get())
        .max()
        .unwrap_or(1);
    let forest_mb = (leaves / 64) as u64;
    // Resource hints per rule: each stage's from the stage table, then the
    // workflow's own rules (a training shard holds a forest as train does).
    let mut hints: Vec<(&str, Hints)> = STAGES.iter().map(|s| (s.name, s.hints)).collect();
    let train = stages::sharded();
    hints.push((
        "train_shard",
        Hints {
            threads: 1,
            ..train.hints
        },
    ));
    // The rounds of the planner's own data: training and planning again.
    let plan = stages::find("plan").expect("a plan stage");
    hints.push((
        "rounds",
        Hints {
            runtime: plan.hints.runtime + train.hints.runtime,
            mem_mb: plan.hints.mem_mb.max(train.hints.mem_mb),
            ..train.hints
        },
    ));
    hints.push((
        "run_record",
        Hints {
            threads: 1,
            mem_mb: 1024,
            runtime: 10,
            holds_forest: false,
        },
    ));
    let line = |value: &dyn Fn(&Hints) -> u64| {
        let entries: Vec<String> = hints
            .iter()
            .map(|(rule, h)| format!("{rule}: {}", value(h)))
            .collect();
        format!("{{{}}}", entries.join(", "))
    };
    let config = format!(
        "# Written by `alnlab export snakemake` for {manifest_path}; edit freely.\n\
         # `alnlab` is the binary the rules call: on a cluster, a path every node can run.\n\
         alnlab: {alnlab:?}\n\
         manifest: {manifest_file:?}\n\
         experiment: {experiment:?}\n\
         variants: [{variants}]\n\
         # Variants whose model trains in one job whatever `shards` says.\n\
         unsharded: [{unsharded}]\n\
         stages: [{stages}]\n\
         sharded_stage: {sharded:?}\n\
         out: {out:?}\n\
         reports: {reports:?}\n\
         datasets: {datasets:?}\n\
         shards: {shards}\n\
         # Resource hints per rule: threads (cores), memory (MB), run time (minutes).\n\
         threads: {threads}\n\
         mem_mb: {mem_mb}\n\
         runtime: {runtime}\n",
        stages = STAGES
            .iter()
            .map(|s| format!("{:?}", s.name))
            .collect::<Vec<_>>()
            .join(", "),
        sharded = train.name,
        threads = line(&|h| u64::from(h.threads)),
        mem_mb = line(&|h| h.mem_mb + if h.holds_forest { forest_mb } else { 0 }),
        runtime = line(&|h| u64::from(h.runtime)),
        manifest_path = manifest.path.display(),
        alnlab = absolute(&export.alnlab)?,
        manifest_file = absolute(&manifest.path)?,
        experiment = manifest.experiment.name,
        variants = quoted(&variants),
        unsharded = quoted(&unsharded),
        out = absolute(&export.out)?,
        reports = absolute(&export.reports)?,
        datasets = absolute(&export.datasets)?,
        shards = export.shards,
    );
    atomic::write_bytes(&dir.join("config.yaml"), config.as_bytes())?;
    atomic::write_bytes(&dir.join("Snakefile"), SNAKEFILE.as_bytes())
}

/// `names` as YAML list items: `"a", "b-2"`.
fn quoted(names: &[&str]) -> String {
    names
        .iter()
        .map(|v| format!("{v:?}"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_config_names_every_variant_and_absolute_paths() {
        let text = "[experiment]\nname = \"x\"\nseed = 1\n\n[[simulate.scene]]\nname = \"s\"\n\n\
                    [[variant]]\nname = \"a\"\n\n[[variant]]\nname = \"b-2\"\n\
                    train.model = \"piecewise-linear\"\n";
        let manifest = Manifest::parse(text, Path::new("m.toml")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let export = Export {
            manifest: &manifest,
            alnlab: "alnlab".into(),
            shards: 4,
            out: "runs".into(),
            reports: "reports".into(),
            datasets: "datasets".into(),
        };
        snakemake(&export, dir.path()).unwrap();
        let config = std::fs::read_to_string(dir.path().join("config.yaml")).unwrap();
        assert!(config.contains("variants: [\"a\", \"b-2\"]"), "{config}");
        assert!(config.contains("shards: 4"), "{config}");
        assert!(config.contains("unsharded: [\"b-2\"]"), "{config}");
        let out = std::path::absolute("runs").unwrap();
        assert!(
            config.contains(&format!("out: {:?}", out.display().to_string())),
            "{config}"
        );
        let snakefile = std::fs::read_to_string(dir.path().join("Snakefile")).unwrap();
        assert!(snakefile.contains("rule train_shard:"));
        assert!(snakefile.contains("rule rounds:") && snakefile.contains("--until rounds"));
        assert!(config.contains("rounds: "), "{config}");
    }
}
