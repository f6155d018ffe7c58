//! A variant's planning section (paper §1: planning by iterated
//! prediction), from the plan stage's `planning.parquet`: per task, every
//! forward model, planner and budget with its summed task cost (mean and
//! 95% interval across episodes), its difference from zero torques paired
//! episode by episode (the same start states) with the verdict the interval
//! allows, and its time per decision; and a chart of cost against time per
//! decision, real time marked.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{PolicyId, Result, atomic};
use alnlab_plan::planning::Episode;

use super::PlanSetup;
use super::format::{Align, MdTable, estimate, interval, sig3};
use super::plan_frontier::Budgeted;
use crate::charts::{self, Axis, Plot, Point, Rule, Series, policy_style};
use alnlab_summarize::paired::{Interval, Verdict};

/// A forward model or reference as the planning section names it: the
/// plan stage's policy, and the round of the planner's own data it was
/// trained again after (0: none; `[plan] rounds`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct PlanModel {
    pub policy: PolicyId,
    pub round: u32,
}

impl PlanModel {
    /// The model an episode was planned with.
    pub(super) fn of(e: &Episode) -> PlanModel {
        PlanModel {
            policy: e.model,
            round: e.round,
        }
    }

    /// `policy` before any round of its own data.
    pub(super) fn first(policy: PolicyId) -> PlanModel {
        PlanModel { policy, round: 0 }
    }

    /// ` (round r)` after r rounds, else nothing.
    pub(super) fn round_suffix(self) -> String {
        match self.round {
            0 => String::new(),
            r => format!(" (round {r})"),
        }
    }
}

impl std::fmt::Display for PlanModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}{}", self.policy, self.round_suffix())
    }
}

/// One policy's episodes of one task, in episode order.
pub(super) struct Policy<'a> {
    pub model: PlanModel,
    pub planner: &'a str,
    pub budget: u32,
    pub evaluations: u64,
    episodes: Vec<&'a Episode>,
}

impl Policy<'_> {
    pub(super) fn costs(&self) -> Vec<f64> {
        self.episodes.iter().map(|e| e.cost).collect()
    }

    /// The median over episodes of their median decision times.
    pub(super) fn ms(&self) -> f64 {
        let mut ms: Vec<f64> = self.episodes.iter().map(|e| e.ms_per_decision).collect();
        ms.sort_by(f64::total_cmp);
        ms[ms.len() / 2]
    }

    /// The cost as a table cell: the mean [95% interval] across episodes,
    /// or the one episode's cost.
    fn cost_cell(&self) -> String {
        let costs = self.costs();
        let i = Interval::of(&costs).expect("a policy has episodes");
        if costs.len() > 1 {
            estimate(i.mean, i.low, i.high)
        } else {
            sig3(i.mean)
        }
    }

    /// The mean over episodes of the model's one-step error.
    fn prediction_rms(&self) -> f64 {
        let sum: f64 = self.episodes.iter().map(|e| e.prediction_rms).sum();
        sum / self.episodes.len() as f64
    }

    /// The mean over episodes of the steady-state error (the task's unit);
    /// NaN for tables written before the column.
    pub(super) fn final_error(&self) -> f64 {
        let errors: Vec<f64> = self.episodes.iter().map(|e| e.final_error).collect();
        mean(&errors)
    }

    /// What the episodes came to against the task's tolerance, as table
    /// cells: the steady-state error (mean over episodes), the episodes
    /// that settled within the tolerance and their median time to settle,
    /// and the mean fraction of frames within it; "—" for tables written
    /// before the columns.
    fn outcome_cells(&self) -> [String; 3] {
        let error = self.final_error();
        if error.is_nan() {
            return ["—".into(), "—".into(), "—".into()];
        }
        // The median over every episode, one that never settled counting
        // as never: a policy that rarely settles is not flattered.
        let mut times: Vec<f64> = self.episodes.iter().map(|e| e.settle_s).collect();
        times.sort_by(f64::total_cmp);
        let n = times.len();
        let k = times.iter().filter(|s| s.is_finite()).count();
        let median = times[(n - 1) / 2];
        let settle = match median.is_finite() {
            true => format!("{k} of {n}, median {} s", sig3(median)),
            false => format!("{k} of {n}, median never"),
        };
        let within: Vec<f64> = self.episodes.iter().map(|e| e.within_tolerance).collect();
        [
            sig3(error),
            settle,
            format!("{:.0}%", 100.0 * mean(&within)),
        ]
    }

    /// Whether it is a feedback loop on gravity compensation.
    pub(super) fn is_feedback(&self) -> bool {
        matches!(
            self.model.policy,
            PolicyId::GravityPd | PolicyId::GravityPid
        )
    }

    /// A feedback loop's frequency as tuned (rad/s), where the policy is one.
    pub(super) fn feedback_frequency(&self) -> Option<f64> {
        let w = self.episodes.first()?.feedback_frequency;
        w.is_finite().then_some(w)
    }

    /// Whether a planner chose the torques (not a reference).
    pub(super) fn planned(&self) -> bool {
        !self.planner.is_empty()
    }

    /// This policy's episode costs minus `other`'s, episode by episode.
    fn differences(&self, other: &Policy) -> Vec<f64> {
        self.episodes
            .iter()
            .zip(&other.episodes)
            .map(|(a, b)| a.cost - b.cost)
            .collect()
    }

    /// The paired difference of this policy's episode costs from `other`'s,
    /// as a table cell: with the verdict its interval allows where `words`
    /// (the run's only replicate), the interval alone where the episodes are
    /// one replicate's of several — a verdict there is the first screen's,
    /// across replicates, and one replicate's word could contradict it.
    fn against(&self, other: &Policy, words: bool) -> String {
        let diffs = self.differences(other);
        match Interval::of(&diffs) {
            Some(d) if diffs.len() > 1 && words => {
                let word = d.verdict().as_str();
                format!("{word}: {}", interval(d.mean, d.low, d.high))
            }
            Some(d) if diffs.len() > 1 => interval(d.mean, d.low, d.high),
            _ => "— (one episode)".into(),
        }
    }

    fn label(&self) -> String {
        match (self.planned(), self.feedback_frequency()) {
            (true, _) => format!("{} {}", self.model, self.planner),
            (false, Some(w)) => format!("{} (ω {} rad/s)", self.model, sig3(w)),
            (false, None) => format!("{} torques", self.model),
        }
    }
}

