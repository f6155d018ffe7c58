//! The circuit stage: a trained ALN as a circuit (paper §5, abstract),
//! where the claim that a trained ALN predicts a state "in a few tens of
//! logic gate propagation delays" is measured — for a bit-forest as gates,
//! for a piecewise-linear model as fixed-point arithmetic.
//!
//! - [`verilog`]: the model's pruned trees as synthesizable Verilog — one
//!   module per tree, per variable (its trees, their majority votes, its
//!   decoder) and one for the whole state — with ports named after the
//!   variables and their code bits (`alnlab export verilog` writes it).
//! - [`synth`]: synthesis by Yosys to two-input gates and inverters; cell
//!   counts and the longest path in gate levels, split into trees, votes and
//!   decoding.
//! - [`simulate`]: the circuit run on rows of levels by Icarus Verilog, or
//!   by Verilator (a mapped piecewise-linear netlist, thousands of lookup
//!   tables).
//! - [`fpga`]: each variable's predictor mapped onto an iCE40 FPGA's lookup
//!   tables, placed and routed between registers, its critical path in ns
//!   from timing analysis.
//! - [`bench`]: a run's model measured, for `alnlab bench circuit`.
//! - [`check`]: all of it — write, synthesize (and, when asked, place and
//!   route), simulate the exported Verilog, the synthesized netlist and the
//!   mapped one, and hold them to the software's predictions row by row.
//! - [`datapath`] and [`piecewise`]: a piecewise-linear model in fixed
//!   point (widths chosen on training rows) as adders, comparators and
//!   multiplexers, combinational and pipelined, simulated against the
//!   fixed-point evaluator and placed and routed.
//! - [`measured`], [`routed`] and [`fixed_point`]: the stage's three tables.
//!
//! The stage ([`run`]) measures the model of its variant on the test rows
//! into `circuit.parquet` (a bit-forest) or `fixed.parquet` (a
//! piecewise-linear model) when `[circuit] synthesize = true`, and into
//! `fpga.parquet` when `[circuit] fpga` names a device; scratch files go
//! into a folder under the stage's output folder, removed when it ends
//! (a killed run's is removed with the unfinished output by the next); Yosys, Icarus
//! Verilog, nextpnr-ice40 and Verilator are external programs (Debian:
//! `apt-get install yosys iverilog nextpnr-ice40 verilator`), which
//! [`tools`] finds and names when they are missing.

pub mod bench;
pub mod check;
pub mod datapath;
pub mod fixed_point;
pub mod fpga;
pub mod measured;
pub mod piecewise;
pub mod routed;
pub mod simulate;
pub mod synth;
pub mod tools;
pub mod verilog;

use std::path::Path;

use alnlab_aln::ModelKind;
use alnlab_aln::pwl::fixed::{self, Widths};
use alnlab_aln::runtime::Trained;
use alnlab_codes::Entry;
use alnlab_common::params::{Count, ParamError};
use alnlab_common::{Error, Progress, Provenance, Result, params};
use alnlab_tables::levels::Levels;
use alnlab_tables::pairs::{Pairs, Side, Split};
use serde::{Deserialize, Serialize};

pub use check::Measurement;
pub use fpga::Device;
pub use synth::{Figures, Part, VariableFigures};
pub use verilog::Circuit;

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 3;
/// File name of the measured figures.
pub const CIRCUIT_FILE: &str = "circuit.parquet";
/// File name of the place-and-route figures.
pub const FPGA_FILE: &str = "fpga.parquet";
/// File name of a piecewise-linear model's fixed-point figures.
pub const FIXED_FILE: &str = "fixed.parquet";

/// The `[circuit]` table of a manifest.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Export the model as Verilog, synthesize it with Yosys and simulate it
    /// with Icarus Verilog on the test rows. Off (the default), the stage
    /// writes an empty table and needs neither program.
    pub synthesize: bool,
    /// The test rows to simulate, the first ones (default: all). A
    /// piecewise-linear model's circuits as written are simulated on every
    /// test row regardless; this bounds the gate-level simulation of their
    /// mapped netlists (by Verilator, a second or two for 8000 rows once
    /// compiled).
    pub rows: Option<Count>,
    /// Also map every variable onto this FPGA (`"ice40-hx8k"`), place and
    /// route it between registers (nextpnr-ice40, seeded by the experiment
    /// seed), read its critical path from timing analysis and simulate the
    /// mapped netlist on the same rows. Off (the default) without it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fpga: Option<Device>,
    /// A piecewise-linear model's input words, in bits (sign, integer and
    /// fractional), for every output; given with `weight_bits`. Unset (the
    /// default), each output takes the narrowest inputs, then weights,
    /// whose error in levels on the training rows is at most 0.005 above
    /// the floating-point model's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub input_bits: Option<u32>,
    /// A piecewise-linear model's weights, in bits (sign and the rest),
    /// for every output; given with `input_bits`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weight_bits: Option<u32>,
}

