//! End-to-end tests of the dataset archive: archive a run, remove it, run
//! again from the archive; damage, and bad names.

use std::path::Path;

use alnlab::records::RunRecord;

use crate::common::{
    MANIFEST, UR5_JOINTS, alnlab, run_ok, stderr, ur5_table_header, write_manifest,
};

/// [`MANIFEST`] with its simulate and stride tables replaced by `[data]`.
fn from_dataset(reference: &str, keep_quantize: bool) -> String {
    let quantize = if keep_quantize {
        "[quantize]\nlevels = 64\n"
    } else {
        ""
    };
    let train = &MANIFEST[MANIFEST.find("[train]").unwrap()..];
    format!(
        "[experiment]\nname = \"e2e\"\nseed = 11\n\n[data]\ndataset = \"{reference}\"\n\n{quantize}{train}"
    )
}

/// The bytes of the predictions and summary a run made.
fn results(dir: &Path, record: &RunRecord) -> Vec<Vec<u8>> {
    ["predictions", "rollout", "summary", "horizons"]
        .iter()
        .map(|role| std::fs::read(dir.join(&record.variants[0].artifacts[*role].path)).unwrap())
        .collect()
}

fn ok(dir: &Path, args: &[&str]) -> String {
    let out = alnlab(dir, args);
    assert!(out.status.success(), "alnlab {args:?}: {}", stderr(&out));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn a_replicated_run_archives_the_replicate_named_and_says_which() {
    let dir = tempfile::tempdir().unwrap();
    let replicated = MANIFEST.replace("seed = 11\n", "seed = 11\nreplicates = 2\n");
    write_manifest(dir.path(), "m.toml", &replicated);
    let record = run_ok(dir.path(), &["m.toml"]);
    let seeds: Vec<u64> = record.variants.iter().map(|v| v.seed).collect();
    assert_eq!(seeds.len(), 2);

    // Two replicates, two seeds, different data: no silent pick.
    let archive = ["dataset", "archive", "--run", "runs/e2e", "--name", "box"];
    let out = alnlab(dir.path(), &archive);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let expected = format!(
        "choose one with --variant and --replicate (the run has variant `base`: replicates 1, 2 \
         with seeds {}, {})",
        seeds[0], seeds[1]
    );
    assert!(stderr(&out).contains(&expected), "{}", stderr(&out));
    let out = alnlab(dir.path(), &[&archive[..], &["--replicate", "3"]].concat());
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("no replicate 3"), "{}", stderr(&out));

    ok(dir.path(), &[&archive[..], &["--replicate", "2"]].concat());
    let show = ok(dir.path(), &["dataset", "show", "box@1"]);
    assert!(
        show.contains("experiment  e2e (variant base, replicate 2)")
            && show.contains(&format!("seed        {}\n", seeds[1])),
        "{show}"
    );
    let pairs = &record.variants[1].artifacts["pairs"].sha256;
    assert!(show.contains(pairs.as_str()), "replicate 2's pairs: {show}");
    assert!(!show.contains(record.variants[0].artifacts["pairs"].sha256.as_str()));
}

