//! The report of a run: `report.md` and its SVG charts, rendered from the
//! artifacts alone (summaries, timings, training logs, models) and the run's
//! record — so it can be rendered again at any time without recomputing.
//!
//! Per variant: the paper's §4.6 table (best and worst variable of each
//! group) beside the baselines' errors for the same variables; the variables
//! the ALN predicts worse than persistence, flagged; the §4.5 histogram of
//! the worst variable; training errors per epoch; the §5 hardware estimate.
//! Across variants: one side-by-side table and the speed-against-error
//! chart. The findings in plain sentences ([`findings`]) head it all, then
//! a reproducibility block.

mod findings;
mod replicates;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use alnlab_aln::model::{Header, Model};
use alnlab_aln::{ModelKind, Target};
use alnlab_codes::{Codebook, unit_of};
use alnlab_common::table::Table;
use alnlab_common::{Result, atomic};
use arrow_array::cast::AsArray;
use arrow_array::types::Float64Type;
use arrow_array::{Float64Array, ListArray, UInt32Array, UInt64Array};

use crate::charts::{self, SpeedPoint};
use crate::paired::{Interval, Verdict};
use crate::{Comparison, REPORT_FILE, Rows, SummaryRow};

/// What the report needs of a run.
pub struct RunInfo {
    pub experiment: String,
    pub manifest_path: String,
    pub manifest_sha256: String,
    pub seed: u64,
    pub alnlab_version: String,
    pub git_commit: Option<String>,
    pub started: String,
    pub wall_seconds: f64,
    pub variants: Vec<VariantInfo>,
    /// Set the §4.6 table beside the paper's numbers ([`PAPER_TABLE`]).
    pub compare_with_paper: bool,
    /// What the experiment is for (the manifest's description).
    pub description: String,
    /// The experimenter's reading of the results (Markdown), if any.
    pub notes: String,
    /// The archived dataset the data came from (`name@version`, sha256).
    pub dataset: Option<(String, String)>,
}

/// The paper's §4.6 results table (Armstrong, Supynuk & Green, "Adaptive
/// Logic Networks and Robot Control", §4.6: error in quantization levels of
/// the best and worst variable of each group, 9000 test samples), as
/// published: group, best|worst, mean, std dev, std err, 5% trimmed mean,
/// median, IQR, max.
pub const PAPER_TABLE: &str = include_str!("../data/paper-table-4-6.csv");

/// What the report needs of one variant: its stage times and artifacts.
pub struct VariantInfo {
    pub name: String,
    pub description: String,
    pub stages: Vec<StageTime>,
    pub summary: PathBuf,
    pub comparisons: PathBuf,
    pub horizons: PathBuf,
    pub timings: PathBuf,
    pub training: PathBuf,
    pub model: PathBuf,
    /// The codebook: which variables were learned, and why not the others.
    pub codebook: PathBuf,
    /// Every replicate of the variant (the first is the one above), when
    /// the experiment runs more than one.
    pub replicates: Vec<Replicate>,
}

/// One replicate of a variant: its seed and its summaries.
pub struct Replicate {
    pub seed: u64,
    pub summary: PathBuf,
    pub comparisons: PathBuf,
}

/// One stage of a variant in the run.
pub struct StageTime {
    pub stage: String,
    pub cached: bool,
    pub wall_seconds: f64,
    pub compute_seconds: f64,
}

/// One row of `timings.parquet`.
struct Timing {
    model: String,
    path: String,
    /// ns per state: the median of the timed runs, and their range.
    ns_per_state: f64,
    ns_min: f64,
    ns_max: f64,
    /// ns per state of every run, in round order: run k of every model was
    /// timed in the same round.
    runs: Vec<f64>,
    threads: u32,
    cores: u32,
    cpu: String,
    failed: u32,
}

impl Timing {
    /// "3.8 µs (3.6–4.1)": median and range.
    fn spread(&self) -> String {
        format!(
            "{:.1} µs ({:.1}–{:.1})",
            self.ns_per_state / 1000.0,
            self.ns_min / 1000.0,
            self.ns_max / 1000.0
        )
    }
}

/// A variant's artifacts, read.
struct Loaded<'a> {
    info: &'a VariantInfo,
    /// Summaries over all test rows.
    summary: Vec<SummaryRow>,
    /// Summaries over the held-out test rows alone (empty when none is).
    held_out: Vec<SummaryRow>,
    /// Test rows in all, and held out of training.
    rows: (u64, u64),
    /// The ALN against each other model, paired.
    comparisons: Vec<Comparison>,
    /// Per learned variable, the SI size of one level and its unit.
    level_si: Vec<(String, f64, &'static str)>,
    /// (model, horizon, mean, 95th percentile) of the closed-loop errors,
    /// from the held-out starts (all starts when none is held out).
    horizons: Vec<(String, u16, f64, f64)>,
    timings: Vec<Timing>,
    /// Mean training errors per tree, per epoch (1-based).
    training: Vec<(f64, f64)>,
    hardware: Hardware,
    coverage: Coverage,
    /// Bytes the trees take in memory while training: two counters per
    /// internal node, a literal per leaf.
    tree_bytes: usize,
    /// The variables not learned, with the codebook's reason.
    not_learned: Vec<(String, String)>,
    /// What the model is and learns, in words.
    description: String,
    /// The replicates' headline figures, when there are several.
    replicates: Vec<replicates::Figures>,
}

