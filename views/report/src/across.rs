//! The report's view across variants: one chart each for closed-loop error
//! against horizon, speed against error (with its Pareto front) and
//! training, every variant's ALN on it (and the baselines once, when the
//! variants share their test rows); then the side-by-side tables and the
//! baselines' table, given once rather than per variant.

use alnlab_common::ModelId;
use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{Result, atomic};

use super::format::{Align, MdTable, interval, sig3};
use super::{
    Loaded, Spread, Timing, baseline_models, closed_loop, normalized, overall,
    worse_than_persistence,
};
use crate::charts::{self, Axis, Marker, Plot, Point, Series, Style, style_of};
use alnlab_summarize::paired::Interval;

/// The chart files this section writes.
pub(super) const CLOSED_LOOP: &str = "closed-loop.svg";
pub(super) const SPEED: &str = "speed.svg";
pub(super) const TRAINING: &str = "training.svg";

/// Whether the variants' baselines are the same — they ran on the same
/// test rows — so the baselines are given once, and errors in levels compare
/// across variants.
pub(super) fn shares_baselines(variants: &[Loaded]) -> bool {
    let baselines = |v: &Loaded| -> Vec<(ModelId, String, u64)> {
        v.judged()
            .0
            .iter()
            .filter(|r| r.model != ModelId::Aln)
            .map(|r| (r.model, r.variable.clone(), r.stats.mean.to_bits()))
            .collect()
    };
    variants
        .windows(2)
        .all(|w| baselines(&w[0]) == baselines(&w[1]))
}

/// The ALN's series name: with its variant's when there are several.
pub(super) fn aln_name(v: &Loaded, variants: usize) -> String {
    if variants > 1 {
        format!("{} · {}", ModelId::Aln, v.info.name)
    } else {
        ModelId::Aln.to_string()
    }
}

/// A model's mean error on the judged rows, across replicates when there
/// are several.
fn mean_point(v: &Loaded, model: ModelId) -> Option<(f64, Option<(f64, f64)>)> {
    let (mean, _) = overall(v.judged().0, model)?;
    let values: Option<Vec<f64>> = v.replicates.iter().map(|f| f.mean_of(model)).collect();
    let across = values
        .filter(|v| v.len() > 1)
        .and_then(|v| Interval::of(&v));
    Some(match across {
        Some(i) => (i.mean, Some((i.low, i.high))),
        None => (mean, None),
    })
}

/// The ALN's mean error minus persistence's on its own rows: across
/// replicates (paired by replicate) when there are several.
fn gap_to_persistence(v: &Loaded) -> Option<(f64, Option<(f64, f64)>)> {
    let values: Option<Vec<f64>> = v
        .replicates
        .iter()
        .map(|f| f.aln_minus(ModelId::Persistence))
        .collect();
    match values
        .filter(|v| v.len() > 1)
        .and_then(|v| Interval::of(&v))
    {
        Some(i) => Some((i.mean, Some((i.low, i.high)))),
        None => v
            .compared(ModelId::Persistence, None)
            .map(|d| (d.mean, None)),
    }
}

