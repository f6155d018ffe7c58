//! One variant's section of the report: what it did not learn, its error
//! by group (paper §4.6) beside the baselines and the paper, the ALN
//! against every model, where it is worse than persistence, the §4.5
//! histogram with its tail, the §5 hardware estimate, and — when the
//! variants ran on different data — its own closed-loop chart.

use alnlab_common::ModelId;
use std::fmt::Write as _;
use std::path::Path;

use alnlab_aln::ModelKind;
use alnlab_common::{Result, atomic};

use super::across::{aln_name, baselines_table};
use super::closed_loop;
use super::format::{Align, MdTable, interval, sig3};
use super::{
    Loaded, SummaryRow, baseline_models, mean_of, overall, paper_rows, worse_than_persistence,
};
use crate::charts::{self, style_of};
use alnlab_summarize::stats::{HISTOGRAM_BINS, HISTOGRAM_EDGES, histogram_bin_name};

/// A chart's file name: the variant's name, made safe, and the chart's.
pub(super) fn file_name(variant: &str, chart: &str) -> String {
    let safe: String = variant
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '-'
            }
        })
        .collect();
    format!("{safe}-{chart}.svg")
}

/// What every variant's section is written with: whether the baselines
/// are shared (shown once, beside all variants), whether to compare with
/// the paper, the variable whose histogram every variant shows, and the
/// fastest bit-forest placed and routed in the run (its variant and ns
/// per state), to set a piecewise-linear circuit beside.
pub(super) struct Context<'a> {
    pub(super) shared: bool,
    pub(super) compare_with_paper: bool,
    pub(super) histogram_variable: Option<&'a str>,
    pub(super) forest: Option<(&'a str, f64)>,
}

/// Writes variant `v` (the `k`th of `n`), its charts into `dir`.
pub(super) fn section(
    md: &mut String,
    v: &Loaded,
    (k, n): (usize, usize),
    context: &Context,
    dir: &Path,
) -> Result<()> {
    let Context {
        shared,
        compare_with_paper,
        histogram_variable,
        forest,
    } = *context;
    let _ = writeln!(md, "## Variant `{}`\n", v.info.name);
    if !v.info.description.is_empty() {
        let _ = writeln!(md, "{}\n", v.info.description);
    }
    let _ = writeln!(md, "Model: {}.\n", v.description);
    // Rows also trained on, reported once, apart: every table below is on
    // the held-out rows.
    let (all, held) = v.rows;
    if held < all
        && let Some((mean, _)) = overall(&v.summary, ModelId::Aln)
    {
        let _ = writeln!(
            md,
            "On all {all} test rows — {} of them also trained on, as the paper's protocol has \
             it — the ALN's mean error is {} levels; every table below is on the {held} held-out \
             rows alone.\n",
            all - held,
            sig3(mean)
        );
    }

    if !v.not_learned.is_empty() {
        let _ = writeln!(
            md,
            "### Variables not learned\n\nThe data hold them, but they carry nothing to predict; \
             no model is scored on them.\n"
        );
        let mut table = MdTable::new(&["variable"]).column("why", Align::Left);
        for (variable, note) in &v.not_learned {
            table.row(vec![format!("`{variable}`"), note.clone()]);
        }
        table.write(md);
    }

    by_group(md, v);
    if compare_with_paper {
        beside_the_paper(md, v);
    }

    let _ = writeln!(md, "### The ALN against every model\n");
    if shared {
        let _ = writeln!(
            md,
            "The ALN's mean paired difference in error against each model on the {} rows, with \
             its 95% interval (the models' own figures are under Baselines).\n",
            v.judged().1.as_str()
        );
        let mut table = MdTable::new(&["model"])
            .column("ALN − model [95%]", Align::Left)
            .column("the ALN is", Align::Left);
        for model in baseline_models(v.judged().0) {
            if let Some(d) = v.compared(model, None) {
                table.row(vec![
                    format!("`{model}`"),
                    interval(d.mean, d.low, d.high),
                    super::findings::accuracy_word(d).into(),
                ]);
            }
        }
        table.write(md);
    } else {
        let _ = writeln!(
            md,
            "Errors averaged over the variables on the {} rows (normalized: each variable's mean \
             error over the standard deviation of its true levels); the ALN's paired difference \
             against each model, with its 95% interval; time per predicted state on one thread, \
             median and range of the timed runs (the simulator: per re-simulated frame); frames \
             a simulator could not step are scored as the worst prediction.\n",
            v.judged().1.as_str()
        );
        baselines_table(md, v, true);
    }

    worse(md, v);
    histogram(md, v, k, histogram_variable, dir)?;
    hardware(md, v, forest);

    if !shared && !v.horizons.is_empty() {
        let _ = writeln!(md, "### Closed loop\n");
        let columns: Vec<closed_loop::Column> = closed_loop::models(v)
            .into_iter()
            .map(|m| closed_loop::Column {
                name: if m == ModelId::Aln {
                    aln_name(v, n)
                } else {
                    m.to_string()
                },
                variant: v,
                model: m,
                style: style_of(m, k),
            })
            .collect();
        let file = file_name(&v.info.name, "closed-loop");
        closed_loop::section(md, dir, (&file, Some(&v.info.name)), &columns)?;
    }
    Ok(())
}

