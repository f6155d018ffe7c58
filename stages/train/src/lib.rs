//! The train stage (paper §3, §4.3; DESIGN.md §5): ALN trees and forests.
//! Work in progress: the tree (training, parsimonious and bit-sliced
//! evaluation, pruning) is here; the forest, the model file and the stage
//! itself are not yet, so train is not yet part of the stage graph.

pub mod forest;
pub mod tree;

/// File name of the model.
pub const MODEL_FILE: &str = "model.aln";
/// File name of the training log table.
pub const TRAINING_FILE: &str = "training.parquet";
