//! The simulate stage: runs the scenes of a manifest and writes
//! `trajectory.mcap` (one `/state` message per logged frame, see
//! [`alnlab_common::state_log`]) and `stats.parquet` (min, max, mean, std and
//! n per variable over all runs of all scenes, paper §4.2).
//!
//! Scenes so far: `tumbler`, one free rigid box under gravity.

pub mod dynamics;
pub mod integrate;
pub mod model;
#[cfg(test)]
mod reference;
pub mod spatial;
mod stats;
pub mod tumbler;

use std::path::Path;

use alnlab_common::params::{Count, Positive};
use alnlab_common::state_log::{StateFrame, StateLayout, StateLogWriter};
use alnlab_common::{Error, Progress, Provenance, Result};
use nalgebra::{UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Version of what this stage writes; part of every cache key, bumped when the
/// same parameters would produce different bytes.
pub const FORMAT_VERSION: u32 = 1;

/// File name of the trajectory log.
pub const TRAJECTORY_FILE: &str = "trajectory.mcap";
/// File name of the statistics table.
pub const STATS_FILE: &str = "stats.parquet";

/// The `[simulate]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The scenes, each run `runs` times (`[[simulate.scene]]`).
    pub scene: Vec<Scene>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            scene: vec![Scene::default()],
        }
    }
}

/// What kind of body a scene simulates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    /// One free asymmetric box tumbling under gravity.
    Tumbler,
}

/// The numerical integrator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Velocities first, then positions with the new velocities.
    #[default]
    SemiImplicitEuler,
    /// Classical fourth-order Runge–Kutta.
    Rk4,
}

/// One `[[simulate.scene]]` entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scene {
    /// The scene's name, unique in the manifest (used in tables and logs).
    pub name: String,
    /// What is simulated.
    pub kind: SceneKind,
    /// How many runs, each with its own seeded initial conditions.
    pub runs: Count,
    /// Simulated seconds per run.
    pub duration: Positive,
    /// Integration step (s).
    pub dt: Positive,
    /// Logged time slice (s); a whole multiple of `dt`.
    pub frame_dt: Positive,
    /// The integrator.
    pub integrator: Integrator,
    /// Gravity in the inertial frame (m/s²).
    pub gravity: [f64; 3],
    /// Edge lengths of the box (m).
    pub size: [Positive; 3],
    /// Mass (kg).
    pub mass: Positive,
    /// Initial angular velocity, link frame (rad/s).
    pub spin: [f64; 3],
    /// Each run adds a seeded uniform perturbation in ±`spin_jitter` to each
    /// component of `spin`, and starts from a seeded random orientation.
    pub spin_jitter: f64,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            name: "tumbler".into(),
            kind: SceneKind::Tumbler,
            runs: Count(2),
            duration: Positive(10.0),
            dt: Positive(1e-3),
            frame_dt: Positive(1e-2),
            integrator: Integrator::default(),
            gravity: [0.0, 0.0, -9.81],
            size: [Positive(0.4), Positive(0.2), Positive(0.1)],
            mass: Positive(1.0),
            // Close to the intermediate axis: the body flips (Dzhanibekov).
            spin: [0.2, 8.0, 0.1],
            spin_jitter: 0.5,
        }
    }
}

/// A parameter error: the dotted key path within `[simulate]` and the message.
#[derive(Debug, PartialEq)]
pub struct ParamError {
    pub key: String,
    pub message: String,
}

impl Params {
    /// Checks what deserialization cannot: relations between fields.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        let mut names = std::collections::BTreeSet::new();
        for (i, scene) in self.scene.iter().enumerate() {
            let key = |field: &str| format!("scene.{i}.{field}");
            if scene.name.is_empty()
                || !scene
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            {
                return Err(ParamError {
                    key: key("name"),
                    message: format!(
                        "expected a name of letters, digits, `-` or `_`, found {:?}",
                        scene.name
                    ),
                });
            }
            if !names.insert(scene.name.as_str()) {
                return Err(ParamError {
                    key: key("name"),
                    message: format!("scene name {:?} is used twice", scene.name),
                });
            }
            let ratio = scene.frame_dt.get() / scene.dt.get();
            if ratio.round() < 1.0 || (ratio - ratio.round()).abs() > 1e-9 * ratio {
                return Err(ParamError {
                    key: key("frame_dt"),
                    message: format!(
                        "expected a whole multiple of dt = {}, found {} ({ratio} steps)",
                        scene.dt.get(),
                        scene.frame_dt.get()
                    ),
                });
            }
            if scene.frame_dt.get() > scene.duration.get() {
                return Err(ParamError {
                    key: key("duration"),
                    message: "expected a duration of at least one frame_dt".into(),
                });
            }
            if !(scene.spin_jitter >= 0.0 && scene.spin_jitter.is_finite()) {
                return Err(ParamError {
                    key: key("spin_jitter"),
                    message: format!("expected a number ≥ 0, found {}", scene.spin_jitter),
                });
            }
            if scene
                .gravity
                .iter()
                .chain(&scene.spin)
                .any(|x| !x.is_finite())
            {
                return Err(ParamError {
                    key: key("gravity"),
                    message: "expected finite numbers".into(),
                });
            }
        }
        Ok(())
    }
}

