//! The planning frontier (issue 62): every forward model's cost at every
//! budget it planned with, against its time a decision, on the same
//! episodes — what a model buys at each deadline, rather than at the one
//! budget a manifest happened to give it. From it: the verdict at fixed
//! deadlines, each model at its largest budget whose decisions fit (a rule
//! of time, never of cost), paired with the nominal simulator there; and
//! the regret against the plant's own simulator, the true model no user
//! has, at the same budget and at its best.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{PolicyId, Result, atomic};
use alnlab_summarize::paired::{Interval, Verdict};

use super::PlanTask;
use super::format::{Align, MdTable, and_list, estimate, interval, sig3, signed};
use super::plan::{PlanModel, Planned, mean, policies, tasks, with_plans};
use crate::charts::{self, Axis, Plot, Point, Rule, Series, policy_style};

/// The deadlines a decision is judged at, in ms.
pub(super) const DEADLINES: [f64; 4] = [1.0, 2.0, 5.0, 10.0];

/// One budget of a forward model: its time and its costs.
pub(super) struct Budgeted {
    pub budget: u32,
    /// Replicate 1's median ms a decision: the time every rule reads.
    pub ms: f64,
    /// Forward-model evaluations (states predicted) a decision.
    pub evaluations: u64,
    /// `[replicate][episode]` summed task costs.
    pub costs: Vec<Vec<f64>>,
    /// The model's one-step error and its error at the horizon on the
    /// task's variables, mean over every episode.
    pub one_step: f64,
    pub horizon: f64,
    /// `[replicate]` the steady-state error in the task's unit, mean over
    /// the replicate's episodes (NaN for tables written before the column).
    pub final_errors: Vec<f64>,
}

impl Budgeted {
    /// The mean over replicates of the mean episode cost.
    pub fn mean(&self) -> f64 {
        let means: Vec<f64> = self.costs.iter().map(|c| mean(c)).collect();
        mean(&means)
    }

    /// Each replicate's mean cost minus `other`'s (the same episodes).
    pub fn minus(&self, other: &Budgeted) -> Vec<f64> {
        self.costs
            .iter()
            .zip(&other.costs)
            .map(|(a, b)| mean(a) - mean(b))
            .collect()
    }

    /// Replicate 1's mean cost: what a pick among models reads, so that
    /// the verdict on the others is not read from the episodes it was
    /// picked on.
    pub fn picked(&self) -> f64 {
        self.costs.first().map_or(f64::NAN, |c| mean(c))
    }

    /// The mean over replicates of the steady-state error.
    pub fn final_error(&self) -> f64 {
        mean(&self.final_errors)
    }

    /// The same, without replicate 1: what a verdict on a pick reads.
    fn judged(&self) -> Budgeted {
        Budgeted {
            costs: self.costs.iter().skip(1).cloned().collect(),
            final_errors: self.final_errors.iter().skip(1).copied().collect(),
            ..*self
        }
    }

    /// Every episode's cost minus `other`'s, all replicates pooled.
    pub fn pooled_minus(&self, other: &Budgeted) -> Vec<f64> {
        self.costs
            .iter()
            .zip(&other.costs)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(a, b)| a - b))
            .collect()
    }
}

/// A forward model with one planner: its name on the first screen and a
/// point per budget, in budget order.
pub(super) struct Method {
    pub label: String,
    pub model: PlanModel,
    pub planner: String,
    pub budgets: Vec<Budgeted>,
}

impl Method {
    /// The label with its budget: "simulator@1, cem (256 sequences)".
    pub fn at(&self, b: &Budgeted) -> String {
        format!("{}, {} ({} sequences)", self.label, self.planner, b.budget)
    }

    /// Its largest budget whose median decision in replicate 1 fits
    /// `limit` ms: a rule fixed before any cost is seen.
    pub fn within(&self, limit: f64) -> Option<&Budgeted> {
        self.budgets
            .iter()
            .filter(|b| b.ms <= limit)
            .max_by_key(|b| b.budget)
    }

    /// Its budget of the lowest mean cost in replicate 1: the best it
    /// achieves, given any time, picked on replicate 1's episodes.
    pub fn saturated(&self) -> Option<&Budgeted> {
        self.budgets
            .iter()
            .min_by(|a, b| a.picked().total_cmp(&b.picked()))
    }
}

