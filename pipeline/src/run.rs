//! `alnlab run`: the stage graph of one manifest, executed in-process through
//! the artifact cache, with a run record at the end.
//!
//! The graph is simulate → stride → quantize → train → test → summarize; a
//! manifest with `[data] dataset` starts instead from an archived dataset
//! (restored into the cache as a `dataset` artifact), which stands for
//! simulate and stride — and quantize, when it holds levels. For every
//! variant, each stage's cache key is computed from its parameters and its
//! inputs' hashes; a stage runs only when no finished artifact has that key
//! (or with `--force`). Restored files hash as the originals did, so the
//! stages after a dataset have the same keys, and make the same bytes, as in
//! the run it was archived from.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{self, File};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

use alnlab_common::{ALNLAB_VERSION, Error, Provenance, Result, atomic};

use crate::cache::{Artifact, Cache, StageKey};
use crate::dataset::{Archive, Entry};
use crate::manifest::{Manifest, Variant, replicate_seed};
use crate::progress::{Bar, Overall};
use crate::records::{
    self, ArtifactRef, DatasetRef, RecordingRef, RunRecord, StageRecord, TableRef, VariantRecord,
};
use crate::stages::{self, Archived, Call, STAGES, Stage, stage_params};
use alnlab_aln::shard::Shard;
use alnlab_ingest::TableFile;

/// How to run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// The output folder (cache, run records).
    pub out: PathBuf,
    /// Re-run every stage even if its artifact is cached.
    pub force: bool,
    /// Run only this variant.
    pub variant: Option<String>,
    /// No progress bars.
    pub quiet: bool,
    /// The dataset archive `[data] dataset` refers to.
    pub datasets: PathBuf,
    /// Stop after this stage (one of the stage table's): no run record, no
    /// report.
    /// How a workflow engine runs the graph one stage at a time.
    pub until: Option<String>,
    /// Where the report is published (`--reports`), if anywhere: the
    /// checkout's changes the record keeps leave that folder out.
    pub reports: Option<PathBuf>,
}

/// Version of the `dataset` artifact's layout (part of its cache key).
const DATASET_FORMAT_VERSION: u32 = 1;

/// Holds the output folder's lock for the duration of a run; a second run on
/// the same folder waits (saying so) until the first is done.
pub struct OutLock {
    _file: File,
}

impl OutLock {
    /// Takes the lock on `out`, waiting for another holder if there is one.
    pub fn acquire(out: &Path) -> Result<OutLock> {
        atomic::create_dir(out)?;
        let path = out.join(".lock");
        let mut file = File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        if file.try_lock().is_err() {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            eprintln!(
                "waiting: another alnlab run (pid {}) is using {}",
                holder.trim(),
                out.display()
            );
            file.lock().map_err(|e| Error::io(&path, e))?;
        }
        file.set_len(0).map_err(|e| Error::io(&path, e))?;
        file.rewind().map_err(|e| Error::io(&path, e))?;
        write!(file, "{}", std::process::id()).map_err(|e| Error::io(&path, e))?;
        Ok(OutLock { _file: file })
    }
}

