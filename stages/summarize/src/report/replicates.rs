//! Replicates: a variant run again with new seeds (new simulation, split
//! and trees). Each headline figure — a model's mean error over the
//! variables, the ALN's paired difference against a baseline — becomes the
//! mean across replicates with its 95% t-interval across replicates, each
//! replicate one independent value. `replicates.csv`, beside the report,
//! holds every figure with each replicate's value, for checking.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{Result, atomic};

use super::findings::{accuracy_word, difference};
use super::format::{estimate, sig3};
use super::{Loaded, Replicate, aln_against, overall, split_rows};
use crate::Rows;
use crate::paired::Interval;

/// The models whose errors the headline gives.
pub(super) const MODELS: [&str; 3] = ["aln", "persistence", "linear"];

/// One replicate's headline figures, on its held-out rows (all test rows
/// when none is held out).
pub(super) struct Figures {
    pub seed: u64,
    pub rows: Rows,
    /// Mean error over the variables, per model of [`MODELS`].
    pub means: Vec<Option<f64>>,
    /// The ALN's mean paired difference against each baseline of
    /// [`MODELS`] (the ALN itself excepted).
    pub differences: Vec<Option<f64>>,
    /// (model, step, mean) of the closed-loop errors.
    pub horizons: Vec<(String, u16, f64)>,
}

impl Figures {
    pub fn read(replicate: &Replicate) -> Result<Figures> {
        let (all, held, rows) = split_rows(crate::read(&replicate.summary)?);
        let judged = if rows == Rows::HeldOut { held } else { all };
        let comparisons = crate::read_comparisons(&replicate.comparisons)?;
        let horizons = crate::read_horizons(&replicate.horizons)?
            .into_iter()
            .filter(|h| h.0 == rows)
            .map(|(_, model, step, mean, _)| (model, step, mean))
            .collect();
        Ok(Figures {
            horizons,
            seed: replicate.seed,
            rows,
            means: MODELS
                .iter()
                .map(|m| overall(&judged, m).map(|(mean, _)| mean))
                .collect(),
            differences: MODELS[1..]
                .iter()
                .map(|b| aln_against(&comparisons, rows, b, None).map(|d| d.mean))
                .collect(),
        })
    }
}

/// Variant `a`'s ALN mean error minus `b`'s, paired replicate by replicate:
/// both ran with the same seeds, so replicate k of each saw the same
/// simulation. `None` unless both have the same ≥ 2 replicate seeds.
pub(super) fn between(a: &Loaded, b: &Loaded) -> Option<(Interval, Vec<Option<f64>>)> {
    let seeds = |v: &Loaded| v.replicates.iter().map(|f| f.seed).collect::<Vec<_>>();
    // Means over different variables (one model given the controls, one
    // predicting them) do not pair.
    fn variables<'a>(v: &'a Loaded) -> Vec<&'a str> {
        let mut names: Vec<&str> = v
            .judged()
            .0
            .iter()
            .filter(|r| r.model == "aln")
            .map(|r| r.variable.as_str())
            .collect();
        names.sort_unstable();
        names
    }
    if a.replicates.len() < 2 || seeds(a) != seeds(b) || variables(a) != variables(b) {
        return None;
    }
    let values: Vec<Option<f64>> = a
        .replicates
        .iter()
        .zip(&b.replicates)
        .map(|(x, y)| Some(x.means[0]? - y.means[0]?))
        .collect();
    Some((across(&values)?, values))
}

/// The interval across replicates of one figure, when every replicate has it.
fn across(values: &[Option<f64>]) -> Option<Interval> {
    let values: Option<Vec<f64>> = values.iter().copied().collect();
    Interval::of(&values?)
}

/// A variant's ALN mean error across its replicates.
pub(super) fn aln_mean(v: &Loaded) -> Option<Interval> {
    let values: Vec<Option<f64>> = v.replicates.iter().map(|f| f.means[0]).collect();
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
        "  - **Across all {n} replicates** (each a new simulation, split and forest; mean and \
         95% interval across replicates, {rows} rows — where this and the replicate above \
         disagree, this is the finding):"
    );
    for (k, model) in MODELS.iter().enumerate() {
        let values: Vec<Option<f64>> = v.replicates.iter().map(|f| f.means[k]).collect();
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
        "## Replicates\n\nEach replicate re-draws the simulation, the split and the trees from a \
         seed derived from the experiment's. Mean errors over the variables and the ALN's mean \
         paired difference against each baseline, per replicate (on its held-out rows), then \
         their mean with the 95% t-interval across replicates. `replicates.csv` holds every \
         value.\n"
    );
    let _ = write!(md, "| variant | replicate | seed |");
    for m in MODELS {
        let _ = write!(md, " {m} mean |");
    }
    for b in &MODELS[1..] {
        let _ = write!(md, " ALN − {b} |");
    }
    let _ = writeln!(
        md,
        "\n|---|---|---:|{}",
        "---:|".repeat(MODELS.len() * 2 - 1)
    );
    let mut csv =
        String::from("variant,figure,replicates,mean,std_dev,ci_low,ci_high,verdict,values\n");
    let cell = |x: Option<f64>| x.map_or("—".into(), sig3);
    for v in variants.iter().filter(|v| v.replicates.len() > 1) {
        for (k, f) in v.replicates.iter().enumerate() {
            let _ = write!(md, "| {} | {} | {} |", v.info.name, k + 1, f.seed);
            for &m in &f.means {
                let _ = write!(md, " {} |", cell(m));
            }
            for &d in &f.differences {
                let _ = write!(md, " {} |", cell(d));
            }
            md.push('\n');
        }
        let _ = write!(md, "| {} | mean [95%] | |", v.info.name);
        let mut figures: Vec<(String, Vec<Option<f64>>)> = Vec::new();
        for (k, m) in MODELS.iter().enumerate() {
            figures.push((
                format!("{m} mean"),
                v.replicates.iter().map(|f| f.means[k]).collect(),
            ));
        }
        for (k, b) in MODELS[1..].iter().enumerate() {
            figures.push((
                format!("aln - {b}"),
                v.replicates.iter().map(|f| f.differences[k]).collect(),
            ));
        }
        for (figure, values) in &figures {
            let interval = across(values);
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
    // Variants against each other, paired by replicate.
    for (i, a) in variants.iter().enumerate() {
        for b in &variants[i + 1..] {
            if let Some((d, values)) = between(a, b) {
                let figure = format!("aln mean - {} aln mean", b.info.name);
                csv_line(&mut csv, &a.info.name, &figure, &d, true, &values);
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