impl Loaded<'_> {
    /// The timing of `model` on evaluation `path` on one thread.
    fn timing(&self, model: &str, path: &str) -> Option<&Timing> {
        self.timings
            .iter()
            .find(|t| t.model == model && t.path == path && t.threads == 1)
    }

    /// Median ns per state of `model` on evaluation `path`, one thread.
    fn ns(&self, model: &str, path: &str) -> Option<f64> {
        self.timing(model, path).map(|t| t.ns_per_state)
    }

    /// The ALN one state at a time: the parsimonious path of a bit-forest,
    /// the binary search of a threshold model.
    fn aln_single(&self) -> Option<&Timing> {
        self.timing("aln", "single")
            .or_else(|| self.timing("aln", "threshold-search"))
    }

    /// The ALN's batches on all threads, when there are more than one.
    fn aln_all_threads(&self) -> Option<&Timing> {
        self.timings
            .iter()
            .find(|t| t.model == "aln" && t.path == "batched" && t.threads > 1)
    }

    /// The rows findings are about: the held-out ones, or all when the run
    /// has none held out.
    fn judged(&self) -> (&[SummaryRow], Rows) {
        if self.held_out.is_empty() {
            (&self.summary, Rows::All)
        } else {
            (&self.held_out, Rows::HeldOut)
        }
    }

    /// The ALN against `against` on the judged rows: for `variable`, or
    /// averaged over the variables.
    fn compared(&self, against: &str, variable: Option<&str>) -> Option<&Interval> {
        aln_against(&self.comparisons, self.judged().1, against, variable)
    }

    /// How the ALN compares with `against` variable by variable on the
    /// judged rows: (lower, higher, indistinguishable, tied) error.
    fn verdict_counts(&self, against: &str) -> [usize; 4] {
        let (_, rows) = self.judged();
        let mut counts = [0; 4];
        for c in self.comparisons.iter().filter(|c| {
            c.rows == rows && c.model == "aln" && c.against == against && c.variable.is_some()
        }) {
            counts[match c.difference.verdict() {
                Verdict::Lower => 0,
                Verdict::Higher => 1,
                Verdict::Indistinguishable => 2,
                Verdict::Tied => 3,
            }] += 1;
        }
        counts
    }

    /// The SI size of one level of `variable`, and its unit.
    fn si(&self, variable: &str) -> Option<(f64, &'static str)> {
        self.level_si
            .iter()
            .find(|(v, _, _)| v == variable)
            .map(|(_, step, unit)| (*step, *unit))
    }
}

/// How much of its input a tree can see: leaves are wired to literals (an
/// input bit or its complement) at random when the tree is made, so with
/// fewer leaves than literals most inputs reach no leaf at all.
struct Coverage {
    leaves: usize,
    /// Literals per tree: twice its input bits.
    literals: usize,
    /// Distinct literals on a tree's leaves, as a fraction of `literals`,
    /// averaged over the trees.
    read: f64,
}

/// The §5 estimate from the pruned trees.
struct Hardware {
    kind: ModelKind,
    max_depth: u32,
    mean_depth: f64,
    max_width: usize,
    levels_steps: u32,
}

impl Hardware {
    /// Gate delays for one predicted state: the deepest tree, then decoding
    /// (§5: twice the code width) — or, for the threshold model, one tree
    /// per binary-search step.
    fn delays(&self) -> u64 {
        match self.kind {
            ModelKind::BitForest => u64::from(self.max_depth) + 2 * self.max_width as u64,
            ModelKind::Threshold => u64::from(self.max_depth) * u64::from(self.levels_steps),
        }
    }
}

/// Renders the report into `dir` (created if need be); returns the path of
/// `report.md`.
pub fn render(run: &RunInfo, dir: &Path) -> Result<PathBuf> {
    atomic::sweep_leftovers(dir)?;
    let variants: Vec<Loaded> = run.variants.iter().map(load).collect::<Result<_>>()?;
    let mut md = String::new();
    let _ = writeln!(md, "# {} — report\n", run.experiment);
    findings::findings(&mut md, run, &variants);
    reproducibility(&mut md, run, &variants);
    replicates::section(&mut md, &variants, dir)?;
    side_by_side(&mut md, &variants);

    let mut points = Vec::new();
    for v in &variants {
        for t in &v.timings {
            if let Some((mean, p95)) = overall(&v.summary, &t.model) {
                points.push(SpeedPoint {
                    label: format!("{} {} {} ({} thr)", v.info.name, t.model, t.path, t.threads),
                    ns_per_state: t.ns_per_state,
                    mean,
                    p95,
                });
            }
        }
    }
    atomic::write_bytes(&dir.join("speed.svg"), charts::speed(&points).as_bytes())?;
    let _ = writeln!(md, "## Speed against error\n");
    let _ = writeln!(
        md,
        "![ns per predicted state against error](speed.svg)\n\nEach point is one model and evaluation \
         path of one variant: its ns per predicted state (for the simulator, per re-simulated \
         frame, at several integration steps per frame) on this machine against its error \
         averaged over the variables (mean filled, 95th percentile hollow).\n"
    );

    for v in &variants {
        variant_section(&mut md, v, dir, run.compare_with_paper)?;
    }
    let path = dir.join(REPORT_FILE);
    atomic::write_bytes(&path, md.as_bytes())?;
    Ok(path)
}

