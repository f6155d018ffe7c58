//! The closed loop: from the true state of spread-out test rows, each model
//! fed its own predictions, scored against the logged trajectory at every
//! step. Drawn as each model's difference from persistence per step (with
//! its interval across replicates), tabled as mean errors; chart and table
//! from the same replicates.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{ModelId, Result, atomic};

use super::Loaded;
use super::format::{MdTable, sig3, signed};
use crate::charts::{self, Axis, Plot, Point, Rule, Series, Style};
use alnlab_summarize::paired::Interval;

/// A model the closed-loop figures cover, by more than this many times the
/// learned models' largest excursion from persistence, is left off the chart
/// (and said so): a simulator drifting by tens of levels would flatten every
/// learned curve into the zero line.
const OFF_SCALE: f64 = 4.0;

/// One model of one variant in the closed-loop chart and table.
pub(super) struct Column<'a> {
    /// As the report names it (`aln · walk`, `linear`).
    pub name: String,
    pub variant: &'a Loaded<'a>,
    pub model: ModelId,
    pub style: Style,
}

/// The models with closed-loop figures in variant `v`, in their order.
pub(super) fn models(v: &Loaded) -> Vec<ModelId> {
    let mut models: Vec<ModelId> = v.horizons.iter().map(|h| h.model).collect();
    models.dedup();
    models
}

/// The steps `v` was rolled out for.
fn steps(v: &Loaded) -> Vec<u16> {
    let mut steps: Vec<u16> = v.horizons.iter().map(|h| h.horizon).collect();
    steps.sort_unstable();
    steps.dedup();
    steps
}

/// `model`'s mean closed-loop error after `step` steps, per replicate (the
/// first replicate alone when the variant has one).
fn per_replicate(v: &Loaded, model: ModelId, step: u16) -> Option<Vec<f64>> {
    if v.replicates.len() > 1 {
        v.replicates
            .iter()
            .map(|f| {
                f.horizons
                    .iter()
                    .find(|h| h.0 == model && h.1 == step)
                    .map(|h| h.2)
            })
            .collect()
    } else {
        v.horizons
            .iter()
            .find(|h| h.model == model && h.horizon == step)
            .map(|h| vec![h.mean])
    }
}

/// Each model's closed-loop error after the last step, per replicate.
pub(super) type AtHorizon = Vec<(ModelId, Vec<f64>)>;

/// Every model's closed-loop errors in `v` after its last step, per
/// replicate: the step, and each model with its figures.
pub(super) fn at_horizon(v: &Loaded) -> Option<(u16, AtHorizon)> {
    let horizon = steps(v).last().copied()?;
    let errors: AtHorizon = models(v)
        .into_iter()
        .filter_map(|m| Some((m, per_replicate(v, m, horizon)?)))
        .collect();
    (!errors.is_empty()).then_some((horizon, errors))
}

/// The mean of `values`, with its 95% interval when there are several.
fn point(step: u16, values: &[f64]) -> Point {
    match Interval::of(values).filter(|_| values.len() > 1) {
        Some(i) => Point {
            y_range: Some((i.low, i.high)),
            ..Point::at(f64::from(step), i.mean)
        },
        None => Point::at(
            f64::from(step),
            values.iter().sum::<f64>() / values.len() as f64,
        ),
    }
}

/// `model`'s mean error minus persistence's, per step, paired replicate by
/// replicate.
fn difference(v: &Loaded, model: ModelId) -> Vec<Point> {
    steps(v)
        .into_iter()
        .filter_map(|step| {
            let a = per_replicate(v, model, step)?;
            let p = per_replicate(v, ModelId::Persistence, step)?;
            let d: Vec<f64> = a.iter().zip(&p).map(|(a, p)| a - p).collect();
            Some(point(step, &d))
        })
        .collect()
}

/// The starts scored in `v`'s first replicate: the errors pooled at step 1
/// over the variables persistence predicts.
fn starts(v: &Loaded) -> Option<u64> {
    let first = v
        .horizons
        .iter()
        .find(|h| h.model == ModelId::Persistence && h.horizon == 1)?;
    let variables = v
        .judged()
        .0
        .iter()
        .filter(|r| r.model == ModelId::Persistence)
        .count() as u64;
    (variables > 0).then(|| first.n / variables)
}

