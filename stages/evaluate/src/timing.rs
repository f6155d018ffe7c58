//! Timing the models fairly: every model on one thread (the ALN's batches
//! also on all threads, labelled), each path run [`REPEATS`] times, and the
//! runs interleaved — round k times every path once — so that a burst of
//! load on the machine falls on one round of every model, not on all runs
//! of one. A path's figure is the median of its runs with their range; two
//! paths compare run by run, round by round ([`Timing::runs`]). A run
//! repeats its path until it has taken at least [`RUN_SECONDS`] (by
//! default; `[test] run_seconds`), how many times settled by an untimed
//! warm-up run, so that a short path is not at the mercy of one scheduler
//! blip.

use std::time::Instant;

use alnlab_common::ModelId;
use serde::Serialize;

/// How many timed runs every evaluation path gets.
pub const REPEATS: usize = 5;

/// The least time one timed run takes by default (s): a path quicker than
/// this is repeated within the run.
pub const RUN_SECONDS: f64 = 0.05;

/// Nanoseconds per state over the timed runs of one path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Spread {
    pub min: f64,
    pub median: f64,
    pub max: f64,
}

impl Spread {
    /// The spread of `runs` (at least one).
    pub fn of(runs: &[f64]) -> Spread {
        let mut sorted = runs.to_vec();
        sorted.sort_by(f64::total_cmp);
        Spread {
            min: sorted[0],
            median: sorted[sorted.len() / 2],
            max: sorted[sorted.len() - 1],
        }
    }
}

/// One measured evaluation path.
#[derive(Clone, Debug, PartialEq)]
pub struct Timing {
    pub model: ModelId,
    /// `batched`, `single` or `threshold-search`.
    pub path: &'static str,
    /// ns per state of each run, in round order.
    pub runs: Vec<f64>,
    /// States timed.
    pub states: usize,
    pub threads: usize,
    /// States the model could not predict (a re-simulation that blew up).
    pub failed: usize,
}

impl Timing {
    /// Median and range of the runs.
    pub fn spread(&self) -> Spread {
        Spread::of(&self.runs)
    }
}

/// An evaluation path to time: what [`Timing`] will say of it, and a run.
pub struct Path<'a> {
    pub model: ModelId,
    pub path: &'static str,
    pub threads: usize,
    pub states: usize,
    pub failed: usize,
    /// One run of the path over every state.
    pub run: Box<dyn FnMut() + 'a>,
}

/// Times `paths` in `repeats` interleaved rounds, after a warm-up run of
/// each that settles how many times a run repeats it: enough to take at
/// least `run_seconds`.
pub fn in_rounds(mut paths: Vec<Path>, repeats: usize, run_seconds: f64) -> Vec<Timing> {
    let times: Vec<usize> = paths
        .iter_mut()
        .map(|path| {
            let clock = Instant::now();
            (path.run)();
            let once = clock.elapsed().as_secs_f64().max(1e-9);
            ((run_seconds / once).ceil() as usize).clamp(1, 1_000_000)
        })
        .collect();
    let mut runs = vec![Vec::with_capacity(repeats); paths.len()];
    for _ in 0..repeats.max(1) {
        for ((path, runs), &times) in paths.iter_mut().zip(&mut runs).zip(&times) {
            let clock = Instant::now();
            for _ in 0..times {
                (path.run)();
            }
            let states = (path.states * times).max(1);
            runs.push(clock.elapsed().as_nanos() as f64 / states as f64);
        }
    }
    paths
        .into_iter()
        .zip(runs)
        .map(|(p, runs)| Timing {
            model: p.model,
            path: p.path,
            runs,
            states: p.states,
            threads: p.threads,
            failed: p.failed,
        })
        .collect()
}

/// Runs `f` `repeats` times (at least once), timing each run: the last
/// run's result and the spread of the runs in ns per each of `states`.
pub fn measure<T>(repeats: usize, states: usize, mut f: impl FnMut() -> T) -> (T, Spread) {
    let mut out = None;
    let runs: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let clock = Instant::now();
            out = Some(f());
            clock.elapsed().as_nanos() as f64 / states.max(1) as f64
        })
        .collect();
    (out.expect("at least one run"), Spread::of(&runs))
}

/// A rayon pool of one thread: every model is timed on one thread, so
/// that their times compare.
pub fn one_thread() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a thread pool of one thread")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounds_interleave_every_path_and_spreads_are_ordered() {
        let order = std::cell::RefCell::new(Vec::new());
        let path = |name: &'static str| Path {
            model: match name {
                "a" => ModelId::Aln,
                _ => ModelId::Linear,
            },
            path: "single",
            threads: 1,
            states: 10,
            failed: 0,
            run: Box::new({
                let order = &order;
                move || order.borrow_mut().push(name)
            }),
        };
        let timings = in_rounds(vec![path("a"), path("b")], 3, RUN_SECONDS);
        // A warm-up run of each, then rounds of a then b (each run repeated
        // to fill its time: these paths take no time at all).
        let order = order.borrow();
        assert_eq!(order[..2], ["a", "b"]);
        let a = order[2..].iter().take_while(|&&n| n == "a").count();
        let b = order[2 + a..].iter().take_while(|&&n| n == "b").count();
        assert!(a > 1 && b > 1, "a run repeats a quick path");
        let round: Vec<&str> = [vec!["a"; a], vec!["b"; b]].concat();
        assert_eq!(order[2..], round.repeat(3)[..]);
        for t in &timings {
            assert_eq!(t.runs.len(), 3);
            let s = t.spread();
            assert!(s.min <= s.median && s.median <= s.max);
        }
        let s = Spread::of(&[3.0, 1.0, 2.0]);
        assert_eq!((s.min, s.median, s.max), (1.0, 2.0, 3.0));
    }
}
