//! The report's first screen: an abstract of four sentences, one figure —
//! every model's difference from persistence against its time per state —
//! and one results table of at most eight rows. Everything after it is the
//! appendix.
//!
//! Every figure is on held-out rows, in levels (the one primary metric).
//! With replicates, a figure is the mean across them with its 95% interval
//! across replicates (seeds before rows); with one replicate the ALN's
//! interval is over the test rows of one replicate and is labelled so,
//! the other models' figures have none.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{ModelId, PolicyId};
use alnlab_common::{Result, atomic};
use alnlab_evaluate::timing::REPEATS;
use alnlab_summarize::paired::Interval;

use super::charts::{self, Axis, Plot, Point, Rule, Series, style_of};
use super::findings::accuracy_word;
use super::format::{MdTable, estimate, interval, sig3};
use super::{Loaded, RunInfo, Spread, Timing, overall};

/// File name of the figure.
const FIGURE: &str = "headline.svg";
/// Rows of the results table, at most: room for two ALNs, three learned or
/// trivial baselines and four simulator settings.
const TABLE_ROWS: usize = 10;

/// What an estimate's interval is over.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Over {
    /// Replicates (seeds): this many.
    Seeds(usize),
    /// The test rows of one replicate.
    Rows,
    /// No interval: one replicate, and no paired comparison over rows.
    Nothing,
}

/// A figure with its interval, if it has one.
#[derive(Clone, Copy, Debug)]
struct Estimate {
    mean: f64,
    interval: Option<(f64, f64)>,
    over: Over,
    /// The interval's verdict, when it is a difference.
    verdict: Option<&'static str>,
}

impl Estimate {
    fn across_seeds(values: &[f64]) -> Option<Estimate> {
        let i = Interval::of(values)?;
        Some(Estimate {
            mean: i.mean,
            interval: Some((i.low, i.high)),
            over: Over::Seeds(values.len()),
            verdict: Some(accuracy_word(&i)),
        })
    }

    fn point(mean: f64) -> Estimate {
        Estimate {
            mean,
            interval: None,
            over: Over::Nothing,
            verdict: None,
        }
    }

    /// "1.04 [1.02, 1.06]", or the mean alone.
    fn cell(&self) -> String {
        match self.interval {
            Some((low, high)) => estimate(self.mean, low, high),
            None => sig3(self.mean),
        }
    }

    /// "-0.136 [-0.150, -0.121]": a difference, signed.
    fn difference_cell(&self) -> String {
        match self.interval {
            Some((low, high)) => interval(self.mean, low, high),
            None => format!("{:+.3}", self.mean),
        }
    }
}

/// One model of one variant on the first screen.
struct Entry<'a> {
    variant: &'a Loaded<'a>,
    /// Its place among the report's variants (its style).
    place: usize,
    model: ModelId,
    variables: usize,
    error: Estimate,
    /// Persistence's mean error on the same rows and variables.
    persistence: Option<Estimate>,
    against_persistence: Option<Estimate>,
    /// One state (or the simulator's frame) at a time, one thread.
    single: Option<&'a Timing>,
    /// Every test state at once, one thread.
    batched: Option<&'a Timing>,
    /// Whether this baseline is another variant's than the best ALN's (its
    /// strongest form on the same data), and so named by its variant.
    elsewhere: bool,
}

impl Entry<'_> {
    fn label(&self, variants: usize) -> String {
        match (self.model, variants) {
            (ModelId::Aln, 1) => "ALN".into(),
            (ModelId::Aln, _) => format!("ALN `{}`", self.variant.info.name),
            (model, _) if self.elsewhere => format!("{model} `{}`", self.variant.info.name),
            (model, _) => model.to_string(),
        }
    }
}

