//! End-to-end tests of running an experiment in pieces: one stage at a time
//! (`run --until`), training in shards (`run --train-shard`, `train --shard`)
//! merged into the model one process would have trained.

use std::path::Path;

use alnlab::records::RunRecord;

use crate::common::{MANIFEST, alnlab, run_ok, stderr, write_manifest};

fn ok(dir: &Path, args: &[&str]) -> String {
    let out = alnlab(dir, args);
    assert!(out.status.success(), "alnlab {args:?}: {}", stderr(&out));
    String::from_utf8(out.stdout).unwrap()
}

fn bytes(dir: &Path, record: &RunRecord, role: &str) -> Vec<u8> {
    std::fs::read(dir.join(&record.variants[0].artifacts[role].path)).unwrap()
}

#[test]
fn shards_trained_apart_merge_into_the_model_of_one_process() {
    let dir = tempfile::tempdir().unwrap();
    write_manifest(dir.path(), "m.toml", MANIFEST);
    let whole = run_ok(dir.path(), &["m.toml", "--out", "whole"]);

    // Stage by stage: no run record until the end.
    ok(
        dir.path(),
        &[
            "-q", "run", "m.toml", "--out", "parts", "--until", "quantize",
        ],
    );
    assert!(!dir.path().join("parts/e2e/run.json").exists());
    for k in 1..=3 {
        let said = ok(
            dir.path(),
            &[
                "-q",
                "run",
                "m.toml",
                "--out",
                "parts",
                "--train-shard",
                &format!("{k}/3"),
            ],
        );
        assert!(
            said.starts_with(&format!("shard {k}/3 of `base`")),
            "{said}"
        );
    }
    // A finished shard is not trained again.
    ok(
        dir.path(),
        &[
            "-q",
            "run",
            "m.toml",
            "--out",
            "parts",
            "--train-shard",
            "2/3",
        ],
    );
    let shards = dir.path().join("parts/shards/train");
    assert_eq!(std::fs::read_dir(&shards).unwrap().count(), 1);
    let merged = run_ok(dir.path(), &["m.toml", "--out", "parts"]);
    let train = merged.variants[0]
        .stages
        .iter()
        .find(|s| s.stage == "train")
        .unwrap();
    assert!(!train.cached, "the train artifact was made, by merging");
    let whole_train = whole.variants[0].stages.iter().find(|s| s.stage == "train");
    assert_eq!(train.cache_key, whole_train.unwrap().cache_key);
    for role in ["model", "predictions", "summary", "horizons"] {
        assert!(
            bytes(dir.path(), &merged, role) == bytes(dir.path(), &whole, role),
            "{role}"
        );
    }
    assert_eq!(
        std::fs::read_dir(&shards).unwrap().count(),
        0,
        "merged shards are cleared"
    );

    // The stage alone: train --shard and merge-models.
    let quantize = &whole.variants[0].artifacts;
    let (codebook, levels) = (&quantize["codebook"].path, &quantize["levels"].path);
    let (pairs, nominal) = (&quantize["pairs"].path, &quantize["nominal"].path);
    for k in 1..=2 {
        let out = format!("s{k}");
        let shard = format!("{k}/2");
        ok(
            dir.path(),
            &[
                "-q",
                "train",
                "--manifest",
                "m.toml",
                "--codebook",
                codebook,
                "--levels",
                levels,
                "--pairs",
                pairs,
                "--nominal",
                nominal,
                "--shard",
                &shard,
                "--out",
                &out,
            ],
        );
    }
    ok(dir.path(), &["merge-models", "s2", "s1", "--out", "merged"]);
    let model = std::fs::read(dir.path().join("merged/model.aln")).unwrap();
    assert!(model == bytes(dir.path(), &whole, "model"));
    let log =
        alnlab_common::table::Table::read(&dir.path().join("merged/training.parquet")).unwrap();
    let whole_log =
        alnlab_common::table::Table::read(&dir.path().join(&quantize["training"].path)).unwrap();
    assert_eq!(log.num_rows(), whole_log.num_rows());
    assert_eq!(
        log.strings("variable").unwrap(),
        whole_log.strings("variable").unwrap()
    );
    // The same provenance; the files' checksums differ with their measured
    // `seconds` column.
    let provenance = |t: &alnlab_common::table::Table| {
        let mut m = t.metadata.clone();
        m.remove(alnlab_common::table::CHECKSUM_KEY);
        m
    };
    assert_eq!(
        provenance(&log),
        provenance(&whole_log),
        "the same provenance"
    );

    // Bad shards are user errors that say what is wrong.
    for (args, says) in [
        (
            vec!["merge-models", "s1", "--out", "x"],
            "shard(s) 2/2 missing",
        ),
        (
            vec!["merge-models", "s1", "s1", "--out", "x"],
            "repeats shard 1/2",
        ),
        (
            vec!["merge-models", "merged", "--out", "x"],
            "is a whole model",
        ),
        (
            vec!["run", "m.toml", "--train-shard", "0/2"],
            "expected K/N with 1 ≤ K ≤ N",
        ),
        (
            vec!["run", "m.toml", "--train-shard", "1/2", "--until", "test"],
            "cannot be used with",
        ),
    ] {
        let out = alnlab(dir.path(), &args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(says), "{args:?}: {}", stderr(&out));
    }
    let two = format!(
        "{MANIFEST}\n[[variant]]\nname = \"a\"\n\n[[variant]]\nname = \"b\"\ntrain.leaves = 32\n"
    );
    write_manifest(dir.path(), "two.toml", &two);
    let out = alnlab(dir.path(), &["run", "two.toml", "--train-shard", "1/2"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("--train-shard needs --variant: the manifest has a, b"),
        "{}",
        stderr(&out)
    );
}