#[test]
fn a_run_from_an_archived_dataset_gives_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    write_manifest(
        dir.path(),
        "m.toml",
        &MANIFEST.replace("[train]", "[quantize]\nlevels = 64\n\n[train]"),
    );
    let original = run_ok(dir.path(), &["m.toml"]);
    let expected = results(dir.path(), &original);

    let said = ok(
        dir.path(),
        &["dataset", "archive", "--run", "runs/e2e", "--name", "box"],
    );
    assert!(said.starts_with("archived box@1"), "{said}");
    let said = ok(
        dir.path(),
        &["dataset", "archive", "--run", "runs/e2e", "--name", "box"],
    );
    assert!(said.contains("already archived as box@1"), "{said}");
    ok(
        dir.path(),
        &[
            "dataset",
            "archive",
            "--run",
            "runs/e2e",
            "--name",
            "box-levels",
            "--with-levels",
        ],
    );
    let list = ok(dir.path(), &["dataset", "list"]);
    assert!(
        list.contains("box@1") && list.contains("box-levels@1"),
        "{list}"
    );
    let show = ok(dir.path(), &["dataset", "show", "box@1"]);
    assert!(
        show.contains("experiment  e2e (variant base, replicate 1)")
            && show.contains("pairs.parquet"),
        "{show}"
    );
    ok(dir.path(), &["dataset", "verify"]);

    // The run folder goes; the data come back from the archive.
    std::fs::remove_dir_all(dir.path().join("runs")).unwrap();
    write_manifest(dir.path(), "d.toml", &from_dataset("box@1", true));
    let again = run_ok(dir.path(), &["d.toml"]);
    assert_eq!(results(dir.path(), &again), expected, "from box@1");
    let stages: Vec<&str> = again.variants[0]
        .stages
        .iter()
        .map(|s| s.stage.as_str())
        .collect();
    assert_eq!(
        stages,
        [
            "dataset",
            "nominal",
            "quantize",
            "train",
            "test",
            "summarize",
            "plan",
            "circuit"
        ]
    );
    let named = again.dataset.as_ref().unwrap();
    assert_eq!(named.dataset, "box@1");
    let report = std::fs::read_to_string(dir.path().join("runs/e2e/report/report.md")).unwrap();
    assert!(report.contains(&format!("| dataset | box@1 (sha256 `{}`) |", named.sha256)));

    // With levels quantize does not run — and a [quantize] table is refused.
    std::fs::remove_dir_all(dir.path().join("runs")).unwrap();
    write_manifest(dir.path(), "l.toml", &from_dataset("box-levels@1", false));
    let levels = run_ok(dir.path(), &["l.toml"]);
    assert_eq!(results(dir.path(), &levels), expected, "from box-levels@1");
    let stages: Vec<&str> = levels.variants[0]
        .stages
        .iter()
        .map(|s| s.stage.as_str())
        .collect();
    assert_eq!(
        stages,
        [
            "dataset",
            "nominal",
            "train",
            "test",
            "summarize",
            "plan",
            "circuit"
        ]
    );
    write_manifest(dir.path(), "lq.toml", &from_dataset("box-levels@1", true));
    let out = alnlab(dir.path(), &["run", "lq.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("holds quantized levels")
            && stderr(&out).contains("so the quantize stage does not run; remove `quantize`"),
        "{}",
        stderr(&out)
    );

    // Restored files are the archived ones.
    ok(
        dir.path(),
        &["dataset", "restore", "box@1", "--to", "restored"],
    );
    let trajectory = &original.variants[0].artifacts["trajectory"];
    let restored = std::fs::read(dir.path().join("restored/trajectory.mcap")).unwrap();
    assert_eq!(
        alnlab_common::hash::sha256_hex(&restored),
        trajectory.sha256
    );
}

