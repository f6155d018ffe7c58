//! Experiment manifests: TOML files with an `[experiment]` table, one table
//! per stage and `[[variant]]` entries that override stage parameters by
//! dotted key. Parsing keeps every value's position, so any error — a
//! misspelt key, a wrong type, an out-of-range value, a broken relation
//! between fields, also inside a variant — names the file, line and column,
//! the key, and what is allowed.
//!
//! A manifest either simulates its data (`[[simulate.scene]]`, `[stride]`)
//! or takes it from the dataset archive (`[data] dataset = "NAME@VERSION"`).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};

use alnlab_common::bounded;
use alnlab_common::hash::sha256_hex;
use alnlab_common::params::Count;
use alnlab_stride::{Fold, Split};
use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;
use toml::de::{DeTable, DeValue};

use crate::stages::{Archived, STAGES, Stage, Stages};

mod locate;
use locate::{Locator, has_key, has_path, span_of};

/// A parsed, validated manifest with every variant resolved.
#[derive(Debug)]
pub struct Manifest {
    /// Where the manifest was read from.
    pub path: PathBuf,
    /// SHA-256 of the manifest file's bytes.
    pub sha256: String,
    /// The `[experiment]` table.
    pub experiment: Experiment,
    /// The `[data]` table, when the data come from the dataset archive.
    pub data: Option<Data>,
    /// The variants in manifest order; a manifest without `[[variant]]` has
    /// one, named `base`.
    pub variants: Vec<Variant>,
}

/// The `[experiment]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    /// Name of the experiment: letters, digits, `-`, `_` (used in paths).
    pub name: String,
    /// The seed every random choice of every stage derives from.
    pub seed: u64,
    /// What the experiment is for.
    #[serde(default)]
    pub description: String,
    /// Set the report's §4.6 table beside the paper's own numbers (for
    /// experiments made as the paper's: L = 214 and its variables).
    #[serde(default)]
    pub compare_with_paper: bool,
    /// The experimenter's reading of the results (Markdown), printed in the
    /// report under the computed findings.
    #[serde(default)]
    pub notes: String,
    /// The experimenter's answer to the experiment's question in a few
    /// sentences (Markdown), printed on the report's first screen under the
    /// results table, labelled as theirs: what the figures cannot say by
    /// themselves (why a model stands where it does).
    #[serde(default)]
    pub answer: String,
    /// Every variant runs this many times, each replicate with its own seed
    /// ([`replicate_seed`]): simulation, split and trees all re-drawn (with
    /// an archived dataset, what comes after the data). The report gives
    /// each headline figure as the mean across replicates with its 95%
    /// confidence interval.
    #[serde(default = "one_replicate")]
    pub replicates: Count,
    /// The most work a variant may ask for (`[experiment.budget]`): a
    /// variant estimated over it is refused before anything runs.
    #[serde(default)]
    pub budget: crate::budget::Budget,
}

fn one_replicate() -> Count {
    Count(1)
}

/// The seed of replicate `r` (0-based) of an experiment seeded `seed`: the
/// seed itself for the first, so that one replicate is the plain run; then
/// the SplitMix64 mix of seed + r·γ (γ = 0x9E3779B97F4A7C15), well apart
/// for neighbouring seeds and replicates.
pub fn replicate_seed(seed: u64, r: u32) -> u64 {
    if r == 0 {
        return seed;
    }
    let mut z = seed.wrapping_add(u64::from(r).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The `[data]` table: where the data come from instead of a simulation —
/// an archived dataset (standing for simulate and stride), or a robot's
/// recording or tables of its samples (the ingest stage standing for
/// simulate).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Data {
    /// An archived dataset: `NAME@VERSION`, or a prefix of at least 8 hex
    /// digits of its sha256 (see `alnlab dataset list`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dataset: Option<String>,
    /// A ROS 2 recording (MCAP) of `sensor_msgs/msg/JointState`, relative
    /// to the manifest; `[ingest]` says how it becomes frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recording: Option<String>,
    /// The recording's topic (default `/joint_states`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topic: Option<String>,
    /// Tables of a robot's samples (CSV or Parquet), each a trajectory: a
    /// path or glob relative to the manifest, or a list of them;
    /// `[ingest.table]` maps their columns.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tables: Option<Tables>,
}

/// `[data] tables`: one path or glob, or a list of them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Tables {
    One(String),
    Many(Vec<String>),
}