/// Writes the closed-loop chart to `dir/file` (its title names `whose`
/// figures, when not every variant's), its caption and its table.
pub(super) fn section(
    md: &mut String,
    dir: &Path,
    (file, whose): (&str, Option<&str>),
    columns: &[Column],
) -> Result<()> {
    let Some(first) = columns.first().map(|c| c.variant) else {
        return Ok(());
    };
    let drawn: Vec<(&Column, Vec<Point>)> = columns
        .iter()
        .filter(|c| c.model != ModelId::Persistence)
        .map(|c| (c, difference(c.variant, c.model)))
        .collect();
    let reach = |points: &[Point]| {
        points
            .iter()
            .flat_map(|p| {
                let (lo, hi) = p.y_range.unwrap_or((p.y, p.y));
                [p.y.abs(), lo.abs(), hi.abs()]
            })
            .fold(0.0, f64::max)
    };
    let learned = drawn
        .iter()
        .filter(|(c, _)| !c.model.is_simulator())
        .map(|(_, p)| reach(p))
        .fold(0.0, f64::max);
    let (on, off): (Vec<_>, Vec<_>) = drawn
        .into_iter()
        .partition(|(_, p)| learned == 0.0 || reach(p) <= OFF_SCALE * learned);
    let chart = charts::plot(&Plot {
        title: match whose {
            Some(name) => format!("{name}: closed loop, error minus persistence's"),
            None => "closed loop: error minus persistence's".into(),
        },
        x: Axis::integer("steps fed back"),
        y: Axis::linear("mean error − persistence's (levels)"),
        series: on
            .iter()
            .map(|(c, points)| Series {
                name: c.name.clone(),
                style: c.style,
                points: points.clone(),
                joined: true,
                hollow: false,
            })
            .collect(),
        pareto: false,
        rules: vec![Rule::horizontal(0.0, &ModelId::Persistence.to_string())],
    });
    atomic::write_bytes(&dir.join(file), chart.as_bytes())?;

    let replicates = first.replicates.len();
    let over = if replicates > 1 {
        format!("mean across {replicates} replicates")
    } else {
        "one replicate".into()
    };
    let bars = if replicates > 1 {
        " (bars: 95% interval, paired by replicate)"
    } else {
        ""
    };
    let horizon = steps(first).last().copied().unwrap_or(0);
    let held = first.judged().1 == alnlab_summarize::Rows::HeldOut;
    let starts = starts(first).map_or("the".into(), |s| s.to_string());
    let _ = write!(
        md,
        "![closed loop: error minus persistence's]({file})\n\nFrom the true state of {starts} \
         starts — test rows spread evenly over those with {horizon} logged frames after them \
         (at most `test.rollout_starts` of them, 200 by default), {} — each model is fed its \
         own predictions for {horizon} steps and scored against the logged trajectory at every \
         step (levels, all its variables pooled). Drawn: its mean error minus persistence's at \
         the same step, {over}{bars}; below zero, better than persistence.",
        if held {
            "those held out of training"
        } else {
            "all of them"
        }
    );
    if !off.is_empty() {
        let named: Vec<String> = off
            .iter()
            .map(|(c, p)| {
                let last = p.last().map_or(0.0, |p| p.y);
                format!("{} ({} at step {horizon})", c.name, signed(last))
            })
            .collect();
        let _ = write!(
            md,
            " Off this scale, so in the table only: {}.",
            named.join(", ")
        );
    }
    // Step 1 against the one-step tables: the same prediction, other rows.
    let one_step: Option<Vec<f64>> = if replicates > 1 {
        first
            .replicates
            .iter()
            .map(|f| f.mean_of(ModelId::Persistence))
            .collect()
    } else {
        super::overall(first.judged().0, ModelId::Persistence).map(|(m, _)| vec![m])
    };
    let mean = |values: Vec<f64>| values.iter().sum::<f64>() / values.len() as f64;
    if let (Some(all), Some(here)) = (one_step, per_replicate(first, ModelId::Persistence, 1)) {
        let _ = write!(
            md,
            " Step 1 is one prediction, as in the one-step tables, but scored on these starts \
             alone: persistence errs {} there against {} over all {} {}{}.",
            sig3(mean(here)),
            sig3(mean(all)),
            if held { first.rows.1 } else { first.rows.0 },
            if held { "held-out rows" } else { "test rows" },
            if replicates > 1 {
                ", each the mean across replicates"
            } else {
                ""
            }
        );
    }
    let _ = writeln!(md, "\n");

    let _ = writeln!(md, "Closed-loop mean error (levels), {over}:\n");
    let names: Vec<&str> = columns.iter().map(|c| c.name.as_str()).collect();
    let mut table = MdTable::new(&["steps"]).numbers(&names);
    for step in steps(first) {
        let mut cells = vec![step.to_string()];
        for c in columns {
            cells.push(
                per_replicate(c.variant, c.model, step).map_or("—".into(), |v| sig3(mean(v))),
            );
        }
        table.row(cells);
    }
    table.write(md);
    Ok(())
}
