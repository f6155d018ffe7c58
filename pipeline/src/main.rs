//! The `alnlab` binary: parses the command line and maps errors to exit
//! codes (2 for what the user can fix, 1 otherwise).

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = alnlab::cli::Cli::parse();
    match alnlab::cli::execute(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
