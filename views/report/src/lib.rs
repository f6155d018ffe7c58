//! The report of a run, a view over every stage's output that only the
//! pipeline uses: `report.md`, `report.html` and their SVG charts, rendered
//! from the artifacts alone (summaries, timings, training logs, models) and the run's
//! record — so it can be rendered again at any time without recomputing.
//!
//! Per variant: the paper's §4.6 table (best and worst variable of each
//! group) beside the baselines' errors for the same variables; the variables
//! the ALN predicts worse than persistence, flagged; the §4.5 histogram of
//! the worst variable; training errors per epoch; the §5 hardware estimate.
//! Across variants: one side-by-side table and the speed-against-error
//! chart. The findings in plain sentences ([`findings`]) head it all, then
//! a reproducibility block.

mod across;
mod charts;
mod circuit;
mod closed_loop;
mod findings;
mod fixed_point;
pub mod format;
mod glossary;
mod headline;
pub mod html;
pub mod metrics;
mod plan;
mod plan_frontier;
mod replicates;
pub mod synthesis;
mod variant;

use alnlab_common::ModelId;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use alnlab_aln::model::{Base, Header, Model};
use alnlab_aln::{ModelKind, Target};
use alnlab_codes::unit_of;
use alnlab_common::{Result, atomic};

use alnlab_evaluate::timings::Row as Timing;
use alnlab_plan::planning::Episode;
use alnlab_summarize::paired::{Interval, Verdict};
use alnlab_summarize::{Comparison, HorizonFigures, Rows, SummaryRow};
use format::{Align, MdTable};

/// File name of the report.
pub const REPORT_FILE: &str = "report.md";

/// What the report needs of a run.
pub struct RunInfo {
    pub experiment: String,
    pub manifest_path: String,
    pub manifest_sha256: String,
    pub seed: u64,
    pub alnlab_version: String,
    pub git_commit: Option<String>,
    /// The paths that differed from `git_commit` when the run started.
    pub git_changes: Vec<String>,
    pub started: String,
    pub wall_seconds: f64,
    pub variants: Vec<VariantInfo>,
    /// Set the §4.6 table beside the paper's numbers ([`PAPER_TABLE`]).
    pub compare_with_paper: bool,
    /// What the experiment is for (the manifest's description).
    pub description: String,
    /// The experimenter's reading of the results (Markdown), if any.
    pub notes: String,
    /// The experimenter's answer (Markdown) for the first screen, if any.
    pub answer: String,
    /// The archived dataset the data came from (`name@version`, sha256).
    pub dataset: Option<(String, String)>,
    /// The recording the data came from (its path as the manifest names
    /// it, its sha256, the topic).
    pub recording: Option<(String, String, String)>,
    /// The tables of samples the data came from (each a trajectory: its
    /// path as the manifest's patterns found it, its sha256).
    pub tables: Vec<(String, String)>,
    /// How the rows were held out of training, in words (none for an
    /// archived dataset, whose record does not say).
    pub split: Option<String>,
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
    /// The plan stage's per-episode table, if the run had one.
    pub planning: Option<PathBuf>,
    /// What the plan stage was asked, when it planned.
    pub plan_setup: Option<PlanSetup>,
    /// Whether the data come from a plant that departs from its scene:
    /// the simulator baselines are then its nominal model.
    pub plant: bool,
    /// Whether the replicates are folds of held-out trajectories (each
    /// tests its own rows), not re-draws of one split.
    pub folds: bool,
    /// The circuit stage's figures, if the run had them.
    pub circuit: Option<PathBuf>,
    /// The circuit stage's place-and-route figures, if the run had them.
    pub fpga: Option<PathBuf>,
    /// The circuit stage's fixed-point figures of a piecewise-linear
    /// model, if the run had them.
    pub fixed: Option<PathBuf>,
    /// Every replicate of the variant (the first is the one above), when
    /// the experiment runs more than one.
    pub replicates: Vec<Replicate>,
}

/// One replicate of a variant: its seed, its summaries, its closed-loop
/// figures and its plans.
pub struct Replicate {
    pub seed: u64,
    pub summary: PathBuf,
    pub comparisons: PathBuf,
    pub horizons: PathBuf,
    /// The test stage's timings of its models.
    pub timings: PathBuf,
    /// The plan stage's per-episode table, if the run had one.
    pub planning: Option<PathBuf>,
    /// Its tables of each round of the planner's own data, in order
    /// (`[plan] rounds`).
    pub rounds: Vec<PathBuf>,
}

