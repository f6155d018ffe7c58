//! The `alnlab` command line: clap definitions and what each command does.

use std::path::{Path, PathBuf};
use std::time::Instant;

use alnlab_common::hash::sha256_file;
use alnlab_common::table::Table;
use alnlab_common::{Error, Provenance, Result};
use clap::{Parser, Subcommand};

use crate::manifest::{Manifest, Stages};
use crate::progress::Bar;
use crate::run::{RunOptions, run, stage_params};
use alnlab_train::shard::Shard;

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
  alnlab run experiments/paper.toml --train-shard 1/2 & alnlab run experiments/paper.toml --train-shard 2/2
  alnlab run experiments/paper.toml            # merges the two shards instead of training")]
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
        /// Folder for reports: the run's goes to `<reports>/<experiment>/`.
        #[arg(long, default_value = "reports")]
        reports: PathBuf,
        /// The dataset archive a manifest's `[data] dataset` refers to.
        #[arg(long, default_value = "datasets")]
        datasets: PathBuf,
        /// Stop after this stage; writes no run record and no report (for
        /// workflow engines running one stage at a time).
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(crate::run::STAGES))]
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
        command: DatasetCommand,
    },
    /// Export an experiment as a workflow for another engine.
    #[command(subcommand)]
    Export(ExportCommand),
    /// Render a run's report again from its record and artifacts, without
    /// recomputing anything.
    #[command(after_help = "Example:
  alnlab report runs/quickstart")]
    Report {
        /// The run's folder: `<out>/<experiment>`, holding run.json.
        run_dir: PathBuf,
        /// Folder for reports: the report goes to `<reports>/<experiment>/`.
        #[arg(long, default_value = "reports")]
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
    /// Run the simulate stage alone: write trajectory.mcap and stats.parquet.
    #[command(after_help = "Example:
  alnlab simulate --manifest experiments/quickstart.toml --out /tmp/sim")]
    Simulate {
        #[command(flatten)]
        from: ManifestArgs,
        /// Folder to write trajectory.mcap and stats.parquet into.
        #[arg(long)]
        out: PathBuf,
    },
    /// Run the stride stage alone: pair every n-th frame with its successor.
    #[command(after_help = "Example:
  alnlab stride --manifest experiments/quickstart.toml \\
      --trajectory /tmp/sim/trajectory.mcap --out /tmp/stride")]
    Stride {
        #[command(flatten)]
        from: ManifestArgs,
        /// The trajectory log written by simulate.
        #[arg(long)]
        trajectory: PathBuf,
        /// Folder to write pairs.parquet into.
        #[arg(long)]
        out: PathBuf,
    },
    /// Run the quantize stage alone: ranges, levels and codes per variable.
    #[command(after_help = "Example:
  alnlab quantize --manifest experiments/quickstart.toml \\
      --pairs /tmp/stride/pairs.parquet --stats /tmp/sim/stats.parquet --out /tmp/quantize")]
    Quantize {
        #[command(flatten)]
        from: ManifestArgs,
        /// The pairs table written by stride.
        #[arg(long)]
        pairs: PathBuf,
        /// The statistics table written by simulate.
        #[arg(long)]
        stats: PathBuf,
        /// Folder to write codebook.parquet and levels.parquet into.
        #[arg(long)]
        out: PathBuf,
    },
    /// Run the train stage alone: an ALN forest over the training rows.
    #[command(after_help = "Example:
  alnlab train --manifest experiments/quickstart.toml \\
      --codebook /tmp/quantize/codebook.parquet --levels /tmp/quantize/levels.parquet --out /tmp/train")]
    Train {
        #[command(flatten)]
        from: ManifestArgs,
        /// The codebook written by quantize.
        #[arg(long)]
        codebook: PathBuf,
        /// The levels table written by quantize.
        #[arg(long)]
        levels: PathBuf,
        /// Folder to write model.aln and training.parquet into.
        #[arg(long)]
        out: PathBuf,
        /// Train only shard K of N of the trees: a partial model, for
        /// `alnlab merge-models`.
        #[arg(long, value_name = "K/N")]
        shard: Option<Shard>,
    },
    /// Run the test stage alone: the model's predictions for every test row,
    /// beside the persistence and linear baselines, their timings, and
    /// closed-loop rollouts.
    #[command(after_help = "Example:
  alnlab test --manifest experiments/quickstart.toml --trajectory /tmp/sim/trajectory.mcap \\
      --model /tmp/train/model.aln --codebook /tmp/quantize/codebook.parquet \\
      --levels /tmp/quantize/levels.parquet --out /tmp/test")]
    Test {
        #[command(flatten)]
        from: ManifestArgs,
        /// The trajectory log written by simulate (the true closed-loop
        /// trajectories).
        #[arg(long)]
        trajectory: PathBuf,
        /// The model written by train.
        #[arg(long)]
        model: PathBuf,
        /// The codebook written by quantize.
        #[arg(long)]
        codebook: PathBuf,
        /// The levels table written by quantize.
        #[arg(long)]
        levels: PathBuf,
        /// Folder to write predictions.parquet, timings.parquet and
        /// rollout.parquet into.
        #[arg(long)]
        out: PathBuf,
    },
    /// Benchmarks; each prints its figures, or one JSON object with --json.
    #[command(
        subcommand,
        after_help = "Examples:
  alnlab bench sim --json
  alnlab bench cache experiments/quickstart.toml"
    )]
    Bench(Bench),
}

