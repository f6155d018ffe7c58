//! The whole suite: what `cargo test` covers, then what needs the real
//! binary and outside programs together, in two lanes side by side — on the
//! quickstart's runs, standard readers, the Python package, a real MLflow
//! server and a real Snakemake workflow; and the robots against Pinocchio.
//! (Circuits on an FPGA are `cargo test`'s: `tests/circuit.rs`.) Every step
//! writes under `target/xtask/`.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::{Failure, root, target_dir};

/// What the steps share: the interpreter of the suite's environment, where
/// their files go, and where their programs' output goes.
struct Suite {
    python: PathBuf,
    /// `target/xtask`.
    work: PathBuf,
    /// The file a lane's programs write to (stdout and stderr), or `None`
    /// for the terminal's.
    log: Option<PathBuf>,
}

/// One step: its name and what it does.
type Step = (&'static str, fn(&Suite) -> Result<(), String>);

/// The first step: it builds the binary every later step runs.
const FIRST: Step = ("cargo test --workspace -- --include-ignored", cargo_test);

/// The steps on the quickstart's runs, in order: each reads what the one
/// before left in the suite's runs folder.
const QUICKSTART_LANE: &[Step] = &[
    (
        "the quickstart (three replicates) read by standard readers, its figures recomputed",
        quickstart_interop,
    ),
    (
        "the Python package: built into the suite's environment, its stubs checked by mypy's \
         stubtest, tested by pytest on the quickstart's models, its rollout benchmark and MPC \
         example run once",
        python_package,
    ),
    (
        "MLflow: runs exported to a real server and read back",
        mlflow_round_trip,
    ),
    // After MLflow, which checks every record of the suite's runs folder:
    // `bench cache` adds one of its own there.
    (
        "every other alnlab bench subcommand once, on the quickstart where it takes a run",
        every_bench,
    ),
    (
        "Snakemake: the exported workflow, sharded, failing, resumed",
        snakemake,
    ),
];

/// The robots' steps: they share nothing with the quickstart's, and run
/// beside them — half of their time is one compiler building the
/// Pinocchio harness and Python on one core, which would leave the
/// machine's second core idle.
const ROBOT_LANE: &[Step] = &[
    (
        "robots from URDF: fourteen robots' logs against Pinocchio, and bench sim beside it",
        robots_against_pinocchio,
    ),
    (
        "hard cases: every robot of example-robot-data at 1 ms under both integrators, \
         the implicit runs against Pinocchio",
        hard_cases,
    ),
    (
        "a real arm's URDF against its recordings: kuka-lwr4's torques, joint by joint",
        real_arm_physics,
    ),
];

/// What one lane did: each step's name and wall time, and the first
/// failure, which ends the lane.
#[derive(Default)]
struct Lane {
    times: Vec<(&'static str, Duration)>,
    failure: Option<String>,
}

impl Lane {
    /// Runs `steps` in order, stopping at the first that fails; each
    /// step's name is printed (to the lane's log, when it has one) as it
    /// starts.
    fn run(suite: &Suite, steps: &[Step]) -> Lane {
        let mut lane = Lane::default();
        for (name, step) in steps {
            suite.say(&format!("== {name}"));
            let start = Instant::now();
            let result = step(suite);
            lane.times.push((*name, start.elapsed()));
            if let Err(message) = result {
                lane.failure = Some(format!("{name}: {message}"));
                break;
            }
        }
        lane
    }
}

/// Runs the first step, then the two lanes side by side — the robots'
/// output kept in `target/xtask/robots.log` and printed when its lane
/// ends —, stopping each lane at its first failing step; prints each
/// step's wall time, then a closing line of passed and failed steps.
pub fn run(python: &Path) -> Result<(), Failure> {
    let suite = Suite {
        python: python.to_path_buf(),
        work: target_dir().join("xtask"),
        log: None,
    };
    let marker = format!("{}-{}", std::process::id(), unix_nanos());
    // SAFETY: the suite has started no thread yet, so nothing reads the
    // environment while it changes; every process the steps start, and
    // theirs, inherit the marker.
    unsafe { std::env::set_var(MARKER, &marker) };
    // The Python scripts import each other from tests/: no bytecode is
    // written beside them, so the checkout stays clean.
    // SAFETY: as above.
    unsafe { std::env::set_var("PYTHONDONTWRITEBYTECODE", "1") };
    let start = Instant::now();
    let mut lanes = vec![Lane::run(&suite, &[FIRST])];
    if lanes[0].failure.is_none() {
        let robots = Suite {
            python: python.to_path_buf(),
            work: suite.work.clone(),
            log: Some(suite.work.join("robots.log")),
        };
        let (quickstart, robot) = std::thread::scope(|s| {
            let robot = s.spawn(|| robots.start_log().map(|()| Lane::run(&robots, ROBOT_LANE)));
            let quickstart = Lane::run(&suite, QUICKSTART_LANE);
            (
                quickstart,
                robot.join().expect("the robots' lane does not panic"),
            )
        });
        let log = robots.log.as_deref().expect("the robots' lane has a log");
        println!(
            "\n== the robots' lane, beside the quickstart's ({}):",
            log.display()
        );
        print!("{}", std::fs::read_to_string(log).unwrap_or_default());
        lanes.push(quickstart);
        lanes.push(robot.unwrap_or_else(|e| Lane {
            failure: Some(e),
            ..Lane::default()
        }));
    }
    // Whatever a step left behind (a server's child, a stray run) is found
    // by the marker it inherited, even when the step failed.
    let left = nothing_left_running(&marker, Duration::from_secs(10));
    println!("\nwall time per step (the last two lanes side by side):");
    for lane in &lanes {
        for (name, time) in &lane.times {
            println!("  {:>7.1} s  {name}", time.as_secs_f64());
        }
    }
    println!("  {:>7.1} s  in all", start.elapsed().as_secs_f64());
    let ran: usize = lanes.iter().map(|l| l.times.len()).sum();
    let mut failures: Vec<String> = lanes.into_iter().filter_map(|l| l.failure).collect();
    println!(
        "steps: {} passed, {} failed",
        ran - failures.len(),
        failures.len()
    );
    match left {
        Ok(true) => println!("left running: nothing"),
        Ok(false) => println!("left running: unchecked (no /proc to read environments from)"),
        Err(message) => {
            println!("left running: {message}");
            failures.push(message);
        }
    }
    match failures.is_empty() {
        true => Ok(()),
        false => Err(Failure::Step(failures.join("; "))),
    }
}

impl Suite {
    /// Starts the lane's log afresh.
    fn start_log(&self) -> Result<(), String> {
        match &self.log {
            Some(log) => std::fs::create_dir_all(&self.work)
                .and_then(|()| std::fs::write(log, ""))
                .map_err(|e| format!("{}: {e}", log.display())),
            None => Ok(()),
        }
    }

    /// Prints `line` to the terminal, or appends it to the lane's log.
    fn say(&self, line: &str) {
        match &self.log {
            Some(log) => {
                if let Err(e) = append_to(log).and_then(|mut f| {
                    writeln!(f, "{line}").map_err(|e| format!("{}: {e}", log.display()))
                }) {
                    eprintln!("{e}");
                }
            }
            None => println!("{line}"),
        }
    }

    /// Runs `command` in the workspace's root, its output passed through to
    /// the terminal or appended to the lane's log; an error names the
    /// command and its exit status.
    fn run(&self, command: &mut Command) -> Result<(), String> {
        if let Some(log) = &self.log {
            command.stdout(append_to(log)?).stderr(append_to(log)?);
        }
        run_in_root(command)
    }
}

/// The lane's `log`, opened to append to; an error names it.
fn append_to(log: &Path) -> Result<std::fs::File, String> {
    std::fs::OpenOptions::new()
        .append(true)
        .open(log)
        .map_err(|e| format!("{}: {e}", log.display()))
}

/// Every test, the full suite's too: the fast tier (`cargo test
/// --workspace`) leaves out those marked `#[ignore = "full suite: …"]`.
fn cargo_test(suite: &Suite) -> Result<(), String> {
    suite.run(cargo().args(["test", "--workspace", "--", "--include-ignored"]))
}

/// The runs of the interop steps.
fn runs(suite: &Suite) -> PathBuf {
    suite.work.join("runs")
}

fn reports(suite: &Suite) -> PathBuf {
    suite.work.join("reports")
}

/// `alnlab run` of the quickstart into the suite's runs and reports.
fn run_quickstart(suite: &Suite) -> Result<(), String> {
    suite.run(
        alnlab()
            .args(["--quiet", "run", "experiments/quickstart.toml", "--out"])
            .arg(runs(suite))
            .arg("--reports")
            .arg(reports(suite)),
    )
}

fn quickstart_interop(suite: &Suite) -> Result<(), String> {
    let _ = std::fs::remove_dir_all(runs(suite));
    let _ = std::fs::remove_dir_all(reports(suite));
    run_quickstart(suite)?;
    interop(
        suite,
        &runs(suite).join("quickstart/run.json"),
        &reports(suite).join("quickstart"),
    )
}

/// The package in `python/` installed into the suite's environment as a
/// user installs it (pip, maturin; the dev profile, whose dependencies the
/// cargo-test step built), then its tests on the quickstart's run (their
/// models' predictions against the test stage's), its benchmark and the
/// model-predictive control example of `docs/` once each (how fast is
/// theirs to say, not a test's).
fn python_package(suite: &Suite) -> Result<(), String> {
    let bin = suite
        .python
        .parent()
        .ok_or("the environment's python has no folder")?;
    let path = std::env::join_paths(std::iter::once(bin.to_path_buf()).chain(
        std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default()),
    ))
    .map_err(|e| format!("PATH: {e}"))?;
    suite.run(
        Command::new(&suite.python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--no-deps",
                "--no-build-isolation",
            ])
            .args(["./python", "--config-settings=build-args=--profile dev"])
            // maturin, from the environment.
            .env("PATH", &path),
    )?;
    let python = |command: &mut Command| {
        command
            .env("ALNLAB_TEST_RUNS", runs(suite))
            .env("ALNLAB_BIN", alnlab_bin());
        suite.run(command)
    };
    // The stubs say what the native module is; mypy's cache kept out of
    // the checkout.
    suite.run(
        Command::new(&suite.python)
            .args(["-m", "mypy.stubtest", "alnlab._alnlab"])
            .env("MYPY_CACHE_DIR", suite.work.join("mypy-cache")),
    )?;
    python(Command::new(&suite.python).args([
        "-m",
        "pytest",
        "python/tests",
        "-p",
        "no:cacheprovider",
        "--import-mode=importlib",
    ]))?;
    python(
        Command::new(&suite.python)
            .arg("python/bench/rollout.py")
            .arg(runs(suite).join("quickstart/run.json"))
            .arg("--json"),
    )?;
    python(
        Command::new(&suite.python)
            .args(["docs/mpc.py", "--out"])
            .arg(runs(suite))
            .args(["--decisions", "3", "--candidates", "32", "--horizon", "4"]),
    )?;
    python(
        Command::new(&suite.python)
            .args(["docs/env_mpc.py", "--out"])
            .arg(runs(suite))
            .args(["--decisions", "3", "--candidates", "32", "--horizon", "4"]),
    )
}

