//! `timings.parquet`, the test stage's speed table: its row, its writer and
//! its reader. One row per model, evaluation path and thread count: the
//! median ns per state of [`timing::REPEATS`](crate::timing::REPEATS)
//! interleaved runs, their range and every run in round order (`ns_runs`),
//! with the states it failed to predict and the machine (cores, CPU model).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{ModelId, Provenance, Result};
use arrow_array::cast::AsArray;
use arrow_array::types::Float64Type;
use arrow_array::{Array, Float64Array, ListArray, StringArray, UInt32Array};

use crate::timing::Timing;

/// One row of `timings.parquet`.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub model: ModelId,
    /// `batched`, `single`, `threshold-search` or a piecewise-linear path.
    pub path: String,
    /// ns per state: the median of the timed runs, and their range.
    pub ns_per_state: f64,
    pub ns_min: f64,
    pub ns_max: f64,
    /// ns per state of every run, in round order: run k of every model was
    /// timed in the same round.
    pub runs: Vec<f64>,
    /// States timed.
    pub states: u32,
    pub threads: u32,
    /// States the model could not predict (a re-simulation that blew up).
    pub failed: u32,
    /// The machine's cores and CPU model.
    pub cores: u32,
    pub cpu: String,
}

impl Row {
    /// The row of `timing`, measured on this machine.
    pub fn measured(timing: &Timing) -> Row {
        let spread = timing.spread();
        Row {
            model: timing.model,
            path: timing.path.to_string(),
            ns_per_state: spread.median,
            ns_min: spread.min,
            ns_max: spread.max,
            runs: timing.runs.clone(),
            states: timing.states as u32,
            threads: timing.threads as u32,
            failed: timing.failed as u32,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()) as u32,
            cpu: cpu_model(),
        }
    }
}

/// Writes `rows` to `path`.
pub fn write(path: &Path, rows: &[Row], provenance: &Provenance) -> Result<()> {
    let column = |f: fn(&Row) -> u32| -> Arc<dyn Array> {
        Arc::new(UInt32Array::from_iter_values(rows.iter().map(f)))
    };
    let ns = |f: fn(&Row) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(rows.iter().map(f)))
    };
    let text = |f: fn(&Row) -> &str| -> Arc<dyn Array> {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
    };
    let batch = table::batch(vec![
        (
            "model",
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.model.to_string()),
            )),
        ),
        ("path", text(|r| &r.path)),
        ("ns_per_state", ns(|r| r.ns_per_state)),
        ("ns_min", ns(|r| r.ns_min)),
        ("ns_max", ns(|r| r.ns_max)),
        (
            "ns_runs",
            Arc::new(ListArray::from_iter_primitive::<Float64Type, _, _>(
                rows.iter()
                    .map(|r| Some(r.runs.iter().map(|&x| Some(x)).collect::<Vec<_>>())),
            )),
        ),
        ("states", column(|r| r.states)),
        ("threads", column(|r| r.threads)),
        ("failed", column(|r| r.failed)),
        ("cores", column(|r| r.cores)),
        ("cpu", text(|r| &r.cpu)),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// Reads `timings.parquet`.
pub fn read(path: &Path) -> Result<Vec<Row>> {
    let table = Table::read(path)?;
    let text = |name: &str| table.strings(name);
    let models: Vec<ModelId> = table.parsed("model")?;
    let (paths, cpu) = (text("path")?, text("cpu")?);
    let float = |name: &str| table.column::<Float64Array>(name).map(|c| c.values());
    let (ns, ns_min, ns_max) = (float("ns_per_state")?, float("ns_min")?, float("ns_max")?);
    let count = |name: &str| table.column::<UInt32Array>(name).map(|c| c.values());
    let (states, threads) = (count("states")?, count("threads")?);
    let (failed, cores) = (count("failed")?, count("cores")?);
    let runs = table.column::<ListArray>("ns_runs")?;
    Ok((0..table.num_rows())
        .map(|i| Row {
            model: models[i],
            path: paths[i].clone(),
            ns_per_state: ns[i],
            ns_min: ns_min[i],
            ns_max: ns_max[i],
            runs: runs
                .value(i)
                .as_primitive_opt::<Float64Type>()
                .map(|r| r.values().to_vec())
                .unwrap_or_default(),
            states: states[i],
            threads: threads[i],
            failed: failed[i],
            cores: cores[i],
            cpu: cpu[i].clone(),
        })
        .collect())
}

/// The CPU's model name (Linux's `/proc/cpuinfo`), or "unknown CPU".
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find_map(|l| l.strip_prefix("model name")?.split_once(':'))
                .map(|(_, name)| name.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_reads_back_as_written() {
        let timing = Timing {
            model: ModelId::Aln,
            path: "batched",
            runs: vec![3.0, 1.0, 2.0],
            states: 9000,
            threads: 1,
            failed: 0,
        };
        let row = Row::measured(&timing);
        assert_eq!((row.ns_min, row.ns_per_state, row.ns_max), (1.0, 2.0, 3.0));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("timings.parquet");
        let provenance = Provenance {
            stage: "test".into(),
            params: serde_json::Value::Null,
            inputs: Default::default(),
        };
        write(&path, std::slice::from_ref(&row), &provenance).unwrap();
        assert_eq!(read(&path).unwrap(), vec![row]);
    }
}