/// Runs the manifest's variants (or the one chosen) and writes the run record.
pub fn run(manifest: &Manifest, options: &RunOptions) -> Result<RunRecord> {
    let started = SystemTime::now();
    // The checkout as the run found it: what its record and report name.
    let git_commit = crate::git::commit(&manifest.path);
    let git_changes = crate::git::changes(&manifest.path, options.reports.as_deref());
    let clock = Instant::now();
    let variants: Vec<&Variant> = match &options.variant {
        Some(name) => vec![manifest.variant(name)?],
        None => manifest.variants.iter().collect(),
    };
    let archive = Archive::new(&options.datasets);
    let dataset = match manifest.data.as_ref().and_then(|d| d.dataset.as_ref()) {
        Some(dataset) => {
            let entry = archive
                .find_pinned(dataset)
                .map_err(|e| e.context(&format!("{}: [data] dataset", manifest.path.display())))?;
            archive.require_whole(&entry)?;
            let reads_tables = variants.iter().any(|v| v.stages.ingest.robot.is_some());
            match (reads_tables, entry.tables().is_empty()) {
                (true, true) => {
                    return Err(Error::Invalid(format!(
                        "{}: [data] dataset: {} holds a run's data, not tables of recordings; \
                         remove [ingest] (its data need no framing)",
                        manifest.path.display(),
                        entry.label()
                    )));
                }
                (false, false) => {
                    return Err(Error::Invalid(format!(
                        "{}: [data] dataset: {} holds tables of recordings: frame them with \
                         [ingest.table] and [ingest.robot]",
                        manifest.path.display(),
                        entry.label()
                    )));
                }
                _ => {}
            }
            for variant in &variants {
                let set = STAGES
                    .iter()
                    .filter(|s| s.archived == Archived::WithLevels)
                    .find(|s| variant.tables.contains(s.name));
                if let Some(stage) = set.filter(|_| entry.has_levels()) {
                    return Err(Error::Invalid(format!(
                        "{}: variant `{}`: dataset {} holds quantized levels, so the {} stage \
                         does not run; remove `{}` (or archive the dataset without levels)",
                        manifest.path.display(),
                        variant.name,
                        entry.label(),
                        stage.name,
                        stage.name
                    )));
                }
            }
            Some(entry)
        }
        None => None,
    };
    // An archived dataset of recordings is read by the ingest stage, table
    // by table from the archive (verified above); a run's data stand for
    // the first stages.
    let (dataset, archived_tables) = match dataset {
        Some(entry) if !entry.tables().is_empty() => {
            let tables: Vec<TableFile> = entry
                .tables()
                .iter()
                .map(|f| TableFile {
                    file: format!("{}/{}", entry.label(), f.name),
                    sha256: f.sha256.clone(),
                    path: archive.object(&f.sha256),
                })
                .collect();
            (Some(entry), Some(tables))
        }
        other => (other, None),
    };
    // The archived tables' trajectories (`[ingest] repeats` names them),
    // checked once a variant before anything runs.
    if let Some(tables) = &archived_tables {
        for variant in &variants {
            let mut ingest = variant.stages.ingest.clone();
            ingest.tables = tables.clone();
            ingest.trajectories().map_err(|(field, message)| {
                Error::Invalid(format!(
                    "{}: `ingest.{field}`: {message}",
                    manifest.path.display()
                ))
            })?;
        }
    }
    let stood_for = dataset.as_ref().filter(|_| archived_tables.is_none());
    let _lock = OutLock::acquire(&options.out)?;
    let cache = Cache::new(&options.out);
    cache.sweep_unfinished()?;
    let mut made_now = BTreeSet::new();
    let mut records = Vec::new();
    let replicates = manifest.experiment.replicates.0 as u32;
    let overall = Overall::new(options.quiet);
    let count = variants.len();
    for (k, variant) in variants.iter().enumerate() {
        for replicate in 0..replicates {
            let mut variant = variant.for_replicate(replicate);
            if let Some(tables) = &archived_tables {
                variant.stages.ingest.tables = tables.clone();
            }
            let variant = &variant;
            let seed = replicate_seed(manifest.experiment.seed, replicate);
            let mut graph = Graph {
                manifest,
                options,
                cache: &cache,
                dataset: stood_for.map(|entry| (&archive, entry)),
                made_now: &mut made_now,
                seed,
                label: if replicates > 1 {
                    format!("{} #{}", variant.name, replicate + 1)
                } else {
                    variant.name.clone()
                },
                overall: &overall,
                place: if replicates > 1 {
                    format!(
                        "variant {} of {count}: {}, replicate {} of {replicates}",
                        k + 1,
                        variant.name,
                        replicate + 1
                    )
                } else {
                    format!("variant {} of {count}: {}", k + 1, variant.name)
                },
                record: VariantRecord {
                    name: variant.name.clone(),
                    description: variant.description.clone(),
                    replicate,
                    seed,
                    artifacts: BTreeMap::new(),
                    stages: Vec::new(),
                    parameters: manifest.parameters(variant),
                    resolved: Some(
                        serde_json::to_value(&variant.stages)
                            .expect("resolved parameters serialize to JSON"),
                    ),
                    metrics: None,
                },
                round: 0,
            };
            graph.run_variant(variant)?;
            records.push(graph.record);
        }
    }
    if options.until.is_none() {
        for record in &mut records {
            record.metrics = Some(records::read_metrics(record, |a| {
                Some(PathBuf::from(&a.path))
            })?);
        }
    }
    let record = RunRecord {
        format: records::FORMAT,
        id: records::new_id(started, &manifest.experiment.name, &manifest.sha256),
        experiment: manifest.experiment.name.clone(),
        manifest_path: crate::git::repository_path(&manifest.path),
        manifest_sha256: manifest.sha256.clone(),
        seed: manifest.experiment.seed,
        alnlab_version: ALNLAB_VERSION.into(),
        git_commit,
        git_changes,
        started: humantime::format_rfc3339_millis(started).to_string(),
        finished: humantime::format_rfc3339_millis(SystemTime::now()).to_string(),
        wall_seconds: clock.elapsed().as_secs_f64(),
        variants: records,
        compare_with_paper: manifest.experiment.compare_with_paper,
        description: manifest.experiment.description.clone(),
        notes: manifest.experiment.notes.clone(),
        answer: manifest.experiment.answer.clone(),
        dataset: dataset.as_ref().map(|entry| DatasetRef {
            dataset: entry.label(),
            sha256: entry.sha256.clone(),
        }),
        recording: manifest.data.as_ref().and_then(|d| {
            let ingest = &manifest.variants.first()?.stages.ingest;
            Some(RecordingRef {
                recording: d.recording.clone()?,
                sha256: ingest.recording_sha256.clone()?,
                topic: ingest.topic.clone(),
            })
        }),
        tables: archived_tables
            .as_deref()
            .or(manifest
                .variants
                .first()
                .map(|v| &v.stages.ingest.tables[..]))
            .unwrap_or_default()
            .iter()
            .map(|t| TableRef {
                file: t.file.clone(),
                sha256: t.sha256.clone(),
            })
            .collect(),
    };
    if options.until.is_none() {
        records::store(&options.out, &record)?;
    }
    Ok(record)
}