impl Tables {
    /// The patterns, in order.
    pub fn patterns(&self) -> Vec<String> {
        match self {
            Tables::One(p) => vec![p.clone()],
            Tables::Many(ps) => ps.clone(),
        }
    }
}

/// Where a manifest's data come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Source {
    Simulated,
    /// `[data] dataset`: the archive stands for the stages it holds.
    Archived,
    /// `[data] recording` or `tables`: the ingest stage stands for
    /// simulate.
    Recorded,
}

impl Source {
    /// Where the data come from: `[data]`, and whether `[ingest]` names a
    /// robot (an archived dataset of tables is then read by the ingest
    /// stage, not stood in for the first stages).
    fn of(data: Option<&Data>, ingest: &alnlab_ingest::Params) -> Source {
        match data {
            Some(Data {
                dataset: Some(_), ..
            }) if ingest.robot.is_some() => Source::Recorded,
            Some(Data {
                dataset: Some(_), ..
            }) => Source::Archived,
            Some(Data {
                recording: Some(_), ..
            })
            | Some(Data {
                tables: Some(_), ..
            }) => Source::Recorded,
            _ => Source::Simulated,
        }
    }

    /// Whether the stage's parameters are left out because the data stand
    /// for it.
    fn stands_for(self, stage: &Stage) -> bool {
        match self {
            Source::Simulated => false,
            Source::Archived => stage.archived == Archived::Always,
            Source::Recorded => stage.name == "simulate",
        }
    }
}

/// One variant: the stage parameters with its overrides applied.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// The variant's name (`base` when the manifest has none).
    pub name: String,
    /// What the variant changes, in words.
    pub description: String,
    /// The resolved parameters of every stage.
    pub stages: Stages,
    /// The stage tables the manifest, with this variant's overrides, sets
    /// (a stage an archived dataset stands for must not be set).
    pub tables: BTreeSet<&'static str>,
}

impl Variant {
    /// The variant as replicate `replicate` (from 0) runs it: where its
    /// split holds whole trajectories out, the replicate tests its own fold.
    pub fn for_replicate(&self, replicate: u32) -> Variant {
        let mut variant = self.clone();
        if let Some(fold) = &mut variant.stages.stride.fold {
            fold.index = u64::from(replicate);
        }
        variant
    }
}

/// The whole document as deserialized (variants handled separately).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Document {
    experiment: Experiment,
    #[serde(default)]
    data: Option<Data>,
    #[serde(default)]
    simulate: alnlab_simulate::Params,
    #[serde(default)]
    stride: alnlab_stride::Params,
    #[serde(default)]
    quantize: alnlab_quantize::Params,
    #[serde(default)]
    train: alnlab_train::Params,
    #[serde(default)]
    test: alnlab_evaluate::Params,
    #[serde(default)]
    plan: alnlab_plan::Params,
    #[serde(default)]
    circuit: alnlab_circuit::Params,
    #[serde(default)]
    ingest: alnlab_ingest::Params,
}

