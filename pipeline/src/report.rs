//! Rendering a run's report from its record: the record names every
//! artifact, the report crate draws the tables and charts.

use std::path::{Path, PathBuf};

use alnlab_common::{Error, Result};
use alnlab_report::{
    self as report, PlanSetup, PlanTask, Replicate, RunInfo, StageTime, VariantInfo,
};
use serde::Deserialize;

use crate::records::{RunRecord, VariantRecord};
use crate::stages::Stages;

/// Renders the report of `record` into `dir`; returns the path of
/// `report.md`.
pub fn render(record: &RunRecord, dir: &Path) -> Result<PathBuf> {
    let artifact = |v: &VariantRecord, role: &str| -> Result<PathBuf> {
        v.artifacts
            .get(role)
            .map(|a| PathBuf::from(&a.path))
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "variant `{}` (replicate {}) of the run record has no `{role}` artifact",
                    v.name,
                    v.replicate + 1
                ))
            })
    };
    // A variant's first replicate stands for it; the others add their figures.
    let variants = record
        .variants
        .iter()
        .filter(|v| v.replicate == 0)
        .map(|v| {
            let replicates = record
                .variants
                .iter()
                .filter(|r| r.name == v.name)
                .map(|r| {
                    Ok(Replicate {
                        seed: r.seed,
                        summary: artifact(r, "summary")?,
                        comparisons: artifact(r, "comparisons")?,
                        horizons: artifact(r, "horizons")?,
                        timings: artifact(r, "timings")?,
                        planning: r.artifacts.get("planning").map(|a| PathBuf::from(&a.path)),
                        rounds: (1..)
                            .map_while(|k| r.artifacts.get(&format!("planning@{k}")))
                            .map(|a| PathBuf::from(&a.path))
                            .collect(),
                    })
                })
                .collect::<Result<_>>()?;
            let artifact = |role: &str| artifact(v, role);
            let stages = resolved(v)?;
            Ok(VariantInfo {
                name: v.name.clone(),
                description: v.description.clone(),
                stages: v
                    .stages
                    .iter()
                    .map(|s| StageTime {
                        stage: s.stage.clone(),
                        cached: s.cached,
                        wall_seconds: s.wall_seconds,
                        compute_seconds: s.compute_seconds,
                    })
                    .collect(),
                summary: artifact("summary")?,
                comparisons: artifact("comparisons")?,
                horizons: artifact("horizons")?,
                timings: artifact("timings")?,
                training: artifact("training")?,
                model: artifact("model")?,
                codebook: artifact("codebook")?,
                planning: v.artifacts.get("planning").map(|a| PathBuf::from(&a.path)),
                plan_setup: plan_setup(&stages.plan),
                // A plant of nominal values resolves to none, so a scene's
                // plant is one that departs; a dataset or a recording
                // stands for the simulated scenes.
                plant: record.dataset.is_none()
                    && record.recording.is_none()
                    && stages.simulate.scene.iter().any(|s| s.plant.is_some()),
                // An archived run's data carry their own split, which the
                // record does not say.
                folds: stages.stride.split == alnlab_stride::Split::ByTrajectory
                    && !(record.dataset.is_some() && record.tables.is_empty()),
                circuit: v.artifacts.get("circuit").map(|a| PathBuf::from(&a.path)),
                fpga: v.artifacts.get("fpga").map(|a| PathBuf::from(&a.path)),
                fixed: v.artifacts.get("fixed").map(|a| PathBuf::from(&a.path)),
                replicates,
            })
        })
        .collect::<Result<_>>()?;
    // The split the rows were held out by (an archived run's data carry
    // their own, which the record does not say; archived recordings are
    // split here).
    let archived_pairs = record.dataset.is_some() && record.tables.is_empty();
    let mut splits: Vec<(&str, &str)> = Vec::new();
    for v in record.variants.iter().filter(|v| v.replicate == 0) {
        splits.push((&v.name, resolved(v)?.stride.split.describe()));
    }
    let split = match splits.as_slice() {
        _ if archived_pairs => None,
        [] => None,
        [(_, first), rest @ ..] if rest.iter().all(|(_, s)| s == first) => Some(first.to_string()),
        many => Some(
            many.iter()
                .map(|(name, s)| format!("`{name}` {s}"))
                .collect::<Vec<_>>()
                .join("; "),
        ),
    };
    let run = RunInfo {
        experiment: record.experiment.clone(),
        manifest_path: record.manifest_path.clone(),
        manifest_sha256: record.manifest_sha256.clone(),
        seed: record.seed,
        alnlab_version: record.alnlab_version.clone(),
        git_commit: record.git_commit.clone(),
        git_changes: record.git_changes.clone(),
        started: record.started.clone(),
        wall_seconds: record.wall_seconds,
        variants,
        compare_with_paper: record.compare_with_paper,
        description: record.description.clone(),
        notes: record.notes.clone(),
        answer: record.answer.clone(),
        dataset: record
            .dataset
            .as_ref()
            .map(|d| (d.dataset.clone(), d.sha256.clone())),
        recording: record
            .recording
            .as_ref()
            .map(|r| (r.recording.clone(), r.sha256.clone(), r.topic.clone())),
        tables: record
            .tables
            .iter()
            .map(|t| (t.file.clone(), t.sha256.clone()))
            .collect(),
        split,
    };
    report::render(&run, dir)
}

/// A variant's resolved stage tables, read back as their types from its
/// record. A record before format 3 kept them only as text: re-running its
/// experiment (every artifact comes from the cache) writes one that has
/// them.
fn resolved(v: &VariantRecord) -> Result<Stages> {
    let value = v.resolved.as_ref().ok_or_else(|| {
        Error::Invalid(format!(
            "variant `{}` of the run record keeps its parameters only as text (a record before \
             format 3): run the experiment again with this alnlab (its artifacts come from the \
             cache) to render its report",
            v.name
        ))
    })?;
    Stages::deserialize(value).map_err(|e| {
        Error::Corrupt(format!(
            "variant `{}` of the run record: its resolved parameters are not this alnlab's \
             stage tables ({e})",
            v.name
        ))
    })
}

/// What the plan stage was asked; `None` when it plans no task.
fn plan_setup(plan: &alnlab_plan::Params) -> Option<PlanSetup> {
    if plan.task.is_empty() {
        return None;
    }
    let tasks = plan
        .task
        .iter()
        .map(|task| PlanTask {
            name: task.name().to_string(),
            definition: task.describe(),
            unit: task.cost_unit().to_string(),
            error_unit: task.error_unit().to_string(),
            tolerance: task.tolerance(),
        })
        .collect();
    Some(PlanSetup {
        tasks,
        horizon: u32::try_from(plan.horizon.0).ok()?,
        frames: u32::try_from(plan.frames.0).ok()?,
        episodes: u32::try_from(plan.episodes.0).ok()?,
        feedback_frequencies: plan.feedback_frequencies.clone(),
        tuning_episodes: u32::try_from(plan.tuning_episodes.unwrap_or(plan.episodes).0).ok()?,
    })
}