/// A summary split into its rows over all test rows and over the held-out
/// ones, with the set findings judge: the held-out rows, or all when none
/// is held out.
fn split_rows(summary: Vec<SummaryRow>) -> (Vec<SummaryRow>, Vec<SummaryRow>, Rows) {
    let (all, held_out): (Vec<SummaryRow>, Vec<SummaryRow>) =
        summary.into_iter().partition(|r| r.rows == Rows::All);
    let judged = if held_out.is_empty() {
        Rows::All
    } else {
        Rows::HeldOut
    };
    (all, held_out, judged)
}

/// The ALN against `against` on `rows`: for `variable`, or averaged over
/// the variables.
fn aln_against<'c>(
    comparisons: &'c [Comparison],
    rows: Rows,
    against: &str,
    variable: Option<&str>,
) -> Option<&'c Interval> {
    comparisons
        .iter()
        .find(|c| {
            c.rows == rows
                && c.model == "aln"
                && c.against == against
                && c.variable.as_deref() == variable
        })
        .map(|c| &c.difference)
}

fn load(info: &VariantInfo) -> Result<Loaded<'_>> {
    let (summary, held_out, judged) = split_rows(crate::read(&info.summary)?);
    let count = |rows: &[SummaryRow]| rows.first().map_or(0, |r| r.stats.n);
    let rows = (count(&summary), count(&held_out));
    let comparisons = crate::read_comparisons(&info.comparisons)?;
    let horizons = crate::read_horizons(&info.horizons)?;
    let horizons = horizons
        .into_iter()
        .filter(|h| h.0 == judged)
        .map(|(_, model, horizon, mean, p95)| (model, horizon, mean, p95))
        .collect();
    let table = Table::read(&info.timings)?;
    let text = |name: &str| table.strings(name);
    let (models, paths) = (text("model")?, text("path")?);
    let ns = table.column::<Float64Array>("ns_per_state")?.values();
    let ns_min = table.column::<Float64Array>("ns_min")?.values();
    let ns_max = table.column::<Float64Array>("ns_max")?.values();
    let runs = table.column::<ListArray>("ns_runs")?;
    let threads = table.column::<UInt32Array>("threads")?.values();
    let cores = table.column::<UInt32Array>("cores")?.values();
    let cpu = text("cpu")?;
    let failed = table.column::<UInt32Array>("failed")?.values();
    let timings = (0..table.num_rows())
        .map(|i| Timing {
            model: models[i].clone(),
            path: paths[i].clone(),
            ns_per_state: ns[i],
            ns_min: ns_min[i],
            ns_max: ns_max[i],
            runs: runs
                .value(i)
                .as_primitive_opt::<Float64Type>()
                .map(|r| r.values().to_vec())
                .unwrap_or_default(),
            threads: threads[i],
            cores: cores[i],
            cpu: cpu[i].clone(),
            failed: failed[i],
        })
        .collect();

    let log = Table::read(&info.training)?;
    let epochs = log.column::<UInt32Array>("epoch")?.values();
    let errors = log.column::<UInt64Array>("errors")?.values();
    let mut per_epoch: Vec<(u64, u64)> = Vec::new();
    for (&epoch, &e) in epochs.iter().zip(errors.iter()) {
        let k = epoch as usize;
        if per_epoch.len() < k {
            per_epoch.resize(k, (0, 0));
        }
        per_epoch[k - 1].0 += e;
        per_epoch[k - 1].1 += 1;
    }
    let training = per_epoch
        .iter()
        .enumerate()
        .filter(|(_, (_, trees))| *trees > 0)
        .map(|(k, (sum, trees))| ((k + 1) as f64, *sum as f64 / *trees as f64))
        .collect();

    let model = Model::read(&info.model)?;
    let depths: Vec<u32> = model.trees.iter().map(|(_, t)| t.prune().depth()).collect();
    let max_width = model
        .header
        .outputs
        .iter()
        .map(|(_, w)| *w)
        .max()
        .unwrap_or(0);
    let hardware = Hardware {
        kind: model.header.model,
        max_depth: depths.iter().copied().max().unwrap_or(0),
        mean_depth: depths.iter().map(|&d| f64::from(d)).sum::<f64>() / depths.len().max(1) as f64,
        max_width,
        // A thermometer of w bits has w + 1 levels: ⌈log₂(w + 1)⌉ steps.
        levels_steps: (max_width + 1).next_power_of_two().trailing_zeros(),
    };
    let codebook = Codebook::read(&info.codebook)?;
    let width_of = |name: &str| {
        codebook
            .entries
            .iter()
            .find(|e| e.variable == name)
            .map_or(0, |e| e.width as usize)
    };
    // The literals a tree may be wired to: its output's inputs (every input
    // bit, or those of the variables it reads), and a threshold tree's
    // candidate.
    let candidate = match model.header.model {
        ModelKind::BitForest => 0,
        ModelKind::Threshold => max_width,
    };
    let literals_of = |variable: usize| {
        let inputs = match model.header.reads.get(variable) {
            Some(reads) => reads.iter().map(|r| width_of(r)).sum(),
            None => model.header.inputs,
        };
        2 * (inputs + candidate)
    };
    let mut seen = Vec::new();
    let (mut read, mut literals) = (0.0, 0);
    for (id, tree) in &model.trees {
        seen.clear();
        seen.extend_from_slice(tree.literals());
        seen.sort_unstable();
        seen.dedup();
        let of = literals_of(id.variable as usize);
        read += seen.len() as f64 / of as f64;
        literals = literals.max(of);
    }
    let read = read / model.trees.len().max(1) as f64;
    let coverage = Coverage {
        leaves: model.trees.first().map_or(0, |(_, t)| t.leaves()),
        literals,
        read,
    };
    let tree_bytes = model
        .trees
        .iter()
        .map(|(_, t)| 2 * (t.leaves() - 1) + std::mem::size_of_val(t.literals()))
        .sum();
    let description = describe(&model.header, model.trees.len(), coverage.leaves);
    let level_si = codebook
        .learned()
        .map(|e| {
            let q = &e.quantizer;
            let step = (q.max - q.min) / (q.levels.max(2) - 1) as f64;
            (e.variable.clone(), step, unit_of(&e.variable))
        })
        .collect();
    let not_learned = codebook
        .entries
        .into_iter()
        .filter(|e| !e.learned)
        .map(|e| (e.variable, e.note))
        .collect();
    let replicates = if info.replicates.len() > 1 {
        info.replicates
            .iter()
            .map(replicates::Figures::read)
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    Ok(Loaded {
        replicates,
        description,
        not_learned,
        info,
        summary,
        held_out,
        rows,
        comparisons,
        level_si,
        horizons,
        timings,
        training,
        hardware,
        coverage,
        tree_bytes,
    })
}