/// Writes the three cross-variant charts and their captions.
pub(super) fn charts(md: &mut String, variants: &[Loaded], shared: bool, dir: &Path) -> Result<()> {
    let n = variants.len();
    let replicated = variants.iter().any(|v| v.replicates.len() > 1);
    let _ = writeln!(
        md,
        "## {}\n",
        if n > 1 { "Across variants" } else { "Charts" }
    );
    let bars = if replicated {
        " Error bars: the 95% interval across replicates (the line: their mean)."
    } else {
        ""
    };

    // Speed against error.
    let unit = if shared {
        "mean error (levels)"
    } else {
        "ALN's mean error − persistence's (levels)"
    };
    let y_of = |v: &Loaded, model: ModelId| -> Option<(f64, Option<(f64, f64)>)> {
        if shared {
            mean_point(v, model)
        } else {
            gap_to_persistence(v)
        }
    };
    let mut series = Vec::new();
    let mut pwl_paths = false;
    for (k, v) in variants.iter().enumerate() {
        let Some((y, y_range)) = y_of(v, ModelId::Aln) else {
            continue;
        };
        for t in v
            .timings
            .iter()
            .filter(|t| t.model == ModelId::Aln && t.threads == 1)
        {
            let single = t.path != "batched";
            // A piecewise-linear model's one-row paths: plain, lazy, compiled.
            let how = match t.path.strip_prefix("pwl-") {
                Some(path) => format!("one at a time, {path}"),
                None if single => "one at a time".into(),
                None => "all at once".into(),
            };
            // The one-row paths of one variant share its colour; each
            // path beyond the plain one has a marker no variant takes.
            let style = style_of(ModelId::Aln, k);
            let marker = match t.path.as_str() {
                "pwl-lazy" => Marker::Plus,
                "pwl-compiled" => Marker::Cross,
                _ => style.marker,
            };
            pwl_paths |= marker != style.marker;
            series.push(Series {
                name: format!("{}, {how}", aln_name(v, n)),
                style: Style { marker, ..style },
                points: vec![Point {
                    x_range: Some((t.ns_min / 1000.0, t.ns_max / 1000.0)),
                    y_range,
                    ..Point::at(t.ns_per_state / 1000.0, y)
                }],
                joined: false,
                hollow: !single,
            });
        }
    }
    let baseline_times = if shared { &variants[..1] } else { &[] };
    for v in baseline_times {
        for t in v
            .timings
            .iter()
            .filter(|t| t.model != ModelId::Aln && t.threads == 1)
        {
            let Some((y, y_range)) = y_of(v, t.model) else {
                continue;
            };
            // The simulator is timed frame by frame alone; a learned
            // baseline both ways.
            let all_at_once = t.path == "batched";
            let name = if t.model.is_simulator() {
                t.model.to_string()
            } else if all_at_once {
                format!("{}, all at once", t.model)
            } else {
                format!("{}, one at a time", t.model)
            };
            series.push(Series {
                name,
                style: style_of(t.model, 0),
                points: vec![Point {
                    x_range: Some((t.ns_min / 1000.0, t.ns_max / 1000.0)),
                    y_range,
                    ..Point::at(t.ns_per_state / 1000.0, y)
                }],
                joined: false,
                hollow: all_at_once,
            });
        }
    }
    if !series.is_empty() {
        let ys = series.iter().flat_map(|s| s.points.iter().map(|p| p.y));
        let (y, rules) = if shared {
            (Axis::error(unit, ys), Vec::new())
        } else {
            (
                Axis::linear(unit),
                vec![charts::Rule::horizontal(
                    0.0,
                    &ModelId::Persistence.to_string(),
                )],
            )
        };
        let chart = charts::plot(&Plot {
            title: "speed against error, one thread".into(),
            x: Axis::log("µs per predicted state (log)"),
            y,
            series,
            // A front only among models that predicted the same rows.
            pareto: shared,
            rules,
        });
        atomic::write_bytes(&dir.join(SPEED), chart.as_bytes())?;
        let whose = if shared {
            "error averaged over the variables on the held-out rows, for every variant's ALN \
             (filled: one state at a time; hollow: every test state at once) and the timed baselines. The dashed \
             staircase is the Pareto front: no point beats one on it in both speed and error."
        } else {
            "every variant's ALN (filled: one state at a time; hollow: every test state at once) by its mean \
             error minus persistence's on its own held-out rows: the variants ran on different \
             data, so their errors are not set side by side, no front is drawn across them, and \
             the baselines are in each variant's section."
        };
        let paths = if pwl_paths {
            " A piecewise-linear ALN one state at a time is timed three ways, in its colour: \
             plain (every piece, its variant's marker), lazy (MIN/MAX with cut-offs, +) and \
             compiled (the pieces of the input's box, ×)."
        } else {
            ""
        };
        let _ = writeln!(
            md,
            "![µs per predicted state against error]({SPEED})\n\nTime per predicted state on one \
             thread (median of the timed runs; horizontal bars their range; the simulator per \
             re-simulated frame) against {whose}{paths}{bars}\n"
        );
    }

    // Training.
    let series: Vec<Series> = variants
        .iter()
        .enumerate()
        .filter(|(_, v)| !v.training.is_empty())
        .map(|(k, v)| Series {
            name: aln_name(v, n),
            style: style_of(ModelId::Aln, k),
            points: v.training.iter().map(|&(x, y)| Point::at(x, y)).collect(),
            joined: true,
            hollow: false,
        })
        .collect();
    if !series.is_empty() {
        let ys = series.iter().flat_map(|s| s.points.iter().map(|p| p.y));
        let chart = charts::plot(&Plot {
            title: "training errors per epoch".into(),
            x: Axis::integer("epoch"),
            y: Axis::error("errors per tree (mean)", ys),
            series,
            pareto: false,
            rules: Vec::new(),
        });
        atomic::write_bytes(&dir.join(TRAINING), chart.as_bytes())?;
        let _ = writeln!(
            md,
            "![training errors per epoch]({TRAINING})\n\nTraining rows each tree got wrong in an \
             epoch, counted as each row is presented (before the tree adapts to it), averaged \
             over the trees (first replicate). Where the count rises after the first epochs, the \
             trees fit the training rows worse as training goes on — not an artifact of counting \
             while adapting (the trees as they stand at an epoch's end err about as often): the \
             §3.3 rule moves every heuristically responsible node a step toward each row's target \
             in turn, which is not a descent on the training error: a step that fixes one row may \
             break others. Training runs the manifest's epochs \
             regardless (the paper's 10).\n"
        );
    }
    if shared && variants.iter().any(|v| !v.horizons.is_empty()) {
        let _ = writeln!(md, "### Closed loop\n");
        let mut columns: Vec<closed_loop::Column> = variants
            .iter()
            .enumerate()
            .map(|(k, v)| closed_loop::Column {
                name: aln_name(v, n),
                variant: v,
                model: ModelId::Aln,
                style: style_of(ModelId::Aln, k),
            })
            .collect();
        for model in closed_loop::models(&variants[0]) {
            if model != ModelId::Aln {
                columns.push(closed_loop::Column {
                    name: model.to_string(),
                    variant: &variants[0],
                    model,
                    style: style_of(model, 0),
                });
            }
        }
        closed_loop::section(md, dir, (CLOSED_LOOP, None), &columns)?;
    }
    Ok(())
}

