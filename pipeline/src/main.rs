//! The `alnlab` binary: parses the command line and maps errors to exit
//! codes (2 for what the user can fix, 1 otherwise).

use std::process::ExitCode;

fn main() -> ExitCode {
    let matches = alnlab::cli::command().get_matches();
    match alnlab::cli::execute(&matches) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