/// What a model is and learns, in a sentence: its kind and trees, its
/// target (with the range of k and the code of a residual target), and
/// which inputs its outputs read.
fn describe(header: &Header, trees: usize, leaves: usize) -> String {
    let kind = match header.model {
        ModelKind::BitForest => "a bit-forest",
        ModelKind::Threshold => "a threshold-predicate model (§6)",
    };
    let mut text = format!("{kind} of {trees} trees of {leaves} leaves");
    if header.vote > 1 {
        let _ = write!(text, ", {} voting per output", header.vote);
    }
    match &header.target {
        Target::Level => text.push_str("; it learns each variable's next level"),
        Target::Delta(specs) => {
            let ks = specs.iter().map(|s| s.k);
            let (lo, hi) = (ks.clone().min().unwrap_or(0), ks.max().unwrap_or(0));
            let _ = write!(
                text,
                "; it learns each variable's change of level Δ, clamped to ±k (k from {lo} to \
                 {hi}, from the training rows)"
            );
            // A threshold model searches Δ's levels; a bit-forest learns its code.
            if let (ModelKind::BitForest, Some(spec)) = (header.model, specs.first()) {
                let _ = write!(text, " in {} code", spec.code);
            }
        }
    }
    if let Some(most) = header.reads.iter().map(Vec::len).max() {
        let _ = write!(
            text,
            "; each output reads only its {most} most informative inputs (mutual information \
             with its target on the training rows)"
        );
    }
    text
}

/// (mean, 95th percentile) of a model's errors, averaged over the variables.
fn overall(summary: &[SummaryRow], model: &str) -> Option<(f64, f64)> {
    let rows: Vec<&SummaryRow> = summary.iter().filter(|r| r.model == model).collect();
    let n = rows.len() as f64;
    (!rows.is_empty()).then(|| {
        (
            rows.iter().map(|r| r.stats.mean).sum::<f64>() / n,
            rows.iter().map(|r| r.stats.p95).sum::<f64>() / n,
        )
    })
}

/// The models other than the ALN, in summary order.
fn baseline_models(summary: &[SummaryRow]) -> Vec<&str> {
    let mut models: Vec<&str> = summary
        .iter()
        .map(|r| r.model.as_str())
        .filter(|m| *m != "aln")
        .collect();
    models.dedup();
    models
}

