//! Adaptive logic networks as trained models (paper §3, §5, §6;
//! docs/design.md §5): the library every stage that reads or evaluates a model uses. The
//! train stage makes models; the test and summarize stages read them with
//! this crate alone, never with the trainer.
//!
//! - [`tree`]: one ALN — node counters and functions, random initial trees,
//!   the adaptation step of §3.3 ([`tree::Tree::adapt`]), full and
//!   parsimonious evaluation, pruning to AND/OR gates.
//! - [`forest`]: a bit-forest as a [`forest::Predictor`] (majority vote,
//!   bit-sliced batches, parsimonious single samples).
//! - [`threshold`]: the §6 predicate, answered by binary search.
//! - [`model`]: the `model.aln` file and its [`model::ModelKind`].
//! - [`output`]: what the trees learn per variable (its next level or its
//!   change) and how their bits decode to the next level.
//! - [`shard`]: which trees a partial model holds.
//! - [`pwl`]: piecewise-linear ALNs — MIN/MAX trees over affine pieces —
//!   evaluated fully, lazily with cut-offs, or compiled over input boxes.
//! - [`boosted`]: not an ALN: the test stage's boosted trees as kept in
//!   their file, for everything that evaluates them.

pub mod boosted;
mod compiled;
pub mod forest;
pub mod linear;
pub mod model;
pub mod output;
pub mod pwl;
pub mod runtime;
pub mod shard;
pub mod threshold;
pub mod tree;

pub use model::{Model, ModelKind};
pub use output::{Output, Target};