/// Every robot of the installed example-robot-data that Pinocchio loads,
/// 10 s at 1 ms with no torque and with random torques, under semi-implicit
/// Euler and the implicit integrator (`tests/hard_cases.py`): each runs or
/// is refused with its reason, none blows up under the implicit integrator,
/// and each implicit run agrees with Pinocchio; prints the table.
fn hard_cases(suite: &Suite) -> Result<(), String> {
    robot_script(suite, "tests/hard_cases.py", "hard-cases").map(|_| ())
}

/// Pinocchio's inverse and forward dynamics of the KUKA LWR 4+'s URDF
/// against the archived recordings' torques and accelerations
/// (`experiments/kuka-lwr4-physics.py`): the table the experiment's notes
/// quote, as committed.
fn real_arm_physics(suite: &Suite) -> Result<(), String> {
    let made = suite.work.join("kuka-lwr4-physics.md");
    suite.run(
        Command::new(&suite.python)
            .arg("experiments/kuka-lwr4-physics.py")
            .arg("--markdown")
            .arg(&made),
    )?;
    let committed = "experiments/kuka-lwr4-physics.md";
    let read = |p: &Path| std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()));
    match read(&made)? == read(&root().join(committed))? {
        true => Ok(()),
        false => Err(format!(
            "{} is not {committed}: the URDF, the recordings or the script changed; run it again \
             and mend the notes of experiments/kuka-lwr4.toml that quote it",
            made.display()
        )),
    }
}