/// The mean error of `model` for `variable`.
fn mean_of(summary: &[SummaryRow], model: &str, variable: &str) -> Option<f64> {
    summary
        .iter()
        .find(|r| r.model == model && r.variable == variable)
        .map(|r| r.stats.mean)
}

/// A model's normalized error averaged over the variables: each
/// variable's mean error over the standard deviation of its true levels
/// (variables whose truth does not vary are left out).
fn normalized(summary: &[SummaryRow], model: &str) -> Option<f64> {
    let ratios: Vec<f64> = summary
        .iter()
        .filter(|r| r.model == model && r.true_std_dev > 0.0)
        .map(|r| r.stats.mean / r.true_std_dev)
        .collect();
    (!ratios.is_empty()).then(|| ratios.iter().sum::<f64>() / ratios.len() as f64)
}

/// The variables the ALN predicts worse than persistence on the judged
/// rows — the interval of the paired difference above zero: (variable,
/// ALN mean, persistence mean, difference).
fn worse_than_persistence<'a>(v: &'a Loaded) -> Vec<(&'a str, f64, f64, &'a Interval)> {
    let (judged, _) = v.judged();
    judged
        .iter()
        .filter(|r| r.model == "aln")
        .filter_map(|r| {
            let persistence = mean_of(judged, "persistence", &r.variable)?;
            let d = v.compared("persistence", Some(&r.variable))?;
            (d.verdict() == Verdict::Higher).then_some((
                r.variable.as_str(),
                r.stats.mean,
                persistence,
                d,
            ))
        })
        .collect()
}

fn reproducibility(md: &mut String, run: &RunInfo, variants: &[Loaded]) {
    let machine = variants
        .iter()
        .flat_map(|v| v.timings.first())
        .map(|t| format!("{}, {} cores", t.cpu, t.cores))
        .next()
        .unwrap_or_else(|| "—".into());
    let _ = writeln!(md, "## Reproducibility\n");
    let _ = writeln!(md, "| | |\n|---|---|");
    let _ = writeln!(md, "| manifest | `{}` |", run.manifest_path);
    let _ = writeln!(md, "| manifest sha256 | `{}` |", run.manifest_sha256);
    if let Some((dataset, sha256)) = &run.dataset {
        let _ = writeln!(md, "| dataset | {dataset} (sha256 `{sha256}`) |");
    }
    let _ = writeln!(md, "| seed | {} |", run.seed);
    if let Some(v) = variants.first().filter(|v| v.info.replicates.len() > 1) {
        let seeds: Vec<String> = v
            .info
            .replicates
            .iter()
            .map(|r| r.seed.to_string())
            .collect();
        let _ = writeln!(
            md,
            "| replicates | {} (seeds {}) |",
            seeds.len(),
            seeds.join(", ")
        );
    }
    let _ = writeln!(md, "| alnlab | {} |", run.alnlab_version);
    let commit = run
        .git_commit
        .as_deref()
        .unwrap_or("(not in a git checkout)");
    let _ = writeln!(md, "| git commit | `{commit}` |");
    let _ = writeln!(md, "| machine | {machine} |");
    let _ = writeln!(md, "| started | {} |", run.started);
    let _ = writeln!(md, "| wall time | {:.2} s |\n", run.wall_seconds);
    let _ = writeln!(
        md,
        "| variant | stage | cached | wall (s) | compute when made (s) |"
    );
    let _ = writeln!(md, "|---|---|---|---:|---:|");
    for v in variants {
        for s in &v.info.stages {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.3} | {:.3} |",
                v.info.name,
                s.stage,
                if s.cached { "yes" } else { "no" },
                s.wall_seconds,
                s.compute_seconds
            );
        }
    }
    md.push('\n');
}

fn side_by_side(md: &mut String, variants: &[Loaded]) {
    let _ = writeln!(md, "## Variants side by side\n");
    let mut baselines: Vec<&str> = Vec::new();
    for v in variants {
        for b in baseline_models(&v.summary) {
            if !baselines.contains(&b) {
                baselines.push(b);
            }
        }
    }
    let _ = write!(
        md,
        "Errors in quantization levels averaged over the variables, on each variant's held-out \
         test rows (all test rows when none is held out), and the ALN's also over all test rows; \
         times on one thread (median of the timed runs); training time as computed (also when \
         the stage was cached); the trees' memory while training. \"Worse than persistence\" \
         counts the variables whose paired difference's interval lies above zero.\n\n\
         | variant | rows | ALN mean | ALN normalized | ALN p95 | ALN mean, all test rows |"
    );
    for b in &baselines {
        let _ = write!(md, " {b} mean |");
    }
    let _ = writeln!(
        md,
        " ALN batched ns/state | ALN single ns/state | hardware estimate (gate delays) | \
         training (s) | trees (MiB) | variables worse than persistence |\n\
         |---|---|---:|---:|---:|---:|{}---:|---:|---:|---:|---:|---:|",
        "---:|".repeat(baselines.len())
    );
    for v in variants {
        let (judged, rows) = v.judged();
        let mean =
            |model: &str| overall(judged, model).map_or("—".into(), |(m, _)| format!("{m:.4}"));
        let p95 = overall(judged, "aln").map_or("—".into(), |(_, p)| format!("{p:.2}"));
        let all = overall(&v.summary, "aln").map_or("—".into(), |(m, _)| format!("{m:.4}"));
        let ns = |t: Option<f64>| t.map_or("—".into(), |t| format!("{t:.0}"));
        let worse = worse_than_persistence(v).len();
        let total = judged.iter().filter(|r| r.model == "aln").count();
        let baseline_means: String = baselines
            .iter()
            .map(|b| format!(" {} |", mean(b)))
            .collect();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {all} |{baseline_means} {} | {} | {} | {} | {:.1} | {}{} of {} |",
            v.info.name,
            rows.as_str(),
            mean("aln"),
            normalized(judged, "aln").map_or("—".into(), |x| format!("{x:.3}")),
            p95,
            ns(v.ns("aln", "batched")),
            ns(v.aln_single().map(|t| t.ns_per_state)),
            v.hardware.delays(),
            v.info
                .stages
                .iter()
                .find(|s| s.stage == "train")
                .map_or("—".into(), |s| format!("{:.1}", s.compute_seconds)),
            v.tree_bytes as f64 / (1024.0 * 1024.0),
            if worse > 0 { "⚠ " } else { "" },
            worse,
            total
        );
    }
    md.push('\n');
}