/// `model`'s figures in `v`: its mean error and its difference from
/// persistence, across replicates when there are several.
fn entry<'a>(v: &'a Loaded<'a>, place: usize, model: ModelId) -> Option<Entry<'a>> {
    let judged = v.judged().0;
    let variables = judged.iter().filter(|r| r.model == model).count();
    let (mean, _) = overall(judged, model)?;
    let per_seed = |f: &dyn Fn(&super::replicates::Figures) -> Option<f64>| -> Option<Vec<f64>> {
        (v.replicates.len() > 1)
            .then(|| v.replicates.iter().map(f).collect::<Option<Vec<f64>>>())
            .flatten()
    };
    let mean_of = |model: ModelId, mean: f64| {
        per_seed(&|f| f.mean_of(model))
            .and_then(|values| Estimate::across_seeds(&values))
            .map(|e| Estimate { verdict: None, ..e })
            .unwrap_or(Estimate::point(mean))
    };
    let error = mean_of(model, mean);
    let persistence =
        overall(judged, ModelId::Persistence).map(|(p, _)| mean_of(ModelId::Persistence, p));
    let against_persistence = if model == ModelId::Persistence {
        None
    } else if let Some(values) = per_seed(&|f| match model {
        ModelId::Aln => f.aln_minus(ModelId::Persistence),
        _ => Some(f.mean_of(model)? - f.mean_of(ModelId::Persistence)?),
    }) {
        Estimate::across_seeds(&values)
    } else if model == ModelId::Aln {
        v.compared(ModelId::Persistence, None).map(|i| Estimate {
            mean: i.mean,
            interval: Some((i.low, i.high)),
            over: Over::Rows,
            verdict: Some(accuracy_word(i)),
        })
    } else {
        overall(judged, ModelId::Persistence).map(|(p, _)| Estimate::point(mean - p))
    };
    let (single, batched) = match model {
        ModelId::Persistence => (None, None),
        _ => (v.single(model), v.all_at_once(model)),
    };
    Some(Entry {
        variant: v,
        place,
        model,
        variables,
        error,
        persistence,
        against_persistence,
        single,
        batched,
        elsewhere: false,
    })
}

/// The models on the first screen: every variant's ALN (the best first),
/// then the best variant's baselines — persistence, the robust linear fit,
/// the learned peer where there is one, and the simulator at every step
/// count it measured (its frontier of error against time) — at most
/// [`TABLE_ROWS`] in all. A learned baseline whose form follows its
/// variant's model (the linear fits read what the ALN reads) is shown in
/// its strongest form: the variant, on the same data, where it errs least.
fn entries<'a>(variants: &'a [Loaded<'a>]) -> Vec<Entry<'a>> {
    let mut alns: Vec<Entry> = variants
        .iter()
        .enumerate()
        .filter_map(|(k, v)| entry(v, k, ModelId::Aln))
        .collect();
    alns.sort_by(|a, b| a.error.mean.total_cmp(&b.error.mean));
    let Some(best) = alns.first().map(|e| (e.variant, e.place)) else {
        return alns;
    };
    let simulators = super::findings::simulators(best.0)
        .into_iter()
        .map(|(name, _)| name);
    let learned = [ModelId::Persistence, ModelId::Linear, ModelId::Boosted];
    let hybrids = [ModelId::LinearNominal, ModelId::BoostedNominal];
    let same = same_data(variants);
    let strongest = |model: ModelId| -> Option<Entry<'a>> {
        let own = entry(best.0, best.1, model);
        if !same || matches!(model, ModelId::Persistence) {
            return own;
        }
        let other = variants
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != best.1)
            .filter_map(|(k, v)| entry(v, k, model))
            .min_by(|a, b| a.error.mean.total_cmp(&b.error.mean));
        match (own, other) {
            (Some(own), Some(other)) if other.error.mean < own.error.mean => Some(Entry {
                elsewhere: true,
                ..other
            }),
            (own, _) => own,
        }
    };
    let baselines: Vec<Entry> = learned
        .into_iter()
        .chain(hybrids)
        .filter_map(strongest)
        .chain(simulators.filter_map(|m| entry(best.0, best.1, m)))
        .collect();
    let keep_alns = TABLE_ROWS.saturating_sub(baselines.len()).max(1);
    alns.truncate(keep_alns);
    alns.extend(baselines);
    alns.truncate(TABLE_ROWS);
    alns
}

