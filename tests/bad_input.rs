//! Bad input, as a new user (or a damaged disk) gives it: manifests, every
//! file kind a stage reads, run records, catalogs, output folders and the
//! dataset commands. Every case must exit 1 (damaged data) or 2 (the user's
//! to fix) with a message naming the file (and the key or row where there
//! is one) — never a panic, an abort or a signal — and must leave its
//! output folder without a finished file.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use alnlab::records::RunRecord;
use alnlab_common::Provenance;
use alnlab_common::table::{Table, batch, write_parquet};
use arrow_array::{Array, Float64Array, RecordBatch, StringArray, UInt16Array, UInt32Array};

use crate::common::{TINY, alnlab, case, check_all, stderr};

/// The tiny experiment's artifacts, by role.
fn tiny_run(dir: &Path) -> RunRecord {
    std::fs::write(dir.join("tiny.toml"), TINY).unwrap();
    let out = alnlab(dir, &["-q", "run", "tiny.toml", "--reports", "reports"]);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_slice(&std::fs::read(dir.join("runs/tiny/run.json")).unwrap()).unwrap()
}

fn flipped(from: &Path, to: &Path, at_fraction: f64) {
    let mut bytes = std::fs::read(from).unwrap();
    let at = ((bytes.len() as f64 * at_fraction) as usize).min(bytes.len() - 1);
    bytes[at] ^= 0x20;
    std::fs::write(to, bytes).unwrap();
}

fn truncated(from: &Path, to: &Path) {
    let bytes = std::fs::read(from).unwrap();
    std::fs::write(to, &bytes[..bytes.len() / 2]).unwrap();
}

/// `table` with column `name` replaced by `column`, written to `to`.
fn replaced(table: &Table, name: &str, column: Arc<dyn Array>, to: &Path) {
    let schema = table.batch.schema();
    let columns: Vec<(&str, Arc<dyn Array>)> = schema
        .fields()
        .iter()
        .zip(table.batch.columns())
        .map(|(f, c)| {
            let c = if f.name() == name {
                column.clone()
            } else {
                c.clone()
            };
            (f.name().as_str(), c)
        })
        .collect();
    write_parquet(to, &batch(columns), &Provenance::default()).unwrap();
}

/// `table` without column `name`, written to `to`.
fn without(table: &Table, name: &str, to: &Path) {
    let schema = table.batch.schema();
    let columns: Vec<(&str, Arc<dyn Array>)> = schema
        .fields()
        .iter()
        .zip(table.batch.columns())
        .filter(|(f, _)| f.name() != name)
        .map(|(f, c)| (f.name().as_str(), c.clone()))
        .collect();
    let b: RecordBatch = batch(columns);
    write_parquet(to, &b, &Provenance::default()).unwrap();
}

