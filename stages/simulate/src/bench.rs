//! `alnlab bench sim`: the simulator's speed. Each figure is the median of
//! repeated timed runs on one core.

use std::collections::BTreeMap;
use std::time::Instant;

use alnlab_common::params::{Count, Positive};
use alnlab_common::{Error, Provenance, Result, Silent};
use serde::Serialize;

use crate::Params;
use alnlab_physics::controller::{Amplitude, ControllerKind, ControllerParams};
use alnlab_physics::dynamics::{Derivative, Kinematics, Loads, State, Workspace};
use alnlab_physics::integrate::{Evaluation, Stepper};
use alnlab_physics::scene::{Scene, SceneKind, run_rng};
use alnlab_physics::urdf::Base;
use alnlab_physics::{Integrator, Prepared, SceneForces, state_from_generalized};

/// The figures of `alnlab bench sim`, with stable keys for `--json`. The
/// per-step figures time the dynamics alone (passive scenes, semi-implicit
/// Euler); the stage figure includes the controller, logging and writing.
#[derive(Debug, Serialize)]
pub struct SimBench {
    /// The worm (3 links) without floor or wall, semi-implicit Euler.
    pub worm_no_contact_ns_per_step: f64,
    /// The worm on the floor in its arena under the random controller.
    pub worm_contact_ns_per_step: f64,
    /// Free chains, by link count, semi-implicit Euler.
    pub chain_ns_per_step: BTreeMap<usize, f64>,
    /// The whole simulate stage (worm, contacts, MCAP and stats writing).
    pub stage_steps_per_s: f64,
    /// Each vendored robot: the articulated-body algorithm and a whole step.
    pub robots: Vec<RobotBench>,
}

/// One robot's figures: ns per call of the articulated-body algorithm
/// (kinematics and forward dynamics, as `pinocchio.aba` computes them) on
/// the states of a simulated run, and ns per integration step with its
/// controller and joint laws; each the median, with the range, of the
/// rounds; beside them Pinocchio's `aba` on the same states, timed by a
/// harness in the same rounds, interleaved, when one is given.
#[derive(Debug, Serialize)]
pub struct RobotBench {
    /// The robot (the vendored file's name).
    pub robot: String,
    /// Degrees of freedom (a free base's 6 included).
    pub dof: usize,
    /// How many states each round times, each once per pass.
    pub states: usize,
    /// ns per ABA call: median, fastest and slowest round.
    pub aba_ns: [f64; 3],
    /// ns per semi-implicit Euler step (ABA, joint laws, controller).
    pub step_ns: [f64; 3],
    /// Pinocchio's `aba` on the same states: median, fastest, slowest.
    pub pinocchio_aba_ns: Option<[f64; 3]>,
}

/// The vendored robots, by name: their description, base and random
/// controller's amplitude (N m; Solo 12's legs weigh grams).
const ROBOTS: [(&str, &str, Base, f64); 2] = [
    (
        "ur5",
        include_str!("../../../robots/ur5/ur5_robot.urdf"),
        Base::Fixed,
        20.0,
    ),
    (
        "solo12",
        include_str!("../../../robots/solo12/solo12.urdf"),
        Base::Free,
        0.2,
    ),
];

