//! The external programs: Yosys (synthesis), Icarus Verilog (`iverilog`,
//! `vvp`: simulation) and nextpnr-ice40 (place and route). A missing
//! program is an error that says how to install it; a failing one, an error
//! with the end of what it printed.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Output};
use std::time::{Duration, Instant};

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
        .map_err(|e| not_started(program, e))
}

/// Why `program` did not start: missing (and how to install it), or else.
fn not_started(program: &str, e: std::io::Error) -> Error {
    match e.kind() {
        std::io::ErrorKind::NotFound => {
            Error::Invalid(format!("`{program}` was not found: {}", install(program)))
        }
        _ => Error::io(Path::new(program), e),
    }
}

/// The error of `program` ended with `status`, quoting the end of what it
/// `said`.
fn failed(program: &str, args: &[&str], dir: &Path, status: ExitStatus, said: &str) -> Error {
    let tail: Vec<&str> = said.lines().rev().take(12).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    Error::Corrupt(format!(
        "`{program} {}` in {} failed ({status}):\n{}",
        args.join(" "),
        dir.display(),
        tail.join("\n")
    ))
}

/// Runs `program` with `args` in `dir`; its standard output on success.
pub fn run(program: &str, args: &[&str], dir: &Path) -> Result<String> {
    let output = spawn(program, args, dir)?;
    if !output.status.success() {
        let mut said = String::from_utf8_lossy(&output.stdout).into_owned();
        said.push_str(&String::from_utf8_lossy(&output.stderr));
        return Err(failed(program, args, dir, output.status, &said));
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

/// Runs `program` with `args` in `dir` for at most `limit`, both its
/// streams into the file `log` there; past the limit it is stopped, and
/// that is the error.
pub fn run_for(program: &str, args: &[&str], dir: &Path, log: &str, limit: Duration) -> Result<()> {
    let path = dir.join(log);
    let file = File::create(&path).map_err(|e| Error::io(&path, e))?;
    let copy = file.try_clone().map_err(|e| Error::io(&path, e))?;
    let mut child = Command::new(program)
        .args(args)
        .current_dir(dir)
        .stdout(copy)
        .stderr(file)
        .spawn()
        .map_err(|e| not_started(program, e))?;
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child
            .try_wait()
            .map_err(|e| Error::io(Path::new(program), e))?
        {
            break status;
        }
        if start.elapsed() > limit {
            // Already ended or killed: either way it is reaped below.
            let _ = child.kill();
            let _ = child.wait();
            return Err(Error::Corrupt(format!(
                "`{program} {}` in {} did not finish in {} s",
                args.join(" "),
                dir.display(),
                limit.as_secs()
            )));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    if !status.success() {
        let said = std::fs::read_to_string(&path).unwrap_or_default();
        return Err(failed(program, args, dir, status, &said));
    }
    Ok(())
}

/// A file of Yosys' data folder (its scripts' `+/`, which holds e.g. the
/// iCE40 cells' simulation models), found where Yosys itself looks:
/// `share/` or `../share/yosys/` beside its own executable, the `yosys` on
/// PATH with links resolved.
pub fn yosys_data(file: &str) -> Result<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    let exe = std::env::split_paths(&path)
        .map(|dir| dir.join("yosys"))
        .find(|p| p.is_file())
        .ok_or_else(|| Error::Invalid(format!("`yosys` was not found: {}", install("yosys"))))?;
    let exe = std::fs::canonicalize(&exe).map_err(|e| Error::io(&exe, e))?;
    let bin = exe.parent().unwrap_or(Path::new("/"));
    let candidates = [
        bin.join("share").join(file),
        bin.join("../share/yosys").join(file),
    ];
    candidates
        .iter()
        .find(|p| p.is_file())
        .cloned()
        .ok_or_else(|| {
            Error::Invalid(format!(
                "Yosys' data file `{file}` is in neither {} nor {}: is Yosys installed whole?",
                candidates[0].display(),
                candidates[1].display()
            ))
        })
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