/// Every forward model of `task` with each planner, on the episodes of the
/// first variant: each variant's ALN (every round), and the first
/// variant's other models (the linear fit, the simulators, the plant's
/// own). A variant whose episodes differ (its zero torques cost otherwise)
/// is left out and named in the second list.
pub(super) fn methods<'a>(planned: &[&Planned<'a>], task: &str) -> (Vec<Method>, Vec<&'a str>) {
    let Some(first) = planned.first() else {
        return (Vec::new(), Vec::new());
    };
    let replicates = first.planning.len();
    let zero_costs = |v: &Planned| -> Option<Vec<Vec<f64>>> {
        v.planning
            .iter()
            .map(|rows| {
                let policies = policies(rows, task);
                let zero = policies.iter().find(|p| p.model.policy == PolicyId::Zero)?;
                Some(zero.costs())
            })
            .collect()
    };
    let reference = zero_costs(first);
    let several = planned.len() > 1;
    let (mut methods, mut left_out): (Vec<Method>, Vec<&str>) = (Vec::new(), Vec::new());
    for v in planned {
        if v.planning.len() != replicates || zero_costs(v) != reference {
            left_out.push(v.name);
            continue;
        }
        let each: Vec<_> = v.planning.iter().map(|rows| policies(rows, task)).collect();
        for p in each[0].iter().filter(|p| p.planned()) {
            if p.model.policy != PolicyId::Aln && !std::ptr::eq(*v, *first) {
                continue;
            }
            let costs: Option<Vec<Vec<f64>>> = each
                .iter()
                .map(|r| {
                    let q = r.iter().find(|q| {
                        q.model == p.model && q.planner == p.planner && q.budget == p.budget
                    })?;
                    Some(q.costs())
                })
                .collect();
            let Some(costs) = costs else {
                continue;
            };
            let chosen = || {
                v.planning.iter().flat_map(|rows| {
                    rows.iter().filter(|e| {
                        e.task == task
                            && PlanModel::of(e) == p.model
                            && e.planner == p.planner
                            && e.budget == p.budget
                    })
                })
            };
            let one_step: Vec<f64> = chosen().map(|e| e.prediction_rms).collect();
            let horizon: Vec<f64> = chosen().map(|e| e.horizon_rms).collect();
            let final_errors = each
                .iter()
                .map(|r| {
                    r.iter()
                        .find(|q| {
                            q.model == p.model && q.planner == p.planner && q.budget == p.budget
                        })
                        .map_or(f64::NAN, |q| q.final_error())
                })
                .collect();
            let point = Budgeted {
                budget: p.budget,
                ms: p.ms(),
                evaluations: p.evaluations,
                costs,
                one_step: mean(&one_step),
                horizon: mean(&horizon),
                final_errors,
            };
            let label = match (p.model.policy, several) {
                (PolicyId::Aln, true) => format!("ALN{} (`{}`)", p.model.round_suffix(), v.name),
                (PolicyId::Aln, false) => format!("ALN{}", p.model.round_suffix()),
                _ => p.model.to_string(),
            };
            match methods
                .iter_mut()
                .find(|m| m.label == label && m.planner == p.planner)
            {
                Some(m) => m.budgets.push(point),
                None => methods.push(Method {
                    label,
                    model: p.model,
                    planner: p.planner.to_string(),
                    budgets: vec![point],
                }),
            }
        }
    }
    for m in &mut methods {
        m.budgets.sort_by_key(|b| b.budget);
    }
    (methods, left_out)
}

/// `a` minus `b`, paired: across replicates (each replicate's mean
/// difference) when there are several, else over the one replicate's
/// episodes.
fn paired(a: &Budgeted, b: &Budgeted) -> Option<Interval> {
    match a.costs.len() {
        1 => Interval::of(&a.pooled_minus(b)),
        _ => Interval::of(&a.minus(b)),
    }
}

/// The Wilcoxon signed-rank p-value over paired episode differences, with
/// the median difference it tests and their number: "3.5e-7, median +1.60
/// (40)".
pub(super) fn rank_cell(pooled: &[f64]) -> String {
    let mut sorted = pooled.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    if n == 0 {
        return "—".into();
    }
    let median = (sorted[(n - 1) / 2] + sorted[n / 2]) / 2.0;
    alnlab_summarize::signed_rank::test(pooled).map_or("— (every episode tied)".into(), |t| {
        format!("{}, median {} ({n})", sig3(t.p), signed(median))
    })
}

