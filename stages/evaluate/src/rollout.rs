//! Closed-loop rollout: from the true levels of a test row, each model is fed
//! its own predictions for H steps, and its levels at every horizon are
//! scored against the true trajectory — the logged frames that follow,
//! quantized by the codebook. A one-step error says little about a predictor
//! that is to replace a simulator; the growth of the error with the horizon
//! does.

use std::collections::HashMap;

use alnlab_codes::Entry;
use alnlab_common::state_log::{StateFrame, StateLog};

/// The true levels after each step from a set of start rows.
pub struct Truth {
    /// The starts: indices of the test rows (in test-row order).
    pub starts: Vec<usize>,
    /// `levels[h][v][s]`: variable v's true level h + 1 steps after start s.
    pub levels: Vec<Vec<Vec<u16>>>,
}

/// Where a test row starts: its scene, run and frame.
#[derive(Clone, Copy, Debug)]
pub struct Start<'a> {
    pub scene: &'a str,
    pub run: u32,
    pub frame: u32,
}

/// The frames of a trajectory log by (scene, run, frame), and where each
/// learned variable sits among each scene's variables.
pub struct LoggedFrames<'a> {
    frames: HashMap<(&'a str, u32, u32), &'a StateFrame>,
    columns: HashMap<&'a str, Vec<Option<usize>>>,
}

impl<'a> LoggedFrames<'a> {
    /// Indexes `log` for the `learned` variables.
    pub fn new(log: &'a StateLog, learned: &[&Entry]) -> LoggedFrames<'a> {
        let mut frames = HashMap::new();
        let mut columns = HashMap::new();
        for scene in &log.scenes {
            let name = scene.layout.scene.as_str();
            let names = &scene.layout.variables;
            let found = learned
                .iter()
                .map(|e| names.iter().position(|n| *n == e.variable));
            columns.insert(name, found.collect());
            for f in &scene.frames {
                frames.insert((name, f.run, f.frame), f);
            }
        }
        LoggedFrames { frames, columns }
    }

    /// The frame `after` frames after a row's, if logged.
    pub fn get(&self, row: &Start, after: u32) -> Option<&'a StateFrame> {
        self.frames
            .get(&(row.scene, row.run, row.frame + after))
            .copied()
    }

    /// The level of learned variable `v` in a frame of `scene`, if the scene
    /// has the variable.
    pub fn level(&self, scene: &str, frame: &StateFrame, v: usize, entry: &Entry) -> Option<u16> {
        Some(entry.quantizer.level(self.value(scene, frame, v)?).0)
    }

    /// The real value of learned variable `v` in a frame of `scene`, if
    /// the scene has the variable.
    pub fn value(&self, scene: &str, frame: &StateFrame, v: usize) -> Option<f64> {
        let column = self.columns.get(scene)?[v]?;
        Some(frame.variables[column])
    }
}

/// The true levels for up to `most` starts, spread evenly over the test rows
/// whose next `horizon` frames are in the log (a start too close to the end
/// of its run, or in a scene lacking a learned variable, is left out).
pub fn truth(
    frames: &LoggedFrames,
    learned: &[&Entry],
    rows: &[Start],
    horizon: usize,
    most: usize,
) -> Truth {
    let scored = |r: &Start, h: u32| {
        frames.get(r, h).is_some_and(|f| {
            (0..learned.len()).all(|v| frames.level(r.scene, f, v, learned[v]).is_some())
        })
    };
    let eligible: Vec<usize> = rows
        .iter()
        .enumerate()
        .filter(|(_, r)| (1..=horizon as u32).all(|h| scored(r, h)))
        .map(|(k, _)| k)
        .collect();
    let take = most.min(eligible.len());
    let starts: Vec<usize> = (0..take)
        .map(|i| eligible[i * eligible.len() / take])
        .collect();
    let levels = (1..=horizon as u32)
        .map(|h| {
            learned
                .iter()
                .enumerate()
                .map(|(v, entry)| {
                    starts
                        .iter()
                        .map(|&k| {
                            let r = &rows[k];
                            let frame = frames.get(r, h).expect("eligible");
                            frames.level(r.scene, frame, v, entry).expect("eligible")
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    Truth { starts, levels }
}

/// Rolls a model out: `step` maps current levels `[v][s]` to the next;
/// returns the levels after each of `horizon` steps, `[h][v][s]`.
pub fn roll(
    start: Vec<Vec<u16>>,
    horizon: usize,
    mut step: impl FnMut(&[Vec<u16>]) -> Vec<Vec<u16>>,
) -> Vec<Vec<Vec<u16>>> {
    let mut current = start;
    (0..horizon)
        .map(|_| {
            current = step(&current);
            current.clone()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rollout_feeds_each_step_its_own_output() {
        let levels = roll(vec![vec![1, 5]], 3, |x| {
            vec![x[0].iter().map(|l| l * 2).collect()]
        });
        assert_eq!(
            levels,
            [vec![vec![2, 10]], vec![vec![4, 20]], vec![vec![8, 40]]]
        );
    }
}