/// An error in a manifest, located in the file.
#[derive(Debug, Clone, PartialEq)]
pub struct ManifestError {
    /// The manifest file.
    pub file: PathBuf,
    /// 1-based line and column, when the error has a position.
    pub position: Option<(usize, usize)>,
    /// The dotted key the error is about (empty for syntax errors).
    pub key: String,
    /// The variant being resolved, if the error is in one.
    pub variant: Option<String>,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl fmt::Display for ManifestError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some((line, column)) = self.position {
            write!(f, ":{line}:{column}")?;
        }
        f.write_str(": ")?;
        if let Some(variant) = &self.variant {
            write!(f, "in variant `{variant}`: ")?;
        }
        if !self.key.is_empty() {
            write!(f, "`{}`: ", self.key)?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for ManifestError {}

impl From<ManifestError> for alnlab_common::Error {
    fn from(e: ManifestError) -> Self {
        alnlab_common::Error::Invalid(e.to_string())
    }
}

impl Manifest {
    /// Reads and validates the manifest at `path`.
    pub fn load(path: &Path) -> Result<Manifest, alnlab_common::Error> {
        let bytes = bounded::read(path, bounded::MANIFEST_BYTES, "a manifest")
            .map_err(|e| alnlab_common::Error::io(path, e))?;
        let text = String::from_utf8(bytes.clone())
            .map_err(|_| alnlab_common::Error::bad_file(path, "expected a UTF-8 TOML file"))?;
        let mut manifest = Manifest::parse(&text, path)?;
        manifest.sha256 = sha256_hex(&bytes);
        Ok(manifest)
    }

    /// Parses and validates manifest text; `path` is used in error messages.
    pub fn parse(text: &str, path: &Path) -> Result<Manifest, ManifestError> {
        let locate = Locator { text, file: path };
        let root = DeTable::parse(text).map_err(|e| locate.toml_error(&e, None, None))?;
        let root_span = root.span();
        let mut base = root.into_inner();
        let variant_entries = take_variants(&mut base, &locate)?;

        let (experiment, data, base_stages) =
            split(deserialize(&base, root_span.clone(), &locate, None)?);
        check_experiment(&experiment, &base, &locate)?;
        check_data(data.as_ref(), &base, &locate)?;
        let source = Source::of(data.as_ref(), &base_stages.ingest);
        let mut variants = Vec::new();
        if variant_entries.is_empty() {
            let mut stages = base_stages;
            read_descriptions(&mut stages, data.as_ref(), &base, &locate, None)?;
            fold_trajectories(&mut stages, &base, &experiment, source);
            validate(&stages, &base, &locate, None, source)?;
            within_budget(&stages, &experiment, &base, &locate, None, source)?;
            variants.push(Variant {
                name: "base".into(),
                description: String::new(),
                stages,
                tables: stage_tables(&base),
            });
        }
        for entry in variant_entries {
            let (name, description, overrides) = variant_parts(entry, &locate, &variants)?;
            let mut merged = base.clone();
            merge(&mut merged, overrides);
            let doc = deserialize(&merged, root_span.clone(), &locate, Some(&name))?;
            let (_, _, mut stages) = split(doc);
            read_descriptions(&mut stages, data.as_ref(), &merged, &locate, Some(&name))?;
            fold_trajectories(&mut stages, &merged, &experiment, source);
            validate(&stages, &merged, &locate, Some(&name), source)?;
            within_budget(&stages, &experiment, &merged, &locate, Some(&name), source)?;
            variants.push(Variant {
                name,
                description,
                stages,
                tables: stage_tables(&merged),
            });
        }
        Ok(Manifest {
            path: path.to_path_buf(),
            sha256: sha256_hex(text.as_bytes()),
            experiment,
            data,
            variants,
        })
    }

    /// The variant called `name`, or an error listing the variants there are.
    pub fn variant(&self, name: &str) -> Result<&Variant, alnlab_common::Error> {
        self.variants
            .iter()
            .find(|v| v.name == name)
            .ok_or_else(|| {
                alnlab_common::Error::Invalid(format!(
                    "{}: no variant `{name}`; the manifest has: {}",
                    self.path.display(),
                    self.variant_names().join(", ")
                ))
            })
    }

    /// The names of all variants.
    pub fn variant_names(&self) -> Vec<&str> {
        self.variants.iter().map(|v| v.name.as_str()).collect()
    }

    /// The fully resolved manifest of one variant, as TOML (without the
    /// tables of stages an archived dataset stands for).
    pub fn resolved_toml(&self, variant: &Variant) -> String {
        toml::to_string(&self.resolved_table(variant))
            .expect("resolved parameters serialize to TOML")
    }

    /// `variant`'s resolved parameters as dotted keys (`train.vote`,
    /// `simulate.scene.0.dt`) and their values as text (strings bare,
    /// arrays of values inline: `[0.0, 0.0, -9.81]`): what run records keep,
    /// `alnlab runs` compares and an MLflow export logs. The experiment's
    /// name, description and notes are not parameters.
    pub fn parameters(&self, variant: &Variant) -> BTreeMap<String, String> {
        let mut table = self.resolved_table(variant);
        if let Some(toml::Value::Table(experiment)) = table.get_mut("experiment") {
            for prose in ["name", "description", "notes"] {
                experiment.remove(prose);
            }
        }
        let mut flat = BTreeMap::new();
        flatten("", &toml::Value::Table(table), &mut flat);
        flat
    }

    /// The resolved tables of `variant`, every default filled in.
    fn resolved_table(&self, variant: &Variant) -> toml::Table {
        #[derive(Serialize)]
        struct Resolved<'a> {
            experiment: &'a Experiment,
            #[serde(skip_serializing_if = "Option::is_none")]
            data: Option<&'a Data>,
            #[serde(flatten)]
            stages: &'a Stages,
        }
        let resolved = Resolved {
            experiment: &self.experiment,
            data: self.data.as_ref(),
            stages: &variant.stages,
        };
        let mut table =
            toml::Table::try_from(&resolved).expect("resolved parameters serialize to TOML");
        let source = Source::of(self.data.as_ref(), &variant.stages.ingest);
        for stage in STAGES.iter().filter(|s| source.stands_for(s)) {
            table.remove(stage.name);
        }
        if source != Source::Recorded {
            table.remove(crate::stages::INGEST.name);
        }
        table
    }
}

/// Adds `value` under `key` to `flat`: tables and arrays of tables by
/// their keys and indices, anything else as its text.
fn flatten(key: &str, value: &toml::Value, flat: &mut BTreeMap<String, String>) {
    let join = |k: &str| {
        if key.is_empty() {
            k.to_string()
        } else {
            format!("{key}.{k}")
        }
    };
    match value {
        toml::Value::Table(table) => {
            for (k, v) in table {
                flatten(&join(k), v, flat);
            }
        }
        toml::Value::Array(items)
            if !items.is_empty() && items.iter().all(toml::Value::is_table) =>
        {
            for (i, item) in items.iter().enumerate() {
                flatten(&join(&i.to_string()), item, flat);
            }
        }
        toml::Value::String(text) => {
            flat.insert(key.to_string(), text.clone());
        }
        other => {
            flat.insert(key.to_string(), other.to_string());
        }
    }
}

/// The experiment and data tables and the stages' parameters, every default
/// filled in.
fn split(document: Document) -> (Experiment, Option<Data>, Stages) {
    let stages = Stages {
        simulate: document.simulate.resolve(),
        stride: document.stride,
        quantize: document.quantize,
        train: document.train,
        test: document.test,
        plan: document.plan,
        circuit: document.circuit,
        ingest: document.ingest,
    };
    (document.experiment, document.data, stages)
}

/// Removes `[[variant]]` from the base document and returns its entries.
fn take_variants<'i>(
    base: &mut DeTable<'i>,
    locate: &Locator,
) -> Result<Vec<Spanned<DeValue<'i>>>, ManifestError> {
    let Some(key) = base.keys().find(|k| k.get_ref() == "variant").cloned() else {
        return Ok(Vec::new());
    };
    let value = base.remove(&key).expect("key just found");
    let span = value.span();
    match value.into_inner() {
        DeValue::Array(items) => Ok(items.into_iter().collect()),
        other => Err(locate.error(
            Some(span),
            "variant".into(),
            None,
            format!(
                "expected an array of tables ([[variant]]), found {}",
                other.type_str()
            ),
        )),
    }
}

