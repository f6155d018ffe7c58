//! The test stage (paper §4.5; DESIGN.md §6–7) — its contract, pending its own
//! issue: reads the model and `levels.parquet`, predicts every test row and
//! writes `predictions.parquet` and `timings.parquet`. Not yet part of the
//! stage graph.

/// File name of the predictions table.
pub const PREDICTIONS_FILE: &str = "predictions.parquet";
/// File name of the timings table.
pub const TIMINGS_FILE: &str = "timings.parquet";
