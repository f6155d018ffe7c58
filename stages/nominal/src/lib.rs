//! The nominal stage (issue 43): what the simulator a user has predicts for
//! every pair of `pairs.parquet`. The simulator is the scene as written —
//! the nominal model, without a plant's departures from it
//! (`alnlab_physics::plant`) — stepping each pair's logged current frame one
//! frame on, its run's controller replayed to that instant
//! (`alnlab_physics::replay`). Of a scene without a plant, at its own step,
//! that is the logged next frame to rounding; of a plant, it is what the
//! nominal model gets wrong, which a learned correction can learn (the test
//! stage's hybrids).
//!
//! Writes `nominal.parquet` in `pairs.parquet`'s layout
//! (`alnlab_tables::pairs`): the same keys row for row, the `x.` columns the
//! pair's current values as logged, the `y.` columns the nominal
//! simulator's next frame. The simulator steps at each scene's own
//! integration step (`frame_dt / dt`), the nominal model at its most
//! accurate, unless the scene's `nominal_steps` names a coarser one.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use alnlab_common::state_log::StateFrame;
use alnlab_common::{Error, Progress, Provenance, Result};
use alnlab_physics::replay::{Replayer, SceneReplay};
use alnlab_tables::pairs::{self, Pairs, Side};
use arrow_array::Array;

/// Version of what this stage writes (part of every cache key; 2: joint
/// limits sized on what the joint moves; 3: implicit drives, mimic joints).
pub const FORMAT_VERSION: u32 = 3;

/// File name of the nominal predictions.
pub const NOMINAL_FILE: &str = "nominal.parquet";

/// The files the stage reads.
pub struct Inputs<'a> {
    /// The trajectory log (MCAP) the pairs came from.
    pub trajectory: &'a Path,
    /// The pairs table to predict.
    pub pairs: &'a Path,
}

