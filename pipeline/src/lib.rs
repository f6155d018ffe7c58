//! alnlab: an experiment pipeline asking how well, and how fast, adaptive
//! logic networks predict the motion of articulated rigid bodies.
//!
//! This crate is the orchestration: manifests, the stage graph, the artifact
//! cache and run records. The stages themselves live in their own crates and
//! meet only through files.

pub mod bench;
pub mod budget;
pub mod cache;
pub mod cli;
pub mod dataset;
pub mod export;
pub mod git;
pub mod manifest;
pub mod mlflow;
pub mod progress;
pub mod records;
pub mod report;
pub mod run;
pub mod runs;
pub mod stages;
