//! The summarize stage (paper §4.5–4.6; DESIGN.md §6–7) — its contract,
//! pending its own issue: reads predictions, timings and the training log and
//! writes `summary.parquet` and `reports/<experiment>/report.md`. Not yet part
//! of the stage graph.

pub mod stats;

/// File name of the summary table.
pub const SUMMARY_FILE: &str = "summary.parquet";
/// File name of the report.
pub const REPORT_FILE: &str = "report.md";