/// Runs a robot-checking `script` on the binary the suite built, in a
/// fresh `work` folder under the suite's, which it returns.
fn robot_script(suite: &Suite, script: &str, work: &str) -> Result<PathBuf, String> {
    let dir = suite.work.join(work);
    let _ = std::fs::remove_dir_all(&dir);
    suite.run(
        Command::new(&suite.python)
            .arg(script)
            .arg(alnlab_bin())
            .arg(&dir),
    )?;
    Ok(dir)
}

/// The vendored robots and further robots of the installed
/// example-robot-data, each simulated for 10 s and every frame checked
/// with Pinocchio (`tests/robots.py`); then the Pinocchio harness built and
/// `alnlab bench sim` run beside it, which must report both robots' figures
/// (how fast is the benchmark's to say, not a test's).
fn robots_against_pinocchio(suite: &Suite) -> Result<(), String> {
    let dir = robot_script(suite, "tests/robots.py", "robots")?;
    let harness = dir.join("pinocchio-aba");
    suite.run(
        Command::new("bash")
            .arg("bench/pinocchio/build.sh")
            .arg(&harness)
            .env("PYTHON", &suite.python),
    )?;
    let bench = alnlab()
        .args(["bench", "sim", "--repeat", "1", "--json", "--pinocchio"])
        .arg(&harness)
        .current_dir(root())
        .output()
        .map_err(|e| format!("alnlab bench sim: {e}"))?;
    if !bench.status.success() {
        return Err(format!(
            "alnlab bench sim: {}",
            String::from_utf8_lossy(&bench.stderr)
        ));
    }
    let figures: serde_json::Value = serde_json::from_slice(&bench.stdout)
        .map_err(|e| format!("alnlab bench sim --json: {e}"))?;
    let models = figures["models"].as_array().into_iter().flatten();
    let batched: Vec<&str> = models
        .clone()
        .filter(|m| m["aba_ns"].is_array() && m["batched_aba_ns"].is_array())
        .filter(|m| m["held_step_ns"].is_array() && m["batched_step_ns"].is_array())
        .filter_map(|m| m["model"].as_str())
        .collect();
    let timed: Vec<&str> = models
        .filter(|m| m["pinocchio_aba_ns"].is_array())
        .filter_map(|m| m["model"].as_str())
        .collect();
    match (&batched[..], &timed[..]) {
        (["worm", "ur5", "solo12"], ["ur5", "solo12"]) => Ok(()),
        _ => Err(format!(
            "bench sim timed {batched:?} one at a time and batched, expected worm, ur5 \
             and solo12; {timed:?} beside Pinocchio, expected ur5 and solo12"
        )),
    }
}