/// Splits one `[[variant]]` entry into name, description and overrides.
fn variant_parts<'i>(
    entry: Spanned<DeValue<'i>>,
    locate: &Locator,
    earlier: &[Variant],
) -> Result<(String, String, DeTable<'i>), ManifestError> {
    let span = entry.span();
    let DeValue::Table(mut table) = entry.into_inner() else {
        return Err(locate.error(
            Some(span),
            "variant".into(),
            None,
            "expected a table ([[variant]])".into(),
        ));
    };
    let mut take_string =
        |field: &str| -> Result<Option<(String, std::ops::Range<usize>)>, ManifestError> {
            let Some(key) = table.keys().find(|k| k.get_ref() == field).cloned() else {
                return Ok(None);
            };
            let value = table.remove(&key).expect("key just found");
            let value_span = value.span();
            match value.get_ref().as_str() {
                Some(s) => Ok(Some((s.to_string(), value_span))),
                None => Err(locate.error(
                    Some(value_span),
                    format!("variant.{field}"),
                    None,
                    format!("expected a string, found {}", value.get_ref().type_str()),
                )),
            }
        };
    let (name, name_span) = take_string("name")?.ok_or_else(|| {
        locate.error(
            Some(span.clone()),
            "variant.name".into(),
            None,
            "every [[variant]] needs a `name`".into(),
        )
    })?;
    let description = take_string("description")?.map(|d| d.0).unwrap_or_default();
    if !is_identifier(&name) {
        return Err(locate.error(
            Some(name_span),
            "variant.name".into(),
            None,
            format!("expected a name of letters, digits, `-` or `_`, found {name:?}"),
        ));
    }
    if earlier.iter().any(|v| v.name == name) {
        return Err(locate.error(
            Some(name_span),
            "variant.name".into(),
            None,
            format!("variant name `{name}` is used twice"),
        ));
    }
    Ok((name, description, table))
}

