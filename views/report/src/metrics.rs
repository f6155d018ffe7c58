//! A variant's headline figures as named numbers, for tracking runs: what
//! `alnlab runs` lists and compares and what an MLflow export logs. Every
//! figure is read from the stage's own tables (and the test stage's timings
//! and the train stage's log), on the rows the report's findings are about:
//! the held-out test rows, or all of them when none is held out.
//!
//! Names are `/`-separated paths (a variable's name may hold a dot):
//! - `error/<model>` — mean error in levels, averaged over the variables;
//! - `error_by_variable/<model>/<variable>` — one variable's mean error;
//! - `difference/<model>`, `difference/<model>/low`, `…/high` — the ALN's
//!   mean paired difference in error against another model (below zero:
//!   the ALN's errors are lower) with its 95% interval;
//! - `ns_per_state/<model>/<path>` — median ns per state on one thread
//!   (`…/threads_<n>` on n threads);
//!
//! and, as series over steps:
//! - `training_error` — mean training errors per tree, per epoch (from 1);
//! - `closed_loop/<model>` — closed-loop mean error per horizon.

use alnlab_common::ModelId;
use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::Result;

use crate::{aln_against, overall, split_rows};
use alnlab_summarize::{Rows, read_comparisons, read_horizons};

/// The prefix of the per-variable figures' names.
pub const BY_VARIABLE: &str = "error_by_variable/";

/// A variant's headline figures (kept in its run record).
pub use alnlab_records::Metrics;

/// The files a variant's metrics are read from.
pub struct Sources<'a> {
    pub summary: &'a Path,
    pub comparisons: &'a Path,
    pub horizons: &'a Path,
    pub timings: &'a Path,
    pub training: &'a Path,
}

/// The headline metrics of one variant (one replicate) from its artifacts.
pub fn read(sources: &Sources) -> Result<Metrics> {
    let (all, held_out, rows) = split_rows(alnlab_summarize::read(sources.summary)?);
    let judged = if rows == Rows::HeldOut { held_out } else { all };
    let mut values = BTreeMap::new();
    let mut put = |name: String, value: f64| {
        // Only finite figures: a record must survive JSON.
        if value.is_finite() {
            values.insert(name, value);
        }
    };
    let mut models: Vec<ModelId> = judged.iter().map(|r| r.model).collect();
    models.dedup();
    for &model in &models {
        if let Some((mean, _)) = overall(&judged, model) {
            put(format!("error/{model}"), mean);
        }
    }
    for row in &judged {
        put(
            format!("{BY_VARIABLE}{}/{}", row.model, row.variable),
            row.stats.mean,
        );
    }
    let comparisons = read_comparisons(sources.comparisons)?;
    for &model in models.iter().filter(|&&m| m != ModelId::Aln) {
        if let Some(d) = aln_against(&comparisons, rows, model, None) {
            put(format!("difference/{model}"), d.mean);
            put(format!("difference/{model}/low"), d.low);
            put(format!("difference/{model}/high"), d.high);
        }
    }
    for t in alnlab_evaluate::timings::read(sources.timings)? {
        let name = match t.threads {
            1 => format!("ns_per_state/{}/{}", t.model, t.path),
            n => format!("ns_per_state/{}/{}/threads_{n}", t.model, t.path),
        };
        put(name, t.ns_per_state);
    }
    let mut steps: BTreeMap<String, Vec<(u32, f64)>> = BTreeMap::new();
    let training: Vec<(u32, f64)> = alnlab_train::log::read(sources.training)?
        .mean_errors_per_epoch()
        .into_iter()
        .filter(|(_, mean)| mean.is_finite())
        .collect();
    if !training.is_empty() {
        steps.insert("training_error".into(), training);
    }
    for h in read_horizons(sources.horizons)? {
        if h.rows == rows && h.mean.is_finite() {
            steps
                .entry(format!("closed_loop/{}", h.model))
                .or_default()
                .push((u32::from(h.horizon), h.mean));
        }
    }
    for series in steps.values_mut() {
        series.sort_by_key(|&(step, _)| step);
    }
    Ok(Metrics {
        rows: rows.as_str().into(),
        values,
        steps,
    })
}
