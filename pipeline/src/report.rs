//! Rendering a run's report from its record: the record names every
//! artifact, the report crate draws the tables and charts.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use alnlab_common::{Error, Result};
use alnlab_plan::task::Task;
use alnlab_report::{
    self as report, PlanSetup, PlanTask, Replicate, RunInfo, StageTime, VariantInfo,
};

use crate::records::{RunRecord, VariantRecord};

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
                plan_setup: plan_setup(&v.parameters),
                // A plant of nominal values resolves to none, so a key of
                // a scene's plant table means one that departs.
                plant: v
                    .parameters
                    .keys()
                    .any(|k| k.starts_with("simulate.scene.") && k.contains(".plant.")),
                circuit: v.artifacts.get("circuit").map(|a| PathBuf::from(&a.path)),
                fpga: v.artifacts.get("fpga").map(|a| PathBuf::from(&a.path)),
                fixed: v.artifacts.get("fixed").map(|a| PathBuf::from(&a.path)),
                replicates,
            })
        })
        .collect::<Result<_>>()?;
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
        dataset: record
            .dataset
            .as_ref()
            .map(|d| (d.dataset.clone(), d.sha256.clone())),
        recording: record
            .recording
            .as_ref()
            .map(|r| (r.recording.clone(), r.sha256.clone(), r.topic.clone())),
    };
    report::render(&run, dir)
}

/// What the plan stage was asked, from a variant's recorded parameters
/// (the manifest's `[plan]` as dotted keys); `None` when it planned nothing
/// or the record predates the keys.
fn plan_setup(parameters: &BTreeMap<String, String>) -> Option<PlanSetup> {
    let get = |key: &str| parameters.get(key);
    let count = |key: &str| get(key)?.parse::<u32>().ok();
    let mut tasks = Vec::new();
    for k in 0.. {
        let key = |field: &str| format!("plan.task.{k}.{field}");
        let Some(kind) = get(&key("kind")) else {
            break;
        };
        let name = get(&key("name"))?.clone();
        let task = match kind.as_str() {
            "hold-angles" => {
                let prefix = key("targets.");
                let targets = parameters
                    .range(prefix.clone()..)
                    .take_while(|(k, _)| k.starts_with(&prefix))
                    .map(|(k, v)| Some((k[prefix.len()..].to_string(), v.parse().ok()?)))
                    .collect::<Option<_>>()?;
                Task::HoldAngles { name, targets }
            }
            "spin" => Task::Spin {
                name,
                variable: get(&key("variable"))?.clone(),
                rate: get(&key("rate"))?.parse().ok()?,
            },
            "reach-point" => {
                // An array is recorded as its TOML text, `[0.3, 0.0, 0.5]`.
                let text = get(&key("target"))?;
                let point: Vec<f64> = text
                    .trim_matches(['[', ']'])
                    .split(',')
                    .map(|x| x.trim().parse().ok())
                    .collect::<Option<_>>()?;
                Task::ReachPoint {
                    name,
                    frame: get(&key("frame"))?.clone(),
                    target: point.try_into().ok()?,
                }
            }
            _ => return None,
        };
        tasks.push(PlanTask {
            name: task.name().to_string(),
            definition: task.describe(),
            unit: task.cost_unit().to_string(),
        });
    }
    if tasks.is_empty() {
        return None;
    }
    Some(PlanSetup {
        tasks,
        horizon: count("plan.horizon")?,
        frames: count("plan.frames")?,
        episodes: count("plan.episodes")?,
    })
}