/// The policies of `task`, in the stage's order.
pub(super) fn policies<'a>(rows: &'a [Episode], task: &str) -> Vec<Policy<'a>> {
    let mut out: Vec<Policy> = Vec::new();
    for e in rows.iter().filter(|e| e.task == task) {
        match out
            .iter_mut()
            .find(|p| p.model == PlanModel::of(e) && p.planner == e.planner && p.budget == e.budget)
        {
            Some(p) => p.episodes.push(e),
            None => out.push(Policy {
                model: PlanModel::of(e),
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

/// Every policy's planning figures across replicates, for
/// `replicates.csv`: per task and policy of the first replicate (model,
/// round, planner, budget, or a reference's torques), its mean episode
/// cost and its median ms a decision in each replicate, named
/// `plan <task>: <policy> cost` and `… ms`; a replicate without the policy
/// gives no value.
pub(super) fn replicate_figures(replicates: &[Vec<Episode>]) -> Vec<(String, Vec<Option<f64>>)> {
    let Some(first) = replicates.first() else {
        return Vec::new();
    };
    let mut figures = Vec::new();
    for task in tasks(first) {
        let each: Vec<Vec<Policy>> = replicates.iter().map(|r| policies(r, task)).collect();
        for p in &each[0] {
            let same =
                |q: &&Policy| q.model == p.model && q.planner == p.planner && q.budget == p.budget;
            let name = match (p.planned(), p.is_feedback()) {
                (true, _) => format!("{} {} {}", p.model, p.planner, p.budget),
                (false, true) => p.model.to_string(),
                (false, false) => format!("{} torques", p.model),
            };
            let of = |f: &dyn Fn(&Policy) -> f64| -> Vec<Option<f64>> {
                each.iter().map(|r| r.iter().find(same).map(f)).collect()
            };
            figures.push((
                format!("plan {task}: {name} cost"),
                of(&|q| mean(&q.costs())),
            ));
            if !p.final_error().is_nan() {
                figures.push((
                    format!("plan {task}: {name} final error"),
                    of(&|q| q.final_error()),
                ));
            }
            if p.planned() {
                figures.push((format!("plan {task}: {name} ms"), of(&|q| q.ms())));
            }
        }
    }
    figures
}

/// `model` with `planner` at its largest budget whose median decision fits
/// `limit` ms: a rule fixed before any cost is seen, not the best of its
/// budgets.
fn within<'p, 'a>(
    policies: &'p [Policy<'a>],
    model: PlanModel,
    planner: &str,
    limit: f64,
) -> Option<&'p Policy<'a>> {
    policies
        .iter()
        .filter(|p| p.model == model && p.planner == planner && p.ms() <= limit)
        .max_by_key(|p| p.budget)
}

/// The tasks of `rows`, in the stage's order: each once, though a round's
/// rows follow every task's again.
pub(super) fn tasks(rows: &[Episode]) -> Vec<&str> {
    once(rows.iter().map(|e| e.task.as_str()))
}

/// Each item once, in the order it first appears.
fn once<T: PartialEq>(items: impl Iterator<Item = T>) -> Vec<T> {
    let mut seen: Vec<T> = Vec::new();
    for item in items {
        if !seen.contains(&item) {
            seen.push(item);
        }
    }
    seen
}

/// The frame's duration, real time, of `task` in ms.
fn real_time(rows: &[Episode], task: &str) -> f64 {
    rows.iter()
        .find(|e| e.task == task)
        .map_or(0.0, |e| e.real_time_ms)
}

/// The planner and budget the first screen times every forward model at:
/// the ALN's first planner at its largest budget within real time on the
/// first task (its smallest budget when none fits).
pub(super) fn reference_policy(rows: &[Episode]) -> Option<(String, u32)> {
    let task = *tasks(rows).first()?;
    let policies = policies(rows, task);
    let aln = PlanModel::first(PolicyId::Aln);
    let first = policies.iter().find(|p| p.model == aln && p.planned())?;
    let chosen = within(&policies, aln, first.planner, real_time(rows, task)).unwrap_or(first);
    Some((chosen.planner.to_string(), chosen.budget))
}

/// `model`'s median ms per decision with `planner` at `budget`, over every
/// episode of every task.
pub(super) fn decision_ms(
    rows: &[Episode],
    model: PolicyId,
    planner: &str,
    budget: u32,
) -> Option<f64> {
    let mut ms: Vec<f64> = rows
        .iter()
        .filter(|e| e.model == model && e.round == 0 && e.planner == planner && e.budget == budget)
        .map(|e| e.ms_per_decision)
        .collect();
    ms.sort_by(f64::total_cmp);
    ms.get(ms.len() / 2).copied()
}

/// Per task and planner of forward `model`, its plan within real time as a
/// phrase for the report's first screen: the planner at its largest budget
/// whose median decision fits one frame in replicate 1 (the rule of the
/// equal-time table, no pick by cost), against zero torques episode by
/// episode — the mean difference across replicates with its 95% interval
/// when there are several, else over the episodes of the one. Costs carry
/// the task's unit from `setup`. Empty when no replicate planned with it.
pub(super) fn within_real_time(
    replicates: &[Vec<Episode>],
    model: PolicyId,
    setup: Option<&PlanSetup>,
) -> Vec<String> {
    let model = PlanModel::first(model);
    let Some(first) = replicates.first() else {
        return Vec::new();
    };
    let mut phrases = Vec::new();
    for task in tasks(first) {
        let unit = setup
            .and_then(|s| s.tasks.iter().find(|t| t.name == task))
            .map_or(String::new(), |t| format!(" {}", t.unit));
        let policies_1 = policies(first, task);
        let planners = once(
            policies_1
                .iter()
                .filter(|p| p.model == model && p.planned())
                .map(|p| p.planner),
        );
        let limit = real_time(first, task);
        for planner in planners {
            let Some(chosen) = within(&policies_1, model, planner, limit) else {
                phrases.push(format!(
                    "`{task}` {planner}: no budget decides within real time ({} ms)",
                    sig3(limit)
                ));
                continue;
            };
            // Per replicate: the mean cost, zero torques', their mean
            // paired difference, and whether every episode tied exactly.
            let per_replicate: Option<Vec<(f64, f64, f64, bool)>> = replicates
                .iter()
                .map(|rows| {
                    let policies = policies(rows, task);
                    let p = policies.iter().find(|p| {
                        p.model == model && p.planner == planner && p.budget == chosen.budget
                    })?;
                    let zero = policies.iter().find(|p| p.model.policy == PolicyId::Zero)?;
                    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
                    let diffs = p.differences(zero);
                    let same = diffs.iter().all(|d| *d == 0.0);
                    Some((mean(&p.costs()), mean(&zero.costs()), mean(&diffs), same))
                })
                .collect();
            let Some(per_replicate) = per_replicate else {
                continue;
            };
            let n = per_replicate.len() as f64;
            let (cost, zero) = per_replicate
                .iter()
                .fold((0.0, 0.0), |(c, z), r| (c + r.0 / n, z + r.1 / n));
            let difference = if per_replicate.iter().all(|r| r.3) {
                Some("the same in every episode: the planner kept zero torque".to_string())
            } else if per_replicate.len() > 1 {
                let d: Vec<f64> = per_replicate.iter().map(|r| r.2).collect();
                Interval::of(&d).map(|i| {
                    format!(
                        "{}: {} across {} replicates",
                        i.verdict().as_str(),
                        interval(i.mean, i.low, i.high),
                        d.len()
                    )
                })
            } else {
                policies_1
                    .iter()
                    .find(|p| p.model.policy == PolicyId::Zero)
                    .map(|zero| {
                        format!(
                            "{} over the episodes of one replicate",
                            chosen.against(zero, true)
                        )
                    })
            };
            phrases.push(format!(
                "`{task}` {planner} ({} sequences, {} ms a decision): cost {}{unit} against zero \
                 torques' {}, {}",
                chosen.budget,
                sig3(chosen.ms()),
                sig3(cost),
                sig3(zero),
                difference.unwrap_or_default()
            ));
        }
    }
    phrases
}

/// The true model among `rows`' forward models: a plant's own simulator
/// at the most steps a frame where the data come from a `plant`, else the
/// simulator at the most steps a frame (the scene as written, which then
/// is the plant).
pub(super) fn true_model(rows: &[Episode], plant: bool) -> Option<PolicyId> {
    rows.iter()
        .filter_map(|e| match e.model {
            PolicyId::Plant { steps } if plant => Some((steps, e.model)),
            PolicyId::Simulator { steps } if !plant => Some((steps, e.model)),
            _ => None,
        })
        .max_by_key(|(steps, _)| *steps)
        .map(|(_, model)| model)
}

/// Writes the planning section of variant `name` (nothing when it planned
/// nothing), its charts into `dir` named by `chart_name`.
pub(super) fn section(
    md: &mut String,
    rows: &[Episode],
    replicates: usize,
    setup: Option<&PlanSetup>,
    dir: &Path,
    chart_name: impl Fn(&str) -> String,
) -> Result<()> {
    if rows.is_empty() {
        return Ok(());
    }
    let _ = writeln!(
        md,
        "### Planning with the predictor (§1)\n\nModel-predictive control in the simulator: \
         every frame a planner searches torque sequences with a forward model, the scene's own \
         simulator — the plant, where the data come from one — executes the first frame's \
         torques, and the task's cost of the frame reached adds up over the episode. \
         simulator@k is the scene as written at k steps a frame (of a plant, the nominal model \
         a user has); plant@k, where present, the plant's own simulator, a reference no user \
         has. Every policy ran the same episodes (the same start states), so each \
         is compared with zero torques episode by episode. {} Cost: mean over episodes [95% \
         interval]; time: median ms per decision on one thread.\n",
        if replicates > 1 {
            format!(
                "The tables and charts are replicate 1's of {replicates}: their differences are \
                 intervals over its episodes, with no verdict word — the verdicts are the first \
                 screen's, which pairs every replicate."
            )
        } else {
            "Lower, higher, indistinguishable: the verdict the interval allows.".into()
        }
    );
    let words = replicates <= 1;
    for task in tasks(rows) {
        let policies = policies(rows, task);
        let (Some(zero), Some(random)) = (
            policies.iter().find(|p| p.model.policy == PolicyId::Zero),
            policies.iter().find(|p| p.model.policy == PolicyId::Random),
        ) else {
            continue;
        };
        let real_time = real_time(rows, task);
        let _ = writeln!(md, "#### Task `{task}`\n");
        if let Some(setup) = setup
            && let Some(what) = setup.tasks.iter().find(|t| t.name == task)
        {
            let _ = writeln!(
                md,
                "The task: {}. An episode is {} frames from a logged state, one decision a \
                 frame, each planning {} frames ahead; its cost is the sum of its frames' costs, \
                 in {}; {} episodes a policy, the same start states for every policy. Real \
                 time: a decision within the {} ms a frame lasts.\n",
                what.definition,
                setup.frames,
                setup.horizon,
                what.unit,
                setup.episodes,
                sig3(real_time)
            );
        }
        let loops: Vec<&Policy> = policies.iter().filter(|p| p.is_feedback()).collect();
        if let Some(setup) =
            setup.filter(|s| !s.feedback_frequencies.is_empty() && !loops.is_empty())
        {
            let grid: Vec<String> = setup
                .feedback_frequencies
                .iter()
                .map(|w| sig3(*w))
                .collect();
            // A pick at an end of the grid says the grid may not hold the
            // loop's best frequency.
            let (low, high) = setup
                .feedback_frequencies
                .iter()
                .fold((f64::INFINITY, 0.0f64), |(l, h), &w| (l.min(w), h.max(w)));
            let tuned: Vec<String> = loops
                .iter()
                .map(|p| match p.feedback_frequency() {
                    Some(w) if w == high && low < high => {
                        format!(
                            "{} (the grid's highest: a higher one may do better)",
                            p.label()
                        )
                    }
                    Some(w) if w == low && low < high => {
                        format!(
                            "{} (the grid's lowest: a lower one may do better)",
                            p.label()
                        )
                    }
                    _ => p.label(),
                })
                .collect();
            let _ = writeln!(
                md,
                "gravity-pd and gravity-pid, the controls engineer's first tries: each driven \
                 joint's effort is the nominal model's gravity effort plus a PD loop, M_ii (ω² e \
                 − 2ω q̇), or a PID loop, M_ii (3ω² e + ω³ ∫e dt − 3ω q̇) with its integral held \
                 while the effort is clamped, on the nominal mass matrix's diagonal, e the angle \
                 still to go to the task's targets (the other joints held where the episode \
                 started), clamped to the planners' box, once a frame; each at the ω of the \
                 lowest mean cost among {} rad/s over {} tuning episodes from other stretches of \
                 the log: {}.\n",
                grid.join(", "),
                setup.tuning_episodes,
                tuned.join(", ")
            );
        }
        let mut table = MdTable::new(&["model", "planner", "budget"])
            .numbers(&[
                "evaluations / decision",
                "cost",
                "ms / decision",
                "one-step error",
                "steady-state error",
            ])
            .column("settled", Align::Left)
            .numbers(&["frames within tolerance"])
            .column("against zero torques", Align::Left)
            .column("against random torques", Align::Left);
        for p in &policies {
            let cost = p.cost_cell();
            let [error, settled, within] = p.outcome_cells();
            let against = |reference: &Policy| {
                if p.model == reference.model {
                    "—".to_string()
                } else {
                    p.against(reference, words)
                }
            };
            let planned = p.planned();
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
                if planned {
                    sig3(p.prediction_rms())
                } else {
                    "—".into()
                },
                error,
                settled,
                within,
                against(zero),
                against(random),
            ]);
        }
        table.write(md);
        let tolerance = setup
            .and_then(|s| s.tasks.iter().find(|t| t.name == task))
            .map_or(String::new(), |t| {
                format!(" ({} {} here)", sig3(t.tolerance), t.error_unit)
            });
        let _ = writeln!(
            md,
            "One-step error: the RMS over frames (mean over episodes) of the model's prediction \
             of the task's variables one frame ahead under the torques chosen, against what the \
             simulator then did, in the variables' units (angles on the circle). A frame's error \
             is the largest of the task's angles still to go (rad; a rate's miss, rad/s; a \
             point's distance, m); steady-state error: its mean over an episode's last quarter \
             (mean over episodes); settled: the episodes whose error came within the task's \
             tolerance{tolerance} and stayed there to the end, and the median over every \
             episode of the time it took (never, for one that did not); frames within \
             tolerance: mean over episodes.\n"
        );
        at_equal_time(md, &policies, (zero, random), real_time, words);

        // Each policy's cost minus zero torques', paired episode by episode,
        // against time per decision: one curve per model and planner.
        let mut series: Vec<Series> = Vec::new();
        let planned: Vec<&Policy> = policies.iter().filter(|p| p.planned()).collect();
        let xs: Vec<f64> = planned.iter().map(|p| p.ms()).chain([real_time]).collect();
        let (x_lo, x_hi) = xs
            .iter()
            .filter(|x| **x > 0.0)
            .fold((f64::MAX, 0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        for p in &planned {
            let name = format!("{} {}", p.model, p.planner);
            let Some(d) = Interval::of(&p.differences(zero)) else {
                continue;
            };
            let point = Point {
                y_range: d.low.is_finite().then_some((d.low, d.high)),
                ..Point::at(p.ms(), d.mean)
            };
            match series.iter_mut().find(|s| s.name == name) {
                Some(s) => s.points.push(point),
                None => series.push(Series {
                    name,
                    style: policy_style(p.model.policy, p.model.round, 0),
                    points: vec![point],
                    joined: true,
                    hollow: p.planner == "random-shooting",
                }),
            }
        }
        let loops = policies.iter().filter(|p| p.is_feedback());
        for reference in std::iter::once(random).chain(loops) {
            let Some(d) = Interval::of(&reference.differences(zero)) else {
                continue;
            };
            series.push(Series {
                name: reference.label(),
                style: policy_style(reference.model.policy, reference.model.round, 0),
                points: vec![Point::at(x_lo, d.mean), Point::at(x_hi, d.mean)],
                joined: true,
                hollow: false,
            });
        }
        let mut rules = vec![Rule::horizontal(0.0, "zero torques")];
        if real_time > 0.0 {
            let name = format!("real time ({} ms a frame)", sig3(real_time));
            rules.push(Rule::vertical(real_time, &name));
        }
        let chart = charts::plot(&Plot {
            title: format!("task `{task}`: cost minus zero torques'"),
            x: Axis::log("ms per decision, one thread (log)"),
            y: Axis::linear("cost − zero torques' (paired)"),
            series,
            pareto: false,
            rules,
        });
        let file = chart_name(&format!("plan-{task}"));
        atomic::write_bytes(&dir.join(&file), chart.as_bytes())?;
        let _ = writeln!(
            md,
            "![task {task}: cost minus zero torques' against time per decision]({file})\n\nEach \
             curve is one forward model with one planner (filled: cross-entropy method; hollow: \
             random shooting), a point per budget: its episodes' costs minus zero torques' on \
             the same episodes, bars the 95% interval of that paired difference over the \
             episodes; the flat lines are the random controller's and, where they ran, the PD \
             and PID loops' on the nominal model's gravity compensation, the grey level zero \
             torques'; \
             left of the dashed grey line (real time) a decision takes less than the frame it \
             plans for.\n"
        );
    }
    Ok(())
}

/// The answer at equal wall time: for time limits from a tenth of real time
/// to ten times it, each model and planner at its largest budget whose
/// decisions fit the limit (a rule fixed before any cost is seen, not the
/// best of its budgets), the one with the lowest mean cost, its paired
/// difference from the lowest of every other forward model, and the ALN's
/// standing against zero and random torques.
fn at_equal_time(
    md: &mut String,
    policies: &[Policy],
    (zero, random): (&Policy, &Policy),
    real_time: f64,
    words: bool,
) {
    if real_time <= 0.0 {
        return;
    }
    let methods: Vec<(PlanModel, &str)> = once(
        policies
            .iter()
            .filter(|p| p.planned())
            .map(|p| (p.model, p.planner)),
    );
    let mut table = MdTable::new(&["ms / decision at most"])
        .column("lowest cost", Align::Left)
        .numbers(&["cost"])
        .column("against the next forward model's lowest", Align::Left)
        .column("the ALN's lowest", Align::Left)
        .column("ALN against zero torques", Align::Left)
        .column("ALN against random torques", Align::Left);
    let aln = PlanModel::first(PolicyId::Aln);
    let aln_missing = if methods.iter().any(|&(model, _)| model == aln) {
        "— (none fits)"
    } else {
        "— (not run)"
    };
    let mut rows = 0;
    for factor in [0.1, 0.3, 1.0, 3.0, 10.0] {
        let limit = factor * real_time;
        // Each method at its largest budget within the limit.
        let fitting: Vec<&Policy> = methods
            .iter()
            .filter_map(|&(model, planner)| within(policies, model, planner, limit))
            .collect();
        let mean = |p: &Policy| Interval::of(&p.costs()).map_or(f64::INFINITY, |i| i.mean);
        let lowest_of = |keep: &dyn Fn(&Policy) -> bool| {
            fitting
                .iter()
                .copied()
                .filter(|p| keep(p))
                .min_by(|a, b| mean(a).total_cmp(&mean(b)))
        };
        let Some(best) = lowest_of(&|_| true) else {
            continue;
        };
        let name = |p: &Policy| format!("{} {} ({})", p.model, p.planner, p.budget);
        let next = match lowest_of(&|p| p.model != best.model) {
            Some(next) => format!("{}, vs {}", best.against(next, words), name(next)),
            None if methods.iter().any(|&(model, _)| model != best.model) => {
                "— (no other model fits)".into()
            }
            None => "— (no other forward model was run)".into(),
        };
        let aln = lowest_of(&|p| p.model == aln);
        table.row(vec![
            format!("{} ({factor}× real time)", sig3(limit)),
            name(best),
            best.cost_cell(),
            next,
            aln.map_or(aln_missing.into(), |a| {
                let c = Interval::of(&a.costs()).expect("episodes");
                format!("{}: {}", name(a), estimate(c.mean, c.low, c.high))
            }),
            aln.map_or("—".into(), |a| a.against(zero, words)),
            aln.map_or("—".into(), |a| a.against(random, words)),
        ]);
        rows += 1;
    }
    if rows == 0 {
        return;
    }
    let _ = writeln!(
        md,
        "**At equal time per decision.** For each limit, every model and planner at its \
         largest budget whose median decision fits it (the budget fixed by the limit, not \
         picked by cost); the lowest mean cost among them, and its difference from the \
         lowest of every other forward model, paired by episode.\n"
    );
    table.write(md);
}

/// One forward model's plans within real time: its planner at the largest
/// budget whose median decision fits a frame in replicate 1 (the rule of
/// the equal-time table).
struct Contender<'m> {
    label: String,
    model: PlanModel,
    point: &'m Budgeted,
}

impl Contender<'_> {
    /// The mean over replicates of the mean episode cost.
    fn mean(&self) -> f64 {
        self.point.mean()
    }
}

/// The mean of `x` (0 for none).
pub(super) fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}