/// Each `alnlab bench` subcommand the other steps and tests do not run
/// (`sim` here, `circuit` by `tests/circuit.rs`), once and with the fewest repeats it takes, on the
/// quickstart's runs where it needs a run or a manifest. A bench must exit
/// 0 and its `--json` hold the figures it promises; how fast is the
/// benchmark's to say, not a test's. Sharded training must still give the
/// one-process model byte for byte.
fn every_bench(suite: &Suite) -> Result<(), String> {
    let quickstart = runs(suite).join("quickstart");
    let quickstart = quickstart.to_str().ok_or("a non-UTF-8 target folder")?;
    let runs = runs(suite);
    let runs = runs.to_str().ok_or("a non-UTF-8 target folder")?;
    let manifest = "experiments/quickstart.toml";
    let benches: [(&[&str], &[&str]); 7] = [
        (
            &["quantize", "--repeat", "1"],
            &["quantize_encode_values_per_s", "walk_decodes_per_s"],
        ),
        (&["train"], &["node_updates_per_s", "worm"]),
        (&["summarize"], &["errors", "errors_per_s"]),
        (
            &["predict"],
            &["batched_ns_per_state", "single_ns_per_state"],
        ),
        (
            &[
                "predict",
                "--run",
                quickstart,
                "--variant",
                "walk",
                "--repeat",
                "1",
            ],
            &[
                "aln_batched_one_thread_ns",
                "simulator_one_step_one_thread_ns",
            ],
        ),
        (&["shards", manifest], &["processes_seconds", "identical"]),
        (
            &["cache", manifest, "--out", runs, "--repeat", "1"],
            &["cached_run_median_s"],
        ),
    ];
    for (args, keys) in benches {
        let shown = format!("alnlab bench {}", args.join(" "));
        println!("-- {shown}");
        let out = alnlab()
            .args(["-q", "bench"])
            .args(args)
            .arg("--json")
            .current_dir(root())
            .stdin(Stdio::null())
            .output()
            .map_err(|e| format!("{shown}: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "{shown} failed ({}): {}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        let figures: serde_json::Value = serde_json::from_slice(&out.stdout)
            .map_err(|e| format!("{shown} --json printed no JSON object: {e}"))?;
        if let Some(key) = keys.iter().find(|k| figures.get(**k).is_none()) {
            return Err(format!("{shown} --json has no `{key}`: {figures}"));
        }
        if figures.get("identical").is_some_and(|i| i != true) {
            return Err(format!(
                "{shown}: the sharded model differs from one process's"
            ));
        }
        println!("{figures}");
    }
    Ok(())
}

fn interop(suite: &Suite, record: &Path, report: &Path) -> Result<(), String> {
    suite.run(
        Command::new(&suite.python)
            .arg("tests/interop.py")
            .arg(record)
            .arg(report),
    )?;
    // The committed planning reports' control headlines, recomputed from
    // their replicates.csv.
    suite.run(
        Command::new(&suite.python)
            .arg("tests/plan_headlines.py")
            .arg("reports"),
    )
}

/// Two runs of the quickstart (the interop step's, then the same manifest
/// again with every stage from the cache) exported to an MLflow server on
/// loopback, the first twice (which must add nothing), and every record read
/// back with MLflow's own client.
fn mlflow_round_trip(suite: &Suite) -> Result<(), String> {
    run_quickstart(suite)?;
    let dir = suite.work.join("mlflow");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let server = MlflowServer::start(&suite.python, &dir)?;
    let uri = format!("http://127.0.0.1:{}", server.port);
    for run in ["quickstart~1", "quickstart~1", "quickstart"] {
        suite.run(
            alnlab()
                .args(["export", "mlflow", run, "--out"])
                .arg(runs(suite))
                .args(["--tracking-uri", &uri]),
        )?;
    }
    let listed = alnlab()
        .args(["runs", "list", "--json", "--out"])
        .arg(runs(suite))
        .current_dir(root())
        .output()
        .map_err(|e| format!("alnlab runs list: {e}"))?;
    if !listed.status.success() {
        return Err(format!(
            "alnlab runs list: {}",
            String::from_utf8_lossy(&listed.stderr)
        ));
    }
    let listed: serde_json::Value = serde_json::from_slice(&listed.stdout)
        .map_err(|e| format!("alnlab runs list --json: {e}"))?;
    let records: Vec<&str> = listed
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|r| r["record"].as_str())
        .collect();
    if records.len() < 2 {
        return Err(format!("expected two recorded runs, listed {records:?}"));
    }
    for record in records {
        suite.run(
            Command::new(&suite.python)
                .arg("tests/mlflow_check.py")
                .arg(record)
                .arg(&uri),
        )?;
    }
    server.stop()
}

fn snakemake(suite: &Suite) -> Result<(), String> {
    let bin = suite.python.parent().expect("the venv's bin folder");
    suite.run(
        Command::new("bash")
            .arg("tests/snakemake.sh")
            .arg(alnlab_bin())
            .arg(bin.join("snakemake"))
            .arg(&suite.python)
            .arg(suite.work.join("snakemake"))
            // The direct runs beside the quickstart's, sharing its cache.
            .arg(runs(suite))
            .arg(reports(suite)),
    )
}

/// An MLflow tracking server on a free loopback port, in a process group of
/// its own: `mlflow server` runs uvicorn and job-runner consumers as its
/// children, which stopping the server alone would leave orphaned. The whole
/// group is stopped by [`MlflowServer::stop`], or killed when dropped. (Out
/// of the terminal's foreground group, it misses a Ctrl-C that ends the
/// suite: `pkill -f "mlflow server"` then stops it.)
struct MlflowServer {
    child: Child,
    port: u16,
}

impl MlflowServer {
    /// Starts the server with its store in `dir` and waits (up to two
    /// minutes) until it answers `/health`.
    fn start(python: &Path, dir: &Path) -> Result<MlflowServer, String> {
        let port = TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map_err(|e| format!("no free loopback port: {e}"))?
            .port();
        let log = dir.join("server.log");
        let log_file =
            std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()))?;
        let child = Command::new(python.parent().expect("venv bin").join("mlflow"))
            .arg("server")
            .arg("--backend-store-uri")
            .arg(format!("sqlite:///{}", dir.join("mlflow.db").display()))
            .arg("--artifacts-destination")
            .arg(dir.join("artifacts"))
            .args(["--host", "127.0.0.1", "--port", &port.to_string()])
            .args(["--workers", "1"])
            .process_group(0)
            .stdout(log_file.try_clone().map_err(|e| e.to_string())?)
            .stderr(log_file)
            .spawn()
            .map_err(|e| format!("mlflow server: {e}"))?;
        let server = MlflowServer { child, port };
        let deadline = Instant::now() + Duration::from_secs(120);
        while Instant::now() < deadline {
            if healthy(port) {
                return Ok(server);
            }
            std::thread::sleep(Duration::from_millis(500));
        }
        Err(format!(
            "the MLflow server did not answer /health within two minutes; its log:\n{}",
            std::fs::read_to_string(&log).unwrap_or_default()
        ))
    }
}