/// Whether the variants ran on the same test rows.
fn same_data(variants: &[Loaded]) -> bool {
    variants.windows(2).all(|w| super::same_rows(&w[0], &w[1]))
}

/// "across 5 replicates" / "over the rows of one replicate".
fn over_words(over: Over) -> String {
    match over {
        Over::Seeds(n) => format!("95% interval across {n} replicates"),
        Over::Rows => "95% interval over the test rows of one replicate".into(),
        Over::Nothing => "one replicate: no interval".into(),
    }
}

/// Writes the first screen into `md` and its figure into `dir`.
pub(super) fn first_screen(
    md: &mut String,
    run: &RunInfo,
    variants: &[Loaded],
    dir: &Path,
) -> Result<()> {
    let entries = entries(variants);
    let Some(best) = entries.first() else {
        return Ok(());
    };
    let frontier = super::plan_frontier::abstract_sentence(&super::plan::planned(variants));
    // Without the frontier's verdicts, each planner at its one budget
    // within real time, the ALN's and the true model's.
    let planning = entries
        .iter()
        .filter(|_| frontier.is_none())
        .find(|e| e.model == ModelId::Aln && !e.variant.planning.is_empty())
        .and_then(|e| {
            let setup = e.variant.info.plan_setup.as_ref();
            let phrases = super::plan::within_real_time(&e.variant.planning, PolicyId::Aln, setup);
            (!phrases.is_empty()).then_some((e.variant.info.name.as_str(), phrases))
        });
    // The true model planning by the same rule, for scale.
    let true_model = variants
        .iter()
        .filter(|_| frontier.is_none())
        .find_map(|v| {
            let model = super::plan::true_model(v.planning.first()?, v.info.plant)?;
            let phrases =
                super::plan::within_real_time(&v.planning, model, v.info.plan_setup.as_ref());
            (!phrases.is_empty()).then_some((model, phrases))
        });
    abstract_(
        md,
        run,
        variants,
        &entries,
        Planning {
            frontier: frontier.as_deref(),
            within_real_time: planning.as_ref(),
            true_model: true_model.as_ref(),
        },
    );
    figure(md, variants.len(), &entries, dir)?;
    let decisions = Decisions::of(variants, &entries);
    table(md, variants.len(), &entries, decisions.as_ref());
    super::synthesis::write_frontier(dir, &frontier_rows(&entries))?;
    let (test, held_out) = best.variant.rows;
    let paired = if best.variant.replicates.len() > 1 {
        "replicate by replicate"
    } else {
        "row by row"
    };
    let baselines = match entries.iter().find(|e| e.model == ModelId::Persistence) {
        Some(p) if entries.iter().any(|e| e.variables != p.variables) => format!(
            " The baselines are scored on the best ALN's variables ({}); an ALN over other \
             variables is set against persistence on its own, in the \"persistence's\" column.",
            p.variables
        ),
        _ => String::new(),
    };
    let intervals = match (best.error.over, best.against_persistence.map(|d| d.over)) {
        (Over::Seeds(_), _) => over_words(best.error.over),
        (_, Some(Over::Rows)) => "one replicate: errors without an interval, the ALN's \
                                  difference from persistence with its 95% interval over the test \
                                  rows of one replicate (rows, not seeds: narrower than seed to \
                                  seed)"
            .into(),
        _ => "one replicate: no intervals".into(),
    };
    let runs = best
        .single
        .or(best.batched)
        .map_or(format!("{REPEATS} interleaved runs"), |t| {
            super::findings::runs_words(best.variant, t)
        });
    let _ = writeln!(
        md,
        "Errors: mean over a model's variables of its mean error in levels on the {held_out} \
         held-out test rows (of {test}{also}){first_fold}; {intervals}; a difference is paired — the same \
         rows and variables, {paired}.{baselines} Models: persistence predicts no change; \
         linear is a robust linear fit of the change{others}; simulator@k/frame re-steps each \
         frame from its logged state with k integration steps (exact at the scene's own step \
         count{nominal}). Times, one thread: one state (the simulator: one frame) at a time, and every \
         test state at once; median and range of {runs}; a baseline several variants share is \
         timed by the first, and that timing is quoted throughout.{decisions} Levels, baselines and intervals \
         are defined under Definitions, at the end.\n",
        others = {
            let shown = |model: ModelId| entries.iter().any(|e| e.model == model);
            let mut words = String::new();
            if shown(ModelId::Boosted) {
                words.push_str("; boosted, gradient-boosted trees fitted to the same change");
            }
            if shown(ModelId::LinearNominal) || shown(ModelId::BoostedNominal) {
                words.push_str(
                    "; a +nominal model is a hybrid: the nominal simulator's prediction (the \
                     scene as written, at its own step or its `nominal_steps`) plus that fit of what the data did \
                     beyond it",
                );
            }
            if entries
                .iter()
                .any(|e| e.model == ModelId::Aln && e.variant.hybrid)
            {
                words.push_str(
                    "; an ALN hybrid is the nominal simulator's prediction plus an ALN trained \
                     as its correction, timed with the simulator's step",
                );
            }
            words
        },
        nominal = if best.variant.info.plant {
            "; here the data come from a plant, and the simulator is the scene as written — the \
             nominal model a user has — which knows nothing of how the plant departs from it"
        } else {
            ""
        },
        first_fold = if best.variant.info.folds {
            " of the first fold, each fold testing its own trajectories"
        } else {
            ""
        },
        also = if test > held_out {
            format!("; the other {} were also trained on", test - held_out)
        } else {
            String::new()
        },
        decisions = if decisions.is_some() {
            " Time per decision (ms): a planner's median time to choose one frame's torques, over \
             every task's episodes, one thread."
        } else {
            ""
        },
    );
    if !run.answer.trim().is_empty() {
        let _ = writeln!(
            md,
            "**The experimenter's answer** (their reading, not computed by the run{}): {}\n",
            match run.notes.trim().is_empty() {
                true => "",
                false => "; the notes in the appendix give its grounds",
            },
            // One paragraph, however the manifest wraps it.
            run.answer.split_whitespace().collect::<Vec<_>>().join(" ")
        );
    }
    // Whose models read the current accelerations, labelled so.
    let mut shown: Vec<&str> = Vec::new();
    for e in &entries {
        let name = e.variant.info.name.as_str();
        if e.variant.reads_accelerations() && !shown.contains(&name) {
            shown.push(name);
        }
    }
    if !shown.is_empty() {
        let _ = writeln!(md, "{}\n", super::findings::reads_more(&shown));
    }
    super::plan::at_real_time(md, variants);
    super::plan_frontier::section(md, &super::plan::planned(variants), dir)?;
    for v in variants {
        if let (Some(routed), Some(circuit)) = (&v.fpga, &v.circuit) {
            let _ = writeln!(
                md,
                "{}\n",
                super::circuit::in_hardware(
                    &v.info.name,
                    routed,
                    circuit.depth,
                    v.hardware.delays()
                )
            );
        }
        if let (Some(routed), false) = (&v.fpga, v.fixed.is_empty()) {
            let _ = writeln!(
                md,
                "{}\n",
                super::fixed_point::in_hardware(&v.info.name, &v.fixed, routed)
            );
        }
    }
    Ok(())
}