/// The true model among `methods`: the plant's own simulator at the most
/// steps a frame where the data come from a plant, else the scene's own
/// simulator at the most (the scene as written is then the plant).
fn truth(methods: &[Method]) -> Option<&Method> {
    let steps = |m: &&Method| match m.model.policy {
        PolicyId::Plant { steps } => Some((1, steps)),
        PolicyId::Simulator { steps } => Some((0, steps)),
        _ => None,
    };
    methods
        .iter()
        .filter(|m| m.model.round == 0 && steps(m).is_some())
        .max_by_key(|m| steps(m))
}

/// The first screen's frontier of each task: a chart of every forward
/// model's regret (its cost minus the true model's at its best budget,
/// paired) against its time a decision, a point per budget; and the
/// verdict at each of [`DEADLINES`].
pub(super) fn section(md: &mut String, variants: &[Planned], dir: &Path) -> Result<()> {
    let planned = with_plans(variants);
    let Some(first) = planned.first() else {
        return Ok(());
    };
    let replicates = first.planning.len();
    for task in tasks(&first.planning[0]) {
        let (methods, left_out) = methods(&planned, task);
        let Some(truth) = truth(&methods) else {
            continue;
        };
        let Some(best) = truth.saturated() else {
            continue;
        };
        let truth_name = match truth.model.policy {
            PolicyId::Plant { .. } => {
                "the plant's own simulator (predicting its mean: its actuators' noise left out), \
                 the reference no user has"
            }
            _ => {
                "the scene's own simulator at its own step, the true model (the scene has no \
                  plant, so a user has it too)"
            }
        };
        chart(md, &methods, (truth, best), truth_name, task, dir)?;
        if !left_out.is_empty() {
            let _ = writeln!(
                md,
                "Left out of the frontier, their episodes not the same: {}.\n",
                left_out.join(", ")
            );
        }
        let feedback = feedback(first, task);
        let defined = first
            .setup
            .and_then(|s| s.tasks.iter().find(|t| t.name == task));
        deadlines(
            md,
            &methods,
            (truth, feedback.as_ref()),
            (task, defined),
            replicates,
        );
    }
    Ok(())
}

/// A feedback loop on gravity compensation, as a point to set the deadline
/// picks against (budget and time 0: it plans nothing).
struct Loop {
    policy: PolicyId,
    point: Budgeted,
    /// Its frequency as tuned, per replicate (rad/s).
    omegas: Vec<f64>,
}

/// The controls engineer's best first try in `task`: of the feedback loops
/// that ran in every replicate, the one of the lower cost in replicate 1
/// (picked there, judged on the others, as the deadline picks are); `None`
/// where none ran.
fn feedback(v: &Planned, task: &str) -> Option<Loop> {
    let each: Vec<_> = v.planning.iter().map(|rows| policies(rows, task)).collect();
    let loops = [PolicyId::GravityPd, PolicyId::GravityPid].map(|policy| -> Option<Loop> {
        let mut point = Budgeted {
            budget: 0,
            ms: 0.0,
            evaluations: 0,
            costs: Vec::new(),
            one_step: f64::NAN,
            horizon: f64::NAN,
            final_errors: Vec::new(),
        };
        let mut omegas = Vec::new();
        for policies in &each {
            let held = policies.iter().find(|p| p.model.policy == policy)?;
            point.costs.push(held.costs());
            point.final_errors.push(held.final_error());
            omegas.push(held.feedback_frequency()?);
        }
        Some(Loop {
            policy,
            point,
            omegas,
        })
    });
    loops
        .into_iter()
        .flatten()
        .min_by(|a, b| a.point.picked().total_cmp(&b.point.picked()))
}