/// The §4.6 table: the ALN's best and worst variable of each group, their
/// statistics, then the same variables beside the baselines.
fn by_group(md: &mut String, v: &Loaded) {
    let _ = writeln!(
        md,
        "### Error by group (paper §4.6)\n\nThe ALN's best and worst variable of each group over \
         the held-out test rows, in quantization levels (the mean also in SI units: levels × the \
         size of one level, which is given beside it).\n"
    );
    let judged = v.judged().0;
    let aln: Vec<&SummaryRow> = judged.iter().filter(|r| r.model == ModelId::Aln).collect();
    let mut groups: Vec<&str> = aln.iter().map(|r| r.group.as_str()).collect();
    groups.dedup();
    let mut picked: Vec<(&str, &str, &SummaryRow)> = Vec::new();
    for group in groups {
        for (which, best) in [("best", true), ("worst", false)] {
            if let Some(r) = aln.iter().find(|r| {
                r.group == group
                    && if best {
                        r.best_in_group
                    } else {
                        r.worst_in_group
                    }
            }) {
                picked.push((group, which, r));
            }
        }
    }
    let keys = ["group", "", "variable"];
    let mut table = MdTable::new(&keys).numbers(&[
        "mean",
        "mean (SI)",
        "one level",
        "std dev",
        "std err",
        "5% trim",
        "median",
        "IQR",
        "max",
    ]);
    for &(group, which, r) in &picked {
        let s = &r.stats;
        let (si, level) = v
            .si(&r.variable)
            .map_or(("—".into(), "—".into()), |(step, unit)| {
                (
                    format!("{} {unit}", sig3(s.mean * step)),
                    format!("{} {unit}", sig3(step)),
                )
            });
        table.row(vec![
            group.into(),
            which.into(),
            format!("`{}`", r.variable),
            sig3(s.mean),
            si,
            level,
            sig3(s.std_dev),
            sig3(s.std_err),
            sig3(s.trimmed_mean),
            sig3(s.median),
            sig3(s.iqr),
            s.max.to_string(),
        ]);
    }
    table.write(md);

    let baselines = baseline_models(judged);
    if baselines.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "The same variables: mean error of the ALN and of each baseline over the held-out test \
         rows.\n"
    );
    let mut names = vec![ModelId::Aln];
    names.extend(&baselines);
    let headings: Vec<String> = names.iter().map(ModelId::to_string).collect();
    let mut table = MdTable::new(&keys).numbers(&headings);
    for &(group, which, r) in &picked {
        let mut cells = vec![group.into(), which.into(), format!("`{}`", r.variable)];
        for &m in &names {
            cells.push(mean_of(judged, m, &r.variable).map_or("—".into(), sig3));
        }
        table.row(cells);
    }
    table.write(md);
}

/// Our best and worst variable of each group beside the paper's (§4.6).
fn beside_the_paper(md: &mut String, v: &Loaded) {
    let _ = writeln!(
        md,
        "### Beside the paper (§4.6)\n\nThe paper's numbers as published (its table of §4.6), \
         ours for the same group and rank on the held-out test rows (the paper's 9000 test \
         samples included its training ones); errors in quantization levels. Our variables and \
         ranges are our simulator's, not DynaTree's, so a row compares like with like only as \
         far as the groups do.\n"
    );
    let mut table = MdTable::new(&["group", ""])
        .column("our variable", Align::Left)
        .numbers(&[
            "paper mean",
            "ours",
            "paper 5% trim",
            "ours",
            "paper median",
            "ours",
            "paper IQR",
            "ours",
            "paper max",
            "ours",
        ]);
    for (f, ours) in paper_rows(v.judged().0) {
        let ours_or = |x: Option<String>| x.unwrap_or_else(|| "—".into());
        table.row(vec![
            f[0].into(),
            f[1].into(),
            ours_or(ours.map(|r| format!("`{}`", r.variable))),
            f[2].into(),
            ours_or(ours.map(|r| sig3(r.stats.mean))),
            f[5].into(),
            ours_or(ours.map(|r| sig3(r.stats.trimmed_mean))),
            f[6].into(),
            ours_or(ours.map(|r| sig3(r.stats.median))),
            f[7].into(),
            ours_or(ours.map(|r| sig3(r.stats.iqr))),
            f[8].into(),
            ours_or(ours.map(|r| r.stats.max.to_string())),
        ]);
    }
    table.write(md);
}