/// What the abstract says of planning: the frontier's verdicts at the
/// deadlines where it reads them, else each planner's cost at the one
/// budget that decides within real time, the ALN's and the true model's.
struct Planning<'a> {
    frontier: Option<&'a str>,
    within_real_time: Option<&'a (&'a str, Vec<String>)>,
    true_model: Option<&'a (PolicyId, Vec<String>)>,
}

/// Four sentences: what was measured, the best ALN's standing, the most
/// accurate of every model one frame and (closed loop) several ahead, and
/// the ALN's speed — or, where it planned, the frontier's verdicts at the
/// deadlines (else how it planned within real time).
fn abstract_(
    md: &mut String,
    run: &RunInfo,
    variants: &[Loaded],
    entries: &[Entry],
    planning: Planning,
) {
    let best = &entries[0];
    let replicates = best.variant.replicates.len().max(1);
    let description = run.description.trim().trim_end_matches('.');
    let _ = write!(
        md,
        "**Abstract.** {description} — {} variant{}, {replicates} replicate{}{} ({}), every error \
         in quantization levels on rows held out of training{}.",
        variants.len(),
        if variants.len() == 1 { "" } else { "s" },
        if replicates == 1 { "" } else { "s" },
        if variants.len() == 1 { "" } else { " each" },
        match (&run.dataset, &run.recording) {
            _ if best.variant.info.folds => {
                "each tests one fold of the trajectories, trained on the others, with a new seed \
                 for the model"
            }
            (Some(_), _) if !run.tables.is_empty() => {
                "the same archived recordings; a new seed for the model and, where it is drawn at \
                 random, the split"
            }
            (Some(_), _) => {
                "the same archived data; a new seed for the model and, where it is drawn at \
                 random, the split"
            }
            (_, Some(_)) => {
                "the same recording; a new seed for the model and, where it is drawn at random, \
                 the split"
            }
            _ if !run.tables.is_empty() => {
                "the same recorded tables; a new seed for the model and, where it is drawn at \
                 random, the split"
            }
            _ => "a new simulation, split and model",
        },
        run.split
            .as_ref()
            .map_or(String::new(), |s| format!(" (the split: {s})")),
    );
    let name = if variants.len() == 1 {
        "The ALN".to_string()
    } else if same_data(variants) {
        format!("The best ALN, `{}`,", best.variant.info.name)
    } else {
        format!(
            "On `{}`, the variant of lowest error (the variants ran on different data, so this \
             ranks them without pairing), the ALN",
            best.variant.info.name
        )
    };
    let _ = write!(md, " {name} errs {} levels", best.error.cell());
    if let Some(d) = &best.against_persistence {
        let _ = write!(
            md,
            ", {} persistence ({})",
            d.verdict.unwrap_or("against"),
            d.difference_cell()
        );
    }
    // The best other learned model (the simulator has a sentence of its
    // own), and the robust linear fit, the practitioner's first try.
    let rival = entries
        .iter()
        .filter(|e| e.model != ModelId::Aln && e.model != ModelId::Persistence)
        .filter(|e| !e.model.is_simulator())
        .min_by(|a, b| a.error.mean.total_cmp(&b.error.mean));
    let against = |other: &Entry| -> String {
        // Another variant's baseline pairs replicate by replicate: the
        // same simulation, split and rows.
        let values: Option<Vec<f64>> = (best.variant.replicates.len() > 1)
            .then(|| {
                best.variant
                    .replicates
                    .iter()
                    .zip(&other.variant.replicates)
                    .map(|(f, g)| match other.elsewhere {
                        true => Some(f.mean_of(ModelId::Aln)? - g.mean_of(other.model)?),
                        false => f.aln_minus(other.model),
                    })
                    .collect()
            })
            .flatten();
        let name = other.label(variants.len());
        match values.and_then(|v| Estimate::across_seeds(&v)) {
            Some(d) => format!(
                "{} {name} ({})",
                d.verdict.unwrap_or("against"),
                d.difference_cell()
            ),
            None => format!("{name}, at {}", other.error.cell()),
        }
    };
    if let Some(rival) = rival {
        if best.variant.replicates.len() > 1 {
            let _ = write!(md, " and {}, the best other learned model", against(rival));
        } else {
            let _ = write!(md, "; the best other learned model is {}", against(rival));
        }
        if let Some(linear) = entries.iter().find(|e| e.model == ModelId::Linear)
            && rival.model != ModelId::Linear
        {
            let _ = write!(md, ", and {}", against(linear));
        }
    }
    md.push('.');
    most_accurate(md, best.variant, entries, variants);
    if let Some(sentence) = planning.frontier {
        let _ = write!(md, " {sentence}\n\n");
        return;
    }
    if let Some((variant, phrases)) = planning.within_real_time {
        let _ = write!(
            md,
            " Planning with it (`{variant}`), each planner at its largest budget that decides \
             within real time: {}",
            phrases.join("; ")
        );
        match planning.true_model {
            Some((model, phrases)) => {
                let _ = write!(
                    md,
                    "; by the same rule with {} as forward model: {}. (The table under \
                     the planning paragraph below pairs every forward model with the best \
                     nominal simulator.)\n\n",
                    if matches!(model, PolicyId::Plant { .. }) {
                        format!(
                            "{model}, the plant's own simulator (no user has it; it knows \
                             neither the torque noise nor its actuators' state)"
                        )
                    } else {
                        format!("{model}/frame, the true model")
                    },
                    phrases.join("; ")
                );
            }
            None => md.push_str(".\n\n"),
        }
        return;
    }
    let aln = best.variant;
    let single = aln.aln_single();
    let batched = aln.all_at_once(ModelId::Aln);
    match (single, super::findings::simulator_rival(aln)) {
        (Some(one), Some(rival)) => {
            let _ = write!(
                md,
                " One state at a time it predicts in {} on one thread; {}.",
                one.spread(),
                super::findings::against_simulator(one, &rival)
            );
        }
        (Some(one), None) => {
            let _ = write!(
                md,
                " One state at a time it predicts in {} on one thread.",
                one.spread()
            );
        }
        _ => {}
    }
    if let Some(all) = batched {
        let _ = write!(
            md,
            " All {} test states at once{}, it takes {} a state (no simulator was timed all at \
             once).",
            all.states,
            if aln.info.folds {
                " (the first fold's)"
            } else {
                ""
            },
            all.spread()
        );
    }
    // The other learned models' times beside the ALN's, so that a cheaper
    // or more accurate learned rival is seen at its own cost.
    let others: Vec<String> = entries
        .iter()
        .filter(|e| e.model != ModelId::Aln && e.model != ModelId::Persistence)
        .filter(|e| !e.model.is_simulator())
        .filter(|e| e.single.is_some() || e.batched.is_some())
        .map(|e| {
            let time = |t: Option<&Timing>| t.map_or("—".into(), |t| t.spread());
            format!("{} {} / {}", e.model, time(e.single), time(e.batched))
        })
        .collect();
    if !others.is_empty() {
        let _ = write!(
            md,
            " The other learned models, one at a time / all at once: {}.",
            others.join("; ")
        );
    }
    md.push_str("\n\n");
}

