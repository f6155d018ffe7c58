//! The aggregate stage (issue 43; DAgger for models, Ross & Bagnell 2012;
//! Nagabandi et al. 2018): a round of the planner's own data joins the
//! training rows. It reads the pairs, their nominal predictions and levels
//! so far and the frames a round of planning executed (the plan stage's
//! `transitions.parquet` and `transitions-nominal.parquet`), and writes
//! the three tables again with those frames appended as training pairs —
//! quantized by the codebook the data were first quantized with, so that
//! every round's model learns in the same levels and is tested on the same
//! held-out rows.
//!
//! Each planned episode becomes a run of its scene numbered after every
//! run already there, so no key repeats; the planned frames' variables that
//! the pairs lack are dropped, and a variable the scene's logged frames
//! have and its planned ones lack is an error.

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::{Error, Progress, Provenance, Result};
use alnlab_tables::levels;
use alnlab_tables::pairs::{self, Key, Pairs, Side};
use arrow_array::{Array, Float64Array};

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 1;

/// The files this stage writes, under the names of the stages that first
/// wrote them.
pub const PAIRS_FILE: &str = pairs::FILE;
/// …
pub const NOMINAL_FILE: &str = "nominal.parquet";
/// …
pub const LEVELS_FILE: &str = levels::FILE;

/// Paths of what the stage reads.
pub struct Inputs<'a> {
    pub pairs: &'a Path,
    pub nominal: &'a Path,
    pub codebook: &'a Path,
    pub levels: &'a Path,
    pub transitions: &'a Path,
    pub transitions_nominal: &'a Path,
}

