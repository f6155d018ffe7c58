//! Re-simulating logged frames, for the simulator baseline of the test
//! stage: a log is self-describing — its `alnlab.scene` records rebuild each
//! scene, its `/state` messages hold full generalized states — so any frame
//! can be stepped forward again, at the logged integration step or a
//! coarser one, to see what a cheaper simulator would have predicted.
//!
//! A re-simulation starts from the logged state with the run's controller
//! replayed to that instant; only the free root's tracked momentum starts
//! afresh there, so at the logged step it reproduces the next frame to
//! rounding — of a scene logged without a plant. A scene with a plant
//! (`crate::plant`) is re-simulated as written, its nominal model: the
//! simulator a user has.

use std::collections::BTreeMap;

use alnlab_common::state_log::{StateFrame, StateLog};
use alnlab_common::{Error, Result};

use crate::{Prepared, Runner, Scene, state_from_generalized};

/// Name of the metadata records holding what re-simulates each scene: its
/// resolved parameters, its index and the experiment seed.
pub const SCENE_RECORD: &str = "alnlab.scene";

/// The `alnlab.scene` record of a scene; a robot's also holds its
/// description (`urdf`).
pub fn scene_record(scene: &Scene, index: usize, seed: u64) -> BTreeMap<String, String> {
    let json = serde_json::to_string(scene).expect("scenes serialize");
    let mut record = BTreeMap::from([
        ("scene".into(), scene.name.clone()),
        ("index".into(), index.to_string()),
        ("seed".into(), seed.to_string()),
        ("json".into(), json),
    ]);
    if let Some(text) = &scene.description {
        record.insert("urdf".into(), text.to_string());
    }
    record
}

/// A logged scene, rebuilt.
pub struct SceneReplay {
    /// The scene as written — the nominal model a user has.
    pub prepared: Prepared,
    /// The scene as simulated, where it differs: with its plant.
    pub plant: Option<Prepared>,
    /// The scene's index in the experiment and the experiment's seed, which
    /// seed a runner of it ([`Runner::new`]).
    pub index: usize,
    pub seed: u64,
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
            let mut scene: Scene = serde_json::from_str(field("json")?)
                .map_err(|e| format!("an {SCENE_RECORD} record does not hold a scene ({e})"))?;
            if let Some(expected) = &scene.file_sha256 {
                let text = field("urdf")?;
                let found = alnlab_common::hash::sha256_hex(text.as_bytes());
                if &found != expected {
                    return Err(format!(
                        "scene `{}`: the robot description in its {SCENE_RECORD} record has \
                         sha256 {found}, not the {expected} it was simulated from",
                        scene.name
                    ));
                }
                scene.description = Some(text.as_str().into());
            }
            // What the simulate stage checked, checked again: a record it
            // did not write must not reach the simulator.
            scene
                .clone()
                .resolve()
                .validate()
                .map_err(|(field, message)| {
                    format!(
                        "scene `{}` in an {SCENE_RECORD} record: `{field}`: {message}",
                        scene.name
                    )
                })?;
            let number = |key: &str| -> std::result::Result<u64, String> {
                field(key)?
                    .parse()
                    .map_err(|e| format!("{SCENE_RECORD} `{key}`: {e}"))
            };
            let replay = SceneReplay {
                // The simulator a user has is the scene as written: a
                // plant's departure from it is what no nominal model knows.
                prepared: Prepared::new(&scene.nominal()),
                plant: scene.plant.is_some().then(|| Prepared::new(&scene)),
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

    /// The scene as its data were simulated: the plant where it has one,
    /// else the scene as written.
    pub fn simulated(&self) -> &Prepared {
        self.plant.as_ref().unwrap_or(&self.prepared)
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