impl MlflowServer {
    /// Stops every process of the server's group (SIGTERM, then SIGKILL for
    /// any still there after ten seconds); an error when one outlives that.
    fn stop(mut self) -> Result<(), String> {
        let group = self.child.id();
        signal_group(group, "TERM");
        // Polled, not waited for: a server slow to heed SIGTERM must not
        // hold the suite past the deadline.
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            let _ = self.child.try_wait();
            if !group_alive(group) {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        if group_alive(group) {
            signal_group(group, "KILL");
            std::thread::sleep(Duration::from_millis(500));
        }
        if group_alive(group) {
            return Err(format!(
                "the MLflow server's process group {group} outlived SIGTERM and SIGKILL"
            ));
        }
        Ok(())
    }
}

impl Drop for MlflowServer {
    fn drop(&mut self) {
        let group = self.child.id();
        if group_alive(group) {
            signal_group(group, "KILL");
        }
        let _ = self.child.wait();
    }
}

/// The environment variable every process the suite starts inherits, so
/// that any still running when it ends can be found whatever its group.
const MARKER: &str = "ALNLAB_SUITE_RUN";

fn unix_nanos() -> u128 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos())
}

/// Waits up to `grace` for every process carrying this suite's marker
/// (zombies aside) to end; those that outlive it are killed and named in
/// the error. `Ok(false)`: there is no `/proc` to look in.
fn nothing_left_running(marker: &str, grace: Duration) -> Result<bool, String> {
    if !Path::new("/proc/self/environ").exists() {
        return Ok(false);
    }
    let deadline = Instant::now() + grace;
    let mut left = marked_processes(marker);
    while !left.is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
        left = marked_processes(marker);
    }
    if left.is_empty() {
        return Ok(true);
    }
    for (pid, _) in &left {
        // Looked at again just before: a pid that ended may have been reused.
        if marked(*pid, marker) {
            let _ = Command::new("kill")
                .args(["-KILL", &pid.to_string()])
                .status();
        }
    }
    let named: Vec<String> = left.iter().map(|(p, c)| format!("{p} ({c})")).collect();
    Err(format!(
        "{} process(es) the suite started were still running at its end, now killed: {}",
        left.len(),
        named.join(", ")
    ))
}

