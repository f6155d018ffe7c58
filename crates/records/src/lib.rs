//! Run records: one JSON file per run, kept — `<out>/<experiment>/records/<id>.json`
//! — with the experiment's latest also at `<out>/<experiment>/run.json`. A
//! record names its manifest, commit and seed, every artifact each variant
//! (and replicate) used, the variant's resolved parameters and its headline
//! metrics, so runs can be listed and compared after their artifacts have
//! left the cache. A run is found by its id, a unique prefix of it, or its
//! experiment's name (the latest run; `NAME~1` the one before).
//!
//! Format 2 added ids, parameters and metrics; a format-1 `run.json` still
//! reads (its id made up from its start and bytes, no parameters, metrics
//! read from its artifacts while they last); a newer format is refused.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use alnlab_core::hash::sha256_hex;
use alnlab_core::{Error, Result, atomic};
use serde::{Deserialize, Serialize};

/// The format of the records this alnlab writes (3: each variant's
/// resolved stage parameters kept as the stages' own types,
/// [`VariantRecord::resolved`]).
pub const FORMAT: u32 = 3;

/// The latest record of an experiment, in its folder.
pub const LATEST_FILE: &str = "run.json";
/// The folder of an experiment's records, one file per run.
pub const RECORDS_DIR: &str = "records";

fn first_format() -> u32 {
    1
}

/// What a run did and what it produced: `<out>/<experiment>/records/<id>.json`
/// (and `run.json` beside `records/`, the experiment's latest).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunRecord {
    /// The record's format ([`FORMAT`]; 1 for a record written before
    /// records had ids, parameters and metrics).
    #[serde(default = "first_format")]
    pub format: u32,
    /// The run's id ([`new_id`]); for a format-1 record, made up on reading
    /// from its start and its bytes ([`legacy_id`]).
    #[serde(default)]
    pub id: String,
    pub experiment: String,
    pub manifest_path: String,
    pub manifest_sha256: String,
    pub seed: u64,
    pub alnlab_version: String,
    pub git_commit: Option<String>,
    /// The paths of the checkout that differed from `git_commit` when the
    /// run started (the reports folder it published into aside); a report
    /// lists them. Empty for a clean checkout, and in records before it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub git_changes: Vec<String>,
    /// When the run started and finished, RFC 3339 UTC: to the millisecond
    /// (to the second in records before), so that runs started in the same
    /// second list in the order they started.
    pub started: String,
    pub finished: String,
    pub wall_seconds: f64,
    pub variants: Vec<VariantRecord>,
    /// The manifest asked for the paper's §4.6 numbers in the report.
    #[serde(default)]
    pub compare_with_paper: bool,
    /// The manifest's description of the experiment.
    #[serde(default)]
    pub description: String,
    /// The manifest's notes on the results.
    #[serde(default)]
    pub notes: String,
    /// The manifest's answer, for the report's first screen.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub answer: String,
    /// The archived dataset the data came from, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dataset: Option<DatasetRef>,
    /// The recording the data came from, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recording: Option<RecordingRef>,
    /// The tables of samples the data came from, if any, each a trajectory.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tables: Vec<TableRef>,
}

/// A table of a robot's samples, as a run record names it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TableRef {
    /// Its path, as the manifest's patterns found it.
    pub file: String,
    pub sha256: String,
}

/// A robot's recording, as a run record names it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RecordingRef {
    /// Its path, as the manifest names it.
    pub recording: String,
    pub sha256: String,
    pub topic: String,
}

/// An archived dataset, as a run record names it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DatasetRef {
    /// `name@version`.
    pub dataset: String,
    /// Its catalog entry's sha256.
    pub sha256: String,
}