/// A sentence naming the most accurate model on the first screen one frame
/// ahead (of `v`'s, the best ALN's variant, or of every variant's where
/// they ran on the same rows) and, where `v` rolled out, after its last
/// closed-loop step, each against the next best, paired replicate by
/// replicate: the answer to "which model predicts best", whatever wins.
fn most_accurate(md: &mut String, v: &Loaded, entries: &[Entry], variants: &[Loaded]) {
    let count = variants.len();
    let same = same_data(variants);
    let name = |e: &Entry| match e.model {
        ModelId::Aln => format!("the {}", e.label(count)),
        _ => e.label(count),
    };
    // A model's error per replicate (the first replicate's alone where its
    // variant has one).
    let per_replicate = |u: &Loaded, model: ModelId| -> Vec<f64> {
        match u.replicates.len() > 1 {
            true => u
                .replicates
                .iter()
                .map(|f| f.mean_of(model))
                .collect::<Option<Vec<f64>>>()
                .unwrap_or_default(),
            false => overall(u.judged().0, model).map_or(vec![], |(m, _)| vec![m]),
        }
    };
    let one_step: Vec<(String, Vec<f64>, String)> = entries
        .iter()
        .filter(|e| same || std::ptr::eq(e.variant, v))
        .map(|e| {
            let speed = match (e.single, e.batched) {
                (Some(t), _) => format!(" in {} a state one at a time", t.spread()),
                (None, Some(t)) => format!(" in {} a state all at once", t.spread()),
                (None, None) => String::new(),
            };
            (name(e), per_replicate(e.variant, e.model), speed)
        })
        .collect();
    let one_step = ranked(one_step);
    if one_step.len() < 2 {
        return;
    }
    let _ = write!(
        md,
        " Of every model, the most accurate one frame ahead is {}",
        lead(&one_step)
    );
    if let Some((horizon, errors)) = super::closed_loop::at_horizon(v) {
        let label = |model: ModelId| match model {
            ModelId::Aln => "the ALN".to_string(),
            model => model.to_string(),
        };
        let errors = errors
            .into_iter()
            .map(|(m, e)| (label(m), e, String::new()))
            .collect();
        let errors = ranked(errors);
        if errors.len() > 1 {
            let aln = errors
                .iter()
                .skip(1)
                .find(|(m, _, _)| m == "the ALN")
                .and_then(|(_, e, _)| Estimate::across_seeds(e).filter(|_| e.len() > 1))
                .map_or(String::new(), |e| format!("; the ALN errs {}", e.cell()));
            let _ = write!(
                md,
                "; {horizon} frames ahead, each fed its own predictions, {}{aln}",
                lead(&errors)
            );
        }
    }
    md.push('.');
}

