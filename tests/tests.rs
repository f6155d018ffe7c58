//! Every end-to-end test in one binary, a module per subject (as ripgrep's
//! `tests/tests.rs`): each further integration-test binary would link arrow
//! and parquet again, and linking dominated the suite's build.

mod common;

mod bad_input;
mod circuit;
mod corruption;
mod datasets;
mod end_to_end;
mod headlines;
mod hostile;
mod plan;
mod provenance;
mod recordings;
mod reports;
mod robots;
mod scale_out;
mod structure;
mod tracking;
mod verdicts;
