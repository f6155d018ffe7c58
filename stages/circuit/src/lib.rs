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
//! - [`fpga`]: each variable's predictor mapped onto an iCE40 FPGA's lookup
//!   tables, placed and routed between registers, its critical path in ns
//!   from timing analysis.
//! - [`bench`]: a run's model measured, for `alnlab bench circuit`.
//! - [`check`]: all of it — write, synthesize (and, when asked, place and
//!   route), simulate the exported Verilog, the synthesized netlist and the
//!   mapped one, and hold them to the software's predictions row by row.
//! - [`measured`] and [`routed`]: the stage's two tables.
//!
//! The stage ([`run`]) measures the model of its variant on the test rows
//! into `circuit.parquet` when `[circuit] synthesize = true`, and into
//! `fpga.parquet` when `[circuit] fpga` names a device; Yosys, Icarus
//! Verilog and nextpnr-ice40 are external programs (Debian: `apt-get
//! install yosys iverilog nextpnr-ice40`), which [`tools`] finds and names
//! when they are missing.

pub mod bench;
pub mod check;
pub mod fpga;
pub mod measured;
pub mod routed;
pub mod simulate;
pub mod synth;
pub mod tools;
pub mod verilog;

use std::path::Path;

use alnlab_aln::ModelKind;
use alnlab_aln::runtime::Trained;
use alnlab_codes::Entry;
use alnlab_common::params::{Count, ParamError};
use alnlab_common::{Error, Progress, Provenance, Result, params};
use alnlab_tables::levels::Levels;
use alnlab_tables::pairs::Side;
use serde::{Deserialize, Serialize};

pub use check::Measurement;
pub use fpga::Device;
pub use synth::{Figures, Part, VariableFigures};
pub use verilog::Circuit;

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 2;
/// File name of the measured figures.
pub const CIRCUIT_FILE: &str = "circuit.parquet";
/// File name of the place-and-route figures.
pub const FPGA_FILE: &str = "fpga.parquet";

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
    /// Also map every variable onto this FPGA (`"ice40-hx8k"`), place and
    /// route it between registers (nextpnr-ice40, seeded by the experiment
    /// seed), read its critical path from timing analysis and simulate the
    /// mapped netlist on the same rows. Off (the default) without it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fpga: Option<Device>,
}

impl Params {
    /// Placing and routing needs the synthesis it follows.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        if self.fpga.is_some() && !self.synthesize {
            return Err((
                "fpga".into(),
                "placing and routing follows synthesis: set `synthesize = true` too".into(),
            ));
        }
        Ok(())
    }
}

/// Measures the circuit of the model (`model_path`, trained with
/// `codebook_path`) on the test rows of `levels_path` into
/// `out_dir/circuit.parquet`: per learned variable and part (`trees`,
/// `votes`, `decode`), gates, inverters and depth in gate levels, and the
/// rows on which both the exported Verilog and the synthesized netlist put
/// out the software's levels (all simulated rows, or the stage fails).
/// With `fpga`, also `out_dir/fpga.parquet`: every variable placed and
/// routed with nextpnr's `seed`, its mapped netlist equal to the software
/// on the same rows. Without `synthesize`, or for a threshold model (whose
/// binary search is sequential, not one combinational circuit), both
/// tables are empty.
#[allow(clippy::too_many_arguments)]
pub fn run(
    params: &Params,
    seed: u64,
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
    let fpga_path = out_dir.join(FPGA_FILE);
    let nothing = || {
        measured::write(&path, None, provenance)?;
        routed::write(&fpga_path, None, provenance)
    };
    if !params.synthesize {
        return nothing();
    }
    let trained = Trained::read(model_path, codebook_path)?;
    if trained.model.header.model == ModelKind::Threshold {
        return nothing();
    }
    if trained.model.header.model == ModelKind::PiecewiseLinear {
        return Err(Error::Invalid(format!(
            "{}: circuit.synthesize needs a bit-forest; a piecewise-linear model computes with \
             real numbers, not gates",
            model_path.display()
        )));
    }
    let (measurement, rows) = measure_test_rows(
        &trained,
        model_path,
        levels_path,
        params.rows.map(Count::get),
        params.fpga.map(|device| (device, seed)),
        progress,
    )?;
    let measured = measured::Measured {
        figures: measurement.figures,
        rows_equal: rows as u64,
    };
    measured::write(&path, Some(&measured), provenance)?;
    let routed = measurement.fpga.map(|state| routed::Routed {
        state,
        rows_equal: rows as u64,
    });
    routed::write(&fpga_path, routed.as_ref(), provenance)
}

/// `trained` (read from `model_path`) measured as a circuit on the first
/// `rows` test rows of `levels_path` (all when none), in a scratch folder
/// ([`check::measure`]), and placed and routed on `fpga` (a device and
/// nextpnr's seed) when given: what was measured and the rows simulated.
pub fn measure_test_rows(
    trained: &Trained,
    model_path: &Path,
    levels_path: &Path,
    rows: Option<usize>,
    fpga: Option<(Device, u64)>,
    progress: &dyn Progress,
) -> Result<(Measurement, usize)> {
    let circuit = circuit_of(trained, model_path)?;
    let levels = Levels::read(levels_path)?;
    let mut test = levels.test_rows();
    if let Some(n) = rows {
        test.truncate(n);
    }
    let learned: Vec<&Entry> = trained.codebook.learned().collect();
    let x = levels.select(Side::Current, &learned, &test)?;
    let expected = trained.runtime().levels(&x, None);
    let scratch = tempfile::tempdir().map_err(|e| Error::io(&std::env::temp_dir(), e))?;
    let measurement = check::measure(
        &circuit,
        &trained.codecs,
        &x,
        &expected,
        fpga,
        scratch.path(),
        progress,
    )?;
    Ok((measurement, test.len()))
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
