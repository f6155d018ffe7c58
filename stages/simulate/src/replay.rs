//! Re-simulating logged frames, for the simulator baseline of the test
//! stage: a log is self-describing — its `alnlab.scene` records rebuild each
//! scene, its `/state` messages hold full generalized states — so any frame
//! can be stepped forward again, at the logged integration step or a
//! coarser one, to see what a cheaper simulator would have predicted.
//!
//! A re-simulation starts from the logged state with the run's controller
//! replayed to that instant; only the free root's tracked momentum starts
//! afresh there, so at the logged step it reproduces the next frame to
//! rounding.

use std::collections::BTreeMap;

use alnlab_common::state_log::{StateFrame, StateLog};
use alnlab_common::{Error, Result};

use crate::{Prepared, Runner, SCENE_RECORD, Scene, state_from_generalized};

/// The `alnlab.scene` record of a scene.
pub fn scene_record(scene: &Scene, index: usize, seed: u64) -> BTreeMap<String, String> {
    let json = serde_json::to_string(scene).expect("scenes serialize");
    BTreeMap::from([
        ("scene".into(), scene.name.clone()),
        ("index".into(), index.to_string()),
        ("seed".into(), seed.to_string()),
        ("json".into(), json),
    ])
}

/// A logged scene, rebuilt.
pub struct SceneReplay {
    pub prepared: Prepared,
    index: usize,
    seed: u64,
}

impl SceneReplay {
    /// Every scene of a log, by name; an error if a record is missing or
    /// unreadable (logs written before format 3 have none).
    pub fn from_log(log: &StateLog) -> std::result::Result<BTreeMap<String, SceneReplay>, String> {
        let mut scenes = BTreeMap::new();
        for record in log.records(SCENE_RECORD) {
            let field = |key: &str| {
                record
                    .get(key)
                    .ok_or_else(|| format!("an {SCENE_RECORD} record lacks `{key}`"))
            };
            let scene: Scene = serde_json::from_str(field("json")?)
                .map_err(|e| format!("an {SCENE_RECORD} record does not hold a scene ({e})"))?;
            let number = |key: &str| -> std::result::Result<u64, String> {
                field(key)?
                    .parse()
                    .map_err(|e| format!("{SCENE_RECORD} `{key}`: {e}"))
            };
            let replay = SceneReplay {
                prepared: Prepared::new(&scene),
                index: number("index")? as usize,
                seed: number("seed")?,
            };
            scenes.insert(scene.name.clone(), replay);
        }
        for scene in &log.scenes {
            if !scenes.contains_key(&scene.layout.scene) {
                return Err(format!(
                    "scene `{}` has no {SCENE_RECORD} record to re-simulate it from",
                    scene.layout.scene
                ));
            }
        }
        Ok(scenes)
    }

    /// A re-simulator of this scene's frames.
    pub fn replayer(&self) -> Replayer<'_> {
        Replayer {
            scene: self,
            runner: None,
        }
    }
}

/// Re-simulates frames of one scene, keeping the run's controller between
/// frames asked for in order (each frame of a run later than the last).
pub struct Replayer<'a> {
    scene: &'a SceneReplay,
    /// The run and the frame last re-simulated, with its moving parts.
    runner: Option<(u32, u32, Runner<'a>)>,
}

impl Replayer<'_> {
    /// The frame after `from` (a logged frame of this scene), re-simulated
    /// from its state in `steps` steps of frame_dt / steps. An error says
    /// the simulation blew up (the step is too coarse) or the logged state
    /// does not fit the model.
    pub fn next_frame(
        &mut self,
        from: &StateFrame,
        steps: u64,
        next: &mut StateFrame,
    ) -> Result<()> {
        let replay = self.scene;
        let p = &replay.prepared;
        let mut state = state_from_generalized(&p.model, &from.state).ok_or_else(|| {
            Error::Invalid(format!(
                "scene `{}`: a logged state of {} numbers does not fit its model",
                p.scene.name,
                from.state.len()
            ))
        })?;
        // The controller only goes forward in time: a new one for another
        // run or an earlier frame.
        let reuse = matches!(&self.runner, Some((run, frame, _)) if *run == from.run && *frame <= from.frame);
        if !reuse {
            let runner = Runner::new(p, replay.seed, replay.index, from.run);
            self.runner = Some((from.run, from.frame, runner));
        }
        let (_, last, runner) = self.runner.as_mut().expect("just made");
        *last = from.frame;
        runner.restart();
        let dt = p.scene.frame_dt.get() / steps as f64;
        let first = u64::from(from.frame) * steps;
        runner.advance(&mut state, first, steps, dt).map_err(|_| {
            Error::Diverged(format!(
                "scene `{}`, run {}, frame {}: re-simulation at dt = {dt} blew up",
                p.scene.name, from.run, from.frame
            ))
        })?;
        runner.observe(&state, (first + steps) as f64 * dt, next);
        next.run = from.run;
        next.frame = from.frame + 1;
        next.time = f64::from(next.frame) * p.scene.frame_dt.get();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Params, TRAJECTORY_FILE};
    use alnlab_common::{Provenance, Silent};

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
        crate::run(&params, 7, &provenance, dir.path(), &Silent).unwrap();
        let log = StateLog::read(&dir.path().join(TRAJECTORY_FILE)).unwrap();
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
}