impl Scene {
    /// Integration steps per logged frame.
    pub fn steps_per_frame(&self) -> u64 {
        (self.frame_dt.get() / self.dt.get()).round() as u64
    }

    /// Logged frames per run (the initial state included).
    pub fn frames_per_run(&self) -> u64 {
        (self.duration.get() / self.frame_dt.get() + 1e-9).floor() as u64 + 1
    }

    /// The scene's `/state` layout.
    pub fn layout(&self) -> StateLayout {
        let names = |n: &[&str]| n.iter().map(|s| s.to_string()).collect();
        StateLayout {
            scene: self.name.clone(),
            state: names(&tumbler::STATE_NAMES),
            variables: names(&tumbler::VARIABLE_NAMES),
        }
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
        .map_err(|e| Error::Invalid(format!("simulate.{}: {}", e.key, e.message)))?;
    let layouts: Vec<StateLayout> = params.scene.iter().map(Scene::layout).collect();
    let total_steps: u64 = params
        .scene
        .iter()
        .map(|s| s.runs.0 * (s.frames_per_run() - 1) * s.steps_per_frame())
        .sum();
    progress.start("simulate", total_steps, "steps");

    let mut log = StateLogWriter::create(&out_dir.join(TRAJECTORY_FILE), &layouts)?;
    let mut stats = stats::VariableStats::default();
    let mut log_time_ns = 0u64;
    for (scene_index, scene) in params.scene.iter().enumerate() {
        log.metadata(
            &format!("alnlab.model.{}", scene.name),
            [("json".to_string(), model_json(scene).to_string())].into(),
        )?;
        let frame_ns = (scene.frame_dt.get() * 1e9).round() as u64;
        for run in 0..scene.runs.0 as u32 {
            simulate_run(scene, seed, scene_index, run, |frame| {
                stats.add(&layouts[scene_index].variables, &frame.variables);
                log.write(scene_index, log_time_ns, frame)?;
                log_time_ns += frame_ns;
                if frame.frame > 0 {
                    progress.advance(scene.steps_per_frame());
                }
                Ok(())
            })?;
        }
    }
    // Stats first: if it fails, no log is renamed into place either.
    stats.write(&out_dir.join(STATS_FILE), provenance)?;
    log.finish(provenance)
}

/// Simulates one run of `scene`, handing every logged frame to `on_frame`.
/// A non-finite value stops the run with an error naming scene, run, step
/// and variable; nothing non-finite reaches `on_frame`.
pub fn simulate_run(
    scene: &Scene,
    seed: u64,
    scene_index: usize,
    run: u32,
    mut on_frame: impl FnMut(&StateFrame) -> Result<()>,
) -> Result<()> {
    let body = tumbler::Body::solid_box(
        scene.mass.get(),
        scene.size.map(Positive::get),
        scene.gravity,
    );
    let mut rng = ChaCha8Rng::seed_from_u64(run_seed(seed, scene_index, run));
    let jitter = scene.spin_jitter;
    let spin = Vector3::from(
        scene
            .spin
            .map(|w| w + jitter * rng.random_range(-1.0..=1.0)),
    );
    let axis = Vector3::new(
        rng.random_range(-1.0..=1.0),
        rng.random_range(-1.0..=1.0),
        rng.random_range(-1.0..=1.0),
    );
    let mut state = tumbler::State {
        p: Vector3::zeros(),
        q: UnitQuaternion::from_scaled_axis(axis * std::f64::consts::PI),
        v: Vector3::zeros(),
        omega: spin,
    };
    let dt = scene.dt.get();
    let steps_per_frame = scene.steps_per_frame();
    let mut generalized = [0.0; 13];
    let mut variables = [0.0; 12];
    let mut frame = StateFrame {
        time: 0.0,
        run,
        frame: 0,
        state: vec![0.0; 13],
        variables: vec![0.0; 12],
    };
    for index in 0..scene.frames_per_run() {
        if index > 0 {
            for _ in 0..steps_per_frame {
                tumbler::step(&body, &mut state, dt, scene.integrator);
            }
        }
        tumbler::generalized_state(&body, &state, &mut generalized);
        tumbler::variables(&body, &state, &mut variables);
        let names = tumbler::STATE_NAMES.iter().zip(&generalized);
        let values = names.chain(tumbler::VARIABLE_NAMES.iter().zip(&variables));
        if let Some((name, value)) = values.into_iter().find(|(_, v)| !v.is_finite()) {
            return Err(Error::Diverged(format!(
                "scene `{}`, run {run}, step {}: {name} became {value}; \
                 the integration is unstable (try a smaller dt)",
                scene.name,
                index * steps_per_frame
            )));
        }
        frame.time = index as f64 * scene.frame_dt.get();
        frame.frame = index as u32;
        frame.state.copy_from_slice(&generalized);
        frame.variables.copy_from_slice(&variables);
        on_frame(&frame)?;
    }
    Ok(())
}

/// The seed of one run, mixed from the experiment seed, scene and run so runs
/// are independent and reproducible.
fn run_seed(seed: u64, scene_index: usize, run: u32) -> u64 {
    let mut x =
        seed ^ ((scene_index as u64) << 32 | u64::from(run)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    // splitmix64 finalizer
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// The scene's model as JSON (metadata record `alnlab.model.<scene>`).
fn model_json(scene: &Scene) -> serde_json::Value {
    let body = tumbler::Body::solid_box(
        scene.mass.get(),
        scene.size.map(Positive::get),
        scene.gravity,
    );
    let inertia_about_hinge = body.inertia_matrix()
        + (nalgebra::Matrix3::identity() * body.c.norm_squared() - body.c * body.c.transpose())
            * body.mass;
    serde_json::json!({
        "scene": scene.name,
        "kind": scene.kind,
        "gravity": scene.gravity,
        "dt": scene.dt,
        "frame_dt": scene.frame_dt,
        "integrator": scene.integrator,
        "links": [{
            "parent": -1,
            "joint": "free",
            "mass": body.mass,
            "c": body.c.as_slice(),
            "J": inertia_about_hinge.as_slice(),
            "l": [0.0, 0.0, 0.0],
        }],
        "conventions": {
            "units": "SI",
            "quaternion_order": ["x", "y", "z", "w"],
            "frames": {
                "root.p": "inertial", "root.q": "link to inertial", "root.v": "inertial",
                "v": "link", "a": "link", "omega": "link", "omega_dot": "link",
            },
            "J": "about the proximal hinge, link frame, column-major",
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_and_steps() {
        let scene = Scene::default();
        assert_eq!(scene.steps_per_frame(), 10);
        assert_eq!(scene.frames_per_run(), 1001);
    }

    #[test]
    fn frame_dt_must_be_a_multiple_of_dt() {
        let params = Params {
            scene: vec![Scene {
                frame_dt: Positive(0.0105),
                ..Scene::default()
            }],
        };
        let err = params.validate().unwrap_err();
        assert_eq!(err.key, "scene.0.frame_dt");
        assert!(err.message.contains("whole multiple of dt"));
    }

    #[test]
    fn blow_up_names_scene_run_step_and_variable() {
        let scene = Scene {
            spin: [1e300, 1e300, 1e300],
            spin_jitter: 0.0,
            ..Scene::default()
        };
        let mut frames = 0;
        let err = simulate_run(&scene, 1, 0, 0, |_| {
            frames += 1;
            Ok(())
        })
        .unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("scene `tumbler`, run 0, step"), "{msg}");
        assert_eq!(err.exit_code(), 2);
        assert!(frames <= 1);
    }

    #[test]
    fn writes_log_and_stats_that_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let params = Params::default();
        run(
            &params,
            7,
            &Provenance::default(),
            dir.path(),
            &alnlab_common::Silent,
        )
        .unwrap();
        let log =
            alnlab_common::state_log::StateLog::read(&dir.path().join(TRAJECTORY_FILE)).unwrap();
        let frames = &log.scenes[0].frames;
        assert_eq!(frames.len(), 2 * 1001);
        assert_eq!((frames[1001].run, frames[1001].frame), (1, 0));
        assert!(log.metadata["alnlab.model.tumbler"]["json"].contains("\"parent\":-1"));
        let stats = alnlab_common::table::Table::read(&dir.path().join(STATS_FILE)).unwrap();
        assert_eq!(stats.num_rows(), 12);
        // Independent check of one statistic: the mean of omega.1.y.
        let k = tumbler::VARIABLE_NAMES
            .iter()
            .position(|n| *n == "omega.1.y")
            .unwrap();
        let mean = frames.iter().map(|f| f.variables[k]).sum::<f64>() / frames.len() as f64;
        let got = stats.f64_column("mean").unwrap().value(k);
        assert!(
            (got - mean).abs() < 1e-12 * mean.abs().max(1.0),
            "{got} vs {mean}"
        );
    }
}