/// The first screen's planning answer (issue 43): for each task, every
/// forward model — each variant's ALN, and the first planning variant's
/// linear fit and simulators, the scene as written (`simulator@k`) and,
/// where the data come from a plant, the plant's own (`plant@k`, the
/// reference no user has) — within real time, paired on the same episodes
/// against the nominal simulator of the lowest mean cost within real time: the
/// mean difference across replicates with its 95% interval (over the
/// episodes of the one replicate when there is one) and the Wilcoxon
/// signed-rank p-value over every paired episode. A variant whose episodes
/// are not the first's (its zero torques cost otherwise) is left out, said
/// so.
pub(super) fn at_real_time(md: &mut String, variants: &[super::Loaded]) {
    at_real_time_of(md, &planned(variants));
}

/// Each variant's name and planning episodes.
pub(super) fn planned<'a>(variants: &'a [super::Loaded]) -> Vec<Planned<'a>> {
    variants
        .iter()
        .map(|v| Planned {
            name: &v.info.name,
            planning: &v.planning,
            setup: v.info.plan_setup.as_ref(),
        })
        .collect()
}

/// A variant's name, its replicates' planning episodes and what the plan
/// stage was asked (its tasks' units).
pub(super) struct Planned<'a> {
    pub name: &'a str,
    pub planning: &'a [Vec<Episode>],
    pub setup: Option<&'a super::PlanSetup>,
}

