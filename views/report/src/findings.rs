//! The report's opening: what the experiment is, how to read its numbers,
//! and its findings stated as plain sentences computed from the artifacts —
//! including the unflattering ones (where persistence or the simulator does
//! better than the ALN) — then the experimenter's own notes, if any.

use std::fmt::Write as _;

use super::format::{estimate, interval, micros, sig3};
use super::{Loaded, RunInfo, Spread, Timing, normalized, overall, paper_rows};
use alnlab_common::ModelId;
use alnlab_evaluate::timing::REPEATS;
use alnlab_summarize::Rows;
use alnlab_summarize::paired::{Interval, Verdict};

/// The simulator baseline at the fewest integration steps per frame that
/// the variant ran: (model name, steps per frame).
pub(super) fn coarsest_simulator(v: &Loaded) -> Option<(ModelId, u64)> {
    simulators(v).first().copied()
}

/// Every simulator setting the variant measured, fewest steps per frame
/// first: (model name, steps per frame).
pub(super) fn simulators(v: &Loaded) -> Vec<(ModelId, u64)> {
    let mut found: Vec<(ModelId, u64)> = v
        .timings
        .iter()
        .filter(|t| t.threads == 1)
        .filter_map(|t| Some((t.model, t.model.simulator_steps()?)))
        .collect();
    found.sort_by_key(|&(_, steps)| steps);
    found.dedup();
    found
}

/// The ALN's mean error minus `model`'s, paired: across replicates where
/// there are several (with whether it is), else over the test rows of one
/// simulation.
pub(super) fn aln_minus(v: &Loaded, model: ModelId) -> Option<(Interval, bool)> {
    if v.replicates.len() > 1 {
        let values: Option<Vec<f64>> = v.replicates.iter().map(|f| f.aln_minus(model)).collect();
        return Interval::of(&values?).map(|i| (i, true));
    }
    v.compared(model, None).map(|i| (*i, false))
}

/// The simulator setting a speed claim is set against: the cheapest one at
/// least as accurate as the ALN — one the ALN is not better than — or, when
/// every setting is less accurate, the most accurate of them. Cheapest is
/// fewest steps a frame: every step costs the same, so fewer never cost
/// more, and measured medians of neighbouring settings (3.4 and 4.1 µs)
/// swap under load, which would change the rival, and the verdict, from one
/// run to the next.
pub(super) struct Rival<'a> {
    pub model: ModelId,
    /// Frame by frame, one thread.
    pub timing: &'a Timing,
    /// The ALN's error minus the simulator's, and whether across replicates.
    pub difference: Interval,
    pub across_replicates: bool,
    /// Whether it is at least as accurate as the ALN.
    pub as_accurate: bool,
}

/// The [`Rival`] of the variant's ALN among its simulator settings.
pub(super) fn simulator_rival<'a>(v: &'a Loaded) -> Option<Rival<'a>> {
    // In order of steps a frame, fewest first.
    let settings: Vec<Rival> = simulators(v)
        .into_iter()
        .filter_map(|(model, _)| {
            let timing = v.single(model)?;
            let (difference, across_replicates) = aln_minus(v, model)?;
            Some(Rival {
                model,
                timing,
                as_accurate: difference.verdict() != Verdict::Lower,
                difference,
                across_replicates,
            })
        })
        .collect();
    let (as_accurate, less): (Vec<Rival>, Vec<Rival>) =
        settings.into_iter().partition(|r| r.as_accurate);
    match as_accurate.into_iter().next() {
        Some(cheapest) => Some(cheapest),
        // The ALN is better than every setting: the one it beats least.
        None => less
            .into_iter()
            .max_by(|a, b| a.difference.mean.total_cmp(&b.difference.mean)),
    }
}

