//! What the suite needs from outside Rust, found or installed: programs
//! from Debian's packages, and a Python environment of its own for the
//! interop readers, MLflow and Snakemake.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::{Failure, root, target_dir};

/// A program the suite runs (or, given by an absolute path, a file it
/// compiles against), and the Debian package that has it.
struct Program {
    command: &'static str,
    package: &'static str,
    /// What needs it, for the message when it is missing.
    needed_by: &'static str,
}

/// Every outside program the suite runs.
const PROGRAMS: &[Program] = &[
    Program {
        command: "yosys",
        package: "yosys",
        needed_by: "for the circuit stage's synthesis",
    },
    Program {
        command: "iverilog",
        package: "iverilog",
        needed_by: "for the circuit stage's simulation",
    },
    Program {
        command: "vvp",
        package: "iverilog",
        needed_by: "for the circuit stage's simulation",
    },
    Program {
        command: "nextpnr-ice40",
        package: "nextpnr-ice40",
        needed_by: "for placing and routing circuits on an FPGA",
    },
    Program {
        command: "verilator",
        package: "verilator",
        needed_by: "for simulating mapped netlists of piecewise-linear circuits",
    },
    Program {
        command: "make",
        package: "make",
        needed_by: "for Verilator's builds",
    },
    Program {
        command: "chromium",
        package: "chromium",
        needed_by: "for the reports test, a headless browser",
    },
    Program {
        command: "python3",
        package: "python3",
        needed_by: "for the interop check, MLflow and Snakemake",
    },
    Program {
        command: "g++",
        package: "g++",
        needed_by: "to build the Pinocchio harness of `alnlab bench sim`",
    },
    Program {
        command: "/usr/include/eigen3/Eigen/Core",
        package: "libeigen3-dev",
        needed_by: "to build the Pinocchio harness of `alnlab bench sim`",
    },
    Program {
        command: "/usr/include/urdf_model/model.h",
        package: "liburdfdom-headers-dev",
        needed_by: "to build the Pinocchio harness of `alnlab bench sim`",
    },
];

/// Sets the machine up (`install`: with apt-get where it may) and returns
/// the Python interpreter of the suite's environment.
pub fn machine(install: bool) -> Result<PathBuf, Failure> {
    programs(install)?;
    python_environment(install)
}

/// Every program on PATH, installing the missing ones' packages when
/// allowed and possible.
fn programs(install: bool) -> Result<(), Failure> {
    let missing: Vec<&Program> = PROGRAMS.iter().filter(|p| !on_path(p.command)).collect();
    let mut packages: Vec<&str> = Vec::new();
    for p in &missing {
        // Several programs can come in one package (iverilog, vvp).
        if !packages.contains(&p.package) {
            packages.push(p.package);
        }
    }
    // Debian's python3 comes without venv; the environment needs it.
    if on_path("python3") && !python_has_venv() {
        packages.push("python3-venv");
    }
    if packages.is_empty() {
        return Ok(());
    }
    let what: Vec<String> = missing
        .iter()
        .map(|p| format!("`{}` {}", p.command, p.needed_by))
        .collect();
    let what = if what.is_empty() {
        "Python's venv module, for the suite's Python environment".to_string()
    } else {
        what.join(", ")
    };
    let line = format!("apt-get install {}", packages.join(" "));
    if !install {
        return Err(Failure::Missing(format!(
            "missing: {what}; install them with `{line}` (Debian, Ubuntu)"
        )));
    }
    if !on_path("apt-get") {
        return Err(Failure::Missing(format!(
            "missing: {what}, and this machine has no apt-get to install Debian's packages \
             ({}): install them with its own package manager",
            packages.join(", ")
        )));
    }
    if !is_root() {
        return Err(Failure::Missing(format!(
            "missing: {what}; installing Debian's packages needs root: run `sudo {line}`, \
             then this command again"
        )));
    }
    println!("== installing Debian's {} (apt-get)", packages.join(", "));
    let log = target_dir().join("xtask/apt.log");
    quiet(
        Command::new("apt-get").args(["update", "-qq"]),
        &log,
        "apt-get update",
    )?;
    quiet(
        Command::new("apt-get")
            .args(["install", "-y", "-qq"])
            .args(&packages)
            .env("DEBIAN_FRONTEND", "noninteractive"),
        &log,
        &line,
    )?;
    let still: Vec<&str> = missing
        .iter()
        .filter(|p| !on_path(p.command))
        .map(|p| p.command)
        .collect();
    if !still.is_empty() {
        return Err(Failure::Missing(format!(
            "`{line}` succeeded but {} still not on PATH",
            still.join(", ")
        )));
    }
    Ok(())
}

