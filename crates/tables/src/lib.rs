//! The tables one stage writes and another stage (or the report) reads:
//! `stats` (simulate → quantize), `pairs` (stride → quantize, train, test),
//! `codebook` (quantize → every stage after it and the report),
//! `levels` (quantize → train, test, plan, circuit), `predictions` and
//! `rollout` (test → summarize).
//! Stages never depend on each other, so such a table's contract cannot
//! live in its writer's crate: each module here holds one table's file name,
//! its columns, its one writer and its one reader, and every other crate
//! sees the table only as the typed value the reader returns.
//!
//! A table written and read by its own stage alone (`training.parquet`,
//! `timings.parquet`, …) stays with that stage.

pub mod codebook;
mod dictionary;
pub mod levels;
pub mod pairs;
pub mod predictions;
pub mod rollout;
pub mod stats;
#[cfg(test)]
mod testing;
