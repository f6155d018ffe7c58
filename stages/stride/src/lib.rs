//! The stride stage (paper §4.3): from `trajectory.mcap`, take every n-th
//! logged frame of each run and its successor, and write them side by side to
//! `pairs.parquet`, never pairing across runs. A `split` column assigns each
//! row to `train` or `test`.
//!
//! Columns: `scene` (string), `run` (u32), `step` (u32, the frame index of the
//! `x.` values), `split` (string), then `x.<variable>` and `y.<variable>` (f64)
//! for the union of the scenes' variables (null where a scene lacks one).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::params::{Count, Fraction};
use alnlab_common::state_log::StateLog;
use alnlab_common::{Error, Progress, Provenance, Result, table};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array};
use serde::{Deserialize, Serialize};

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 1;
/// File name of the pairs table.
pub const PAIRS_FILE: &str = "pairs.parquet";

/// How rows are assigned to training and testing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    /// Each row goes to test with probability `test_fraction`, decided by a
    /// seeded hash of (scene, run, step), so train and test never share a row.
    #[default]
    Disjoint,
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
}

impl Default for Params {
    fn default() -> Self {
        Params {
            n: Count(9),
            offset: 0,
            split: Split::Disjoint,
            test_fraction: Fraction(0.5),
        }
    }
}

impl Params {
    /// Checks relations between fields; on error, the key and what is allowed.
    pub fn validate(&self) -> std::result::Result<(), (String, String)> {
        if self.offset >= self.n.0 {
            return Err((
                "offset".into(),
                format!(
                    "expected an offset below n = {}, found {}",
                    self.n.0, self.offset
                ),
            ));
        }
        Ok(())
    }
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
        .map_err(|(key, message)| Error::Invalid(format!("stride.{key}: {message}")))?;
    let log = StateLog::read(trajectory)?;
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

    let (mut scene_col, mut run_col, mut step_col, mut split_col) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut x_cols: Vec<Vec<Option<f64>>> = vec![Vec::new(); variables.len()];
    let mut y_cols: Vec<Vec<Option<f64>>> = vec![Vec::new(); variables.len()];
    for scene in &log.scenes {
        // Where each of the table's variables sits in this scene's frames.
        let index: Vec<Option<usize>> = variables
            .iter()
            .map(|v| scene.layout.variables.iter().position(|s| s == v))
            .collect();
        for pair in scene.frames.windows(2) {
            let (x, y) = (&pair[0], &pair[1]);
            let taken = u64::from(x.frame) % params.n.0 == params.offset;
            if !taken || y.run != x.run || y.frame != x.frame + 1 {
                continue;
            }
            scene_col.push(scene.layout.scene.clone());
            run_col.push(x.run);
            step_col.push(x.frame);
            let test =
                unit_hash(seed, &scene.layout.scene, x.run, x.frame) < params.test_fraction.get();
            split_col.push(if test { "test" } else { "train" });
            for (k, i) in index.iter().enumerate() {
                x_cols[k].push(i.map(|i| x.variables[i]));
                y_cols[k].push(i.map(|i| y.variables[i]));
            }
        }
        progress.advance(scene.frames.len() as u64);
    }
    if scene_col.is_empty() {
        return Err(Error::bad_file(
            trajectory,
            format!(
                "has no frame pairs with n = {} and offset = {}",
                params.n.0, params.offset
            ),
        ));
    }

    let x_names: Vec<String> = variables.iter().map(|v| format!("x.{v}")).collect();
    let y_names: Vec<String> = variables.iter().map(|v| format!("y.{v}")).collect();
    let mut columns: Vec<(&str, Arc<dyn Array>)> = vec![
        ("scene", Arc::new(StringArray::from(scene_col))),
        ("run", Arc::new(UInt32Array::from(run_col))),
        ("step", Arc::new(UInt32Array::from(step_col))),
        ("split", Arc::new(StringArray::from(split_col))),
    ];
    for (name, values) in x_names.iter().zip(x_cols).chain(y_names.iter().zip(y_cols)) {
        columns.push((name, Arc::new(Float64Array::from(values))));
    }
    table::write_parquet(
        &out_dir.join(PAIRS_FILE),
        &table::batch(columns),
        provenance,
    )
}

/// A seeded hash of a row's identity, uniform in [0, 1).
fn unit_hash(seed: u64, scene: &str, run: u32, step: u32) -> f64 {
    // FNV-1a over the scene name, then splitmix64 over everything.
    let name = scene.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    });
    let mut x =
        seed ^ name ^ (u64::from(run) << 32 | u64::from(step)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_common::Silent;
    use alnlab_common::table::Table;

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

        let log = StateLog::read(&trajectory).unwrap();
        let frames = &log.scenes[0].frames;
        let pairs = Table::read(&dir.path().join(PAIRS_FILE)).unwrap();
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
