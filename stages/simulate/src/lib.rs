//! The simulate stage (paper §2, §4.1–4.2; docs/design.md §3): runs the scenes of
//! a manifest and writes
//! - `trajectory.mcap`: one `/state` message per logged frame (see
//!   [`alnlab_common::state_log`]) holding the generalized state and the
//!   paper's variables; `/tf` and `/scene` in Foxglove's schemas at the
//!   viewing rate; per scene an `alnlab.model` metadata record (the model)
//!   and an `alnlab.scene` record (what re-simulates it, see `alnlab_physics::replay`);
//! - `stats.parquet`: min, max, mean, std and n per variable over all runs of
//!   all scenes (paper §4.2).
//!
//! The dynamics, scenes and re-simulation are the `alnlab-physics` library;
//! this stage runs a manifest's scenes with it and writes what it saw.

pub mod bench;
#[cfg(test)]
mod tests;

use std::path::Path;

use alnlab_common::params::{self, ParamError, Positive};
use alnlab_common::state_log::{StateLayout, StateLogWriter};
use alnlab_common::{Progress, Provenance, Result};
use alnlab_physics::controller::ControllerKind;
use alnlab_physics::{Prepared, simulate_run};
use alnlab_physics::{foxglove, replay};
use serde::{Deserialize, Serialize};

pub use alnlab_physics::{Integrator, Scene, SceneKind};

/// Version of what this stage writes; part of every cache key, bumped when the
/// same parameters would produce different bytes (5: a log of applied
/// efforts says its total effort is applied + passive; 6: half turns on
/// /tf, joint limits sized on what the joint moves; 7: implicit drives
/// that give their effort, mimic joints).
pub const FORMAT_VERSION: u32 = 7;

/// File name of the trajectory log.
pub const TRAJECTORY_FILE: &str = "trajectory.mcap";
/// File name of the statistics table ([`alnlab_tables::stats`]).
pub const STATS_FILE: &str = alnlab_tables::stats::FILE;
pub use alnlab_physics::replay::{MODEL_RECORD, SCENE_RECORD};

/// The `[simulate]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The scenes (`[[simulate.scene]]`).
    #[serde(default = "default_scenes")]
    pub scene: Vec<Scene>,
    /// Rate of the `/tf` viewing channel (Hz); rounded to whole frames.
    #[serde(default = "default_view_rate")]
    pub view_rate: Positive,
}

fn default_scenes() -> Vec<Scene> {
    vec![Scene::default().resolve()]
}

fn default_view_rate() -> Positive {
    Positive(50.0)
}

impl Default for Params {
    fn default() -> Self {
        Params {
            scene: default_scenes(),
            view_rate: default_view_rate(),
        }
    }
}

impl Params {
    /// Reads the robot description of every `urdf` scene (paths relative to
    /// `dir`, the manifest's folder); on error, the field and what is wrong.
    pub fn read_descriptions(&mut self, dir: &Path) -> std::result::Result<(), ParamError> {
        for (i, scene) in self.scene.iter_mut().enumerate() {
            scene
                .read_description(dir)
                .map_err(|(field, message)| (format!("scene.{i}.{field}"), message))?;
        }
        Ok(())
    }

    /// Fills every scene's kind defaults (so the resolved manifest shows them).
    pub fn resolve(mut self) -> Params {
        self.scene = self.scene.into_iter().map(Scene::resolve).collect();
        self
    }

    /// Checks what deserialization cannot: relations between fields.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        if self.scene.is_empty() {
            return Err((
                "scene".into(),
                "expected at least one [[simulate.scene]]".into(),
            ));
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, scene) in self.scene.iter().enumerate() {
            let at = |field: &str| format!("scene.{i}.{field}");
            let valid_name = !scene.name.is_empty()
                && scene
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
            if !valid_name {
                return Err((
                    at("name"),
                    format!(
                        "expected a name of letters, digits, `-` or `_`, found {:?}",
                        scene.name
                    ),
                ));
            }
            if !names.insert(scene.name.as_str()) {
                return Err((
                    at("name"),
                    format!("scene name {:?} is used twice", scene.name),
                ));
            }
            let resolved = scene.clone().resolve();
            resolved
                .validate()
                .map_err(|(field, message)| (at(&field), message))?;
            if resolved.controller().kind == ControllerKind::Logged {
                return Err((
                    at("controller.kind"),
                    "`logged` is a recording's (the ingest stage's); a simulated scene's \
                     controller is none, constant, sine or random"
                        .into(),
                ));
            }
        }
        Ok(())
    }
}

/// Runs every scene of `params` and writes `trajectory.mcap` and
/// `stats.parquet` into `out_dir`. The result depends only on `params` and
/// `seed`.
pub fn run(
    params: &Params,
    seed: u64,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    params
        .validate()
        .map_err(|e| params::invalid("simulate", e))?;
    let prepared: Vec<Prepared> = params.scene.iter().map(Prepared::new).collect();
    let layouts: Vec<StateLayout> = prepared.iter().map(|p| p.layout.clone()).collect();
    let total_steps: u64 = prepared
        .iter()
        .map(|p| p.scene.runs.0 * (p.scene.frames_per_run() - 1) * p.scene.steps_per_frame())
        .sum();
    progress.start("simulate", total_steps, "steps");

    let mut log = StateLogWriter::create(&out_dir.join(TRAJECTORY_FILE), &layouts)?;
    let [tf, scene_channel] = log.add_json_channels(foxglove::channels())?;
    let mut stats = alnlab_tables::stats::VariableStats::default();
    let mut log_time_ns = 0u64;
    for (scene_index, p) in prepared.iter().enumerate() {
        log.metadata(MODEL_RECORD, replay::model_record(p))?;
        log.metadata(
            SCENE_RECORD,
            replay::scene_record(&p.scene, scene_index, seed),
        )?;
        let frame_ns = (p.scene.frame_dt.get() * 1e9).round() as u64;
        let view_every = ((1.0 / params.view_rate.get()) / p.scene.frame_dt.get())
            .round()
            .max(1.0) as u32;
        for run in 0..p.scene.runs.0 as u32 {
            log.write_json(
                scene_channel,
                log_time_ns,
                &foxglove::scene_update(p, run, log_time_ns),
            )?;
            simulate_run(p, seed, scene_index, run, |frame, kin| {
                stats.add(&p.layout.variables, &frame.variables);
                log.write(scene_index, log_time_ns, frame)?;
                if frame.frame % view_every == 0 {
                    log.write_json(
                        tf,
                        log_time_ns,
                        &foxglove::transforms(p, run, kin, log_time_ns),
                    )?;
                }
                log_time_ns += frame_ns;
                if frame.frame > 0 {
                    progress.advance(p.scene.steps_per_frame());
                }
                Ok(())
            })?;
        }
    }
    // Stats first: if it fails, no log is renamed into place either.
    stats.write(&out_dir.join(STATS_FILE), provenance)?;
    log.finish(provenance)
}