#[test]
fn manifests_that_cannot_run_are_refused_at_check() {
    let dir = tempfile::tempdir().unwrap();
    let edits: &[(&str, &str, &str, &str)] = &[
        // (case, replace, with, the key the error must name)
        (
            "unknown key",
            "epochs = 1",
            "epochs = 1\nepoch = 2",
            "epoch",
        ),
        ("wrong type", "levels = 8", "levels = \"eight\"", "levels"),
        ("zero runs", "runs = 2", "runs = 0", "runs"),
        ("negative runs", "runs = 2", "runs = -3", "runs"),
        ("runs past 32 bits", "runs = 2", "runs = 4294967297", "runs"),
        ("negative dt", "dt = 0.01", "dt = -0.01", "dt"),
        ("nan dt", "dt = 0.01", "dt = nan", "dt"),
        (
            "infinite duration",
            "duration = 0.5",
            "duration = inf",
            "duration",
        ),
        (
            "duration of a thousand years",
            "duration = 0.5",
            "duration = 1e12",
            "duration",
        ),
        (
            "dt of a picosecond",
            "dt = 0.01\nframe_dt = 0.01",
            "dt = 1e-12\nframe_dt = 0.01",
            "simulate",
        ),
        (
            "frame_dt not a multiple of dt",
            "frame_dt = 0.01",
            "frame_dt = 0.015",
            "frame_dt",
        ),
        (
            "endless epochs",
            "epochs = 1",
            "epochs = 1000000000000",
            "train",
        ),
        (
            "endless piecewise-linear epochs",
            "epochs = 1",
            "epochs = 1\nmodel = \"piecewise-linear\"\npwl.epochs = 1000000000000",
            "pwl.epochs",
        ),
        (
            "endless piecewise-linear rounds",
            "epochs = 1",
            "epochs = 1\nmodel = \"piecewise-linear\"\npwl.rounds = 1000000000000",
            "pwl.rounds",
        ),
        (
            "sixteen million leaves",
            "leaves = 8",
            "leaves = 16777216",
            "train",
        ),
        (
            "endless resimulation",
            "resimulate_steps = [1]",
            "resimulate_steps = [1000000000000]",
            "test",
        ),
        (
            "endless closed loop",
            "horizon = 2",
            "horizon = 1000000000000",
            "test",
        ),
        ("one level", "levels = 8", "levels = 1", "levels"),
        (
            "unknown code",
            "code = \"gray\"",
            "code = \"morse\"",
            "code",
        ),
        (
            "test fraction above 1",
            "test_fraction = 0.5",
            "test_fraction = 1.5",
            "test_fraction",
        ),
        (
            "unknown split",
            "split = \"disjoint\"",
            "split = \"random\"",
            "split",
        ),
        (
            "unknown scene kind",
            "kind = \"pendulum\"",
            "kind = \"octopus\"",
            "kind",
        ),
        (
            "scene name with a slash",
            "name = \"pendulum\"",
            "name = \"../pendulum\"",
            "name",
        ),
        (
            "experiment name leading out",
            "name = \"tiny\"",
            "name = \"../../x\"",
            "name",
        ),
        ("negative seed", "seed = 7", "seed = -7", "seed"),
        (
            "zero replicates",
            "seed = 7",
            "seed = 7\nreplicates = 0",
            "replicates",
        ),
        (
            "unknown budget key",
            "seed = 7",
            "seed = 7\nbudget.money = 3",
            "money",
        ),
        (
            "negative budget",
            "seed = 7",
            "seed = 7\nbudget.steps = -1",
            "steps",
        ),
        ("syntax error", "[train]", "[train", "unclosed table"),
        (
            "no experiment table",
            "[experiment]",
            "[experimen]",
            "experimen",
        ),
        (
            "a payload on a link the scene lacks",
            "duration = 0.5",
            "duration = 0.5\nplant = { payload = { link = \"9\", mass = 1.0 } }",
            "plant.payload.link",
        ),
        (
            "a plant without mass",
            "duration = 0.5",
            "duration = 0.5\nplant = { mass_scale = 0.0 }",
            "plant.mass_scale",
        ),
        (
            "Coulomb friction at ball hinges",
            "duration = 0.5",
            "duration = 0.5\nplant = { coulomb_friction = 0.2 }",
            "plant.coulomb_friction",
        ),
        (
            "unknown plant key",
            "duration = 0.5",
            "duration = 0.5\nplant = { mass = 2.0 }",
            "mass",
        ),
        ("zero leaves", "leaves = 8", "leaves = 0", "leaves"),
        ("zero stride", "n = 1", "n = 0", "n"),
    ];
    let mut cases = Vec::new();
    for (i, (name, from, to, key)) in edits.iter().enumerate() {
        assert!(
            TINY.contains(from),
            "{name}: `{from}` is not in the manifest"
        );
        let file = format!("m{i}.toml");
        std::fs::write(dir.path().join(&file), TINY.replacen(from, to, 1)).unwrap();
        cases.push(case(name, &["check", &file], &[&file, key], None));
    }
    // Files that never end are refused at a stated size, not read until
    // memory runs out.
    cases.push(
        case(
            "an endless manifest",
            &["check", "/dev/zero"],
            &[
                "/dev/zero",
                "more than 16 MiB, far more than a manifest holds",
            ],
            None,
        )
        .exits(2),
    );
    // Robot descriptions that cannot be taken, each in a manifest of its own.
    let mut chain = String::from("<robot name=\"chain\">");
    for i in 0..20_000 {
        chain += &format!("<link name=\"l{i}\"/>");
        if i > 0 {
            chain += &format!(
                "<joint name=\"j{i}\" type=\"fixed\"><parent link=\"l{}\"/><child link=\"l{i}\"/></joint>",
                i - 1
            );
        }
    }
    std::fs::write(dir.path().join("chain.urdf"), chain + "</robot>").unwrap();
    std::fs::write(
        dir.path().join("arm.urdf.xacro"),
        "<robot name=\"arm\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\
         <xacro:include filename=\"arm.macros.xacro\"/><link name=\"base\"/></robot>",
    )
    .unwrap();
    let robots: [(&str, &str, &str, &[&str]); 3] = [
        (
            "an endless robot description",
            "endless-robot.toml",
            "/dev/zero",
            &["more than 64 MiB, far more than a robot description holds"],
        ),
        (
            // It overflowed the stack (signal 6).
            "a chain of 20 000 links",
            "chain.toml",
            "chain.urdf",
            &["has 20000 links; alnlab takes robots of at most 10000"],
        ),
        (
            "a xacro file",
            "xacro.toml",
            "arm.urdf.xacro",
            &["this is a xacro file", "expand it to URDF first"],
        ),
    ];
    for (name, manifest, description, says) in robots {
        let scene = format!("kind = \"urdf\"\nfile = \"{description}\"");
        let text = TINY.replacen("kind = \"pendulum\"", &scene, 1);
        std::fs::write(dir.path().join(manifest), text).unwrap();
        let mut mentions = vec![manifest, "file", description];
        mentions.extend_from_slice(says);
        cases.push(case(name, &["check", manifest], &mentions, None).exits(2));
    }
    // Issue 45: nothing would move, so nothing would be learned; it logged
    // empty frames and failed late.
    std::fs::write(
        dir.path().join("frame.urdf"),
        "<robot name=\"frame\"><link name=\"base\"><inertial><mass value=\"1\"/>\
         <inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link></robot>",
    )
    .unwrap();
    let scene = "kind = \"urdf\"\nfile = \"frame.urdf\"";
    std::fs::write(
        dir.path().join("still.toml"),
        TINY.replacen("kind = \"pendulum\"", scene, 1),
    )
    .unwrap();
    cases.push(
        case(
            "a welded robot with nothing that moves",
            &["check", "still.toml"],
            &[
                "still.toml",
                "base",
                "robot `frame` has no joint that moves",
                "nothing to learn",
            ],
            None,
        )
        .exits(2),
    );
    std::fs::write(dir.path().join("empty.toml"), "").unwrap();
    cases.push(case(
        "empty manifest",
        &["check", "empty.toml"],
        &["empty.toml"],
        None,
    ));
    std::fs::write(
        dir.path().join("latin1.toml"),
        b"[experiment]\nname = \"caf\xe9\"\n",
    )
    .unwrap();
    cases.push(case(
        "not UTF-8",
        &["check", "latin1.toml"],
        &["latin1.toml", "UTF-8"],
        None,
    ));
    cases.push(case(
        "missing manifest",
        &["check", "nowhere.toml"],
        &["nowhere.toml"],
        None,
    ));
    std::fs::create_dir(dir.path().join("folder.toml")).unwrap();
    cases.push(case(
        "a folder as manifest",
        &["check", "folder.toml"],
        &["folder.toml"],
        None,
    ));
    check_all(dir.path(), &cases);
}