/// Where a stage run alone takes its parameters from.
#[derive(Debug, clap::Args)]
pub struct ManifestArgs {
    /// The experiment manifest holding the stage's parameters.
    #[arg(long)]
    manifest: PathBuf,
    /// The variant whose parameters to use (default: the first).
    #[arg(long)]
    variant: Option<String>,
}

/// The `alnlab export` subcommands.
#[derive(Debug, Subcommand)]
pub enum ExportCommand {
    /// Write a Snakefile and config.yaml that run the experiment's stages as
    /// Snakemake jobs (training in --shards jobs per variant) on the same
    /// output folder `alnlab run` uses: the cache and the run record are
    /// shared. See docs/cluster.md.
    #[command(after_help = "Examples:
  alnlab export snakemake experiments/quickstart.toml --shards 4 -o workflow
  snakemake --snakefile workflow/Snakefile --directory workflow --cores 2
  snakemake --snakefile workflow/Snakefile --directory workflow --executor slurm --jobs 32")]
    Snakemake {
        /// The experiment manifest.
        manifest: PathBuf,
        /// Training jobs per variant (1: one job trains the whole forest).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1024))]
        shards: u32,
        /// Folder to write Snakefile and config.yaml into.
        #[arg(short, long)]
        output: PathBuf,
        /// The run's output folder (cache, run records), as for `alnlab run`.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// Folder for the report.
        #[arg(long, default_value = "reports")]
        reports: PathBuf,
        /// The dataset archive, for a manifest with `[data] dataset`.
        #[arg(long, default_value = "datasets")]
        datasets: PathBuf,
        /// The alnlab binary the jobs run (default: this one).
        #[arg(long)]
        alnlab: Option<PathBuf>,
    },
}

