//! The project's own commands, by the xtask convention of Rust workspaces
//! (`cargo xtask …`, an alias in `.cargo/config.toml`):
//!
//! - `cargo xtask test` — the README's test command: installs what the
//!   suite needs and the machine lacks ([`setup`]: Debian packages, a Python
//!   environment of its own), then runs the whole suite ([`suite`]): `cargo
//!   test --workspace -- --include-ignored` (the fast tier and the tests it
//!   leaves out: circuits placed and routed on an iCE40 among them), the
//!   interop check with standard readers, the Python package, robots
//!   against Pinocchio, the MLflow round trip against a real server on
//!   loopback and the Snakemake workflow.
//! - `cargo xtask setup` — only the installing.

mod setup;
mod suite;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The project's own commands: set a machine up, run the whole test suite.
#[derive(Debug, Parser)]
#[command(
    name = "cargo xtask",
    bin_name = "cargo xtask",
    after_help = "Examples:
  cargo xtask test                 # install what is missing, then the whole suite
  cargo xtask test --no-install    # the same on a machine set up by hand: name what is missing
  cargo xtask setup                # only install (Debian packages, target/xtask/venv)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Install what the suite needs and is missing, then run the whole
    /// suite: `cargo test`, then two lanes of steps side by side, each
    /// stopping at its first step that fails.
    ///
    /// Debian packages (yosys, iverilog, chromium) are installed with
    /// apt-get when this runs as root; otherwise a missing one stops the
    /// command with the line that installs it. The Python packages of
    /// `xtask/requirements.txt` go into `target/xtask/venv`, reinstalled
    /// when the file changes. Everything the suite writes stays under
    /// `target/`, so the checkout stays clean.
    #[command(after_help = "Examples:
  cargo xtask test
  cargo xtask test --no-install")]
    Test {
        /// Install nothing: check the machine and name what is missing.
        #[arg(long)]
        no_install: bool,
    },
    /// Install what the suite needs and is missing, and nothing else.
    #[command(after_help = "Example:
  cargo xtask setup    # then target/xtask/venv/bin/python has the interop readers")]
    Setup {
        /// Install nothing: check the machine and name what is missing.
        #[arg(long)]
        no_install: bool,
    },
}

/// Why the command stopped.
#[derive(Debug)]
pub enum Failure {
    /// The machine lacks something this command may not or cannot install
    /// (exit 2): the message names it and how to get it.
    Missing(String),
    /// A step of the suite failed (exit 1).
    Step(String),
}

/// The workspace's root folder (the parent of this crate's).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

/// The folder of cargo's build output, where this command keeps its own
/// (`xtask/`): `CARGO_TARGET_DIR` when set.
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root().join("target"), PathBuf::from)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Test { no_install } => {
            setup::machine(!no_install).and_then(|python| suite::run(&python))
        }
        Command::Setup { no_install } => setup::machine(!no_install).map(|python| {
            println!("ready: {}", python.display());
        }),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Missing(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(2)
        }
        Err(Failure::Step(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(1)
        }
    }
}