/// Appends the planned frames to the pairs, their nominal predictions and
/// levels, and writes the three into `out_dir`.
pub fn run(
    inputs: &Inputs,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let pairs = Pairs::read(inputs.pairs)?;
    let nominal = Pairs::read(inputs.nominal)?;
    let codebook = alnlab_tables::codebook::read(inputs.codebook)?;
    let levels = levels::Levels::read(inputs.levels, inputs.codebook)?;
    let planned = Pairs::read(inputs.transitions)?;
    let planned_nominal = Pairs::read(inputs.transitions_nominal)?;
    for (table, of) in [(&nominal, &pairs), (&planned_nominal, &planned)] {
        if table.keys() != of.keys() {
            return Err(Error::bad_file(
                table.path(),
                format!(
                    "does not hold the nominal predictions of {} ({} rows against {})",
                    of.path().display(),
                    table.len(),
                    of.len()
                ),
            ));
        }
    }
    if levels.keys() != pairs.keys() {
        return Err(Error::bad_file(
            inputs.levels,
            format!(
                "does not hold the levels of {} ({} rows against {})",
                inputs.pairs.display(),
                levels.len(),
                pairs.len()
            ),
        ));
    }
    progress.start("aggregate", 3, "tables");
    // Each planned episode a new run of its scene, after the runs there.
    let mut last_run: BTreeMap<&str, u32> = BTreeMap::new();
    for key in pairs.keys() {
        let last = last_run.entry(key.scene.as_str()).or_insert(0);
        *last = (*last).max(key.run);
    }
    let appended: Vec<Key> = planned
        .keys()
        .iter()
        .map(|k| Key {
            run: last_run.get(k.scene.as_str()).map_or(0, |r| r + 1) + k.run,
            ..k.clone()
        })
        .collect();
    let keys: Vec<Key> = pairs.keys().iter().cloned().chain(appended).collect();
    let variables: Vec<&str> = pairs.variables().iter().map(String::as_str).collect();
    // A planned scene's frames hold every variable its logged frames do.
    for v in variables
        .iter()
        .filter(|v| !planned.variables().iter().any(|n| n == *v))
    {
        let x = pairs.column(Side::Current, v)?;
        let logged = pairs
            .keys()
            .iter()
            .enumerate()
            .find(|(r, k)| x.is_valid(*r) && planned.keys().iter().any(|p| p.scene == k.scene));
        if let Some((_, k)) = logged {
            return Err(Error::bad_file(
                inputs.transitions,
                format!("has no `{v}`, which scene `{}` logs", k.scene),
            ));
        }
    }
    let before = pairs.len();
    for (old, new, file) in [
        (&pairs, &planned, PAIRS_FILE),
        (&nominal, &planned_nominal, NOMINAL_FILE),
    ] {
        let (old_x, old_y) = (
            columns(old, &variables, Side::Current)?,
            columns(old, &variables, Side::Next)?,
        );
        let (new_x, new_y) = (
            columns(new, &variables, Side::Current)?,
            columns(new, &variables, Side::Next)?,
        );
        let value = |side: Side, k: usize, r: usize| {
            let (column, row) = match (side, r < before) {
                (Side::Current, true) => (old_x[k], r),
                (Side::Next, true) => (old_y[k], r),
                (Side::Current, false) => (new_x[k], r - before),
                (Side::Next, false) => (new_y[k], r - before),
            };
            column.and_then(|c| c.is_valid(row).then(|| c.value(row)))
        };
        pairs::write(&out_dir.join(file), &keys, &variables, value, provenance)?;
        progress.advance(1);
    }
    let learned: Vec<_> = codebook.learned().collect();
    let names: Vec<&str> = learned.iter().map(|e| e.variable.as_str()).collect();
    let mut sides = Vec::with_capacity(2);
    for side in [Side::Current, Side::Next] {
        let mut columns = Vec::with_capacity(learned.len());
        for entry in &learned {
            let mut column = levels.column(side, entry)?.to_vec();
            let values = planned.column(side, &entry.variable).map_err(|_| {
                Error::bad_file(
                    inputs.transitions,
                    format!(
                        "has no `{}`, which the codebook learns: the planned scene's frames \
                         cannot be quantized",
                        entry.variable
                    ),
                )
            })?;
            for r in 0..values.len() {
                if values.is_null(r) {
                    return Err(Error::bad_file(
                        inputs.transitions,
                        format!("row {r}: `{}` is null", entry.variable),
                    ));
                }
                column.push(entry.quantizer.level(values.value(r)).0);
            }
            columns.push(column);
        }
        sides.push(columns);
    }
    levels::write(
        &out_dir.join(LEVELS_FILE),
        &keys,
        &names,
        &sides[0],
        &sides[1],
        provenance,
    )?;
    progress.advance(1);
    Ok(())
}