/// One variant's walk through the stages.
struct Graph<'a> {
    manifest: &'a Manifest,
    options: &'a RunOptions,
    cache: &'a Cache,
    /// The archived dataset standing for the first stages, if any.
    dataset: Option<(&'a Archive, &'a Entry)>,
    /// Keys made by this run, so `--force` makes shared artifacts only once.
    made_now: &'a mut BTreeSet<String>,
    /// The replicate's seed, which every stage's parameters carry.
    seed: u64,
    /// The variant (and replicate) as progress and errors name it.
    label: String,
    /// The run's overall progress line, and where this variant is in it.
    overall: &'a Overall,
    place: String,
    record: VariantRecord,
    /// The round of the planner's own data being made (0: the first plan).
    round: usize,
}

impl Graph<'_> {
    /// Walks the stage table for `variant`: each stage finds or makes its
    /// artifact from the artifacts of the stages it reads; an archived
    /// dataset stands for the stages it holds.
    fn run_variant(&mut self, variant: &Variant) -> Result<()> {
        let seed = self.seed;
        let archived = match self.dataset {
            Some((archive, entry)) => Some((self.dataset_stage(archive, entry)?, entry)),
            None => None,
        };
        let mut made: BTreeMap<&str, Artifact> = BTreeMap::new();
        for (j, stage) in STAGES.iter().enumerate() {
            self.overall
                .at(&self.place, (j + 1, STAGES.len()), stage.name);
            if self.record.replicate > 0 && !stage.every_replicate {
                if self.options.until.as_deref() == Some(stage.name) {
                    break;
                }
                continue;
            }
            let from_archive = archived
                .as_ref()
                .filter(|(_, entry)| stage.archived.holds(entry.has_levels()));
            let ingest = &variant.stages.ingest;
            let recorded = (ingest.recording.is_some() || !ingest.tables.is_empty())
                && stage.name == "simulate";
            let artifact = match from_archive {
                Some((artifact, _)) => artifact.clone(),
                // A recording stands where the simulation would, the same
                // for every replicate (no seed in its key).
                None if recorded => {
                    let params = stage_params(0, (stages::INGEST.params)(&variant.stages));
                    self.stage(&stages::INGEST, &params, &[], variant)?
                }
                None => {
                    let inputs: Vec<(&'static str, &Artifact)> = stage
                        .inputs
                        .iter()
                        .map(|i| (i.role, &made[i.from]))
                        .collect();
                    let params = stage_params(seed, (stage.params)(&variant.stages));
                    self.stage(stage, &params, &inputs, variant)?
                }
            };
            made.insert(stage.name, artifact);
            if self.options.until.as_deref() == Some(stage.name) {
                break;
            }
        }
        let rounds = variant.stages.plan.rounds;
        let through = matches!(self.options.until.as_deref(), None | Some(stages::ROUNDS));
        if rounds > 0 && through && made.contains_key("plan") {
            self.rounds(variant, &made, rounds)?;
        }
        Ok(())
    }

    /// The planner's own data, round by round (`[plan] rounds`; DAgger for
    /// models): the frames the ALN's planners executed join the training
    /// pairs (the aggregate stage), the model is trained again, and the
    /// learned models plan the same episodes with it — the simulators,
    /// whose plans no data change, are not planned again. Each round's
    /// artifacts are recorded as `<role>@<round>`, its stages as
    /// `<stage>@<round>`.
    fn rounds(
        &mut self,
        variant: &Variant,
        made: &BTreeMap<&str, Artifact>,
        rounds: usize,
    ) -> Result<()> {
        let (train, plan) = (
            stages::find("train").expect("a train stage"),
            stages::find("plan").expect("a plan stage"),
        );
        let mut learned_only = variant.clone();
        learned_only.stages.plan.simulator_steps.clear();
        learned_only.stages.plan.plant_steps.clear();
        let seed = self.seed;
        let (quantize, simulate) = (&made["quantize"], &made["simulate"]);
        let (mut pairs, mut nominal, mut levels, mut planned) = (
            made["stride"].clone(),
            made["nominal"].clone(),
            quantize.clone(),
            made["plan"].clone(),
        );
        for round in 1..=rounds {
            self.round = round;
            let aggregate = self.stage(
                &stages::AGGREGATE,
                &stage_params(seed, (stages::AGGREGATE.params)(&variant.stages)),
                &[
                    ("pairs", &pairs),
                    ("nominal", &nominal),
                    ("codebook", quantize),
                    ("levels", &levels),
                    ("transitions", &planned),
                    ("transitions-nominal", &planned),
                ],
                variant,
            )?;
            let model = self.stage(
                train,
                &stage_params(seed, (train.params)(&variant.stages)),
                &[
                    ("codebook", quantize),
                    ("levels", &aggregate),
                    ("pairs", &aggregate),
                    ("nominal", &aggregate),
                ],
                variant,
            )?;
            planned = self.stage(
                plan,
                &stage_params(seed, (plan.params)(&learned_only.stages)),
                &[
                    ("trajectory", simulate),
                    ("model", &model),
                    ("codebook", quantize),
                    ("levels", &aggregate),
                ],
                &learned_only,
            )?;
            (pairs, nominal, levels) = (aggregate.clone(), aggregate.clone(), aggregate);
        }
        self.round = 0;
        Ok(())
    }

    /// The archived dataset's files, restored (verified) into the cache as
    /// one artifact keyed by their content.
    fn dataset_stage(&mut self, archive: &Archive, entry: &Entry) -> Result<Artifact> {
        let files: Vec<serde_json::Value> = entry
            .files
            .iter()
            .map(|f| serde_json::json!({ "role": f.role, "name": f.name, "sha256": f.sha256 }))
            .collect();
        let params = serde_json::json!({ "files": files });
        let outputs: Vec<(&str, &str)> = entry
            .files
            .iter()
            .map(|f| (f.role.as_str(), f.name.as_str()))
            .collect();
        self.find_or_make(
            "dataset",
            DATASET_FORMAT_VERSION,
            &params,
            &[],
            &outputs,
            // `run` verified the whole dataset before it began.
            |_, _, dir, _| archive.copy_out(entry, dir),
        )
    }

    /// Finds or makes one stage's artifact: a stage that runs in shards
    /// merges a complete set of finished shards instead of running again.
    fn stage(
        &mut self,
        stage: &'static Stage,
        params: &serde_json::Value,
        inputs: &[(&'static str, &Artifact)],
        variant: &Variant,
    ) -> Result<Artifact> {
        let shards = shard_store(&self.options.out);
        let seed = self.seed;
        let artifact = self.find_or_make(
            stage.name,
            stage.format_version,
            params,
            inputs,
            stage.outputs,
            |provenance, key, dir, bar| {
                if let Some(merge) = stage.merge_shards
                    && let Some(parts) = complete_shards(&shards, stage.name, key)
                {
                    return merge(&parts, provenance, dir);
                }
                (stage.run)(&Call {
                    stages: &variant.stages,
                    seed,
                    inputs: inputs
                        .iter()
                        .map(|&(role, artifact)| (role, artifact.path(role)))
                        .collect(),
                    shard: Shard::ALL,
                    provenance,
                    out_dir: dir,
                    progress: bar,
                })
            },
        )?;
        if stage.merge_shards.is_some() {
            let merged = shards.root().join(stage.name).join(&artifact.record.key);
            if merged.exists() {
                fs::remove_dir_all(&merged).map_err(|e| Error::io(&merged, e))?;
            }
        }
        Ok(artifact)
    }

    /// Finds or makes the artifact of `name` with these parameters and
    /// inputs, and records it; `execute` makes it, given the provenance to
    /// write, the cache key, the folder and a progress bar.
    fn find_or_make(
        &mut self,
        name: &str,
        format_version: u32,
        params: &serde_json::Value,
        inputs: &[(&str, &Artifact)],
        outputs: &[(&str, &str)],
        execute: impl FnOnce(&Provenance, &str, &Path, &Bar) -> Result<()>,
    ) -> Result<Artifact> {
        let clock = Instant::now();
        let input_hashes: BTreeMap<String, String> = inputs
            .iter()
            .map(|(role, artifact)| (role.to_string(), artifact.sha256(role).to_string()))
            .collect();
        let provenance = Provenance {
            stage: name.into(),
            params: params.clone(),
            inputs: input_hashes,
        };
        let key = StageKey::of(&provenance, format_version);
        let reuse = !self.options.force || self.made_now.contains(&key);
        let found = if reuse {
            self.cache.lookup(name, &key)
        } else {
            None
        };
        let cached = found.is_some();
        let artifact = match found {
            Some(artifact) => {
                self.overall.found_cached();
                artifact
            }
            None => {
                let label = format!("{}/{}", self.manifest.experiment.name, self.label);
                let bar = self.overall.bar(&label);
                let context = format!("variant `{}`, stage {name}", self.label);
                let artifact = self
                    .cache
                    .make(name, &key, outputs, |dir| {
                        execute(&provenance, &key, dir, &bar)
                    })
                    .map_err(|e| e.context(&context))?;
                self.made_now.insert(key.clone());
                artifact
            }
        };
        let round = |name: &str| match self.round {
            0 => name.to_string(),
            r => format!("{name}@{r}"),
        };
        for (role, _) in outputs {
            self.record.artifacts.insert(
                round(role),
                ArtifactRef {
                    path: artifact.path(role).display().to_string(),
                    sha256: artifact.sha256(role).to_string(),
                    cache_key: key.clone(),
                },
            );
        }
        self.record.stages.push(StageRecord {
            stage: round(name),
            cache_key: key,
            cached,
            wall_seconds: clock.elapsed().as_secs_f64(),
            compute_seconds: artifact.record.compute_seconds,
        });
        Ok(artifact)
    }
}

/// Where sharded stages keep their parts: `<out>/shards/<stage>/<stage
/// key>/<K>-of-<N>/`, outside the cache (whose sweep of unfinished work must
/// not touch a shard another process is still training).
fn shard_store(out: &Path) -> Cache {
    Cache::at(&out.join("shards"))
}

/// The folders of a complete set of finished shards (1..=N of one N) of
/// `stage` with cache key `key`, if there is one.
fn complete_shards(shards: &Cache, stage: &str, key: &str) -> Option<Vec<PathBuf>> {
    let dir = shards.root().join(stage).join(key);
    let mut counts: Vec<u32> = fs::read_dir(&dir)
        .ok()?
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.split_once("-of-")?.1.parse().ok()
        })
        .collect();
    counts.sort_unstable();
    counts.dedup();
    counts.into_iter().find_map(|count| {
        (1..=count)
            .map(|index| shards.lookup(stage, &shard_key(key, Shard { index, count })))
            .map(|found| found.map(|artifact| artifact.dir))
            .collect()
    })
}