/// One planning task, as the plan stage defines it.
pub struct PlanTask {
    pub name: String,
    /// What it asks and what a frame costs
    /// (`alnlab_plan::task::Task::describe`).
    pub definition: String,
    /// The unit of its cost (`rad²`).
    pub unit: String,
    /// The unit of a frame's error (`rad`) and the tolerance within which
    /// a frame counts as there.
    pub error_unit: String,
    pub tolerance: f64,
}

/// What the plan stage was asked, defined beside its figures.
pub struct PlanSetup {
    pub tasks: Vec<PlanTask>,
    /// Frames a plan looks ahead.
    pub horizon: u32,
    /// Frames per episode, one decision each.
    pub frames: u32,
    /// Episodes per task and replicate.
    pub episodes: u32,
    /// The feedback loops' natural frequencies (rad/s) their tuning chose among
    /// (none: no loop), and its tuning episodes per task.
    pub feedback_frequencies: Vec<f64>,
    pub tuning_episodes: u32,
}

/// One stage of a variant in the run.
pub struct StageTime {
    pub stage: String,
    pub cached: bool,
    pub wall_seconds: f64,
    pub compute_seconds: f64,
}

/// "3.81 µs (3.62–4.10)": a timing's median and range, to the precision
/// the range supports ([`format::timing`]).
pub(crate) trait Spread {
    fn spread(&self) -> String;

    /// The same without the unit, for a column that names it: "2.64
    /// (2.62–2.71)".
    fn spread_in_column(&self) -> String {
        self.spread().replace(" µs", "")
    }
}

impl Spread for Timing {
    fn spread(&self) -> String {
        format::timing(self.ns_per_state, self.ns_min, self.ns_max)
    }
}

/// Every replicate's runs of each timed path pooled into the first
/// replicate's rows: each replicate's test stage timed its models in
/// interleaved rounds of its own, minutes apart, so the pooled runs carry
/// the spread from one timing session to the next, not only within one.
/// Run k of every model still belongs to the same round of the same
/// replicate, so runs pair by position. A path some replicate lacks keeps
/// the runs the others have.
fn pool_timings(first: Vec<Timing>, others: &[Vec<Timing>]) -> Vec<Timing> {
    first
        .into_iter()
        .map(|mut t| {
            for other in others {
                if let Some(o) = other
                    .iter()
                    .find(|o| o.model == t.model && o.path == t.path && o.threads == t.threads)
                {
                    t.runs.extend_from_slice(&o.runs);
                    t.failed = t.failed.max(o.failed);
                }
            }
            if !t.runs.is_empty() {
                let mut sorted = t.runs.clone();
                sorted.sort_by(f64::total_cmp);
                t.ns_per_state = sorted[sorted.len() / 2];
                t.ns_min = sorted[0];
                t.ns_max = sorted[sorted.len() - 1];
            }
            t
        })
        .collect()
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
    /// The closed-loop errors from the held-out starts (all starts when
    /// none is held out).
    horizons: Vec<HorizonFigures>,
    timings: Vec<Timing>,
    /// Mean training errors per tree, per epoch (1-based).
    training: Vec<(f64, f64)>,
    hardware: Hardware,
    /// The synthesized circuit's figures, when the circuit stage measured
    /// them.
    circuit: Option<circuit::Measured>,
    /// Every variable placed and routed on an FPGA, when the circuit stage
    /// did it.
    fpga: Option<alnlab_circuit::routed::Routed>,
    /// A piecewise-linear model's outputs in fixed point, when the circuit
    /// stage measured them (empty otherwise).
    fixed: Vec<alnlab_circuit::piecewise::OutputFigures>,
    coverage: Coverage,
    /// Bytes the trees take in memory while training: two counters per
    /// internal node, a literal per leaf.
    tree_bytes: usize,
    /// The variables not learned, with the codebook's reason.
    not_learned: Vec<(String, String)>,
    /// What the model is and learns, in words.
    description: String,
    /// Whether the model is a hybrid: the nominal simulator's prediction,
    /// corrected (its time includes the simulator's step).
    hybrid: bool,
    /// The replicates' headline figures, when there are several.
    replicates: Vec<replicates::Figures>,
    /// Every replicate's plans, in replicate order (empty when the variant
    /// planned nothing).
    planning: Vec<Vec<Episode>>,
}