fn file_name(variant: &str, chart: &str) -> String {
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

fn variant_section(
    md: &mut String,
    v: &Loaded,
    dir: &Path,
    compare_with_paper: bool,
) -> Result<()> {
    let _ = writeln!(md, "## Variant `{}`\n", v.info.name);
    if !v.info.description.is_empty() {
        let _ = writeln!(md, "{}\n", v.info.description);
    }

    if !v.not_learned.is_empty() {
        let _ = writeln!(
            md,
            "### Variables not learned\n\nThe data hold them, but they carry nothing to predict; \
             no model is scored on them.\n\n| variable | why |\n|---|---|"
        );
        for (variable, note) in &v.not_learned {
            let _ = writeln!(md, "| `{variable}` | {note} |");
        }
        let _ = writeln!(md);
    }

    let _ = writeln!(md, "### Error by group (paper §4.6)\n");
    let baselines = baseline_models(&v.summary);
    let _ = write!(
        md,
        "The ALN's best and worst variable of each group over all test rows, in quantization \
         levels (the mean also in SI units: levels × the size of one level), beside its mean on \
         the held-out rows alone and the baselines' mean error on the same variable.\n\n\
         | group | | variable | mean | mean (SI) | std dev | std err | 5% trim | median | IQR | max | held-out mean |"
    );
    for b in &baselines {
        let _ = write!(md, " {b} mean |");
    }
    let _ = writeln!(
        md,
        "\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|{}",
        "---:|".repeat(baselines.len())
    );
    let aln: Vec<&SummaryRow> = v.summary.iter().filter(|r| r.model == "aln").collect();
    let mut groups: Vec<&str> = aln.iter().map(|r| r.group.as_str()).collect();
    groups.dedup();
    for group in groups {
        for (which, pick) in [("best", true), ("worst", false)] {
            let Some(r) = aln.iter().find(|r| {
                r.group == group
                    && if pick {
                        r.best_in_group
                    } else {
                        r.worst_in_group
                    }
            }) else {
                continue;
            };
            let s = &r.stats;
            let baseline = |m: &str| {
                mean_of(&v.summary, m, &r.variable).map_or("—".into(), |x| format!("{x:.4}"))
            };
            let others: String = baselines
                .iter()
                .map(|b| format!(" {} |", baseline(b)))
                .collect();
            let si = v.si(&r.variable).map_or("—".into(), |(step, unit)| {
                format!("{} {unit}", sig(s.mean * step))
            });
            let held = mean_of(&v.held_out, "aln", &r.variable)
                .map_or("—".into(), |x| format!("{x:.4}"));
            let _ = writeln!(
                md,
                "| {group} | {which} | {} | {:.4} | {si} | {:.4} | {:.4} | {:.4} | {} | {} | {} | {held} |{others}",
                r.variable, s.mean, s.std_dev, s.std_err, s.trimmed_mean, s.median, s.iqr, s.max,
            );
        }
    }
    md.push('\n');

    if compare_with_paper {
        beside_the_paper(md, v);
    }
    models_table(md, v);

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
    } else {
        let _ = writeln!(
            md,
            "⚠ On {} of {} variables the ALN's error is higher than predicting no change, the \
             95% interval of the paired difference above zero ({} rows; SI: the difference × \
             the size of one level):\n\n\
             | variable | ALN mean | persistence mean | difference [95% interval] | difference (SI) |\n\
             |---|---:|---:|---|---:|",
            worse.len(),
            judged.iter().filter(|r| r.model == "aln").count(),
            rows.as_str()
        );
        for (variable, mean, persistence, d) in &worse {
            let si = v.si(variable).map_or("—".into(), |(step, unit)| {
                format!("{} {unit}", sig(d.mean * step))
            });
            let _ = writeln!(
                md,
                "| ⚠ {variable} | {mean:.4} | {persistence:.4} | {} | {si} |",
                findings::difference(d)
            );
        }
        md.push('\n');
    }

    if let Some(worst) = aln
        .iter()
        .max_by(|a, b| a.stats.mean.total_cmp(&b.stats.mean))
    {
        let name = file_name(&v.info.name, "histogram");
        let title = format!("{}: errors of {}", v.info.name, worst.variable);
        atomic::write_bytes(
            &dir.join(&name),
            charts::histogram(&title, &worst.stats.histogram).as_bytes(),
        )?;
        let _ = writeln!(
            md,
            "### Error histogram of the worst variable, `{}` (paper §4.5)\n",
            worst.variable
        );
        let _ = writeln!(md, "![histogram]({name})\n");
        let _ = writeln!(
            md,
            "| error (levels) | 0 | 1 | 2 | 3 | 4 | 5 | 6 | 7 | 8 | 9 | 10+ |"
        );
        let _ = writeln!(
            md,
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
        let counts: Vec<String> = worst.stats.histogram.iter().map(u64::to_string).collect();
        let _ = writeln!(md, "| count | {} |\n", counts.join(" | "));
    }

    let name = file_name(&v.info.name, "training");
    let series = vec![("mean errors per tree".to_string(), v.training.clone())];
    let title = format!("{}: training errors per epoch", v.info.name);
    atomic::write_bytes(
        &dir.join(&name),
        charts::lines(&title, "epoch", "errors per tree", &series).as_bytes(),
    )?;
    let _ = writeln!(md, "### Training\n\n![training errors per epoch]({name})\n");

    let h = &v.hardware;
    let _ = writeln!(md, "### Hardware estimate (paper §5)\n");
    let _ = match h.kind {
        ModelKind::BitForest => writeln!(
            md,
            "Pruned trees are at most {} gate delays deep (mean {:.1}); decoding a {}-bit code takes \
             about twice its width: {} + 2·{} = **{} gate delays** per predicted state, all trees \
             in parallel.\n",
            h.max_depth,
            h.mean_depth,
            h.max_width,
            h.max_depth,
            h.max_width,
            h.delays()
        ),
        ModelKind::Threshold => writeln!(
            md,
            "Pruned trees are at most {} gate delays deep (mean {:.1}); the binary search over {} \
             levels takes {} evaluations in sequence: {}·{} = **{} gate delays** per predicted state.\n",
            h.max_depth,
            h.mean_depth,
            h.max_width + 1,
            h.levels_steps,
            h.max_depth,
            h.levels_steps,
            h.delays()
        ),
    };
    closed_loop(md, v, dir)
}

/// The rows of the paper's §4.6 table (its CSV fields: group, best|worst,
/// mean, …), each with the ALN's variable of the same group and rank, if
/// the run has that group. Groups are named as in the paper's table (ω is
/// omega, R roll and pitch).
fn paper_rows(summary: &[SummaryRow]) -> Vec<(Vec<&'static str>, Option<&SummaryRow>)> {
    PAPER_TABLE
        .lines()
        .skip(1)
        .map(|line| {
            let f: Vec<&'static str> = line.split(',').collect();
            let ours = summary.iter().find(|r| {
                r.model == "aln"
                    && r.group == f[0]
                    && if f[1] == "best" {
                        r.best_in_group
                    } else {
                        r.worst_in_group
                    }
            });
            (f, ours)
        })
        .collect()
}

/// Our best and worst variable of each group beside the paper's (§4.6).
fn beside_the_paper(md: &mut String, v: &Loaded) {
    let _ = writeln!(
        md,
        "### Beside the paper (§4.6)\n\nThe paper's numbers as published (its table of §4.6), ours \
         for the same group and rank; errors in quantization levels. Our variables and ranges are \
         our simulator's, not DynaTree's, so a row compares like with like only as far as the \
         groups do.\n\n\
         | group | | paper mean | our mean (variable) | paper 5% trim | ours | paper median | ours | \
         paper IQR | ours | paper max | ours |\n\
         |---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for (f, ours) in paper_rows(&v.summary) {
        let (group, which) = (f[0], f[1]);
        let (mean, trim, median, iqr, max) = match ours {
            Some(r) => (
                format!("{:.4} ({})", r.stats.mean, r.variable),
                format!("{:.4}", r.stats.trimmed_mean),
                r.stats.median.to_string(),
                r.stats.iqr.to_string(),
                r.stats.max.to_string(),
            ),
            None => ("—".into(), "—".into(), "—".into(), "—".into(), "—".into()),
        };
        let _ = writeln!(
            md,
            "| {group} | {which} | {} | {mean} | {} | {trim} | {} | {median} | {} | {iqr} | {} | {max} |",
            f[2], f[5], f[6], f[7], f[8]
        );
    }
    md.push('\n');
}

/// Every model beside the ALN: its error over all variables, on all and
/// on held-out rows, against the ALN, and its speed.
fn models_table(md: &mut String, v: &Loaded) {
    let (judged, rows) = v.judged();
    let _ = writeln!(
        md,
        "### Every model\n\nErrors averaged over the variables, over all test rows and over the \
         {} rows (normalized: each variable's mean error over the standard deviation of its \
         true levels); the ALN's paired difference against the model on those rows, with its \
         95% interval; time per predicted state (the simulator: per re-simulated frame, \
         `simulator@k/frame` taking k integration steps per frame), median and range of the \
         timed runs, with the path and threads; frames a simulator could not step are scored \
         as the worst prediction.\n\n\
         | model | mean | 5% trim | p95 | max | {0} mean | {0} normalized | ALN − model [95%] | µs/state (path, threads) | failed |\n\
         |---|---:|---:|---:|---:|---:|---:|---|---|---:|",
        rows.as_str()
    );
    let mut models: Vec<&str> = v.summary.iter().map(|r| r.model.as_str()).collect();
    models.dedup();
    for model in models {
        let rows: Vec<&SummaryRow> = v.summary.iter().filter(|r| r.model == model).collect();
        let n = rows.len() as f64;
        let average = |f: fn(&SummaryRow) -> f64| rows.iter().map(|r| f(r)).sum::<f64>() / n;
        let max = rows.iter().map(|r| r.stats.max).max().unwrap_or(0);
        let speed: Vec<String> = v
            .timings
            .iter()
            .filter(|t| t.model == model)
            .map(|t| format!("{} ({}, {})", t.spread(), t.path, t.threads))
            .collect();
        let failed: u32 = v
            .timings
            .iter()
            .filter(|t| t.model == model && t.threads == 1)
            .map(|t| t.failed)
            .max()
            .unwrap_or(0);
        let compared = v
            .compared(model, None)
            .map_or("—".into(), findings::difference);
        let _ = writeln!(
            md,
            "| {model} | {:.4} | {:.4} | {:.2} | {max} | {} | {} | {compared} | {} | {failed} |",
            average(|r| r.stats.mean),
            average(|r| r.stats.trimmed_mean),
            average(|r| r.stats.p95),
            overall(judged, model).map_or("—".into(), |(m, _)| format!("{m:.4}")),
            normalized(judged, model).map_or("—".into(), |x| format!("{x:.3}")),
            if speed.is_empty() {
                "—".into()
            } else {
                speed.join("; ")
            },
        );
    }
    md.push('\n');
}

/// Four significant digits, in plain or scientific notation as the size
/// asks.
fn sig(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if (1e-3..1e4).contains(&x.abs()) {
        let decimals = (3 - x.abs().log10().floor() as i32).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.3e}")
    }
}

