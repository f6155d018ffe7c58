//! Frames of a recording written as the simulate stage writes a robot's
//! frames: the trajectory log of the robot's scene (its generalized state
//! and variables per frame, its `alnlab.model` and `alnlab.scene` records)
//! and `stats.parquet`. Each frame's state is the recorded joint positions
//! and velocities; its variables are what the robot's model makes of them
//! — link velocities by kinematics, each joint's passive effort by its
//! law — except what was measured: `tau.<joint>` is the recorded effort,
//! and `qdd.<joint>` the central difference of the recorded velocities
//! (which drops each run's first and last frame). The scene is recorded
//! with the controller `logged`, so a re-simulation drives each frame's
//! recorded efforts.

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::params::{Count, Positive};
use alnlab_common::state_log::{StateFrame, StateLogWriter};
use alnlab_common::{Error, Provenance, Result};
use alnlab_physics::controller::{ControllerKind, ControllerParams};
use alnlab_physics::replay::{self, MODEL_RECORD, SCENE_RECORD};
use alnlab_physics::urdf::Base;
use alnlab_physics::{Prepared, Runner, Scene, state_from_generalized};
use alnlab_tables::stats::VariableStats;
use nalgebra::Vector3;

use crate::frames::Run;

/// The trajectory log's file name, as the simulate stage's.
pub const TRAJECTORY_FILE: &str = "trajectory.mcap";

/// The robot's one-DOF joints, in model order: the order of a frame's
/// values. An error for a robot a recording of joints cannot describe.
pub fn joints(p: &Prepared) -> std::result::Result<Vec<String>, String> {
    if p.scene.base != Some(Base::Fixed) {
        return Err(format!(
            "robot `{}` has a free base: a recording of its joints gives no pose of the base",
            p.scene.name
        ));
    }
    if let Some(c) = p.model.couplings.first() {
        let robot = p.robot.as_ref().expect("a robot scene");
        return Err(format!(
            "robot `{}` has mimic joints (`{}` follows `{}`): a recording of them is not read \
             yet; remove the <mimic> elements to read each joint as recorded",
            p.scene.name, robot.joints[c.follower], robot.joints[c.leader]
        ));
    }
    Ok(p.controls()
        .into_iter()
        .map(|c| c.name["tau.".len()..].to_string())
        .collect())
}

/// Frames a run needs: one logged, and one on either side for its
/// acceleration.
pub const LEAST_FRAMES: usize = 3;

/// `scene` (a robot, its description read) as a recording's: the
/// controller `logged`, as many runs as `runs` (each of at least
/// [`LEAST_FRAMES`]), each as long as the longest logs.
pub fn recorded_scene(scene: &Scene, runs: &[Run]) -> Scene {
    let frames = runs
        .iter()
        .map(|r| r.frames.len())
        .max()
        .unwrap_or(LEAST_FRAMES);
    let mut scene = scene.clone();
    scene.runs = Count(runs.len() as u64);
    // Logged: all but the first and last.
    scene.duration = Positive((frames - 3).max(1) as f64 * scene.frame_dt.get());
    scene.controller = Some(ControllerParams {
        kind: ControllerKind::Logged,
        ..ControllerParams::default()
    });
    scene
}

/// Writes `runs` of the robot `p` (a [`recorded_scene`]) as
/// `trajectory.mcap` and `stats.parquet` into `out_dir`; `record` adds
/// what the scene record says of the recording.
pub fn write(
    p: &Prepared,
    runs: &[Run],
    record: BTreeMap<String, String>,
    provenance: &Provenance,
    out_dir: &Path,
) -> Result<()> {
    let frame_dt = p.scene.frame_dt.get();
    let layout = &p.layout;
    let find = |name: &str| layout.variables.iter().position(|v| v == name);
    let joints = joints(p).map_err(Error::Invalid)?;
    let qdd: Vec<usize> = joints
        .iter()
        .filter_map(|j| find(&format!("qdd.{j}")))
        .collect();
    let tau: Vec<usize> = joints
        .iter()
        .filter_map(|j| find(&format!("tau.{j}")))
        .collect();
    if qdd.len() != joints.len() || tau.len() != joints.len() {
        return Err(Error::Invalid(format!(
            "scene `{}` does not log every joint's qdd and tau",
            p.scene.name
        )));
    }
    let controls = p.controls();
    let mut log =
        StateLogWriter::create(&out_dir.join(TRAJECTORY_FILE), std::slice::from_ref(layout))?;
    log.metadata(MODEL_RECORD, replay::model_record(p))?;
    let mut scene_record = replay::scene_record(&p.scene, 0, 0);
    scene_record.extend(record);
    log.metadata(SCENE_RECORD, scene_record)?;
    let mut stats = VariableStats::default();
    let efforts = joints.len();
    let mut values = vec![0.0; 3 + 3 * efforts];
    let mut g = vec![Vector3::zeros(); p.model.len() - 1];
    let mut frame = StateFrame::default();
    let mut log_time_ns = 0u64;
    for (r, run) in runs.iter().enumerate() {
        let mut runner = Runner::new(p, 0, 0, r as u32);
        // The first and last frame have no central difference.
        for k in 1..run.frames.len().saturating_sub(1) {
            let m = &run.frames[k];
            for (j, (q, qd)) in m.q.iter().zip(&m.qd).enumerate() {
                values[3 + 2 * j] = *q;
                values[4 + 2 * j] = *qd;
            }
            let state = state_from_generalized(&p.model, &values)
                .expect("a fixed base's position and every joint's");
            for (c, &effort) in controls.iter().zip(&m.effort) {
                g[c.hinge][c.axis] = effort;
            }
            runner.drive(Some(&g));
            let time = (k - 1) as f64 * frame_dt;
            runner.observe(&state, time, &mut frame);
            let (before, after) = (&run.frames[k - 1], &run.frames[k + 1]);
            for (j, (&v, &t)) in qdd.iter().zip(&tau).enumerate() {
                frame.variables[v] = (after.qd[j] - before.qd[j]) / (2.0 * frame_dt);
                frame.variables[t] = m.effort[j];
            }
            frame.run = r as u32;
            frame.frame = (k - 1) as u32;
            frame.time = time;
            stats.add(&layout.variables, &frame.variables);
            log.write(0, log_time_ns, &frame)?;
            log_time_ns += (frame_dt * 1e9).round() as u64;
        }
    }
    stats.write(&out_dir.join(alnlab_tables::stats::FILE), provenance)?;
    log.finish(provenance)
}