/// The variables where the ALN is worse than persistence.
fn worse(md: &mut String, v: &Loaded) {
    let worse = worse_than_persistence(v);
    let (judged, rows) = v.judged();
    let _ = writeln!(md, "### Worse than persistence\n");
    if worse.is_empty() {
        let _ = writeln!(
            md,
            "On no variable is the ALN's error above persistence's beyond the 95% interval of \
             their paired difference ({} rows).\n",
            rows.as_str()
        );
        return;
    }
    let _ = writeln!(
        md,
        "⚠ On {} of {} variables the ALN's error is higher than predicting no change, the 95% \
         interval of the paired difference above zero ({} rows; SI: the difference × the size \
         of one level):\n",
        worse.len(),
        judged.iter().filter(|r| r.model == ModelId::Aln).count(),
        rows.as_str()
    );
    let mut table = MdTable::new(&["variable"])
        .numbers(&["ALN mean", "persistence mean"])
        .column("difference [95%]", Align::Left)
        .numbers(&["difference (SI)"]);
    for (variable, mean, persistence, d) in &worse {
        let si = v.si(variable).map_or("—".into(), |(step, unit)| {
            format!("{} {unit}", sig3(d.mean * step))
        });
        table.row(vec![
            format!("⚠ `{variable}`"),
            sig3(*mean),
            sig3(*persistence),
            interval(d.mean, d.low, d.high),
            si,
        ]);
    }
    table.write(md);
}

/// The variable every variant's histogram shows: the first variant's worst
/// ALN variable on the judged rows, when every variant predicts it.
pub(super) fn histogram_variable<'a>(variants: &'a [Loaded]) -> Option<&'a str> {
    let worst = variants
        .first()?
        .judged()
        .0
        .iter()
        .filter(|r| r.model == ModelId::Aln)
        .max_by(|a, b| a.stats.mean.total_cmp(&b.stats.mean))?;
    variants
        .iter()
        .all(|v| {
            v.judged()
                .0
                .iter()
                .any(|r| r.model == ModelId::Aln && r.variable == worst.variable)
        })
        .then_some(worst.variable.as_str())
}

/// The bins of `row`'s error histogram, the open last one closed at its
/// largest error; none past the largest.
fn bins_of(row: &SummaryRow) -> Vec<charts::Bin> {
    (0..HISTOGRAM_BINS)
        .map(|b| {
            let low = f64::from(HISTOGRAM_EDGES[b]);
            let high = HISTOGRAM_EDGES
                .get(b + 1)
                .map_or(f64::from(row.stats.max) + 1.0, |&e| f64::from(e));
            charts::Bin {
                low,
                high: high.max(low + 1.0),
                count: row.stats.histogram[b],
            }
        })
        .filter(|b| b.low <= f64::from(row.stats.max))
        .collect()
}