#[test]
fn damaged_and_hostile_files_given_to_stages_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let record = tiny_run(d);
    let art = |role: &str| d.join(&record.variants[0].artifacts[role].path);
    let mut cases = Vec::new();
    let mut n = 0;
    let mut fresh_out = || {
        n += 1;
        d.join(format!("out{n}"))
    };
    let s = |p: &Path| p.to_string_lossy().into_owned();

    // The trajectory log, to stride.
    let trajectory = art("trajectory");
    let bad_logs: Vec<(&str, PathBuf)> = {
        let mut v = Vec::new();
        for (name, at) in [
            ("flip near the start", 0.05),
            ("flip in the middle", 0.5),
            ("flip in the summary", 0.97),
        ] {
            let p = d.join(format!("log-{}.mcap", v.len()));
            flipped(&trajectory, &p, at);
            v.push((name, p));
        }
        let p = d.join("log-half.mcap");
        truncated(&trajectory, &p);
        v.push(("truncated log", p));
        let p = d.join("log-empty.mcap");
        std::fs::write(&p, b"").unwrap();
        v.push(("empty log", p));
        v.push(("a Parquet table as log", art("pairs")));
        v
    };
    for (name, log) in &bad_logs {
        let out = fresh_out();
        let file = log.file_name().unwrap().to_string_lossy().into_owned();
        cases.push(case(
            name,
            &[
                "stride",
                "--manifest",
                "tiny.toml",
                "--trajectory",
                &s(log),
                "--out",
                &s(&out),
            ],
            &[&file],
            Some(&out),
        ));
    }

    // Statistics and pairs, to quantize.
    let stats = Table::read(&art("stats")).unwrap();
    let pairs = Table::read(&art("pairs")).unwrap();
    let n_stats = stats.num_rows();
    let mut min_nan = stats.f64_column("min").unwrap().values().to_vec();
    min_nan[0] = f64::NAN;
    replaced(
        &stats,
        "min",
        Arc::new(Float64Array::from(min_nan)),
        &d.join("stats-nan.parquet"),
    );
    let swapped: Vec<f64> = stats
        .f64_column("max")
        .unwrap()
        .values()
        .iter()
        .map(|m| m + 1.0)
        .collect();
    replaced(
        &stats,
        "min",
        Arc::new(Float64Array::from(swapped)),
        &d.join("stats-min-above-max.parquet"),
    );
    without(&stats, "max", &d.join("stats-no-max.parquet"));
    replaced(
        &stats,
        "min",
        Arc::new(StringArray::from(vec!["low"; n_stats])),
        &d.join("stats-string-min.parquet"),
    );
    let x_name = pairs
        .batch
        .schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .find(|n| n.starts_with("x."))
        .unwrap();
    let mut with_null: Vec<Option<f64>> = pairs.f64_column(&x_name).unwrap().iter().collect();
    with_null[3] = None;
    replaced(
        &pairs,
        &x_name,
        Arc::new(Float64Array::from(with_null)),
        &d.join("pairs-null.parquet"),
    );
    let mut with_inf = pairs.f64_column(&x_name).unwrap().values().to_vec();
    with_inf[5] = f64::INFINITY;
    replaced(
        &pairs,
        &x_name,
        Arc::new(Float64Array::from(with_inf)),
        &d.join("pairs-inf.parquet"),
    );
    flipped(&art("pairs"), &d.join("pairs-flipped.parquet"), 0.4);
    flipped(&art("stats"), &d.join("stats-flipped.parquet"), 0.9);
    truncated(&art("pairs"), &d.join("pairs-half.parquet"));
    std::fs::write(
        d.join("pairs-garbage.parquet"),
        b"PAR1 this is not a table PAR1",
    )
    .unwrap();
    let good_pairs = s(&art("pairs"));
    let good_nominal = s(&art("nominal"));
    let good_stats = s(&art("stats"));
    for (name, pairs, stats, mention) in [
        (
            "NaN in stats",
            good_pairs.as_str(),
            "stats-nan.parquet",
            "row 0",
        ),
        (
            "min above max in stats",
            &good_pairs,
            "stats-min-above-max.parquet",
            "row 0",
        ),
        (
            "stats without max",
            &good_pairs,
            "stats-no-max.parquet",
            "`max`",
        ),
        (
            "stats min of strings",
            &good_pairs,
            "stats-string-min.parquet",
            "`min`",
        ),
        (
            "a null in pairs",
            "pairs-null.parquet",
            &good_stats,
            "row 3",
        ),
        (
            "infinity in pairs",
            "pairs-inf.parquet",
            &good_stats,
            "row 5",
        ),
        (
            "a flipped byte in pairs",
            "pairs-flipped.parquet",
            &good_stats,
            "damaged",
        ),
        (
            "a flipped byte in stats",
            &good_pairs,
            "stats-flipped.parquet",
            "damaged",
        ),
        (
            "truncated pairs",
            "pairs-half.parquet",
            &good_stats,
            "pairs-half.parquet",
        ),
        (
            "garbage pairs",
            "pairs-garbage.parquet",
            &good_stats,
            "pairs-garbage.parquet",
        ),
    ] {
        let out = fresh_out();
        let file = if pairs.ends_with(".parquet") && !pairs.contains("cache") {
            pairs
        } else {
            stats
        };
        cases.push(case(
            name,
            &[
                "quantize",
                "--manifest",
                "tiny.toml",
                "--pairs",
                pairs,
                "--stats",
                stats,
                "--out",
                &s(&out),
            ],
            &[file, mention],
            Some(&out),
        ));
    }

    // Levels and codebook, to train.
    let levels = Table::read(&art("levels")).unwrap();
    let codebook = Table::read(&art("codebook")).unwrap();
    let level_name = levels
        .batch
        .schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .find(|n| n.starts_with("y."))
        .unwrap();
    let mut too_high = levels
        .column::<UInt16Array>(&level_name)
        .unwrap()
        .values()
        .to_vec();
    too_high[2] = 9;
    replaced(
        &levels,
        &level_name,
        Arc::new(UInt16Array::from(too_high)),
        &d.join("levels-high.parquet"),
    );
    let mut split = levels.strings("split").unwrap();
    split[1] = "validation".into();
    replaced(
        &levels,
        "split",
        Arc::new(StringArray::from(split)),
        &d.join("levels-split.parquet"),
    );
    flipped(&art("levels"), &d.join("levels-flipped.parquet"), 0.6);
    let rows = codebook.num_rows();
    replaced(
        &codebook,
        "min",
        Arc::new(Float64Array::from(vec![f64::NAN; rows])),
        &d.join("codebook-nan.parquet"),
    );
    replaced(
        &codebook,
        "code",
        Arc::new(StringArray::from(vec!["morse"; rows])),
        &d.join("codebook-morse.parquet"),
    );
    replaced(
        &codebook,
        "levels",
        Arc::new(arrow_array::UInt64Array::from(vec![1u64; rows])),
        &d.join("codebook-one-level.parquet"),
    );
    replaced(
        &codebook,
        "width",
        Arc::new(arrow_array::UInt64Array::from(vec![1u64 << 40; rows])),
        &d.join("codebook-wide.parquet"),
    );
    let good_levels = s(&art("levels"));
    let good_codebook = s(&art("codebook"));
    for (name, levels, codebook, mention) in [
        (
            "levels beyond the codebook's",
            "levels-high.parquet",
            good_codebook.as_str(),
            "row 2",
        ),
        (
            "an unknown split",
            "levels-split.parquet",
            &good_codebook,
            "row 1",
        ),
        (
            "a flipped byte in levels",
            "levels-flipped.parquet",
            &good_codebook,
            "damaged",
        ),
        (
            "NaN codebook minima",
            &good_levels,
            "codebook-nan.parquet",
            "row 0",
        ),
        (
            "an unknown code",
            &good_levels,
            "codebook-morse.parquet",
            "morse",
        ),
        (
            "one level",
            &good_levels,
            "codebook-one-level.parquet",
            "levels",
        ),
        (
            "a width past 32 bits",
            &good_levels,
            "codebook-wide.parquet",
            "width",
        ),
    ] {
        let out = fresh_out();
        let file = if levels.contains("cache") {
            codebook
        } else {
            levels
        };
        cases.push(case(
            name,
            &[
                "train",
                "--manifest",
                "tiny.toml",
                "--levels",
                levels,
                "--codebook",
                codebook,
                "--pairs",
                &good_pairs,
                "--nominal",
                &good_nominal,
                "--out",
                &s(&out),
            ],
            &[file, mention],
            Some(&out),
        ));
    }

    // Model files, to test.
    let model = art("model");
    flipped(&model, &d.join("model-flipped.aln"), 0.5);
    flipped(&model, &d.join("model-header.aln"), 0.02);
    truncated(&model, &d.join("model-half.aln"));
    std::fs::write(d.join("model-garbage.aln"), b"not a model").unwrap();
    for (name, file) in [
        ("a flipped byte in a tree", "model-flipped.aln"),
        ("a flipped byte in the header", "model-header.aln"),
        ("a truncated model", "model-half.aln"),
        ("not a model", "model-garbage.aln"),
        ("a Parquet table as the model", "pairs-garbage.parquet"),
    ] {
        let out = fresh_out();
        cases.push(case(
            name,
            &[
                "test",
                "--manifest",
                "tiny.toml",
                "--trajectory",
                &s(&trajectory),
                "--model",
                file,
                "--codebook",
                &good_codebook,
                "--levels",
                &good_levels,
                "--pairs",
                &good_pairs,
                "--nominal",
                &good_nominal,
                "--out",
                &s(&out),
            ],
            &[file],
            Some(&out),
        ));
    }

    // Pairs that are not the ones the levels were made from: one pair's
    // step moved.
    let pairs = Table::read(&art("pairs")).unwrap();
    let mut steps = pairs
        .column::<UInt32Array>("step")
        .unwrap()
        .values()
        .to_vec();
    steps[3] += 1;
    replaced(
        &pairs,
        "step",
        Arc::new(UInt32Array::from(steps)),
        &d.join("pairs-other.parquet"),
    );
    let out = fresh_out();
    cases.push(case(
        "pairs other than the levels were made from",
        &[
            "test",
            "--manifest",
            "tiny.toml",
            "--trajectory",
            &s(&trajectory),
            "--model",
            &s(&model),
            "--codebook",
            &good_codebook,
            "--levels",
            &good_levels,
            "--pairs",
            "pairs-other.parquet",
            "--nominal",
            &good_nominal,
            "--out",
            &s(&out),
        ],
        &["pairs-other.parquet", "does not hold the pairs"],
        Some(&out),
    ));

    // Predictions, to summarize.
    flipped(
        &art("predictions"),
        &d.join("predictions-flipped.parquet"),
        0.3,
    );
    let out = fresh_out();
    cases.push(case(
        "a flipped byte in predictions",
        &[
            "summarize",
            "--manifest",
            "tiny.toml",
            "--predictions",
            "predictions-flipped.parquet",
            "--rollout",
            &s(&art("rollout")),
            "--out",
            &s(&out),
        ],
        &["predictions-flipped.parquet", "damaged"],
        Some(&out),
    ));

    // An output folder that is a file.
    std::fs::write(d.join("a-file"), b"mine").unwrap();
    cases.push(case(
        "--out is a file (stage)",
        &[
            "stride",
            "--manifest",
            "tiny.toml",
            "--trajectory",
            &s(&trajectory),
            "--out",
            "a-file",
        ],
        &["a-file", "is a file, expected a folder"],
        None,
    ));
    cases.push(case(
        "--out is a file (run)",
        &["-q", "run", "tiny.toml", "--out", "a-file"],
        &["a-file", "is a file, expected a folder"],
        None,
    ));
    check_all(d, &cases);
    assert_eq!(std::fs::read(d.join("a-file")).unwrap(), b"mine");
}

