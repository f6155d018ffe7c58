//! The quantize stage (paper §4.2, §4.4, §6; DESIGN.md §4) — its contract,
//! pending its own issue: reads `pairs.parquet` and `stats.parquet`, clamps
//! each variable to its range, quantizes it to L levels and writes the
//! codebook and `levels.parquet`. Not yet part of the stage graph.

/// File name of the codebook.
pub const CODEBOOK_FILE: &str = "codebook.parquet";
/// File name of the levels table.
pub const LEVELS_FILE: &str = "levels.parquet";
