//! The `alnlab` binary: parses the command line and maps errors to exit
//! codes (2 for what the user can fix, 1 otherwise).

use std::process::ExitCode;

fn main() -> ExitCode {
    end_quietly_on_a_closed_pipe();
    let matches = alnlab::cli::command().get_matches();
    match alnlab::cli::execute(&matches) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

/// A reader that goes away (`alnlab check M | head`) ends the program as it
/// ends every Unix tool: by SIGPIPE, quietly. Rust ignores the signal, so
/// that a write fails instead and `println!` panics. The tools alnlab
/// starts get no input from it, and its sockets write with MSG_NOSIGNAL,
/// so only stdout and stderr can raise it.
fn end_quietly_on_a_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: called first thing, before any thread exists; SIG_DFL is a
    // valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
