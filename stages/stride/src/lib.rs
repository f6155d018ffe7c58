//! The stride stage (paper §4.3): from `trajectory.mcap`, take every n-th
//! logged frame of each run and its successor, and write them side by side to
//! `pairs.parquet`, never pairing across runs. A `split` column assigns each
//! row to training and testing.
//!
//! Columns: `scene` (string), `run` (u32), `step` (u32, the frame index of the
//! `x.` values), `split` (string: `train`, `test`, or `both` — only the
//! `paper` split puts a row in both), then `x.<variable>` and `y.<variable>`
//! (f64) for the union of the scenes' variables (null where a scene lacks one).
//!
//! The `by-trajectory` split holds whole trajectories out: a scene's run is
//! one trajectory, or, where its scene record says which trajectory each
//! run records (`run_trajectories`, the ingest stage's: a table's, or the
//! group's of tables that repeat one), the runs of one trajectory are.
//! The trajectories are dealt into `fold.of` folds in order (the i-th into
//! fold i mod `fold.of`), and fold `fold.index` is tested: a run's
//! replicates, one a fold, test each trajectory once.

use std::path::Path;

use alnlab_common::hash::{fnv1a, mix_seed};
use alnlab_common::params::{self, Count, Fraction, ParamError};
use alnlab_common::state_log::{SCENE_RECORD, StateFrame, StateLog};
use alnlab_common::{Error, Progress, Provenance, Result};
// A pair's split is its role here: `Split` is the parameter that assigns them.
use alnlab_tables::pairs::{self, Key, Side, Split as Role};
use serde::{Deserialize, Serialize};

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 3;

/// How rows are assigned to training and testing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    /// Each row goes to test with probability `test_fraction`, decided by a
    /// seeded hash of (scene, run, step), so train and test never share a
    /// row; `train_rows` / `test_rows`, if given, keep that many of each
    /// (chosen by another seeded hash, so from all over the log).
    #[default]
    Disjoint,
    /// As the paper (§4.3): train on the first `train_rows` rows and test on
    /// the first `test_rows` rows, so with 1000 and 9000 one test row in nine
    /// was also seen in training.
    Paper,
    /// Whole trajectories held out: the trajectories of one fold
    /// (`fold`) are tested, the others trained on; `train_rows` /
    /// `test_rows`, if given, cap each side as `disjoint` does.
    ByTrajectory,
}

impl Split {
    /// The split as a report names it.
    pub fn describe(self) -> &'static str {
        match self {
            Split::Disjoint => {
                "rows drawn at random, so neighbouring rows of one trajectory can fall on both sides"
            }
            Split::Paper => {
                "the paper's §4.3 split: training on the first train_rows rows and testing on the \
                 first test_rows, so the training rows are tested too"
            }
            Split::ByTrajectory => {
                "by trajectory: whole trajectories held out, one fold of them a replicate"
            }
        }
    }
}

/// The `[stride]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Take every n-th frame (paper: 9).
    pub n: Count,
    /// Index of the first frame taken; less than `n`.
    pub offset: u64,
    /// How rows are split into train and test.
    pub split: Split,
    /// Share of rows that go to test (with `split = "disjoint"`).
    pub test_fraction: Fraction,
    /// Number of training rows (required by `paper`, a cap for `disjoint`).
    pub train_rows: Option<Count>,
    /// Number of test rows (required by `paper`, a cap for `disjoint`).
    pub test_rows: Option<Count>,
    /// With `by-trajectory`: the fold tested (set by the run: the
    /// replicate's, of as many folds as replicates).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fold: Option<Fold>,
}

/// One fold of a `by-trajectory` split: the `index`-th (from 0) of `of`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fold {
    pub index: u64,
    pub of: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            n: Count(9),
            offset: 0,
            split: Split::Disjoint,
            test_fraction: Fraction(0.5),
            train_rows: None,
            test_rows: None,
            fold: None,
        }
    }
}

