//! `alnlab dataset …`: the subcommands and what each does, on top of
//! [`crate::dataset`].

use std::path::{Path, PathBuf};

use alnlab_common::{Error, Result};

use crate::dataset::{
    Archive, BASE_ROLES, DatasetProvenance, Entry, ImportedSource, LEVEL_ROLES, LICENCE_ROLE,
    Origin, Source, TABLE_ROLE, check_name,
};
use crate::records::pick_variant;
use crate::records::read_record;
use clap::Subcommand;

/// The `alnlab dataset` subcommands.
#[derive(Debug, Subcommand)]
pub enum DatasetCommand {
    /// Archive a run's trajectory log, statistics and pairs (with
    /// --with-levels also its codebook and levels) as a new version of NAME;
    /// content already archived is stored once.
    #[command(after_help = "Example:
  alnlab dataset archive --run runs/quickstart --variant walk --replicate 1 --name worm-small")]
    Archive {
        /// The run's folder, `<out>/<experiment>`, holding run.json.
        #[arg(long)]
        run: PathBuf,
        /// The variant whose data to archive (needed when the run's variants'
        /// data differ).
        #[arg(long)]
        variant: Option<String>,
        /// The replicate whose data to archive, from 1 (needed when the
        /// variant's replicates' data differ: each has its own seed).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
        replicate: Option<u32>,
        /// The dataset's name: letters, digits, `-`, `_`.
        #[arg(long)]
        name: String,
        /// Also archive the quantize outputs; a run on the dataset then
        /// starts at train.
        #[arg(long)]
        with_levels: bool,
    },
    /// Import a robot's recordings made elsewhere — tables of samples, CSV
    /// or Parquet, one a trajectory — as a new version of NAME, with where
    /// they were published, how to cite them and their licence (its text
    /// kept beside them). A manifest reads them with `[data] dataset` and
    /// `[ingest.table]`.
    #[command(after_help = "Example:
  alnlab dataset import --name kuka-lwr4 \\
    --source 'https://github.com/kjyv/FloBaRoID (commit e6c077e, data/KUKA/HW)' \\
    --citation 'S. Bethge et al., FloBaRoID, RAAD 2017' \\
    --licence LGPL-3.0-only --licence-file LICENSE measurements_1.parquet measurements_2.parquet")]
    Import {
        /// The dataset's name: letters, digits, `-`, `_`.
        #[arg(long)]
        name: String,
        /// Where the recordings were published (a URL, with a commit or
        /// version where there is one).
        #[arg(long)]
        source: String,
        /// How to cite them.
        #[arg(long)]
        citation: String,
        /// Their licence's SPDX identifier, e.g. LGPL-3.0-only.
        #[arg(long)]
        licence: String,
        /// The licence's text, archived beside the tables.
        #[arg(long)]
        licence_file: PathBuf,
        /// What else a user must know (what was converted, caveats).
        #[arg(long, default_value = "")]
        notes: String,
        /// The tables, each one trajectory (`.csv` or `.parquet`), in order.
        #[arg(required = true)]
        tables: Vec<PathBuf>,
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

/// Runs one `alnlab dataset` subcommand on the archive in `datasets`.
pub fn execute(datasets: &Path, command: DatasetCommand) -> Result<()> {
    let archive = Archive::new(datasets);
    match command {
        DatasetCommand::Archive {
            run,
            variant,
            replicate,
            name,
            with_levels,
        } => archive_run(
            &archive,
            &run,
            variant.as_deref(),
            replicate,
            &name,
            with_levels,
        ),
        DatasetCommand::Import {
            name,
            source,
            citation,
            licence,
            licence_file,
            notes,
            tables,
        } => {
            let imported = ImportedSource {
                url: source,
                citation,
                licence,
                notes,
            };
            import(&archive, &name, imported, &licence_file, &tables)
        }
        DatasetCommand::List => {
            let catalog = archive.catalog()?;
            if catalog.datasets.is_empty() {
                println!("no datasets in {}", archive.dir().display());
            }
            for entry in &catalog.datasets {
                let roles: Vec<&str> = entry.files.iter().map(|f| f.role.as_str()).collect();
                let origin = match (&entry.provenance, &entry.source) {
                    (Some(p), _) => format!("{}/{}", p.experiment, p.variant),
                    (None, Some(s)) => format!("imported ({})", s.licence),
                    (None, None) => "(no origin recorded)".into(),
                };
                println!(
                    "{:<24} {}  {:>10}  {}  {}  [{}]",
                    entry.label(),
                    &entry.sha256[..12.min(entry.sha256.len())],
                    human_bytes(entry.bytes),
                    entry.created,
                    origin,
                    roles.join(", ")
                );
            }
            Ok(())
        }
        DatasetCommand::Show { dataset } => {
            let entry = archive.find(&dataset)?;
            print!("{}", show(&entry));
            Ok(())
        }
        DatasetCommand::Verify { dataset } => {
            let entries = match dataset {
                Some(reference) => vec![archive.find(&reference)?],
                None => archive.catalog()?.datasets,
            };
            let mut problems = Vec::new();
            for entry in &entries {
                let found = archive.verify(entry)?;
                if found.is_empty() {
                    println!("ok       {} ({} files)", entry.label(), entry.files.len());
                } else {
                    println!("DAMAGED  {}", entry.label());
                }
                problems.extend(found);
            }
            if problems.is_empty() {
                return Ok(());
            }
            let list: Vec<String> = problems.iter().map(ToString::to_string).collect();
            Err(Error::Corrupt(format!(
                "{} problem(s) in {}:\n  {}",
                problems.len(),
                archive.dir().display(),
                list.join("\n  ")
            )))
        }
        DatasetCommand::Restore { dataset, to } => {
            let entry = archive.find(&dataset)?;
            archive.restore(&entry, &to)?;
            for file in &entry.files {
                println!("{}", to.join(&file.name).display());
            }
            Ok(())
        }
        DatasetCommand::Remove {
            dataset,
            force,
            experiments,
        } => {
            let entry = archive.remove(&dataset, force, &experiments)?;
            println!("removed {}", entry.label());
            Ok(())
        }
    }
}

/// `alnlab dataset archive`: the chosen variant's data files of a run.
fn archive_run(
    archive: &Archive,
    run_dir: &Path,
    variant: Option<&str>,
    replicate: Option<u32>,
    name: &str,
    with_levels: bool,
) -> Result<()> {
    check_name(name)?;
    let record = read_record(run_dir)?;
    let roles: Vec<&str> = if with_levels {
        BASE_ROLES.iter().chain(&LEVEL_ROLES).copied().collect()
    } else {
        BASE_ROLES.to_vec()
    };
    let chosen = pick_variant(
        &record.variants,
        variant,
        replicate,
        &roles,
        run_dir,
        crate::records::Spelling::Cli,
    )?;
    let mut sources = Vec::new();
    for &role in &roles {
        let artifact = chosen.artifacts.get(role).ok_or_else(|| {
            Error::bad_file(
                &run_dir.join("run.json"),
                format!("variant `{}` has no `{role}` artifact", chosen.name),
            )
        })?;
        let path = PathBuf::from(&artifact.path);
        let file_name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| role.to_string());
        sources.push(Source {
            role: role.to_string(),
            name: file_name,
            path,
            sha256: Some(artifact.sha256.clone()),
        });
    }
    let provenance = DatasetProvenance {
        experiment: record.experiment.clone(),
        variant: chosen.name.clone(),
        manifest: record.manifest_path.clone(),
        manifest_sha256: record.manifest_sha256.clone(),
        replicate: Some(chosen.replicate.saturating_add(1)),
        // Records from before replicates had seeds of their own hold 0 here.
        seed: crate::manifest::replicate_seed(record.seed, chosen.replicate),
        alnlab_version: record.alnlab_version.clone(),
        git_commit: record.git_commit.clone().unwrap_or_default(),
    };
    let (entry, new) = archive.archive(name, &sources, Origin::Run(provenance))?;
    report_archived(&entry, new);
    Ok(())
}

/// `alnlab dataset import`: tables of a robot's samples, with their source
/// and licence.
fn import(
    archive: &Archive,
    name: &str,
    imported: ImportedSource,
    licence_file: &Path,
    tables: &[PathBuf],
) -> Result<()> {
    check_name(name)?;
    for (field, value) in [
        ("--source", &imported.url),
        ("--citation", &imported.citation),
        ("--licence", &imported.licence),
    ] {
        if value.trim().is_empty() {
            return Err(Error::Invalid(format!(
                "{field}: expected some text: recordings are kept only with their source, \
                 citation and licence"
            )));
        }
    }
    let mut sources = Vec::new();
    for path in tables {
        let file_name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        alnlab_ingest::table::Format::of(path)?;
        if sources.iter().any(|s: &Source| s.name == file_name) {
            return Err(Error::Invalid(format!(
                "two tables are named `{file_name}`: each keeps its file name in the archive"
            )));
        }
        sources.push(Source {
            role: TABLE_ROLE.into(),
            name: file_name,
            path: path.clone(),
            sha256: None,
        });
    }
    sources.push(Source {
        role: LICENCE_ROLE.into(),
        name: "LICENCE".into(),
        path: licence_file.to_path_buf(),
        sha256: None,
    });
    let (entry, new) = archive.archive(name, &sources, Origin::Imported(imported))?;
    report_archived(&entry, new);
    Ok(())
}

/// Says what archiving did.
fn report_archived(entry: &Entry, new: bool) {
    if new {
        println!(
            "archived {} ({}, sha256 {})",
            entry.label(),
            human_bytes(entry.bytes),
            entry.sha256
        );
    } else {
        println!("already archived as {} (nothing stored)", entry.label());
    }
}

/// A catalog entry for people.
fn show(entry: &Entry) -> String {
    let mut text = format!(
        "dataset     {}\nsha256      {}\ncreated     {}\nsize        {}\n",
        entry.label(),
        entry.sha256,
        entry.created,
        human_bytes(entry.bytes),
    );
    if let Some(s) = &entry.source {
        text.push_str(&format!(
            "source      {}\ncitation    {}\nlicence     {} (its text: the `{LICENCE_ROLE}` file)\n",
            s.url, s.citation, s.licence
        ));
        if !s.notes.is_empty() {
            text.push_str(&format!("notes       {}\n", s.notes));
        }
    }
    if let Some(p) = &entry.provenance {
        text.push_str(&provenance(p));
    }
    text.push_str("files:\n");
    for f in &entry.files {
        text.push_str(&format!(
            "  {:<11} {:<18} {:>10}  {}\n",
            f.role,
            f.name,
            human_bytes(f.bytes),
            f.sha256
        ));
    }
    text
}

/// The run a dataset was archived from, for people.
fn provenance(p: &DatasetProvenance) -> String {
    format!(
        "experiment  {} (variant {}{})\nmanifest    {} (sha256 {})\nseed        {}\n\
         alnlab      {}\ngit commit  {}\n",
        p.experiment,
        p.variant,
        p.replicate
            .map(|r| format!(", replicate {r}"))
            .unwrap_or_default(),
        p.manifest,
        p.manifest_sha256,
        p.seed,
        p.alnlab_version,
        if p.git_commit.is_empty() {
            "(not in a git checkout)"
        } else {
            &p.git_commit
        },
    )
}

/// "1.2 MiB".
fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 4] = ["B", "KiB", "MiB", "GiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}
