//! Run records ([`alnlab_records`], which the Python package reads too),
//! and what only the pipeline does with them: read a variant's metrics
//! from its artifacts through the report.

use std::path::PathBuf;

pub use alnlab_records::*;

use alnlab_common::{Error, Result};

/// `variant`'s headline metrics read from its artifacts, each found by
/// `file` (its recorded path, or where the cache holds it now).
pub fn read_metrics(
    variant: &VariantRecord,
    file: impl Fn(&ArtifactRef) -> Option<PathBuf>,
) -> Result<Metrics> {
    let path = |role: &str| {
        variant.artifacts.get(role).and_then(&file).ok_or_else(|| {
            Error::Invalid(format!(
                "variant `{}`: no `{role}` artifact to read its metrics from",
                variant.name
            ))
        })
    };
    alnlab_report::metrics::read(&alnlab_report::metrics::Sources {
        summary: &path("summary")?,
        comparisons: &path("comparisons")?,
        horizons: &path("horizons")?,
        timings: &path("timings")?,
        training: &path("training")?,
    })
}
