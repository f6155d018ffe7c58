//! `alnlab bench sim`: the simulator's speed. Each figure is the median of
//! repeated timed runs on one core.

use std::collections::BTreeMap;
use std::time::Instant;

use alnlab_common::params::{Count, Positive};
use alnlab_common::{Error, Provenance, Result, Silent};
use serde::Serialize;

use crate::Params;
use alnlab_physics::batch::Batch;
use alnlab_physics::controller::{Amplitude, ControllerKind, ControllerParams};
use alnlab_physics::dynamics::{Derivative, Kinematics, Loads, State, Workspace};
use alnlab_physics::integrate::{Evaluation, Forces, Stepper};
use alnlab_physics::model::Model;
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
    /// The worm in its arena and each vendored robot: the articulated-body
    /// algorithm and a step, one state at a time and many at once.
    pub models: Vec<ModelBench>,
}

/// One model's figures on the [`BATCH`] states of a simulated run, on one
/// thread, each the median with the fastest and slowest of interleaved
/// rounds: ns per state of the articulated-body algorithm (kinematics and
/// forward dynamics, as `pinocchio.aba` computes them) one state at a time
/// and all states at once ([`alnlab_physics::batch`]); ns per state of a
/// semi-implicit Euler step under each state's loads held, both ways; a
/// robot's whole step with its controller and joint laws; and Pinocchio's
/// `aba` on the same states, timed by a harness in the same rounds, when
/// one is given.
#[derive(Debug, Serialize)]
pub struct ModelBench {
    /// The model: `worm`, or a vendored robot's file name.
    pub model: String,
    /// Degrees of freedom (a free base's 6 included).
    pub dof: usize,
    /// How many states each round times, each once per pass.
    pub states: usize,
    /// ns per state, the articulated-body algorithm one state at a time.
    pub aba_ns: [f64; 3],
    /// ns per state, the articulated-body algorithm on all states at once.
    pub batched_aba_ns: [f64; 3],
    /// ns per state, a semi-implicit Euler step (held loads) one at a time.
    pub held_step_ns: [f64; 3],
    /// ns per state, the same step on all states at once.
    pub batched_step_ns: [f64; 3],
    /// A robot's: ns per step of its scene (controller and joint laws).
    pub step_ns: Option<[f64; 3]>,
    /// Pinocchio's `aba` on the same states, ns per call.
    pub pinocchio_aba_ns: Option<[f64; 3]>,
}