/// The variants whose first replicate planned anything.
pub(super) fn with_plans<'b, 'a>(variants: &'b [Planned<'a>]) -> Vec<&'b Planned<'a>> {
    variants
        .iter()
        .filter(|v| v.planning.first().is_some_and(|r| !r.is_empty()))
        .collect()
}

/// [`at_real_time`] of the variants' planning.
fn at_real_time_of(md: &mut String, variants: &[Planned]) {
    let planned = with_plans(variants);
    let Some(first) = planned.first() else {
        return;
    };
    let replicates = first.planning.len();
    for task in tasks(&first.planning[0]) {
        let limit = real_time(&first.planning[0], task);
        let (methods, left_out) = super::plan_frontier::methods(&planned, task);
        let contenders: Vec<Contender> = methods
            .iter()
            .filter_map(|m| {
                let point = m.within(limit)?;
                Some(Contender {
                    label: m.at(point),
                    model: m.model,
                    point,
                })
            })
            .collect();
        let nominal = contenders
            .iter()
            .filter(|c| matches!(c.model.policy, PolicyId::Simulator { .. }))
            .min_by(|a, b| a.mean().total_cmp(&b.mean()));
        let Some(nominal) = nominal else {
            continue;
        };
        let mut table = MdTable::new(&["forward model, planner (budget)"])
            .numbers(&["ms / decision", "µs / state", "cost"])
            .column(&format!("− {}", nominal.label), Align::Left)
            .column("signed-rank p, median difference (episodes)", Align::Left)
            .numbers(&["one-step error", "error at the horizon"]);
        let mut order: Vec<&Contender> = contenders.iter().collect();
        order.sort_by(|a, b| a.mean().total_cmp(&b.mean()));
        let over = if replicates > 1 {
            format!("across {replicates} replicates")
        } else {
            "over the episodes of one replicate".to_string()
        };
        let mut aln_planned = false;
        // The ALNs whose plans cost less than the nominal simulator's, the
        // interval below zero: the question's answer.
        let mut aln_lower: Vec<&str> = Vec::new();
        for c in &order {
            let means: Vec<f64> = c.point.costs.iter().map(|r| mean(r)).collect();
            let cost = match Interval::of(&means) {
                Some(i) if replicates > 1 => estimate(i.mean, i.low, i.high),
                _ => sig3(c.mean()),
            };
            let pooled = c.point.pooled_minus(nominal.point);
            let (difference, p) = if std::ptr::eq(*c, nominal) {
                ("—".to_string(), "—".to_string())
            } else {
                let per: Vec<f64> = if replicates > 1 {
                    c.point.minus(nominal.point)
                } else {
                    pooled.clone()
                };
                let difference = Interval::of(&per).map_or("—".into(), |d| {
                    format!(
                        "{}: {}",
                        d.verdict().as_str(),
                        interval(d.mean, d.low, d.high)
                    )
                });
                // The signed-rank test is of the median: say which way.
                let p = super::plan_frontier::rank_cell(&pooled);
                if c.model.policy == PolicyId::Aln {
                    aln_planned = true;
                    let lower = Interval::of(&per).is_some_and(|d| d.verdict() == Verdict::Lower);
                    if lower {
                        aln_lower.push(&c.label);
                    }
                }
                (difference, p)
            };
            let label = if matches!(c.model.policy, PolicyId::Plant { .. }) {
                format!("{} — reference", c.label)
            } else {
                c.label.clone()
            };
            table.row(vec![
                label,
                sig3(c.point.ms),
                sig3(c.point.ms * 1e3 / c.point.evaluations.max(1) as f64),
                cost,
                difference,
                p,
                sig3(c.point.one_step),
                sig3(c.point.horizon),
            ]);
        }
        let best = order[0];
        let _ = writeln!(
            md,
            "**Planning `{task}` within real time** ({} ms a decision): {} {} has the lowest \
             mean cost of the forward models a user could have{}. Below, every model and planner \
             at its largest budget whose median decision fits a frame in replicate 1, on the same \
             episodes; the deadline table further down picks among them on replicate 1 alone \
             and judges on the other replicates.\n",
            sig3(limit),
            match (aln_lower.as_slice(), aln_planned) {
                (_, false) => "No ALN plans within real time.".to_string(),
                ([], true) => format!(
                    "no ALN plans to a lower cost than {}, the nominal simulator of the lowest \
                     mean cost ({over}).",
                    nominal.label
                ),
                (lower, true) => format!(
                    "{} {} to a lower cost than {}, the nominal simulator of the lowest mean cost \
                     ({over}).",
                    lower.join(" and "),
                    if lower.len() > 1 { "plan" } else { "plans" },
                    nominal.label
                ),
            },
            order
                .iter()
                .find(|c| !matches!(c.model.policy, PolicyId::Plant { .. }))
                .map_or(best.label.clone(), |c| c.label.clone()),
            if matches!(best.model.policy, PolicyId::Plant { .. }) {
                format!(
                    " (the plant's own simulator, which no user has, has a lower mean still: {})",
                    best.label
                )
            } else {
                String::new()
            },
        );
        table.write(md);
        let _ = writeln!(
            md,
            "µs / state: the decision's time over the states its model predicted (sequences × \
             horizon), the planner's own work included. Every model predicts a decision's \
             candidates together (a simulator, the plant's own too, and a hybrid's nominal step \
             in SIMD lanes; the plant's own simulator predicts its mean, without its actuators' \
             noise), except a simulator of a scene integrated by RK4, of a robot with mimic \
             joints, or costing a task that reads a link's acceleration or external force, which \
             steps them one at a time. Cost: the task's summed cost, mean {over}. Differences: \
             from the nominal simulator of the lowest mean cost, paired, {over}; beside them the \
             Wilcoxon signed-rank p over every paired episode and the median paired difference \
             (a replicate's episodes share its model, so the interval across replicates is the \
             verdict). One-step error: the model's prediction of the task's variables one frame \
             ahead against what the plant then did, RMS over each episode's frames, mean over \
             episodes, on the states its own planner visited. Error at the horizon: the same, \
             the model fed its own predictions for as many frames as the planner looks ahead \
             ({} frames, the torques executed), from every frame with that many after it: the \
             error its plans were scored with.{}{}\n",
            first.planning[0]
                .iter()
                .find(|e| e.budget > 0)
                .map_or(0, |e| e.evaluations / u64::from(e.budget)),
            if contenders.iter().any(|c| c.model.round > 0) {
                " A model \"(round r)\" was trained again after r rounds of the ALN's planned \
                 frames joined the training rows (DAgger for models), and planned the same \
                 episodes."
            } else {
                ""
            },
            if left_out.is_empty() {
                String::new()
            } else {
                format!(
                    " Left out, its episodes not the same: {}.",
                    left_out.join(", ")
                )
            }
        );
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Episode `k` of `task` by `model` with `planner` at `budget` (a
    /// reference: no planner, budget 0): its cost, `ms` a decision, a frame
    /// 10 ms, its steady-state error a hundredth of `base`.
    pub(in super::super) fn row(
        task: &str,
        (model, planner, budget): (&str, &str, u32),
        k: u32,
        (base, cost): (f64, f64),
        ms: f64,
    ) -> Episode {
        Episode {
            task: task.into(),
            model: model.parse().unwrap(),
            round: 0,
            planner: planner.into(),
            budget,
            episode: k,
            evaluations: u64::from(budget) * 10,
            cost,
            ms_per_decision: ms,
            ms_min: ms,
            ms_max: ms,
            real_time_ms: 10.0,
            prediction_rms: 0.1,
            horizon_rms: 0.4,
            final_error: 0.01 * base,
            settle_s: if k == 0 {
                f64::INFINITY
            } else {
                0.1 * f64::from(k)
            },
            within_tolerance: 0.5,
            feedback_frequency: if model.starts_with("gravity-") {
                8.0
            } else {
                f64::NAN
            },
        }
    }

    /// Four episodes of `model` (with `planner` when it planned), costs
    /// `base` + the episode, each decision `ms` long, a frame 10 ms.
    fn episodes(model: &str, planner: &str, base: f64, ms: f64) -> Vec<Episode> {
        (0..4)
            .map(|k| {
                let budget = if planner.is_empty() { 0 } else { 64 };
                let step = if planner.is_empty() { 1.0 } else { 1.1 };
                let cost = base + f64::from(k) * step;
                row("bend", (model, planner, budget), k, (base, cost), ms)
            })
            .collect()
    }

    /// The ALN alone planned, well below zero torques on every episode.
    fn aln_only() -> Vec<Episode> {
        [
            episodes("zero", "", 50.0, 0.0),
            episodes("random", "", 80.0, 0.0),
            episodes("aln", "cem", 10.0, 1.0),
        ]
        .concat()
    }

    fn rendered(replicates: usize) -> String {
        let dir = tempfile::tempdir().unwrap();
        let mut md = String::new();
        section(&mut md, &aln_only(), replicates, None, dir.path(), |c| {
            format!("{c}.svg")
        })
        .unwrap();
        md
    }

    /// The feedback loops are described with the frequency each was tuned
    /// to, and a pick at an end of the grid is said to be one.
    #[test]
    fn a_task_is_named_once_though_a_rounds_rows_follow_every_task_again() {
        let rows: Vec<Episode> = ["raise", "hold", "raise", "hold"]
            .iter()
            .enumerate()
            .map(|(k, task)| row(task, ("aln", "cem", 8), k as u32, (1.0, 1.0), 1.0))
            .collect();
        assert_eq!(tasks(&rows), ["raise", "hold"]);
    }

    #[test]
    fn a_loop_tuned_to_the_grids_end_is_said_to_be() {
        let mut rows = aln_only();
        rows.extend((0..4).map(|k| row("bend", ("gravity-pd", "", 0), k, (30.0, 30.0), 0.0)));
        let setup = PlanSetup {
            tasks: vec![super::super::PlanTask {
                name: "bend".into(),
                definition: "reach and hold".into(),
                unit: "rad²".into(),
                error_unit: "rad".into(),
                tolerance: 0.05,
            }],
            horizon: 10,
            frames: 40,
            episodes: 4,
            feedback_frequencies: vec![2.0, 8.0],
            tuning_episodes: 4,
        };
        let dir = tempfile::tempdir().unwrap();
        let mut md = String::new();
        section(&mut md, &rows, 1, Some(&setup), dir.path(), |c| {
            format!("{c}.svg")
        })
        .unwrap();
        assert!(
            md.contains(
                "lowest mean cost among 2, 8 rad/s over 4 tuning episodes from other stretches \
                 of the log: gravity-pd (ω 8 rad/s) (the grid's highest: a higher one may do \
                 better)."
            ),
            "{md}"
        );
        assert!(md.contains("| gravity-pd | — | — |"), "{md}");
    }

    #[test]
    fn one_replicate_of_several_gets_no_verdict_words() {
        let several = rendered(3);
        assert!(several.contains("replicate 1's of 3"), "{several}");
        for word in ["lower:", "higher:", "indistinguishable:"] {
            assert!(!several.contains(word), "{word} in {several}");
        }
        // The run's only replicate: the verdict its interval allows.
        let one = rendered(1);
        assert!(one.contains("lower: "), "{one}");
    }

    /// Two variants of two replicates: each ALN set against the nominal
    /// simulator that plans best within real time, with the mean
    /// difference across replicates and the signed-rank p-value over the
    /// eight paired episodes; the plant's simulator a reference; a variant
    /// on other episodes left out.
    #[test]
    fn planning_within_real_time_pairs_every_forward_model_with_the_nominal_simulator() {
        let replicate = |aln: f64| {
            [
                episodes("zero", "", 50.0, 0.0),
                episodes("random", "", 80.0, 0.0),
                episodes("aln", "cem", aln, 1.0),
                episodes("simulator@10", "cem", 20.0, 5.0),
                episodes("simulator@1", "cem", 30.0, 1.0),
                episodes("simulator@10", "cem", 5.0, 50.0)
                    .into_iter()
                    .map(|e| Episode { budget: 512, ..e })
                    .collect(),
                episodes("plant@10", "cem", 12.0, 5.0),
            ]
            .concat()
        };
        let learned = [replicate(10.0), replicate(12.0), replicate(11.0)];
        let hybrid = [replicate(25.0), replicate(26.0), replicate(27.0)];
        let mut other = [replicate(10.0), replicate(10.0), replicate(10.0)];
        for e in other
            .iter_mut()
            .flatten()
            .filter(|e| e.model == PolicyId::Zero)
        {
            e.cost += 1.0;
        }
        let mut md = String::new();
        at_real_time_of(
            &mut md,
            &[
                Planned {
                    name: "learned",
                    planning: &learned,
                    setup: None,
                },
                Planned {
                    name: "hybrid",
                    planning: &hybrid,
                    setup: None,
                },
                Planned {
                    name: "other",
                    planning: &other,
                    setup: None,
                },
            ],
        );
        assert!(
            md.contains("ALN (`learned`), cem (64 sequences) has the lowest mean cost"),
            "{md}"
        );
        assert!(
            md.contains(
                "(10 ms a decision): ALN (`learned`), cem (64 sequences) plans to a lower cost \
                 than simulator@10, cem (64 sequences), the nominal simulator of the lowest mean \
                 cost (across 3 replicates)."
            ),
            "{md}"
        );
        // The 512-sequence simulator takes 50 ms: beyond a frame.
        assert!(md.contains("− simulator@10, cem (64 sequences)"), "{md}");
        // learned: −10, −8 and −9 across the replicates.
        let row = |label: &str| -> &str {
            md.lines()
                .find(|l| l.starts_with(&format!("| {label} |")))
                .unwrap_or_else(|| panic!("no row {label}: {md}"))
        };
        assert!(
            row("ALN (`learned`), cem (64 sequences)").contains("| lower: -9.0 ["),
            "{md}"
        );
        // The pooled episode differences, as the table computes them.
        let pooled: Vec<f64> = [10.0, 12.0, 11.0]
            .iter()
            .flat_map(|&aln| (0..4).map(move |k| (aln + k as f64 * 1.1) - (20.0 + k as f64 * 1.1)))
            .collect();
        let p = alnlab_summarize::signed_rank::test(&pooled).unwrap().p;
        assert!(
            row("ALN (`learned`), cem (64 sequences)")
                .contains(&format!("| {}, median -9 (12) |", sig3(p))),
            "{md}"
        );
        assert_eq!(md.matches("| simulator@10, cem").count(), 1, "{md}");
        assert!(
            row("ALN (`hybrid`), cem (64 sequences)").contains("| higher: "),
            "{md}"
        );
        assert!(
            md.contains("plant@10, cem (64 sequences) — reference"),
            "{md}"
        );
        assert!(
            md.contains("Left out, its episodes not the same: other."),
            "{md}"
        );
    }

    #[test]
    fn a_model_not_run_is_said_to_be_not_run() {
        let md = rendered(1);
        assert!(md.contains("— (no other forward model was run)"), "{md}");
        assert!(!md.contains("no other model fits"), "{md}");
    }
}
