//! Replicates: a variant run again with new seeds (a new split and
//! trees, and a new simulation where the data are simulated). Each headline figure — a model's mean error over the
//! variables, the ALN's paired difference against a baseline — becomes the
//! mean across replicates with its 95% t-interval across replicates, each
//! replicate one independent value. `replicates.csv`, beside the report,
//! holds every figure with each replicate's value, for checking.

use alnlab_common::ModelId;
use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{Result, atomic};

use super::findings::{accuracy_word, difference};
use super::format::{estimate, sig3};
use super::{Loaded, Replicate, aln_against, overall, split_rows};
use alnlab_summarize::Rows;
use alnlab_summarize::paired::Interval;

/// The models whose errors the headline gives (the learned peer and the
/// hybrids where the test stage fitted them).
pub(super) const MODELS: &[ModelId] = &ModelId::FIXED;

/// One replicate's headline figures, on its held-out rows (all test rows
/// when none is held out).
pub(super) struct Figures {
    pub seed: u64,
    pub rows: Rows,
    /// The ALN's mean paired difference against each baseline of
    /// [`MODELS`] (the ALN itself excepted).
    pub differences: Vec<Option<f64>>,
    /// (model, step, mean) of the closed-loop errors.
    pub horizons: Vec<(ModelId, u16, f64)>,
    /// The ALN's mean error per variable, sorted by variable: variants that
    /// predict different sets of variables pair over the ones they share.
    pub aln_by_variable: Vec<(String, f64)>,
    /// Every model's mean error over the variables, in summary order.
    pub model_means: Vec<(ModelId, f64)>,
}

impl Figures {
    /// The ALN's mean paired difference against `model`: the stage's paired
    /// comparison for the headline baselines, the difference of the two
    /// means (the same rows and variables) for any other model.
    pub fn aln_minus(&self, model: ModelId) -> Option<f64> {
        match MODELS[1..].iter().position(|m| *m == model) {
            Some(k) => self.differences[k],
            None => Some(self.mean_of(ModelId::Aln)? - self.mean_of(model)?),
        }
    }

    /// `model`'s mean error over the variables, if the replicate has it.
    pub fn mean_of(&self, model: ModelId) -> Option<f64> {
        self.model_means
            .iter()
            .find(|&&(m, _)| m == model)
            .map(|(_, e)| *e)
    }
}

impl Figures {
    /// One replicate's figures, read from its summary and comparisons.
    pub fn read(replicate: &Replicate) -> Result<Figures> {
        let (all, held, rows) = split_rows(alnlab_summarize::read(&replicate.summary)?);
        let judged = if rows == Rows::HeldOut { held } else { all };
        let comparisons = alnlab_summarize::read_comparisons(&replicate.comparisons)?;
        let horizons = alnlab_summarize::read_horizons(&replicate.horizons)?
            .into_iter()
            .filter(|h| h.rows == rows)
            .map(|h| (h.model, h.horizon, h.mean))
            .collect();
        let mut aln_by_variable: Vec<(String, f64)> = judged
            .iter()
            .filter(|r| r.model == ModelId::Aln)
            .map(|r| (r.variable.clone(), r.stats.mean))
            .collect();
        aln_by_variable.sort_by(|a, b| a.0.cmp(&b.0));
        let mut model_means: Vec<(ModelId, f64)> = Vec::new();
        for row in &judged {
            if !model_means.iter().any(|&(m, _)| m == row.model) {
                let (mean, _) = overall(&judged, row.model).expect("the model has rows");
                model_means.push((row.model, mean));
            }
        }
        Ok(Figures {
            aln_by_variable,
            model_means,
            horizons,
            seed: replicate.seed,
            rows,
            differences: MODELS[1..]
                .iter()
                .map(|&b| aln_against(&comparisons, rows, b, None).map(|d| d.mean))
                .collect(),
        })
    }
}

/// Two variants' ALNs paired replicate by replicate.
pub(super) struct Between {
    /// Variant `a`'s ALN mean error minus `b`'s, across replicates.
    pub difference: Interval,
    /// Each replicate's difference.
    pub values: Vec<Option<f64>>,
    /// The variables both predict, when they do not predict the same ones
    /// (one given the controls, one predicting them): the means are over
    /// these alone.
    pub common: Option<usize>,
}

