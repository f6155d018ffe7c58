//! The external programs: Yosys (synthesis), Icarus Verilog (`iverilog`,
//! `vvp`: simulation), Verilator (fast simulation of mapped netlists, which
//! runs make and a C++ compiler) and nextpnr-ice40 (place and route). A
//! missing program is an error that says how to install it; a failing one,
//! an error with the end of what it printed. Each is started so that it
//! ends with alnlab, the programs it starts with it: killed, alnlab leaves
//! nothing running on.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use alnlab_common::{Error, Result};

/// How to install `program`, for error messages.
fn install(program: &str) -> &'static str {
    if program.starts_with("nextpnr") {
        "place and route needs nextpnr-ice40 on PATH (Debian, Ubuntu: `apt-get install \
         nextpnr-ice40`)"
    } else if program == "verilator" {
        "simulating a mapped netlist needs Verilator, make and a C++ compiler on PATH (Debian, \
         Ubuntu: `apt-get install verilator make g++`)"
    } else {
        "the circuit check needs Yosys and Icarus Verilog on PATH (Debian, Ubuntu: `apt-get \
         install yosys iverilog`)"
    }
}

/// The exit status coreutils' `timeout` gives when it could not start its
/// command: not found.
#[cfg(target_os = "linux")]
const NOT_FOUND: i32 = 127;

/// A command for `program` working in `dir`, its own temporary files
/// (Yosys' for ABC) there too, that ends with alnlab (Linux; elsewhere a
/// tool runs on to its end). Some programs start others — Yosys runs ABC,
/// Verilator make and the compiler — which a signal to the program alone
/// would orphan; so the program runs under coreutils' `timeout` (with no
/// limit), which puts it in a process group of its own and passes a
/// termination on to the whole group, killing what is left a second
/// later. The kernel sends `timeout` that termination when the thread that
/// started it ends — alnlab's threads live as long as alnlab.
fn command(program: &str, dir: &Path) -> Command {
    #[cfg(target_os = "linux")]
    let mut command = {
        use std::os::unix::process::CommandExt;
        let mut command = Command::new("timeout");
        command.args(["--kill-after=1", "0", program]);
        let parent = std::process::id() as libc::pid_t;
        // SAFETY: between fork and exec the closure calls only prctl,
        // getppid and _exit, which are async-signal-safe, and allocates
        // nothing.
        unsafe {
            command.pre_exec(move || {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                // alnlab died before the signal was asked for.
                if libc::getppid() != parent {
                    libc::_exit(1);
                }
                Ok(())
            });
        }
        command
    };
    #[cfg(not(target_os = "linux"))]
    let mut command = Command::new(program);
    command.current_dir(dir).env("TMPDIR", dir);
    command
}