/// What one variant's stages did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct VariantRecord {
    pub name: String,
    pub description: String,
    /// Which replicate of the variant this is (0-based; the experiment's
    /// `replicates` runs each variant that many times).
    #[serde(default)]
    pub replicate: u32,
    /// The replicate's seed (derived from the experiment's seed).
    #[serde(default)]
    pub seed: u64,
    /// Every artifact file by role (`trajectory`, `stats`, `pairs`, …).
    pub artifacts: BTreeMap<String, ArtifactRef>,
    /// The stages in execution order.
    pub stages: Vec<StageRecord>,
    /// The variant's resolved parameters as dotted keys (the manifest's
    /// fields, each variant's overrides applied); empty in a format-1
    /// record.
    #[serde(default)]
    pub parameters: BTreeMap<String, String>,
    /// The same parameters as the pipeline's typed stage tables, serialized
    /// (`simulate`, `train`, `plan`, …, each its stage's own `Params`), for
    /// readers that read them back as those types rather than parse the
    /// dotted keys (the report); `None` in records before format 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolved: Option<serde_json::Value>,
    /// Its headline figures, read from its artifacts when the run ended
    /// (`None` in a format-1 record).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metrics: Option<Metrics>,
}

/// A variant's headline figures, as the report reads them from its
/// artifacts (`alnlab_report::metrics` names them).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// The rows the figures are over: `held-out` or `all`.
    pub rows: String,
    /// Figure name → value.
    pub values: BTreeMap<String, f64>,
    /// Series name → (step, value), steps ascending.
    pub steps: BTreeMap<String, Vec<(u32, f64)>>,
}

/// Whether `s` is a non-empty name of ASCII letters, digits, `-` and `_`:
/// what an experiment's or a variant's name must be, as it becomes a
/// folder's or a file's.
pub fn is_identifier(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// One artifact file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ArtifactRef {
    pub path: String,
    pub sha256: String,
    pub cache_key: String,
}

/// One stage of one variant.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StageRecord {
    pub stage: String,
    pub cache_key: String,
    /// Whether the artifact was reused rather than made.
    pub cached: bool,
    /// Time this run spent on the stage (s).
    pub wall_seconds: f64,
    /// Time the stage took when it made the artifact (s).
    pub compute_seconds: f64,
}

/// A new run's id: when it started (UTC, to the second) and 6 hex digits
/// of a hash of what it ran, where and when, so runs started in the same
/// second differ: `20261123-152330-3fa9c1`. Ids sort by start to the
/// second; listing orders by `started`, to the millisecond.
pub fn new_id(started: SystemTime, experiment: &str, manifest_sha256: &str) -> String {
    let nanos = started
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let salt = format!(
        "{experiment} {manifest_sha256} {nanos} {}",
        std::process::id()
    );
    id_from(
        &humantime::format_rfc3339_seconds(started).to_string(),
        salt.as_bytes(),
    )
}

/// The id a format-1 record is known by: its start and a hash of its bytes.
pub fn legacy_id(started: &str, bytes: &[u8]) -> String {
    id_from(started, bytes)
}

/// `YYYYMMDD-HHMMSS-` of an RFC 3339 time and 6 hex digits of `salt`'s hash.
fn id_from(rfc3339: &str, salt: &[u8]) -> String {
    let digits: String = rfc3339.chars().filter(char::is_ascii_digit).collect();
    let stamp = match digits.get(..14) {
        Some(d) => format!("{}-{}", &d[..8], &d[8..]),
        None => "00000000-000000".into(),
    };
    format!("{stamp}-{}", &sha256_hex(salt)[..6])
}

/// Writes `record` as `<out>/<experiment>/records/<id>.json` and as the
/// experiment's latest, `<out>/<experiment>/run.json`; returns the first.
pub fn store(out: &Path, record: &RunRecord) -> Result<PathBuf> {
    let json = serde_json::to_vec_pretty(record).expect("records serialize");
    let folder = out.join(&record.experiment);
    let records = folder.join(RECORDS_DIR);
    atomic::create_dir(&records)?;
    let path = records.join(format!("{}.json", record.id));
    atomic::write_bytes(&path, &json)?;
    atomic::write_bytes(&folder.join(LATEST_FILE), &json)?;
    Ok(path)
}

/// Reads a run's folder's latest record, `<run_dir>/run.json`.
pub fn read_record(run_dir: &Path) -> Result<RunRecord> {
    read(&run_dir.join(LATEST_FILE))
}

/// Reads one record file: refused when it is not a record, is of a newer
/// format, or names an experiment or variant that could lead out of a
/// folder.
pub fn read(path: &Path) -> Result<RunRecord> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    from_bytes(path, &bytes)
}