impl Params {
    /// Placing and routing needs the synthesis it follows; widths come
    /// together, each within what a word can be.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        if self.fpga.is_some() && !self.synthesize {
            return Err((
                "fpga".into(),
                "placing and routing follows synthesis: set `synthesize = true` too".into(),
            ));
        }
        match (self.input_bits, self.weight_bits) {
            (Some(_), None) | (None, Some(_)) => Err((
                "input_bits".into(),
                "give `input_bits` and `weight_bits` together, or neither (each output's \
                 chosen on the training rows)"
                    .into(),
            )),
            (Some(i), _) if !(2..=fixed::MAX_INPUT_BITS).contains(&i) => Err((
                "input_bits".into(),
                format!(
                    "{i}: an input word takes from 2 to {} bits",
                    fixed::MAX_INPUT_BITS
                ),
            )),
            (_, Some(w)) if !(2..=32).contains(&w) => Err((
                "weight_bits".into(),
                format!("{w}: a signed weight takes from 2 to 32 bits"),
            )),
            _ => Ok(()),
        }
    }

    /// The widths given for every output, if any.
    pub fn widths(&self) -> Option<Widths> {
        Some(Widths {
            input_bits: self.input_bits?,
            weight_bits: self.weight_bits?,
        })
    }
}

/// The files the stage reads.
pub struct Inputs<'a> {
    /// The trained model (`model.aln`).
    pub model: &'a Path,
    /// Its codebook.
    pub codebook: &'a Path,
    /// The levels table whose test rows the circuit is checked on.
    pub levels: &'a Path,
    /// The pairs table the levels were made from.
    pub pairs: &'a Path,
}

/// Measures the circuit of the model (`model_path`, trained with
/// `codebook_path`) on the test rows of `levels_path` (a piecewise-linear
/// model on their real values in `pairs_path`). A bit-forest goes into
/// `out_dir/circuit.parquet`: per learned variable and part (`trees`,
/// `votes`, `decode`), gates, inverters and depth in gate levels, and the
/// rows on which both the exported Verilog and the synthesized netlist put
/// out the software's levels (all simulated rows, or the stage fails). A
/// piecewise-linear model goes into `out_dir/fixed.parquet`: its
/// fixed-point form and errors, every output's circuits equal to the
/// fixed-point evaluator on every row. With `fpga`, also
/// `out_dir/fpga.parquet`: every variable placed and routed with
/// nextpnr's `seed`, its mapped netlist equal on the same rows. Without
/// `synthesize`, or for a threshold model (whose binary search is
/// sequential, not one combinational circuit), the tables are empty.
pub fn run(
    params: &Params,
    seed: u64,
    inputs: &Inputs,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let Inputs {
        model: model_path,
        codebook: codebook_path,
        levels: levels_path,
        pairs: pairs_path,
    } = *inputs;
    params
        .validate()
        .map_err(|e| params::invalid("circuit", e))?;
    let path = out_dir.join(CIRCUIT_FILE);
    let fpga_path = out_dir.join(FPGA_FILE);
    let fixed_path = out_dir.join(FIXED_FILE);
    let nothing = || {
        measured::write(&path, None, provenance)?;
        fixed_point::write(&fixed_path, &[], provenance)?;
        routed::write(&fpga_path, None, provenance)
    };
    if !params.synthesize {
        return nothing();
    }
    let trained = Trained::read(model_path, codebook_path)?;
    // A threshold model finds its level by a binary search over repeated
    // evaluations, a sequential circuit this stage does not build.
    let piecewise = match trained.model.header.model {
        ModelKind::Threshold => return nothing(),
        ModelKind::PiecewiseLinear => true,
        ModelKind::BitForest => false,
    };
    let fpga = params.fpga.map(|device| (device, seed));
    let rows = params.rows.map(Count::get);
    let scratch = scratch_in(out_dir)?;
    if piecewise {
        let all = piecewise_rows(&trained, levels_path, pairs_path)?;
        let measured = piecewise::measure(
            &trained,
            &all,
            params.widths(),
            fpga,
            rows,
            scratch.path(),
            progress,
        )?;
        measured::write(&path, None, provenance)?;
        fixed_point::write(&fixed_path, &measured.outputs, provenance)?;
        let routed = measured.placed.map(|[state, pipelined]| routed::Routed {
            state,
            pipelined: Some(pipelined),
            rows_equal: measured.mapped_rows as u64,
        });
        drop(scratch);
        return routed::write(&fpga_path, routed.as_ref(), provenance);
    }
    let (measurement, rows) = measure_test_rows(
        &trained,
        model_path,
        levels_path,
        rows,
        fpga,
        scratch.path(),
        progress,
    )?;
    drop(scratch);
    let measured = measured::Measured {
        figures: measurement.figures,
        rows_equal: rows as u64,
    };
    measured::write(&path, Some(&measured), provenance)?;
    fixed_point::write(&fixed_path, &[], provenance)?;
    let routed = measurement.fpga.map(|state| routed::Routed {
        state,
        pipelined: None,
        rows_equal: rows as u64,
    });
    routed::write(&fpga_path, routed.as_ref(), provenance)
}