impl Loaded<'_> {
    /// The timing of `model` on evaluation `path` on one thread.
    fn timing(&self, model: ModelId, path: &str) -> Option<&Timing> {
        self.timings
            .iter()
            .find(|t| t.model == model && t.path == path && t.threads == 1)
    }

    /// Median ns per state of `model` on evaluation `path`, one thread.
    fn ns(&self, model: ModelId, path: &str) -> Option<f64> {
        self.timing(model, path).map(|t| t.ns_per_state)
    }

    /// The ALN one state at a time: the parsimonious path of a bit-forest,
    /// the binary search of a threshold model, a piecewise-linear model's
    /// plain path (its fastest).
    fn aln_single(&self) -> Option<&Timing> {
        self.timing(ModelId::Aln, "single")
            .or_else(|| self.timing(ModelId::Aln, "threshold-search"))
            .or_else(|| self.timing(ModelId::Aln, "pwl-plain"))
    }

    /// `model` one state at a time on one thread, where it was so timed:
    /// the ALN's path of [`Loaded::aln_single`], the robust linear fit's
    /// plain path, the simulator's frame by frame.
    fn single(&self, model: ModelId) -> Option<&Timing> {
        match model {
            ModelId::Aln => self.aln_single(),
            ModelId::Linear => self.timing(model, "pwl-plain"),
            _ => self.timing(model, "single"),
        }
    }

    /// `model` predicting every test state at once on one thread, where it
    /// was so timed (the simulator never is).
    fn all_at_once(&self, model: ModelId) -> Option<&Timing> {
        self.timing(model, "batched")
    }

    /// The ALN's batches on all threads, when there are more than one.
    fn aln_all_threads(&self) -> Option<&Timing> {
        self.timings
            .iter()
            .find(|t| t.model == ModelId::Aln && t.path == "batched" && t.threads > 1)
    }

    /// Whether the variant's models read the current accelerations (its
    /// `qdd` group is learned, so every model reads the frame's own): the
    /// torque being applied produces them, so a controller choosing that
    /// torque does not know them.
    fn reads_accelerations(&self) -> bool {
        self.summary.iter().any(|r| r.group == "qdd")
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
    fn compared(&self, against: ModelId, variable: Option<&str>) -> Option<&Interval> {
        aln_against(&self.comparisons, self.judged().1, against, variable)
    }

    /// How the ALN compares with `against` variable by variable on the
    /// judged rows: (lower, higher, indistinguishable, tied) error.
    fn verdict_counts(&self, against: ModelId) -> [usize; 4] {
        let (_, rows) = self.judged();
        let mut counts = [0; 4];
        for c in self.comparisons.iter().filter(|c| {
            c.rows == rows
                && c.model == ModelId::Aln
                && c.against == against
                && c.variable.is_some()
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
    /// AND/OR gates of all pruned trees.
    pruned_gates: u64,
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
            // Arithmetic, not gates: no estimate in gate delays.
            ModelKind::PiecewiseLinear => 0,
        }
    }
}

/// Renders the report into `dir` (created if need be): `report.md`, the
/// same as `report.html`, and their charts; returns the path of
/// `report.md`.
pub fn render(run: &RunInfo, dir: &Path) -> Result<PathBuf> {
    atomic::sweep_leftovers(dir)?;
    let mut variants: Vec<Loaded> = run.variants.iter().map(load).collect::<Result<_>>()?;
    one_timing_per_model(&mut variants);
    let shared = across::shares_baselines(&variants);
    let mut md = String::new();
    let _ = writeln!(md, "# {} — report\n", run.experiment);
    headline::first_screen(&mut md, run, &variants, dir)?;
    let _ = writeln!(
        md,
        "## Appendix\n\nThe figures above in detail: findings per variant, the experimenter's \
         notes, replicates, each variant's tables and charts, definitions and how to reproduce \
         the run.\n"
    );
    findings::findings(&mut md, run, &variants);
    across::charts(&mut md, &variants, shared, dir)?;
    across::side_by_side(&mut md, &variants, shared);
    replicates::section(&mut md, &variants, dir)?;
    let n = variants.len();
    let context = variant::Context {
        shared,
        compare_with_paper: run.compare_with_paper,
        histogram_variable: variant::histogram_variable(&variants),
        forest: fixed_point::routed_forest(&variants),
    };
    for (k, v) in variants.iter().enumerate() {
        variant::section(&mut md, v, (k, n), &context, dir)?;
        if let Some(rows) = v.planning.first() {
            let replicates = v.planning.len();
            plan::section(
                &mut md,
                rows,
                replicates,
                v.info.plan_setup.as_ref(),
                dir,
                |chart| variant::file_name(&v.info.name, chart),
            )?;
        }
    }
    glossary::section(&mut md, &variants);
    findings::definitions(&mut md);
    reproducibility(&mut md, run, &variants);
    let path = dir.join(REPORT_FILE);
    atomic::write_bytes(&path, md.as_bytes())?;
    remove_stale_charts(dir, &md)?;
    let title = format!("{} — report", run.experiment);
    atomic::write_bytes(
        &dir.join(html::HTML_FILE),
        html::page(&title, &md).as_bytes(),
    )?;
    Ok(path)
}

/// Whether variants `a` and `b` ran on the same test rows: persistence —
/// which learns nothing — errs the same on every variable they share.
fn same_rows(a: &Loaded, b: &Loaded) -> bool {
    let persistence = |v: &Loaded| -> Vec<(String, u64)> {
        v.judged()
            .0
            .iter()
            .filter(|r| r.model == ModelId::Persistence)
            .map(|r| (r.variable.clone(), r.stats.mean.to_bits()))
            .collect()
    };
    let (a, b) = (persistence(a), persistence(b));
    let common: Vec<&(String, u64)> = a.iter().filter(|x| b.iter().any(|y| y.0 == x.0)).collect();
    !common.is_empty() && common.iter().all(|x| b.contains(x))
}

/// Gives a model that several variants timed on the same rows one timing:
/// the first such variant's. Each variant's test stage times its own
/// baselines, so a simulator or a linear fit the variants share would
/// otherwise be quoted at as many speeds as there are variants. The
/// simulator re-steps the same frames whatever a variant learns, so it is
/// one model wherever the rows are the same; a fitted baseline only where
/// its errors are too (the same variables, to the bit). ALNs are each
/// variant's own.
fn one_timing_per_model(variants: &mut [Loaded]) {
    let same_model = |a: &Loaded, b: &Loaded, model: ModelId| {
        if model.is_simulator() {
            return same_rows(a, b);
        }
        let rows = |v: &Loaded| -> Vec<(String, u64)> {
            v.judged()
                .0
                .iter()
                .filter(|r| r.model == model)
                .map(|r| (r.variable.clone(), r.stats.mean.to_bits()))
                .collect()
        };
        let first = rows(a);
        !first.is_empty() && first == rows(b)
    };
    for k in 1..variants.len() {
        let (earlier, rest) = variants.split_at_mut(k);
        let later = &mut rest[0];
        let mut timings = std::mem::take(&mut later.timings);
        for t in timings.iter_mut().filter(|t| t.model != ModelId::Aln) {
            let first = earlier.iter().find_map(|e| {
                if !same_model(e, later, t.model) {
                    return None;
                }
                e.timings
                    .iter()
                    .find(|f| f.model == t.model && f.path == t.path && f.threads == t.threads)
            });
            if let Some(first) = first {
                *t = first.clone();
            }
        }
        later.timings = timings;
    }
}

/// Removes the charts in `dir` the report no longer shows (left by an
/// earlier rendering, or an earlier version's layout).
fn remove_stale_charts(dir: &Path, md: &str) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| alnlab_common::Error::io(dir, e))?;
    for entry in entries {
        let path = entry.map_err(|e| alnlab_common::Error::io(dir, e))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if name.ends_with(".svg") && !md.contains(&format!("]({name})")) {
            std::fs::remove_file(&path).map_err(|e| alnlab_common::Error::io(&path, e))?;
        }
    }
    Ok(())
}