/// A record from the bytes of the file at `path` (named in errors), checked
/// as [`read`] checks it.
pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<RunRecord> {
    let value: serde_json::Value = serde_json::from_slice(bytes)
        .map_err(|e| Error::bad_file(path, format!("not a run record ({e})")))?;
    let format = match value.get("format") {
        None => 1,
        Some(f) => f
            .as_u64()
            .ok_or_else(|| Error::bad_file(path, "`format` is not a whole number"))?,
    };
    if format > u64::from(FORMAT) {
        return Err(Error::bad_file(
            path,
            format!(
                "run record format {format} is newer than this alnlab ({}) reads (up to \
                 {FORMAT}); use a newer alnlab",
                alnlab_core::ALNLAB_VERSION
            ),
        ));
    }
    let mut record: RunRecord = serde_json::from_value(value)
        .map_err(|e| Error::bad_file(path, format!("not a run record ({e})")))?;
    if record.format < 2 {
        record.id = legacy_id(&record.started, bytes);
    }
    let names = std::iter::once(("experiment", &record.experiment))
        .chain(record.variants.iter().map(|v| ("variant", &v.name)));
    for (what, name) in names {
        // The names become folder and file names: they must not lead out.
        if !is_identifier(name) {
            return Err(Error::bad_file(
                path,
                format!("{what} name {name:?} is not letters, digits, `-` and `_`"),
            ));
        }
    }
    if !record
        .id
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'-')
    {
        return Err(Error::bad_file(
            path,
            format!("run id {:?} is not letters, digits and `-`", record.id),
        ));
    }
    Ok(record)
}

/// A record as found under an output folder.
#[derive(Clone, Debug)]
pub struct Stored {
    pub record: RunRecord,
    /// The file it was read from.
    pub path: PathBuf,
}

/// A record file that could not be read, and why.
pub type Unreadable = (PathBuf, Error);

/// Every run recorded under `out`, oldest first (by start, then id): each
/// experiment folder's `records/`, and its `run.json` when that is a
/// format-1 record no file of `records/` holds. Files that cannot be read
/// are returned beside, each with its error, for the caller to report;
/// messages spelled for the caller.
pub fn all(out: &Path, spelling: Spelling) -> Result<(Vec<Stored>, Vec<Unreadable>)> {
    let mut found = Vec::new();
    let mut damaged = Vec::new();
    let folders = match std::fs::read_dir(out) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(Error::Invalid(format!(
                "{}: no such output folder (where {} writes)",
                out.display(),
                spelling.writes_runs()
            )));
        }
        Err(e) => return Err(Error::io(out, e)),
    };
    let mut folders: Vec<PathBuf> = folders
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join(LATEST_FILE).is_file() || p.join(RECORDS_DIR).is_dir())
        .collect();
    folders.sort();
    for folder in folders {
        let mut ids = Vec::new();
        let records = folder.join(RECORDS_DIR);
        if let Ok(entries) = std::fs::read_dir(&records) {
            let mut files: Vec<PathBuf> = entries
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "json"))
                .collect();
            files.sort();
            for path in files {
                match read(&path) {
                    Ok(record) => {
                        ids.push(record.id.clone());
                        found.push(Stored { record, path });
                    }
                    Err(e) => damaged.push((path, e)),
                }
            }
        }
        let latest = folder.join(LATEST_FILE);
        if latest.is_file() {
            match read(&latest) {
                Ok(record) if !ids.contains(&record.id) => found.push(Stored {
                    record,
                    path: latest,
                }),
                Ok(_) => {}
                Err(e) => damaged.push((latest, e)),
            }
        }
    }
    found.sort_by(|a, b| (&a.record.started, &a.record.id).cmp(&(&b.record.started, &b.record.id)));
    Ok((found, damaged))
}

/// How a message names what the user can give to choose: the command
/// line's flags, or the Python package's keywords.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spelling {
    Cli,
    Python,
}