/// The suite's Python environment (`target/xtask/venv`), made and filled
/// from `xtask/requirements.txt` unless it holds that file's packages
/// already; its interpreter.
fn python_environment(install: bool) -> Result<PathBuf, Failure> {
    let venv = target_dir().join("xtask/venv");
    let python = venv.join("bin/python");
    let requirements = root().join("xtask/requirements.txt");
    let wanted = std::fs::read_to_string(&requirements)
        .map_err(|e| Failure::Missing(format!("{}: {e}", requirements.display())))?;
    // The requirements the environment was filled from, kept beside it.
    let stamp = venv.join("alnlab-requirements.txt");
    if python.is_file() && std::fs::read_to_string(&stamp).ok().as_deref() == Some(&wanted) {
        return Ok(python);
    }
    let pip_line = format!(
        "{} -m pip install -r {}",
        python.display(),
        requirements.display()
    );
    if !install {
        return Err(Failure::Missing(format!(
            "the suite's Python environment {} is missing or out of date: run `cargo xtask \
             setup`, or `python3 -m venv {}` and `{pip_line}`",
            venv.display(),
            venv.display()
        )));
    }
    println!(
        "== the Python environment: {} from {}",
        venv.display(),
        requirements.display()
    );
    let log = target_dir().join("xtask/pip.log");
    if !python.is_file() {
        quiet(
            Command::new("python3").arg("-m").arg("venv").arg(&venv),
            &log,
            &format!("python3 -m venv {}", venv.display()),
        )?;
    }
    quiet(
        Command::new(&python)
            .args(["-m", "pip", "install", "--disable-pip-version-check", "-r"])
            .arg(&requirements),
        &log,
        &pip_line,
    )?;
    std::fs::write(&stamp, wanted)
        .map_err(|e| Failure::Step(format!("{}: {e}", stamp.display())))?;
    Ok(python)
}

/// Whether `command` is an executable file in a folder of PATH.
fn on_path(command: &str) -> bool {
    use std::os::unix::fs::PermissionsExt;
    if command.starts_with('/') {
        return Path::new(command).is_file();
    }
    std::env::var_os("PATH").is_some_and(|path| {
        std::env::split_paths(&path).any(|dir| {
            std::fs::metadata(dir.join(command))
                .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        })
    })
}

fn python_has_venv() -> bool {
    Command::new("python3")
        .args(["-c", "import venv, ensurepip"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| o.stdout.trim_ascii() == b"0")
}

/// Runs an installing command with its output appended to `log`; on
/// failure, the end of that output and the log's path.
fn quiet(command: &mut Command, log: &Path, line: &str) -> Result<(), Failure> {
    let output = command
        .output()
        .map_err(|e| Failure::Missing(format!("`{line}` could not start: {e}")))?;
    if let Some(folder) = log.parent() {
        let _ = std::fs::create_dir_all(folder);
    }
    let mut said = output.stdout;
    said.extend_from_slice(&output.stderr);
    let _ = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .and_then(|mut file| std::io::Write::write_all(&mut file, &said));
    if output.status.success() {
        return Ok(());
    }
    let said = String::from_utf8_lossy(&said);
    let tail: Vec<&str> = said.lines().rev().take(15).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    Err(Failure::Missing(format!(
        "`{line}` failed ({}); the end of what it said (all of it in {}):\n{}",
        output.status,
        log.display(),
        tail.join("\n")
    )))
}
