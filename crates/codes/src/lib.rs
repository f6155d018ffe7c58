//! The codes of quantization levels (paper §4.2, §4.4, §6; docs/design.md §4) and
//! the codebook that names each variable's code: a library the quantize,
//! train and test stages share, so that no stage reads another stage's code.
//!
//! - [`codes`]: binary, Gray, walk and thermometer codes, every decoder
//!   defined on every bit pattern; [`Codec`] is one variable's code.
//! - [`walk`]: the seeded random-walk code and its distance guarantee.
//! - [`bits`]: level columns → packed bit matrices.
//! - [`residual`]: a variable's change of level as a target of its own
//!   (clamped to ±k, on the circle for angles that wrap).
//! - [`codebook`]: `codebook.parquet` read and written.

pub mod bits;
pub mod codebook;
pub mod codes;
mod near;
pub mod residual;
pub mod walk;

pub use codebook::{Codebook, Entry, GROUPS, Quantizer, group_of, unit_of};
pub use codes::{Code, Codec};
pub use residual::{DeltaSpec, Residual};