/// The frontier chart of one task.
fn chart(
    md: &mut String,
    methods: &[Method],
    (truth, best): (&Method, &Budgeted),
    truth_name: &str,
    task: &str,
    dir: &Path,
) -> Result<()> {
    // One curve per model and round of the planner's own data, each ALN
    // variant in its own colour, a round in its marker.
    let mut series = Vec::new();
    let mut variants: Vec<String> = Vec::new();
    for m in methods {
        let points: Vec<Point> = m
            .budgets
            .iter()
            .filter_map(|b| {
                let d = paired(b, best)?;
                Some(Point {
                    y_range: d.low.is_finite().then_some((d.low, d.high)),
                    ..Point::at(b.ms, d.mean)
                })
            })
            .collect();
        // A variant's rounds share its colour: its label less the round.
        let variant = match m.model.policy {
            PolicyId::Aln => {
                let of = m.label.replace(&m.model.round_suffix(), "");
                match variants.iter().position(|v| *v == of) {
                    Some(k) => k,
                    None => {
                        variants.push(of);
                        variants.len() - 1
                    }
                }
            }
            _ => 0,
        };
        series.push(Series {
            // Markdown's code quotes mean nothing in a chart.
            name: format!("{}, {}", m.label.replace('`', ""), m.planner),
            style: policy_style(m.model.policy, m.model.round, variant),
            points,
            joined: true,
            hollow: m.planner == "random-shooting",
        });
    }
    let named = DEADLINES.map(sig3).join(", ");
    let mut rules: Vec<Rule> = DEADLINES
        .iter()
        .map(|&d| Rule::vertical(d, &format!("deadlines: {named} ms")))
        .collect();
    rules.push(Rule::horizontal(
        0.0,
        &format!("{}, the reference, at its best budget", truth.label),
    ));
    let svg = charts::plot(&Plot {
        title: format!("task `{task}`: cost above the reference's best"),
        x: Axis::log("ms a decision, one thread (log)"),
        y: Axis::difference(&format!(
            "cost − {} ({} sequences)",
            truth.label, best.budget
        )),
        series,
        pareto: false,
        rules,
    });
    let file = format!("plan-frontier-{task}.svg");
    atomic::write_bytes(&dir.join(&file), svg.as_bytes())?;
    let _ = writeln!(
        md,
        "![task {task}: the planning frontier]({file})\n\n**The planning frontier of `{task}`.** \
         Every forward model at every budget it planned with (a point each, joined by \
         budget; a model trained again on its planner's frames in its colour, with a marker \
         of its round): its task cost minus that of {truth_name} ({}, at its lowest-cost budget in \
         replicate 1, here {} sequences), paired on the same \
         episodes and averaged over every replicate, against the median ms a decision of \
         replicate 1 (bars: 95% interval of the paired difference across replicates; the table \
         below judges on the replicates after the first, which its picks were not made on). \
         Where the differences span decades the vertical axis is linear in a shaded band around \
         zero and logarithmic beyond, so that those near zero, where the deadlines' verdicts are \
         read, stay apart; a symmetric interval that crosses the band looks lopsided. Given budget, a wrong model may match the reference: the task \
         tells models apart only as far as their errors change the plans. Lower is better; a \
         model moves the frontier where its curve passes below every other's at the same \
         time. The grey verticals are the deadlines the table below reads. Where an ALN is \
         lower, its regret at the same budget says why: a model that costs less a state \
         searches more sequences in the time, which can outweigh its larger error.\n",
        truth.label, best.budget
    );
    Ok(())
}

/// A deadline's pick: a forward model, its largest budget that fits (less
/// replicate 1: what a verdict reads), and how many of its kind fit.
type Pick<'m> = (&'m Method, Budgeted, usize);

/// At `limit` ms, the nominal simulator and the ALN of the lowest mean cost
/// in replicate 1 (so picked on its episodes), each at its largest budget
/// whose median decision fits.
fn picks(methods: &[Method], limit: f64) -> (Option<Pick<'_>>, Option<Pick<'_>>) {
    let lowest = |keep: &dyn Fn(&Method) -> bool| {
        let fitting: Vec<(&Method, &Budgeted)> = methods
            .iter()
            .filter(|m| keep(m))
            .filter_map(|m| Some((m, m.within(limit)?)))
            .collect();
        let n = fitting.len();
        let pick = fitting
            .into_iter()
            .min_by(|a, b| a.1.picked().total_cmp(&b.1.picked()));
        pick.map(|(m, b)| (m, b.judged(), n))
    };
    (
        lowest(&|m| matches!(m.model.policy, PolicyId::Simulator { .. })),
        lowest(&|m| m.model.policy == PolicyId::Aln),
    )
}