/// Median, fastest and slowest of `xs`.
fn spread(mut xs: Vec<f64>) -> [f64; 3] {
    xs.sort_by(f64::total_cmp);
    [xs[xs.len() / 2], xs[0], xs[xs.len() - 1]]
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// Median nanoseconds per step of `scene` (passive: no control torques)
/// over `repeat` timed runs of `steps` steps each, after a warm-up run.
pub fn ns_per_step(scene: &Scene, steps: usize, repeat: usize) -> Result<f64> {
    let p = Prepared::new(scene);
    let timed = |steps: usize| {
        let mut state = p.scene.initial_state(&p.model, &mut run_rng(1, 0, 0));
        let mut forces = SceneForces::new(&p);
        let mut stepper = Stepper::new(&p.model);
        let dt = p.scene.dt.get();
        let clock = Instant::now();
        for _ in 0..steps {
            stepper.step(&p.model, &mut state, dt, p.scene.integrator, &mut forces);
        }
        let ns = clock.elapsed().as_nanos() as f64 / steps as f64;
        if state.is_finite() {
            Ok(ns)
        } else {
            Err(Error::Diverged(format!(
                "benchmark scene `{}` blew up",
                p.scene.name
            )))
        }
    };
    timed(steps / 10)?;
    Ok(median(
        (0..repeat).map(|_| timed(steps)).collect::<Result<_>>()?,
    ))
}

fn worm(contact: bool) -> Scene {
    Scene {
        name: "worm".into(),
        kind: SceneKind::Worm,
        floor: Some(contact),
        arena_radius: Some(if contact { 2.0 } else { 0.0 }),
        initial_height: Some(if contact { 0.1 } else { 0.5 }),
        ..Scene::default()
    }
    .resolve()
}

/// Runs every simulator benchmark; `repeat` timed runs each (at least 5
/// rounds for the robots), a robot's ABA beside `pinocchio`'s if given.
pub fn run(repeat: usize, pinocchio: Option<&Pinocchio>) -> Result<SimBench> {
    let steps = 20_000;
    let worm_no_contact_ns_per_step = ns_per_step(&worm(false), steps, repeat)?;
    let worm_contact_ns_per_step = ns_per_step(&worm(true), steps, repeat)?;
    let mut chain_ns_per_step = BTreeMap::new();
    for links in [1, 2, 4, 8, 16, 32, 64] {
        let chain = Scene {
            name: format!("chain{links}"),
            kind: SceneKind::Chain,
            links: Some(Count(links as u64)),
            initial_spin: Some(0.2),
            controller: Some(ControllerParams {
                kind: ControllerKind::None,
                ..ControllerParams::default()
            }),
            ..Scene::default()
        }
        .resolve();
        chain_ns_per_step.insert(
            links,
            ns_per_step(&chain, steps / links.max(4) * 4, repeat)?,
        );
    }

    // The stage: 2 runs of 20 s of the worm in its arena, written to disk.
    let params = Params {
        scene: vec![Scene {
            runs: Count(2),
            duration: Positive(20.0),
            integrator: Integrator::SemiImplicitEuler,
            ..worm(true)
        }],
        ..Params::default()
    };
    let total_steps = 2.0 * 20.0 / 1e-3;
    let mut seconds = Vec::new();
    for _ in 0..repeat.max(1) {
        let dir = std::env::temp_dir().join(format!("alnlab-bench-sim-{}", std::process::id()));
        let clock = Instant::now();
        crate::run(&params, 1, &Provenance::default(), &dir, &Silent)?;
        seconds.push(clock.elapsed().as_secs_f64());
        let _ = std::fs::remove_dir_all(&dir);
    }
    let robots = ROBOTS
        .iter()
        .map(|&(name, text, base, amplitude)| {
            let scene = robot_scene(name, text, base, amplitude)?;
            robot(&scene, text, base, repeat.max(5), pinocchio)
        })
        .collect::<Result<_>>()?;
    Ok(SimBench {
        worm_no_contact_ns_per_step,
        worm_contact_ns_per_step,
        chain_ns_per_step,
        stage_steps_per_s: total_steps / median(seconds),
        robots,
    })
}

/// A robot's scene: a random controller, in the air (no floor).
fn robot_scene(name: &str, text: &str, base: Base, amplitude: f64) -> Result<Scene> {
    let mut scene = Scene {
        name: name.into(),
        kind: SceneKind::Urdf,
        base: Some(base),
        initial_height: Some(1.0),
        controller: Some(ControllerParams {
            kind: ControllerKind::Random,
            amplitude: vec![Amplitude::Axis(amplitude)],
            ..ControllerParams::default()
        }),
        ..Scene::default()
    };
    scene
        .set_description(text)
        .map_err(|e| Error::Invalid(format!("vendored robot {name}: {e}")))?;
    Ok(scene.resolve())
}

/// Times one robot in `rounds` interleaved rounds: ours, then Pinocchio's
/// harness (if any) on the same states.
fn robot(
    scene: &Scene,
    text: &str,
    base: Base,
    rounds: usize,
    pinocchio: Option<&Pinocchio>,
) -> Result<RobotBench> {
    let name = scene.name.as_str();
    let p = Prepared::new(scene);
    // The states of a 2 s run, one per frame, with the efforts acting.
    let mut states = Vec::new();
    alnlab_physics::simulate_run(&p, 1, 0, 0, |frame, _| {
        states.push(frame.state.clone());
        Ok(())
    })?;
    states.truncate(200);
    let mut eval = Evaluation::new(&p.model);
    let mut forces = SceneForces::new(&p);
    let cases: Vec<(State, Loads)> = states
        .iter()
        .map(|values| {
            let state = state_from_generalized(&p.model, values).expect("its own log");
            eval.run(&p.model, &state, &mut forces);
            (state, eval.loads.clone())
        })
        .collect();
    let passes = 200_000 / cases.len();
    let harness_input = pinocchio.map(|_| harness_states(&p, &cases));
    let (mut ours, mut theirs, mut steps) = (Vec::new(), Vec::new(), Vec::new());
    let mut kin = Kinematics::new(&p.model);
    let mut ws = Workspace::new(&p.model);
    let mut out = Derivative::zeros(&p.model);
    for round in 0..=rounds {
        let clock = Instant::now();
        for _ in 0..passes {
            for (state, loads) in &cases {
                kin.update(&p.model, state);
                ws.forward(&p.model, state, &kin, loads, &mut out);
                std::hint::black_box(&out);
            }
        }
        let aba = clock.elapsed().as_nanos() as f64 / (passes * cases.len()) as f64;
        let step = ns_per_step(scene, 20_000, 1)?;
        let pinocchio_ns = match (pinocchio, &harness_input) {
            (Some(harness), Some(input)) => Some(harness.time(name, text, base, input, passes)?),
            _ => None,
        };
        // Round 0 warms up.
        if round > 0 {
            ours.push(aba);
            steps.push(step);
            theirs.extend(pinocchio_ns);
        }
    }
    Ok(RobotBench {
        robot: name.into(),
        dof: p.model.dof(),
        states: cases.len(),
        aba_ns: spread(ours),
        step_ns: spread(steps),
        pinocchio_aba_ns: (!theirs.is_empty()).then(|| spread(theirs)),
    })
}

/// Pinocchio's `aba` timed by a harness program (`bench/pinocchio/aba.cpp`,
/// built by `bench/pinocchio/build.sh`): given a URDF, `fixed` or `free`,
/// a file of states and a pass count, it prints its ns per call.
pub struct Pinocchio {
    /// The harness binary.
    pub harness: std::path::PathBuf,
}

impl Pinocchio {
    /// ns per `aba` call over the states in `input`, `passes` times each.
    fn time(&self, name: &str, urdf: &str, base: Base, input: &str, passes: usize) -> Result<f64> {
        let dir = std::env::temp_dir().join(format!(
            "alnlab-bench-pinocchio-{}-{name}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let (urdf_path, states_path) = (dir.join("robot.urdf"), dir.join("states.txt"));
        std::fs::write(&urdf_path, urdf).map_err(|e| Error::io(&urdf_path, e))?;
        std::fs::write(&states_path, input).map_err(|e| Error::io(&states_path, e))?;
        let output = std::process::Command::new(&self.harness)
            .arg(&urdf_path)
            .arg(match base {
                Base::Fixed => "fixed",
                Base::Free => "free",
            })
            .arg(&states_path)
            .arg(passes.to_string())
            .output()
            .map_err(|e| Error::io(&self.harness, e))?;
        let _ = std::fs::remove_dir_all(&dir);
        let stdout = String::from_utf8_lossy(&output.stdout);
        if !output.status.success() {
            return Err(Error::Invalid(format!(
                "{}: {}",
                self.harness.display(),
                String::from_utf8_lossy(&output.stderr).trim()
            )));
        }
        stdout
            .split_whitespace()
            .nth(1)
            .and_then(|x| x.parse().ok())
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "{}: expected `ns_per_call <number>`, printed {stdout:?}",
                    self.harness.display()
                ))
            })
    }
}

/// The harness's input: the joints by name, then per state the free
/// base's position, orientation (x, y, z, w), linear and angular velocity
/// (root frame), and each joint's position, velocity and effort.
fn harness_states(p: &Prepared, cases: &[(State, Loads)]) -> String {
    use std::fmt::Write as _;
    let robot = p.robot.as_ref().expect("a robot scene");
    let mut text = format!("joints {}", robot.joints.len() - 1);
    for joint in &robot.joints[1..] {
        let _ = write!(text, " {joint}");
    }
    let _ = writeln!(text, "\nstates {}", cases.len());
    for (state, loads) in cases {
        if p.model.root == alnlab_physics::model::Root::Free {
            let q = state.orient[0];
            for x in state.root_p.iter().chain([q.i, q.j, q.k, q.w].iter()) {
                let _ = write!(text, "{x:e} ");
            }
            for x in state.root_v.iter().chain(state.rates[0].iter()) {
                let _ = write!(text, "{x:e} ");
            }
        }
        for i in 1..p.model.len() {
            let _ = write!(
                text,
                "{:e} {:e} {:e} ",
                state.q[i], state.qd[i], loads.effort[i]
            );
        }
        text.push('\n');
    }
    text
}