/// Overlays `overrides` on `base`: tables merge key by key, anything else
/// (numbers, strings, arrays) replaces the base value.
fn merge<'i>(base: &mut DeTable<'i>, overrides: DeTable<'i>) {
    for (key, value) in overrides {
        let existing = base.iter_mut().find(|(k, _)| k.get_ref() == key.get_ref());
        match (existing, value.get_ref()) {
            (Some((_, slot)), DeValue::Table(_)) if slot.get_ref().is_table() => {
                let DeValue::Table(inner) = value.into_inner() else {
                    unreachable!("matched as a table")
                };
                if let DeValue::Table(target) = slot.get_mut() {
                    merge(target, inner);
                }
            }
            _ => {
                base.insert(key, value);
            }
        }
    }
}

fn deserialize(
    table: &DeTable,
    span: std::ops::Range<usize>,
    locate: &Locator,
    variant: Option<&str>,
) -> Result<Document, ManifestError> {
    let deserializer = toml::de::Deserializer::from(Spanned::new(span, table.clone()));
    Document::deserialize(deserializer).map_err(|e| locate.toml_error(&e, Some(table), variant))
}

fn check_experiment(
    experiment: &Experiment,
    table: &DeTable,
    locate: &Locator,
) -> Result<(), ManifestError> {
    if is_identifier(&experiment.name) {
        return Ok(());
    }
    Err(locate.error(
        span_of(table, &["experiment", "name"]),
        "experiment.name".into(),
        None,
        format!(
            "expected a name of letters, digits, `-` or `_`, found {:?}",
            experiment.name
        ),
    ))
}

/// Reads the files the data come from, relative to the manifest's folder:
/// the robot descriptions of the simulation's `urdf` scenes, or a
/// recording or tables and their robot's (none for an archived dataset).
fn read_descriptions(
    stages: &mut Stages,
    data: Option<&Data>,
    table: &DeTable,
    locate: &Locator,
    variant: Option<&str>,
) -> Result<(), ManifestError> {
    let dir = locate.file.parent().unwrap_or(Path::new(""));
    let located = |stage: &str, key: String, message: String| {
        let path: Vec<&str> = std::iter::once(stage).chain(key.split('.')).collect();
        match (stage, key.as_str()) {
            ("ingest", "recording") => locate.error(
                span_of(table, &["data", "recording"]),
                "data.recording".into(),
                variant,
                message,
            ),
            ("ingest", "tables") => locate.error(
                span_of(table, &["data", "tables"]),
                "data.tables".into(),
                variant,
                message,
            ),
            _ => locate.error(span_of(table, &path), path.join("."), variant, message),
        }
    };
    match Source::of(data, &stages.ingest) {
        Source::Simulated => stages
            .simulate
            .read_descriptions(dir)
            .map_err(|(key, message)| located("simulate", key, message)),
        Source::Archived if has_key(table, crate::stages::INGEST.name) => Err(located(
            "ingest",
            "robot".into(),
            "[ingest] reads the tables of an archived dataset of recordings with their robot: \
             add [ingest.robot] (or remove [ingest]: a run's archived data need no framing)"
                .into(),
        )),
        Source::Archived => Ok(()),
        Source::Recorded => {
            let data = data.expect("recorded data");
            let read = match (&data.recording, &data.tables) {
                (Some(recording), _) => {
                    stages
                        .ingest
                        .read_sources(dir, recording, data.topic.as_deref())
                }
                (None, Some(tables)) => stages.ingest.read_tables(dir, &tables.patterns()),
                // An archived dataset of tables: the run reads them from
                // the archive it is given.
                (None, None) => stages.ingest.read_archived_tables(dir),
            };
            read.map_err(|(key, message)| located("ingest", key, message))
        }
    }
}

