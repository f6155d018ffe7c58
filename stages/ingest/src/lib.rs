//! The ingest stage (issue 44): data from a robot rather than a simulation.
//! A ROS 2 recording (MCAP) of `sensor_msgs/msg/JointState` on one topic is
//! read and decoded ([`recording`], [`joint_state`]), its joints matched to
//! the robot's description by name and resampled onto frames
//! ([`frames`]), and written as the simulate stage writes a robot's frames
//! ([`log`]): the trajectory log and its statistics, so that every later
//! stage learns and evaluates as from a simulation. Not yet built: its
//! place in the manifest (`[data] recording`) and the stage table.

pub mod frames;
pub mod joint_state;
pub mod log;
pub mod recording;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::hash::sha256_hex;
use alnlab_common::{Error, Provenance, Result};
use alnlab_physics::{Prepared, Scene};

use crate::frames::{Grid, Source};

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
pub fn run(source: &Recorded, grid: &Grid, provenance: &Provenance, out_dir: &Path) -> Result<()> {
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
