//! The ingest stage (issue 44): data from a robot rather than a simulation.
//! A ROS 2 recording (MCAP) of `sensor_msgs/msg/JointState` on one topic is
//! read and decoded ([`recording`], [`joint_state`]), or tables of samples
//! — CSV or Parquet files, one a trajectory — are read column by column
//! ([`table`]); the joints are matched to the robot's description by name
//! and resampled onto frames ([`frames`]), and written as the simulate
//! stage writes a robot's frames ([`log`]): the trajectory log and its
//! statistics, so that every later stage learns and evaluates as from a
//! simulation. A manifest names the recording or the tables in `[data]`
//! and says how to frame them in `[ingest]` ([`Params`]); the ingest stage
//! then stands where the simulate stage would.

pub mod frames;
pub mod joint_state;
pub mod log;
pub mod recording;
pub mod table;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use alnlab_common::hash::{sha256_file, sha256_hex};
use alnlab_common::params::{self, ParamError, Positive};
use alnlab_common::{Error, Progress, Provenance, Result};
use alnlab_physics::model::Joint;
use alnlab_physics::{Prepared, Scene, SceneKind};
use serde::{Deserialize, Serialize};

use crate::frames::{Gaps, Grid, Resample, Source};

/// Version of what this stage writes (part of every cache key; 2: the
/// implicit integrator's drives by default; 3: frame times counted from
/// each run's start, exact where absolute stamps as f64 were not; 4: the
/// trajectory each run records, `run_trajectories`, where it was the table).
pub const FORMAT_VERSION: u32 = 4;

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
    /// How tables of samples (`[data] tables`) map to the robot's joints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<table::Columns>,
    /// The tables (`[data] tables`, patterns expanded), filled in when the
    /// manifest is read: each a trajectory, in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tables: Vec<TableFile>,
    /// Tables that record one trajectory run again, each group named by
    /// the tables' names as `[data] tables` lists them (or their file
    /// names): one trajectory to a `by-trajectory` split, so a repeat is
    /// never trained on while its twin is tested.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub repeats: Vec<Vec<String>>,
}