/// Stops `child` (a [`command`]) and everything it started, and reaps it.
fn stop(child: &mut Child) {
    #[cfg(target_os = "linux")]
    {
        // `timeout` leads its own process group: its id is the group's.
        // SAFETY: killpg only sends a signal.
        unsafe {
            libc::killpg(child.id() as libc::pid_t, libc::SIGKILL);
        }
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Whether `status` says `program` (run by [`command`]) was not found.
fn not_found(status: std::process::ExitStatus) -> bool {
    #[cfg(target_os = "linux")]
    return status.code() == Some(NOT_FOUND);
    #[cfg(not(target_os = "linux"))]
    {
        let _ = status;
        false
    }
}

/// The error for a `program` that was not found: how to install it.
fn missing(program: &str) -> Error {
    Error::Invalid(format!("`{program}` was not found: {}", install(program)))
}

/// Runs `program` with `args` in `dir` to its end; a missing program is an
/// error that says how to install it.
fn spawn(program: &str, args: &[&str], dir: &Path) -> Result<Output> {
    let output = command(program, dir)
        .args(args)
        .output()
        .map_err(|e| not_started(program, e))?;
    if not_found(output.status) {
        return Err(missing(program));
    }
    Ok(output)
}

/// Why `program` did not start: missing (and how to install it), or else.
fn not_started(program: &str, e: std::io::Error) -> Error {
    match e.kind() {
        std::io::ErrorKind::NotFound => missing(program),
        _ => Error::io(Path::new(program), e),
    }
}

/// The error of `program`, which `ended` so (failed with a status, or did
/// not finish), quoting the end of what it `said`.
fn failed(program: &str, args: &[&str], dir: &Path, ended: &str, said: &str) -> Error {
    let tail: Vec<&str> = said.lines().rev().take(12).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    Error::Corrupt(format!(
        "`{program} {}` in {} {ended}:\n{}",
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
        let ended = format!("failed ({})", output.status);
        return Err(failed(program, args, dir, &ended, &said));
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

/// How a program run for a limited time ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ended {
    /// It finished, successfully.
    Finished,
    /// It was still running at the limit, and was stopped.
    Stopped,
}

/// Runs `program` with `args` in `dir` for at most `limit`, both its
/// streams into the file `log` there; past the limit it is stopped
/// ([`Ended::Stopped`]). A failure is an error with the end of its log
/// (which lives in `dir`).
pub fn run_for(
    program: &str,
    args: &[&str],
    dir: &Path,
    log: &str,
    limit: Duration,
) -> Result<Ended> {
    let path = dir.join(log);
    let file = File::create(&path).map_err(|e| Error::io(&path, e))?;
    let copy = file.try_clone().map_err(|e| Error::io(&path, e))?;
    let mut child = command(program, dir)
        .args(args)
        .stdin(Stdio::null())
        .stdout(copy)
        .stderr(file)
        .spawn()
        .map_err(|e| not_started(program, e))?;
    let start = Instant::now();
    let waited = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Ok(Some(status)),
            Ok(None) if start.elapsed() <= limit => std::thread::sleep(Duration::from_millis(20)),
            Ok(None) => break Ok(None),
            Err(e) => break Err(format!("could not be waited for ({e})")),
        }
    };
    let said = || std::fs::read_to_string(&path).unwrap_or_default();
    match waited {
        Ok(Some(status)) if status.success() => Ok(Ended::Finished),
        Ok(Some(status)) if not_found(status) => Err(missing(program)),
        Ok(None) => {
            stop(&mut child);
            Ok(Ended::Stopped)
        }
        Ok(Some(status)) => Err(failed(
            program,
            args,
            dir,
            &format!("failed ({status})"),
            &said(),
        )),
        Err(why) => {
            // Stopped and reaped whatever it was doing (an error here means
            // it has ended already).
            stop(&mut child);
            Err(failed(program, args, dir, &why, &said()))
        }
    }
}

/// A file of Yosys' data folder (its scripts' `+/`, which holds e.g. the
/// iCE40 cells' simulation models), found where Yosys itself looks:
/// `share/` or `../share/yosys/` beside its own executable, the `yosys` on
/// PATH with links resolved. (`yosys-config --datdir` would say it, but
/// Debian ships that in `yosys-dev`, not with Yosys.)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_program_past_its_limit_is_stopped_and_a_failing_one_quoted() {
        let dir = tempfile::tempdir().unwrap();
        let start = Instant::now();
        let ended = run_for(
            "sleep",
            &["30"],
            dir.path(),
            "s.log",
            Duration::from_millis(200),
        )
        .unwrap();
        assert_eq!(ended, Ended::Stopped);
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "stopped, not waited for"
        );
        let error = run_for(
            "sh",
            &["-c", "echo placing; echo no room >&2; exit 3"],
            dir.path(),
            "f.log",
            Duration::from_secs(30),
        )
        .unwrap_err()
        .to_string();
        assert!(error.contains("failed (exit status: 3)"), "{error}");
        assert!(
            error.contains("placing\nno room"),
            "both streams, in order: {error}"
        );
        let ended = run_for("true", &[], dir.path(), "t.log", Duration::from_secs(30)).unwrap();
        assert_eq!(ended, Ended::Finished);
        let error = run_for(
            "no-such-tool",
            &[],
            dir.path(),
            "n.log",
            Duration::from_secs(1),
        )
        .unwrap_err()
        .to_string();
        assert!(error.contains("`no-such-tool` was not found"), "{error}");
        let error = run("no-such-tool", &[], dir.path())
            .unwrap_err()
            .to_string();
        assert!(error.contains("`no-such-tool` was not found"), "{error}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_program_stopped_at_its_limit_takes_what_it_started_with_it() {
        let dir = tempfile::tempdir().unwrap();
        let ended = run_for(
            "sh",
            &["-c", "sleep 30 & echo $! > started; sleep 30"],
            dir.path(),
            "s.log",
            Duration::from_millis(300),
        )
        .unwrap();
        assert_eq!(ended, Ended::Stopped);
        let started = std::fs::read_to_string(dir.path().join("started")).unwrap();
        let proc = Path::new("/proc").join(started.trim());
        let start = Instant::now();
        // Gone, or a zombie until init reaps it.
        let alive = || {
            std::fs::read_to_string(proc.join("stat"))
                .is_ok_and(|stat| !stat.split(") ").nth(1).unwrap_or("").starts_with('Z'))
        };
        while alive() && start.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(!alive(), "the program's own child ran on");
    }
}