/// Variant `a`'s ALN mean error minus `b`'s, paired replicate by replicate:
/// both ran with the same seeds, so replicate k of each saw the same
/// simulation; over the variables both predict. `None` unless both have
/// the same ≥ 2 replicate seeds and share a variable.
pub(super) fn between(a: &Loaded, b: &Loaded) -> Option<Between> {
    let seeds = |v: &Loaded| v.replicates.iter().map(|f| f.seed).collect::<Vec<_>>();
    if a.replicates.len() < 2 || seeds(a) != seeds(b) {
        return None;
    }
    let names = |f: &Figures| {
        f.aln_by_variable
            .iter()
            .map(|(v, _)| v.clone())
            .collect::<Vec<_>>()
    };
    let (first_a, first_b) = (names(&a.replicates[0]), names(&b.replicates[0]));
    let shared: Vec<&String> = first_a.iter().filter(|v| first_b.contains(v)).collect();
    if shared.is_empty() {
        return None;
    }
    let mean_over_shared = |f: &Figures| -> Option<f64> {
        let errors: Vec<f64> = f
            .aln_by_variable
            .iter()
            .filter(|(v, _)| shared.contains(&v))
            .map(|(_, e)| *e)
            .collect();
        (errors.len() == shared.len()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
    };
    let values: Vec<Option<f64>> = a
        .replicates
        .iter()
        .zip(&b.replicates)
        .map(|(x, y)| Some(mean_over_shared(x)? - mean_over_shared(y)?))
        .collect();
    Some(Between {
        difference: across(&values)?,
        values,
        common: (first_a != first_b).then_some(shared.len()),
    })
}

/// The interval across replicates of one figure, when every replicate has it.
fn across(values: &[Option<f64>]) -> Option<Interval> {
    let values: Option<Vec<f64>> = values.iter().copied().collect();
    Interval::of(&values?)
}

/// A variant's ALN mean error across its replicates.
pub(super) fn aln_mean(v: &Loaded) -> Option<Interval> {
    let values: Vec<Option<f64>> = v.replicates.iter().map(|f| f.mean_of(MODELS[0])).collect();
    across(&values)
}

/// "1.04 [1.02, 1.06]".
fn with_interval(i: &Interval) -> String {
    estimate(i.mean, i.low, i.high)
}

/// The findings' line on a variant's replicates, if it has several.
pub(super) fn finding(md: &mut String, v: &Loaded) {
    let n = v.replicates.len();
    if n < 2 {
        return;
    }
    let rows = v.replicates[0].rows.as_str();
    let mut line = format!(
        "  - **Across all {n} replicates** (each from a new seed: the model, the split where it \
         is drawn at random, the data where they are simulated; mean and \
         95% interval across replicates, {rows} rows — where this and the replicate above \
         disagree, this is the finding):"
    );
    for (k, model) in MODELS.iter().enumerate() {
        let values: Vec<Option<f64>> = v.replicates.iter().map(|f| f.mean_of(MODELS[k])).collect();
        if let Some(i) = across(&values) {
            let _ = write!(line, " {model} {};", with_interval(&i));
        }
    }
    for (k, baseline) in MODELS[1..].iter().enumerate() {
        let values: Vec<Option<f64>> = v.replicates.iter().map(|f| f.differences[k]).collect();
        if let Some(i) = across(&values) {
            let _ = write!(
                line,
                " the ALN is {} {baseline} (difference {});",
                accuracy_word(&i),
                difference(&i)
            );
        }
    }
    line.pop();
    let _ = writeln!(md, "{line}.");
}

/// The replicates section and `replicates.csv`, when some variant has
/// several replicates.
pub(super) fn section(md: &mut String, variants: &[Loaded], dir: &Path) -> Result<()> {
    if variants.iter().all(|v| v.replicates.len() < 2) {
        return Ok(());
    }
    let _ = writeln!(
        md,
        "## Replicates\n\nEach replicate re-draws the trees, the split where it is drawn at \
         random and the data where they are simulated, from a seed derived from the \
         experiment's. Mean errors over the variables and the ALN's mean \
         paired difference against each baseline, per replicate (on its held-out rows), then \
         their mean with the 95% t-interval across replicates. `replicates.csv` holds every \
         value.\n"
    );
    // The models some replicated variant has.
    let replicated: Vec<&Loaded> = variants.iter().filter(|v| v.replicates.len() > 1).collect();
    let shown: Vec<usize> = (0..MODELS.len())
        .filter(|&k| {
            replicated
                .iter()
                .any(|v| v.replicates.iter().any(|f| f.mean_of(MODELS[k]).is_some()))
        })
        .collect();
    let baselines = || shown.iter().copied().filter(|&k| k > 0);
    let _ = write!(md, "| variant | replicate | seed |");
    for &k in &shown {
        let _ = write!(md, " {} mean |", MODELS[k]);
    }
    for k in baselines() {
        let _ = write!(md, " ALN − {} |", MODELS[k]);
    }
    let _ = writeln!(
        md,
        "\n|---|---|---:|{}",
        "---:|".repeat(shown.len() * 2 - 1)
    );
    let mut csv =
        String::from("variant,figure,replicates,mean,std_dev,ci_low,ci_high,verdict,values\n");
    let cell = |x: Option<f64>| x.map_or("—".into(), sig3);
    for v in replicated.iter().copied() {
        for (r, f) in v.replicates.iter().enumerate() {
            let _ = write!(md, "| {} | {} | {} |", v.info.name, r + 1, f.seed);
            for &k in &shown {
                let _ = write!(md, " {} |", cell(f.mean_of(MODELS[k])));
            }
            for k in baselines() {
                let _ = write!(md, " {} |", cell(f.differences[k - 1]));
            }
            md.push('\n');
        }
        let _ = write!(md, "| {} | mean [95%] | |", v.info.name);
        let mut figures: Vec<(String, Vec<Option<f64>>)> = Vec::new();
        for &k in &shown {
            figures.push((
                format!("{} mean", MODELS[k]),
                v.replicates.iter().map(|f| f.mean_of(MODELS[k])).collect(),
            ));
        }
        for k in baselines() {
            figures.push((
                format!("aln - {}", MODELS[k]),
                v.replicates.iter().map(|f| f.differences[k - 1]).collect(),
            ));
        }
        let shown_in_table = figures.len();
        // For the first screen's check, in the file only: every other
        // model's mean, and each baseline's mean minus persistence's.
        for &(model, _) in &v.replicates[0].model_means {
            let means = |m: ModelId| -> Vec<Option<f64>> {
                v.replicates.iter().map(|f| f.mean_of(m)).collect()
            };
            if !MODELS.contains(&model) {
                figures.push((format!("{model} mean"), means(model)));
                // The first screen sets the ALN against each simulator
                // setting.
                figures.push((
                    format!("aln - {model}"),
                    v.replicates.iter().map(|f| f.aln_minus(model)).collect(),
                ));
            }
            if model != ModelId::Aln && model != ModelId::Persistence {
                let persistence = means(ModelId::Persistence);
                let gap = means(model)
                    .iter()
                    .zip(&persistence)
                    .map(|(m, p)| Some((*m)? - (*p)?))
                    .collect();
                figures.push((format!("{model} mean - persistence mean"), gap));
            }
        }
        for (k, (figure, values)) in figures.iter().enumerate() {
            let interval = across(values);
            if k >= shown_in_table {
                if let Some(i) = interval {
                    let verdict = figure.starts_with("aln - ");
                    csv_line(&mut csv, &v.info.name, figure, &i, verdict, values);
                }
                continue;
            }
            let _ = write!(
                md,
                " {} |",
                interval.as_ref().map_or("—".into(), with_interval)
            );
            if let Some(i) = interval {
                // Only a difference has a verdict.
                let verdict = figure.starts_with("aln - ");
                csv_line(&mut csv, &v.info.name, figure, &i, verdict, values);
            }
        }
        md.push('\n');
    }
    md.push('\n');
    // In the file only: every planning figure per replicate, from which
    // each control headline can be recomputed.
    for v in replicated.iter().copied() {
        for (figure, values) in super::plan::replicate_figures(&v.planning) {
            if let Some(i) = across(&values) {
                csv_line(&mut csv, &v.info.name, &figure, &i, false, &values);
            }
        }
    }
    // Variants against each other, paired by replicate.
    for (i, a) in variants.iter().enumerate() {
        for b in &variants[i + 1..] {
            if let Some(paired) = between(a, b) {
                let over = paired
                    .common
                    .map_or(String::new(), |n| format!(" over {n} common variables"));
                let figure = format!("aln mean - {} aln mean{over}", b.info.name);
                csv_line(
                    &mut csv,
                    &a.info.name,
                    &figure,
                    &paired.difference,
                    true,
                    &paired.values,
                );
            }
        }
    }
    atomic::write_bytes(&dir.join("replicates.csv"), csv.as_bytes())
}

/// One figure's line of `replicates.csv`: its interval across replicates,
/// its verdict (when it is a difference) and every replicate's value, each
/// number as Rust prints it back exactly.
fn csv_line(
    csv: &mut String,
    variant: &str,
    figure: &str,
    i: &Interval,
    verdict: bool,
    values: &[Option<f64>],
) {
    let listed: Vec<String> = values
        .iter()
        .map(|x| x.map_or(String::new(), |x| x.to_string()))
        .collect();
    let _ = writeln!(
        csv,
        "{variant},{figure},{},{},{},{},{},{},{}",
        i.n,
        i.mean,
        i.std_dev,
        i.low,
        i.high,
        if verdict { i.verdict().as_str() } else { "" },
        listed.join(";")
    );
}
