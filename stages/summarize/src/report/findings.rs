//! The report's opening: what the experiment is, how to read its numbers,
//! and its findings stated as plain sentences computed from the artifacts —
//! including the unflattering ones (where persistence or the simulator does
//! better than the ALN) — then the experimenter's own notes, if any.

use std::fmt::Write as _;

use super::{Loaded, RunInfo, overall, paper_rows, worse_than_persistence};

/// The simulator baseline at the fewest integration steps per frame that
/// the variant ran: (model name, steps per frame).
fn coarsest_simulator<'a>(v: &'a Loaded) -> Option<(&'a str, u32)> {
    v.timings
        .iter()
        .filter_map(|t| {
            let steps = t.model.strip_prefix("simulator@")?.strip_suffix("/frame")?;
            Some((t.model.as_str(), steps.parse().ok()?))
        })
        .min_by_key(|&(_, steps)| steps)
}

/// "1.23 µs" for a time in ns.
fn micros(ns: f64) -> String {
    format!("{:.1} µs", ns / 1000.0)
}

/// "2.1× faster" / "2.1× slower" of `a` against `b` (both ns); within 10%,
/// "about as fast".
fn speed_ratio(a: f64, b: f64) -> String {
    if (a / b - 1.0).abs() < 0.1 {
        "about as fast".into()
    } else if a < b {
        format!("{:.1}× faster", b / a)
    } else {
        format!("{:.1}× slower", a / b)
    }
}

/// Writes the findings section.
pub(super) fn findings(md: &mut String, run: &RunInfo, variants: &[Loaded]) {
    let _ = writeln!(md, "## Findings\n");
    if !run.description.is_empty() {
        let _ = writeln!(md, "{}\n", run.description);
    }
    let _ = writeln!(
        md,
        "Errors are in quantization levels (0 is the exact level) of the variable predicted one \
         stride ahead, averaged over a variant's variables. Baselines: *persistence* predicts no \
         change, *linear* is a least-squares linear map of the state, *simulator@k/frame* \
         re-steps the physics from the logged frame with k integration steps per frame (the \
         logged step is exact by construction). Times are from the machine named under \
         Reproducibility.\n"
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
    let Some((aln, _)) = overall(&v.summary, "aln") else {
        return;
    };
    let variables = v.summary.iter().filter(|r| r.model == "aln").count();
    let worse = worse_than_persistence(&v.summary).len();
    let mut groups: Vec<(&str, usize)> = Vec::new();
    for r in v.summary.iter().filter(|r| r.model == "aln") {
        match groups.iter_mut().find(|(g, _)| *g == r.group) {
            Some((_, n)) => *n += 1,
            None => groups.push((&r.group, 1)),
        }
    }
    let groups: Vec<String> = groups.iter().map(|(g, n)| format!("{g} {n}")).collect();
    let mut sentence = format!(
        "- **`{name}`**: the ALN's mean error is {aln:.3} levels over {variables} variables \
         ({})",
        groups.join(", ")
    );
    for baseline in ["persistence", "linear"] {
        if let Some((mean, _)) = overall(&v.summary, baseline) {
            let verdict = if aln < mean {
                "better than"
            } else {
                "worse than"
            };
            let _ = write!(sentence, "; {verdict} {baseline} ({mean:.3})");
        }
    }
    let _ = write!(
        sentence,
        ". It beats persistence on {} of {variables} variables",
        variables - worse
    );
    sentence.push_str(if worse * 2 > variables {
        " — predicting no change is the better model for most of this state.\n"
    } else {
        ".\n"
    });
    md.push_str(&sentence);
    let _ = writeln!(md, "  - Model: {}.", v.description);

    let batched = v.ns("aln", "batched");
    let single = v.aln_single_ns();
    if let (Some(aln_ns), Some((simulator, steps))) = (batched.or(single), coarsest_simulator(v))
        && let (Some(sim_ns), Some((sim_mean, _))) =
            (v.ns(simulator, "single"), overall(&v.summary, simulator))
    {
        let path = if batched.is_some() {
            "batched"
        } else {
            "one at a time"
        };
        let accuracy = if aln < sim_mean {
            "more accurate"
        } else {
            "less accurate"
        };
        let _ = write!(
            md,
            "  - Speed: the ALN predicts a state in {} ({path}",
            micros(aln_ns)
        );
        if let (Some(_), Some(one)) = (batched, single) {
            let _ = write!(md, "; {} one at a time", micros(one));
        }
        let _ = writeln!(
            md,
            "). The simulator re-stepping a frame with {steps} step{} takes {} for an error of \
             {sim_mean:.3}: the ALN is {} and {accuracy}.",
            if steps == 1 { "" } else { "s" },
            micros(sim_ns),
            speed_ratio(aln_ns, sim_ns),
        );
    }

    let c = &v.coverage;
    if c.read < 0.99 {
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

    if let Some(last) = v.horizons.iter().map(|h| h.1).max() {
        let at = |model: &str| {
            v.horizons
                .iter()
                .find(|h| h.0 == model && h.1 == last)
                .map(|h| h.2)
        };
        if let (Some(aln), Some(persistence)) = (at("aln"), at("persistence")) {
            let _ = write!(
                md,
                "  - Closed loop: fed its own predictions for {last} steps, the ALN's mean error \
                 grows to {aln:.2} levels, against {persistence:.2} for persistence"
            );
            if let Some((simulator, steps)) = coarsest_simulator(v)
                && let Some(sim) = at(simulator)
            {
                let _ = write!(
                    md,
                    " and {sim:.2} for the simulator at {steps} step{} per frame",
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
        .filter_map(|v| Some((v.info.name.as_str(), overall(&v.summary, "aln")?.0)))
        .collect();
    let (Some(best), Some(worst)) = (
        means.iter().min_by(|a, b| a.1.total_cmp(&b.1)),
        means.iter().max_by(|a, b| a.1.total_cmp(&b.1)),
    ) else {
        return;
    };
    let _ = write!(
        md,
        "- Across variants: the lowest ALN error is `{}`'s ({:.3}), the highest `{}`'s ({:.3})",
        best.0, best.1, worst.0, worst.1
    );
    let fastest = variants
        .iter()
        .filter_map(|v| Some((v.info.name.as_str(), v.ns("aln", "batched")?)))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((name, t)) = fastest {
        let _ = write!(
            md,
            "; the fastest batched prediction is `{name}`'s ({})",
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
        for (f, ours) in paper_rows(&v.summary) {
            let (group, which) = (f[0], f[1]);
            let Ok(paper) = f[2].parse::<f64>() else {
                continue;
            };
            if let Some(r) = ours {
                rows += 1;
                if r.stats.mean < paper {
                    lower += 1;
                } else if r.stats.mean > 2.0 * paper {
                    far_higher.push(format!("{group} {which} ({:.2} vs {paper})", r.stats.mean));
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
