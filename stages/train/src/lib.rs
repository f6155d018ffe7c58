//! The train stage (paper §3, §4.3; DESIGN.md §5) — its contract, pending its
//! own issue: reads `levels.parquet` and the codebook, trains the ALN forest
//! and writes the model file and `training.parquet`. Not yet part of the
//! stage graph.

/// File name of the model.
pub const MODEL_FILE: &str = "model.aln";
/// File name of the training log table.
pub const TRAINING_FILE: &str = "training.parquet";
