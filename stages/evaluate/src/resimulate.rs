//! The simulator as a baseline (docs/design.md §7): each test row's frame is
//! stepped forward again from its logged state with `steps` integration
//! steps per frame — the logged step reproduces the log; coarser ones are
//! faster and less accurate, until they blow up — then quantized by the
//! codebook and scored like any prediction, and timed per frame. A frame the
//! coarse simulator cannot step (it blows up) is scored as the worst
//! prediction there is: the level farthest from the truth.

use std::collections::{BTreeMap, HashMap};

use alnlab_codes::Entry;
use alnlab_common::state_log::StateFrame;
use alnlab_common::{Error, ModelId, Result};
use alnlab_physics::replay::{Replayer, SceneReplay};

use crate::rollout::{LoggedFrames, Start};
use crate::timing::Path;

/// One re-simulation baseline's predictions.
pub struct Resimulated {
    /// The model: the simulator at `steps` steps a frame.
    pub model: ModelId,
    /// Predicted levels `[variable][test row]`.
    pub levels: Vec<Vec<u16>>,
    /// Integration steps per frame.
    pub steps: u64,
    /// Frames that blew up.
    pub failed: usize,
}

/// Re-simulates every test row's frame with `steps` steps per frame. `y` are
/// the true next levels `[variable][test row]`.
pub fn baseline(
    frames: &LoggedFrames,
    replays: &BTreeMap<String, SceneReplay>,
    learned: &[&Entry],
    rows: &[Start],
    y: &[Vec<u16>],
    steps: u64,
) -> Result<Resimulated> {
    let (levels, failed) = one_frame(frames, replays, learned, rows, y, steps)?;
    Ok(Resimulated {
        model: ModelId::Simulator { steps },
        levels,
        steps,
        failed,
    })
}

/// The path to time of a re-simulation baseline: every frame re-stepped
/// once, on one thread.
pub fn path<'a>(
    baseline: &Resimulated,
    frames: &'a LoggedFrames,
    replays: &'a BTreeMap<String, SceneReplay>,
    learned: &'a [&'a Entry],
    rows: &'a [Start],
    y: &'a [Vec<u16>],
) -> Path<'a> {
    let steps = baseline.steps;
    Path {
        model: baseline.model,
        path: "single",
        threads: 1,
        states: rows.len(),
        failed: baseline.failed,
        // The levels were checked when the baseline was made; a run that
        // failed now would have failed then.
        run: Box::new(move || {
            let _ = std::hint::black_box(one_frame(frames, replays, learned, rows, y, steps));
        }),
    }
}

/// Re-simulates every test row's frame once with `steps` steps per frame:
/// the levels `[variable][test row]` and how many frames blew up.
pub fn one_frame(
    frames: &LoggedFrames,
    replays: &BTreeMap<String, SceneReplay>,
    learned: &[&Entry],
    rows: &[Start],
    y: &[Vec<u16>],
    steps: u64,
) -> Result<(Vec<Vec<u16>>, usize)> {
    let (levels, failed) = simulate(frames, replays, learned, rows, 1, steps, |v, k, _| y[v][k])?;
    Ok((levels.into_iter().next().expect("one frame ahead"), failed))
}

/// The simulator fed its own frames for `horizon` frames from each start
/// row: levels `[h][variable][start]`, scored against `truth[h][v][s]`.
pub fn rollout(
    frames: &LoggedFrames,
    replays: &BTreeMap<String, SceneReplay>,
    learned: &[&Entry],
    starts: &[Start],
    truth: &[Vec<Vec<u16>>],
    steps: u64,
) -> Result<Vec<Vec<Vec<u16>>>> {
    let horizon = truth.len();
    let (levels, _) = simulate(
        frames,
        replays,
        learned,
        starts,
        horizon,
        steps,
        |v, k, h| truth[h][v][k],
    )?;
    Ok(levels)
}

/// Steps each row's logged frame `horizon` frames on, each from the last:
/// levels `[h][v][row]`, and the rows that blew up (whose levels from then on
/// are the farthest from `truth(v, row, h)`).
fn simulate(
    frames: &LoggedFrames,
    replays: &BTreeMap<String, SceneReplay>,
    learned: &[&Entry],
    rows: &[Start],
    horizon: usize,
    steps: u64,
    truth: impl Fn(usize, usize, usize) -> u16,
) -> Result<(Vec<Vec<Vec<u16>>>, usize)> {
    // In time order within each run, so each run's controller mostly moves
    // forward.
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by_key(|&k| (rows[k].scene, rows[k].run, rows[k].frame));
    let mut replayers: HashMap<&str, Replayer> = replays
        .iter()
        .map(|(name, r)| (name.as_str(), r.replayer()))
        .collect();
    let mut levels = vec![vec![vec![0u16; rows.len()]; learned.len()]; horizon];
    let mut next = StateFrame::default();
    let mut failed = 0;
    for k in order {
        let row = &rows[k];
        let missing = || {
            Error::Invalid(format!(
                "test row of scene `{}`, run {}, frame {} is not in the trajectory log",
                row.scene, row.run, row.frame
            ))
        };
        let mut current = frames.get(row, 0).ok_or_else(missing)?.clone();
        let replayer = replayers.get_mut(row.scene).ok_or_else(missing)?;
        let mut blown = false;
        for (h, at_h) in levels.iter_mut().enumerate() {
            if !blown {
                // Only a blow-up scores as one; a log that does not fit its
                // model is an error.
                match replayer.next_frame(&current, steps, &mut next) {
                    Ok(()) => {}
                    Err(Error::Diverged(_)) => blown = true,
                    Err(e) => return Err(e),
                }
            }
            for (v, entry) in learned.iter().enumerate() {
                // A blown-up frame was not written: score it the farthest.
                let level = (!blown)
                    .then(|| frames.level(row.scene, &next, v, entry))
                    .flatten();
                at_h[v][k] =
                    level.unwrap_or_else(|| farthest(truth(v, k, h), entry.quantizer.levels));
            }
            std::mem::swap(&mut current, &mut next);
        }
        failed += usize::from(blown);
    }
    Ok((levels, failed))
}

/// The level farthest from `truth` among `levels` levels.
pub fn farthest(truth: u16, levels: usize) -> u16 {
    let top = (levels - 1) as u16;
    if truth >= top - truth { 0 } else { top }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_blown_up_frame_scores_the_worst_error() {
        assert_eq!(farthest(3, 10), 9);
        assert_eq!(farthest(7, 10), 0);
        assert_eq!(farthest(0, 2), 1);
    }
}