/// The §4.5 histogram of `variable` (the report's choice, the same in
/// every variant that predicts it; else this variant's worst), with its
/// tail and persistence's errors overlaid.
fn histogram(
    md: &mut String,
    v: &Loaded,
    k: usize,
    variable: Option<&str>,
    dir: &Path,
) -> Result<()> {
    let judged = v.judged().0;
    let aln = || judged.iter().filter(|r| r.model == ModelId::Aln);
    let chosen = variable.and_then(|name| aln().find(|r| r.variable == name));
    let Some(worst) = chosen.or_else(|| aln().max_by(|a, b| a.stats.mean.total_cmp(&b.stats.mean)))
    else {
        return Ok(());
    };
    let bins: Vec<(String, u64)> = (0..HISTOGRAM_BINS)
        .map(|b| (histogram_bin_name(b), worst.stats.histogram[b]))
        .collect();
    let persistence = judged
        .iter()
        .find(|r| r.model == ModelId::Persistence && r.variable == worst.variable);
    let name = file_name(&v.info.name, "histogram");
    let title = format!("{}: errors of {}", v.info.name, worst.variable);
    let overlay = persistence.map(bins_of);
    let persistence_name = ModelId::Persistence.to_string();
    let chart = charts::histogram(
        &title,
        &bins_of(worst),
        style_of(ModelId::Aln, k).colour,
        overlay.as_deref().map(|o| (persistence_name.as_str(), o)),
    );
    atomic::write_bytes(&dir.join(&name), chart.as_bytes())?;
    let _ = writeln!(
        md,
        "### Error histogram of `{}` (paper §4.5)\n\n![histogram]({name})\n\n{} Held-out test \
         rows; the paper's bars of 0 to 9 levels, then its \"10 or more\" split to show the tail. \
         Each bar is as wide as its bin on the log(1 + error) axis and as high as its share of the \
         errors per decade of that axis, so its area is its share; the black outline is \
         persistence on the same rows.\n",
        worst.variable,
        if chosen.is_some() {
            "The first variant's worst variable, shown in every variant that predicts it."
        } else {
            "This variant's worst variable."
        }
    );
    let total = worst.stats.n.max(1) as f64;
    let mut table = MdTable::new(&["error (levels)"]).numbers(&["count", "share"]);
    for (bin, count) in bins {
        table.row(vec![
            bin,
            count.to_string(),
            format!("{}%", sig3(100.0 * count as f64 / total)),
        ]);
    }
    table.write(md);
    Ok(())
}

/// The §5 estimate from the pruned trees, the measured circuit and, for a
/// piecewise-linear model, its fixed-point circuit beside `forest`.
fn hardware(md: &mut String, v: &Loaded, forest: Option<(&str, f64)>) {
    let h = &v.hardware;
    let _ = writeln!(md, "### Hardware estimate (paper §5)\n");
    let _ = match h.kind {
        ModelKind::PiecewiseLinear => writeln!(
            md,
            "No gate estimate: a piecewise-linear model computes with numbers — affine pieces \
             under MIN and MAX — not with AND/OR gates{}.\n",
            if v.fixed.is_empty() {
                ""
            } else {
                "; its circuit is fixed-point arithmetic, measured below"
            }
        ),
        ModelKind::BitForest => writeln!(
            md,
            "Pruned trees are at most {} gate delays deep (mean {}); decoding a {}-bit code takes \
             about twice its width: {} + 2·{} = **{} gate delays** per predicted state, all trees \
             in parallel.\n",
            h.max_depth,
            sig3(h.mean_depth),
            h.max_width,
            h.max_depth,
            h.max_width,
            h.delays()
        ),
        ModelKind::Threshold => writeln!(
            md,
            "Pruned trees are at most {} gate delays deep (mean {}); the binary search over {} \
             levels takes {} evaluations in sequence: {}·{} = **{} gate delays** per predicted \
             state.\n",
            h.max_depth,
            sig3(h.mean_depth),
            h.max_width + 1,
            h.levels_steps,
            h.max_depth,
            h.levels_steps,
            h.delays()
        ),
    };
    let cpu = || super::circuit::Cpu {
        aln_batched: v.ns(ModelId::Aln, "batched"),
        aln_single: v.aln_single().map(|t| t.ns_per_state),
        simulator: super::findings::simulator_rival(v)
            .map(|r| (r.model.to_string(), r.timing.ns_per_state)),
    };
    match (&v.circuit, h.kind) {
        (None, ModelKind::PiecewiseLinear) if !v.fixed.is_empty() => {
            super::fixed_point::section(md, &v.fixed, v.fpga.as_ref(), &cpu(), forest);
        }
        (Some(measured), _) => {
            super::circuit::section(md, measured, (h.pruned_gates, h.max_depth), h.delays());
            if let Some(routed) = &v.fpga {
                super::circuit::fpga_section(md, routed, measured.depth, &cpu());
            }
        }
        (None, ModelKind::Threshold) if v.info.circuit.is_some() => {
            let _ = writeln!(
                md,
                "Not measured as a circuit: a threshold model's binary search evaluates its trees \
                 once per step, in sequence — a sequential circuit, which the circuit stage does \
                 not export.\n"
            );
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn chart_file_names_are_safe() {
        assert_eq!(
            super::file_name("a b/c", "histogram"),
            "a-b-c-histogram.svg"
        );
    }
}