/// `errors` (a model's name, its error per replicate, and its speed) by
/// their mean, those without figures left out.
fn ranked(mut errors: Vec<(String, Vec<f64>, String)>) -> Vec<(String, Vec<f64>, String)> {
    errors.retain(|(_, e, _)| !e.is_empty());
    errors.sort_by(|a, b| super::plan::mean(&a.1).total_cmp(&super::plan::mean(&b.1)));
    errors
}

/// The first of `ranked` with its error and speed, against the second:
/// paired across replicates where there are several.
fn lead(ranked: &[(String, Vec<f64>, String)]) -> String {
    let (model, values, speed) = &ranked[0];
    let cell = match Estimate::across_seeds(values).filter(|_| values.len() > 1) {
        Some(e) => e.cell(),
        None => sig3(values[0]),
    };
    let (next, others, _) = &ranked[1];
    let d: Vec<f64> = values.iter().zip(others).map(|(a, b)| a - b).collect();
    match Estimate::across_seeds(&d).filter(|_| d.len() > 1 && others.len() == values.len()) {
        Some(e) => format!(
            "{model} at {cell} levels{speed}, {} {next}, the next ({})",
            e.verdict.unwrap_or("against"),
            e.difference_cell()
        ),
        None => format!(
            "{model} at {cell} levels{speed} (the next, {next}, at {})",
            sig3(super::plan::mean(others))
        ),
    }
}

