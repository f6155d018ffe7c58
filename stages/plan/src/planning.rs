//! `planning.parquet`, the plan stage's table of episodes: its row, its
//! writer and its reader. One row per task, model, planner, budget and
//! episode: the summed cost, the evaluations per decision, the decision
//! time in ms (median and range over the episode's decisions), real time
//! (the simulated time a decision stands for: one frame), and the model's
//! one-step error on the task's variables over the episode, and its error
//! over the planning horizon fed its own predictions; what the episode came
//! to in the task's physical unit (steady-state error, time to settle,
//! fraction of frames within tolerance); a feedback loop's frequency.

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{PolicyId, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array, UInt64Array};

/// One row of `planning.parquet`: an episode of one policy.
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
    pub task: String,
    /// The forward model (`aln`, `linear`, `simulator@k`, `plant@k`) or a
    /// reference (`zero`, `random`, `gravity-pd`, `gravity-pid`).
    pub model: PolicyId,
    /// The round of the planner's own data (`[plan] rounds`) whose table
    /// the episode was read from: 0 for the first plan stage's, r for the
    /// plan stage after r rounds. Not a column: each round writes a table.
    pub round: u32,
    /// The planner; empty for a reference.
    pub planner: String,
    /// Sequences per decision.
    pub budget: u32,
    pub episode: u32,
    /// Forward-model evaluations per decision.
    pub evaluations: u64,
    /// The task's cost summed over the episode's frames.
    pub cost: f64,
    /// ms per decision: the median over the episode's decisions, and the
    /// range.
    pub ms_per_decision: f64,
    pub ms_min: f64,
    pub ms_max: f64,
    /// Simulated time per decision (one frame), in ms: real time.
    pub real_time_ms: f64,
    /// RMS over frames of the model's one-step error on the task's
    /// variables.
    pub prediction_rms: f64,
    /// RMS over the episode's windows of the model's error at the end of
    /// the planning horizon, fed its own predictions under the torques
    /// executed ([`crate::episode::Outcome::horizon_rms`]); NaN for a
    /// reference.
    pub horizon_rms: f64,
    /// The steady-state error: the mean error (the task's unit: rad, rad/s
    /// or m) over the episode's last quarter of frames
    /// ([`crate::episode::Outcome::final_error`]).
    pub final_error: f64,
    /// Seconds until the error stayed within the task's tolerance; +∞ if it
    /// did not by the last frame.
    pub settle_s: f64,
    /// The fraction of frames within the task's tolerance.
    pub within_tolerance: f64,
    /// A feedback loop's natural frequency (rad/s) as tuned; NaN for every
    /// other policy.
    pub feedback_frequency: f64,
}

/// Writes `rows` to `path`.
pub fn write(path: &Path, rows: &[Episode], provenance: &Provenance) -> Result<()> {
    let real = |f: fn(&Episode) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(rows.iter().map(f)))
    };
    let count = |f: fn(&Episode) -> u32| -> Arc<dyn Array> {
        Arc::new(UInt32Array::from_iter_values(rows.iter().map(f)))
    };
    let text = |f: fn(&Episode) -> &str| -> Arc<dyn Array> {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
    };
    let batch = table::batch(vec![
        ("task", text(|r| &r.task)),
        (
            "model",
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.model.to_string()),
            )),
        ),
        ("planner", text(|r| &r.planner)),
        ("budget", count(|r| r.budget)),
        ("episode", count(|r| r.episode)),
        (
            "evaluations",
            Arc::new(UInt64Array::from_iter_values(
                rows.iter().map(|r| r.evaluations),
            )),
        ),
        ("cost", real(|r| r.cost)),
        ("ms_per_decision", real(|r| r.ms_per_decision)),
        ("ms_min", real(|r| r.ms_min)),
        ("ms_max", real(|r| r.ms_max)),
        ("real_time_ms", real(|r| r.real_time_ms)),
        ("prediction_rms", real(|r| r.prediction_rms)),
        ("horizon_rms", real(|r| r.horizon_rms)),
        ("final_error", real(|r| r.final_error)),
        ("settle_s", real(|r| r.settle_s)),
        ("within_tolerance", real(|r| r.within_tolerance)),
        ("feedback_frequency", real(|r| r.feedback_frequency)),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// Reads `planning.parquet`.
pub fn read(path: &Path) -> Result<Vec<Episode>> {
    let t = Table::read(path)?;
    let model: Vec<PolicyId> = t.parsed("model")?;
    let (task, planner) = (t.strings("task")?, t.strings("planner")?);
    let count = |name: &str| t.column::<UInt32Array>(name).map(|c| c.values());
    let real = |name: &str| t.f64_column(name).map(|c| c.values());
    let (budget, episode) = (count("budget")?, count("episode")?);
    let evaluations = t.column::<UInt64Array>("evaluations")?.values();
    let (cost, ms) = (real("cost")?, real("ms_per_decision")?);
    let (ms_min, ms_max) = (real("ms_min")?, real("ms_max")?);
    let (real_time, rms) = (real("real_time_ms")?, real("prediction_rms")?);
    // Tables written before a column (plan format 5 for the horizon's
    // error, 12 for the physical outcomes) read as NaN.
    let optional = |name: &str| match t.batch.column_by_name(name) {
        Some(_) => real(name).map(|c| Some(&c[..])),
        None => Ok(None),
    };
    let horizon_rms = optional("horizon_rms")?;
    let (final_error, settle_s) = (optional("final_error")?, optional("settle_s")?);
    let within = optional("within_tolerance")?;
    let feedback_frequency = optional("feedback_frequency")?;
    let or_nan = |c: Option<&[f64]>, i: usize| c.map_or(f64::NAN, |c| c[i]);
    Ok((0..t.num_rows())
        .map(|i| Episode {
            task: task[i].clone(),
            model: model[i],
            round: 0,
            planner: planner[i].clone(),
            budget: budget[i],
            episode: episode[i],
            evaluations: evaluations[i],
            cost: cost[i],
            ms_per_decision: ms[i],
            ms_min: ms_min[i],
            ms_max: ms_max[i],
            real_time_ms: real_time[i],
            prediction_rms: rms[i],
            horizon_rms: or_nan(horizon_rms, i),
            final_error: or_nan(final_error, i),
            settle_s: or_nan(settle_s, i),
            within_tolerance: or_nan(within, i),
            feedback_frequency: or_nan(feedback_frequency, i),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episodes_read_back_as_written() {
        let rows = vec![Episode {
            task: "bend".into(),
            model: PolicyId::Aln,
            round: 0,
            planner: "cem".into(),
            budget: 64,
            episode: 3,
            evaluations: 640,
            cost: 12.5,
            ms_per_decision: 1.5,
            ms_min: 1.25,
            ms_max: 2.0,
            real_time_ms: 10.0,
            prediction_rms: 0.03,
            horizon_rms: 0.25,
            final_error: 0.04,
            settle_s: f64::INFINITY,
            within_tolerance: 0.5,
            feedback_frequency: f64::NAN,
        }];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("planning.parquet");
        let provenance = Provenance {
            stage: "plan".into(),
            params: serde_json::Value::Null,
            inputs: Default::default(),
        };
        write(&path, &rows, &provenance).unwrap();
        let back = read(&path).unwrap();
        assert!(back[0].feedback_frequency.is_nan());
        let same = |e: &Episode| Episode {
            feedback_frequency: 0.0,
            ..e.clone()
        };
        assert_eq!(
            back.iter().map(same).collect::<Vec<_>>(),
            rows.iter().map(same).collect::<Vec<_>>()
        );
    }
}
