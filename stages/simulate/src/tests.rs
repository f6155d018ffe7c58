//! Stage-level tests: parameters, the log and the statistics, a blow-up that
//! leaves nothing, and the log replaying through `alnlab_physics::replay`.

use alnlab_common::params::{Count, Positive};
use alnlab_common::table::Table;
use alnlab_common::{Provenance, Silent};
use alnlab_physics::contact::ContactParams;
use alnlab_physics::replay::SceneReplay;
use arrow_array::Array;

use crate::*;

#[test]
fn frame_dt_must_be_a_multiple_of_dt() {
    let params = Params {
        scene: vec![Scene {
            frame_dt: Positive(0.0105),
            ..Scene::default()
        }],
        ..Params::default()
    };
    let err = params.validate().unwrap_err();
    assert_eq!(err.0, "scene.0.frame_dt");
    assert!(err.1.contains("whole multiple of dt"));
}

#[test]
fn a_recordings_logged_controller_is_refused() {
    let params = Params {
        scene: vec![Scene {
            controller: Some(alnlab_physics::controller::ControllerParams {
                kind: ControllerKind::Logged,
                ..Default::default()
            }),
            ..Scene::default()
        }],
        ..Params::default()
    };
    let err = params.validate().unwrap_err();
    assert_eq!(err.0, "scene.0.controller.kind");
    assert!(err.1.contains("`logged` is a recording's"), "{}", err.1);
}

#[test]
fn writes_log_and_stats_that_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let params = Params {
        scene: vec![
            Scene {
                duration: Positive(2.0),
                ..Scene::default()
            },
            Scene {
                name: "pend".into(),
                kind: SceneKind::Pendulum,
                runs: Count(1),
                duration: Positive(1.0),
                ..Scene::default()
            },
        ],
        ..Params::default()
    };
    run(&params, 7, &Provenance::default(), dir.path(), &Silent).unwrap();
    let log = alnlab_common::state_log::read(&dir.path().join(TRAJECTORY_FILE)).unwrap();
    let frames = &log.scenes[0].frames;
    assert_eq!(frames.len(), 2 * 201);
    assert_eq!((frames[201].run, frames[201].frame), (1, 0));
    assert_eq!(log.scenes[1].frames.len(), 101);
    let models: Vec<_> = log.records(MODEL_RECORD).collect();
    assert_eq!(models.len(), 2);
    assert!(models[0]["json"].contains("\"parent\":-1") && models[1]["scene"] == "pend");

    // Statistics against an independent computation over the decoded log.
    let stats = Table::read(&dir.path().join(STATS_FILE)).unwrap();
    let names = stats
        .column::<arrow_array::StringArray>("variable")
        .unwrap();
    let row = (0..names.len())
        .find(|&r| names.value(r) == "omega.2.y")
        .unwrap();
    let values: Vec<f64> = log
        .scenes
        .iter()
        .flat_map(|s| {
            let k = s
                .layout
                .variables
                .iter()
                .position(|n| n == "omega.2.y")
                .unwrap();
            s.frames.iter().map(move |f| f.variables[k])
        })
        .collect();
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let std =
        (values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (values.len() - 1) as f64).sqrt();
    let got = |c: &str| stats.f64_column(c).unwrap().value(row);
    assert!((got("mean") - mean).abs() < 1e-9 * mean.abs().max(1.0));
    assert!((got("std") - std).abs() < 1e-9 * std);
    assert_eq!(got("max"), values.iter().cloned().fold(f64::MIN, f64::max));
}

/// Hard case 7: an unstable scene stops with a clear error and leaves no log.
#[test]
fn blow_up_names_scene_run_step_and_variable_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let params = Params {
        scene: vec![Scene {
            name: "brittle".into(),
            dt: Positive(5e-3),
            frame_dt: Positive(1e-2),
            contact: ContactParams {
                stiffness: Positive(1e8),
                ..ContactParams::default()
            },
            ..Scene::default()
        }],
        ..Params::default()
    };
    let err = run(&params, 1, &Provenance::default(), dir.path(), &Silent).unwrap_err();
    let msg = err.to_string();
    assert!(msg.starts_with("scene `brittle`, run 0, step "), "{msg}");
    assert!(
        msg.contains(" became ") && msg.contains("unstable"),
        "{msg}"
    );
    assert_eq!(err.exit_code(), 2);
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing left behind"
    );
}

#[test]
fn at_the_logged_step_a_replayed_frame_is_the_next_logged_frame() {
    let dir = tempfile::tempdir().unwrap();
    let scene: Scene =
        toml::from_str("name = \"worm\"\nkind = \"worm\"\nruns = 1\nduration = 3.0").unwrap();
    let params = Params {
        scene: vec![scene.resolve()],
        ..Params::default()
    };
    let provenance = Provenance {
        stage: "simulate".into(),
        params: serde_json::Value::Null,
        inputs: Default::default(),
    };
    run(&params, 7, &provenance, dir.path(), &Silent).unwrap();
    let log = alnlab_common::state_log::read(&dir.path().join(TRAJECTORY_FILE)).unwrap();
    let replays = SceneReplay::from_log(&log).unwrap();
    let worm = &replays["worm"];
    let mut replayer = worm.replayer();
    let frames = &log.scenes[0].frames;
    let steps = worm.prepared.scene.steps_per_frame();
    let mut next = frames[0].clone();
    let mut worst = 0f64;
    for pair in frames.windows(2) {
        replayer.next_frame(&pair[0], steps, &mut next).unwrap();
        assert_eq!((next.run, next.frame), (pair[1].run, pair[1].frame));
        for (a, b) in next.state.iter().zip(&pair[1].state) {
            worst = worst.max((a - b).abs() / b.abs().max(1.0));
        }
    }
    eprintln!("replayed frames at the logged dt: worst state difference {worst:e}");
    assert!(worst < 1e-9, "{worst:e}");
    // Coarser steps give another (finite) frame; going back in time
    // starts the run's controller again, to the same frame as before.
    replayer.next_frame(&frames[100], 2, &mut next).unwrap();
    let first = next.clone();
    replayer.next_frame(&frames[50], 2, &mut next).unwrap();
    replayer.next_frame(&frames[100], 2, &mut next).unwrap();
    assert_eq!(next, first);
    let coarse = next
        .state
        .iter()
        .zip(&frames[101].state)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(coarse > 0.0 && coarse.is_finite(), "{coarse}");
}