/// The variants side by side: accuracy, then cost; and the baselines once
/// when the variants share them.
pub(super) fn side_by_side(md: &mut String, variants: &[Loaded], shared: bool) {
    let _ = writeln!(
        md,
        "## Variants side by side\n\nErrors in quantization levels averaged over the variables, \
         on each variant's held-out test rows (all test rows when none is held out), first \
         replicate; \"worse than persistence\" counts the variables whose paired difference's \
         95% interval lies above zero.\n"
    );
    let mut table = MdTable::new(&["variant"])
        .column("rows", Align::Left)
        .numbers(&["ALN mean", "ALN normalized (secondary)", "ALN p95"])
        .column("ALN − persistence [95%]", Align::Left)
        .numbers(&["variables worse than persistence"]);
    for v in variants {
        let (judged, rows) = v.judged();
        let aln = overall(judged, ModelId::Aln);
        let worse = worse_than_persistence(v).len();
        let total = judged.iter().filter(|r| r.model == ModelId::Aln).count();
        table.row(vec![
            format!("`{}`", v.info.name),
            rows.as_str().into(),
            aln.map_or("—".into(), |(m, _)| sig3(m)),
            normalized(judged, ModelId::Aln).map_or("—".into(), sig3),
            aln.map_or("—".into(), |(_, p)| sig3(p)),
            v.compared(ModelId::Persistence, None)
                .map_or("—".into(), |d| interval(d.mean, d.low, d.high)),
            format!("{}{worse} of {total}", if worse > 0 { "⚠ " } else { "" }),
        ]);
    }
    table.write(md);

    // The measured circuit's column only when the circuit stage measured one.
    let measured = variants.iter().any(|v| v.circuit.is_some());
    let placed = variants.iter().any(|v| v.fpga.is_some());
    let _ = writeln!(
        md,
        "Cost: time per predicted state on one thread (median of the timed runs), the §5 \
         hardware estimate{}{}, training time as computed (also when the stage was cached) and \
         the trees' memory while training.\n",
        if measured {
            ", the synthesized circuit's longest path in gate levels (the circuit stage)"
        } else {
            ""
        },
        if placed {
            " and its time per state placed and routed on an FPGA (the critical path, from timing \
             analysis)"
        } else {
            ""
        }
    );
    let mut columns = vec![
        "ALN all at once (µs)",
        "ALN one at a time (µs)",
        "hardware (gate delays)",
    ];
    if measured {
        columns.push("circuit (gate levels)");
    }
    if placed {
        columns.push("FPGA (ns)");
    }
    columns.extend(["training (s)", "trees (MiB)"]);
    let mut table = MdTable::new(&["variant"]).numbers(&columns);
    for v in variants {
        let time = |t: Option<&Timing>| t.map_or("—".into(), Spread::spread_in_column);
        let mut row = vec![
            format!("`{}`", v.info.name),
            time(v.all_at_once(ModelId::Aln)),
            time(v.aln_single()),
            match v.hardware.delays() {
                // No gates: a piecewise-linear model computes with numbers.
                0 => "—".to_string(),
                delays => delays.to_string(),
            },
        ];
        if measured {
            row.push(
                v.circuit
                    .as_ref()
                    .map_or("—".into(), |c| c.depth.to_string()),
            );
        }
        if placed {
            row.push(
                v.fpga
                    .as_ref()
                    .and_then(|f| f.state.critical_ns())
                    .map_or("—".into(), sig3),
            );
        }
        row.push(
            v.info
                .stages
                .iter()
                .find(|s| s.stage == "train")
                .map_or("—".into(), |s| sig3(s.compute_seconds)),
        );
        row.push(sig3(v.tree_bytes as f64 / (1024.0 * 1024.0)));
        table.row(row);
    }
    table.write(md);

    if shared && let Some(v) = variants.first() {
        let _ = writeln!(
            md,
            "### Baselines\n\nThe same for every variant: they ran on the same test rows. Errors \
             on the {} rows; time per predicted state, median and range of the timed runs (the \
             simulator: per re-simulated frame, `simulator@k/frame` taking k integration steps \
             per frame); frames a simulator could not step are scored as the worst \
             prediction.\n",
            v.judged().1.as_str()
        );
        baselines_table(md, v, false);
    }
}

