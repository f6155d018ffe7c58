//! `alnlab runs …`: list, show and compare recorded runs, as aligned text,
//! Markdown, CSV or JSON.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use alnlab_common::{Error, Result};
use alnlab_report::format::sig3;
use clap::{Args, Subcommand};
use serde_json::json;

use crate::records::{self, Stored};
use alnlab_report::metrics;

use crate::runs::{self, Diff, Figure, Filter, HEADLINE, MetricChange, VariantRun};

/// The `alnlab runs` arguments: a subcommand, or `list`'s arguments.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct RunsArgs {
    /// The output folder the runs were made in (`alnlab run --out`).
    #[arg(long, default_value = "runs", global = true)]
    pub out: PathBuf,
    #[command(subcommand)]
    pub command: Option<RunsCommand>,
    #[command(flatten)]
    pub list: ListArgs,
}

/// The `alnlab runs` subcommands.
#[derive(Debug, Subcommand)]
pub enum RunsCommand {
    /// Every recorded run, one line per variant: id, experiment, start,
    /// commit, replicates, headline metrics (with 95% intervals across
    /// replicates), and how much of it the cache still holds.
    #[command(after_help = "Examples:
  alnlab runs
  alnlab runs list --experiment quickstart --where quantize.code=gray
  alnlab runs list --json > runs.json
  alnlab runs list --csv --out /scratch/runs")]
    List(ListArgs),
    /// One run's parameters (fully resolved, per variant), metrics and
    /// artifacts.
    #[command(after_help = "Examples:
  alnlab runs show quickstart            # the experiment's latest run
  alnlab runs show 20261123-152818-0ef52a:gray
  alnlab runs show quickstart~1 --json   # the run before the latest")]
    Show {
        /// The run: an id (or a unique prefix), an experiment's name (its
        /// latest run) or NAME~N (N runs before it), optionally :VARIANT.
        run: String,
        /// The record (with the artifacts the cache still holds) as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Two runs (or variants) compared: the parameters that differ, then
    /// every metric side by side with its change — and, where both have
    /// replicates, whether each mean lies outside the other's 95% interval.
    #[command(after_help = "Examples:
  alnlab runs diff quickstart~1 quickstart          # the last two runs, variant by variant
  alnlab runs diff quickstart:walk quickstart:gray  # two variants of one run
  alnlab runs diff 20261122-0931 20261123-1528 --only-changed --json")]
    Diff {
        /// Run A, as for `show` (optionally :VARIANT).
        a: String,
        /// Run B.
        b: String,
        /// Show only the metrics that changed.
        #[arg(long)]
        only_changed: bool,
        /// Also compare each variable's mean error
        /// (`error_by_variable/<model>/<variable>`), not only the headline.
        #[arg(long)]
        variables: bool,
        /// The comparison as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// What `runs list` shows, and how.
#[derive(Debug, Args)]
pub struct ListArgs {
    /// Only runs of this experiment.
    #[arg(long)]
    pub experiment: Option<String>,
    /// Only variants with this parameter value (repeatable; dotted keys as
    /// `runs show` lists them; numbers compare as numbers).
    #[arg(long = "where", value_name = "KEY=VALUE")]
    pub filters: Vec<Filter>,
    /// As JSON: one object per run, its variants and their metrics.
    #[arg(long, conflicts_with_all = ["csv", "md"])]
    pub json: bool,
    /// As CSV, one row per variant.
    #[arg(long, conflicts_with = "md")]
    pub csv: bool,
    /// As a Markdown table.
    #[arg(long)]
    pub md: bool,
}

/// Runs one `alnlab runs` command.
pub fn execute(args: RunsArgs) -> Result<()> {
    let out = args.out;
    match args.command.unwrap_or(RunsCommand::List(args.list)) {
        RunsCommand::List(list) => list_runs(&out, &list),
        RunsCommand::Show { run, json } => show(&out, &run, json),
        RunsCommand::Diff {
            a,
            b,
            only_changed,
            variables,
            json,
        } => {
            let shown = Shown {
                only_changed,
                variables,
            };
            diff(&out, &a, &b, shown, json)
        }
    }
}

/// Reads every record under `out`, naming on stderr the files it skips.
fn read_all(out: &Path) -> Result<Vec<Stored>> {
    let (runs, damaged) = records::all(out, records::Spelling::Cli)?;
    for (_, error) in damaged {
        eprintln!("warning: skipped {error}");
    }
    Ok(runs)
}

/// `alnlab runs list`.
fn list_runs(out: &Path, args: &ListArgs) -> Result<()> {
    let runs = read_all(out)?;
    let variants = runs::list(out, &runs, args.experiment.as_deref(), &args.filters);
    if args.json {
        let mut by_run: Vec<serde_json::Value> = Vec::new();
        for stored in &runs {
            let mine: Vec<serde_json::Value> = variants
                .iter()
                .filter(|v| std::ptr::eq(v.run, &stored.record))
                .map(|v| variant_json(out, v))
                .collect();
            if !mine.is_empty() {
                let r = &stored.record;
                by_run.push(json!({
                    "id": r.id,
                    "experiment": r.experiment,
                    "started": r.started,
                    "finished": r.finished,
                    "git_commit": r.git_commit,
                    "manifest": r.manifest_path,
                    "manifest_sha256": r.manifest_sha256,
                    "seed": r.seed,
                    "record": stored.path,
                    "format": r.format,
                    "variants": mine,
                }));
            }
        }
        println!("{}", serde_json::to_string_pretty(&by_run).expect("JSON"));
        return Ok(());
    }
    let mut table = TextTable::new(&[
        "run",
        "experiment",
        "started",
        "commit",
        "variant",
        "replicates",
        "rows",
        "error aln",
        "error persistence",
        "error linear",
        "aln ns/state batched",
        "aln ns/state single",
        "cached files",
    ]);
    for v in &variants {
        let (present, total) = v.cached(out);
        let mut row = vec![
            v.run.id.clone(),
            v.run.experiment.clone(),
            v.run.started.clone(),
            v.run
                .git_commit
                .as_deref()
                .map_or("—".into(), |c| c[..c.len().min(10)].to_string()),
            v.name.to_string(),
            v.replicates.len().to_string(),
            v.rows().unwrap_or("—").to_string(),
        ];
        for name in HEADLINE {
            row.push(match v.figure(name) {
                Some(f) if args.csv => f.mean.to_string(),
                Some(f) => figure_text(&f),
                None => "—".into(),
            });
        }
        row.push(format!("{present}/{total}"));
        table.row(row);
    }
    if args.csv {
        print!("{}", table.csv()?);
    } else if args.md {
        print!("{}", table.markdown());
    } else if variants.is_empty() {
        println!("no runs recorded under {}", out.display());
    } else {
        print!("{}", table.plain());
    }
    Ok(())
}

/// One variant of `runs list --json`.
fn variant_json(out: &Path, v: &VariantRun) -> serde_json::Value {
    let (present, total) = v.cached(out);
    let metrics: serde_json::Map<String, serde_json::Value> = v
        .figure_names()
        .into_iter()
        .filter_map(|name| Some((name.to_string(), json!(v.figure(name)?))))
        .collect();
    json!({
        "name": v.name,
        "replicates": v.replicates.len(),
        "rows": v.rows(),
        "cached_files": present,
        "files": total,
        "metrics": metrics,
    })
}

/// "0.545", or "0.545 [0.530, 0.560]" across replicates.
fn figure_text(f: &Figure) -> String {
    match (f.low, f.high) {
        (Some(low), Some(high)) => alnlab_report::format::estimate(f.mean, low, high),
        _ => sig3(f.mean),
    }
}

/// Three significant figures with a sign: "+0.0206", "-0.149".
fn signed(x: f64) -> String {
    let text = sig3(x);
    if x > 0.0 { format!("+{text}") } else { text }
}

/// `alnlab runs show`.
fn show(out: &Path, reference: &str, as_json: bool) -> Result<()> {
    let (stored, variant) = records::find(out, reference, records::Spelling::Cli)?;
    let record = &stored.record;
    let variants: Vec<VariantRun> = match &variant {
        Some(name) => vec![VariantRun::of(out, record, name)],
        None => VariantRun::all(out, record),
    };
    if as_json {
        let mut value = serde_json::to_value(record).expect("records serialize");
        value["record"] = json!(stored.path);
        value["artifacts_in_cache"] = json!(
            record
                .variants
                .iter()
                .map(|v| {
                    let present: serde_json::Map<String, serde_json::Value> = v
                        .artifacts
                        .iter()
                        .map(|(role, a)| (role.clone(), json!(records::locate(out, a))))
                        .collect();
                    json!({ "variant": v.name, "replicate": v.replicate, "files": present })
                })
                .collect::<Vec<_>>()
        );
        println!("{}", serde_json::to_string_pretty(&value).expect("JSON"));
        return Ok(());
    }
    let mut text = String::new();
    let _ = writeln!(text, "run        {}", record.id);
    let _ = writeln!(text, "experiment {}", record.experiment);
    let _ = writeln!(
        text,
        "manifest   {} (sha256 {})",
        record.manifest_path, record.manifest_sha256
    );
    let _ = writeln!(
        text,
        "commit     {}",
        record
            .git_commit
            .as_deref()
            .unwrap_or("— (not a git checkout)")
    );
    let _ = writeln!(
        text,
        "started    {}  ({:.1} s)",
        record.started, record.wall_seconds
    );
    let _ = writeln!(
        text,
        "record     {} (format {})",
        stored.path.display(),
        record.format
    );
    if let Some(d) = &record.dataset {
        let _ = writeln!(text, "dataset    {} (sha256 {})", d.dataset, d.sha256);
    }
    for v in &variants {
        let _ = writeln!(
            text,
            "\n## variant {} — {} replicate{}, figures over the {} rows",
            v.name,
            v.replicates.len(),
            if v.replicates.len() == 1 { "" } else { "s" },
            v.rows().unwrap_or("(no metrics)")
        );
        let parameters = v.parameters();
        if parameters.is_empty() {
            let _ = writeln!(text, "\nparameters: not recorded (a format-1 record)");
        } else {
            let mut table = TextTable::new(&["parameter", "value"]);
            for (k, value) in parameters {
                table.row(vec![k.clone(), value.clone()]);
            }
            let _ = write!(text, "\n{}", table.plain());
        }
        let mut table = TextTable::new(&["metric", "value"]);
        for name in v.figure_names() {
            if let Some(f) = v.figure(name) {
                table.row(vec![name.to_string(), figure_text(&f)]);
            }
        }
        let _ = write!(text, "\n{}", table.plain());
        let mut table = TextTable::new(&["replicate", "seed", "artifact", "in cache", "sha256"]);
        for r in &v.replicates {
            for (role, a) in &r.artifacts {
                let here = records::locate(out, a);
                table.row(vec![
                    (r.replicate + 1).to_string(),
                    r.seed.to_string(),
                    role.clone(),
                    here.map_or("no".into(), |p| p.display().to_string()),
                    a.sha256[..12].to_string(),
                ]);
            }
        }
        let _ = write!(text, "\n{}", table.plain());
    }
    print!("{text}");
    Ok(())
}

/// Which metrics `runs diff` shows.
#[derive(Clone, Copy)]
struct Shown {
    only_changed: bool,
    variables: bool,
}

impl Shown {
    /// Whether `m` is shown.
    fn admits(self, m: &MetricChange) -> bool {
        (!self.only_changed || m.changed())
            && (self.variables || !m.name.starts_with(metrics::BY_VARIABLE))
    }
}

/// `alnlab runs diff`.
fn diff(out: &Path, a: &str, b: &str, shown: Shown, as_json: bool) -> Result<()> {
    let (sa, va) = records::find(out, a, records::Spelling::Cli)?;
    let (sb, vb) = records::find(out, b, records::Spelling::Cli)?;
    let pairs = runs::pairs(
        out,
        (&sa.record, va.as_deref()),
        (&sb.record, vb.as_deref()),
    )?;
    let diffs: Vec<(&VariantRun, &VariantRun, Diff)> = pairs
        .iter()
        .map(|(x, y)| (x, y, runs::diff(x, y)))
        .collect();
    if as_json {
        let value: Vec<serde_json::Value> = diffs
            .iter()
            .map(|(x, y, d)| {
                let metrics: Vec<_> = d.metrics.iter().filter(|m| shown.admits(m)).collect();
                json!({
                    "a": { "run": x.run.id, "experiment": x.run.experiment, "variant": x.name },
                    "b": { "run": y.run.id, "experiment": y.run.experiment, "variant": y.name },
                    "parameters": d.parameters,
                    "parameters_compared": d.parameters_compared,
                    "metrics": metrics,
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&value).expect("JSON"));
        return Ok(());
    }
    let mut text = String::new();
    for (x, y, d) in &diffs {
        let side = |v: &VariantRun| {
            format!(
                "{}:{} ({}, {}, {} replicate{})",
                v.run.id,
                v.name,
                v.run.experiment,
                v.run.started,
                v.replicates.len(),
                if v.replicates.len() == 1 { "" } else { "s" }
            )
        };
        let _ = writeln!(text, "A: {}\nB: {}\n", side(x), side(y));
        if x.parameters().is_empty() || y.parameters().is_empty() {
            let _ = writeln!(
                text,
                "parameters: not recorded on one side (a format-1 record); not compared\n"
            );
        } else if d.parameters.is_empty() {
            let _ = writeln!(text, "parameters: all {} the same\n", d.parameters_compared);
        } else {
            let _ = writeln!(
                text,
                "parameters that differ ({} of {}):",
                d.parameters.len(),
                d.parameters_compared
            );
            let mut table = TextTable::new(&["parameter", "A", "B"]);
            for p in &d.parameters {
                let or_unset = |v: &Option<String>| v.clone().unwrap_or_else(|| "(unset)".into());
                table.row(vec![p.key.clone(), or_unset(&p.a), or_unset(&p.b)]);
            }
            let _ = writeln!(text, "{}", table.plain());
        }
        let with_intervals = x.replicates.len() > 1 && y.replicates.len() > 1;
        let mut headers = vec!["metric", "A", "B", "change"];
        if with_intervals {
            headers.push("outside both 95% intervals");
        }
        let mut table = TextTable::new(&headers);
        let admitted: Vec<_> = d.metrics.iter().filter(|m| shown.admits(m)).collect();
        for m in &admitted {
            let cell = |f: &Option<Figure>| f.as_ref().map_or("—".into(), figure_text);
            let change = match (m.change, m.relative) {
                (Some(c), Some(r)) if c != 0.0 => format!("{} ({:+.1}%)", signed(c), 100.0 * r),
                (Some(c), _) if c != 0.0 => signed(c),
                (Some(_), _) => "0".into(),
                (None, _) => "—".into(),
            };
            let mut row = vec![m.name.clone(), cell(&m.a), cell(&m.b), change];
            if with_intervals {
                row.push(match m.outside_both_intervals {
                    Some(true) => "yes".into(),
                    Some(false) => "no".into(),
                    None => "—".into(),
                });
            }
            table.row(row);
        }
        let what = match (shown.only_changed, shown.variables) {
            (true, true) => "changed, variables included",
            (true, false) => "changed, without per-variable errors (--variables)",
            (false, true) => "variables included",
            (false, false) => "without per-variable errors (--variables)",
        };
        if admitted.is_empty() {
            let _ = writeln!(text, "metrics: none changed\n");
        } else {
            let _ = writeln!(
                text,
                "metrics ({} of {}: {what}; change is B − A):",
                admitted.len(),
                d.metrics.len(),
            );
            let _ = writeln!(text, "{}", table.plain());
        }
    }
    print!("{text}");
    Ok(())
}

/// A table printed as aligned text, Markdown or CSV.
struct TextTable {
    headers: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl TextTable {
    fn new(headers: &[&str]) -> TextTable {
        TextTable {
            headers: headers.iter().map(|h| h.to_string()).collect(),
            rows: Vec::new(),
        }
    }

    fn row(&mut self, cells: Vec<String>) {
        debug_assert_eq!(cells.len(), self.headers.len());
        self.rows.push(cells);
    }

    /// Whether column `c` holds numbers (then right-aligned).
    fn numeric(&self, c: usize) -> bool {
        !self.rows.is_empty()
            && self.rows.iter().all(|r| {
                let cell = r[c].split(' ').next().unwrap_or("");
                cell == "—" || cell.trim_start_matches(['+', '-']).parse::<f64>().is_ok()
            })
    }

    fn plain(&self) -> String {
        let widths: Vec<usize> = (0..self.headers.len())
            .map(|c| {
                std::iter::once(&self.headers[c])
                    .chain(self.rows.iter().map(|r| &r[c]))
                    .map(|s| s.chars().count())
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        let numeric: Vec<bool> = (0..self.headers.len()).map(|c| self.numeric(c)).collect();
        let mut text = String::new();
        for row in std::iter::once(&self.headers).chain(&self.rows) {
            let cells: Vec<String> = row
                .iter()
                .enumerate()
                .map(|(c, s)| {
                    let pad = widths[c] - s.chars().count();
                    if numeric[c] {
                        format!("{}{s}", " ".repeat(pad))
                    } else {
                        format!("{s}{}", " ".repeat(pad))
                    }
                })
                .collect();
            let _ = writeln!(text, "{}", cells.join("  ").trim_end());
        }
        text
    }

    fn markdown(&self) -> String {
        let escape = |s: &String| s.replace('|', "\\|");
        let mut text = format!(
            "| {} |\n|",
            self.headers
                .iter()
                .map(escape)
                .collect::<Vec<_>>()
                .join(" | ")
        );
        for c in 0..self.headers.len() {
            text.push_str(if self.numeric(c) { "---:|" } else { "---|" });
        }
        text.push('\n');
        for row in &self.rows {
            let _ = writeln!(
                text,
                "| {} |",
                row.iter().map(escape).collect::<Vec<_>>().join(" | ")
            );
        }
        text
    }

    fn csv(&self) -> Result<String> {
        let mut writer = csv::Writer::from_writer(Vec::new());
        let fail = |e: csv::Error| Error::Invalid(format!("CSV: {e}"));
        writer.write_record(&self.headers).map_err(fail)?;
        for row in &self.rows {
            writer.write_record(row).map_err(fail)?;
        }
        let bytes = writer
            .into_inner()
            .map_err(|e| Error::Invalid(format!("CSV: {e}")))?;
        Ok(String::from_utf8(bytes).expect("CSV of UTF-8 cells is UTF-8"))
    }
}