/// A shard's key in the shard store: the stage's key and the shard.
fn shard_key(stage_key: &str, shard: Shard) -> String {
    format!("{stage_key}/{}-of-{}", shard.index, shard.count)
}

/// What a variant's train stage reads, and the provenance it writes.
pub struct TrainInputs {
    pub inputs: BTreeMap<&'static str, PathBuf>,
    pub provenance: Provenance,
}

/// Runs `variant` up to the stage before train through the cache (holding
/// the output folder's lock while it does, as a run does) and returns what
/// its train stage would be given.
pub fn up_to_train(
    manifest: &Manifest,
    options: &RunOptions,
    variant: &Variant,
) -> Result<TrainInputs> {
    let train = stages::sharded();
    let before = STAGES
        .iter()
        .take_while(|s| s.name != train.name)
        .last()
        .expect("a stage before train");
    let upstream = RunOptions {
        until: Some(before.name.into()),
        variant: Some(variant.name.clone()),
        ..options.clone()
    };
    let record = run(manifest, &upstream)?;
    let made = &record.variants[0].artifacts;
    Ok(TrainInputs {
        inputs: train
            .inputs
            .iter()
            .map(|i| (i.role, PathBuf::from(&made[i.role].path)))
            .collect(),
        provenance: Provenance {
            stage: train.name.into(),
            params: stage_params(manifest.experiment.seed, (train.params)(&variant.stages)),
            inputs: train
                .inputs
                .iter()
                .map(|i| (i.role.to_string(), made[i.role].sha256.clone()))
                .collect(),
        },
    })
}