impl Spelling {
    /// The arguments that choose a variant's replicate.
    fn choose(self) -> &'static str {
        match self {
            Spelling::Cli => "--variant and --replicate",
            Spelling::Python => "variant= and replicate=",
        }
    }

    /// What writes runs into an output folder.
    fn writes_runs(self) -> &'static str {
        match self {
            Spelling::Cli => "`alnlab run --out`",
            Spelling::Python => "`alnlab run --out`, read here with `out=`",
        }
    }

    /// What lists the runs under `out`.
    fn list_runs(self, out: &Path) -> String {
        match self {
            Spelling::Cli => format!("`alnlab runs list --out {}`", out.display()),
            Spelling::Python => format!("`alnlab.runs(out=\"{}\")`", out.display()),
        }
    }
}

/// A run, and optionally one of its variants, as the command line names
/// it: `RUN[:VARIANT]`, RUN an id, a unique prefix of one, an experiment's
/// name (its latest run) or `NAME~N` (N runs before its latest); messages
/// spelled for the caller.
pub fn find(out: &Path, reference: &str, spelling: Spelling) -> Result<(Stored, Option<String>)> {
    let (run, variant) = match reference.rsplit_once(':') {
        Some((run, variant)) => (run, Some(variant.to_string())),
        None => (reference, None),
    };
    let (runs, damaged) = all(out, spelling)?;
    let (name, back) = match run.rsplit_once('~') {
        Some((name, n)) => {
            let n: usize = n.parse().map_err(|_| {
                Error::Invalid(format!(
                    "run `{reference}`: `~` must be followed by how many runs back (`{name}~1`)"
                ))
            })?;
            (name, n)
        }
        None => (run, 0),
    };
    let of_experiment: Vec<&Stored> = runs
        .iter()
        .filter(|s| s.record.experiment == name)
        .collect();
    let chosen = if !of_experiment.is_empty() {
        let count = of_experiment.len();
        of_experiment.into_iter().rev().nth(back).ok_or_else(|| {
            Error::Invalid(format!(
                "run `{reference}`: experiment `{name}` has {count} recorded run{} under {}",
                if count == 1 { "" } else { "s" },
                out.display()
            ))
        })?
    } else {
        let matching: Vec<&Stored> = runs
            .iter()
            .filter(|s| !run.is_empty() && s.record.id.starts_with(run))
            .collect();
        match matching.as_slice() {
            [one] => *one,
            [] => {
                let mut experiments: Vec<&str> =
                    runs.iter().map(|s| s.record.experiment.as_str()).collect();
                experiments.dedup();
                // Record files are named by their run's id: the one asked
                // for, if it is among the unreadable, is named alone.
                let named = |path: &PathBuf| {
                    path.file_stem()
                        .is_some_and(|stem| stem.to_string_lossy().starts_with(run))
                };
                let asked = damaged.iter().any(|(path, _)| named(path));
                let shown: Vec<String> = damaged
                    .iter()
                    .filter(|(path, _)| !asked || named(path))
                    .map(|(_, e)| e.to_string())
                    .collect();
                let unreadable = match shown.len() {
                    0 => String::new(),
                    n => format!(
                        "; {n} record{} could not be read: {}",
                        if n == 1 { "" } else { "s" },
                        shown.join("; ")
                    ),
                };
                return Err(Error::Invalid(format!(
                    "no run `{run}` under {}: give a run id (see {}) or an experiment's name \
                     ({}){unreadable}",
                    out.display(),
                    spelling.list_runs(out),
                    if experiments.is_empty() {
                        "none recorded".to_string()
                    } else {
                        experiments.join(", ")
                    }
                )));
            }
            many => {
                return Err(Error::Invalid(format!(
                    "run `{run}` is ambiguous under {}: {}",
                    out.display(),
                    many.iter()
                        .map(|s| s.record.id.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )));
            }
        }
    };
    if let Some(variant) = &variant
        && !chosen.record.variants.iter().any(|v| &v.name == variant)
    {
        let mut names: Vec<&str> = chosen
            .record
            .variants
            .iter()
            .map(|v| v.name.as_str())
            .collect();
        names.dedup();
        return Err(Error::Invalid(format!(
            "run {} ({}) has no variant `{variant}`; it has: {}",
            chosen.record.id,
            chosen.record.experiment,
            names.join(", ")
        )));
    }
    Ok((chosen.clone(), variant))
}

/// The variant and replicate a command takes from a run: the one named
/// (`replicate` counts from 1), or — where several are left — the first when they all share the
/// same data files. Otherwise an error listing every variant and its
/// replicates, so that the choice is the user's.
pub fn pick_variant<'a>(
    variants: &'a [VariantRecord],
    name: Option<&str>,
    replicate: Option<u32>,
    roles: &[&str],
    run_dir: &Path,
    spelling: Spelling,
) -> Result<&'a VariantRecord> {
    let run_has = || {
        format!(
            "the run has {}",
            describe(&variants.iter().collect::<Vec<_>>())
        )
    };
    let named: Vec<&VariantRecord> = variants
        .iter()
        .filter(|v| name.is_none_or(|n| v.name == n))
        .collect();
    if let (Some(name), []) = (name, named.as_slice()) {
        return Err(Error::Invalid(format!(
            "{}: no variant `{name}`; {}",
            run_dir.display(),
            run_has()
        )));
    }
    let chosen: Vec<&VariantRecord> = named
        .iter()
        .copied()
        .filter(|v| replicate.is_none_or(|r| v.replicate == r - 1))
        .collect();
    if let (Some(replicate), []) = (replicate, chosen.as_slice()) {
        return Err(Error::Invalid(format!(
            "{}: no replicate {replicate}{}; {}",
            run_dir.display(),
            name.map(|n| format!(" of variant `{n}`"))
                .unwrap_or_default(),
            run_has()
        )));
    }
    let data = |v: &VariantRecord| -> Vec<Option<String>> {
        roles
            .iter()
            .map(|r| v.artifacts.get(*r).map(|a| a.sha256.clone()))
            .collect()
    };
    match chosen.as_slice() {
        [] => Err(Error::bad_file(
            &run_dir.join("run.json"),
            "the run has no variants",
        )),
        [first, rest @ ..] if rest.iter().all(|v| data(v) == data(first)) => Ok(first),
        _ => Err(Error::Invalid(format!(
            "{}: the data of {} differ; choose one with {} ({})",
            run_dir.display(),
            describe(&chosen),
            spelling.choose(),
            run_has()
        ))),
    }
}