/// "simulator@2/frame, at least as accurate (the ALN is worse than it,
/// +0.204 [+0.140, +0.269] across replicates), re-steps a frame in 5.31 µs
/// (5.22–5.40): the ALN, one state at a time, is 2.89× faster" — the ALN's
/// one-at-a-time speed against its [`Rival`], like with like.
pub(super) fn against_simulator(aln_single: &Timing, rival: &Rival) -> String {
    let over = if rival.across_replicates {
        "across replicates"
    } else {
        "over the test rows of one replicate"
    };
    let standing = if rival.as_accurate {
        "the cheapest simulator setting at least as accurate as the ALN"
    } else {
        "the most accurate simulator setting (every setting measured is less accurate than the \
         ALN)"
    };
    let word = speed_verdict(aln_single, rival.timing);
    let speed = if word.starts_with("indistinguishable") {
        word
    } else {
        format!("{word} than it")
    };
    format!(
        "{}, {standing} (the ALN is {} it, {} {over}), re-steps a frame in {}: one state at a \
         time, the ALN is {speed}",
        rival.model,
        accuracy_word(&rival.difference),
        difference(&rival.difference),
        rival.timing.spread(),
    )
}

/// The speed verdict of `a` against `b` from their timed runs, which were
/// interleaved: run k of each in round k. Faster or slower (by the ratio
/// of medians) only when the range of the round-by-round ratios a/b lies
/// wholly below or above 1 — a burst of load on the machine slows one
/// round of both, so the pairs are compared, not the two ranges.
pub(super) fn speed_verdict(a: &Timing, b: &Timing) -> String {
    let ratios: Vec<f64> = a.runs.iter().zip(&b.runs).map(|(x, y)| x / y).collect();
    let (lo, hi) = ratios
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &r| {
            (lo.min(r), hi.max(r))
        });
    if ratios.is_empty() {
        "not comparable in speed (no paired runs)".into()
    } else if hi < 1.0 {
        format!("{}× faster", sig3(b.ns_per_state / a.ns_per_state))
    } else if lo > 1.0 {
        format!("{}× slower", sig3(a.ns_per_state / b.ns_per_state))
    } else {
        format!(
            "indistinguishable in speed (its time over the simulator's ranges from {} to {} \
             across the rounds)",
            sig3(lo),
            sig3(hi)
        )
    }
}

/// "5 interleaved runs" or "25 runs: 5 interleaved in each of 5
/// replicates".
pub(super) fn runs_words(v: &Loaded, t: &Timing) -> String {
    let replicates = v.info.replicates.len().max(1);
    if replicates > 1 && t.runs.len() > REPEATS {
        format!(
            "{} runs: {REPEATS} interleaved rounds in each of {replicates} replicates",
            t.runs.len()
        )
    } else {
        format!("{} interleaved runs", t.runs.len())
    }
}

/// Where the secondary metric (normalized error) orders the ALN and
/// persistence the other way round from the primary one (levels), a clause
/// saying so; none where they agree.
fn metrics_disagree(v: &Loaded) -> Option<String> {
    let judged = v.judged().0;
    let (aln, persistence) = (
        overall(judged, ModelId::Aln)?.0,
        overall(judged, ModelId::Persistence)?.0,
    );
    let (aln_n, persistence_n) = (
        normalized(judged, ModelId::Aln)?,
        normalized(judged, ModelId::Persistence)?,
    );
    let (levels, secondary) = (aln - persistence, aln_n - persistence_n);
    (levels * secondary < 0.0).then(|| {
        format!(
            " — the secondary metric disagrees: in normalized error the ALN's {} is {} than \
             persistence's {}, so the two metrics order them oppositely; levels are the \
             headline",
            sig3(aln_n),
            if secondary < 0.0 { "lower" } else { "higher" },
            sig3(persistence_n)
        )
    })
}

/// "-0.136 [-0.150, -0.121]": a paired difference and its interval.
pub(super) fn difference(i: &Interval) -> String {
    interval(i.mean, i.low, i.high)
}

/// The label of the variants whose models read the current accelerations.
pub(super) fn reads_more(variants: &[&str]) -> String {
    let named: Vec<String> = variants.iter().map(|v| format!("`{v}`")).collect();
    let who = super::format::and_list(&named);
    let (learn, their) = match named.len() {
        0 | 1 => ("learns", "its"),
        _ => ("learn", "their"),
    };
    format!(
        "**Reads more than a controller knows:** {who} {learn} the accelerations (`qdd`), so \
         {their} one-step figures come from models that can read the frame's own, which the \
         torque being applied produces — more than a controller choosing that torque knows; a \
         planner must feed them its own last prediction instead, and they err more so \
         (`[quantize] never_learned = [\"qdd\"]` makes models that read none)."
    )
}