/// The abstract's sentence on planning, where the frontier reads verdicts
/// at deadlines: per task, the best ALN minus the best nominal simulator at
/// each deadline, neighbouring deadlines of one verdict together, and the
/// last deadline's pick of the lower replicate-1 cost against the controls
/// engineer's loop where one ran. `None` with fewer than 3 replicates or no
/// task the ALN planned.
pub(super) fn abstract_sentence(variants: &[Planned]) -> Option<String> {
    let planned = with_plans(variants);
    let first = planned.first()?;
    let replicates = first.planning.len();
    if replicates < 3 {
        return None;
    }
    let mut said = Vec::new();
    for task in tasks(&first.planning[0]) {
        let (methods, _) = methods(&planned, task);
        if truth(&methods).and_then(Method::saturated).is_none() {
            continue;
        }
        // Runs of neighbouring deadlines of one verdict (`None`: only the
        // ALN fits), in deadline order.
        let mut runs: Vec<(Option<Verdict>, Vec<String>)> = Vec::new();
        let mut last = None;
        for &limit in &DEADLINES {
            let (nominal, aln) = picks(&methods, limit);
            let deadline = format!("{} ms", sig3(limit));
            let (verdict, figure) = match (&nominal, &aln) {
                (Some((_, nb, _)), Some((_, ab, _))) => {
                    let Some(d) = paired(ab, nb) else {
                        continue;
                    };
                    let figure = format!(
                        "{deadline} ({}{})",
                        interval(d.mean, d.low, d.high),
                        p_if_indistinguishable(&d, ab, nb)
                    );
                    (Some(d.verdict()), figure)
                }
                (None, Some(_)) => (None, deadline),
                _ => continue,
            };
            match runs.last_mut() {
                Some((v, at)) if *v == verdict => at.push(figure),
                _ => runs.push((verdict, vec![figure])),
            }
            last = Some((limit, [nominal, aln]));
        }
        if runs.is_empty() {
            continue;
        }
        let verdicts: Vec<String> = runs
            .iter()
            .map(|(verdict, at)| match verdict {
                None => format!("only the ALN fits at {}", and_list(at)),
                Some(v) => format!("{} at {}", v.as_str(), and_list(at)),
            })
            .collect();
        let mut phrase = format!("`{task}`: {}", verdicts.join(", "));
        // The last deadline's pick of the lower cost in replicate 1 against
        // the loop, judged on the other replicates as the picks are.
        if let (Some(held), Some((limit, last))) = (feedback(first, task), last) {
            let lower = last
                .iter()
                .flatten()
                .filter_map(|(m, b, _)| Some((m, b, m.within(limit)?.picked())))
                .min_by(|a, b| a.2.total_cmp(&b.2));
            let judged = held.point.judged();
            if let Some((m, b, _)) = lower
                && let Some(d) = paired(b, &judged)
            {
                let verdict = d.verdict();
                let _ = write!(
                    phrase,
                    ", and at {} ms {} {} the {} loop on the nominal model's gravity \
                     compensation, which plans nothing ({}{})",
                    sig3(limit),
                    m.at(b),
                    match verdict {
                        Verdict::Lower => "is lower than",
                        Verdict::Higher => "is higher than",
                        Verdict::Indistinguishable => "is indistinguishable from",
                        Verdict::Tied => "is tied with",
                    },
                    law(held.policy),
                    interval(d.mean, d.low, d.high),
                    p_if_indistinguishable(&d, b, &judged)
                );
            }
        }
        said.push(phrase);
    }
    (!said.is_empty()).then(|| {
        format!(
            "Planning, each model at its largest budget that decides in time, the best ALN minus \
             the best nominal simulator (picked on replicate 1, judged on the other {}): {}.",
            replicates - 1,
            said.join("; ")
        )
    })
}

/// ", p = 0.31" where `d` (`a` minus `b`) holds zero: the signed-rank p over
/// their paired episodes, which an "indistinguishable" never goes without.
fn p_if_indistinguishable(d: &Interval, a: &Budgeted, b: &Budgeted) -> String {
    match d.verdict() {
        Verdict::Indistinguishable => alnlab_summarize::signed_rank::test(&a.pooled_minus(b))
            .map(|t| format!(", p = {}", sig3(t.p)))
            .unwrap_or_default(),
        _ => String::new(),
    }
}

/// "PD" or "PID": a feedback loop's law by name.
fn law(policy: PolicyId) -> &'static str {
    match policy {
        PolicyId::GravityPid => "PID",
        _ => "PD",
    }
}

