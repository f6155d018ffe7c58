//! A variant's planning section (paper §1: planning by iterated
//! prediction), from the plan stage's `planning.parquet`: per task, every
//! forward model, planner and budget with its summed task cost (mean and
//! 95% interval across episodes), its difference from zero torques paired
//! episode by episode (the same start states) with the verdict the interval
//! allows, and its time per decision; and a chart of cost against time per
//! decision, real time marked.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::table::Table;
use alnlab_common::{Result, atomic};
use arrow_array::{UInt32Array, UInt64Array};

use super::format::{Align, MdTable, estimate, interval, sig3};
use crate::charts::{self, Axis, Plot, Point, Series, style_of};
use crate::paired::Interval;

/// One row of `planning.parquet`.
struct Episode {
    task: String,
    model: String,
    planner: String,
    budget: u32,
    episode: u32,
    evaluations: u64,
    cost: f64,
    ms: f64,
    real_time_ms: f64,
}

fn read(path: &Path) -> Result<Vec<Episode>> {
    let t = Table::read(path)?;
    let (task, model, planner) = (
        t.strings("task")?,
        t.strings("model")?,
        t.strings("planner")?,
    );
    let budget = t.column::<UInt32Array>("budget")?.values();
    let episode = t.column::<UInt32Array>("episode")?.values();
    let evaluations = t.column::<UInt64Array>("evaluations")?.values();
    let cost = t.f64_column("cost")?.values();
    let ms = t.f64_column("ms_per_decision")?.values();
    let real = t.f64_column("real_time_ms")?.values();
    Ok((0..t.num_rows())
        .map(|i| Episode {
            task: task[i].clone(),
            model: model[i].clone(),
            planner: planner[i].clone(),
            budget: budget[i],
            episode: episode[i],
            evaluations: evaluations[i],
            cost: cost[i],
            ms: ms[i],
            real_time_ms: real[i],
        })
        .collect())
}

/// One policy's episodes of one task, in episode order.
struct Policy<'a> {
    model: &'a str,
    planner: &'a str,
    budget: u32,
    evaluations: u64,
    episodes: Vec<&'a Episode>,
}

impl Policy<'_> {
    fn costs(&self) -> Vec<f64> {
        self.episodes.iter().map(|e| e.cost).collect()
    }

    /// The median over episodes of their median decision times.
    fn ms(&self) -> f64 {
        let mut ms: Vec<f64> = self.episodes.iter().map(|e| e.ms).collect();
        ms.sort_by(f64::total_cmp);
        ms[ms.len() / 2]
    }

    fn label(&self) -> String {
        if self.planner.is_empty() {
            format!("{} torques", self.model)
        } else {
            format!("{} {}", self.model, self.planner)
        }
    }
}

/// The policies of `task`, in the stage's order.
fn policies<'a>(rows: &'a [Episode], task: &str) -> Vec<Policy<'a>> {
    let mut out: Vec<Policy> = Vec::new();
    for e in rows.iter().filter(|e| e.task == task) {
        match out
            .iter_mut()
            .find(|p| p.model == e.model && p.planner == e.planner && p.budget == e.budget)
        {
            Some(p) => p.episodes.push(e),
            None => out.push(Policy {
                model: &e.model,
                planner: &e.planner,
                budget: e.budget,
                evaluations: e.evaluations,
                episodes: vec![e],
            }),
        }
    }
    for p in &mut out {
        p.episodes.sort_by_key(|e| e.episode);
    }
    out
}

/// The chart's style name of a plan model (`simulator@10` is the report's
/// `simulator@10/frame`).
fn style_name(model: &str) -> String {
    if model.starts_with("simulator@") {
        format!("{model}/frame")
    } else {
        model.to_string()
    }
}

