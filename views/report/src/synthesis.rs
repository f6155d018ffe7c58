//! The answer across reports. Each report writes `frontier.csv` beside
//! itself: every model of its first screen with its mean error (and its
//! interval across replicates), persistence's on the same rows, and its time
//! per state on one thread, one at a time and all at once — the figures of
//! the results table, unrounded. [`render_synthesis`] reads every report's
//! file and draws one chart across experiments: each ALN and each simulator
//! setting, error relative to persistence's against time.

use alnlab_common::ModelId;
use std::path::{Path, PathBuf};

use alnlab_common::{Error, Result, atomic};
use serde::{Deserialize, Serialize};

use super::charts::{self, Axis, Marker, Plot, Point, Rule, Series, Style, style_of};

/// File name of a report's frontier table.
pub const FRONTIER: &str = "frontier.csv";

/// File name of the chart across reports.
pub const SYNTHESIS: &str = "synthesis.svg";

/// One first-screen model of a report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrontierRow {
    pub model: ModelId,
    /// The variant it belongs to (a baseline: the best ALN's variant).
    pub variant: String,
    pub variables: usize,
    /// Mean error in levels over the variables, on the judged rows; with
    /// its 95% interval across replicates where there are several.
    pub error: f64,
    pub error_low: Option<f64>,
    pub error_high: Option<f64>,
    /// Persistence's mean error on the same rows and variables.
    pub persistence: Option<f64>,
    /// µs per state on one thread, one at a time: median, fastest, slowest.
    pub one_at_a_time_us: Option<f64>,
    pub one_at_a_time_min_us: Option<f64>,
    pub one_at_a_time_max_us: Option<f64>,
    /// µs per state on one thread, every test state at once.
    pub all_at_once_us: Option<f64>,
    pub all_at_once_min_us: Option<f64>,
    pub all_at_once_max_us: Option<f64>,
}

/// Writes `rows` as `dir/frontier.csv`.
pub(super) fn write_frontier(dir: &Path, rows: &[FrontierRow]) -> Result<()> {
    let mut writer = csv::Writer::from_writer(Vec::new());
    for row in rows {
        writer
            .serialize(row)
            .map_err(|e| Error::Invalid(format!("{FRONTIER}: {e}")))?;
    }
    let bytes = writer
        .into_inner()
        .map_err(|e| Error::Invalid(format!("{FRONTIER}: {e}")))?;
    atomic::write_bytes(&dir.join(FRONTIER), &bytes)
}

/// Reads a report's `frontier.csv`.
pub fn read_frontier(path: &Path) -> Result<Vec<FrontierRow>> {
    let mut reader = csv::Reader::from_path(path).map_err(|e| Error::bad_file(path, e))?;
    reader
        .deserialize()
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| Error::bad_file(path, e))
}