/// `table`'s column of each of `variables` on `side`, where it has one.
fn columns<'t>(
    table: &'t Pairs,
    variables: &[&str],
    side: Side,
) -> Result<Vec<Option<&'t Float64Array>>> {
    variables
        .iter()
        .map(|v| {
            table
                .variables()
                .iter()
                .any(|n| n == v)
                .then(|| table.column(side, v))
                .transpose()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use alnlab_codes::codebook::{Entry, Quantizer};
    use alnlab_codes::{Code, Codebook};
    use alnlab_common::Silent;
    use alnlab_tables::pairs::Split;

    use super::*;

    fn key(run: u32, step: u32, split: Split) -> Key {
        Key {
            scene: "arm".into(),
            run,
            step,
            split,
        }
    }

    /// Writes pairs of `variables` with x = `x + r`, y = `y + r` on row r.
    fn pairs_of(path: &Path, keys: &[Key], variables: &[&str], x: f64, y: f64) {
        let value = |side, _, r: usize| {
            Some(match side {
                Side::Current => x + r as f64,
                Side::Next => y + r as f64,
            })
        };
        pairs::write(path, keys, variables, value, &Provenance::default()).unwrap();
    }

    /// A planned round's frames join the pairs as training rows of a new
    /// run, their levels by the first codebook; a planned scene without a
    /// learned variable is refused, naming it.
    #[test]
    fn planned_frames_join_as_training_pairs_of_new_runs() {
        let dir = tempfile::tempdir().unwrap();
        let path = |name: &str| dir.path().join(name);
        let old = [key(0, 0, Split::Train), key(3, 1, Split::Test)];
        pairs_of(&path("pairs.parquet"), &old, &["q", "v"], 0.0, 1.0);
        pairs_of(&path("nominal.parquet"), &old, &["q", "v"], 0.0, 1.5);
        let planned = [key(0, 0, Split::Train), key(1, 4, Split::Train)];
        pairs_of(&path("t.parquet"), &planned, &["q", "v", "w"], 2.0, 3.0);
        pairs_of(&path("tn.parquet"), &planned, &["q", "v", "w"], 2.0, 3.5);
        let entry = Entry {
            variable: "q".into(),
            learned: true,
            note: String::new(),
            quantizer: Quantizer {
                min: 0.0,
                max: 10.0,
                levels: 11,
            },
            code: Code::Gray,
            width: 4,
            walk_step: 0,
            walk_span: 0,
            seed: 0,
            clamped: 0,
        };
        let codebook = Codebook {
            entries: vec![entry],
        };
        alnlab_tables::codebook::write(
            &codebook,
            &path("codebook.parquet"),
            &Provenance::default(),
        )
        .unwrap();
        levels::write(
            &path("levels.parquet"),
            &old,
            &["q"],
            &[vec![0, 1]],
            &[vec![1, 2]],
            &Provenance::default(),
        )
        .unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir(&out).unwrap();
        let (t, tn) = (path("t.parquet"), path("tn.parquet"));
        let (p, n, c, l) = (
            path("pairs.parquet"),
            path("nominal.parquet"),
            path("codebook.parquet"),
            path("levels.parquet"),
        );
        let inputs = Inputs {
            pairs: &p,
            nominal: &n,
            codebook: &c,
            levels: &l,
            transitions: &t,
            transitions_nominal: &tn,
        };
        run(&inputs, &Provenance::default(), &out, &Silent).unwrap();
        let joined = Pairs::read(&out.join(PAIRS_FILE)).unwrap();
        // After run 3, the scene's last: runs 4 and 5.
        let runs: Vec<u32> = joined.keys().iter().map(|k| k.run).collect();
        assert_eq!(runs, [0, 3, 4, 5]);
        assert!(joined.keys()[2..].iter().all(|k| k.split == Split::Train));
        let q = joined.column(Side::Next, "q").unwrap();
        assert_eq!(q.values().to_vec(), [1.0, 2.0, 3.0, 4.0]);
        // `w`, which the logged pairs lack, is dropped.
        assert_eq!(joined.variables(), ["q", "v"]);
        let nominal = Pairs::read(&out.join(NOMINAL_FILE)).unwrap();
        assert_eq!(nominal.keys(), joined.keys());
        let predicted = nominal.column(Side::Next, "q").unwrap();
        assert_eq!(predicted.values().to_vec(), [1.5, 2.5, 3.5, 4.5]);
        let levels = levels::Levels::read(&out.join(LEVELS_FILE), &c).unwrap();
        let entry = &codebook.entries[0];
        assert_eq!(levels.column(Side::Current, entry).unwrap(), [0, 1, 2, 3]);
        assert_eq!(levels.column(Side::Next, entry).unwrap(), [1, 2, 3, 4]);
        assert_eq!(levels.train_rows(), [0, 2, 3]);

        // Planned frames that lack a variable the scene logs.
        pairs_of(&t, &planned, &["q"], 2.0, 3.0);
        pairs_of(&tn, &planned, &["q"], 2.0, 3.5);
        let e = run(&inputs, &Provenance::default(), &out, &Silent).unwrap_err();
        assert!(
            e.to_string().contains("has no `v`, which scene `arm` logs"),
            "{e}"
        );
    }
}
