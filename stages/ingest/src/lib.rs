//! The ingest stage (issue 44): data from a robot rather than a simulation.
//! A ROS 2 recording (MCAP) of `sensor_msgs/msg/JointState` on one topic is
//! read and decoded ([`recording`], [`joint_state`]), its joints matched to
//! the robot's description by name and resampled onto frames
//! ([`frames`]), and written as the simulate stage writes a robot's frames
//! ([`log`]): the trajectory log and its statistics, so that every later
//! stage learns and evaluates as from a simulation. A manifest names the
//! recording in `[data]` and says how to frame it in `[ingest]`
//! ([`Params`]); the ingest stage then stands where the simulate stage
//! would.

pub mod frames;
pub mod joint_state;
pub mod log;
pub mod recording;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use alnlab_common::hash::sha256_hex;
use alnlab_common::params::{self, ParamError, Positive};
use alnlab_common::{Error, Progress, Provenance, Result};
use alnlab_physics::{Prepared, Scene, SceneKind};
use serde::{Deserialize, Serialize};

use crate::frames::{Gaps, Grid, Resample, Source};

/// Version of what this stage writes (part of every cache key; 2: the
/// implicit integrator's drives by default).
pub const FORMAT_VERSION: u32 = 2;

/// The `[ingest]` table: how a recording (`[data] recording`) becomes
/// frames, and the robot it records.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The recording's topic of `sensor_msgs/msg/JointState` (from
    /// `[data] topic`).
    #[serde(default = "joint_states")]
    pub topic: String,
    /// How a frame's values come from the samples around its time.
    #[serde(default)]
    pub resample: Resample,
    /// What a gap longer than `max_gap` does: `error` or `split` (a new run).
    #[serde(default)]
    pub gaps: Gaps,
    /// The longest time between two samples of a run (s).
    #[serde(default = "fifty_milliseconds")]
    pub max_gap: Positive,
    /// The robot: a `urdf` scene, its description (`file`) and how its
    /// model steps (`dt`, `frame_dt` — the frames' spacing —,
    /// `hinge_damping`, `link_velocities`, `nominal_steps`). Its runs,
    /// duration and controller come from the recording.
    pub robot: Option<Scene>,
    /// The recording's sha256, filled in when the manifest is read: the
    /// data's identity in the cache key.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recording_sha256: Option<String>,
    /// The recording's path, filled in when the manifest is read.
    #[serde(skip)]
    pub recording: Option<PathBuf>,
}

fn joint_states() -> String {
    "/joint_states".into()
}

fn fifty_milliseconds() -> Positive {
    Positive(0.05)
}

impl Default for Params {
    fn default() -> Params {
        Params {
            topic: joint_states(),
            resample: Resample::default(),
            gaps: Gaps::default(),
            max_gap: fifty_milliseconds(),
            robot: None,
            recording_sha256: None,
            recording: None,
        }
    }
}

impl Params {
    /// Takes the recording `path` (relative to `dir`, the manifest's
    /// folder) and `topic`, reads the robot's description and resolves
    /// it; on error, the field and what is wrong.
    pub fn read_sources(
        &mut self,
        dir: &Path,
        path: &str,
        topic: Option<&str>,
    ) -> std::result::Result<(), ParamError> {
        let recording = dir.join(path);
        let bytes = std::fs::read(&recording).map_err(|e| {
            (
                "recording".to_string(),
                format!("{}: {e}", recording.display()),
            )
        })?;
        self.recording_sha256 = Some(sha256_hex(&bytes));
        self.recording = Some(recording);
        if let Some(topic) = topic {
            self.topic = topic.to_string();
        }
        let robot = self.robot.as_mut().ok_or_else(|| {
            (
                "robot".to_string(),
                "a recording needs its robot: [ingest.robot] with kind = \"urdf\" and its file"
                    .to_string(),
            )
        })?;
        if robot.kind != SceneKind::Urdf {
            return Err((
                "robot.kind".into(),
                "expected \"urdf\": a recording's joints are a robot's".into(),
            ));
        }
        robot
            .read_description(dir)
            .map_err(|(field, message)| (format!("robot.{field}"), message))?;
        let resolved = robot.clone().resolve();
        resolved
            .validate()
            .map_err(|(field, message)| (format!("robot.{field}"), message))?;
        let prepared = Prepared::new(&resolved);
        let field = match prepared.model.couplings.is_empty() {
            true => "robot.base",
            false => "robot.file",
        };
        log::joints(&prepared).map_err(|m| (field.to_string(), m))?;
        *robot = resolved;
        Ok(())
    }