/// How many states the model benchmarks time, one at a time and batched.
pub const BATCH: usize = 256;

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
        // The series' integrator since it began (the default is implicit;
        // without one-DOF joints the two are the same bit for bit).
        integrator: Integrator::SemiImplicitEuler,
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
            integrator: Integrator::SemiImplicitEuler,
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
    let mut models = vec![model_bench(&worm(true), None, repeat.max(5), None)?];
    for &(name, text, base, amplitude) in &ROBOTS {
        let scene = robot_scene(name, text, base, amplitude)?;
        let robot = pinocchio.map(|harness| (harness, text, base));
        models.push(model_bench(&scene, Some(20_000), repeat.max(5), robot)?);
    }
    Ok(SimBench {
        worm_no_contact_ns_per_step,
        worm_contact_ns_per_step,
        chain_ns_per_step,
        stage_steps_per_s: total_steps / median(seconds),
        models,
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

/// Times one model in `rounds` interleaved rounds (after one to warm up):
/// ours one at a time, ours batched, the scene's whole step (`scene_steps`
/// steps a round, if given) and Pinocchio's harness (a robot's, if given)
/// on the same states.
fn model_bench(
    scene: &Scene,
    scene_steps: Option<usize>,
    rounds: usize,
    pinocchio: Option<(&Pinocchio, &str, Base)>,
) -> Result<ModelBench> {
    let name = scene.name.as_str();
    let p = Prepared::new(scene);
    // BATCH states of a simulated run, with the loads acting on each.
    let mut states = Vec::new();
    let mut run = 0;
    while states.len() < BATCH {
        alnlab_physics::simulate_run(&p, 1, 0, run, |frame, _| {
            states.push(frame.state.clone());
            Ok(())
        })?;
        run += 1;
    }
    states.truncate(BATCH);
    let mut eval = Evaluation::new(&p.model);
    let mut forces = SceneForces::new(&p);
    let (states, loads): (Vec<State>, Vec<Loads>) = states
        .iter()
        .map(|values| {
            let state = state_from_generalized(&p.model, values).expect("its own log");
            eval.run(&p.model, &state, &mut forces);
            (state, eval.loads.clone())
        })
        .unzip();
    let passes = 100_000 / BATCH;
    let per_state = |clock: Instant| clock.elapsed().as_nanos() as f64 / (passes * BATCH) as f64;
    let harness_input = pinocchio.map(|_| harness_states(&p, &states, &loads));
    let mut kin = Kinematics::new(&p.model);
    let mut ws = Workspace::new(&p.model);
    let mut out = Derivative::zeros(&p.model);
    let mut stepper = Stepper::new(&p.model);
    let start = Batch::pack(&p.model, &states, &loads);
    let dt = p.scene.dt.get();
    let mut times: [Vec<f64>; 6] = Default::default();
    for round in 0..=rounds {
        let mut batch = Batch::pack(&p.model, &states, &loads);
        let clock = Instant::now();
        for _ in 0..passes {
            for (state, loads) in states.iter().zip(&loads) {
                kin.update(&p.model, state);
                ws.forward(&p.model, state, &kin, loads, &mut out);
                std::hint::black_box(&out);
            }
        }
        let aba = per_state(clock);
        let clock = Instant::now();
        for _ in 0..passes {
            for g in 0..batch.states.len() {
                std::hint::black_box(batch.accelerations(&p.model, g));
            }
        }
        let batched_aba = per_state(clock);
        // Each pass steps every state once from where it started (held
        // loads would carry a state far from them), the copy timed both ways.
        let mut stepped = states.clone();
        let clock = Instant::now();
        for _ in 0..passes {
            for ((state, start), loads) in stepped.iter_mut().zip(&states).zip(&loads) {
                state.clone_from(start);
                stepper.restart();
                let mut held = Held(loads);
                stepper.step(
                    &p.model,
                    state,
                    dt,
                    Integrator::SemiImplicitEuler,
                    &mut held,
                );
            }
        }
        let held_step = per_state(clock);
        let clock = Instant::now();
        for _ in 0..passes {
            batch.copy_states_from(&start);
            batch.step(&p.model, dt);
        }
        let batched_step = per_state(clock);
        let step = scene_steps
            .map(|steps| ns_per_step(scene, steps, 1))
            .transpose()?;
        let pinocchio_ns = match (pinocchio, &harness_input) {
            (Some((harness, text, base)), Some(input)) => {
                Some(harness.time(name, text, base, input, passes)?)
            }
            _ => None,
        };
        let mut batched = states.clone();
        batch.unpack(&mut batched);
        if !stepped.iter().chain(&batched).all(State::is_finite) {
            return Err(Error::Diverged(format!("benchmark model `{name}` blew up")));
        }
        // Round 0 warms up.
        if round > 0 {
            let figures = [
                Some(aba),
                Some(batched_aba),
                Some(held_step),
                Some(batched_step),
                step,
                pinocchio_ns,
            ];
            for (list, x) in times.iter_mut().zip(figures) {
                list.extend(x);
            }
        }
    }
    let [aba, batched_aba, held_step, batched_step, step, theirs] = times;
    let optional = |xs: Vec<f64>| (!xs.is_empty()).then(|| spread(xs));
    Ok(ModelBench {
        model: name.into(),
        dof: p.model.dof(),
        states: BATCH,
        aba_ns: spread(aba),
        batched_aba_ns: spread(batched_aba),
        held_step_ns: spread(held_step),
        batched_step_ns: spread(batched_step),
        step_ns: optional(step),
        pinocchio_aba_ns: optional(theirs),
    })
}

/// Each state's loads held through a step, as a batch steps.
struct Held<'a>(&'a Loads);

impl Forces for Held<'_> {
    fn apply(&mut self, _: &Model, _: &State, _: &Kinematics, loads: &mut Loads) {
        loads.clone_from(self.0);
    }
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
fn harness_states(p: &Prepared, states: &[State], loads: &[Loads]) -> String {
    use std::fmt::Write as _;
    let robot = p.robot.as_ref().expect("a robot scene");
    let mut text = format!("joints {}", robot.joints.len() - 1);
    for joint in &robot.joints[1..] {
        let _ = write!(text, " {joint}");
    }
    let _ = writeln!(text, "\nstates {}", states.len());
    for (state, loads) in states.iter().zip(loads) {
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