/// A folder for the tools' files under `dir` (the stage's unfinished
/// output, which a killed run leaves for the next to remove), removed when
/// dropped.
pub fn scratch_in(dir: &Path) -> Result<tempfile::TempDir> {
    tempfile::Builder::new()
        .prefix("scratch-")
        .tempdir_in(dir)
        .map_err(|e| Error::io(dir, e))
}

/// The rows a piecewise-linear `trained` is measured on: the real values
/// of `pairs_path` (the pairs `levels_path` was made from) on its training
/// rows and its test rows held out of training (the rows the report's
/// errors are on), and their levels.
pub fn piecewise_rows(
    trained: &Trained,
    levels_path: &Path,
    pairs_path: &Path,
) -> Result<piecewise::Rows> {
    let levels = Levels::read(levels_path, &trained.codebook_path)?;
    let pairs = Pairs::read(pairs_path)?;
    levels.check_made_from(&pairs)?;
    let learned: Vec<&Entry> = trained.codebook.learned().collect();
    let values = pairs.values(Side::Current, &learned)?;
    let keys = levels.keys();
    let test: Vec<usize> = levels
        .test_rows()
        .into_iter()
        .filter(|&r| keys[r].split == Split::Test)
        .collect();
    let pick = |rows: &[usize]| -> Vec<Vec<f64>> {
        values
            .iter()
            .map(|column| rows.iter().map(|&r| column[r]).collect())
            .collect()
    };
    let train = levels.train_rows();
    Ok(piecewise::Rows {
        train: pick(&train),
        test: pick(&test),
        train_truth: levels.select(Side::Next, &learned, &train)?,
        truth: levels.select(Side::Next, &learned, &test)?,
        current: levels.select(Side::Current, &learned, &test)?,
    })
}

/// `trained` (read from `model_path`) measured as a circuit on the first
/// `rows` test rows of `levels_path` (all when none), in the folder
/// `scratch` ([`check::measure`]), and placed and routed on `fpga` (a device and
/// nextpnr's seed) when given: what was measured and the rows simulated.
pub fn measure_test_rows(
    trained: &Trained,
    model_path: &Path,
    levels_path: &Path,
    rows: Option<usize>,
    fpga: Option<(Device, u64)>,
    scratch: &Path,
    progress: &dyn Progress,
) -> Result<(Measurement, usize)> {
    let circuit = circuit_of(trained, model_path)?;
    let levels = Levels::read(levels_path, &trained.codebook_path)?;
    let mut test = levels.test_rows();
    if let Some(n) = rows {
        test.truncate(n);
    }
    let learned: Vec<&Entry> = trained.codebook.learned().collect();
    let x = levels.select(Side::Current, &learned, &test)?;
    let expected = trained
        .runtime()
        .map_err(|m| Error::bad_file(model_path, m))?
        .levels(&x, None);
    let measurement = check::measure(
        &circuit,
        &trained.codecs,
        &x,
        &expected,
        fpga,
        scratch,
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