/// The models other than the ALN (with the ALN's own row and its paired
/// difference against each when `with_aln`): errors and speed.
pub(super) fn baselines_table(md: &mut String, v: &Loaded, with_aln: bool) {
    let (judged, _) = v.judged();
    let mut table =
        MdTable::new(&["model"]).numbers(&["mean", "normalized (secondary)", "p95", "max"]);
    if with_aln {
        table = table.column("ALN − model [95%]", Align::Left);
    }
    table = table
        .column("µs per state, one at a time", Align::Left)
        .column("µs per state, all at once", Align::Left)
        .numbers(&["failed"]);
    let mut models = baseline_models(judged);
    if with_aln {
        models.insert(0, ModelId::Aln);
    }
    for model in models {
        let rows: Vec<_> = judged.iter().filter(|r| r.model == model).collect();
        let max = rows.iter().map(|r| r.stats.max).max().unwrap_or(0);
        let (single, batched) = (v.single(model), v.all_at_once(model));
        let mut cells = vec![
            format!("`{model}`"),
            overall(judged, model).map_or("—".into(), |(m, _)| sig3(m)),
            normalized(judged, model).map_or("—".into(), sig3),
            overall(judged, model).map_or("—".into(), |(_, p)| sig3(p)),
            max.to_string(),
        ];
        if with_aln {
            cells.push(
                v.compared(model, None)
                    .map_or("—".into(), |d| interval(d.mean, d.low, d.high)),
            );
        }
        cells.push(single.map_or("—".into(), |t| t.spread()));
        cells.push(batched.map_or("—".into(), |t| t.spread()));
        let failed = single.into_iter().chain(batched).map(|t| t.failed).max();
        cells.push(failed.unwrap_or(0).to_string());
        table.row(cells);
    }
    table.write(md);
}