/// The `alnlab dataset` subcommands.
#[derive(Debug, Subcommand)]
pub enum DatasetCommand {
    /// Archive a run's trajectory log, statistics and pairs (with
    /// --with-levels also its codebook and levels) as a new version of NAME;
    /// content already archived is stored once.
    #[command(after_help = "Example:
  alnlab dataset archive --run runs/quickstart --variant walk --name worm-small")]
    Archive {
        /// The run's folder, `<out>/<experiment>`, holding run.json.
        #[arg(long)]
        run: PathBuf,
        /// The variant whose data to archive (needed when the run has several).
        #[arg(long)]
        variant: Option<String>,
        /// The dataset's name: letters, digits, `-`, `_`.
        #[arg(long)]
        name: String,
        /// Also archive the quantize outputs; a run on the dataset then
        /// starts at train.
        #[arg(long)]
        with_levels: bool,
    },
    /// List the archived datasets.
    #[command(after_help = "Example:
  alnlab dataset list")]
    List,
    /// Show one dataset's catalog entry: files, hashes, provenance.
    #[command(after_help = "Example:
  alnlab dataset show worm-small@1")]
    Show {
        /// NAME (latest version), NAME@VERSION or a sha256 prefix.
        dataset: String,
    },
    /// Re-hash every file of one dataset, or of all; exit code 1 if any is
    /// damaged, naming the dataset, the file and both hashes.
    #[command(after_help = "Examples:
  alnlab dataset verify
  alnlab dataset verify worm-small@1")]
    Verify {
        /// NAME, NAME@VERSION or a sha256 prefix; all datasets if left out.
        dataset: Option<String>,
    },
    /// Copy a dataset's files into a folder, verifying them first.
    #[command(after_help = "Example:
  alnlab dataset restore worm-small@1 --to /tmp/worm-small")]
    Restore {
        /// NAME, NAME@VERSION or a sha256 prefix.
        dataset: String,
        /// The folder to copy the files into.
        #[arg(long)]
        to: PathBuf,
    },
    /// Remove one dataset version, and the files no other version uses.
    /// Refuses while a manifest in experiments/ uses it, unless --force.
    #[command(after_help = "Example:
  alnlab dataset remove worm-small@1")]
    Remove {
        /// NAME@VERSION or a sha256 prefix.
        dataset: String,
        /// Remove it even if a manifest uses it.
        #[arg(long)]
        force: bool,
        /// The folder of manifests to check for users of the dataset.
        #[arg(long, default_value = "experiments")]
        experiments: PathBuf,
    },
}