/// The verdict word of the ALN against another model, from the interval of
/// their paired difference in error.
pub(super) fn accuracy_word(i: &Interval) -> &'static str {
    match i.verdict() {
        Verdict::Lower => "better than",
        Verdict::Higher => "worse than",
        Verdict::Indistinguishable => "indistinguishable from",
        Verdict::Tied => "tied with",
    }
}

/// The definitions section, at the end of the report: every term the first
/// screen and the findings use.
pub(super) fn definitions(md: &mut String) {
    let _ = writeln!(
        md,
        "## Definitions\n\n\
         - **Level**: a variable's range is cut into L evenly spaced values (its quantization \
         levels; the size of one level in SI units is in each variant's group table). An \
         error is how many levels a prediction lands from the true next value's level, 0 being \
         exact — for an angle that wraps (a roll over the whole circle), the shorter way round, \
         so +179° for −179° is 2° off; every error is averaged over a model's variables — the \
         primary metric.\n\
         - **Held-out rows**: test rows not trained on. Where the split lets test rows be \
         training rows too (the paper's protocol), the figure over all of them is given once per \
         variant, apart.\n\
         - **Variant, replicate**: a variant is one configuration of the manifest; a replicate \
         runs it again from a new seed — a new model, a new split where it is drawn at random, \
         and a new simulation unless the data come from an archived dataset or a recording.\n\
         - **ALN**: the adaptive logic network under test — a *bit-forest* (the 1991 form: \
         AND/OR trees over input bits, one per output bit, decoded to a level) or a \
         *piecewise-linear* ALN (MIN/MAX trees over affine pieces of the real inputs, predicting \
         the change) — an *ALN hybrid* where its variant's model says so: the nominal \
         simulator's prediction plus the ALN's correction, trees that also read that prediction \
         and learn the change from it.\n\
         - **Baselines**: *persistence* predicts no change; *linear* is the robust linear fit of \
         each variable's change (least absolute deviations, from the real values of the inputs \
         the ALN reads); *boosted* (where present) gradient-boosted trees fitted to the same \
         change; *linear+nominal* and *boosted+nominal* (where present) are hybrids: the \
         nominal simulator's prediction (the scene as written, at its own step or its \
         `nominal_steps`) plus the same \
         fits of the change from it to the next value, what the plant did beyond its nominal \
         model; *simulator@k/frame* re-steps the physics from the logged frame with k \
         integration steps per frame (the logged step is exact by construction — unless the \
         data come from a plant that departs from the scene as written: the simulator is the \
         scene's, the nominal model a user has).\n\
         - **Normalized error** (a secondary metric): each variable's mean error over the \
         standard deviation of its true levels on the same rows, so runs with different ranges, \
         level counts or codes compare.\n\
         - **Comparison and interval**: the mean paired difference of two models' errors on the \
         same rows and variables (below zero: the first is better) with its 95% t-interval — \
         across replicates where there are several, else over the test rows of one replicate, \
         which treats rows as independent (neighbouring frames are not quite, so it is on the \
         narrow side, and it says nothing of seed-to-seed spread). \"Better\" or \"worse\" \
         only when the interval excludes zero, otherwise \"indistinguishable\" (\"tied\" \
         when every difference is zero).\n\
         - **Times**: on the machine named under Reproducibility, every model on one thread — \
         *one at a time* (a state, or the simulator's frame, per call) or *all at once* (every \
         test state in one call); each replicate's test stage times every model in {REPEATS} \
         interleaved rounds, and a time is the median of every replicate's runs with their \
         range, printed to the precision that range supports (three figures while it spans \
         under a tenth of the median, two under its whole, one beyond). Speed is compared like \
         with like — one at a time with one at a time — and against the cheapest simulator \
         setting at least as accurate as the ALN (one the ALN is not better than; cheapest is \
         fewest steps a frame, as every step costs the same); \
         \"faster\" or \"slower\" only when one's time over the other's is below 1 in every \
         round of every replicate, or above 1 in every one.\n"
    );
}

