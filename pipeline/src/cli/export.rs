//! `alnlab export …`: an experiment as a workflow for another engine, a
//! recorded run to an experiment tracker.

use std::path::{Path, PathBuf};
use std::time::Duration;

use alnlab_common::{Error, Result};
use clap::Subcommand;

use crate::manifest::Manifest;
use crate::{mlflow, records};

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
    /// Hand a recorded run to an MLflow tracking server, through its REST
    /// API: each variant (and replicate) becomes an MLflow run with the
    /// variant's resolved parameters, its metrics (figures, and training
    /// and closed-loop errors by step), tags (run id, git commit, manifest
    /// sha256) and the report as artifacts. Exporting again adds nothing.
    ///
    /// The server must serve artifacts (`mlflow server`'s default). Set
    /// MLFLOW_TRACKING_TOKEN, or MLFLOW_TRACKING_USERNAME and
    /// MLFLOW_TRACKING_PASSWORD, for a server that asks for them.
    #[command(after_help = "Examples:
  mlflow server --backend-store-uri sqlite:///mlflow.db --host 127.0.0.1 --port 5000 &
  alnlab export mlflow quickstart --tracking-uri http://127.0.0.1:5000
  alnlab export mlflow 20261123-152818-0ef52a --out /scratch/runs --experiment worm-codes
  alnlab export mlflow quickstart --tracking-uri https://mlflow.example.org --timeout 300")]
    Mlflow {
        /// The run: an id (or a unique prefix), an experiment's name (its
        /// latest run) or NAME~N, as `alnlab runs list` shows them.
        run: String,
        /// The tracking server's address.
        #[arg(long, env = "MLFLOW_TRACKING_URI")]
        tracking_uri: String,
        /// The output folder the run was made in.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// The MLflow experiment to export into (default: the alnlab
        /// experiment's name).
        #[arg(long)]
        experiment: Option<String>,
        /// Seconds one request may take; a request safe to repeat (a read,
        /// an artifact's upload) is tried three times.
        #[arg(long, default_value_t = 60.0, value_parser = positive_seconds)]
        timeout: f64,
    },
    /// Write a trained bit-forest as synthesizable Verilog: one module per
    /// pruned tree (ports named after the variables and their code bits:
    /// `roll_2_b5` is bit 5 of `roll.2`'s code), one per learned variable
    /// (its trees, their majority votes and its decoder, from the code bits
    /// to the level in binary), and `predict_state` in top.v for the whole
    /// state. `alnlab bench circuit` synthesizes and simulates it.
    #[command(after_help = "Examples:
  alnlab export verilog runs/cache/train/<key>/model.aln \\
      --codebook runs/cache/quantize/<key>/codebook.parquet -o verilog
  yosys -p 'read_verilog verilog/*.v; synth -top predict_state; stat'")]
    Verilog {
        /// The model.aln written by train (a bit-forest).
        model: PathBuf,
        /// The codebook.parquet it was trained with.
        #[arg(long)]
        codebook: PathBuf,
        /// Folder to write the Verilog files into (made; it must not hold
        /// files already).
        #[arg(short, long)]
        output: PathBuf,
    },
}

/// Runs one `alnlab export` subcommand.
pub fn execute(command: ExportCommand) -> Result<()> {
    match command {
        ExportCommand::Snakemake {
            manifest,
            shards,
            output,
            out,
            reports,
            datasets,
            alnlab,
        } => {
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
        ExportCommand::Mlflow {
            run,
            tracking_uri,
            out,
            experiment,
            timeout,
        } => export_mlflow(
            &run,
            &tracking_uri,
            &out,
            experiment,
            Duration::from_secs_f64(timeout),
        ),
        ExportCommand::Verilog {
            model,
            codebook,
            output,
        } => export_verilog(&model, &codebook, &output),
    }
}

/// `alnlab export verilog`: the files are written into a hidden folder
/// beside `output`, which becomes `output` when all are written.
fn export_verilog(model: &Path, codebook: &Path, output: &Path) -> Result<()> {
    let trained = alnlab_aln::runtime::Trained::read(model, codebook)?;
    let circuit = alnlab_circuit::circuit_of(&trained, model)?;
    if output.exists() && !output.is_dir() {
        return Err(Error::Invalid(format!(
            "{}: is a file; name a new folder for the Verilog",
            output.display()
        )));
    }
    if output.read_dir().is_ok_and(|mut d| d.next().is_some()) {
        return Err(Error::Invalid(format!(
            "{}: holds files already; name a new folder",
            output.display()
        )));
    }
    let parent = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    let staging = tempfile::Builder::new()
        .prefix(".verilog-")
        .tempdir_in(parent)
        .map_err(|e| Error::io(parent, e))?;
    alnlab_circuit::check::write_files(&circuit, staging.path())?;
    if output.exists() {
        std::fs::remove_dir(output).map_err(|e| Error::io(output, e))?;
    }
    let staged = staging.keep();
    std::fs::rename(&staged, output).map_err(|e| Error::io(output, e))?;
    let trees: usize = circuit.variables.iter().map(|v| v.trees.len()).sum();
    println!(
        "{}: {} files — {trees} tree modules, {} variable modules, top module `{}` in {}",
        output.display(),
        circuit.files.len(),
        circuit.variables.len(),
        alnlab_circuit::verilog::TOP,
        alnlab_circuit::verilog::TOP_FILE
    );
    Ok(())
}

/// `alnlab export mlflow`: the report is rendered from the record into a
/// temporary folder (so a run other than the latest gets its own report);
/// without its artifacts in the cache, the export goes on without it.
fn export_mlflow(
    reference: &str,
    tracking_uri: &str,
    out: &Path,
    experiment: Option<String>,
    timeout: Duration,
) -> Result<()> {
    let (stored, _) = records::find(out, reference, records::Spelling::Cli)?;
    let record = &stored.record;
    let client = mlflow::Client::new(tracking_uri, timeout)?;
    let staging = tempfile::tempdir().map_err(|e| Error::io(&std::env::temp_dir(), e))?;
    let report = match crate::report::render(record, staging.path()) {
        Ok(_) => Some(staging.path()),
        Err(e) => {
            eprintln!("warning: the report is not exported: rendering it failed ({e})");
            None
        }
    };
    let experiment = experiment.unwrap_or_else(|| record.experiment.clone());
    println!(
        "run {} ({}) → MLflow experiment `{experiment}` at {tracking_uri}",
        record.id, record.experiment
    );
    mlflow::export(&client, record, &experiment, report, |variant, outcome| {
        let name = format!("{} #{}", variant.name, variant.replicate + 1);
        match outcome {
            mlflow::Outcome::Exported {
                run_id,
                params,
                metrics,
                artifacts,
            } => println!(
                "  {name}: MLflow run {run_id} — {params} parameters, {metrics} metric values, \
                 {artifacts} artifacts"
            ),
            mlflow::Outcome::AlreadyThere { run_id } => {
                println!("  {name}: already exported as MLflow run {run_id}")
            }
        }
    })
}

/// A number of seconds > 0 (and at most a day), for `--timeout`.
fn positive_seconds(text: &str) -> std::result::Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if s > 0.0 && s <= 86_400.0 => Ok(s),
        _ => Err(format!("expected seconds > 0 and ≤ 86400, found `{text}`")),
    }
}