#[test]
fn a_damaged_dataset_is_named_and_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_manifest(dir.path(), "m.toml", MANIFEST);
    run_ok(dir.path(), &["m.toml"]);
    ok(
        dir.path(),
        &["dataset", "archive", "--run", "runs/e2e", "--name", "box"],
    );
    let other = MANIFEST.replace("seed = 11", "seed = 12");
    write_manifest(dir.path(), "o.toml", &other);
    run_ok(dir.path(), &["o.toml"]);
    ok(
        dir.path(),
        &["dataset", "archive", "--run", "runs/e2e", "--name", "other"],
    );

    let archive = alnlab::dataset::Archive::new(&dir.path().join("datasets"));
    let entry = archive.find("box@1").unwrap();
    let pairs = entry.file("pairs").unwrap();
    let object = dir.path().join("datasets/objects").join(&pairs.sha256);
    let mut bytes = std::fs::read(&object).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x20;
    std::fs::write(&object, &bytes).unwrap();
    let before: Vec<(String, Vec<u8>)> = walk(&dir.path().join("datasets"));

    let out = alnlab(dir.path(), &["dataset", "verify"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("dataset box@1: pairs.parquet")
            && err.contains(&format!("expected sha256 {}", pairs.sha256)),
        "{err}"
    );
    let found = alnlab_common::hash::sha256_hex(&bytes);
    assert!(err.contains(&format!("found {found}")), "{err}");
    let listing = String::from_utf8(out.stdout).unwrap();
    assert!(
        listing.contains("DAMAGED  box@1") && listing.contains("ok       other@1"),
        "{listing}"
    );
    ok(dir.path(), &["dataset", "verify", "other"]);

    let out = alnlab(
        dir.path(),
        &["dataset", "restore", "box@1", "--to", "restored"],
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("dataset box@1 is damaged; refusing"),
        "{}",
        stderr(&out)
    );
    assert!(!dir.path().join("restored").exists());

    write_manifest(dir.path(), "d.toml", &from_dataset("box@1", false));
    let out = alnlab(dir.path(), &["run", "d.toml", "--out", "fresh"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("dataset box@1 is damaged"),
        "{}",
        stderr(&out)
    );
    assert!(!dir.path().join("fresh/cache/dataset").exists());

    // Truncated and missing files, and an edited catalog entry.
    let stats = dir
        .path()
        .join("datasets/objects")
        .join(&entry.file("stats").unwrap().sha256);
    std::fs::write(&stats, b"PAR1").unwrap();
    let trajectory = entry.file("trajectory").unwrap();
    std::fs::remove_file(dir.path().join("datasets/objects").join(&trajectory.sha256)).unwrap();
    let out = alnlab(dir.path(), &["dataset", "verify", "box@1"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("trajectory.mcap") && stderr(&out).contains("missing"),
        "{}",
        stderr(&out)
    );
    assert!(stderr(&out).contains("3 problem(s)"), "{}", stderr(&out));

    let catalog = dir.path().join("datasets/catalog.toml");
    let text = std::fs::read_to_string(&catalog).unwrap();
    let other_entry = archive.find("other@1").unwrap();
    std::fs::write(&catalog, text.replace("seed = 12", "seed = 13")).unwrap();
    let out = alnlab(dir.path(), &["dataset", "verify", "other@1"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains(&format!(
            "dataset other@1: catalog.toml: expected sha256 {}",
            other_entry.sha256
        )),
        "{}",
        stderr(&out)
    );
    // Verifying touched nothing: only what this test changed differs.
    let after = walk(&dir.path().join("datasets"));
    let changed: Vec<&String> = before
        .iter()
        .filter(|(path, bytes)| {
            after
                .iter()
                .find(|(p, _)| p == path)
                .is_none_or(|(_, b)| b != bytes)
        })
        .map(|(path, _)| path)
        .collect();
    assert_eq!(
        changed.len(),
        3,
        "stats, trajectory and the catalog: {changed:?}"
    );
}

/// Every file under `dir`, by path, with its bytes.
fn walk(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(walk(&path));
        } else {
            files.push((path.display().to_string(), std::fs::read(&path).unwrap()));
        }
    }
    files.sort();
    files
}

#[test]
fn bad_dataset_names_are_user_errors() {
    let dir = tempfile::tempdir().unwrap();
    for (args, says) in [
        (
            vec!["dataset", "show", "nope@3"],
            "no dataset `nope@3`; the archive",
        ),
        (vec!["dataset", "show", "../up@1"], "no paths"),
        (vec!["dataset", "restore", "a/b", "--to", "x"], "no paths"),
        (vec!["dataset", "verify", "box@one"], "whole version number"),
        (
            vec!["dataset", "archive", "--run", "runs/e2e", "--name", "../x"],
            "no paths",
        ),
        (
            vec!["dataset", "archive", "--run", "nowhere", "--name", "x"],
            "nowhere/run.json",
        ),
    ] {
        let out = alnlab(dir.path(), &args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(says), "{args:?}: {}", stderr(&out));
    }
    write_manifest(dir.path(), "m.toml", &from_dataset("../evil@1", false));
    let out = alnlab(dir.path(), &["run", "m.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("m.toml: [data] dataset: dataset name \"../evil\""),
        "{}",
        stderr(&out)
    );
    // Simulating and taking data from the archive at once is refused.
    let both = format!("{MANIFEST}\n[data]\ndataset = \"box@1\"\n");
    write_manifest(dir.path(), "both.toml", &both);
    let out = alnlab(dir.path(), &["check", "both.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("remove `simulate`"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn the_committed_dataset_verifies_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets");
    let archive = dir.path().join("datasets");
    std::fs::create_dir_all(archive.join("objects")).unwrap();
    std::fs::copy(committed.join("catalog.toml"), archive.join("catalog.toml")).unwrap();
    for entry in std::fs::read_dir(committed.join("objects")).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(
            &path,
            archive.join("objects").join(path.file_name().unwrap()),
        )
        .unwrap();
    }
    let said = ok(dir.path(), &["dataset", "verify"]);
    assert!(said.contains("ok       tiny-worm@1 (3 files)"), "{said}");
    // A real arm's recordings, kept with their licence.
    assert!(said.contains("ok       kuka-lwr4@1 (4 files)"), "{said}");
    write_manifest(dir.path(), "m.toml", &from_dataset("tiny-worm@1", false));
    let record = run_ok(dir.path(), &["m.toml"]);
    assert_eq!(record.dataset.unwrap().dataset, "tiny-worm@1");
    let summary = &record.variants[0].artifacts["summary"];
    let rows = alnlab_summarize::read(&dir.path().join(&summary.path)).unwrap();
    assert!(
        rows.iter().any(|r| r.variable == "roll.2"),
        "the worm's variables"
    );
}

/// A CSV table of `seconds` of the UR5 at 100 Hz: a slow swing of every
/// joint (phase `phase`), its efforts constant.
fn swing(path: &Path, seconds: f64, phase: f64) {
    let mut text = ur5_table_header();
    for k in 0..(seconds * 100.0) as usize {
        let t = k as f64 * 0.01;
        text += &format!("\n{t}");
        for j in 0..UR5_JOINTS.len() {
            let a = t + j as f64 + phase;
            text += &format!(",{},{},{}", 0.3 * a.sin(), 0.3 * a.cos(), 1.0 + j as f64);
        }
    }
    std::fs::write(path, text + "\n").unwrap();
}

#[test]
fn imported_recordings_are_kept_with_their_terms_and_held_out_by_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (k, name) in ["a.csv", "b.csv", "c.csv"].iter().enumerate() {
        swing(&d.join(name), 1.0, k as f64);
    }
    std::fs::write(d.join("LICENCE"), "the terms\n").unwrap();
    std::fs::write(d.join("notes.txt"), "not a table\n").unwrap();
    let import = |source: &str, tables: &[&str]| {
        let mut args = vec![
            "dataset",
            "import",
            "--name",
            "arm",
            "--source",
            source,
            "--citation",
            "Someone, 2026",
            "--licence",
            "CC-BY-4.0",
            "--licence-file",
            "LICENCE",
        ];
        args.extend_from_slice(tables);
        alnlab(d, &args)
    };
    // Kept only with their terms, and only tables.
    let refused = import(" ", &["a.csv"]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(
        stderr(&refused).contains("--source: expected some text"),
        "{}",
        stderr(&refused)
    );
    let refused = import("https://example.org/arm", &["a.csv", "notes.txt"]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(
        stderr(&refused).contains("notes.txt: expected a table of samples"),
        "{}",
        stderr(&refused)
    );
    let out = import("https://example.org/arm", &["a.csv", "b.csv", "c.csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let shown = ok(d, &["dataset", "show", "arm@1"]);
    for said in [
        "source      https://example.org/arm",
        "citation    Someone, 2026",
        "licence     CC-BY-4.0",
        "table       a.csv",
        "licence     LICENCE",
    ] {
        assert!(shown.contains(said), "{said}: {shown}");
    }

    // Three replicates, three folds: replicate k tests table k alone.
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/ur5/ur5_robot.urdf");
    let manifest = format!(
        "[experiment]\nname = \"e2e\"\nseed = 3\nreplicates = 3\n\n[data]\ndataset = \"arm@1\"\n\n\
         [ingest.table]\ntime = \"t\"\n\n[ingest.robot]\nname = \"ur5\"\nkind = \"urdf\"\n\
         file = \"{}\"\ndt = 0.001\nframe_dt = 0.01\n\n[stride]\nn = 1\n\n[quantize]\n\
         levels = 64\n\n[train]\nmodel = \"piecewise-linear\"\ncontrols = \"given\"\n\n\
         [test]\nrun_seconds = 0.000001\n",
        urdf.display()
    );
    write_manifest(d, "m.toml", &manifest);
    let record = run_ok(d, &["m.toml"]);
    assert_eq!(record.dataset.as_ref().unwrap().dataset, "arm@1");
    let files: Vec<&str> = record.tables.iter().map(|t| t.file.as_str()).collect();
    assert_eq!(files, ["arm@1/a.csv", "arm@1/b.csv", "arm@1/c.csv"]);
    for v in &record.variants {
        let pairs = alnlab_tables::pairs::Pairs::read(&d.join(&v.artifacts["pairs"].path)).unwrap();
        for key in pairs.keys() {
            let tested = key.split == alnlab_tables::pairs::Split::Test;
            assert_eq!(
                tested,
                key.run == v.replicate,
                "{key:?} in replicate {}",
                v.replicate
            );
        }
    }
    let report = std::fs::read_to_string(d.join("runs/e2e/report/report.md")).unwrap();
    assert!(report.contains("(the split: by trajectory: whole trajectories held out"));

    // A run's data are not framed, and recordings need their robot.
    ok(
        d,
        &[
            "dataset",
            "archive",
            "--run",
            "runs/e2e",
            "--replicate",
            "1",
            "--name",
            "run",
        ],
    );
    write_manifest(d, "framed.toml", &manifest.replace("arm@1", "run@1"));
    let refused = alnlab(d, &["-q", "run", "framed.toml"]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(
        stderr(&refused).contains("run@1 holds a run's data, not tables of recordings"),
        "{}",
        stderr(&refused)
    );
    let without_robot = manifest[..manifest.find("[ingest.robot]").unwrap()].to_string()
        + &manifest[manifest.find("[stride]").unwrap()..];
    write_manifest(d, "no-robot.toml", &without_robot);
    let refused = alnlab(d, &["-q", "run", "no-robot.toml"]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(
        stderr(&refused).contains("add [ingest.robot]"),
        "{}",
        stderr(&refused)
    );
}
