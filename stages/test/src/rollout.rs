//! Closed-loop rollout: from the true levels of a test row, each model is fed
//! its own predictions for H steps, and its levels at every horizon are
//! scored against the true trajectory — the logged frames that follow,
//! quantized by the codebook. A one-step error says little about a predictor
//! that is to replace a simulator; the growth of the error with the horizon
//! does.

use std::collections::HashMap;

use alnlab_common::state_log::StateLog;
use alnlab_quantize::Entry;

/// The true levels after each step from a set of start rows.
pub struct Truth {
    /// The starts: indices of the test rows (in test-row order).
    pub starts: Vec<usize>,
    /// `levels[h][v][s]`: variable v's true level h + 1 steps after start s.
    pub levels: Vec<Vec<Vec<u16>>>,
}

/// Where a test row starts: its scene, run and frame.
pub struct Start<'a> {
    pub scene: &'a str,
    pub run: u32,
    pub frame: u32,
}

/// The true levels for up to `most` starts, spread evenly over the test rows
/// whose next `horizon` frames are in the log (a start too close to the end
/// of its run, or in a scene lacking a learned variable, is left out).
pub fn truth(
    log: &StateLog,
    learned: &[&Entry],
    rows: &[Start],
    horizon: usize,
    most: usize,
) -> Truth {
    // (scene, run, frame) → the frame's variables; per scene, where each
    // learned variable sits in them.
    let mut frames = HashMap::new();
    let mut columns = HashMap::new();
    for scene in &log.scenes {
        let names = &scene.layout.variables;
        let found: Option<Vec<usize>> = learned
            .iter()
            .map(|e| names.iter().position(|n| *n == e.variable))
            .collect();
        if let Some(found) = found {
            columns.insert(scene.layout.scene.as_str(), found);
            for f in &scene.frames {
                frames.insert((scene.layout.scene.as_str(), f.run, f.frame), &f.variables);
            }
        }
    }
    let eligible: Vec<usize> = rows
        .iter()
        .enumerate()
        .filter(|(_, r)| {
            (1..=horizon as u32).all(|h| frames.contains_key(&(r.scene, r.run, r.frame + h)))
        })
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
                            let values = frames[&(r.scene, r.run, r.frame + h)];
                            entry.quantizer.level(values[columns[r.scene][v]]).0
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
