//! The corruption sweep: single flipped bytes, spread over every kind of
//! artifact. A stage given a damaged file alone must refuse it, naming the
//! file (exit 1; 2 where the flip breaks a model's or log's magic, which
//! makes it another kind of file); `alnlab run` over a cache holding it must notice and make it again,
//! giving outputs identical to the undamaged run's (measured columns aside).

use std::path::Path;

use alnlab::records::RunRecord;

use crate::common::{TINY, alnlab, artifact_bytes, stderr};

/// Positions per artifact: spread evenly from the first byte to the last.
const POSITIONS: usize = 20;

/// A damaged input, the stage that reads it, and its other inputs.
type Reader<'a> = (&'a str, &'a str, Vec<(&'a str, String)>);

fn run(dir: &Path) -> RunRecord {
    let out = alnlab(dir, &["-q", "run", "tiny.toml", "--reports", "reports"]);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_slice(&std::fs::read(dir.join("runs/tiny/run.json")).unwrap()).unwrap()
}

/// The `i`th of `POSITIONS` positions spread over a file of `len` bytes.
fn position(i: usize, len: usize) -> usize {
    i * (len - 1) / (POSITIONS - 1)
}

fn flip(path: &Path, at: usize) -> Vec<u8> {
    let original = std::fs::read(path).unwrap();
    let mut bytes = original.clone();
    bytes[at] ^= 0x01;
    std::fs::write(path, bytes).unwrap();
    original
}

#[test]
#[ignore = "full suite: remakes a tiny run once per damaged file (about 2.5 minutes)"]
fn every_flipped_byte_is_refused_or_remade() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("tiny.toml"), TINY).unwrap();
    let record = run(d);
    let intact = artifact_bytes(d, &record);
    let artifacts = &record.variants[0].artifacts;
    let path = |role: &str| d.join(&artifacts[role].path);
    let kinds: Vec<String> = artifacts.keys().cloned().collect();
    assert_eq!(kinds.len(), 24, "{kinds:?}");

    // Through the cache: every kind.
    let mut trials = 0;
    for role in &kinds {
        let file = path(role);
        for i in 0..POSITIONS {
            // Re-read the length: a remade file holding measured columns
            // (timings) may differ in size from the one damaged before.
            let len = std::fs::metadata(&file).unwrap().len() as usize;
            let at = position(i, len);
            flip(&file, at);
            let again = run(d);
            assert_eq!(
                artifact_bytes(d, &again),
                intact,
                "{role}: a flip at byte {at} of {len} changed the outputs"
            );
            trials += 1;
        }
    }
    assert_eq!(trials, kinds.len() * POSITIONS);

    // To a stage alone: every kind a stage reads.
    let s = |p: &Path| p.to_string_lossy().into_owned();
    // (the damaged input, the stage reading it, its other inputs intact)
    let readers: [Reader; 12] = [
        ("trajectory", "stride", vec![]),
        ("trajectory", "nominal", vec![("pairs", s(&path("pairs")))]),
        (
            "pairs",
            "nominal",
            vec![("trajectory", s(&path("trajectory")))],
        ),
        ("pairs", "quantize", vec![("stats", s(&path("stats")))]),
        ("stats", "quantize", vec![("pairs", s(&path("pairs")))]),
        (
            "levels",
            "train",
            vec![
                ("codebook", s(&path("codebook"))),
                ("pairs", s(&path("pairs"))),
                ("nominal", s(&path("nominal"))),
            ],
        ),
        (
            "codebook",
            "train",
            vec![
                ("levels", s(&path("levels"))),
                ("pairs", s(&path("pairs"))),
                ("nominal", s(&path("nominal"))),
            ],
        ),
        (
            "model",
            "test",
            vec![
                ("trajectory", s(&path("trajectory"))),
                ("codebook", s(&path("codebook"))),
                ("levels", s(&path("levels"))),
                ("pairs", s(&path("pairs"))),
                ("nominal", s(&path("nominal"))),
            ],
        ),
        (
            "trajectory",
            "test",
            vec![
                ("model", s(&path("model"))),
                ("codebook", s(&path("codebook"))),
                ("levels", s(&path("levels"))),
                ("pairs", s(&path("pairs"))),
                ("nominal", s(&path("nominal"))),
            ],
        ),
        (
            "nominal",
            "test",
            vec![
                ("trajectory", s(&path("trajectory"))),
                ("model", s(&path("model"))),
                ("codebook", s(&path("codebook"))),
                ("levels", s(&path("levels"))),
                ("pairs", s(&path("pairs"))),
            ],
        ),
        (
            "predictions",
            "summarize",
            vec![("rollout", s(&path("rollout")))],
        ),
        (
            "rollout",
            "summarize",
            vec![("predictions", s(&path("predictions")))],
        ),
    ];
    for (role, stage, others) in readers {
        let copy = d.join(format!("damaged-{role}"));
        let len = std::fs::metadata(path(role)).unwrap().len() as usize;
        for at in (0..POSITIONS).map(|i| position(i, len)) {
            std::fs::copy(path(role), &copy).unwrap();
            flip(&copy, at);
            let out_dir = d.join("alone");
            let mut args = vec![stage.to_string(), "--manifest".into(), "tiny.toml".into()];
            args.extend([format!("--{role}"), s(&copy)]);
            for (other, p) in &others {
                args.extend([format!("--{other}"), p.clone()]);
            }
            args.extend(["--out".into(), s(&out_dir)]);
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let out = alnlab(d, &args);
            let err = stderr(&out);
            // A model's or log's first byte is its format's magic: without
            // it the file is another kind of file (the user's to fix, 2).
            // Anywhere else — and anywhere in a table, whose checksum in its
            // footer says alnlab wrote it — it is damaged (1).
            let table = path(role).extension().is_some_and(|e| e == "parquet");
            let code = if at == 0 && !table { 2 } else { 1 };
            assert!(
                out.status.code() == Some(code) && err.contains(&format!("damaged-{role}")),
                "{stage} with {role} flipped at byte {at} of {len}: exit {:?}, want {code}: {err}",
                out.status.code()
            );
            let left = std::fs::read_dir(&out_dir).map_or(0, |e| e.count());
            assert_eq!(left, 0, "{stage} wrote outputs from a damaged {role}");
        }
    }
}
