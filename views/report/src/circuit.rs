//! The measured circuit (paper §5): what the circuit stage's
//! `circuit.parquet` says of a variant's model — gates and depth in gate
//! levels of its trees, votes and decoders after synthesis, and the rows
//! on which the simulated circuit equalled the software — set beside the
//! paper's estimate of 13 + 23·2 = 59 gate delays.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::Result;

use super::format::MdTable;

/// The paper's estimate for its model (§5): 13 levels of a tree of 8192
/// leaves, then twice the 23 bits of a code to decode it.
pub(super) const PAPER_DELAYS: u32 = 59;
/// … of which decoding.
const PAPER_DECODE: u32 = 46;

/// Gates and depth of one part, over all variables.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Part {
    pub(super) cells: u64,
    pub(super) inverters: u64,
    /// The deepest variable's.
    pub(super) depth: u32,
}

/// A model's measured circuit.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Measured {
    pub(super) trees: Part,
    pub(super) votes: Part,
    pub(super) decode: Part,
    /// The longest path from input bits to a level: the deepest variable's
    /// trees + votes + decoder.
    pub(super) depth: u32,
    /// … its parts, and which variable.
    pub(super) deepest: (String, u32, u32, u32),
    pub(super) variables: usize,
    /// The test rows simulated, every variable equal to the software.
    pub(super) rows_equal: u64,
    pub(super) tools: String,
    pub(super) library: String,
}

impl Measured {
    /// All gates.
    pub(super) fn cells(&self) -> u64 {
        self.trees.cells + self.votes.cells + self.decode.cells
    }
}

/// Reads `circuit.parquet` ([`alnlab_circuit::measured`]); none when the
/// stage measured nothing (`[circuit] synthesize` off, or a threshold
/// model).
pub(super) fn read(path: &Path) -> Result<Option<Measured>> {
    let Some(measured) = alnlab_circuit::measured::read(path)? else {
        return Ok(None);
    };
    let f = &measured.figures;
    let part = |p: alnlab_circuit::synth::Part| Part {
        cells: p.cells,
        inverters: p.inverters,
        depth: p.depth,
    };
    let mut m = Measured {
        trees: part(f.part(|v| v.trees)),
        votes: part(f.part(|v| v.votes)),
        decode: part(f.part(|v| v.decode)),
        depth: 0,
        deepest: (String::new(), 0, 0, 0),
        variables: f.variables.len(),
        rows_equal: measured.rows_equal,
        tools: f.tools.clone(),
        library: f.library.clone(),
    };
    // The deepest variable, the first of equals.
    for v in &f.variables {
        if m.deepest.0.is_empty() || v.depth() > m.depth {
            m.depth = v.depth();
            m.deepest = (
                v.variable.clone(),
                v.trees.depth,
                v.votes.depth,
                v.decode.depth,
            );
        }
    }
    Ok(Some(m))
}

/// The section's measured part: the table of parts and the comparison
/// with the paper's estimate. `pruned` is the exported trees' AND/OR gates
/// and their greatest depth; `estimate` this model's §5 estimate.
pub(super) fn section(md: &mut String, m: &Measured, pruned: (u64, u32), estimate: u64) {
    let _ = writeln!(
        md,
        "**Measured** ({}): the pruned trees, exported as Verilog, hold {} AND/OR gates, at most \
         {} deep. Synthesized by Yosys into {} (each one gate delay; logic optimized and mapped \
         for the least delay, each variable's trees, votes and decoder kept apart):\n",
        m.tools, pruned.0, pruned.1, m.library
    );
    let mut table =
        MdTable::new(&["part"]).numbers(&["gates", "of them inverters", "depth (gate levels)"]);
    let mut row = |name: &str, p: &Part| {
        table.row(vec![
            name.into(),
            p.cells.to_string(),
            p.inverters.to_string(),
            p.depth.to_string(),
        ])
    };
    row("trees (all; depth: the deepest)", &m.trees);
    row("votes (majority gates)", &m.votes);
    row("decoding (code bits to level)", &m.decode);
    table.row(vec![
        format!("the whole state ({} variables)", m.variables),
        m.cells().to_string(),
        (m.trees.inverters + m.votes.inverters + m.decode.inverters).to_string(),
        m.depth.to_string(),
    ]);
    table.write(md);
    let (variable, trees, votes, decode) = &m.deepest;
    let _ = write!(
        md,
        "The longest path from the input bits to a predicted level is **{} gate levels** (`{}`: \
         trees {}, votes {}, decoding {}), beside the paper's estimate of {PAPER_DELAYS} and this \
         model's of {estimate}. ",
        m.depth, variable, trees, votes, decode
    );
    if m.depth > PAPER_DELAYS {
        let over = if *decode > PAPER_DECODE {
            format!("the decoding ({decode} levels against the paper's 2·23 = {PAPER_DECODE})")
        } else {
            format!(
                "the trees and votes ({} levels against the paper's 13)",
                trees + votes
            )
        };
        let _ = write!(
            md,
            "Over the paper's {PAPER_DELAYS} by {} levels: the excess is in {over}. ",
            m.depth - PAPER_DELAYS
        );
    } else {
        let _ = write!(md, "Within the paper's {PAPER_DELAYS}. ");
    }
    let _ = writeln!(
        md,
        "The exported Verilog and the synthesized netlist, simulated by Icarus Verilog, put out \
         the software's level on every one of the {} test rows for every variable.\n",
        m.rows_equal
    );
}
