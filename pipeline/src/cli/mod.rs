//! The `alnlab` command line: the top-level arguments and a thin dispatch.
//! Each group of commands has its module — [`stage`] (every stage alone,
//! from the stage table), [`dataset`], [`export`], [`bench`], [`runs`] — and the
//! experiment commands (`run`, `check`, `report`, `merge-models`) are here.

pub mod bench;
pub mod dataset;
pub mod export;
pub mod runs;
pub mod stage;

use std::path::PathBuf;

use alnlab_aln::shard::Shard;
use alnlab_common::table::Table;
use alnlab_common::{Error, Provenance, Result};
use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser, Subcommand};

use crate::manifest::Manifest;
use crate::run::{RunOptions, run};
use crate::stages;

/// alnlab — how well, and how fast, can adaptive logic networks predict the
/// motion of articulated rigid bodies?
///
/// An experiment is a TOML manifest; `alnlab run` executes its stages
/// (simulate → stride → …) through a content-addressed artifact cache and
/// writes a run record. Every stage can also run alone on explicit files.
#[derive(Debug, Parser)]
#[command(
    name = "alnlab",
    version,
    after_help = "Examples:
  alnlab run                                  # experiments/quickstart.toml into runs/
  alnlab check experiments/quickstart.toml    # validate, print the resolved variants
  alnlab simulate --manifest experiments/quickstart.toml --out /tmp/sim"
)]
pub struct Cli {
    /// No progress bars.
    #[arg(long, short, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run an experiment: every stage of every variant, reusing cached artifacts.
    ///
    /// Artifacts go to <OUT>/cache/<stage>/<key>/, keyed by the stage's
    /// parameters and inputs; only stages whose key changed run again. The run
    /// record is written to <OUT>/<experiment>/run.json. A second run on the
    /// same <OUT> waits until the first is done.
    #[command(after_help = "Examples:
  alnlab run
  alnlab run experiments/quickstart.toml --out runs --variant walk
  alnlab run experiments/quickstart.toml --force
  alnlab run experiments/paper.toml --until quantize
  alnlab run experiments/paper.toml --reports reports

Training in two shards, then a run that merges them instead of training:
  alnlab run experiments/paper.toml --train-shard 1/2 &
  alnlab run experiments/paper.toml --train-shard 2/2
  alnlab run experiments/paper.toml")]
    Run {
        /// The experiment manifest.
        #[arg(default_value = "experiments/quickstart.toml")]
        manifest: PathBuf,
        /// Output folder for the cache and run records.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// Re-run every stage, cached or not.
        #[arg(long)]
        force: bool,
        /// Run only this variant.
        #[arg(long)]
        variant: Option<String>,
        /// Publish the report to `<REPORTS>/<experiment>/` (e.g. the
        /// committed `reports`) instead of the run's own folder,
        /// `<OUT>/<experiment>/report/`.
        #[arg(long)]
        reports: Option<PathBuf>,
        /// The dataset archive a manifest's `[data] dataset` refers to.
        #[arg(long, default_value = "datasets")]
        datasets: PathBuf,
        /// Stop after this stage (or, `rounds`, after the rounds of the
        /// planner's own data that follow every stage); writes no run record
        /// and no report (for workflow engines running one stage at a time).
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(stages::until_names()))]
        until: Option<String>,
        /// Train only shard K of N of the variant's forest (after bringing it
        /// up to quantize), into <OUT>/shards/; a later run through train
        /// merges the complete set instead of training. Needs --variant when
        /// the manifest has several.
        #[arg(long, value_name = "K/N", conflicts_with = "until")]
        train_shard: Option<Shard>,
    },
    /// Join the partial models of `train --shard K/N` (all N of them) into
    /// the model file and training log one process would have written.
    #[command(after_help = "Example:
  alnlab train --manifest m.toml --codebook c.parquet --levels l.parquet --shard 1/2 --out s1
  alnlab train --manifest m.toml --codebook c.parquet --levels l.parquet --shard 2/2 --out s2
  alnlab merge-models s1 s2 --out merged")]
    MergeModels {
        /// The shards' folders (each with model.aln and training.parquet).
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Folder to write model.aln and training.parquet into.
        #[arg(long)]
        out: PathBuf,
    },
    /// Archive, list, verify and restore datasets: a run's simulate and
    /// stride outputs (and optionally its quantized levels), kept
    /// content-addressed under the archive folder with a catalog.
    ///
    /// A manifest runs on an archived dataset instead of simulating with
    /// `[data] dataset = "NAME@VERSION"`.
    #[command(after_help = "Examples:
  alnlab dataset archive --run runs/quickstart --variant walk --name worm-small
  alnlab dataset list
  alnlab dataset show worm-small@1
  alnlab dataset verify
  alnlab dataset restore worm-small@1 --to /tmp/worm-small
  alnlab dataset remove worm-small@1")]
    Dataset {
        /// The archive folder.
        #[arg(long, default_value = "datasets", global = true)]
        datasets: PathBuf,
        #[command(subcommand)]
        command: dataset::DatasetCommand,
    },
    /// Export an experiment as a workflow for another engine.
    #[command(subcommand)]
    Export(export::ExportCommand),
    /// Render a run's report again from its record and artifacts, without
    /// recomputing anything.
    #[command(after_help = "Example:
  alnlab report runs/quickstart
  alnlab report runs/quickstart --reports reports   # refresh the committed report")]
    Report {
        /// The run's folder: `<out>/<experiment>`, holding run.json.
        run_dir: PathBuf,
        /// Publish the report to `<REPORTS>/<experiment>/` (e.g. the
        /// committed `reports`) instead of `<RUN_DIR>/report/`.
        #[arg(long)]
        reports: Option<PathBuf>,
    },
    /// Draw the chart across reports: every report's ALNs and simulator
    /// settings, mean error over persistence's against µs per state one at a
    /// time, from each `<REPORTS>/<name>/frontier.csv` (written with the
    /// report) into `<REPORTS>/synthesis.svg`.
    #[command(after_help = "Example:
  alnlab synthesis reports      # after refreshing reports with --reports reports")]
    Synthesis {
        /// The folder of published reports.
        #[arg(default_value = "reports")]
        reports: PathBuf,
    },
    /// Validate a manifest and print it fully resolved, once per variant.
    ///
    /// Errors name the file, line and column, the key, and what is allowed;
    /// the exit code is then 2.
    #[command(after_help = "Example:
  alnlab check experiments/quickstart.toml")]
    Check {
        /// The experiment manifest.
        manifest: PathBuf,
    },
    /// List, show and compare recorded runs: every `alnlab run` keeps its
    /// record (parameters, headline metrics, artifacts) under
    /// <OUT>/<experiment>/records/<id>.json. Without a subcommand: `list`.
    #[command(after_help = "Examples:
  alnlab runs                                    # every run under runs/, one line per variant
  alnlab runs list --where train.vote=3 --json
  alnlab runs show quickstart                    # the latest quickstart run
  alnlab runs diff quickstart~1 quickstart --only-changed
  alnlab export mlflow quickstart --tracking-uri http://127.0.0.1:5000")]
    Runs(runs::RunsArgs),
    /// Benchmarks; each prints its figures, or one JSON object with --json.
    #[command(
        subcommand,
        after_help = "Examples:
  alnlab bench sim --json
  alnlab bench cache experiments/quickstart.toml"
    )]
    Bench(bench::Bench),
}

