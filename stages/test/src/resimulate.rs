//! The simulator as a baseline (DESIGN.md §7): each test row's frame is
//! stepped forward again from its logged state with `steps` integration
//! steps per frame — the logged step reproduces the log; coarser ones are
//! faster and less accurate, until they blow up — then quantized by the
//! codebook and scored like any prediction, and timed per frame. A frame the
//! coarse simulator cannot step (it blows up) is scored as the worst
//! prediction there is: the level farthest from the truth.

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use alnlab_common::state_log::{StateFrame, StateLog};
use alnlab_common::{Error, Result};
use alnlab_quantize::Entry;
use alnlab_simulate::replay::{Replayer, SceneReplay};

use crate::predict::Timing;
use crate::rollout::Start;

/// One re-simulation baseline's predictions.
pub struct Resimulated {
    /// The model's name: `simulator@<steps>/frame`.
    pub name: String,
    /// Predicted levels `[variable][test row]`.
    pub levels: Vec<Vec<u16>>,
    /// Its time per frame, and the frames that blew up.
    pub timing: Timing,
}

/// Re-simulates every test row's frame with `steps` steps per frame. `y` are
/// the true next levels `[variable][test row]`.
pub fn baseline(
    log: &StateLog,
    replays: &BTreeMap<String, SceneReplay>,
    learned: &[&Entry],
    rows: &[Start],
    y: &[Vec<u16>],
    steps: u64,
) -> Result<Resimulated> {
    let mut frames: HashMap<(&str, u32, u32), &StateFrame> = HashMap::new();
    let mut columns: HashMap<&str, Vec<Option<usize>>> = HashMap::new();
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
    // In time order within each run, so each run's controller only moves
    // forward.
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by_key(|&k| (rows[k].scene, rows[k].run, rows[k].frame));
    let mut replayers: HashMap<&str, Replayer> = replays
        .iter()
        .map(|(name, r)| (name.as_str(), r.replayer()))
        .collect();
    let mut levels = vec![vec![0u16; rows.len()]; learned.len()];
    let mut next = StateFrame {
        time: 0.0,
        run: 0,
        frame: 0,
        state: Vec::new(),
        variables: Vec::new(),
    };
    let mut failed = 0;
    let clock = Instant::now();
    for k in order {
        let row = &rows[k];
        let from = frames
            .get(&(row.scene, row.run, row.frame))
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "test row of scene `{}`, run {}, frame {} is not in the trajectory log",
                    row.scene, row.run, row.frame
                ))
            })?;
        let replayer = replayers.get_mut(row.scene).ok_or_else(|| {
            Error::Invalid(format!(
                "scene `{}` is not in the trajectory log",
                row.scene
            ))
        })?;
        let stepped = replayer.next_frame(from, steps, &mut next);
        for (v, entry) in learned.iter().enumerate() {
            levels[v][k] = match (&stepped, columns[row.scene][v]) {
                (Ok(()), Some(c)) => entry.quantizer.level(next.variables[c]).0,
                _ => farthest(y[v][k], entry.quantizer.levels),
            };
        }
        failed += usize::from(stepped.is_err());
    }
    let name = format!("simulator@{steps}/frame");
    let timing = Timing {
        model: name.clone(),
        path: "single",
        ns_per_state: clock.elapsed().as_nanos() as f64 / rows.len().max(1) as f64,
        states: rows.len(),
        threads: 1,
        failed,
    };
    Ok(Resimulated {
        name,
        levels,
        timing,
    })
}

/// The level farthest from `truth` among `levels` levels.
fn farthest(truth: u16, levels: usize) -> u16 {
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