/// Holds whole trajectories out where the data are recorded and `[stride]
/// split` is not given; a `by-trajectory` split deals them into as many
/// folds as replicates, the first tested here (the run sets each
/// replicate's: [`Variant::for_replicate`]).
fn fold_trajectories(
    stages: &mut Stages,
    table: &DeTable,
    experiment: &Experiment,
    source: Source,
) {
    if source == Source::Recorded && !has_path(table, &["stride", "split"]) {
        stages.stride.split = Split::ByTrajectory;
    }
    if stages.stride.split == Split::ByTrajectory {
        stages.stride.fold = Some(Fold {
            index: 0,
            of: experiment.replicates.0,
        });
    }
}

/// Refuses a `[data]` table that names no source or more than one, a topic
/// without a recording, and `[ingest]` without recorded data.
fn check_data(data: Option<&Data>, table: &DeTable, locate: &Locator) -> Result<(), ManifestError> {
    let at = |path: &[&str], message: &str| {
        Err(locate.error(
            span_of(table, path),
            path.join("."),
            None,
            message.to_string(),
        ))
    };
    let sources = data.map_or(0, |d| {
        [
            d.dataset.is_some(),
            d.recording.is_some(),
            d.tables.is_some(),
        ]
        .iter()
        .filter(|&&s| s)
        .count()
    });
    match data {
        Some(_) if sources > 1 => at(
            &["data"],
            "the data come from one of an archived dataset (`dataset`), a recording \
             (`recording`) or tables (`tables`), not more",
        ),
        Some(_) if sources == 0 => at(
            &["data"],
            "expected `dataset` (an archived dataset), `recording` (a ROS 2 recording) or \
             `tables` (CSV or Parquet files of samples)",
        ),
        Some(Data {
            recording: None,
            topic: Some(_),
            ..
        }) => at(
            &["data", "topic"],
            "a topic is a recording's: add `recording`",
        ),
        Some(Data {
            recording: Some(_), ..
        })
        | Some(Data {
            tables: Some(_), ..
        })
        | Some(Data {
            dataset: Some(_), ..
        }) => Ok(()),
        _ if has_key(table, crate::stages::INGEST.name) => at(
            &[crate::stages::INGEST.name],
            "[ingest] frames recorded data: add [data] recording or tables (or remove [ingest])",
        ),
        _ => Ok(()),
    }
}

/// The checks between fields that each stage makes, located in the file.
fn validate(
    stages: &Stages,
    table: &DeTable,
    locate: &Locator,
    variant: Option<&str>,
    source: Source,
) -> Result<(), ManifestError> {
    // With `[data]`, the data stand for some stages: their parameters would
    // be silently ignored, so they are an error, and they are not checked.
    let held = |stage: &&Stage| source.stands_for(stage);
    if let Some(stage) = STAGES.iter().filter(held).find(|s| has_key(table, s.name)) {
        let names: Vec<&str> = STAGES.iter().filter(held).map(|s| s.name).collect();
        let message = match source {
            Source::Recorded => format!(
                "the data come from `[data]`'s recorded data, which the ingest stage turns into \
                 the simulate stage's outputs; remove `{}` (the robot is [ingest.robot])",
                stage.name
            ),
            _ => format!(
                "the data come from `[data] dataset`, which holds the {} outputs; remove `{}` \
                 (or `[data]`)",
                names.join(" and "),
                stage.name
            ),
        };
        return Err(locate.error(
            span_of(table, &[stage.name]),
            stage.name.into(),
            variant,
            message,
        ));
    }
    if source == Source::Recorded && !stages.plan.task.is_empty() {
        return Err(locate.error(
            span_of(table, &["plan", "task"]),
            "plan.task".into(),
            variant,
            "planning executes its torques in the plant the data come from, and recorded data \
             have none (the robot is not here to try them; its URDF is only the nominal model): \
             remove [[plan.task]]"
                .into(),
        ));
    }
    let recorded = (source == Source::Recorded).then_some(&crate::stages::INGEST);
    let failure = STAGES
        .iter()
        .filter(|s| !held(s))
        .chain(recorded)
        .find_map(|stage| {
            let check = (stage.validate)(stages, source == Source::Simulated);
            check.err().map(|(key, message)| (stage.name, key, message))
        });
    match failure {
        None => Ok(()),
        Some((stage, key, message)) => {
            let path: Vec<&str> = std::iter::once(stage).chain(key.split('.')).collect();
            Err(locate.error(span_of(table, &path), path.join("."), variant, message))
        }
    }
}