/// Reads the trajectory and its pairs, writes `out_dir/nominal.parquet`.
pub fn run(
    inputs: &Inputs,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let Inputs {
        trajectory,
        pairs: pairs_path,
    } = *inputs;
    let log = alnlab_common::state_log::read(trajectory)?;
    let pairs = Pairs::read(pairs_path)?;
    let replays = SceneReplay::from_log(&log).map_err(|m| Error::bad_file(trajectory, m))?;
    let variables: Vec<&str> = pairs.variables().iter().map(String::as_str).collect();
    // Each scene's frames by (run, frame), and where each of the table's
    // variables sits among the scene's.
    let mut frames: HashMap<(&str, u32, u32), &StateFrame> = HashMap::new();
    let mut columns: HashMap<&str, Vec<Option<usize>>> = HashMap::new();
    for scene in &log.scenes {
        let name = scene.layout.scene.as_str();
        for f in &scene.frames {
            frames.insert((name, f.run, f.frame), f);
        }
        let names = &scene.layout.variables;
        columns.insert(
            name,
            variables
                .iter()
                .map(|v| names.iter().position(|n| n == v))
                .collect(),
        );
    }
    let keys = pairs.keys();
    // In time order within each run, so each run's controller only moves
    // forward.
    let mut order: Vec<usize> = (0..keys.len()).collect();
    order.sort_by(|&a, &b| {
        let (a, b) = (&keys[a], &keys[b]);
        (&a.scene, a.run, a.step).cmp(&(&b.scene, b.run, b.step))
    });
    let mut replayers: BTreeMap<&str, Replayer> = replays
        .iter()
        .map(|(name, r)| (name.as_str(), r.replayer()))
        .collect();
    let mut next_values = vec![vec![None; keys.len()]; variables.len()];
    let mut next = StateFrame::default();
    progress.start("nominal", keys.len() as u64, "pairs");
    for (done, r) in order.into_iter().enumerate() {
        let key = &keys[r];
        let missing = || {
            Error::bad_file(
                pairs_path,
                format!(
                    "row {r}: scene `{}`, run {}, frame {} is not in {}",
                    key.scene,
                    key.run,
                    key.step,
                    trajectory.display()
                ),
            )
        };
        let scene = key.scene.as_str();
        let from = frames
            .get(&(scene, key.run, key.step))
            .ok_or_else(missing)?;
        let replayer = replayers.get_mut(scene).ok_or_else(missing)?;
        let steps = replays[scene].prepared.scene.nominal_steps_per_frame();
        replayer
            .next_frame(from, steps, &mut next)
            .map_err(|e| match e {
                Error::Diverged(m) => Error::Diverged(format!(
                    "{m}: the scene as written cannot be simulated from the plant's states"
                )),
                e => e,
            })?;
        for (values, column) in next_values.iter_mut().zip(&columns[scene]) {
            values[r] = column.map(|i| next.variables[i]);
        }
        if done % 1024 == 1023 {
            progress.advance(1024);
        }
    }
    let current: Vec<_> = variables
        .iter()
        .map(|v| pairs.column(Side::Current, v))
        .collect::<Result<_>>()?;
    let value = |side: Side, k: usize, r: usize| match side {
        Side::Current => current[k].is_valid(r).then(|| current[k].value(r)),
        Side::Next => next_values[k][r],
    };
    pairs::write(
        &out_dir.join(NOMINAL_FILE),
        keys,
        &variables,
        value,
        provenance,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_common::Silent;

    /// Simulates `scenes` (the `[[scene]]` tables of a `[simulate]` table),
    /// pairs every frame and runs the stage: the pairs and the nominal
    /// predictions read back.
    fn nominal(dir: &Path, scenes: &str) -> Result<(Pairs, Pairs)> {
        let sim: alnlab_simulate::Params = toml::from_str(scenes).unwrap();
        let none = Provenance::default();
        alnlab_simulate::run(&sim, 3, &none, dir, &Silent).unwrap();
        let trajectory = dir.join(alnlab_simulate::TRAJECTORY_FILE);
        let stride = alnlab_stride::Params {
            n: alnlab_common::params::Count(1),
            ..Default::default()
        };
        alnlab_stride::run(&stride, 3, &trajectory, &none, dir, &Silent).unwrap();
        let pairs_path = dir.join(pairs::FILE);
        let inputs = Inputs {
            trajectory: &trajectory,
            pairs: &pairs_path,
        };
        run(&inputs, &none, dir, &Silent)?;
        Ok((
            Pairs::read(&pairs_path)?,
            Pairs::read(&dir.join(NOMINAL_FILE))?,
        ))
    }

    const WORM: &str = "[[scene]]\nname = \"worm\"\nkind = \"worm\"\nruns = 1\nduration = 1.0\n";

    /// The largest difference between two columns' values.
    fn most_apart(a: &Pairs, b: &Pairs, side: Side, variable: &str) -> f64 {
        let (a, b) = (
            a.column(side, variable).unwrap(),
            b.column(side, variable).unwrap(),
        );
        a.values()
            .iter()
            .zip(b.values())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn without_a_plant_the_nominal_simulator_is_the_log() {
        let dir = tempfile::tempdir().unwrap();
        let (pairs, nominal) = nominal(dir.path(), WORM).unwrap();
        assert_eq!(pairs.keys(), nominal.keys());
        assert_eq!(pairs.variables(), nominal.variables());
        for v in pairs.variables() {
            assert_eq!(most_apart(&pairs, &nominal, Side::Current, v), 0.0, "{v}");
            let off = most_apart(&pairs, &nominal, Side::Next, v);
            assert!(off < 1e-9, "{v}: {off}");
        }
    }

    #[test]
    fn a_plant_is_what_the_nominal_simulator_gets_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let plant = format!("{WORM}[scene.plant]\nmass_scale = 2.0\nviscous_friction = 0.05\n");
        let (pairs, nominal) = nominal(dir.path(), &plant).unwrap();
        assert_eq!(
            most_apart(&pairs, &nominal, Side::Current, "omega.1.z"),
            0.0
        );
        let off = most_apart(&pairs, &nominal, Side::Next, "omega.1.z");
        assert!(
            off > 1e-3,
            "the heavier, damped plant moves otherwise: {off}"
        );
    }

    #[test]
    fn a_coarser_nominal_step_is_a_cheaper_and_wronger_simulator() {
        let dir = tempfile::tempdir().unwrap();
        let pendulum = "[[scene]]\nname = \"p\"\nkind = \"pendulum\"\nlinks = 2\nruns = 1\n\
                        duration = 1.0\nnominal_steps = 2\n";
        let (pairs, nominal) = nominal(dir.path(), pendulum).unwrap();
        let off = most_apart(&pairs, &nominal, Side::Next, "omega.2.y");
        assert!(
            off > 1e-6 && off < 0.5,
            "two steps a frame instead of ten: near the log, not on it ({off})"
        );
    }

    #[test]
    fn pairs_of_another_log_are_refused_naming_the_row() {
        let dir = tempfile::tempdir().unwrap();
        nominal(dir.path(), WORM).unwrap();
        // A log of a shorter run: the pairs reach past its frames.
        let other = tempfile::tempdir().unwrap();
        let short = WORM.replace("duration = 1.0", "duration = 0.5");
        let sim: alnlab_simulate::Params = toml::from_str(&short).unwrap();
        let none = Provenance::default();
        alnlab_simulate::run(&sim, 3, &none, other.path(), &Silent).unwrap();
        let (trajectory, pairs) = (
            other.path().join(alnlab_simulate::TRAJECTORY_FILE),
            dir.path().join(pairs::FILE),
        );
        let inputs = Inputs {
            trajectory: &trajectory,
            pairs: &pairs,
        };
        let e = run(&inputs, &none, other.path(), &Silent).unwrap_err();
        let message = e.to_string();
        assert!(
            message.contains("pairs.parquet: row ") && message.contains("is not in"),
            "{message}"
        );
        assert_eq!(e.exit_code(), 2);
        assert!(!other.path().join(NOMINAL_FILE).exists());
    }
}