/// Whether process `pid` exists and its environment holds `MARKER=marker`.
fn marked(pid: u32, marker: &str) -> bool {
    let entry = format!("{MARKER}={marker}");
    std::fs::read(format!("/proc/{pid}/environ"))
        .is_ok_and(|environ| environ.split(|b| *b == 0).any(|v| v == entry.as_bytes()))
}

/// Every process but this one whose environment holds `MARKER=marker` and
/// that has not exited, as (pid, command line). (A process that clears its
/// environment, or another user's, is not seen.)
fn marked_processes(marker: &str) -> Vec<(u32, String)> {
    let entry = format!("{MARKER}={marker}");
    let me = std::process::id();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    let mut found = Vec::new();
    for dir in entries.flatten() {
        let Some(pid) = dir.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
            continue;
        };
        if pid == me {
            continue;
        }
        // Another user's process, or one that just ended: unreadable, skipped.
        let Ok(environ) = std::fs::read(dir.path().join("environ")) else {
            continue;
        };
        if !environ.split(|b| *b == 0).any(|v| v == entry.as_bytes()) {
            continue;
        }
        let stat = std::fs::read_to_string(dir.path().join("stat")).unwrap_or_default();
        let zombie = stat
            .rsplit_once(')')
            .is_some_and(|(_, after)| after.split_whitespace().next() == Some("Z"));
        if !zombie {
            let cmdline = std::fs::read(dir.path().join("cmdline")).unwrap_or_default();
            let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
            found.push((pid, cmdline.trim().to_string()));
        }
    }
    found
}

