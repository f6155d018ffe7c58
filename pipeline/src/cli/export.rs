//! `alnlab export …`: an experiment as a workflow for another engine.

use std::path::{Path, PathBuf};

use alnlab_common::{Error, Result};
use clap::Subcommand;

use crate::manifest::Manifest;

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
    }
}