/// Writes the findings section.
pub(super) fn findings(md: &mut String, run: &RunInfo, variants: &[Loaded]) {
    let _ = writeln!(md, "## Findings\n");
    if !run.description.is_empty() {
        let _ = writeln!(md, "{}\n", run.description);
    }
    let _ = writeln!(
        md,
        "Terms (levels, baselines, intervals, verdicts) are defined under Definitions at the \
         end.\n"
    );
    for v in variants {
        variant_findings(md, v);
    }
    if variants.len() > 1 {
        across_variants(md, variants);
    }
    if run.compare_with_paper {
        against_the_paper(md, variants);
    }
    md.push('\n');
    if !run.notes.trim().is_empty() {
        let _ = writeln!(
            md,
            "## Notes from the experimenter\n\n{}\n",
            run.notes.trim()
        );
    }
}

fn variant_findings(md: &mut String, v: &Loaded) {
    let name = &v.info.name;
    let (judged, rows) = v.judged();
    let Some((aln, _)) = overall(judged, ModelId::Aln) else {
        return;
    };
    let variables = judged.iter().filter(|r| r.model == ModelId::Aln).count();
    let mut groups: Vec<(&str, usize)> = Vec::new();
    for r in judged.iter().filter(|r| r.model == ModelId::Aln) {
        match groups.iter_mut().find(|(g, _)| *g == r.group) {
            Some((_, n)) => *n += 1,
            None => groups.push((&r.group, 1)),
        }
    }
    let groups: Vec<String> = groups.iter().map(|(g, n)| format!("{g} {n}")).collect();
    let (all, held) = v.rows;
    let which = match rows {
        Rows::HeldOut if held < all => {
            format!("on the {held} held-out test rows (of {all}; the others were trained on)")
        }
        Rows::HeldOut => format!("on the {held} test rows, all held out of training"),
        Rows::All => format!("on the {all} test rows (none held out of training)"),
    };
    let replicate = match v.info.replicates.len() {
        0 | 1 => String::new(),
        n => format!(", replicate 1 of {n} (seed {})", v.info.replicates[0].seed),
    };
    let mut sentence = format!(
        "- **`{name}`**{replicate} {which}: the ALN's mean error is {} levels ({} normalized, \
         a secondary metric) over {variables} variables ({})",
        sig3(aln),
        sig3(normalized(judged, ModelId::Aln).unwrap_or(f64::NAN)),
        groups.join(", ")
    );
    for baseline in [ModelId::Persistence, ModelId::Linear] {
        if let (Some((mean, _)), Some(d)) = (overall(judged, baseline), v.compared(baseline, None))
        {
            let _ = write!(
                sentence,
                "; {} {baseline} ({}; difference {})",
                accuracy_word(d),
                sig3(mean),
                difference(d)
            );
        }
    }
    if let Some(note) = metrics_disagree(v) {
        sentence.push_str(&note);
    }
    let [lower, higher, unclear, tied] = v.verdict_counts(ModelId::Persistence);
    let _ = write!(
        sentence,
        ". Variable by variable it is better than persistence on {lower} of {variables}, worse \
         on {higher}, indistinguishable on {unclear}"
    );
    if tied > 0 {
        let _ = write!(sentence, ", tied on {tied}");
    }
    sentence.push_str(if higher * 2 > variables {
        " — predicting no change is the better model for most of this state.\n"
    } else {
        ".\n"
    });
    md.push_str(&sentence);
    super::replicates::finding(md, v);
    let _ = writeln!(md, "  - Model: {}.", v.description);
    if v.reads_accelerations() {
        let _ = writeln!(md, "  - {}", reads_more(&[&v.info.name]));
    }

    let batched = v.all_at_once(ModelId::Aln);
    let single = v.aln_single();
    if let Some(first) = single.or(batched) {
        let _ = write!(
            md,
            "  - Speed, one thread each (median and range of {}): the ALN predicts a state in {}",
            runs_words(v, first),
            first.spread()
        );
        let _ = write!(
            md,
            " {}",
            match (single.is_some(), v.hybrid) {
                (true, true) => "one at a time (the nominal simulator's step, then the correction)",
                (true, false) => "one at a time",
                (false, _) => "all at once",
            }
        );
        if let (Some(_), Some(all)) = (single, batched) {
            let _ = write!(
                md,
                ", {} all {} test states at once",
                all.spread(),
                all.states
            );
        }
        if let Some(all) = v.aln_all_threads() {
            let _ = write!(
                md,
                "; all at once on all {} threads {}",
                all.threads,
                all.spread()
            );
        }
        match (single, simulator_rival(v)) {
            (Some(one), Some(rival)) => {
                let _ = writeln!(
                    md,
                    ". The simulator: {}. (No simulator was timed all at once.)",
                    against_simulator(one, &rival)
                );
            }
            _ => md.push_str(".\n"),
        }
    }

    let c = &v.coverage;
    // (A piecewise-linear model has no leaves to wire: coverage is 0 of 0.)
    if c.read < 0.99 && c.literals > 0 {
        let _ = writeln!(
            md,
            "  - ⚠ Each tree has {} leaves for {} input literals (bits and their complements), \
             wired at random: a tree reads {:.0}% of its inputs and is blind to the rest. \
             `train.leaves = {}` or more lets every tree read every input.",
            c.leaves,
            c.literals,
            100.0 * c.read,
            c.literals.next_power_of_two()
        );
    }

    if let Some(last) = v.horizons.iter().map(|h| h.horizon).max() {
        let at = |model: ModelId| {
            v.horizons
                .iter()
                .find(|h| h.model == model && h.horizon == last)
                .map(|h| h.mean)
        };
        if let (Some(aln), Some(persistence)) = (at(ModelId::Aln), at(ModelId::Persistence)) {
            let _ = write!(
                md,
                "  - Closed loop: fed its own predictions for {last} steps, the ALN's mean error \
                 grows to {} levels, against {} for persistence",
                sig3(aln),
                sig3(persistence)
            );
            if let Some((simulator, steps)) = coarsest_simulator(v)
                && let Some(sim) = at(simulator)
            {
                let _ = write!(
                    md,
                    " and {} for the simulator at {steps} step{} per frame",
                    sig3(sim),
                    if steps == 1 { "" } else { "s" }
                );
            }
            md.push_str(".\n");
        }
    }
}

