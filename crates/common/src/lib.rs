//! The file formats several alnlab stages share: the Parquet table helpers
//! and the MCAP trajectory-log format (the `/state` message and its codec),
//! on top of `alnlab-core`, whose items this crate re-exports so that a
//! stage imports one crate.
//!
//! Stages never call each other; they meet through the files this crate knows
//! how to write and read.

pub mod mcap_read;
pub mod state_log;
pub mod table;

pub use alnlab_core::{
    ALNLAB_VERSION, Error, ModelId, PolicyId, Progress, Provenance, Result, Silent, atomic,
    bounded, error, hash, model_id, params, progress, provenance,
};