/// A summary split into its rows over all test rows and over the held-out
/// ones, with the set findings judge: the held-out rows, or all when none
/// is held out.
pub(crate) fn split_rows(summary: Vec<SummaryRow>) -> (Vec<SummaryRow>, Vec<SummaryRow>, Rows) {
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
pub(crate) fn aln_against<'c>(
    comparisons: &'c [Comparison],
    rows: Rows,
    against: ModelId,
    variable: Option<&str>,
) -> Option<&'c Interval> {
    comparisons
        .iter()
        .find(|c| {
            c.rows == rows
                && c.model == ModelId::Aln
                && c.against == against
                && c.variable.as_deref() == variable
        })
        .map(|c| &c.difference)
}

fn load(info: &VariantInfo) -> Result<Loaded<'_>> {
    let (summary, held_out, judged) = split_rows(alnlab_summarize::read(&info.summary)?);
    let count = |rows: &[SummaryRow]| rows.first().map_or(0, |r| r.stats.n);
    let rows = (count(&summary), count(&held_out));
    let comparisons = alnlab_summarize::read_comparisons(&info.comparisons)?;
    let horizons = alnlab_summarize::read_horizons(&info.horizons)?;
    let horizons = horizons.into_iter().filter(|h| h.rows == judged).collect();
    let others = info
        .replicates
        .iter()
        .skip(1)
        .map(|r| alnlab_evaluate::timings::read(&r.timings))
        .collect::<Result<Vec<_>>>()?;
    let timings = pool_timings(alnlab_evaluate::timings::read(&info.timings)?, &others);
    let training = read_training(&info.training)?;

    let model = Model::read(&info.model)?;
    let pruned: Vec<_> = model.trees.iter().map(|(_, t)| t.prune()).collect();
    let depths: Vec<u32> = pruned.iter().map(|p| p.depth()).collect();
    let pruned_gates = pruned.iter().map(|p| p.gates() as u64).sum();
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
        pruned_gates,
        max_width,
        // A thermometer of w bits has w + 1 levels: ⌈log₂(w + 1)⌉ steps.
        levels_steps: (max_width + 1).next_power_of_two().trailing_zeros(),
    };
    let codebook = alnlab_tables::codebook::read(&info.codebook)?;
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
        ModelKind::BitForest | ModelKind::PiecewiseLinear => 0,
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
    let description = match model.header.model {
        ModelKind::PiecewiseLinear => describe_piecewise(&model),
        _ => describe(&model.header, model.trees.len(), coverage.leaves),
    };
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
    let planning = match &info.planning {
        Some(first) => std::iter::once(Some(first))
            .chain(info.replicates.iter().skip(1).map(|r| r.planning.as_ref()))
            .flatten()
            .zip(
                info.replicates
                    .iter()
                    .map(|r| r.rounds.as_slice())
                    .chain(std::iter::repeat(&[][..])),
            )
            .map(|(path, rounds)| {
                let mut episodes = alnlab_plan::planning::read(path)?;
                // Each round's plans as models of their own: `aln (round 1)`.
                for (r, path) in (1..).zip(rounds) {
                    let round = alnlab_plan::planning::read(path)?;
                    episodes.extend(
                        round
                            .into_iter()
                            .filter(|e| !e.planner.is_empty())
                            .map(|e| Episode { round: r, ..e }),
                    );
                }
                Ok(episodes)
            })
            .collect::<Result<_>>()?,
        None => Vec::new(),
    };
    Ok(Loaded {
        planning,
        replicates,
        description,
        hybrid: model.header.base == Base::Nominal,
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
        circuit: match &info.circuit {
            Some(path) => circuit::read(path)?,
            None => None,
        },
        fpga: match &info.fpga {
            Some(path) => alnlab_circuit::routed::read(path)?,
            None => None,
        },
        fixed: match &info.fixed {
            Some(path) => alnlab_circuit::fixed_point::read(path)?,
            None => Vec::new(),
        },
        coverage,
        tree_bytes,
    })
}

