//! What several alnlab stages share, and nothing else: the error type, atomic
//! file writing, content hashes, provenance metadata, the Parquet table helpers
//! and the MCAP trajectory-log format (the `/state` message and its codec).
//!
//! Stages never call each other; they meet through the files this crate knows
//! how to write and read.

pub mod atomic;
pub mod bounded;
pub mod error;
pub mod hash;
pub mod mcap_read;
pub mod params;
pub mod progress;
pub mod provenance;
pub mod state_log;
pub mod table;

pub use error::{Error, Result};
pub use progress::{Progress, Silent};
pub use provenance::Provenance;

/// The alnlab version, written into every artifact's provenance.
pub const ALNLAB_VERSION: &str = env!("CARGO_PKG_VERSION");
