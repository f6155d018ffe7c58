//! Sharded training: the K-th of N disjoint, deterministic subsets of a
//! forest's trees, trained by one process each, and the N partial models
//! merged back into the model file a single process would have written.
//!
//! Trees are dealt round-robin in their canonical order (variable, bit,
//! voter): shard K of N owns the trees at positions K − 1, K − 1 + N, … .
//! Every tree's seed comes from its identity alone, so a tree trained in a
//! shard is the tree trained in one process, and merging is a sort.

use std::path::{Path, PathBuf};

use alnlab_common::{Error, Provenance, Result};

use crate::log::{self, Log};
use crate::{MODEL_FILE, TRAINING_FILE};
use alnlab_aln::model::RawModel;

/// Merges the partial models and training logs in `parts` (each a folder
/// written by a sharded train stage) into `out_dir`: the model file byte for
/// byte as one process would write it, the log with its rows in tree order.
pub fn merge(parts: &[PathBuf], provenance: &Provenance, out_dir: &Path) -> Result<()> {
    let mut models = Vec::new();
    for dir in parts {
        let path = dir.join(MODEL_FILE);
        // The records are copied as they are, not parsed into trees: the
        // model's reader checks the merged file when it is used.
        let model = RawModel::read(&path)?;
        let shard = model
            .header
            .shard
            .ok_or_else(|| Error::bad_file(&path, "is a whole model, not a shard's part"))?;
        models.push((path, shard, model));
    }
    let Some((first_path, first_shard, first)) = models.first() else {
        return Err(Error::Invalid("merge: no partial models given".into()));
    };
    let count = first_shard.count;
    let mut seen = vec![false; count as usize];
    for (path, shard, model) in &models {
        let mut header = model.header.clone();
        header.shard = first.header.shard;
        if header != first.header {
            return Err(Error::bad_file(
                path,
                format!(
                    "was trained with other parameters or data than {}",
                    first_path.display()
                ),
            ));
        }
        if shard.count != count {
            return Err(Error::bad_file(
                path,
                format!("is shard {shard}, the others are of {count}"),
            ));
        }
        let slot = &mut seen[(shard.index - 1) as usize];
        if *slot {
            return Err(Error::bad_file(path, format!("repeats shard {shard}")));
        }
        *slot = true;
    }
    let missing: Vec<String> = (1..=count)
        .filter(|k| !seen[(*k - 1) as usize])
        .map(|k| format!("{k}/{count}"))
        .collect();
    if !missing.is_empty() {
        return Err(Error::Invalid(format!(
            "merge: shard(s) {} missing",
            missing.join(", ")
        )));
    }

    let mut header = first.header.clone();
    header.shard = None;
    let mut records: Vec<_> = models.into_iter().flat_map(|(_, _, m)| m.records).collect();
    records.sort_by_key(|(id, _)| *id);
    let order: Vec<String> = header.outputs.iter().map(|(v, _)| v.clone()).collect();
    RawModel { header, records }.write(&out_dir.join(MODEL_FILE))?;
    merge_logs(parts, &order, provenance, &out_dir.join(TRAINING_FILE))
}

/// The bit models' logs of `parts`, one log with its rows in tree order
/// (`variables` gives the variables' order).
fn merge_logs(
    parts: &[PathBuf],
    variables: &[String],
    provenance: &Provenance,
    path: &Path,
) -> Result<()> {
    let mut rows = Vec::new();
    for dir in parts {
        let part = dir.join(TRAINING_FILE);
        match log::read(&part)? {
            Log::Epochs(epochs) => rows.extend(epochs),
            Log::Rounds(_) => {
                return Err(Error::bad_file(
                    &part,
                    "a piecewise-linear model's rounds: only bit models are trained in shards",
                ));
            }
        }
    }
    let position = |v: &str| variables.iter().position(|x| *x == v).unwrap_or(usize::MAX);
    rows.sort_by_key(|r| (position(&r.variable), r.bit, r.vote, r.epoch));
    log::write(path, &Log::Epochs(rows), provenance)
}
