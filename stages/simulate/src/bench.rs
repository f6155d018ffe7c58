//! `alnlab bench sim`: the simulator's speed. Each figure is the median of
//! repeated timed runs on one core.

use std::collections::BTreeMap;
use std::time::Instant;

use alnlab_common::params::{Count, Positive};
use alnlab_common::{Error, Provenance, Result, Silent};
use serde::Serialize;

use crate::Params;
use alnlab_physics::controller::{ControllerKind, ControllerParams};
use alnlab_physics::integrate::Stepper;
use alnlab_physics::scene::{Scene, SceneKind, run_rng};
use alnlab_physics::{Integrator, Prepared, SceneForces};

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

/// Runs every simulator benchmark; `repeat` timed runs each.
pub fn run(repeat: usize) -> Result<SimBench> {
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
    Ok(SimBench {
        worm_no_contact_ns_per_step,
        worm_contact_ns_per_step,
        chain_ns_per_step,
        stage_steps_per_s: total_steps / median(seconds),
    })
}