/// One table of samples: its name as the manifest's patterns found it (or,
/// archived, `NAME@VERSION/<file>`), its sha256 (its identity in the cache
/// key) and where it is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableFile {
    pub file: String,
    pub sha256: String,
    #[serde(skip)]
    pub path: PathBuf,
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
            table: None,
            tables: Vec::new(),
            repeats: Vec::new(),
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
        if self.table.is_some() {
            return Err((
                "table".into(),
                "[ingest.table] maps the columns of tables: a recording's joints are named in \
                 its messages (remove [ingest.table], or give [data] tables)"
                    .into(),
            ));
        }
        if !self.repeats.is_empty() {
            return Err((
                "repeats".into(),
                "groups tables that record one trajectory: a recording is one file (remove \
                 repeats, or give [data] tables)"
                    .into(),
            ));
        }
        self.read_robot(dir)
    }

    /// Takes the tables that `patterns` (paths or globs relative to `dir`,
    /// the manifest's folder) name, each a trajectory, in the patterns'
    /// order (a glob's matches sorted), and reads the robot's description;
    /// on error, the field and what is wrong.
    pub fn read_tables(
        &mut self,
        dir: &Path,
        patterns: &[String],
    ) -> std::result::Result<(), ParamError> {
        self.validate_table()?;
        if patterns.is_empty() {
            return Err(("tables".into(), "expected at least one table".into()));
        }
        let mut tables: Vec<TableFile> = Vec::new();
        for pattern in patterns {
            let matched = expand(dir, pattern).map_err(|m| ("tables".to_string(), m))?;
            for (file, path) in matched {
                if let Some(twin) = tables.iter().find(|t| t.path == path) {
                    return Err((
                        "tables".into(),
                        format!(
                            "`{file}` is named twice (also as `{}`): each table is one trajectory",
                            twin.file
                        ),
                    ));
                }
                if !path.is_file() {
                    return Err(("tables".into(), format!("{}: no such file", path.display())));
                }
                let sha256 =
                    sha256_file(&path).map_err(|e| ("tables".to_string(), e.to_string()))?;
                if let Some(twin) = tables.iter().find(|t| t.sha256 == sha256) {
                    return Err((
                        "tables".into(),
                        format!(
                            "`{file}` holds the same bytes as `{}`: one trajectory named twice \
                             would be trained on and tested",
                            twin.file
                        ),
                    ));
                }
                tables.push(TableFile { file, sha256, path });
            }
        }
        self.tables = tables;
        self.trajectories()?;
        self.read_robot(dir)
    }

    /// The trajectory each table records (an index, in the order the
    /// tables first record them): its own, or its group's in `repeats`;
    /// on error, the name in `repeats` that names no table, two, or one
    /// already grouped.
    pub fn trajectories(&self) -> std::result::Result<Vec<usize>, ParamError> {
        let mut group: Vec<Option<usize>> = vec![None; self.tables.len()];
        for (g, names) in self.repeats.iter().enumerate() {
            if names.len() < 2 {
                return Err((
                    format!("repeats[{g}]"),
                    "expected at least two tables that record one trajectory".into(),
                ));
            }
            for name in names {
                let named: Vec<usize> = (0..self.tables.len())
                    .filter(|&i| {
                        let file = &self.tables[i].file;
                        file == name || Path::new(file).file_name() == Some(name.as_ref())
                    })
                    .collect();
                let i = match named[..] {
                    [i] => i,
                    [] => {
                        return Err((
                            format!("repeats[{g}]"),
                            format!(
                                "`{name}` is none of the tables ({})",
                                self.tables
                                    .iter()
                                    .map(|t| format!("`{}`", t.file))
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        ));
                    }
                    _ => {
                        return Err((
                            format!("repeats[{g}]"),
                            format!("`{name}` names {} tables: give its path", named.len()),
                        ));
                    }
                };
                if let Some(other) = group[i] {
                    return Err((
                        format!("repeats[{g}]"),
                        format!(
                            "`{}` is already in repeats[{other}]: a table records one trajectory",
                            self.tables[i].file
                        ),
                    ));
                }
                group[i] = Some(g);
            }
        }
        // Trajectories numbered in the order the tables first record them.
        let mut first: Vec<(Option<usize>, usize)> = Vec::new();
        Ok((0..self.tables.len())
            .map(|i| {
                let key = match group[i] {
                    Some(g) => (Some(g), 0),
                    None => (None, i),
                };
                match first.iter().position(|k| *k == key) {
                    Some(t) => t,
                    None => {
                        first.push(key);
                        first.len() - 1
                    }
                }
            })
            .collect())
    }

    /// Checks `[ingest.table]` and reads the robot's description, for tables
    /// an archived dataset holds (the run fills in `tables`, from the
    /// archive it is given).
    pub fn read_archived_tables(&mut self, dir: &Path) -> std::result::Result<(), ParamError> {
        self.validate_table()?;
        self.read_robot(dir)
    }

    /// Checks `[ingest.table]` (its defaults where it is left out).
    fn validate_table(&mut self) -> std::result::Result<(), ParamError> {
        self.table
            .get_or_insert_with(table::Columns::default)
            .validate()
            .map_err(|(field, message)| (format!("table.{field}"), message))
    }

    /// Reads the robot's description (relative to `dir`) and resolves it.
    fn read_robot(&mut self, dir: &Path) -> std::result::Result<(), ParamError> {
        let robot = self.robot.as_mut().ok_or_else(|| {
            (
                "robot".to_string(),
                "recorded data need their robot: [ingest.robot] with kind = \"urdf\" and its \
                 file"
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
    let Some(robot) = &params.robot else {
        return Err(Error::Invalid(
            "ingest: no robot the data are of ([ingest.robot])".into(),
        ));
    };
    let file = robot.file.clone().unwrap_or_default();
    let robot_file = Path::new(&file);
    let grid = Grid {
        frame_dt: robot.frame_dt.get(),
        resample: params.resample,
        max_gap: params.max_gap.get(),
        gaps: params.gaps,
    };
    match (&params.recording, &params.table, params.tables.is_empty()) {
        (Some(recording), None, true) => {
            progress.start("ingest", 1, "recordings");
            let source = Recorded {
                recording,
                topic: &params.topic,
                robot,
                robot_file,
            };
            ingest(&source, &grid, provenance, out_dir)?;
            progress.advance(1);
            Ok(())
        }
        (None, Some(columns), false) => {
            let trajectories = params
                .trajectories()
                .map_err(|e| params::invalid("ingest", e))?;
            let source = Tabled {
                tables: &params.tables,
                trajectories: &trajectories,
                columns,
                robot,
                robot_file,
            };
            ingest_tables(&source, &grid, provenance, out_dir, progress)
        }
        _ => Err(Error::Invalid(
            "ingest: expected a recording ([data] recording) or tables ([data] tables and \
             [ingest.table]) to read"
                .into(),
        )),
    }
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

/// Where the data come from: tables of samples, each a trajectory, what
/// their columns hold, and the robot (a `urdf` scene, its description
/// read) the joints belong to.
pub struct Tabled<'a> {
    pub tables: &'a [TableFile],
    /// The trajectory each table records ([`Params::trajectories`]).
    pub trajectories: &'a [usize],
    pub columns: &'a table::Columns,
    pub robot: &'a Scene,
    /// The robot's description, for messages.
    pub robot_file: &'a Path,
}

/// Reads `source`'s tables, frames each on `grid` (a table's stretches
/// between gaps each a run, where gaps split) and writes `trajectory.mcap`
/// and `stats.parquet` into `out_dir`. The scene record names each table,
/// its sha256, the rate its data imply and the trajectory it records
/// (`table.<i>.*`), and the trajectory each run records
/// (`run_trajectories`, one index a run): whole trajectories can then be
/// held out together.
pub fn ingest_tables(
    source: &Tabled,
    grid: &Grid,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let p = Prepared::new(source.robot);
    let names = log::joints(&p).map_err(|m| Error::bad_file(source.robot_file, m))?;
    let joints: Vec<table::Joint> = names
        .into_iter()
        .zip(p.controls())
        .map(|(name, c)| table::Joint {
            name,
            revolute: matches!(p.model.links[c.hinge + 1].joint, Joint::Revolute { .. }),
        })
        .collect();
    progress.start("ingest", source.tables.len() as u64, "tables");
    let mut runs = Vec::new();
    let mut run_trajectories = Vec::new();
    let mut left_out: Vec<String> = Vec::new();
    let mut record = BTreeMap::from([
        ("source".to_string(), "tables".to_string()),
        ("tables".to_string(), source.tables.len().to_string()),
    ]);
    for (i, t) in source.tables.iter().enumerate() {
        let named = Path::new(&t.file);
        // The bytes read are the bytes the cache key was made from.
        let found = sha256_file(&t.path)?;
        if found != t.sha256 {
            return Err(Error::Corrupt(format!(
                "{}: its sha256 is {found}, not the {} it had when the manifest was read: it \
                 changed under the run; run again",
                t.file, t.sha256
            )));
        }
        let trajectory = table::read(&t.path, named, source.columns, &joints, grid)?;
        for run in frames::runs(&trajectory.stamps_ns, &trajectory.samples, grid) {
            match run.frames.len() >= log::LEAST_FRAMES {
                true => {
                    runs.push(run);
                    run_trajectories.push(source.trajectories[i].to_string());
                }
                false => left_out.push(format!(
                    "{} (from {:.3} s)",
                    t.file,
                    run.start_ns as f64 * 1e-9
                )),
            }
        }
        let implied = trajectory
            .implied_dt
            .map_or("not checked: the joints barely move".to_string(), |dt| {
                format!("{:.4}", 1.0 / dt)
            });
        record.insert(format!("table.{i}.file"), t.file.clone());
        record.insert(format!("table.{i}.sha256"), t.sha256.clone());
        record.insert(
            format!("table.{i}.samples"),
            trajectory.samples.len().to_string(),
        );
        record.insert(format!("table.{i}.implied_hz"), implied);
        record.insert(
            format!("table.{i}.trajectory"),
            source.trajectories[i].to_string(),
        );
        progress.advance(1);
    }
    if runs.is_empty() {
        return Err(Error::Invalid(format!(
            "ingest: no stretch of the tables makes {} frames of {} s without a gap (too \
             short: {})",
            log::LEAST_FRAMES,
            grid.frame_dt,
            left_out.join(", ")
        )));
    }
    record.insert("run_trajectories".to_string(), run_trajectories.join(","));
    record.insert("runs_left_out".to_string(), left_out.len().to_string());
    if !left_out.is_empty() {
        record.insert("runs_left_out_from".to_string(), left_out.join(", "));
    }
    let p = Prepared::new(&log::recorded_scene(source.robot, &runs));
    log::write(&p, &runs, record, provenance, out_dir)
}

/// The files `pattern` names relative to `dir`: the path itself, or a
/// glob's matches sorted; each with its name as the pattern gave it.
fn expand(dir: &Path, pattern: &str) -> std::result::Result<Vec<(String, PathBuf)>, String> {
    // A file of that very name is taken as named (`run[1].csv`).
    if !pattern.contains(['*', '?', '[']) || dir.join(pattern).is_file() {
        return Ok(vec![(pattern.to_string(), dir.join(pattern))]);
    }
    // The manifest's folder is a path, not a pattern; hidden files and
    // folders are no tables.
    let folder = dir
        .to_str()
        .ok_or_else(|| format!("`{pattern}`: the manifest's folder is not UTF-8"))?;
    let full = Path::new(&glob::Pattern::escape(folder)).join(pattern);
    let options = glob::MatchOptions {
        require_literal_leading_dot: true,
        ..glob::MatchOptions::new()
    };
    let mut found: Vec<PathBuf> = glob::glob_with(&full.to_string_lossy(), options)
        .map_err(|e| format!("`{pattern}` is not a glob pattern: {e}"))?
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|e| format!("`{pattern}`: {e}"))?
        .into_iter()
        .filter(|p| p.is_file())
        .collect();
    found.sort();
    if found.is_empty() {
        return Err(format!("`{pattern}` matches no file"));
    }
    Ok(found
        .into_iter()
        .map(|path| {
            let name = path
                .strip_prefix(dir)
                .unwrap_or(&path)
                .to_string_lossy()
                .into_owned();
            (name, path)
        })
        .collect())
}