/// `alnlab run --train-shard K/N`: brings the variant up to train through
/// the cache (holding the output folder's lock, as a run does), then — the
/// lock released, so that shards train side by side — trains shard K of N of
/// its forest into the shard store, unless it is there already. A later run
/// through train merges the complete set. Returns the shard's folder.
pub fn train_shard(
    manifest: &Manifest,
    options: &RunOptions,
    variant: &str,
    shard: Shard,
) -> Result<PathBuf> {
    let variant = manifest.variant(variant)?;
    stages::refuse_sharded_piecewise(&variant.stages, shard, "--train-shard")?;
    let train = stages::sharded();
    let TrainInputs { inputs, provenance } = up_to_train(manifest, options, variant)?;
    let key = shard_key(&StageKey::of(&provenance, train.format_version), shard);
    let shards = shard_store(&options.out);
    if let Some(done) = shards.lookup(train.name, &key) {
        return Ok(done.dir);
    }
    let label = format!(
        "{}/{} shard {shard}",
        manifest.experiment.name, variant.name
    );
    let bar = Bar::new(&label, options.quiet);
    let made = shards
        .make(train.name, &key, train.outputs, |dir| {
            (train.run)(&Call {
                stages: &variant.stages,
                seed: manifest.experiment.seed,
                inputs,
                shard,
                provenance: &provenance,
                out_dir: dir,
                progress: &bar,
            })
        })
        .map_err(|e| e.context(&format!("variant `{}`, train shard {shard}", variant.name)))?;
    Ok(made.dir)
}
