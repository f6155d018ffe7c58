//! `alnlab <stage> …`: any stage of the stage table run alone on explicit
//! files, its parameters from a manifest. Every subcommand is made from the
//! table: an option per input role, `--out`, and for a stage that runs in
//! shards, `--shard K/N`. The files written are byte for byte those `alnlab
//! run` writes from the same inputs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use alnlab_aln::shard::Shard;
use alnlab_common::hash::sha256_file;
use alnlab_common::{Error, Provenance, Result, atomic};
use clap::{Arg, ArgMatches, value_parser};

use crate::manifest::Manifest;
use crate::progress::Bar;
use crate::stages::{Call, STAGES, Stage, stage_params};

/// The file an input role names, as its producing stage writes it.
fn file_of(role: &str, from: &str) -> &'static str {
    STAGES
        .iter()
        .filter(|s| s.name == from)
        .flat_map(|s| s.outputs)
        .find(|(r, _)| *r == role)
        .map_or("?", |(_, file)| file)
}

/// The subcommand's example: the quickstart manifest, and every input as
/// the producing stage alone would have written it under `/tmp/<stage>/`.
fn example(stage: &Stage) -> String {
    let mut args = vec!["--manifest experiments/quickstart.toml".to_string()];
    args.extend(
        stage
            .inputs
            .iter()
            .map(|i| format!("--{} /tmp/{}/{}", i.role, i.from, file_of(i.role, i.from))),
    );
    args.push(format!("--out /tmp/{}", stage.name));
    let lines: Vec<String> = args.chunks(2).map(|pair| pair.join(" ")).collect();
    format!(
        "Example:\n  alnlab {} {}",
        stage.name,
        lines.join(" \\\n      ")
    )
}

/// One subcommand per stage.
pub fn commands() -> Vec<clap::Command> {
    STAGES
        .iter()
        .map(|stage| {
            let outputs: Vec<&str> = stage.outputs.iter().map(|(_, file)| *file).collect();
            let mut command = clap::Command::new(stage.name)
                .about(stage.about)
                .after_help(example(stage))
                .arg(
                    Arg::new("manifest")
                        .long("manifest")
                        .value_name("FILE")
                        .required(true)
                        .value_parser(value_parser!(PathBuf))
                        .help("The experiment manifest holding the stage's parameters"),
                )
                .arg(
                    Arg::new("variant")
                        .long("variant")
                        .value_name("NAME")
                        .help("The variant whose parameters to use (default: the first)"),
                );
            for input in stage.inputs {
                command = command.arg(
                    Arg::new(input.role)
                        .long(input.role)
                        .value_name("FILE")
                        .required(true)
                        .value_parser(value_parser!(PathBuf))
                        .help(format!(
                            "The {} written by {}",
                            file_of(input.role, input.from),
                            input.from
                        )),
                );
            }
            command = command.arg(
                Arg::new("out")
                    .long("out")
                    .value_name("DIR")
                    .required(true)
                    .value_parser(value_parser!(PathBuf))
                    .help(format!("Folder to write {} into", outputs.join(", "))),
            );
            if stage.merge_shards.is_some() {
                command = command.arg(
                    Arg::new("shard")
                        .long("shard")
                        .value_name("K/N")
                        .value_parser(|s: &str| s.parse::<Shard>())
                        .help("Run only shard K of N: a partial output, for `alnlab merge-models`"),
                );
            }
            command
        })
        .collect()
}

/// Runs `stage` alone as `args` say: its parameters from the chosen variant
/// of the manifest, provenance from them and the inputs' hashes (as `alnlab
/// run` writes it, so the files are the same), then names the files written.
/// The outputs appear together when the stage succeeds, or not at all.
pub fn execute(stage: &'static Stage, args: &ArgMatches, quiet: bool) -> Result<()> {
    let path = |id: &str| -> &Path { args.get_one::<PathBuf>(id).expect("required") };
    let manifest = Manifest::load(path("manifest"))?;
    let variant = match args.get_one::<String>("variant") {
        Some(name) => manifest.variant(name)?,
        None => &manifest.variants[0],
    };
    let seed = manifest.experiment.seed;
    let inputs: BTreeMap<&'static str, PathBuf> = stage
        .inputs
        .iter()
        .map(|i| (i.role, path(i.role).to_path_buf()))
        .collect();
    let provenance = Provenance {
        stage: stage.name.into(),
        params: stage_params(seed, (stage.params)(&variant.stages)),
        inputs: inputs
            .iter()
            .map(|(role, path)| Ok((role.to_string(), sha256_file(path)?)))
            .collect::<Result<_>>()?,
    };
    let out = path("out");
    let shard = args
        .try_get_one::<Shard>("shard")
        .ok()
        .flatten()
        .copied()
        .unwrap_or(Shard::ALL);
    crate::stages::refuse_sharded_piecewise(&variant.stages, shard, "--shard")?;
    // The stage writes into a hidden folder inside `out`; its files move
    // into `out` only when it has finished, so a failure leaves none.
    atomic::create_dir(out)?;
    let staging = atomic::temporary_name(&out.join(stage.name));
    let result = atomic::create_dir(&staging)
        .and_then(|()| {
            (stage.run)(&Call {
                stages: &variant.stages,
                seed,
                inputs,
                shard,
                provenance: &provenance,
                out_dir: &staging,
                progress: &Bar::new(stage.name, quiet),
            })
        })
        .and_then(|()| {
            for (_, file) in stage.outputs {
                let target = out.join(file);
                std::fs::rename(staging.join(file), &target).map_err(|e| Error::io(&target, e))?;
            }
            Ok(())
        });
    let _ = std::fs::remove_dir_all(&staging);
    result?;
    for (_, file) in stage.outputs {
        println!("wrote {}", out.join(file).display());
    }
    Ok(())
}