/// Draws `<reports>/synthesis.svg` from every `<reports>/<name>/frontier.csv`
/// (reports in name order): per report, its best ALN, its best hybrid
/// (`…+nominal`, a triangle) where it has one, and its simulator settings
/// (joined, fewest steps first, hollow; one line for reports on the same
/// data), each by its mean error over persistence's on the same rows
/// against its µs per state one at a time. A report's colour is its own
/// throughout, and its marker on its ALN and its simulator line. Returns the chart's path and
/// the reports drawn.
pub fn render_synthesis(reports: &Path) -> Result<(PathBuf, Vec<String>)> {
    let mut found: Vec<(String, PathBuf)> = std::fs::read_dir(reports)
        .map_err(|e| Error::io(reports, e))?
        .filter_map(|entry| {
            let dir = entry.ok()?.path();
            let frontier = dir.join(FRONTIER);
            let name = dir.file_name()?.to_str()?.to_string();
            frontier.is_file().then_some((name, frontier))
        })
        .collect();
    found.sort();
    if found.is_empty() {
        return Err(Error::Invalid(format!(
            "{}: no report holds a {FRONTIER} (render the reports first)",
            reports.display()
        )));
    }
    let mut series = Vec::new();
    let mut simulator_lines: Vec<(Vec<String>, Vec<Point>)> = Vec::new();
    let mut simulator_series: Vec<(String, Style)> = Vec::new();
    for (k, (name, path)) in found.iter().enumerate() {
        let rows = read_frontier(path)?;
        let point = |r: &FrontierRow| -> Option<Point> {
            let ratio = r.error / r.persistence?;
            Some(Point {
                x: r.one_at_a_time_us?,
                y: ratio,
                x_range: r.one_at_a_time_min_us.zip(r.one_at_a_time_max_us),
                y_range: None,
            })
        };
        // Past the palette's colours, the marker tells reports apart.
        let Style {
            colour,
            marker: aln_marker,
            ..
        } = style_of(ModelId::Aln, k);
        // The lowest error over persistence's among the rows `keep` picks.
        let best = |keep: &dyn Fn(&FrontierRow) -> bool| {
            rows.iter()
                .filter(|r| keep(r))
                .filter_map(|r| Some((r, point(r)?)))
                .min_by(|a, b| a.1.y.total_cmp(&b.1.y))
        };
        let single = |name: String, marker, point| Series {
            name,
            style: Style {
                colour,
                marker,
                dashed: false,
            },
            points: vec![point],
            joined: false,
            hollow: false,
        };
        // The report's best ALN, and its best hybrid (the nominal simulator
        // corrected) where it has one: the model to beat on a plant.
        if let Some((row, p)) = best(&|r| r.model == ModelId::Aln) {
            series.push(single(
                format!("{name}: ALN `{}`", row.variant),
                aln_marker,
                p,
            ));
        }
        if let Some((row, p)) = best(&|r| r.model.is_hybrid()) {
            series.push(single(
                format!("{name}: {} (hybrid)", row.model),
                Marker::Triangle,
                p,
            ));
        }
        let mut simulators: Vec<(u64, Point)> = rows
            .iter()
            .filter_map(|r| Some((r.model.simulator_steps()?, point(r)?)))
            .collect();
        simulators.sort_by_key(|&(steps, _)| steps);
        if simulators.is_empty() {
            continue;
        }
        let points: Vec<Point> = simulators.iter().map(|(_, p)| *p).collect();
        // Reports on the same data (one cached simulation and test stage)
        // share one simulator line, named after all of them.
        if let Some(same) = simulator_lines
            .iter_mut()
            .find(|(_, drawn): &&mut (Vec<String>, Vec<Point>)| *drawn == points)
        {
            same.0.push(name.clone());
            continue;
        }
        simulator_lines.push((vec![name.clone()], points));
        let steps: Vec<String> = simulators.iter().map(|(s, _)| s.to_string()).collect();
        simulator_series.push((
            steps.join(","),
            // The report's own colour and marker, hollow and dashed: past
            // the palette, two reports' lines differ by marker.
            Style {
                colour,
                marker: aln_marker,
                dashed: true,
            },
        ));
    }
    for ((names, points), (steps, style)) in simulator_lines.into_iter().zip(simulator_series) {
        series.push(Series {
            name: format!("{}: simulator@{steps}/frame", names.join(", ")),
            style,
            points,
            joined: true,
            hollow: true,
        });
    }
    let svg = charts::plot(&Plot {
        title: "every report: error against speed, one state at a time".into(),
        x: Axis::log("µs per state, one at a time, one thread (log)"),
        y: Axis::linear("mean error ÷ persistence's (below 1: better than no change)"),
        series,
        pareto: false,
        rules: vec![Rule::horizontal(1.0, "persistence (no change)")],
    });
    let out = reports.join(SYNTHESIS);
    atomic::write_bytes(&out, svg.as_bytes())?;
    Ok((out, found.into_iter().map(|(name, _)| name).collect()))
}
