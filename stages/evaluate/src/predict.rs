//! Predicting the test rows with a trained model, timed per evaluation path.
//!
//! A bit-forest predicts bit-sliced in batches (all rows at once, on all
//! threads — the levels come from this path) and one row at a time
//! (parsimonious chains), which must agree; a threshold model's binary
//! search runs for all rows at once, bit-sliced (`batched`), and one row at
//! a time (`threshold-search`), which must agree too. Times are for encoded inputs to decoded
//! levels: the trees, the votes and the decoding (with rate limiting, when
//! on, as `decode_near` around the current level).

use alnlab_aln::runtime::Runtime;
use alnlab_common::ModelId;

use crate::timing::Path;

/// The levels of every row, checked equal on every evaluation path: the
/// batched path on one thread (in `pool`) and on all, and the one-row
/// path (a bit-forest's bit-sliced and parsimonious evaluation, a
/// threshold model's batched and one-row searches).
pub fn levels(
    runtime: &Runtime,
    x: &[Vec<u16>],
    windows: Option<&[usize]>,
    pool: &rayon::ThreadPool,
) -> Vec<Vec<u16>> {
    let levels = runtime.levels(x, windows);
    assert_eq!(
        pool.install(|| runtime.levels(x, windows)),
        levels,
        "batches on one and on all threads disagree"
    );
    let inputs = runtime.encode(x);
    assert_eq!(
        runtime.one_row(x, &inputs, windows),
        levels,
        "the one-row and batched paths disagree"
    );
    levels
}

/// Every evaluation path to time: the batched path on one thread (in
/// `pool`) and, labelled, on all threads when there are more; the one-row
/// path.
pub fn paths<'s>(
    runtime: &'s Runtime,
    x: &'s [Vec<u16>],
    windows: Option<&'s [usize]>,
    pool: &'s rayon::ThreadPool,
) -> Vec<Path<'s>> {
    let inputs = runtime.encode(x);
    let rows = inputs.rows();
    let path = |path, threads, run: Box<dyn FnMut() + 's>| Path {
        model: ModelId::Aln,
        path,
        threads,
        states: rows,
        failed: 0,
        run,
    };
    let mut paths = vec![path(
        "batched",
        1,
        Box::new(move || {
            std::hint::black_box(pool.install(|| runtime.levels(x, windows)));
        }),
    )];
    let threads = rayon::current_num_threads();
    if threads > 1 {
        paths.push(path(
            "batched",
            threads,
            Box::new(move || {
                std::hint::black_box(runtime.levels(x, windows));
            }),
        ));
    }
    paths.push(path(
        runtime.one_row_path(),
        1,
        Box::new(move || {
            std::hint::black_box(runtime.one_row(x, &inputs, windows));
        }),
    ));
    paths
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_aln::model::Header;
    use alnlab_aln::model::Model;
    use alnlab_aln::shard::Shard;
    use alnlab_aln::tree::TreeSpec;
    use alnlab_aln::{ModelKind, Output, Target};
    use alnlab_codes::bits::{Columns, encode};
    use alnlab_codes::codes::{Code, Codec};
    use alnlab_codes::walk::WalkSpec;
    use alnlab_train::forest;

    /// A forest (vote 3) trained on y = x + 1 over 64 walk-coded levels, and
    /// its codec.
    fn successor_model() -> (Model, Codec) {
        let spec = WalkSpec {
            levels: 64,
            width: 23,
            step: 1,
            span: 7,
            seed: 3,
        };
        let codec = Codec::new(Code::Walk, 64, Some(spec)).unwrap();
        let x: Vec<u16> = (0..800).map(|i| (i * 37 % 63) as u16).collect();
        let y: Vec<u16> = x.iter().map(|v| v + 1).collect();
        let all: Vec<usize> = (0..800).collect();
        let inputs = Columns::from_rows(&encode(&[&codec], &[&x]), &all);
        let targets = [Columns::from_rows(&encode(&[&codec], &[&y]), &all)];
        let tree = TreeSpec {
            leaves: 512,
            inputs: 23,
            counter_bound: 3,
            initial_spread: 1,
        };
        let trained = forest::train(
            &tree,
            10,
            3,
            1,
            Shard::ALL,
            &inputs,
            &targets,
            &forest::every_bit(23, 1),
            &|| {},
        );
        let header = Header {
            codebook_sha256: String::new(),
            params: serde_json::Value::Null,
            model: ModelKind::BitForest,
            target: Target::Level,
            inputs: 23,
            outputs: vec![("v".into(), 23)],
            reads: Vec::new(),
            vote: 3,
            counter_bound: 3,
            shard: None,
            base: alnlab_aln::model::Base::Current,
        };
        let trees = trained.into_iter().map(|t| (t.id, t.tree)).collect();
        let pieces = Vec::new();
        (
            Model {
                header,
                trees,
                pieces,
            },
            codec,
        )
    }

    #[test]
    fn both_paths_predict_the_successor_and_rate_limits_hold() {
        let (model, codec) = successor_model();
        let x = vec![(0..63u16).rev().collect::<Vec<_>>()];
        // (The two paths' levels are compared inside.)
        let codecs = std::slice::from_ref(&codec);
        let outputs = [Output::Level(codec.clone())];
        let aln = Runtime::new(&model, codecs, &outputs).unwrap();
        let pool = crate::timing::one_thread();
        let levels = super::levels(&aln, &x, None, &pool);
        let paths = super::paths(&aln, &x, None, &pool);
        let timings = crate::timing::in_rounds(paths, 2, crate::timing::RUN_SECONDS);
        let error: usize = levels[0]
            .iter()
            .zip(&x[0])
            .map(|(&p, &c)| p.abs_diff(c + 1) as usize)
            .sum();
        assert!(
            error as f64 / 63.0 <= 1.0,
            "mean error {}",
            error as f64 / 63.0
        );
        // Every path on one thread; the batches on all threads too, labelled.
        let paths: Vec<(&str, usize)> = timings.iter().map(|t| (t.path, t.threads)).collect();
        let threads = rayon::current_num_threads();
        let mut expected = vec![("batched", 1)];
        if threads > 1 {
            expected.push(("batched", threads));
        }
        expected.push(("single", 1));
        assert_eq!(paths, expected);
        assert!(
            timings
                .iter()
                .all(|t| t.runs.len() == 2 && t.runs.iter().all(|&ns| ns > 0.0) && t.states == 63)
        );

        // Rate limited to 0 levels: nothing moves.
        let still = super::levels(&aln, &x, Some(&[0]), &pool);
        assert_eq!(
            aln.levels(&x, None),
            levels,
            "the fast path alone gives the same levels"
        );
        assert_eq!(still, x);
    }
}