/// Refuses a variant whose estimated work is over the experiment's budget
/// (the simulation's is not counted when an archived dataset holds it).
fn within_budget(
    stages: &Stages,
    experiment: &Experiment,
    table: &DeTable,
    locate: &Locator,
    variant: Option<&str>,
    source: Source,
) -> Result<(), ManifestError> {
    let estimate = crate::budget::Estimate::of(stages);
    match estimate.exceeds(&experiment.budget) {
        Some(("simulate", _)) if source != Source::Simulated => Ok(()),
        Some((stage, message)) => {
            Err(locate.error(span_of(table, &[stage]), stage.into(), variant, message))
        }
        None => Ok(()),
    }
}

/// The stages whose tables `table` has.
fn stage_tables(table: &DeTable) -> BTreeSet<&'static str> {
    STAGES
        .iter()
        .map(|s| s.name)
        .filter(|name| has_key(table, name))
        .collect()
}

pub use alnlab_records::is_identifier;

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[experiment]
name = "demo"
seed = 5

[[simulate.scene]]
name = "box"
duration = 2.0

[stride]
n = 4

[[variant]]
name = "n3"
stride.n = 3

[[variant]]
name = "rk4"
description = "fourth order"
simulate.scene = [{ name = "box", duration = 2.0, integrator = "rk4" }]
"#;

    fn parse(text: &str) -> Result<Manifest, ManifestError> {
        Manifest::parse(text, Path::new("m.toml"))
    }

    #[test]
    fn variants_override_by_dotted_key() {
        let m = parse(GOOD).unwrap();
        assert_eq!(m.variant_names(), ["n3", "rk4"]);
        assert_eq!(m.variants[0].stages.stride.n.0, 3);
        assert_eq!(m.variants[1].stages.stride.n.0, 4);
        assert_eq!(
            m.variants[1].stages.simulate.scene[0].integrator,
            alnlab_simulate::Integrator::Rk4
        );
        assert_eq!(m.variants[1].description, "fourth order");
        // Unset fields take their documented defaults.
        assert_eq!(m.variants[0].stages.simulate.scene[0].dt.get(), 1e-3);
        let toml = m.resolved_toml(&m.variants[0]);
        assert!(toml.contains("n = 3"), "{toml}");
    }

    #[test]
    fn data_from_the_archive_stands_for_simulate_and_stride() {
        let text = "[experiment]\nname = \"x\"\nseed = 1\n\n[data]\ndataset = \"worm@2\"\n\n\
                    [train]\nleaves = 64\n\n[[variant]]\nname = \"q\"\nquantize.levels = 16\n";
        let m = parse(text).unwrap();
        assert_eq!(m.data.as_ref().unwrap().dataset.as_deref(), Some("worm@2"));
        assert!(m.variants[0].tables.contains("quantize"));
        let toml = m.resolved_toml(&m.variants[0]);
        assert!(
            toml.contains("[data]") && toml.contains("[quantize]"),
            "{toml}"
        );
        assert!(
            !toml.contains("[simulate") && !toml.contains("[stride]"),
            "{toml}"
        );
        // A variant that sets a stride parameter is refused where it does.
        let err = parse(&format!("{text}stride.n = 3\n")).unwrap_err();
        assert_eq!(err.variant.as_deref(), Some("q"));
        assert_eq!(
            (err.key.as_str(), err.position.map(|p| p.0)),
            ("stride", Some(14))
        );
        assert!(err.message.contains("remove `stride`"), "{err}");
    }

    #[test]
    fn no_variant_means_one_called_base() {
        let m = parse("[experiment]\nname = \"x\"\nseed = 1\n").unwrap();
        assert_eq!(m.variant_names(), ["base"]);
        assert_eq!(m.variants[0].stages, Stages::default());
    }

    #[test]
    fn replicates_default_to_one_and_draw_their_own_seeds() {
        let m = parse("[experiment]\nname = \"x\"\nseed = 1\n").unwrap();
        assert_eq!(m.experiment.replicates, Count(1));
        let m = parse("[experiment]\nname = \"x\"\nseed = 1\nreplicates = 5\n").unwrap();
        assert_eq!(m.experiment.replicates, Count(5));
        let e = parse("[experiment]\nname = \"x\"\nseed = 1\nreplicates = 0\n").unwrap_err();
        assert_eq!(e.key, "experiment.replicates");
        assert!(e.message.contains("≥ 1"), "{}", e.message);
        // The first replicate is the plain run; the others differ from it,
        // from each other and from the neighbouring seed's.
        assert_eq!(replicate_seed(7, 0), 7);
        let seeds: BTreeSet<u64> = (0..5)
            .flat_map(|r| [replicate_seed(7, r), replicate_seed(8, r)])
            .collect();
        assert_eq!(seeds.len(), 10);
    }

    #[test]
    fn misspelt_key_is_located() {
        let text = GOOD.replace("n = 4", "m = 4");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.position, Some((11, 1)));
        assert_eq!(e.key, "stride.m");
        assert!(e.message.contains("unknown field `m`"), "{}", e.message);
        assert!(e.message.contains("expected one of"), "{}", e.message);
    }

    #[test]
    fn wrong_type_is_located() {
        let text = GOOD.replace("duration = 2.0\n", "duration = \"long\"\n");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.position, Some((8, 12)));
        assert_eq!(e.key, "simulate.scene.0.duration");
        assert!(e.message.contains("expected a number > 0"), "{}", e.message);
    }

    #[test]
    fn negative_count_is_located_even_in_a_variant() {
        let text = GOOD.replace("stride.n = 3", "stride.n = -3");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.position, Some((15, 12)));
        assert_eq!(e.key, "stride.n");
        assert_eq!(e.variant.as_deref(), Some("n3"));
        assert!(
            e.message.contains("whole number ≥ 1, found -3"),
            "{}",
            e.message
        );
        let shown = e.to_string();
        assert!(
            shown.starts_with("m.toml:15:12: in variant `n3`: `stride.n`: expected"),
            "{shown}"
        );
    }

    #[test]
    fn relation_errors_point_at_the_field() {
        // Valid in the base (n = 4), invalid in variant n3.
        let text = GOOD.replace("n = 4", "n = 4\noffset = 3");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.key, "stride.offset");
        assert_eq!(e.variant.as_deref(), Some("n3"));
        assert_eq!(e.position, Some((12, 10)));
        assert!(e.message.contains("below n = 3, found 3"), "{}", e.message);
    }

    #[test]
    fn bad_variant_entries() {
        let e = parse(&GOOD.replace("name = \"n3\"\n", "")).unwrap_err();
        assert!(e.message.contains("needs a `name`"), "{e}");
        let e = parse(&GOOD.replace("\"n3\"", "\"rk4\"")).unwrap_err();
        assert!(e.message.contains("used twice"), "{e}");
        let e = parse(&GOOD.replace("\"n3\"", "\"a/b\"")).unwrap_err();
        assert!(e.message.contains("letters, digits"), "{e}");
    }

    #[test]
    fn syntax_error_is_located() {
        let e = parse("[experiment\nname = 1").unwrap_err();
        assert_eq!(e.position.map(|p| p.0), Some(1));
    }
}