/// Writes the planning section of variant `name` (nothing when it planned
/// nothing), its charts into `dir` named by `chart_name`.
pub(super) fn section(
    md: &mut String,
    path: &Path,
    dir: &Path,
    chart_name: impl Fn(&str) -> String,
) -> Result<()> {
    let rows = read(path)?;
    if rows.is_empty() {
        return Ok(());
    }
    let mut tasks: Vec<&str> = rows.iter().map(|e| e.task.as_str()).collect();
    tasks.dedup();
    let _ = writeln!(
        md,
        "### Planning with the predictor (§1)\n\nModel-predictive control in the simulator: \
         every frame a planner searches torque sequences with a forward model, the simulator \
         executes the first frame's torques, and the task's cost of the frame reached adds up \
         over the episode. Every policy ran the same episodes (the same start states), so each \
         is compared with zero torques episode by episode. Cost: mean over episodes [95% \
         interval]; time: median ms per decision on one thread.\n"
    );
    for task in tasks {
        let policies = policies(&rows, task);
        let Some(zero) = policies.iter().find(|p| p.model == "zero") else {
            continue;
        };
        let zero_costs = zero.costs();
        let real_time = rows
            .iter()
            .find(|e| e.task == task)
            .map_or(0.0, |e| e.real_time_ms);
        let _ = writeln!(md, "#### Task `{task}`\n");
        let mut table = MdTable::new(&["model", "planner", "budget"])
            .numbers(&["evaluations / decision", "cost", "ms / decision"])
            .column("against zero torques", Align::Left);
        for p in &policies {
            let costs = p.costs();
            let mean = Interval::of(&costs).expect("a policy has episodes");
            let cost = if costs.len() > 1 {
                estimate(mean.mean, mean.low, mean.high)
            } else {
                sig3(mean.mean)
            };
            let against = if p.model == "zero" {
                "—".to_string()
            } else {
                let diffs: Vec<f64> = costs.iter().zip(&zero_costs).map(|(a, z)| a - z).collect();
                match Interval::of(&diffs) {
                    Some(d) if diffs.len() > 1 => {
                        let word = d.verdict().as_str();
                        format!("{word}: {}", interval(d.mean, d.low, d.high))
                    }
                    _ => "— (one episode)".into(),
                }
            };
            let planned = !p.planner.is_empty();
            table.row(vec![
                p.model.to_string(),
                if planned {
                    p.planner.to_string()
                } else {
                    "—".into()
                },
                if planned {
                    p.budget.to_string()
                } else {
                    "—".into()
                },
                if planned {
                    p.evaluations.to_string()
                } else {
                    "—".into()
                },
                cost,
                if planned { sig3(p.ms()) } else { "—".into() },
                against,
            ]);
        }
        table.write(md);

        // Cost against time per decision, one curve per model and planner.
        let mut series: Vec<Series> = Vec::new();
        let planned: Vec<&Policy> = policies.iter().filter(|p| !p.planner.is_empty()).collect();
        let xs: Vec<f64> = planned.iter().map(|p| p.ms()).chain([real_time]).collect();
        let (x_lo, x_hi) = xs
            .iter()
            .filter(|x| **x > 0.0)
            .fold((f64::MAX, 0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        for p in &planned {
            let name = format!("{} {}", p.model, p.planner);
            let point = {
                let costs = p.costs();
                let i = Interval::of(&costs).expect("episodes");
                Point {
                    y_range: (costs.len() > 1).then_some((i.low.max(0.0), i.high)),
                    ..Point::at(p.ms(), i.mean)
                }
            };
            match series.iter_mut().find(|s| s.name == name) {
                Some(s) => s.points.push(point),
                None => series.push(Series {
                    name,
                    style: style_of(&style_name(p.model), 0),
                    points: vec![point],
                    joined: true,
                    hollow: p.planner == "random-shooting",
                }),
            }
        }
        let costs: Vec<f64> = policies
            .iter()
            .map(|p| Interval::of(&p.costs()).map_or(0.0, |i| i.mean))
            .collect();
        let (y_lo, y_hi) = costs
            .iter()
            .fold((f64::MAX, 0f64), |(lo, hi), &y| (lo.min(y), hi.max(y)));
        for p in policies.iter().filter(|p| p.planner.is_empty()) {
            let mean = Interval::of(&p.costs()).map_or(0.0, |i| i.mean);
            series.push(Series {
                name: p.label(),
                style: style_of(&p.label(), 0),
                points: vec![Point::at(x_lo, mean), Point::at(x_hi, mean)],
                joined: true,
                hollow: true,
            });
        }
        if real_time > 0.0 {
            series.push(Series {
                name: format!("real time ({} ms a frame)", sig3(real_time)),
                style: style_of("real time", 0),
                points: vec![
                    Point::at(real_time, y_lo.max(0.0)),
                    Point::at(real_time, y_hi),
                ],
                joined: true,
                hollow: true,
            });
        }
        let chart = charts::plot(&Plot {
            title: format!("task `{task}`: cost against time per decision"),
            x: Axis::log("ms per decision, one thread (log)"),
            y: Axis::error("task cost per episode", costs.iter().copied()),
            series,
            pareto: false,
        });
        let file = chart_name(&format!("plan-{task}"));
        atomic::write_bytes(&dir.join(&file), chart.as_bytes())?;
        let _ = writeln!(
            md,
            "![task {task}: cost against time per decision]({file})\n\nEach curve is one forward \
             model with one planner (filled: cross-entropy method; hollow: random shooting), a \
             point per budget, bars the 95% interval across episodes; the flat lines are zero \
             torques (black) and the random controller (orange); left of the vertical grey line a \
             decision takes less than the frame it plans for.\n"
        );
    }
    Ok(())
}