/// Error against closed-loop horizon: each model fed its own output.
fn closed_loop(md: &mut String, v: &Loaded, dir: &Path) -> Result<()> {
    let _ = writeln!(
        md,
        "### Closed loop
"
    );
    if v.horizons.is_empty() {
        let _ = writeln!(
            md,
            "No test row has enough logged frames after it for a rollout.\n"
        );
        return Ok(());
    }
    let mut models: Vec<&str> = v.horizons.iter().map(|h| h.0.as_str()).collect();
    models.dedup();
    let series: Vec<(String, Vec<(f64, f64)>)> = models
        .iter()
        .map(|&m| {
            let points = v.horizons.iter().filter(|h| h.0 == m);
            (
                m.to_string(),
                points.map(|h| (f64::from(h.1), h.2)).collect(),
            )
        })
        .collect();
    let name = file_name(&v.info.name, "closed-loop");
    let title = format!("{}: closed-loop error against horizon", v.info.name);
    let chart = charts::lines(&title, "steps fed back", "mean error (levels)", &series);
    atomic::write_bytes(&dir.join(&name), chart.as_bytes())?;
    let _ = writeln!(
        md,
        "From the true state of test rows held out of training (all test rows when none is), \
         each model is fed its own predictions; its levels are scored against the logged \
         trajectory at every step (all variables pooled).\n\n\
         ![closed-loop error against horizon]({name})\n"
    );
    let _ = write!(md, "| steps |");
    for m in &models {
        let _ = write!(md, " {m} mean | {m} p95 |");
    }
    let _ = write!(md, "\n|---:|");
    for _ in &models {
        let _ = write!(md, "---:|---:|");
    }
    md.push('\n');
    let mut steps: Vec<u16> = v.horizons.iter().map(|h| h.1).collect();
    steps.sort_unstable();
    steps.dedup();
    for step in steps {
        let _ = write!(md, "| {step} |");
        for m in &models {
            match v.horizons.iter().find(|h| h.0 == *m && h.1 == step) {
                Some(h) => {
                    let _ = write!(md, " {:.3} | {:.1} |", h.2, h.3);
                }
                None => md.push_str(" — | — |"),
            }
        }
        md.push('\n');
    }
    md.push('\n');
    Ok(())
}
