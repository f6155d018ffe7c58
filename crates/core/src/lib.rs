//! What every alnlab crate shares and that needs no file format: the error
//! type, atomic file writing, content hashes and seeds, bounded reads of
//! files a user names, typed parameters, progress and provenance.
//!
//! It links no Parquet, Arrow or MCAP, so the libraries that need only
//! these (codes, physics, records) build without them; the file formats
//! live in `alnlab-common`, which re-exports this crate's items.

pub mod atomic;
pub mod bounded;
pub mod error;
pub mod hash;
pub mod model_id;
pub mod params;
pub mod progress;
pub mod provenance;
pub mod state;

pub use error::{Error, Result};
pub use model_id::{ModelId, PolicyId};
pub use progress::{Progress, Silent};
pub use provenance::Provenance;

/// The alnlab version, written into every artifact's provenance.
pub const ALNLAB_VERSION: &str = env!("CARGO_PKG_VERSION");