/// The verdict of one task at each deadline: the nominal simulator and the
/// ALN of the lowest mean cost in replicate 1 among those whose largest
/// budget that fits, and the true model, judged on the other replicates:
/// the differences and the regrets.
fn deadlines(
    md: &mut String,
    methods: &[Method],
    (truth, feedback): (&Method, Option<&Loop>),
    (task, defined): (&str, Option<&PlanTask>),
    replicates: usize,
) {
    // The units of a cost and of a frame's error, where the run says them.
    let unit = |of: fn(&PlanTask) -> &str| defined.map_or("", of);
    let (cost_unit, error_unit) = (unit(|t| &t.unit), unit(|t| &t.error_unit));
    let titled = |name: &str, unit: &str| match unit {
        "" => name.to_string(),
        unit => format!("{name} ({unit})"),
    };
    if replicates < 3 {
        let _ = writeln!(
            md,
            "No verdict at fixed deadlines: the models are picked on replicate 1 and judged on \
             the others, which takes at least 3 replicates ({replicates} here).\n"
        );
        return;
    }
    let judged = replicates - 1;
    let mut table = MdTable::new(&["deadline", "forward model, planner (budget)"])
        .numbers(&[
            "ms / decision".to_string(),
            format!("{}, replicates 2–{replicates}", titled("cost", cost_unit)),
            titled("steady-state error", error_unit),
        ])
        .column("− the nominal simulator", Align::Left)
        .column("signed-rank p, median difference (episodes)", Align::Left)
        .column("regret: − the reference, same budget", Align::Left)
        .column("regret: − the reference at its best", Align::Left);
    let best_truth = truth.saturated().map(Budgeted::judged);
    let mut answers = Vec::new();
    // The deadline picks' standing against the PD loop, judged alike.
    let mut against_feedback = Vec::new();
    for &limit in &DEADLINES {
        let (nominal, aln) = picks(methods, limit);
        let true_now = truth.within(limit).map(|b| (truth, b.judged(), 1));
        let deadline = format!("{} ms", sig3(limit));
        match (&nominal, &aln) {
            (Some((n, nb, _)), Some((a, ab, fit))) => {
                let d = paired(ab, nb);
                let of = match fit {
                    1 => String::new(),
                    n => format!(" (the lowest in replicate 1 of {n} ALN models that fit)"),
                };
                answers.push(format!(
                    "at {deadline}, {}{of} {}",
                    a.at(ab),
                    d.map_or("—".into(), |d| format!(
                        "is {} {} {}: {}{}",
                        d.verdict().as_str(),
                        match d.verdict() {
                            Verdict::Indistinguishable => "from",
                            _ => "than",
                        },
                        n.at(nb),
                        interval(d.mean, d.low, d.high),
                        p_if_indistinguishable(&d, ab, nb)
                    ))
                ));
            }
            (None, Some((a, ab, _))) => answers.push(format!(
                "at {deadline}, {} plans and no nominal simulator fits",
                a.at(ab)
            )),
            _ => {}
        }
        if let Some(held) = feedback {
            let pd = held.point.judged();
            let each: Vec<String> = [&nominal, &aln]
                .into_iter()
                .flatten()
                .filter_map(|(m, b, _)| {
                    let d = paired(b, &pd)?;
                    Some(format!(
                        "{} {}: {}",
                        m.at(b),
                        d.verdict().as_str(),
                        interval(d.mean, d.low, d.high)
                    ))
                })
                .collect();
            if !each.is_empty() {
                against_feedback.push(format!("at {deadline}, {}", each.join("; ")));
            }
        }
        for (k, found) in [nominal.as_ref(), aln.as_ref(), true_now.as_ref()]
            .into_iter()
            .enumerate()
        {
            let Some((m, b, _)) = found else {
                continue;
            };
            // The true model picked as the nominal simulator (a scene with
            // no plant) is not shown twice.
            let again = nominal
                .as_ref()
                .is_some_and(|(n, nb, _)| n.label == m.label && nb.budget == b.budget);
            if k == 2 && again {
                continue;
            }
            let against = nominal.as_ref().filter(|_| k > 0).map(|(_, nb, _)| nb);
            let against_nominal = against
                .and_then(|nb| paired(b, nb))
                .map_or("—".into(), |d| {
                    format!(
                        "{}: {}",
                        d.verdict().as_str(),
                        interval(d.mean, d.low, d.high)
                    )
                });
            let p = against.map_or("—".into(), |nb| rank_cell(&b.pooled_minus(nb)));
            let regret = |t: Option<&Budgeted>| match (k, t) {
                (2, _) | (_, None) => "—".to_string(),
                (_, Some(t)) => {
                    paired(b, t).map_or("—".into(), |d| interval(d.mean, d.low, d.high))
                }
            };
            let same = truth
                .budgets
                .iter()
                .find(|t| t.budget == b.budget)
                .map(Budgeted::judged);
            let means: Vec<f64> = b.costs.iter().map(|c| mean(c)).collect();
            let cost =
                Interval::of(&means).map_or("—".into(), |i| estimate(i.mean, i.low, i.high));
            let label = match k {
                2 => format!("{} — the reference", m.at(b)),
                _ => m.at(b),
            };
            table.row(vec![
                deadline.clone(),
                label,
                sig3(b.ms),
                cost,
                match b.final_error().is_nan() {
                    true => "—".into(),
                    false => sig3(b.final_error()),
                },
                against_nominal,
                p,
                regret(same.as_ref()),
                regret(best_truth.as_ref()),
            ]);
        }
    }
    if answers.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "**`{task}` at each deadline** (each model at its largest budget whose median decision \
         in replicate 1 fits, a rule of time, not of cost; the nominal simulator and the ALN of \
         the lowest cost in replicate 1, so picked on its episodes and judged on the other \
         {judged} replicates: costs, differences and regrets across those {judged}, the \
         signed-rank p over their paired episodes, which share a replicate's model, so the \
         interval is the verdict): {}.\n",
        answers.join("; ")
    );
    table.write(md);
    if let Some(held) = feedback {
        let judged_loop = held.point.judged();
        let means: Vec<f64> = judged_loop.costs.iter().map(|c| mean(c)).collect();
        let cost = Interval::of(&means).map_or("—".into(), |i| estimate(i.mean, i.low, i.high));
        let tuned: Vec<String> = held.omegas.iter().map(|w| sig3(*w)).collect();
        let law = law(held.policy);
        let _ = writeln!(
            md,
            "**Against the controls engineer's first try**, the {law} loop on the nominal \
             model's gravity compensation ({}, the lower-cost loop in replicate 1; ω tuned on \
             episodes of its own, per replicate: {} rad/s), which plans nothing and costs {cost} \
             on the same {judged} replicates (steady-state error {}{}): the picks above, each \
             minus it, across those replicates — {}.\n",
            held.policy,
            tuned.join(", "),
            sig3(judged_loop.final_error()),
            match error_unit {
                unit if !unit.is_empty() && judged_loop.final_error().is_finite() => {
                    format!(" {unit}")
                }
                _ => String::new(),
            },
            match against_feedback.is_empty() {
                true => "none fits a deadline".to_string(),
                false => against_feedback.join("; "),
            }
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::tests::row;
    use alnlab_plan::planning::Episode;

    /// Four episodes of `model` at `budget` (0: a reference), costs `base`
    /// plus `spread` times the episode, each decision `ms` long.
    fn at(model: &str, budget: u32, base: f64, spread: f64, ms: f64) -> Vec<Episode> {
        let planner = if budget == 0 { "" } else { "cem" };
        (0..4)
            .map(|k| {
                let cost = base + spread * f64::from(k);
                row("hold", (model, planner, budget), k, (base, cost), ms)
            })
            .collect()
    }

    /// A fast ALN that beats the slow simulator at tight deadlines and
    /// loses to it given time; the plant's own simulator best of all at
    /// its largest budget.
    fn replicate(shift: f64) -> Vec<Episode> {
        [
            at("zero", 0, 100.0, 1.0, 0.0),
            at("random", 0, 90.0, 1.0, 0.0),
            at("gravity-pd", 0, 35.0, 1.0, 0.0),
            at("aln", 8, 30.0 + shift, 1.2, 0.5),
            at("aln", 64, 25.0 + shift, 1.2, 1.5),
            at("simulator@2", 8, 40.0, 1.0, 1.5),
            at("simulator@2", 64, 20.0, 1.0, 8.0),
            at("plant@2", 8, 38.0, 1.0, 3.0),
            at("plant@2", 64, 15.0, 1.0, 20.0),
        ]
        .concat()
    }

    #[test]
    fn each_model_gathers_its_budgets_and_fits_a_deadline_by_time_alone() {
        let planning = vec![replicate(0.0), replicate(0.5), replicate(-0.5)];
        let planned = [Planned {
            name: "v",
            planning: &planning,
            setup: None,
        }];
        let refs: Vec<&Planned> = planned.iter().collect();
        let (methods, left_out) = methods(&refs, "hold");
        assert!(left_out.is_empty());
        let labels: Vec<&str> = methods.iter().map(|m| m.label.as_str()).collect();
        assert_eq!(labels, ["ALN", "simulator@2", "plant@2"]);
        let aln = &methods[0];
        assert_eq!(
            aln.budgets.iter().map(|b| b.budget).collect::<Vec<_>>(),
            [8, 64]
        );
        // Within 1 ms only budget 8 fits; within 2 ms budget 64, though a
        // budget's cost never enters the rule.
        assert_eq!(aln.within(1.0).unwrap().budget, 8);
        assert_eq!(aln.within(2.0).unwrap().budget, 64);
        assert!(methods[1].within(1.0).is_none());
        // The replicates' mean costs: 30 + 1.2 × 1.5 on average.
        assert!((aln.budgets[0].mean() - 31.8).abs() < 1e-12);
        assert_eq!(truth(&methods).unwrap().label, "plant@2");
        assert_eq!(truth(&methods).unwrap().saturated().unwrap().budget, 64);
    }

    #[test]
    fn the_deadline_table_judges_on_the_replicates_the_pick_was_not_made_on() {
        let planning: Vec<Vec<Episode>> = [0.0, 0.2, -0.2, 0.1, -0.1].map(replicate).into();
        let planned = [Planned {
            name: "v",
            planning: &planning,
            setup: None,
        }];
        let dir = tempfile::tempdir().unwrap();
        let mut md = String::new();
        section(&mut md, &planned, dir.path()).unwrap();
        assert!(dir.path().join("plan-frontier-hold.svg").exists());
        // At 2 ms the ALN (64 sequences, 26.8 + shift) is 14.7 below the
        // simulator at its 8 (41.5), judged on replicates 2 to 5: ± t(3) ×
        // 0.183 / √4 = ± 0.29. At 10 ms the simulator plans 64 sequences
        // (21.5) and costs 5.3 less.
        assert!(
            md.contains(
                "at 2 ms, ALN, cem (64 sequences) is lower than simulator@2, cem (8 sequences): \
                 -14.7 [-15.0, -14.4]"
            ),
            "{md}"
        );
        assert!(
            md.contains(
                "at 10 ms, ALN, cem (64 sequences) is higher than simulator@2, cem (64 \
                 sequences): +5.30 [+5.01, +5.59]"
            ),
            "{md}"
        );
        assert!(md.contains("at 1 ms, ALN, cem (8 sequences) plans and no nominal simulator fits"));
        // The PD loop (36.5 a replicate) against the same picks: at 2 ms
        // the ALN's 26.8 + shift is 9.7 lower, the simulator's 41.5 5.0
        // higher (the same in every replicate: no interval to speak of).
        assert!(
            md.contains("ω tuned on episodes of its own, per replicate: 8, 8, 8, 8, 8"),
            "{md}"
        );
        assert!(
            md.contains(
                "at 2 ms, simulator@2, cem (8 sequences) higher: +5.00 [+5.00, +5.00]; ALN, cem \
                 (64 sequences) lower: -9.70 [-9.99, -9.41]"
            ),
            "{md}"
        );
        // The steady-state error beside each pick's cost (0.01 × base).
        assert!(md.contains("| 26.8 [26.5, 27.1] | 0.250 |"), "{md}");
        assert!(md.contains("judged on the other 4 replicates"), "{md}");
        // The true model's regret is against itself: no figure.
        assert!(
            md.contains("plant@2, cem (8 sequences) — the reference"),
            "{md}"
        );
        // The abstract's sentence: the same verdicts, deadlines of one
        // verdict together, and at 10 ms the lower pick (the simulator's
        // 21.5) against the PD loop's 36.5.
        assert_eq!(
            abstract_sentence(&planned).unwrap(),
            "Planning, each model at its largest budget that decides in time, the best ALN \
             minus the best nominal simulator (picked on replicate 1, judged on the other 4): \
             `hold`: only the ALN fits at 1 ms, lower at 2 ms (-14.7 [-15.0, -14.4]) and 5 ms \
             (-14.7 [-15.0, -14.4]), higher at 10 ms (+5.30 [+5.01, +5.59]), and at 10 ms \
             simulator@2, cem (64 sequences) is lower than the PD loop on the nominal model's \
             gravity compensation, which plans nothing (-15.0 [-15.0, -15.0])."
        );
        // Too few replicates to pick on one and judge on the others.
        let two = vec![replicate(0.0), replicate(0.5)];
        let mut md = String::new();
        let planned = [Planned {
            name: "v",
            planning: &two,
            setup: None,
        }];
        section(&mut md, &planned, dir.path()).unwrap();
        assert!(md.contains("No verdict at fixed deadlines"), "{md}");
        assert!(abstract_sentence(&planned).is_none());
    }
}
