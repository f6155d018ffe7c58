//! Hostile input for the surfaces rounds 2 and 3 added: the plan stage's
//! tasks, `alnlab runs` over damaged records, `export mlflow` against
//! servers that fail, `export verilog`, the circuit stage without its
//! tools, and piecewise-linear models where they cannot go. Every
//! case exits with its code — 2 for the user's mistake, 1 for damaged data
//! — and names the file, key or row; none panics or leaves a file behind.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use crate::common::{TINY, alnlab, case, check_all, stderr};

/// A worm with two tasks; each case below breaks one thing of it.
const PLANNED: &str = r#"
[experiment]
name = "planned"
seed = 5

[[simulate.scene]]
name = "worm"
kind = "worm"
runs = 2
duration = 2.0
controller = { kind = "random" }

[train]
leaves = 64
epochs = 1

[plan]
episodes = 2
frames = 6
horizon = 3
budgets = [4, 8]

[[plan.task]]
kind = "hold-angles"
name = "bend"
targets = { "pitch.2" = 0.6, "pitch.3" = -0.6 }

[[plan.task]]
kind = "spin"
name = "spin"
variable = "omega.1.x"
rate = 1.0
"#;

#[test]
fn plan_tasks_that_cannot_run_are_refused_at_check() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("planned.toml"), PLANNED).unwrap();
    let ok = alnlab(dir.path(), &["check", "planned.toml"]);
    assert!(ok.status.success(), "the base manifest: {}", stderr(&ok));
    // (case, replace, with, what the error must name)
    let edits: &[(&str, &str, &str, &[&str])] = &[
        (
            "a variable the scene lacks",
            "\"pitch.3\" = -0.6",
            "\"pitch.7\" = -0.6",
            &["plan.task.0", "bend", "no variable `pitch.7`"],
        ),
        (
            "a spin of a link the scene lacks",
            "omega.1.x",
            "omega.9.x",
            &["plan.task.1", "no variable `omega.9.x`"],
        ),
        (
            "a scene that is not simulated",
            "budgets = [4, 8]",
            "budgets = [4, 8]\nscene = \"arm\"",
            &["plan.scene", "no scene `arm`", "worm"],
        ),
        (
            "a NaN target",
            "= 0.6",
            "= nan",
            &["plan.task.0.targets", "finite"],
        ),
        (
            "an infinite rate",
            "rate = 1.0",
            "rate = -inf",
            &["plan.task.1.rate", "finite"],
        ),
        (
            "no budget",
            "budgets = [4, 8]",
            "budgets = []",
            &["plan.budgets", "at least one"],
        ),
        (
            "a zero budget",
            "budgets = [4, 8]",
            "budgets = [0]",
            &["plan.budgets", "≥ 1"],
        ),
        (
            "an absurd budget",
            "budgets = [4, 8]",
            "budgets = [4000000000000]",
            &["plan", "forward-model evaluations", "plan_work"],
        ),
        (
            "a zero horizon",
            "horizon = 3",
            "horizon = 0",
            &["plan.horizon", "≥ 1"],
        ),
        (
            "an absurd horizon",
            "horizon = 3",
            "horizon = 1000000000",
            &["plan", "forward-model evaluations"],
        ),
        (
            "a negative episode count",
            "episodes = 2",
            "episodes = -1",
            &["plan.episodes", "≥ 1"],
        ),
        (
            "an unknown model",
            "horizon = 3",
            "horizon = 3\nmodels = [\"oracle\"]",
            &["plan.models", "oracle", "aln"],
        ),
        (
            "a plant's simulator for a scene without one",
            "horizon = 3",
            "horizon = 3\nplant_steps = [10]",
            &["plan.plant_steps", "has no plant"],
        ),
        (
            "too many rounds",
            "horizon = 3",
            "horizon = 3\nrounds = 21",
            &["plan.rounds", "at most 20"],
        ),
        (
            "rounds without the ALN",
            "horizon = 3",
            "horizon = 3\nrounds = 1\nmodels = [\"linear\"]",
            &["plan.rounds", "the ALN among `models`"],
        ),
        (
            "an unknown planner",
            "horizon = 3",
            "horizon = 3\nplanners = [\"gradient\"]",
            &["plan.planners", "gradient", "cem"],
        ),
        (
            "an unknown task kind",
            "kind = \"spin\"",
            "kind = \"fly\"",
            &["plan.task.1.kind", "fly", "hold-angles"],
        ),
        (
            "two tasks of one name",
            "name = \"spin\"",
            "name = \"bend\"",
            &["plan.task.1.name", "two tasks are named `bend`"],
        ),
        (
            "a target that is no angle",
            "\"pitch.2\" = 0.6",
            "\"v.2.x\" = 0.6",
            &["plan.task.0.targets", "not a hinge angle"],
        ),
        (
            "no targets",
            "targets = { \"pitch.2\" = 0.6, \"pitch.3\" = -0.6 }",
            "targets = {}",
            &["plan.task.0.targets", "at least one"],
        ),
        (
            "an unknown task field",
            "rate = 1.0",
            "rate = 1.0\nspeed = 2.0",
            &["plan.task", "speed"],
        ),
    ];
    let cases: Vec<_> = edits
        .iter()
        .map(|(name, from, to, mentions)| {
            assert!(
                PLANNED.contains(from),
                "{name}: `{from}` is in the manifest"
            );
            let file = format!("{}.toml", name.replace(' ', "-"));
            std::fs::write(dir.path().join(&file), PLANNED.replacen(from, to, 1)).unwrap();
            let mut mentions = mentions.to_vec();
            mentions.push(&file);
            case(name, &["check", &file], &mentions, None).exits(2)
        })
        .collect();
    check_all(dir.path(), &cases);
}