/// The benchmarks.
#[derive(Debug, Subcommand)]
pub enum Bench {
    /// Time the simulator: ns per step for the worm with and without
    /// contacts and for free chains of 1 to 64 links, and the simulate
    /// stage's throughput with MCAP writing. Medians of REPEAT runs, one core.
    #[command(after_help = "Example:
  alnlab bench sim --json")]
    Sim {
        /// How many timed runs per figure.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time quantization and coding: values quantized and walk-encoded into
    /// a bit matrix per second, and walk nearest-code decodes per second
    /// (W = 23, L = 214). Medians of REPEAT runs, one core.
    #[command(after_help = "Example:
  alnlab bench quantize --json")]
    Quantize {
        /// How many timed runs per figure.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time ALN training at the paper's scale (8192 leaves, 10 epochs, 1000
    /// samples, 23-bit walk codes, all cores) twice: on paper-shaped data
    /// (64 variables: 1472 trees over 1472 input bits), and on the worm
    /// simulated and quantized by the stages (its 57 learned variables:
    /// 1311 trees; the `worm` object of `--json`).
    #[command(after_help = "Example:
  alnlab bench train --json")]
    Train {
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time the summarize stage on 10⁷ errors (3 models × 64 variables ×
    /// 52 084 rows): reading predictions.parquet, the statistics, writing
    /// summary.parquet.
    #[command(after_help = "Example:
  alnlab bench summarize --json")]
    Summarize {
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time full-state prediction at the paper's scale: all 1472 trees and
    /// the decoding, bit-sliced in batches and one sample at a time
    /// (parsimonious), with the fraction of nodes evaluated.
    #[command(after_help = "Example:
  alnlab bench predict --json")]
    Predict {
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time sharded training: the manifest's forest trained in one process
    /// (all cores) against SHARDS processes of `train --shard K/N` side by
    /// side (each given its share of the cores) and the merge; checks the
    /// merged model equals the in-process one byte for byte.
    #[command(after_help = "Example:
  alnlab bench shards experiments/paper.toml --shards 2 --json")]
    Shards {
        /// The experiment manifest (its data are made in a temporary folder).
        #[arg(default_value = "experiments/paper.toml")]
        manifest: PathBuf,
        /// The variant (default: the first).
        #[arg(long)]
        variant: Option<String>,
        /// Training processes.
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
        shards: u32,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time a fully cached `run` of a manifest (the no-op re-run).
    ///
    /// Runs the manifest once to fill the cache, then times REPEAT re-runs
    /// that find everything cached, and reports the median.
    #[command(after_help = "Example:
  alnlab bench cache experiments/quickstart.toml --json")]
    Cache {
        /// The experiment manifest.
        #[arg(default_value = "experiments/quickstart.toml")]
        manifest: PathBuf,
        /// Output folder for the cache.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// How many cached re-runs to time.
        #[arg(long, default_value_t = 10)]
        repeat: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

/// Executes the parsed command line.
pub fn execute(cli: Cli) -> Result<()> {
    let quiet = cli.quiet;
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
            let options = RunOptions {
                out,
                force,
                variant,
                quiet,
                datasets,
                until,
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
            let path = options.out.join(&record.experiment).join("run.json");
            println!(
                "run record: {}  ({:.3} s)",
                path.display(),
                record.wall_seconds
            );
            let report = crate::report::render(&record, &reports)?;
            println!("report:     {}", report.display());
            Ok(())
        }
        Command::Dataset { datasets, command } => crate::dataset_cli::execute(&datasets, command),
        Command::Export(ExportCommand::Snakemake {
            manifest,
            shards,
            output,
            out,
            reports,
            datasets,
            alnlab,
        }) => {
            let manifest = Manifest::load(&manifest)?;
            let alnlab = match alnlab {
                Some(path) => path,
                None => std::env::current_exe().map_err(|e| Error::io(Path::new("alnlab"), e))?,
            };
            let export = crate::export::Export {
                manifest: &manifest,
                alnlab,
                shards,
                out,
                reports,
                datasets,
            };
            crate::export::snakemake(&export, &output)?;
            println!(
                "{0}/Snakefile, {0}/config.yaml — run with: snakemake --snakefile {0}/Snakefile \
                 --directory {0} --cores 2",
                output.display()
            );
            Ok(())
        }
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
            let record = crate::report::read_record(&run_dir)?;
            let report = crate::report::render(&record, &reports)?;
            println!("report: {}", report.display());
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
        Command::Simulate { from, out } => run_alone(
            &from,
            "simulate",
            |s| &s.simulate,
            &[],
            &out,
            &[
                alnlab_simulate::TRAJECTORY_FILE,
                alnlab_simulate::STATS_FILE,
            ],
            quiet,
            |params, seed, provenance, bar| {
                alnlab_simulate::run(params, seed, provenance, &out, bar)
            },
        ),
        Command::Stride {
            from,
            trajectory,
            out,
        } => run_alone(
            &from,
            "stride",
            |s| &s.stride,
            &[("trajectory", &trajectory)],
            &out,
            &[alnlab_stride::PAIRS_FILE],
            quiet,
            |params, seed, provenance, bar| {
                alnlab_stride::run(params, seed, &trajectory, provenance, &out, bar)
            },
        ),
        Command::Bench(Bench::Cache {
            manifest,
            out,
            repeat,
            json,
        }) => bench_cache(&manifest, out, repeat.max(1), json, quiet),
        Command::Quantize {
            from,
            pairs,
            stats,
            out,
        } => run_alone(
            &from,
            "quantize",
            |s| &s.quantize,
            &[("pairs", &pairs), ("stats", &stats)],
            &out,
            &[alnlab_quantize::CODEBOOK_FILE, alnlab_quantize::LEVELS_FILE],
            quiet,
            |params, seed, provenance, bar| {
                alnlab_quantize::run(params, seed, &pairs, &stats, provenance, &out, bar)
            },
        ),
        Command::Train {
            from,
            codebook,
            levels,
            out,
            shard,
        } => run_alone(
            &from,
            "train",
            |s| &s.train,
            &[("codebook", &codebook), ("levels", &levels)],
            &out,
            &[alnlab_train::MODEL_FILE, alnlab_train::TRAINING_FILE],
            quiet,
            |params, seed, provenance, bar| {
                let shard = shard.unwrap_or(Shard::ALL);
                alnlab_train::run(
                    params, seed, shard, &codebook, &levels, provenance, &out, bar,
                )
            },
        ),
        Command::Test {
            from,
            trajectory,
            model,
            codebook,
            levels,
            out,
        } => run_alone(
            &from,
            "test",
            |s| &s.test,
            &[
                ("trajectory", &trajectory),
                ("model", &model),
                ("codebook", &codebook),
                ("levels", &levels),
            ],
            &out,
            &[
                alnlab_test::PREDICTIONS_FILE,
                alnlab_test::TIMINGS_FILE,
                alnlab_test::ROLLOUT_FILE,
            ],
            quiet,
            |params, _seed, provenance, bar| {
                alnlab_test::run(
                    params,
                    &trajectory,
                    &model,
                    &codebook,
                    &levels,
                    provenance,
                    &out,
                    bar,
                )
            },
        ),
        Command::Bench(Bench::Shards {
            manifest,
            variant,
            shards,
            json,
        }) => {
            let variant = match variant {
                Some(v) => v,
                None => Manifest::load(&manifest)?.variants[0].name.clone(),
            };
            let figures = crate::bench::shards(&manifest, &variant, shards)?;
            print_figures(&figures, json, |f| {
                println!(
                    "{} trees: in-process {:.2} s; {} processes {:.2} s + merge {:.2} s = {:.2}× \
                     ({})",
                    f.trees,
                    f.in_process_seconds,
                    f.shards,
                    f.processes_seconds,
                    f.merge_seconds,
                    f.ratio,
                    if f.identical {
                        "merged model identical"
                    } else {
                        "MERGED MODEL DIFFERS"
                    }
                )
            });
            if figures.identical {
                Ok(())
            } else {
                Err(Error::Invalid("bench: the merged model differs".into()))
            }
        }
        Command::Bench(Bench::Summarize { json }) => {
            let figures = alnlab_summarize::bench::run()?;
            print_figures(&figures, json, |figures| {
                println!(
                    "summarize: {:.3} s for {} errors ({:.3e} errors/s)",
                    figures.seconds, figures.errors, figures.errors_per_s
                );
            });
            Ok(())
        }
        Command::Bench(Bench::Train { json }) => {
            let figures = alnlab_train::bench::train();
            let worm = crate::bench::worm_training()?;
            if json {
                let mut value = serde_json::to_value(&figures).expect("figures serialize");
                value["worm"] = serde_json::to_value(&worm).expect("figures serialize");
                println!("{value}");
            } else {
                println!(
                    "paper-shaped data:  {:5.1} s for {} trees on {} threads ({:.3e} node updates/s)",
                    figures.seconds, figures.trees, figures.threads, figures.node_updates_per_s
                );
                println!(
                    "worm (simulated):   {:5.1} s for {} trees on {} threads ({:.3e} node updates/s)",
                    worm.seconds, worm.trees, worm.threads, worm.node_updates_per_s
                );
            }
            Ok(())
        }
        Command::Bench(Bench::Predict { json }) => {
            let figures = alnlab_train::bench::predict();
            print_figures(&figures, json, |figures| {
                println!(
                    "batched (bit-sliced):     {:10.0} ns per state on {} threads, of which decoding {:.0} ns",
                    figures.batched_ns_per_state, figures.threads, figures.decode_ns_per_state
                );
                println!(
                    "batched, one thread:      {:10.0} ns per state",
                    figures.batched_one_thread_ns_per_state
                );
                println!(
                    "single (parsimonious):    {:10.0} ns per state, {:.0} leaves tested",
                    figures.single_ns_per_state, figures.leaves_tested_per_state
                );
                println!(
                    "nodes evaluated:          {:.4} of all (estimate ½·(3/4)^13 = {:.4})",
                    figures.nodes_evaluated_fraction, figures.estimated_fraction
                );
            });
            Ok(())
        }
        Command::Bench(Bench::Quantize { repeat, json }) => {
            let figures = alnlab_quantize::bench::run(repeat.max(1));
            print_figures(&figures, json, |figures| {
                println!(
                    "quantize + encode: {:12.0} values/s",
                    figures.quantize_encode_values_per_s
                );
                println!(
                    "walk decode:       {:12.0} decodes/s",
                    figures.walk_decodes_per_s
                );
            });
            Ok(())
        }
        Command::Bench(Bench::Sim { repeat, json }) => {
            let figures = alnlab_simulate::bench::run(repeat.max(1))?;
            print_figures(&figures, json, |figures| {
                println!(
                    "worm without contacts: {:8.0} ns/step",
                    figures.worm_no_contact_ns_per_step
                );
                println!(
                    "worm with contacts:    {:8.0} ns/step",
                    figures.worm_contact_ns_per_step
                );
                for (links, ns) in &figures.chain_ns_per_step {
                    println!("free chain, {links:2} links: {ns:8.0} ns/step");
                }
                println!(
                    "simulate stage:        {:8.0} steps/s",
                    figures.stage_steps_per_s
                );
            });
            Ok(())
        }
    }
}

/// Prints a benchmark's figures: one JSON object with `--json`, else as
/// `text` words them.
fn print_figures<T: serde::Serialize>(figures: &T, json: bool, text: impl FnOnce(&T)) {
    if json {
        println!(
            "{}",
            serde_json::to_string(figures).expect("figures serialize")
        );
    } else {
        text(figures);
    }
}

impl ManifestArgs {
    fn load(&self) -> Result<(Manifest, String)> {
        let manifest = Manifest::load(&self.manifest)?;
        let variant = match &self.variant {
            Some(v) => v.clone(),
            None => manifest.variants[0].name.clone(),
        };
        Ok((manifest, variant))
    }
}

/// Runs one stage alone: its parameters from the chosen variant of the
/// manifest, provenance from the manifest and the inputs' hashes (as
/// `alnlab run` writes them, so the files are the same), then names the
/// files written.
#[allow(clippy::too_many_arguments)]
fn run_alone<P: serde::Serialize>(
    from: &ManifestArgs,
    stage: &str,
    pick: fn(&Stages) -> &P,
    inputs: &[(&str, &PathBuf)],
    out: &Path,
    outputs: &[&str],
    quiet: bool,
    run: impl FnOnce(&P, u64, &Provenance, &Bar) -> Result<()>,
) -> Result<()> {
    let (manifest, variant) = from.load()?;
    let params = pick(&manifest.variant(&variant)?.stages);
    let seed = manifest.experiment.seed;
    let provenance = Provenance {
        stage: stage.into(),
        params: stage_params(seed, params),
        inputs: inputs
            .iter()
            .map(|(role, path)| Ok((role.to_string(), sha256_file(path)?)))
            .collect::<Result<_>>()?,
    };
    run(params, seed, &provenance, &Bar::new(stage, quiet))?;
    for file in outputs {
        println!("wrote {}", out.join(file).display());
    }
    Ok(())
}

fn bench_cache(
    manifest: &Path,
    out: PathBuf,
    repeat: usize,
    json: bool,
    quiet: bool,
) -> Result<()> {
    let options = RunOptions {
        out,
        force: false,
        variant: None,
        quiet,
        datasets: PathBuf::from("datasets"),
        until: None,
    };
    let warm = Manifest::load(manifest)?;
    run(&warm, &options)?;
    let mut seconds = Vec::with_capacity(repeat);
    for _ in 0..repeat {
        let clock = Instant::now();
        // Everything a cached `alnlab run` does after process start.
        let manifest = Manifest::load(manifest)?;
        let record = run(&manifest, &options)?;
        seconds.push(clock.elapsed().as_secs_f64());
        if record
            .variants
            .iter()
            .flat_map(|v| &v.stages)
            .any(|s| !s.cached)
        {
            return Err(Error::Invalid(
                "a stage re-ran although nothing changed".into(),
            ));
        }
    }
    seconds.sort_by(f64::total_cmp);
    let median = seconds[seconds.len() / 2];
    if json {
        println!(
            "{}",
            serde_json::json!({
                "manifest": manifest.display().to_string(),
                "repeat": repeat,
                "cached_run_median_s": median,
                "cached_run_max_s": seconds[seconds.len() - 1],
            })
        );
    } else {
        println!(
            "cached re-run of {}: median {:.1} ms, max {:.1} ms over {repeat} runs",
            manifest.display(),
            median * 1e3,
            seconds[seconds.len() - 1] * 1e3
        );
    }
    Ok(())
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
