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
//! the pairs lack are dropped, and a learned variable the planned scene
//! lacks is an error (its level would be unknown).

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_codes::Codebook;
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
    let codebook = Codebook::read(inputs.codebook)?;
    let levels = levels::Levels::read(inputs.levels)?;
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