fn across_variants(md: &mut String, variants: &[Loaded]) {
    let means: Vec<(&str, f64)> = variants
        .iter()
        .filter_map(|v| Some((v.info.name.as_str(), overall(v.judged().0, ModelId::Aln)?.0)))
        .collect();
    let (Some(best), Some(worst)) = (
        means.iter().min_by(|a, b| a.1.total_cmp(&b.1)),
        means.iter().max_by(|a, b| a.1.total_cmp(&b.1)),
    ) else {
        return;
    };
    let _ = write!(
        md,
        "- Across variants (each on its own held-out rows; a ranking, not a paired test): the \
         ALN's mean error ranges from {} (`{}`) to {} (`{}`)",
        sig3(best.1),
        best.0,
        sig3(worst.1),
        worst.0
    );
    // With replicates, the variants compared paired by replicate, against
    // the one of lowest mean error across replicates.
    let best = variants
        .iter()
        .filter_map(|v| Some((v, super::replicates::aln_mean(v)?)))
        .min_by(|a, b| a.1.mean.total_cmp(&b.1.mean));
    if let Some((best, mean)) = best {
        let others: Vec<String> = variants
            .iter()
            .filter(|v| v.info.name != best.info.name)
            .filter_map(|v| {
                let paired = super::replicates::between(v, best)?;
                let d = &paired.difference;
                let over = paired.common.map_or(String::new(), |n| {
                    format!(", over the {n} variables both predict")
                });
                Some(format!(
                    "`{}` is {} it ({}{over})",
                    v.info.name,
                    accuracy_word(d),
                    difference(d)
                ))
            })
            .collect();
        if !others.is_empty() {
            let _ = write!(
                md,
                "; across replicates (paired by replicate), `{}` has the lowest ALN error ({}): \
                 {}",
                best.info.name,
                estimate(mean.mean, mean.low, mean.high),
                others.join(", ")
            );
        }
    }
    let fastest = variants
        .iter()
        .filter_map(|v| Some((v.info.name.as_str(), v.ns(ModelId::Aln, "batched")?)))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((name, t)) = fastest {
        let _ = write!(
            md,
            "; the quickest prediction of every test state at once on one thread (median) is `{name}`'s ({})",
            micros(t)
        );
    }
    md.push_str(".\n");
}

