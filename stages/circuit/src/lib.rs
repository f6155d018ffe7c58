//! The circuit stage: a trained bit-forest as a combinational circuit
//! (paper §5, abstract), where the claim that a trained ALN predicts a state
//! "in a few tens of logic gate propagation delays" is measured.
//!
//! - [`verilog`]: the model's pruned trees as synthesizable Verilog — one
//!   module per tree, per variable (its trees, their majority votes, its
//!   decoder) and one for the whole state — with ports named after the
//!   variables and their code bits (`alnlab export verilog` writes it).
//! - [`synth`]: synthesis by Yosys to two-input gates and inverters; cell
//!   counts and the longest path in gate levels, split into trees, votes and
//!   decoding.
//! - [`simulate`]: the circuit run by Icarus Verilog on rows of levels.
//! - [`bench`]: a run's model measured, for `alnlab bench circuit`.
//! - [`check`]: all of it — write, synthesize, simulate both the exported
//!   Verilog and the synthesized netlist, and hold them to the software's
//!   predictions row by row.
//!
//! The stage ([`run`]) measures the model of its variant on the test rows
//! into `circuit.parquet` when `[circuit] synthesize = true`; Yosys and
//! Icarus Verilog are external programs (Debian: `apt-get install yosys
//! iverilog`), which [`tools`] finds and names when they are missing.

pub mod bench;
pub mod check;
pub mod fpga;
pub mod measured;
pub mod simulate;
pub mod synth;
pub mod tools;
pub mod verilog;

use std::path::Path;

use alnlab_aln::ModelKind;
use alnlab_aln::runtime::Trained;
use alnlab_codes::{Entry, level_rows, split_rows};
use alnlab_common::params::{Count, ParamError};
use alnlab_common::table::Table;
use alnlab_common::{Error, Progress, Provenance, Result, params};
use serde::{Deserialize, Serialize};

pub use synth::{Figures, Part, VariableFigures};
pub use verilog::Circuit;

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 1;
/// File name of the measured figures.
pub const CIRCUIT_FILE: &str = "circuit.parquet";

/// The `[circuit]` table of a manifest.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Export the model as Verilog, synthesize it with Yosys and simulate it
    /// with Icarus Verilog on the test rows. Off (the default), the stage
    /// writes an empty table and needs neither program.
    pub synthesize: bool,
    /// The test rows to simulate, the first ones (default: all).
    pub rows: Option<Count>,
}

impl Params {
    /// Nothing relates the parameters; kept for the stage table's shape.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        Ok(())
    }
}

/// Measures the circuit of the model (`model_path`, trained with
/// `codebook_path`) on the test rows of `levels_path` into
/// `out_dir/circuit.parquet`: per learned variable and part (`trees`,
/// `votes`, `decode`), gates, inverters and depth in gate levels, and the
/// rows on which both the exported Verilog and the synthesized netlist put
/// out the software's levels (all simulated rows, or the stage fails).
/// Without `synthesize`, or for a threshold model (whose binary search is
/// sequential, not one combinational circuit), the table is empty.
pub fn run(
    params: &Params,
    model_path: &Path,
    codebook_path: &Path,
    levels_path: &Path,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    params
        .validate()
        .map_err(|e| params::invalid("circuit", e))?;
    let path = out_dir.join(CIRCUIT_FILE);
    if !params.synthesize {
        return measured::write(&path, None, provenance);
    }
    let trained = Trained::read(model_path, codebook_path)?;
    if trained.model.header.model == ModelKind::Threshold {
        return measured::write(&path, None, provenance);
    }
    if trained.model.header.model == ModelKind::PiecewiseLinear {
        return Err(Error::Invalid(format!(
            "{}: circuit.synthesize needs a bit-forest; a piecewise-linear model computes with \
             real numbers, not gates",
            model_path.display()
        )));
    }
    let (figures, rows) = measure_test_rows(
        &trained,
        model_path,
        levels_path,
        params.rows.map(Count::get),
        progress,
    )?;
    let measured = measured::Measured {
        figures,
        rows_equal: rows as u64,
    };
    measured::write(&path, Some(&measured), provenance)
}

/// `trained` (read from `model_path`) measured as a circuit on the first
/// `rows` test rows of `levels_path` (all when none), in a scratch folder
/// ([`check::measure`]): its figures and the rows simulated.
pub fn measure_test_rows(
    trained: &Trained,
    model_path: &Path,
    levels_path: &Path,
    rows: Option<usize>,
    progress: &dyn Progress,
) -> Result<(Figures, usize)> {
    let circuit = circuit_of(trained, model_path)?;
    let levels = Table::read(levels_path)?;
    let mut test = split_rows(&levels, "test")?;
    if let Some(n) = rows {
        test.truncate(n);
    }
    let learned: Vec<&Entry> = trained.codebook.learned().collect();
    let x = level_rows(&levels, "x", &learned, &test)?;
    let expected = trained.runtime().levels(&x, None);
    let scratch = tempfile::tempdir().map_err(|e| Error::io(&std::env::temp_dir(), e))?;
    let figures = check::measure(
        &circuit,
        &trained.codecs,
        &x,
        &expected,
        scratch.path(),
        progress,
    )?;
    Ok((figures, test.len()))
}

/// The circuit of `trained` (read from `model_path`); an error says why a
/// model cannot be one.
pub fn circuit_of(trained: &Trained, model_path: &Path) -> Result<Circuit> {
    let names: Vec<String> = trained
        .codebook
        .learned()
        .map(|e| e.variable.clone())
        .collect();
    Circuit::new(&trained.model, &names, &trained.codecs, &trained.outputs)
        .map_err(|m| Error::bad_file(model_path, m))
}