/// The main figure: every entry's difference from persistence (its
/// interval) against its time per state on one thread (its range).
fn figure(md: &mut String, variants: usize, entries: &[Entry], dir: &Path) -> Result<()> {
    let point = |e: &Entry, t: &Timing| -> Option<Point> {
        let d = e.against_persistence?;
        Some(Point {
            x: t.ns_per_state / 1000.0,
            y: d.mean,
            x_range: Some((t.ns_min / 1000.0, t.ns_max / 1000.0)),
            y_range: d.interval,
        })
    };
    let mut series: Vec<Series> = Vec::new();
    for e in entries {
        let name = e.label(variants).replace('`', "");
        if let Some(p) = e.single.and_then(|t| point(e, t)) {
            series.push(Series {
                // The simulator is timed frame by frame alone.
                name: if e.batched.is_some() {
                    format!("{name}, one at a time")
                } else {
                    name.clone()
                },
                style: style_of(e.model, e.place),
                points: vec![p],
                joined: false,
                hollow: false,
            });
        }
        if let Some(p) = e.batched.and_then(|t| point(e, t)) {
            series.push(Series {
                name: format!("{name}, all at once"),
                style: style_of(e.model, e.place),
                points: vec![p],
                joined: false,
                hollow: true,
            });
        }
    }
    if series.is_empty() {
        return Ok(());
    }
    let svg = charts::plot(&Plot {
        title: "error against speed: difference from persistence".into(),
        x: Axis::log("µs per state, one thread (log)"),
        y: Axis::linear("mean error − persistence's (levels; below 0: better)"),
        series,
        pareto: false,
        rules: vec![Rule::horizontal(0.0, "persistence (no change)")],
    });
    atomic::write_bytes(&dir.join(FIGURE), svg.as_bytes())?;
    let over = entries[0]
        .against_persistence
        .map_or(Over::Nothing, |d| d.over);
    let _ = writeln!(
        md,
        "![difference from persistence against time per state]({FIGURE})\n\n\
         Each model's mean error minus persistence's on the same rows (bars: {}) against its time \
         to predict a state on one thread (bars: the range of its timed runs): filled, one state \
         (the simulator: one frame) at a time; hollow, every test state at once. Each simulator \
         setting is a point of its own. Lower is more accurate, left is faster.\n",
        over_words(over)
    );
    Ok(())
}