/// A bit model's mean training errors per tree, per epoch (1-based), from
/// `training.parquet`; none for a piecewise-linear model's rounds.
pub(crate) fn read_training(path: &Path) -> Result<Vec<(f64, f64)>> {
    let log = alnlab_train::log::read(path)?;
    Ok(log
        .mean_errors_per_epoch()
        .into_iter()
        .map(|(epoch, errors)| (f64::from(epoch), errors))
        .collect())
}

/// What a model is and learns, in a sentence: its kind and trees, its
/// target (with the range of k and the code of a residual target), and
/// which inputs its outputs read.
fn describe(header: &Header, trees: usize, leaves: usize) -> String {
    let kind = match header.model {
        ModelKind::BitForest => "a bit-forest",
        ModelKind::Threshold => "a threshold-predicate model (§6)",
        ModelKind::PiecewiseLinear => "a piecewise-linear ALN",
    };
    let mut text = format!("{kind} of {trees} trees of {leaves} leaves");
    if header.vote > 1 {
        let _ = write!(text, ", {} voting per output", header.vote);
    }
    match &header.target {
        Target::Level => text.push_str("; it learns each variable's next level"),
        Target::Change => {}
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

/// What a piecewise-linear model is, in a sentence: its trees, their
/// pieces and MIN/MAX nodes, what they learn and read — for a hybrid, the
/// correction of the nominal simulator's prediction.
fn describe_piecewise(model: &Model) -> String {
    let pieces: Vec<usize> = model.pieces.iter().map(|t| t.pieces()).collect();
    let (mins, maxes) = model
        .pieces
        .iter()
        .map(|t| t.operators())
        .fold((0, 0), |(a, b), (m, x)| (a + m, b + x));
    let most = model.header.reads.iter().map(Vec::len).max().unwrap_or(0);
    let (what, from, variables) = match model.header.base {
        Base::Current => (
            "its variable's change of real value",
            "the current state's real values",
            model.header.inputs,
        ),
        Base::Nominal => (
            "the change from the nominal simulator's prediction of its variable (the scene as \
             written, stepped one frame) to the next real value",
            "the current state's real values and the nominal simulator's predictions",
            model.header.inputs / 2,
        ),
    };
    format!(
        "a piecewise-linear ALN{}: {} MIN/MAX trees over {} affine pieces in all (from {} to {} \
         a tree; {mins} MIN and {maxes} MAX nodes); each learns {what} in level spacings from \
         at most {most} of {from}{}",
        match model.header.base {
            Base::Current => "",
            Base::Nominal => " hybrid",
        },
        pieces.len(),
        pieces.iter().sum::<usize>(),
        pieces.iter().min().unwrap_or(&0),
        pieces.iter().max().unwrap_or(&0),
        if model.header.outputs.len() < variables {
            "; the controls (torques or efforts) are given, not predicted"
        } else {
            ""
        }
    )
}

/// (mean, 95th percentile) of a model's errors, averaged over the variables.
pub(crate) fn overall(summary: &[SummaryRow], model: ModelId) -> Option<(f64, f64)> {
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
fn baseline_models(summary: &[SummaryRow]) -> Vec<ModelId> {
    let mut models: Vec<ModelId> = summary
        .iter()
        .map(|r| r.model)
        .filter(|&m| m != ModelId::Aln)
        .collect();
    models.dedup();
    models
}

/// The mean error of `model` for `variable`.
fn mean_of(summary: &[SummaryRow], model: ModelId, variable: &str) -> Option<f64> {
    summary
        .iter()
        .find(|r| r.model == model && r.variable == variable)
        .map(|r| r.stats.mean)
}

/// A model's normalized error averaged over the variables: each
/// variable's mean error over the standard deviation of its true levels
/// (variables whose truth does not vary are left out).
fn normalized(summary: &[SummaryRow], model: ModelId) -> Option<f64> {
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
        .filter(|r| r.model == ModelId::Aln)
        .filter_map(|r| {
            let persistence = mean_of(judged, ModelId::Persistence, &r.variable)?;
            let d = v.compared(ModelId::Persistence, Some(&r.variable))?;
            (d.verdict() == Verdict::Higher).then_some((
                r.variable.as_str(),
                r.stats.mean,
                persistence,
                d,
            ))
        })
        .collect()
}

/// How the run was made: manifest, seeds, versions, machine, and every
/// stage's time.
fn reproducibility(md: &mut String, run: &RunInfo, variants: &[Loaded]) {
    let machine = variants
        .iter()
        .flat_map(|v| v.timings.first())
        .map(|t| {
            let cpu = if t.cpu.trim().is_empty() {
                "CPU model not reported"
            } else {
                t.cpu.trim()
            };
            format!("{cpu}, {} cores", t.cores)
        })
        .next()
        .unwrap_or_else(|| "—".into());
    let _ = writeln!(md, "## Reproducibility\n");
    let mut table = MdTable::new(&["what"]).column("", Align::Left);
    let mut add = |what: &str, value: String| table.row(vec![what.into(), value]);
    add("manifest", format!("`{}`", run.manifest_path));
    add("manifest sha256", format!("`{}`", run.manifest_sha256));
    if let Some((dataset, sha256)) = &run.dataset {
        add("dataset", format!("{dataset} (sha256 `{sha256}`)"));
    }
    if let Some((recording, sha256, topic)) = &run.recording {
        add(
            "recording",
            format!("`{recording}`, topic `{topic}` (sha256 `{sha256}`)"),
        );
    }
    for (file, sha256) in &run.tables {
        add("table", format!("`{file}` (sha256 `{sha256}`)"));
    }
    if let Some(split) = &run.split {
        add("split", split.clone());
    }
    add("seed", run.seed.to_string());
    if let Some(v) = variants.first().filter(|v| v.info.replicates.len() > 1) {
        let seeds: Vec<String> = v
            .info
            .replicates
            .iter()
            .map(|r| r.seed.to_string())
            .collect();
        add(
            "replicates",
            format!("{} (seeds {})", seeds.len(), seeds.join(", ")),
        );
    }
    add("alnlab", run.alnlab_version.clone());
    let commit = run
        .git_commit
        .as_deref()
        .unwrap_or("(not in a git checkout)");
    add(
        "git commit",
        if run.git_changes.is_empty() {
            format!("`{commit}`")
        } else {
            format!(
                "`{commit}`, with uncommitted changes to {} path{}: {}",
                run.git_changes.len(),
                if run.git_changes.len() == 1 { "" } else { "s" },
                run.git_changes
                    .iter()
                    .take(10)
                    .map(|p| format!("`{p}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
                    + if run.git_changes.len() > 10 {
                        ", …"
                    } else {
                        ""
                    }
            )
        },
    );
    add("machine", machine);
    add("started", run.started.clone());
    add("wall time", format!("{} s", format::sig3(run.wall_seconds)));
    table.write(md);
    let _ = writeln!(
        md,
        "Stage times of this run (first replicate): wall time in this run (a cached stage only \
         looked up), and compute time when the artifact was made.\n"
    );
    let mut table = MdTable::new(&["variant", "stage"])
        .column("cached", Align::Left)
        .numbers(&["wall (s)", "compute when made (s)"]);
    for v in variants {
        for s in &v.info.stages {
            table.row(vec![
                format!("`{}`", v.info.name),
                s.stage.clone(),
                if s.cached { "yes" } else { "no" }.into(),
                format::sig3(s.wall_seconds),
                format::sig3(s.compute_seconds),
            ]);
        }
    }
    table.write(md);
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
                r.model == ModelId::Aln
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

#[cfg(test)]
mod tests {
    use super::*;

    fn timed(model: ModelId, path: &str, runs: &[f64]) -> Timing {
        Timing {
            model,
            path: path.into(),
            ns_per_state: f64::NAN,
            ns_min: f64::NAN,
            ns_max: f64::NAN,
            runs: runs.to_vec(),
            states: 10,
            threads: 1,
            failed: 0,
            cores: 2,
            cpu: "cpu".into(),
        }
    }

    /// Replicates' runs join the first replicate's, in replicate order, and
    /// the median and range are of them all.
    #[test]
    fn timings_pool_across_replicates() {
        let first = vec![timed(ModelId::Aln, "batched", &[1.0, 2.0, 3.0])];
        let others = vec![
            vec![timed(ModelId::Aln, "batched", &[10.0, 11.0, 12.0])],
            vec![
                timed(ModelId::Aln, "single", &[99.0]),
                timed(ModelId::Aln, "batched", &[0.5]),
            ],
        ];
        let pooled = pool_timings(first, &others);
        assert_eq!(pooled.len(), 1);
        let t = &pooled[0];
        assert_eq!(t.runs, [1.0, 2.0, 3.0, 10.0, 11.0, 12.0, 0.5]);
        assert_eq!((t.ns_min, t.ns_per_state, t.ns_max), (0.5, 3.0, 12.0));
    }
}