/// Variants with their replicates and seeds, for people: `walk
/// (replicates 1, 2 — seeds 7, 8), gray (replicate 1 — seed 7)`.
fn describe(variants: &[&VariantRecord]) -> String {
    let mut names: Vec<&str> = Vec::new();
    for v in variants {
        if !names.contains(&v.name.as_str()) {
            names.push(&v.name);
        }
    }
    let each: Vec<String> = names
        .iter()
        .map(|&name| {
            let of: Vec<&VariantRecord> = variants
                .iter()
                .copied()
                .filter(|v| v.name == name)
                .collect();
            let join = |f: &dyn Fn(&VariantRecord) -> String| {
                of.iter().map(|v| f(v)).collect::<Vec<_>>().join(", ")
            };
            format!(
                "variant `{name}`: replicate{} {} with seed{} {}",
                if of.len() == 1 { "" } else { "s" },
                join(&|v| (u64::from(v.replicate) + 1).to_string()),
                if of.len() == 1 { "" } else { "s" },
                join(&|v| v.seed.to_string()),
            )
        })
        .collect();
    each.join("; ")
}

/// Where an artifact file is now: its recorded path, or — when the run was
/// made from another working folder — the same file of `<out>/cache/`.
/// `None` once the cache no longer holds it.
pub fn locate(out: &Path, artifact: &ArtifactRef) -> Option<PathBuf> {
    let recorded = PathBuf::from(&artifact.path);
    if recorded.is_file() {
        return Some(recorded);
    }
    // `…/cache/<stage>/<key>/<file>`: the last three parts, under `out`.
    let parts: Vec<_> = recorded.components().rev().take(3).collect();
    let moved = parts
        .iter()
        .rev()
        .fold(out.join("cache"), |path, part| path.join(part));
    (parts.len() == 3 && moved.is_file()).then_some(moved)
}
