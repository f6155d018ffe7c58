//! Runs as the CLI finds them (`alnlab_records`): a run by id, prefix or
//! experiment name, a variant's artifact files by role, every record of a
//! runs folder — with the CLI's messages.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use alnlab_common::Error;
use alnlab_common::hash::sha256_file;
use alnlab_records as records;
use pyo3::prelude::*;

use crate::raise;

/// A variant's artifact files, as `find_artifacts` gives them.
type Found = (String, String, String, u32, BTreeMap<String, String>);

/// Finds `run` (`RUN[:VARIANT]`: an id, a unique prefix of one, an
/// experiment's name for its latest run, `NAME~N` for N runs before)
/// under `out`, then the variant (the one named, or the only data there
/// is) and its replicate (counted from 1; the first where all share their
/// data), and the files of `roles` where they are now. Returns the run's
/// id, its experiment, the variant, its replicate (from 1) and `{role:
/// path}`; with `verify`, each file's sha256 checked against the record.
#[pyfunction]
#[pyo3(signature = (out, run, roles, *, variant = None, replicate = None, verify = false))]
pub fn find_artifacts(
    out: PathBuf,
    run: &str,
    roles: Vec<String>,
    variant: Option<&str>,
    replicate: Option<&Bound<'_, PyAny>>,
    verify: bool,
) -> PyResult<Found> {
    let replicate = crate::arrays::count(replicate, "replicate", 1)?
        .map(|r| {
            u32::try_from(r).map_err(|_| crate::invalid(format!("replicate: {r} is too many")))
        })
        .transpose()?;
    let (stored, named) = records::find(&out, run, records::Spelling::Python).map_err(raise)?;
    let variant = match (variant, named.as_deref()) {
        (Some(a), Some(b)) if a != b => {
            return Err(raise(Error::Invalid(format!(
                "run `{run}` names variant `{b}`, and variant=`{a}` another"
            ))));
        }
        (Some(v), _) | (None, Some(v)) => Some(v),
        (None, None) => None,
    };
    let run_dir = stored.path.parent().unwrap_or(Path::new("."));
    let run_dir = match run_dir.file_name() {
        // `<experiment>/records/<id>.json`: the run's folder is above.
        Some(name) if name == records::RECORDS_DIR => run_dir.parent().unwrap_or(run_dir),
        _ => run_dir,
    };
    let wanted: Vec<&str> = roles.iter().map(String::as_str).collect();
    let chosen = records::pick_variant(
        &stored.record.variants,
        variant,
        replicate,
        &wanted,
        run_dir,
        records::Spelling::Python,
    )
    .map_err(raise)?;
    let mut files = BTreeMap::new();
    for role in &roles {
        let artifact = chosen.artifacts.get(role).ok_or_else(|| {
            let mut has: Vec<&str> = chosen.artifacts.keys().map(String::as_str).collect();
            has.sort_unstable();
            raise(Error::Invalid(format!(
                "run {} ({}), variant `{}`: no `{role}` artifact; it has {}",
                stored.record.id,
                stored.record.experiment,
                chosen.name,
                has.join(", ")
            )))
        })?;
        let path = records::locate(&out, artifact).ok_or_else(|| {
            raise(Error::Invalid(format!(
                "run {} ({}), variant `{}`: its `{role}` file {} is gone (the cache was \
                 cleared since): run the experiment again",
                stored.record.id, stored.record.experiment, chosen.name, artifact.path
            )))
        })?;
        if verify && sha256_file(&path).map_err(raise)? != artifact.sha256 {
            return Err(raise(Error::damaged(
                &path,
                format!(
                    "its sha256 is not the one run {} recorded for it",
                    stored.record.id
                ),
            )));
        }
        files.insert(role.clone(), path.display().to_string());
    }
    Ok((
        stored.record.id.clone(),
        stored.record.experiment.clone(),
        chosen.name.clone(),
        chosen.replicate + 1,
        files,
    ))
}

/// Records as JSON, and (path, why) of the files that could not be read.
type Listed = (Vec<String>, Vec<(String, String)>);

/// Every readable run record under `out`, oldest first, as JSON (the
/// records' own), and the files that could not be read with why.
#[pyfunction]
pub fn run_records(out: PathBuf) -> PyResult<Listed> {
    let (found, unreadable) = records::all(&out, records::Spelling::Python).map_err(raise)?;
    let json = found
        .iter()
        .map(|s| serde_json::to_string(&s.record).expect("records serialize"))
        .collect();
    let unreadable = unreadable
        .into_iter()
        .map(|(path, e)| (path.display().to_string(), e.to_string()))
        .collect();
    Ok((json, unreadable))
}

/// The record of `run` (as [`find_artifacts`] finds it) under `out`, as
/// JSON (the record's own).
#[pyfunction]
pub fn run_record(out: PathBuf, run: &str) -> PyResult<String> {
    let (stored, _) = records::find(&out, run, records::Spelling::Python).map_err(raise)?;
    Ok(serde_json::to_string(&stored.record).expect("records serialize"))
}