/// Sends `signal` to every process of the group `group` (with `kill`, the
/// command: the suite needs no binding to libc for two signals).
fn signal_group(group: u32, signal: &str) {
    let _ = Command::new("kill")
        .arg(format!("-{signal}"))
        .arg("--")
        .arg(format!("-{group}"))
        .stderr(Stdio::null())
        .status();
}

/// Whether any process of the group `group` is still there, read from
/// `/proc`, zombies aside: a process that has exited but whose parent, init, has not
/// yet reaped it is gone for this purpose.
fn group_alive(group: u32) -> bool {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return false;
    };
    entries.flatten().any(|entry| {
        // /proc/PID/stat: "PID (COMM) STATE PPID PGRP ..."; COMM may hold
        // spaces or parentheses, so the fields are read after the last ')'.
        let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
        let Some((_, after)) = stat.rsplit_once(')') else {
            return false;
        };
        let fields: Vec<&str> = after.split_whitespace().collect();
        matches!(fields.as_slice(), [state, _ppid, pgrp, ..]
            if *state != "Z" && pgrp.parse() == Ok(group))
    })
}

/// Whether an HTTP server on the loopback port answers `GET /health` 200.
fn healthy(port: u16) -> bool {
    let Ok(mut stream) = TcpStream::connect(("127.0.0.1", port)) else {
        return false;
    };
    let _ = stream.set_read_timeout(Some(Duration::from_secs(2)));
    let request = "GET /health HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if stream.write_all(request.as_bytes()).is_err() {
        return false;
    }
    let mut answer = [0u8; 32];
    let n = stream.read(&mut answer).unwrap_or(0);
    let status_line = String::from_utf8_lossy(&answer[..n]);
    status_line.starts_with("HTTP/") && status_line.contains(" 200")
}

fn cargo() -> Command {
    Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
}

/// The alnlab binary as the first step's `cargo test --workspace` built
/// it. Not `cargo run`: that resolves the root package's features alone,
/// without the Python package's (NumPy's num-complex, pyo3's syn), and
/// would build nalgebra and everything above it a second time.
fn alnlab() -> Command {
    Command::new(alnlab_bin())
}

/// Where the first step's `cargo test --workspace` put the alnlab binary.
fn alnlab_bin() -> PathBuf {
    target_dir().join("debug/alnlab")
}

/// Runs `command` in the workspace's root, its output passed through; an
/// error names the command and its exit status.
fn run_in_root(command: &mut Command) -> Result<(), String> {
    let shown = format!("{command:?}");
    let status = command
        .current_dir(root())
        .stdin(Stdio::null())
        .status()
        .map_err(|e| format!("{shown} could not start: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{shown} failed ({status})"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_marked_process_left_running_is_found_killed_and_named() {
        let marker = format!("test-{}", unix_nanos());
        let mut child = Command::new("sleep")
            .arg("60")
            .env(MARKER, &marker)
            .spawn()
            .unwrap();
        // A child spawned through vfork is running before its new
        // environment is in place (a window a loaded machine widens): wait
        // a few seconds at most for it to show.
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut found = marked_processes(&marker);
        while found.is_empty() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
            found = marked_processes(&marker);
        }
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].0, child.id());
        assert_eq!(found[0].1, "sleep 60");
        let error = nothing_left_running(&marker, Duration::from_secs(1)).unwrap_err();
        assert!(error.contains("sleep 60"), "{error}");
        child.wait().unwrap();
        assert!(marked_processes(&marker).is_empty());
        assert_eq!(nothing_left_running(&marker, Duration::ZERO), Ok(true));
    }
}