/// A folder holding the tiny experiment, run once.
fn tiny_run() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tiny.toml"), TINY).unwrap();
    let out = alnlab(dir.path(), &["-q", "run", "tiny.toml"]);
    assert!(out.status.success(), "{}", stderr(&out));
    dir
}

/// Two tiny runs; their record files, oldest first.
fn two_tiny_runs(dir: &Path) -> Vec<std::path::PathBuf> {
    std::fs::write(dir.join("tiny.toml"), TINY).unwrap();
    for extra in [&[][..], &["--force"][..]] {
        let mut args = vec!["-q", "run", "tiny.toml"];
        args.extend_from_slice(extra);
        let out = alnlab(dir, &args);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let mut records: Vec<_> = std::fs::read_dir(dir.join("runs/tiny/records"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    // In the order they started (two quick runs may share a second, and
    // so the first part of their ids).
    let started = |path: &std::path::PathBuf| {
        let record: serde_json::Value =
            serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
        record["started"].as_str().unwrap().to_string()
    };
    records.sort_by_key(started);
    assert_eq!(records.len(), 2);
    records
}

fn id_of(record: &Path) -> String {
    record.file_stem().unwrap().to_string_lossy().into_owned()
}

#[test]
fn runs_over_damaged_records_list_the_rest_and_name_the_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let records = two_tiny_runs(d);
    let (older, newer) = (&records[0], &records[1]);

    // A truncated record: listed as skipped, by name; the other still listed.
    let bytes = std::fs::read(older).unwrap();
    std::fs::write(older, &bytes[..bytes.len() / 3]).unwrap();
    let out = alnlab(d, &["runs", "list"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let listed = String::from_utf8_lossy(&out.stdout);
    assert!(listed.contains(&id_of(newer)), "{listed}");
    assert!(!listed.contains(&id_of(older)), "{listed}");
    let err = stderr(&out);
    assert!(
        err.contains(&older.file_name().unwrap().to_string_lossy().into_owned())
            && err.contains("not a run record"),
        "{err}"
    );
    // Asked for by id, it is refused with its file named.
    let out = alnlab(d, &["runs", "show", &id_of(older)]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("could not be read"),
        "{}",
        stderr(&out)
    );

    // A record of a newer format: skipped by list, refused by name.
    let mut value: serde_json::Value =
        serde_json::from_slice(&std::fs::read(newer).unwrap()).unwrap();
    value["format"] = 99.into();
    std::fs::write(newer, serde_json::to_vec(&value).unwrap()).unwrap();
    let out = alnlab(d, &["runs", "list"]);
    assert!(
        stderr(&out).contains("format 99 is newer"),
        "{}",
        stderr(&out)
    );
    for (a, b) in [(newer, older), (older, newer)] {
        let out = alnlab(d, &["runs", "diff", &id_of(a), &id_of(b)]);
        assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
        let err = stderr(&out);
        let named = |r: &Path| err.contains(&*r.file_name().unwrap().to_string_lossy());
        assert!(
            (named(a) || named(b)) && err.contains("1 record could not be read"),
            "{err}"
        );
    }
    // The latest run's copy, run.json, stands in for its record while it
    // is intact; without it the run is refused by name.
    let out = alnlab(d, &["runs", "show", &id_of(newer)]);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::remove_file(d.join("runs/tiny/run.json")).unwrap();
    let out = alnlab(d, &["runs", "show", &id_of(newer)]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("format 99 is newer"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn runs_whose_artifacts_left_the_cache_still_list_show_and_diff() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let records = two_tiny_runs(d);
    std::fs::remove_dir_all(d.join("runs/cache/summarize")).unwrap();
    std::fs::remove_dir_all(d.join("runs/cache/test")).unwrap();
    let out = alnlab(d, &["runs", "list", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let listed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let runs = listed.as_array().unwrap();
    assert_eq!(runs.len(), 2);
    for run in runs {
        let variant = &run["variants"][0];
        let (cached, all) = (
            variant["cached_files"].as_u64().unwrap(),
            variant["files"].as_u64().unwrap(),
        );
        // summary, comparisons, horizons; predictions, timings, rollout,
        // linear, boosted.
        assert_eq!(all - cached, 8, "{run}");
        assert!(
            variant["metrics"]["error/aln"]["mean"].as_f64().unwrap() > 0.0,
            "{run}"
        );
    }
    let out = alnlab(d, &["runs", "show", &id_of(&records[0])]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains(" no "));
    let out = alnlab(d, &["runs", "diff", &id_of(&records[0]), "tiny"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// A loopback server that answers every request with `answer` (or, with
/// `None`, accepts and never answers) until the test drops it; it counts
/// the requests and stops by itself after a minute.
struct FakeServer {
    port: u16,
    requests: Arc<AtomicUsize>,
    stop: Arc<AtomicBool>,
}

impl FakeServer {
    fn start(answer: Option<&'static str>) -> FakeServer {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        listener.set_nonblocking(true).unwrap();
        let port = listener.local_addr().unwrap().port();
        let requests = Arc::new(AtomicUsize::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (count, stopped) = (requests.clone(), stop.clone());
        std::thread::spawn(move || {
            let deadline = Instant::now() + Duration::from_secs(60);
            let mut held: Vec<TcpStream> = Vec::new();
            while !stopped.load(Ordering::Relaxed) && Instant::now() < deadline {
                match listener.accept() {
                    Ok((mut stream, _)) => {
                        stream.set_nonblocking(false).unwrap();
                        stream
                            .set_read_timeout(Some(Duration::from_secs(5)))
                            .unwrap();
                        let mut head = Vec::new();
                        let mut byte = [0u8; 1];
                        while !head.ends_with(b"\r\n\r\n")
                            && stream.read(&mut byte).is_ok_and(|n| n == 1)
                        {
                            head.push(byte[0]);
                        }
                        count.fetch_add(1, Ordering::Relaxed);
                        match answer {
                            Some(text) => {
                                let _ = stream.write_all(text.as_bytes());
                            }
                            None => held.push(stream),
                        }
                    }
                    Err(_) => std::thread::sleep(Duration::from_millis(20)),
                }
            }
        });
        FakeServer {
            port,
            requests,
            stop,
        }
    }

    fn uri(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }
}

impl Drop for FakeServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

const SERVER_ERROR: &str = "HTTP/1.1 500 Internal Server Error\r\nContent-Type: text/plain\r\n\
                            Content-Length: 13\r\nConnection: close\r\n\r\ndatabase down";

#[test]
fn mlflow_servers_that_fail_give_clear_errors() {
    let dir = tiny_run();
    let d = dir.path();

    // Nothing listening: a port just freed.
    let closed = {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let nothing = format!("http://127.0.0.1:{closed}");
    let cases = vec![
        case(
            "nothing listening",
            &[
                "export",
                "mlflow",
                "tiny",
                "--tracking-uri",
                &nothing,
                "--timeout",
                "5",
            ],
            &["cannot reach the MLflow server", &nothing, "3 tries"],
            None,
        )
        .exits(2),
        case(
            "a file store, not a server",
            &[
                "export",
                "mlflow",
                "tiny",
                "--tracking-uri",
                "file:///tmp/mlruns",
            ],
            &["--tracking-uri file:///tmp/mlruns", "http://host:port"],
            None,
        )
        .exits(2),
        case(
            "no timeout",
            &[
                "export",
                "mlflow",
                "tiny",
                "--tracking-uri",
                &nothing,
                "--timeout",
                "0",
            ],
            &["--timeout", "expected seconds > 0"],
            None,
        )
        .exits(2),
        case(
            "a run that is not there",
            &["export", "mlflow", "nonesuch", "--tracking-uri", &nothing],
            &["nonesuch"],
            None,
        )
        .exits(2),
    ];
    check_all(d, &cases);

    // A server that answers 500: the read is tried three times, then refused
    // with what the server said.
    let failing = FakeServer::start(Some(SERVER_ERROR));
    let uri = failing.uri();
    let out = alnlab(d, &["export", "mlflow", "tiny", "--tracking-uri", &uri]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("HTTP 500") && err.contains("database down") && err.contains("3 tries"),
        "{err}"
    );
    assert_eq!(failing.requests.load(Ordering::Relaxed), 3);

    // A server that never answers: each try times out.
    let hanging = FakeServer::start(None);
    let uri = hanging.uri();
    let start = Instant::now();
    let out = alnlab(
        d,
        &[
            "export",
            "mlflow",
            "tiny",
            "--tracking-uri",
            &uri,
            "--timeout",
            "1",
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("did not answer within 1 s"),
        "{}",
        stderr(&out)
    );
    assert!(start.elapsed() < Duration::from_secs(30));
    assert_eq!(hanging.requests.load(Ordering::Relaxed), 3);
}

#[test]
fn verilog_export_refuses_what_it_cannot_write_or_trust() {
    let dir = tiny_run();
    let d = dir.path();
    // Another run's codebook: two levels more, another code.
    let other = TINY
        .replace("name = \"tiny\"", "name = \"other\"")
        .replace("levels = 8", "levels = 10")
        .replace("code = \"gray\"", "code = \"binary\"");
    std::fs::write(d.join("other.toml"), other).unwrap();
    let out = alnlab(d, &["-q", "run", "other.toml"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let artifact = |experiment: &str, role: &str| {
        let record: serde_json::Value = serde_json::from_slice(
            &std::fs::read(d.join(format!("runs/{experiment}/run.json"))).unwrap(),
        )
        .unwrap();
        record["variants"][0]["artifacts"][role]["path"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let (model, codebook) = (artifact("tiny", "model"), artifact("tiny", "codebook"));
    let other_codebook = artifact("other", "codebook");
    let bytes = std::fs::read(d.join(&model)).unwrap();
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x20;
    std::fs::write(d.join("flipped.aln"), flipped).unwrap();
    std::fs::write(d.join("truncated.aln"), &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(d.join("a-file"), "not a folder").unwrap();
    std::fs::create_dir(d.join("full")).unwrap();
    std::fs::write(d.join("full/keep.v"), "// mine").unwrap();
    let export = |model: &str, codebook: &str, to: &str| -> Vec<String> {
        ["export", "verilog", model, "--codebook", codebook, "-o", to]
            .map(String::from)
            .to_vec()
    };
    let cases: Vec<_> = [
        (
            "onto a file",
            export(&model, &codebook, "a-file"),
            2,
            vec!["a-file", "is a file"],
        ),
        (
            "into a folder with files",
            export(&model, &codebook, "full"),
            2,
            vec!["full", "holds files already"],
        ),
        (
            "a model with a flipped byte",
            export("flipped.aln", &codebook, "v1"),
            1,
            vec!["flipped.aln", "damaged", "CRC-32"],
        ),
        (
            "a truncated model",
            export("truncated.aln", &codebook, "v2"),
            1,
            vec!["truncated.aln", "damaged"],
        ),
        (
            "another run's codebook",
            export(&model, &other_codebook, "v3"),
            2,
            vec![other_codebook.as_str(), "another codebook"],
        ),
        (
            "a table that is no codebook",
            export(&model, &artifact("tiny", "pairs"), "v4"),
            2,
            vec!["pairs.parquet"],
        ),
        (
            "a missing model",
            export("gone.aln", &codebook, "v5"),
            2,
            vec!["gone.aln"],
        ),
    ]
    .into_iter()
    .map(|(name, args, code, mentions)| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        case(name, &args, &mentions, None).exits(code)
    })
    .collect();
    check_all(d, &cases);
    // Nothing was written where it was refused.
    assert_eq!(
        std::fs::read_to_string(d.join("a-file")).unwrap(),
        "not a folder"
    );
    assert_eq!(std::fs::read_dir(d.join("full")).unwrap().count(), 1);
    for v in ["v1", "v2", "v3", "v4", "v5"] {
        assert!(!d.join(v).exists(), "{v} was made");
    }
}

#[test]
fn the_circuit_stage_without_its_tools_says_how_to_install_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("tiny.toml"), TINY).unwrap();
    let manifest = format!("{TINY}\n[circuit]\nsynthesize = true\n");
    std::fs::write(d.join("synthesized.toml"), manifest).unwrap();
    // A PATH with neither Yosys nor Icarus Verilog on it.
    let empty = d.join("no-tools");
    std::fs::create_dir(&empty).unwrap();
    let without_tools = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_alnlab"))
            .current_dir(d)
            .env("PATH", &empty)
            .args(args)
            .output()
            .unwrap()
    };
    // Measured afterwards, from a run record: a bench.
    let out = without_tools(&["-q", "run", "tiny.toml"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = without_tools(&["-q", "bench", "circuit", "--run", "runs/tiny"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("apt-get install yosys iverilog"),
        "{}",
        stderr(&out)
    );
    // As a stage of the run.
    let circuits = || {
        std::fs::read_dir(d.join("runs/cache/circuit"))
            .unwrap()
            .filter(|e| e.as_ref().unwrap().path().join("circuit.parquet").is_file())
            .count()
    };
    let before = circuits();
    let out = without_tools(&["-q", "run", "synthesized.toml"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("`yosys` was not found") && err.contains("apt-get install yosys iverilog"),
        "{err}"
    );
    assert!(err.contains("circuit"), "the stage is named: {err}");
    // The stages before it ran and are cached; no circuit artifact was
    // added.
    assert!(d.join("runs/cache/summarize").is_dir());
    assert_eq!(circuits(), before, "a circuit artifact was left");
}

#[test]
fn piecewise_linear_models_refuse_what_they_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let piecewise = TINY.replace("[train]\n", "[train]\nmodel = \"piecewise-linear\"\n");
    std::fs::write(d.join("pwl.toml"), &piecewise).unwrap();
    let out = alnlab(d, &["-q", "run", "pwl.toml"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("runs/tiny/run.json")).unwrap()).unwrap();
    let artifact = |role: &str| {
        record["variants"][0]["artifacts"][role]["path"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let edits: [(&str, &str, &str, &[&str]); 4] = [
        (
            "controls given to a bit-forest",
            "model = \"piecewise-linear\"\n",
            "controls = \"given\"\n",
            &["controls", "piecewise-linear"],
        ),
        (
            "a learning rate of zero",
            "model = \"piecewise-linear\"\n",
            "model = \"piecewise-linear\"\npwl = { rate = 0.0 }\n",
            &["pwl.rate", "0 < rate"],
        ),
        (
            "circuit widths given halfway",
            "[test]\n",
            "[circuit]\nsynthesize = true\ninput_bits = 12\n\n[test]\n",
            &["input_bits", "weight_bits", "together"],
        ),
        (
            "a weight of one bit",
            "[test]\n",
            "[circuit]\nsynthesize = true\ninput_bits = 12\nweight_bits = 1\n\n[test]\n",
            &["weight_bits", "from 2 to 32 bits"],
        ),
    ];
    let mut cases: Vec<_> = edits
        .iter()
        .map(|(name, from, to, mentions)| {
            let file = format!("{}.toml", name.replace(' ', "-"));
            std::fs::write(d.join(&file), piecewise.replacen(from, to, 1)).unwrap();
            let mut mentions = mentions.to_vec();
            mentions.push(&file);
            case(name, &["check", &file], &mentions, None).exits(2)
        })
        .collect();
    let (model, codebook) = (artifact("model"), artifact("codebook"));
    cases.push(
        case(
            "a piecewise-linear model exported as Verilog",
            &[
                "export",
                "verilog",
                &model,
                "--codebook",
                &codebook,
                "-o",
                "v",
            ],
            &["piecewise-linear", "only bit-forests"],
            None,
        )
        .exits(2),
    );
    let (levels, pairs, nominal) = (artifact("levels"), artifact("pairs"), artifact("nominal"));
    // The circuit stage alone: input words too narrow for the training
    // rows' levels, and a damaged model; neither leaves a table.
    let circuit = |name: &str, manifest: &str, model: &str, out: &str, mentions: &[&str]| {
        let args = [
            "circuit",
            "--manifest",
            manifest,
            "--model",
            model,
            "--codebook",
            &codebook,
            "--levels",
            &levels,
            "--pairs",
            &pairs,
            "--out",
            out,
        ];
        case(name, &args, mentions, Some(Path::new(out)))
    };
    let narrow = piecewise.replacen(
        "[test]\n",
        "[circuit]\nsynthesize = true\ninput_bits = 3\nweight_bits = 6\n\n[test]\n",
        1,
    );
    std::fs::write(d.join("narrow.toml"), &narrow).unwrap();
    let mut damaged = std::fs::read(d.join(&model)).unwrap();
    damaged.truncate(damaged.len() * 2 / 3);
    std::fs::write(d.join("damaged.aln"), damaged).unwrap();
    cases.push(
        circuit(
            "input words too narrow for the training rows",
            "narrow.toml",
            &model,
            "c1",
            &["input_bits = 3", "integer bits", "at least"],
        )
        .exits(2),
    );
    cases.push(
        circuit(
            "a damaged model to the circuit stage",
            "narrow.toml",
            "damaged.aln",
            "c2",
            &["damaged.aln"],
        )
        .exits(1),
    );
    cases.push(
        case(
            "a piecewise-linear model trained in shards",
            &[
                "train",
                "--manifest",
                "pwl.toml",
                "--codebook",
                &codebook,
                "--levels",
                &levels,
                "--pairs",
                &pairs,
                "--nominal",
                &nominal,
                "--shard",
                "1/2",
                "--out",
                "s1",
            ],
            &["piecewise-linear", "without --shard"],
            Some(Path::new("s1")),
        )
        .exits(2),
    );
    check_all(d, &cases);
    assert!(!d.join("v").exists(), "the refused export made its folder");
}

/// A reader that goes away before alnlab writes (`alnlab check M | head`)
/// ends it quietly, by SIGPIPE as any Unix tool, never by a panic (exit
/// 101 with a message on stderr).
#[test]
fn a_closed_pipe_ends_the_program_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tiny.toml"), TINY).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_alnlab"))
        .current_dir(dir.path())
        .args(["check", "tiny.toml"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The reader is gone before the first line is written.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let quiet = out.status.success() || out.status.signal() == Some(13);
    assert!(quiet, "{:?}: {}", out.status, stderr(&out));
    assert!(!stderr(&out).contains("panicked"), "{}", stderr(&out));
}