/// How the best and worst variable of each group compare with the paper's
/// §4.6 table: where ours is lower, and where it is more than twice as high.
fn against_the_paper(md: &mut String, variants: &[Loaded]) {
    for v in variants {
        let (mut lower, mut rows, mut far_higher) = (0, 0, Vec::new());
        for (f, ours) in paper_rows(v.judged().0) {
            let (group, which) = (f[0], f[1]);
            let Ok(paper) = f[2].parse::<f64>() else {
                continue;
            };
            if let Some(r) = ours {
                rows += 1;
                if r.stats.mean < paper {
                    lower += 1;
                } else if r.stats.mean > 2.0 * paper {
                    far_higher.push(format!(
                        "{group} {which} ({} vs {paper})",
                        sig3(r.stats.mean)
                    ));
                }
            }
        }
        if rows == 0 {
            continue;
        }
        let _ = write!(
            md,
            "- Beside the paper (`{}`): our mean error is lower than the paper's in {lower} of \
             {rows} rows of its §4.6 table",
            v.info.name
        );
        if far_higher.is_empty() {
            md.push_str(".\n");
        } else {
            let _ = writeln!(
                md,
                "; more than twice the paper's in {}: {}.",
                far_higher.len(),
                far_higher.join(", ")
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_summarize::Predictions;

    /// A verdict word only where the interval excludes zero: the ALN against
    /// a model equal to it on every row, one that differs from it by ±1 in
    /// turn (mean difference 0), and one whose error is 1 higher on every
    /// other row.
    #[test]
    fn verdict_words_follow_the_interval_of_constructed_models() {
        let rows = 200u32;
        let aln: Vec<u16> = (0..rows).map(|r| 5 + (r % 3) as u16).collect();
        let same = aln.clone();
        let noisy: Vec<u16> = aln
            .iter()
            .enumerate()
            .map(|(r, &e)| if r % 2 == 0 { e + 1 } else { e - 1 })
            .collect();
        let worse: Vec<u16> = aln
            .iter()
            .enumerate()
            .map(|(r, &e)| e + (r % 2) as u16)
            .collect();
        let rows_ids: Vec<u32> = (0..rows).collect();
        let truth = vec![vec![7u16; rows as usize]; 2];
        let mut table = alnlab_tables::predictions::Predictions::new(
            &["a.1.x", "v.1.x"],
            &[None, None],
            &rows_ids,
            &vec![true; rows as usize],
            &truth,
        );
        // Constructed models under the names of real ones.
        let (same_id, noisy_id, worse_id) =
            (ModelId::Persistence, ModelId::Linear, ModelId::Boosted);
        for (model, errors) in [
            (ModelId::Aln, &aln),
            (same_id, &same),
            (noisy_id, &noisy),
            (worse_id, &worse),
        ] {
            let levels: Vec<u16> = errors.iter().map(|e| 7 + e).collect();
            table.push_model(model, &[levels.clone(), levels]);
        }
        let comparisons = Predictions::of(&table).compare(ModelId::Aln);
        let word = |against: ModelId| {
            let c = comparisons
                .iter()
                .find(|c| c.against == against && c.variable.is_none() && c.rows == Rows::All)
                .unwrap();
            (accuracy_word(&c.difference), c.difference)
        };
        assert_eq!(word(same_id).0, "tied with");
        let (noisy_word, noisy) = word(noisy_id);
        assert_eq!(noisy_word, "indistinguishable from");
        assert!(noisy.low < 0.0 && noisy.high > 0.0 && noisy.mean == 0.0);
        let (worse_word, worse) = word(worse_id);
        assert_eq!(worse_word, "better than", "the ALN's errors are lower");
        assert!(worse.high < 0.0 && (worse.mean + 0.5).abs() < 1e-12);
    }
}
