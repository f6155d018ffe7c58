//! The external programs: Yosys (synthesis), Icarus Verilog (`iverilog`,
//! `vvp`: simulation) and nextpnr-ice40 (place and route). A missing
//! program is an error that says how to install it; a failing one, an error
//! with the end of what it printed.

use std::path::Path;
use std::process::{Command, Output};

use alnlab_common::{Error, Result};

/// How to install `program`, for error messages.
fn install(program: &str) -> &'static str {
    if program.starts_with("nextpnr") {
        "place and route needs nextpnr-ice40 on PATH (Debian, Ubuntu: `apt-get install \
         nextpnr-ice40`)"
    } else {
        "the circuit check needs Yosys and Icarus Verilog on PATH (Debian, Ubuntu: `apt-get \
         install yosys iverilog`)"
    }
}

/// Runs `program` with `args` in `dir` to its end; a missing program is an
/// error that says how to install it.
fn spawn(program: &str, args: &[&str], dir: &Path) -> Result<Output> {
    Command::new(program)
        .args(args)
        .current_dir(dir)
        .output()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => {
                Error::Invalid(format!("`{program}` was not found: {}", install(program)))
            }
            _ => Error::io(Path::new(program), e),
        })
}

/// Runs `program` with `args` in `dir`; its standard output on success.
pub fn run(program: &str, args: &[&str], dir: &Path) -> Result<String> {
    let output = spawn(program, args, dir)?;
    if !output.status.success() {
        let mut said = String::from_utf8_lossy(&output.stdout).into_owned();
        said.push_str(&String::from_utf8_lossy(&output.stderr));
        let tail: Vec<&str> = said.lines().rev().take(12).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        return Err(Error::Corrupt(format!(
            "`{program} {}` in {} failed ({}):\n{}",
            args.join(" "),
            dir.display(),
            output.status,
            tail.join("\n")
        )));
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

/// The first line `program` prints, on either stream, given `--version`.
pub fn version(program: &str) -> Result<String> {
    let output = spawn(program, &["--version"], Path::new("."))?;
    let mut said = String::from_utf8_lossy(&output.stdout).into_owned();
    said.push_str(&String::from_utf8_lossy(&output.stderr));
    Ok(said.lines().next().unwrap_or("").trim().to_string())
}

/// The versions of Yosys and Icarus Verilog, as they print them (their
/// figures depend on them); an error when either is missing.
pub fn versions() -> Result<String> {
    let here = Path::new(".");
    let yosys = run("yosys", &["-V"], here)?;
    let iverilog = run("iverilog", &["-V"], here)?;
    Ok(format!(
        "{}; {}",
        yosys.trim(),
        iverilog.lines().next().unwrap_or("").trim()
    ))
}