    /// Checks what does not need the files.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        if self.topic.is_empty() {
            return Err(("topic".into(), "expected a topic name".into()));
        }
        Ok(())
    }
}

/// Runs the stage on `params` (their sources read): `trajectory.mcap` and
/// `stats.parquet` into `out_dir`.
pub fn run(
    params: &Params,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    params
        .validate()
        .map_err(|e| params::invalid("ingest", e))?;
    let (Some(recording), Some(robot)) = (&params.recording, &params.robot) else {
        return Err(Error::Invalid(
            "ingest: no recording to read ([data] recording and [ingest.robot])".into(),
        ));
    };
    progress.start("ingest", 1, "recordings");
    let file = robot.file.clone().unwrap_or_default();
    let source = Recorded {
        recording,
        topic: &params.topic,
        robot,
        robot_file: Path::new(&file),
    };
    let grid = Grid {
        frame_dt: robot.frame_dt.get(),
        resample: params.resample,
        max_gap: params.max_gap.get(),
        gaps: params.gaps,
    };
    ingest(&source, &grid, provenance, out_dir)?;
    progress.advance(1);
    Ok(())
}

/// Where the data come from: a recording, its topic, and the robot (a
/// `urdf` scene, its description read) the joints belong to.
pub struct Recorded<'a> {
    pub recording: &'a Path,
    pub topic: &'a str,
    pub robot: &'a Scene,
    /// The robot's description, for messages.
    pub robot_file: &'a Path,
}

/// Reads `source`'s recording, frames it on `grid` (`frame_dt` the
/// robot scene's) and writes `trajectory.mcap` and `stats.parquet` into
/// `out_dir`. Runs too short to log a frame (fewer than
/// [`log::LEAST_FRAMES`]) are left out, counted in the scene record.
pub fn ingest(
    source: &Recorded,
    grid: &Grid,
    provenance: &Provenance,
    out_dir: &Path,
) -> Result<()> {
    let bytes = std::fs::read(source.recording).map_err(|e| Error::io(source.recording, e))?;
    let samples = recording::read(source.recording, &bytes, source.topic)?;
    let joints = log::joints(&Prepared::new(source.robot))
        .map_err(|m| Error::bad_file(source.robot_file, m))?;
    let framing = Source {
        recording: source.recording,
        topic: source.topic,
        robot: source.robot_file,
        joints: &joints,
    };
    let mut runs = frames::frames(&framing, &samples, grid)?;
    let all = runs.len();
    runs.retain(|r| r.frames.len() >= log::LEAST_FRAMES);
    if runs.is_empty() {
        return Err(Error::bad_file(
            source.recording,
            format!(
                "topic `{}`: no stretch without a gap makes {} frames of {} s",
                source.topic,
                log::LEAST_FRAMES,
                grid.frame_dt
            ),
        ));
    }
    let p = Prepared::new(&log::recorded_scene(source.robot, &runs));
    let record = BTreeMap::from([
        ("source".to_string(), "recording".to_string()),
        ("recording_sha256".to_string(), sha256_hex(&bytes)),
        ("topic".to_string(), source.topic.to_string()),
        ("messages".to_string(), samples.len().to_string()),
        ("runs_left_out".to_string(), (all - runs.len()).to_string()),
    ]);
    log::write(&p, &runs, record, provenance, out_dir)
}