/// Where the run planned: every first-screen model's ms per decision at
/// one planner and budget (the ALN's within real time), read from the plans
/// of the variant that planned with it.
struct Decisions {
    planner: String,
    budget: u32,
    /// Per entry, in order.
    ms: Vec<Option<f64>>,
}

impl Decisions {
    fn of(variants: &[Loaded], entries: &[Entry]) -> Option<Decisions> {
        let best = entries
            .iter()
            .find(|e| e.model == ModelId::Aln && !e.variant.planning.is_empty())?;
        let (planner, budget) = super::plan::reference_policy(&best.variant.planning[0])?;
        let ms = entries
            .iter()
            .map(|e| {
                let policy = PolicyId::planning_with(e.model)?;
                // The ALN's own plans; a baseline's from whichever variant
                // planned with it.
                let sources: Vec<&Loaded> = if e.model == ModelId::Aln {
                    vec![e.variant]
                } else {
                    variants.iter().collect()
                };
                sources.iter().find_map(|v| {
                    super::plan::decision_ms(v.planning.first()?, policy, &planner, budget)
                })
            })
            .collect();
        Some(Decisions {
            planner,
            budget,
            ms,
        })
    }
}

/// The first screen's models as `frontier.csv` rows, unrounded.
fn frontier_rows(entries: &[Entry]) -> Vec<super::synthesis::FrontierRow> {
    let us = |t: Option<&Timing>, f: fn(&Timing) -> f64| t.map(|t| f(t) / 1000.0);
    entries
        .iter()
        .map(|e| super::synthesis::FrontierRow {
            model: e.model,
            variant: e.variant.info.name.clone(),
            variables: e.variables,
            error: e.error.mean,
            error_low: e.error.interval.map(|(low, _)| low),
            error_high: e.error.interval.map(|(_, high)| high),
            persistence: e.persistence.map(|p| p.mean),
            one_at_a_time_us: us(e.single, |t| t.ns_per_state),
            one_at_a_time_min_us: us(e.single, |t| t.ns_min),
            one_at_a_time_max_us: us(e.single, |t| t.ns_max),
            all_at_once_us: us(e.batched, |t| t.ns_per_state),
            all_at_once_min_us: us(e.batched, |t| t.ns_min),
            all_at_once_max_us: us(e.batched, |t| t.ns_max),
        })
        .collect()
}

/// The results table: at most [`TABLE_ROWS`] rows.
fn table(md: &mut String, variants: usize, entries: &[Entry], decisions: Option<&Decisions>) {
    let decision_column = decisions.map(|d| {
        format!(
            "ms per decision ({}, {} sequences; median over tasks)",
            d.planner, d.budget
        )
    });
    let mut columns = vec![
        "mean error (levels)",
        "persistence's",
        "− persistence",
        "µs per state, one at a time",
        "µs per state, all at once",
    ];
    columns.extend(decision_column.as_deref());
    let mut t = MdTable::new(&["model", "variables"]).numbers(&columns);
    for (k, e) in entries.iter().enumerate() {
        let mut cells = vec![
            e.label(variants),
            e.variables.to_string(),
            e.error.cell(),
            match (e.model, e.persistence) {
                (ModelId::Persistence, _) | (_, None) => "—".into(),
                (_, Some(p)) => p.cell(),
            },
            e.against_persistence
                .map_or("—".into(), |d| d.difference_cell()),
            e.single.map_or("—".into(), Spread::spread_in_column),
            e.batched.map_or("—".into(), Spread::spread_in_column),
        ];
        if let Some(d) = decisions {
            cells.push(d.ms[k].map_or("—".into(), sig3));
        }
        t.row(cells);
    }
    t.write(md);
}
