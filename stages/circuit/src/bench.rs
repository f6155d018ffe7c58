//! `alnlab bench circuit`: a run's model measured as a circuit — the
//! stage's measurement on its test rows, with the totals a reader compares
//! with the paper's estimate, and how long synthesis and simulation took;
//! for a piecewise-linear model, the trade between its fixed-point widths
//! and its error and arithmetic, and its circuits placed and routed.

use std::path::Path;
use std::time::Instant;

use alnlab_aln::runtime::Trained;
use alnlab_common::{Progress, Result};
use serde::Serialize;

use alnlab_aln::pwl::fixed::Widths;

use crate::fpga::{self, Device};
use crate::piecewise::{self, Trade};
use crate::synth::{Figures, Part};
use crate::{Measurement, measure_test_rows};

/// The paper's estimate (§5): 13 + 23·2 gate delays.
pub const PAPER_DELAYS: u32 = 59;

/// The figures of `alnlab bench circuit`.
#[derive(Debug, Serialize)]
pub struct Bench {
    /// Test rows simulated, every variable equal to the software on each.
    pub rows: usize,
    /// The longest path from input bits to a level, in gate levels.
    pub depth: u32,
    /// … in which variable, split into its trees, votes and decoding.
    pub deepest: String,
    pub deepest_parts: [u32; 3],
    /// The paper's estimate, for comparison.
    pub paper_estimate: u32,
    /// All gates.
    pub cells: u64,
    /// Per part, over all variables (depth: the deepest).
    pub trees: Part,
    pub votes: Part,
    pub decode: Part,
    /// Wall time of reading the rows, export, synthesis, simulations and,
    /// with `fpga`, mapping, placing and routing (all threads).
    pub seconds: f64,
    pub threads: usize,
    /// Per variable.
    pub figures: Figures,
    /// Placed and routed on an FPGA, when asked: every variable's critical
    /// path in ns (its mapped netlist simulated on the same rows).
    pub fpga: Option<fpga::State>,
    /// The state's time on the FPGA: the slowest variable's critical path
    /// (ns); none without `fpga`, or when a variable does not fit.
    pub fpga_ns_per_state: Option<f64>,
}

/// Measures the model at `model` (trained with `codebook`) on the first
/// `rows` test rows of `levels` (all when none); with `fpga`, also places
/// and routes every variable on that device with that nextpnr seed. The
/// tools' files go into a folder under `scratch`, removed when done.
pub fn on_run(
    model: &Path,
    codebook: &Path,
    levels: &Path,
    rows: Option<usize>,
    fpga: Option<(Device, u64)>,
    scratch: &Path,
    progress: &dyn Progress,
) -> Result<Bench> {
    let trained = Trained::read(model, codebook)?;
    let start = Instant::now();
    let scratch = crate::scratch_in(scratch)?;
    let (measurement, rows) = measure_test_rows(
        &trained,
        model,
        levels,
        rows,
        fpga,
        scratch.path(),
        progress,
    )?;
    let seconds = start.elapsed().as_secs_f64();
    let Measurement { figures, fpga } = measurement;
    let deepest = figures.deepest().expect("a model predicts a variable");
    Ok(Bench {
        rows,
        depth: figures.depth(),
        deepest: deepest.variable.clone(),
        deepest_parts: [
            deepest.trees.depth,
            deepest.votes.depth,
            deepest.decode.depth,
        ],
        paper_estimate: PAPER_DELAYS,
        cells: figures.cells(),
        trees: figures.part(|v| v.trees),
        votes: figures.part(|v| v.votes),
        decode: figures.part(|v| v.decode),
        seconds,
        threads: rayon::current_num_threads(),
        figures,
        fpga_ns_per_state: fpga.as_ref().and_then(fpga::State::critical_ns),
        fpga,
    })
}

/// The figures of `alnlab bench circuit` for a piecewise-linear model.
#[derive(Debug, Serialize)]
pub struct PiecewiseBench {
    /// The trade between width and error: the chosen widths first, then
    /// every width asked for at once for every output.
    pub trade: Vec<Trade>,
    /// With `fpga`: the chosen fixed-point model's circuits placed and
    /// routed, per output.
    pub outputs: Vec<piecewise::OutputFigures>,
    pub placed: Option<[fpga::State; 2]>,
    /// Test rows the mapped netlists were simulated equal on.
    pub mapped_rows: usize,
    /// The state's time: combinational, the slowest variable's critical
    /// path; pipelined, the slowest clock (ns).
    pub ns_per_state: Option<f64>,
    pub pipelined_clock_ns: Option<f64>,
    /// Wall time of choosing, tabulating and, with `fpga`, writing,
    /// mapping, placing, routing and simulating (all threads).
    pub seconds: f64,
    pub threads: usize,
}

/// Measures the piecewise-linear model at `model` (trained with
/// `codebook`) on the rows of `levels` and `pairs`: its fixed-point trade
/// at the chosen widths and at each of `widths`; with `fpga`, its circuits
/// placed and routed, their mapped netlists simulated on the first `rows`
/// test rows (all when none). The tools' files go into a folder under
/// `scratch`, removed when done.
#[allow(clippy::too_many_arguments)]
pub fn piecewise_on_run(
    (model, codebook, levels, pairs): (&Path, &Path, &Path, &Path),
    widths: &[Widths],
    rows: Option<usize>,
    fpga: Option<(Device, u64)>,
    scratch: &Path,
    progress: &dyn Progress,
) -> Result<PiecewiseBench> {
    let trained = Trained::read(model, codebook)?;
    let start = Instant::now();
    let all = crate::piecewise_rows(&trained, levels, pairs)?;
    let trade = piecewise::trade(&trained, &all, widths)?;
    let measured = match fpga {
        Some(fpga) => {
            let scratch = crate::scratch_in(scratch)?;
            let m = piecewise::measure(
                &trained,
                &all,
                None,
                Some(fpga),
                rows,
                scratch.path(),
                progress,
            )?;
            Some(m)
        }
        None => None,
    };
    let (outputs, placed, mapped_rows) = measured.map_or((Vec::new(), None, 0), |m| {
        (m.outputs, m.placed, m.mapped_rows)
    });
    Ok(PiecewiseBench {
        trade,
        ns_per_state: placed.as_ref().and_then(|[c, _]| c.critical_ns()),
        pipelined_clock_ns: placed.as_ref().and_then(|[_, p]| p.critical_ns()),
        outputs,
        placed,
        mapped_rows,
        seconds: start.elapsed().as_secs_f64(),
        threads: rayon::current_num_threads(),
    })
}