/// The whole command line: the commands above and one subcommand per stage
/// of the stage table.
pub fn command() -> clap::Command {
    stage::commands()
        .into_iter()
        .fold(Cli::command(), |cli, stage| cli.subcommand(stage))
}

/// Parses `matches` (from [`command`]) and executes the command.
pub fn execute(matches: &ArgMatches) -> Result<()> {
    let quiet = matches.get_flag("quiet");
    if let Some((name, args)) = matches.subcommand()
        && let Some(stage) = stages::find(name)
    {
        return stage::execute(stage, args, quiet);
    }
    let cli = Cli::from_arg_matches(matches).map_err(|e| Error::Invalid(e.to_string()))?;
    match cli.command {
        Command::Run {
            manifest,
            out,
            force,
            variant,
            reports,
            datasets,
            until,
            train_shard,
        } => {
            let manifest = Manifest::load(&manifest)?;
            if let (Some(folder), None) = (&reports, &until) {
                crate::git::check_run_publishable(folder, &manifest.path)?;
            }
            let options = RunOptions {
                out,
                force,
                variant,
                quiet,
                datasets,
                until,
                reports: reports.clone(),
            };
            if let Some(shard) = train_shard {
                let variant = match &options.variant {
                    Some(name) => name.clone(),
                    None => only_variant(&manifest)?,
                };
                let dir = crate::run::train_shard(&manifest, &options, &variant, shard)?;
                println!("shard {shard} of `{variant}`: {}", dir.display());
                return Ok(());
            }
            let record = run(&manifest, &options)?;
            for variant in &record.variants {
                for stage in &variant.stages {
                    let what = if stage.cached { "cached" } else { "ran" };
                    println!(
                        "{}/{} {:<9} {what:<6} {:>8.3} s",
                        record.experiment, variant.name, stage.stage, stage.wall_seconds
                    );
                }
            }
            if options.until.is_some() {
                return Ok(());
            }
            let path = options
                .out
                .join(&record.experiment)
                .join(crate::records::RECORDS_DIR)
                .join(format!("{}.json", record.id));
            println!(
                "run record: {}  ({:.3} s)",
                path.display(),
                record.wall_seconds
            );
            let run_dir = options.out.join(&record.experiment);
            let report = crate::report::render(&record, &report_dir(&run_dir, reports, &record))?;
            println!("report:     {}", report.display());
            Ok(())
        }
        Command::Dataset { datasets, command } => dataset::execute(&datasets, command),
        Command::Export(command) => export::execute(command),
        Command::Bench(command) => bench::execute(command, quiet),
        Command::Runs(args) => runs::execute(args),
        Command::MergeModels { parts, out } => {
            // The merged files carry the parts' provenance (the train
            // stage's parameters and inputs, the same for every part).
            let log = parts[0].join(alnlab_train::TRAINING_FILE);
            let provenance = Provenance::from_key_values(&Table::read(&log)?.metadata)
                .ok_or_else(|| Error::bad_file(&log, "has no alnlab provenance"))?;
            alnlab_train::shard::merge(&parts, &provenance, &out)?;
            println!("{}", out.join(alnlab_train::MODEL_FILE).display());
            Ok(())
        }
        Command::Report { run_dir, reports } => {
            let record = crate::records::read_record(&run_dir)?;
            if let Some(folder) = &reports {
                crate::git::check_record_publishable(
                    folder,
                    record.git_commit.as_deref(),
                    &record.git_changes,
                )?;
            }
            let report = crate::report::render(&record, &report_dir(&run_dir, reports, &record))?;
            println!("report: {}", report.display());
            Ok(())
        }
        Command::Synthesis { reports } => {
            let (chart, drawn) = alnlab_report::synthesis::render_synthesis(&reports)?;
            println!("{} ({})", chart.display(), drawn.join(", "));
            Ok(())
        }
        Command::Check { manifest } => {
            let manifest = Manifest::load(&manifest)?;
            for variant in &manifest.variants {
                println!("# variant `{}`", variant.name);
                if !variant.description.is_empty() {
                    println!("# {}", variant.description);
                }
                println!("{}", manifest.resolved_toml(variant));
            }
            Ok(())
        }
    }
}

/// The manifest's one variant, or an error asking to choose.
fn only_variant(manifest: &Manifest) -> Result<String> {
    match manifest.variants.as_slice() {
        [one] => Ok(one.name.clone()),
        many => Err(Error::Invalid(format!(
            "{}: --train-shard needs --variant: the manifest has {}",
            manifest.path.display(),
            many.iter()
                .map(|v| v.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

/// Where a run's report goes: `<reports>/<experiment>/` when publishing,
/// else the run's own `report/` folder (so a run leaves a checkout's
/// committed reports alone).
fn report_dir(
    run_dir: &std::path::Path,
    reports: Option<PathBuf>,
    record: &crate::records::RunRecord,
) -> PathBuf {
    match reports {
        Some(reports) => reports.join(&record.experiment),
        None => run_dir.join("report"),
    }
}