impl Params {
    /// Checks relations between fields; on error, the key and what is allowed.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        if self.offset >= self.n.0 {
            return Err((
                "offset".into(),
                format!(
                    "expected an offset below n = {}, found {}",
                    self.n.0, self.offset
                ),
            ));
        }
        if self.split == Split::ByTrajectory
            && self.fold.is_none_or(|f| f.of < 2 || f.index >= f.of)
        {
            return Err((
                "split".into(),
                "the `by-trajectory` split (the default for recorded data) tests one fold of \
                 the trajectories a replicate: it needs experiment.replicates of at least 2 \
                 (or set [stride] split = \"disjoint\" to draw rows at random)"
                    .into(),
            ));
        }
        if self.split == Split::Paper {
            for (key, value) in [
                ("train_rows", self.train_rows),
                ("test_rows", self.test_rows),
            ] {
                if value.is_none() {
                    return Err((
                        key.into(),
                        "the `paper` split needs train_rows and test_rows".into(),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// One pair: the scene, its trajectory (an index among the log's) and the
/// two frames.
struct Pair<'a> {
    scene: usize,
    trajectory: usize,
    x: &'a StateFrame,
    y: &'a StateFrame,
}

/// Reads `trajectory`, writes `out_dir/pairs.parquet`.
pub fn run(
    params: &Params,
    seed: u64,
    trajectory: &Path,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    params
        .validate()
        .map_err(|e| params::invalid("stride", e))?;
    let log = alnlab_common::state_log::read(trajectory)?;
    let mut variables: Vec<&str> = Vec::new();
    for scene in &log.scenes {
        for v in &scene.layout.variables {
            if !variables.contains(&v.as_str()) {
                variables.push(v);
            }
        }
    }
    let total: usize = log.scenes.iter().map(|s| s.frames.len()).sum();
    progress.start("stride", total as u64, "frames");

    let mut pairs = Vec::new();
    let mut trajectories: Vec<(usize, u32)> = Vec::new();
    for (scene_index, scene) in log.scenes.iter().enumerate() {
        let recorded = run_trajectories(&log, &scene.layout.scene)
            .map_err(|e| Error::bad_file(trajectory, e))?;
        for window in scene.frames.windows(2) {
            let (x, y) = (&window[0], &window[1]);
            let taken = u64::from(x.frame) % params.n.0 == params.offset;
            if taken && y.run == x.run && y.frame == x.frame + 1 {
                let id = match &recorded {
                    Some(ids) => *ids.get(x.run as usize).ok_or_else(|| {
                        Error::bad_file(
                            trajectory,
                            format!(
                                "scene `{}`: run {} has no trajectory in its scene record's \
                                 run_trajectories",
                                scene.layout.scene, x.run
                            ),
                        )
                    })?,
                    None => x.run,
                };
                let t = match trajectories.iter().position(|&t| t == (scene_index, id)) {
                    Some(t) => t,
                    None => {
                        trajectories.push((scene_index, id));
                        trajectories.len() - 1
                    }
                };
                pairs.push(Pair {
                    scene: scene_index,
                    trajectory: t,
                    x,
                    y,
                });
            }
        }
        progress.advance(scene.frames.len() as u64);
    }
    if let Some(fold) = params.fold.filter(|_| params.split == Split::ByTrajectory)
        && (trajectories.len() as u64) < fold.of
    {
        return Err(Error::bad_file(
            trajectory,
            format!(
                "has {} trajectories, fewer than the {} folds the `by-trajectory` split (the \
                 default for recorded data) deals them into, one a replicate: lower \
                 experiment.replicates, or set [stride] split = \"disjoint\" to draw rows at \
                 random",
                trajectories.len(),
                fold.of
            ),
        ));
    }
    if pairs.is_empty() {
        return Err(Error::bad_file(
            trajectory,
            format!(
                "has no frame pairs with n = {} and offset = {}",
                params.n.0, params.offset
            ),
        ));
    }
    let scene_name = |p: &Pair| log.scenes[p.scene].layout.scene.as_str();
    let roles = assign(
        params,
        seed,
        &pairs,
        |p| (scene_name(p), p.x.run, p.x.frame),
        |p| p.trajectory,
    )
    .map_err(|e| Error::bad_file(trajectory, e))?;
    let chosen: Vec<(&Pair, Role)> = pairs
        .iter()
        .zip(roles)
        .filter_map(|(p, r)| r.map(|r| (p, r)))
        .collect();

    // Where each of the table's variables sits in each scene's frames.
    let index: Vec<Vec<Option<usize>>> = log
        .scenes
        .iter()
        .map(|s| {
            variables
                .iter()
                .map(|v| s.layout.variables.iter().position(|n| n == v))
                .collect()
        })
        .collect();
    let keys: Vec<Key> = chosen
        .iter()
        .map(|(p, role)| Key {
            scene: scene_name(p).to_string(),
            run: p.x.run,
            step: p.x.frame,
            split: *role,
        })
        .collect();
    let value = |side: Side, k: usize, row: usize| {
        let (p, _) = chosen[row];
        let frame = if side == Side::Next { p.y } else { p.x };
        index[p.scene][k].map(|i| frame.variables[i])
    };
    pairs::write(
        &out_dir.join(pairs::FILE),
        &keys,
        &variables,
        value,
        provenance,
    )
}

/// Which trajectory each run of `scene` records, where its scene record
/// says (`run_trajectories`: one index a run, comma-separated).
fn run_trajectories(log: &StateLog, scene: &str) -> std::result::Result<Option<Vec<u32>>, String> {
    let record = log
        .records(SCENE_RECORD)
        .find(|r| r.get("scene").is_some_and(|s| s == scene));
    let Some(list) = record.and_then(|r| r.get("run_trajectories")) else {
        return Ok(None);
    };
    list.split(',')
        .map(|t| {
            t.parse().map_err(|_| {
                format!(
                    "scene `{scene}`: run_trajectories `{list}` is not a list of trajectory \
                     indices"
                )
            })
        })
        .collect::<std::result::Result<_, _>>()
        .map(Some)
}

/// The split of every pair (`None`: left out), from its identity and its
/// trajectory (an index).
fn assign<T>(
    params: &Params,
    seed: u64,
    pairs: &[T],
    identity: impl Fn(&T) -> (&str, u32, u32),
    trajectory: impl Fn(&T) -> usize,
) -> std::result::Result<Vec<Option<Role>>, String> {
    match params.split {
        Split::Paper => {
            let (train, test) = (
                params.train_rows.expect("validated").get(),
                params.test_rows.expect("validated").get(),
            );
            if pairs.len() < train.max(test) {
                return Err(format!(
                    "has {} frame pairs; the paper split asks for {train} training and {test} test rows",
                    pairs.len()
                ));
            }
            Ok((0..pairs.len())
                .map(|i| match (i < train, i < test) {
                    (true, true) => Some(Role::Both),
                    (true, false) => Some(Role::Train),
                    (false, true) => Some(Role::Test),
                    (false, false) => None,
                })
                .collect())
        }
        Split::Disjoint | Split::ByTrajectory => {
            let mut roles: Vec<Option<Role>> = pairs
                .iter()
                .map(|p| {
                    let test = match (params.split, params.fold) {
                        (Split::ByTrajectory, Some(f)) => trajectory(p) as u64 % f.of == f.index,
                        _ => {
                            let (scene, run, step) = identity(p);
                            unit_hash(seed, scene, run, step) < params.test_fraction.get()
                        }
                    };
                    Some(if test { Role::Test } else { Role::Train })
                })
                .collect();
            for (role, cap) in [
                (Role::Train, params.train_rows),
                (Role::Test, params.test_rows),
            ] {
                let Some(cap) = cap else { continue };
                // Keep the `cap` rows of this split with the smallest second hash.
                let mut members: Vec<(f64, usize)> = roles
                    .iter()
                    .enumerate()
                    .filter(|(_, r)| **r == Some(role))
                    .map(|(i, _)| {
                        let (scene, run, step) = identity(&pairs[i]);
                        (unit_hash(!seed, scene, run, step), i)
                    })
                    .collect();
                if members.len() < cap.get() {
                    let with = match (params.split, params.fold) {
                        (Split::ByTrajectory, Some(f)) => {
                            format!("in fold {} of {} (by trajectory)", f.index + 1, f.of)
                        }
                        _ => format!("with test_fraction = {}", params.test_fraction.get()),
                    };
                    return Err(format!(
                        "has {} {} rows {with}, fewer than the {} asked for",
                        members.len(),
                        role.name(),
                        cap.get()
                    ));
                }
                members.sort_by(|a, b| a.0.total_cmp(&b.0));
                for &(_, i) in &members[cap.get()..] {
                    roles[i] = None;
                }
            }
            Ok(roles)
        }
    }
}

/// A seeded hash of a row's identity, uniform in [0, 1).
fn unit_hash(seed: u64, scene: &str, run: u32, step: u32) -> f64 {
    // FNV-1a over the scene name, then splitmix64 over everything.
    let name = fnv1a(scene.as_bytes(), 0);
    let x = mix_seed(seed ^ name, u64::from(run) << 32 | u64::from(step));
    (x >> 11) as f64 / (1u64 << 53) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_common::Silent;
    use alnlab_common::table::Table;
    use arrow_array::{Array, StringArray, UInt32Array};

    #[test]
    fn every_row_matches_the_log() {
        let dir = tempfile::tempdir().unwrap();
        let sim = alnlab_simulate::Params::default();
        alnlab_simulate::run(&sim, 3, &Provenance::default(), dir.path(), &Silent).unwrap();
        let trajectory = dir.path().join(alnlab_simulate::TRAJECTORY_FILE);
        let params = Params {
            offset: 4,
            ..Params::default()
        };
        run(
            &params,
            3,
            &trajectory,
            &Provenance::default(),
            dir.path(),
            &Silent,
        )
        .unwrap();

        let log = alnlab_common::state_log::read(&trajectory).unwrap();
        let frames = &log.scenes[0].frames;
        let pairs = Table::read(&dir.path().join(pairs::FILE)).unwrap();
        // 1001 frames per run: frames 4, 13, …, 994 have successors.
        assert_eq!(pairs.num_rows(), 2 * 111);
        let runs = pairs.column::<UInt32Array>("run").unwrap();
        let steps = pairs.column::<UInt32Array>("step").unwrap();
        let names = &log.scenes[0].layout.variables;
        for row in 0..pairs.num_rows() {
            let (r, s) = (runs.value(row), steps.value(row));
            assert_eq!(s % 9, 4);
            let at = |frame: u32| {
                frames
                    .iter()
                    .find(|f| f.run == r && f.frame == frame)
                    .unwrap()
            };
            for (k, name) in names.iter().enumerate() {
                let x = pairs.f64_column(&format!("x.{name}")).unwrap().value(row);
                let y = pairs.f64_column(&format!("y.{name}")).unwrap().value(row);
                assert_eq!(x, at(s).variables[k]);
                assert_eq!(y, at(s + 1).variables[k]);
            }
        }
        let split = pairs.column::<StringArray>("split").unwrap();
        let tests = (0..split.len())
            .filter(|&i| split.value(i) == "test")
            .count();
        assert!((70..=152).contains(&tests), "{tests} test rows of 222");
        assert!((0..split.len()).all(|i| matches!(split.value(i), "train" | "test")));
    }

    fn roles(params: &Params, n: u32) -> std::result::Result<Vec<Option<Role>>, String> {
        let ids: Vec<u32> = (0..n).collect();
        assign(
            params,
            5,
            &ids,
            |&i| ("s", i / 100, i % 100),
            |&i| (i / 100) as usize,
        )
    }

    #[test]
    fn paper_split_tests_on_a_superset_of_training() {
        let params = Params {
            split: Split::Paper,
            train_rows: Some(Count(100)),
            test_rows: Some(Count(900)),
            ..Params::default()
        };
        let r = roles(&params, 1200).unwrap();
        let count = |role| r.iter().filter(|x| **x == Some(role)).count();
        assert_eq!(
            (count(Role::Both), count(Role::Test), count(Role::Train)),
            (100, 800, 0)
        );
        assert_eq!(r.iter().filter(|x| x.is_none()).count(), 300);
        // One test row in nine was also seen in training, as in §4.3.
        assert_eq!(count(Role::Both) * 9, count(Role::Both) + count(Role::Test));
        let err = roles(&params, 500).unwrap_err();
        assert!(
            err.contains("asks for 100 training and 900 test rows"),
            "{err}"
        );
        let missing = Params {
            split: Split::Paper,
            ..Params::default()
        };
        assert_eq!(missing.validate().unwrap_err().0, "train_rows");
    }

    #[test]
    fn disjoint_split_caps_sizes_from_all_over() {
        let params = Params {
            train_rows: Some(Count(50)),
            test_rows: Some(Count(40)),
            ..Params::default()
        };
        let r = roles(&params, 1000).unwrap();
        let train: Vec<usize> = (0..1000).filter(|&i| r[i] == Some(Role::Train)).collect();
        assert_eq!(train.len(), 50);
        assert_eq!(r.iter().filter(|x| **x == Some(Role::Test)).count(), 40);
        assert!(
            train[0] < 200 && train[49] > 800,
            "spread over the log: {train:?}"
        );
        let too_many = Params {
            test_rows: Some(Count(900)),
            ..Params::default()
        };
        assert!(
            roles(&too_many, 1000)
                .unwrap_err()
                .contains("fewer than the 900 asked for")
        );
    }

    #[test]
    fn by_trajectory_tests_each_trajectory_in_one_fold_and_never_trains_on_it() {
        // 1000 rows: 10 trajectories (runs) of 100; 3 folds.
        let mut tested = vec![0; 10];
        for fold in 0..3 {
            let params = Params {
                split: Split::ByTrajectory,
                fold: Some(Fold { index: fold, of: 3 }),
                test_rows: Some(Count(250)),
                ..Params::default()
            };
            params.validate().unwrap();
            let r = roles(&params, 1000).unwrap();
            for t in 0..10 {
                let of = &r[t * 100..(t + 1) * 100];
                let is = |role| of.contains(&Some(role));
                assert!(
                    !(is(Role::Test) && is(Role::Train)),
                    "trajectory {t} on both sides"
                );
                if t as u64 % 3 == fold {
                    assert!(!is(Role::Train));
                    tested[t] += 1;
                } else {
                    assert!(of.iter().all(|x| *x == Some(Role::Train)));
                }
            }
            // Fold 0 holds trajectories 0, 3, 6, 9 (400 rows), capped at 250.
            let test = r.iter().filter(|x| **x == Some(Role::Test)).count();
            assert_eq!(test, 250.min(100 * [4, 3, 3][fold as usize]));
        }
        assert_eq!(tested, vec![1; 10]);
        let one = Params {
            split: Split::ByTrajectory,
            ..Params::default()
        };
        assert!(
            one.validate()
                .unwrap_err()
                .1
                .contains("experiment.replicates of at least 2")
        );
        let capped = Params {
            split: Split::ByTrajectory,
            fold: Some(Fold { index: 1, of: 3 }),
            test_rows: Some(Count(301)),
            ..Params::default()
        };
        let err = roles(&capped, 1000).unwrap_err();
        assert!(
            err.contains("has 300 test rows in fold 2 of 3 (by trajectory), fewer than the 301"),
            "{err}"
        );
    }

    #[test]
    fn offset_must_be_below_n() {
        let p = Params {
            offset: 9,
            ..Params::default()
        };
        assert_eq!(p.validate().unwrap_err().0, "offset");
    }

    #[test]
    fn unit_hash_is_uniform_enough() {
        let n = 100_000;
        let below = (0..n)
            .filter(|&i| unit_hash(5, "s", i / 1000, i % 1000) < 0.3)
            .count();
        assert!((below as f64 / n as f64 - 0.3).abs() < 0.01);
    }
}