#[test]
fn run_records_and_catalogs_cannot_write_outside_their_folders() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    tiny_run(d);
    let record = std::fs::read_to_string(d.join("runs/tiny/run.json")).unwrap();
    let mut cases = Vec::new();
    for (i, (name, from, to)) in [
        (
            "experiment name leading out",
            "\"experiment\": \"tiny\"",
            "\"experiment\": \"../../x\"",
        ),
        (
            "variant name leading out",
            "\"name\": \"base\"",
            "\"name\": \"../y\"",
        ),
        ("not JSON", "{", "<"),
        (
            "a field of the wrong type",
            "\"seed\": 7",
            "\"seed\": \"seven\"",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        assert!(record.contains(from), "{name}");
        let run_dir = d.join(format!("edited{i}"));
        std::fs::create_dir(&run_dir).unwrap();
        std::fs::write(run_dir.join("run.json"), record.replacen(from, to, 1)).unwrap();
        let reports = d.join(format!("reports{i}"));
        cases.push(case(
            name,
            &[
                "report",
                &run_dir.to_string_lossy(),
                "--reports",
                &reports.to_string_lossy(),
            ],
            &["run.json"],
            Some(&reports),
        ));
    }
    cases.push(case(
        "no run record",
        &["report", "nowhere"],
        &["nowhere"],
        None,
    ));

    // Archive, then damage the catalog in the ways a hand edit would.
    let out = alnlab(
        d,
        &[
            "dataset",
            "archive",
            "--run",
            "runs/tiny",
            "--name",
            "t",
            "--datasets",
            "archive",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let catalog = std::fs::read_to_string(d.join("archive/catalog.toml")).unwrap();
    let hostile = d.join("hostile");
    std::fs::create_dir_all(hostile.join("objects")).unwrap();
    for entry in std::fs::read_dir(d.join("archive/objects")).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(
            entry.path(),
            hostile.join("objects").join(entry.file_name()),
        )
        .unwrap();
    }
    std::fs::write(
        hostile.join("catalog.toml"),
        catalog.replacen(
            "name = \"trajectory.mcap\"",
            "name = \"../escaped.mcap\"",
            1,
        ),
    )
    .unwrap();
    cases.push(case(
        "a catalog file name leading out",
        &[
            "dataset",
            "restore",
            "t@1",
            "--datasets",
            "hostile",
            "--to",
            "restored-h",
        ],
        &["t@1"],
        Some(&d.join("restored-h")),
    ));
    std::fs::create_dir(d.join("garbage")).unwrap();
    std::fs::write(d.join("garbage/catalog.toml"), "[[dataset]\nname = ").unwrap();
    cases.push(case(
        "a catalog that is not TOML",
        &["dataset", "list", "--datasets", "garbage"],
        &["catalog.toml"],
        None,
    ));
    // A user's file in the way of a restore: refused, and kept.
    std::fs::create_dir(d.join("mine")).unwrap();
    std::fs::write(d.join("mine/pairs.parquet"), b"my own notes").unwrap();
    cases.push(case(
        "restore over a user's file",
        &[
            "dataset",
            "restore",
            "t@1",
            "--datasets",
            "archive",
            "--to",
            "mine",
        ],
        &["pairs.parquet", "overwrite"],
        None,
    ));
    // A damaged cached artifact is never archived.
    let pairs = std::fs::read_dir(d.join("runs/cache/stride"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    flipped(
        &pairs.join("pairs.parquet"),
        &pairs.join("pairs.parquet"),
        0.5,
    );
    cases.push(case(
        "archiving a damaged artifact",
        &[
            "dataset",
            "archive",
            "--run",
            "runs/tiny",
            "--name",
            "t2",
            "--datasets",
            "archive",
        ],
        &["pairs.parquet", "damaged"],
        None,
    ));
    check_all(d, &cases);
    assert!(!d.join("escaped.mcap").exists());
    assert_eq!(
        std::fs::read(d.join("mine/pairs.parquet")).unwrap(),
        b"my own notes"
    );
    let names: Vec<String> = std::fs::read_dir(d.join("mine"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        ["pairs.parquet"],
        "a refused restore leaves nothing behind"
    );
    assert!(
        !std::fs::read_to_string(d.join("archive/catalog.toml"))
            .unwrap()
            .contains("name = \"t2\"")
    );
}
