//! The measured circuit (paper §5): what the circuit stage's
//! `circuit.parquet` says of a variant's model — gates and depth in gate
//! levels of its trees, votes and decoders after synthesis, and the rows
//! on which the simulated circuit equalled the software — set beside the
//! paper's estimate of 13 + 23·2 = 59 gate delays.

use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::Result;

use alnlab_circuit::routed::Routed;

use super::format::{MdTable, sig3};

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

/// The first screen's sentence on variant `name`'s forest in hardware:
/// its ns per state on the FPGA, its gate levels beside the paper's 59 and
/// this model's estimate, and the paper's "nanoseconds" judged.
pub(super) fn in_hardware(name: &str, routed: &Routed, gate_levels: u32, estimate: u64) -> String {
    let state = &routed.state;
    let n = state.variables.len();
    let time = state.critical_ns().map_or_else(
        || format!("has no time for a state: {}", unmeasured(state)),
        |ns| format!("predicts a state in {} ns", sig3(ns)),
    );
    format!(
        "**In hardware** (§5): `{name}`'s forest (replicate 1), each of its {n} variables placed \
         and routed on a {} of its own, {time} — {gate_levels} gate levels against the paper's \
         estimate of {PAPER_DELAYS} and this model's of {estimate} — and equals the software on \
         all {} test rows it was simulated on: the paper's \"nanoseconds\", {}. The hardware \
         table is in the appendix, under `{name}`.",
        state.device.description(),
        routed.rows_equal,
        claim(state.critical_ns())
    )
}

/// The paper's "nanoseconds" for a state's time (none: it does not fit),
/// read as: under a microsecond.
pub(super) fn claim(ns: Option<f64>) -> &'static str {
    match ns {
        Some(ns) if ns < 1000.0 => "confirmed (under a microsecond)",
        Some(_) => "refuted (over a microsecond)",
        None => "not measured on this part",
    }
}

/// The variables of `state` without a critical path, in at most two
/// sentences: those that do not fit their part, and those that fit but
/// nextpnr did not route in time.
pub(super) fn not_fitting(md: &mut String, state: &alnlab_circuit::fpga::State) {
    let (large, unrouted) = without_path(state);
    let _ = match large.as_slice() {
        [] => Ok(()),
        [p] => write!(
            md,
            "`{}` does not fit: it needs up to {} logic cells (its lookup tables and \
             flip-flops), the part has {}. ",
            p.variable, p.logic_cells, p.available
        ),
        many => write!(
            md,
            "{} do not fit: each needs more than the part's {} (its lookup tables and \
             flip-flops, at most). ",
            cells_listed(many),
            many[0].available
        ),
    };
    let minutes = alnlab_circuit::fpga::PLACE_AND_ROUTE_LIMIT.as_secs() / 60;
    let _ = match unrouted.as_slice() {
        [] => Ok(()),
        [p] => write!(
            md,
            "`{}` fits ({} of the part's {} logic cells) but nextpnr did not finish routing \
             it within {minutes} minutes. ",
            p.variable, p.logic_cells, p.available
        ),
        many => write!(
            md,
            "{} fit the part's {} but nextpnr did not finish routing them within {minutes} \
             minutes each. ",
            cells_listed(many),
            many[0].available
        ),
    };
}

/// The variables of `state` without a critical path: those too large for
/// the part, and those that fit but were not routed in time.
fn without_path(
    state: &alnlab_circuit::fpga::State,
) -> (
    Vec<&alnlab_circuit::fpga::Placed>,
    Vec<&alnlab_circuit::fpga::Placed>,
) {
    let (unrouted, large) = state
        .variables
        .iter()
        .filter(|p| p.critical_ns.is_none())
        .partition(|p| p.fits());
    (large, unrouted)
}

/// Variables with their logic cells: "`a` (900 logic cells), `b` (800)
/// and `c` (700)".
fn cells_listed(placed: &[&alnlab_circuit::fpga::Placed]) -> String {
    let names: Vec<String> = placed
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let unit = if i == 0 { " logic cells" } else { "" };
            format!("`{}` ({}{unit})", p.variable, p.logic_cells)
        })
        .collect();
    super::format::and_list(&names)
}

/// How many variables of `state` have no critical path, and why: "3 of
/// its variables are too large for the part", "1 of its variables was not
/// routed in time", or both.
pub(super) fn unmeasured(state: &alnlab_circuit::fpga::State) -> String {
    let (large, unrouted) = without_path(state);
    let (large, unrouted) = (large.len(), unrouted.len());
    let mut parts = Vec::new();
    if large > 0 {
        parts.push(format!(
            "{large} of its variables are too large for the part"
        ));
    }
    if unrouted > 0 {
        parts.push(format!(
            "{unrouted} of its variables were not routed within {} minutes",
            alnlab_circuit::fpga::PLACE_AND_ROUTE_LIMIT.as_secs() / 60
        ));
    }
    parts.join(" and ")
}

/// A variant's CPU figures beside the FPGA's: ns per state on one thread.
pub(super) struct Cpu {
    /// The software ALN in batches…
    pub(super) aln_batched: Option<f64>,
    /// … and one state at a time.
    pub(super) aln_single: Option<f64>,
    /// The simulator setting the ALN's speed is set against (the cheapest
    /// at least as accurate), re-stepping a frame: its name and ns.
    pub(super) simulator: Option<(String, f64)>,
}

/// The forest placed and routed on an FPGA: how, the table of gate levels,
/// lookup-table levels, ns and states per second beside the paper's
/// estimate and the CPU, and whether the paper's "nanoseconds" holds.
/// `gate_levels` is the synthesized circuit's longest path.
pub(super) fn fpga_section(md: &mut String, routed: &Routed, gate_levels: u32, cpu: &Cpu) {
    let state = &routed.state;
    let n = state.variables.len();
    let available = state.variables.first().map_or(0, |p| p.available);
    let _ = writeln!(
        md,
        "**On an FPGA** ({}, {available} logic cells; {}; nextpnr seed {}, the next of at most {} when a placement's routing stalls for {} minutes). Each variable's \
         predictor — its trees, votes and decoder — sits between an input register (filled bit \
         by bit from one pin: a state's code bits outnumber the part's pins) and an output \
         register, on a part of its own: {n} parts side by side, so a state takes the slowest \
         variable's time. Yosys maps the predictor whole onto 4-input lookup tables \
         (`synth_ice40`; trees, votes and decoder optimized together, where the gate count \
         above keeps them apart; adders in lookup tables too) and nextpnr places and routes it. \
         A prediction's latency is the critical path between the registers, from nextpnr's \
         timing analysis at a 1 MHz target clock, so nextpnr did not push timing: an upper \
         bound, for one placement seed. States per second are one per clock, as if the inputs \
         arrived all at once (here they are shifted in one bit per clock). The predictor's \
         mapped netlist — the one placed, without delays; not the post-route netlist — \
         simulated by Icarus Verilog puts out the software's level on every one of the {} test \
         rows for every variable.\n",
        state.device.description(),
        state.tools,
        state.seed,
        alnlab_circuit::fpga::ROUTING_ATTEMPTS,
        alnlab_circuit::fpga::ATTEMPT_LIMIT.as_secs() / 60,
        routed.rows_equal
    );
    let mut table = MdTable::new(&["predictor"]).numbers(&[
        "gate levels",
        "lookup-table levels",
        "ns per state",
        "states per second",
    ]);
    let per_second = |ns: f64| format!("{} million", sig3(1e3 / ns));
    let dash = || "—".to_string();
    table.row(vec![
        "the paper's estimate (§5)".into(),
        PAPER_DELAYS.to_string(),
        dash(),
        dash(),
        dash(),
    ]);
    let ns = state.critical_ns();
    table.row(vec![
        format!(
            "this forest on the {} (each figure its worst variable's, of {n})",
            state.device.description()
        ),
        gate_levels.to_string(),
        state.lut_levels().to_string(),
        ns.map_or_else(dash, sig3),
        ns.map_or_else(dash, per_second),
    ]);
    for (name, figure) in [
        (
            "the software ALN, one CPU thread, every test state at once",
            cpu.aln_batched,
        ),
        (
            "the software ALN, one CPU thread, one state at a time",
            cpu.aln_single,
        ),
    ]
    .into_iter()
    .map(|(name, figure)| (name.to_string(), figure))
    .chain(cpu.simulator.iter().map(|(model, ns)| {
        (
            format!("{model}, one CPU thread, a frame at a time"),
            Some(*ns),
        )
    })) {
        if let Some(cpu_ns) = figure {
            table.row(vec![name, dash(), dash(), sig3(cpu_ns), per_second(cpu_ns)]);
        }
    }
    table.write(md);
    let mut placed: Vec<f64> = state
        .variables
        .iter()
        .filter_map(|p| p.critical_ns)
        .collect();
    placed.sort_by(f64::total_cmp);
    let luts: u64 = state.variables.iter().map(|p| p.luts).sum();
    let largest = state
        .variables
        .iter()
        .map(|p| p.logic_cells)
        .max()
        .unwrap_or(0);
    if let (Some(first), Some(last)) = (placed.first(), placed.last()) {
        let middle = placed.len() / 2;
        let median = if placed.len().is_multiple_of(2) {
            (placed[middle - 1] + placed[middle]) / 2.0
        } else {
            placed[middle]
        };
        let _ = write!(
            md,
            "Per variable, critical paths run from {} to {} ns (median {}); {luts} lookup tables \
             in all, the largest variable taking {largest} of the part's {available} logic cells. ",
            sig3(*first),
            sig3(*last),
            sig3(median),
        );
    }
    not_fitting(md, state);
    let software = match (cpu.aln_batched, cpu.aln_single) {
        (Some(batched), Some(single)) => format!(
            ", where the software ALN on one CPU thread takes {} ns per state with every test \
             state at once and {} ns one state at a time",
            sig3(batched),
            sig3(single)
        ),
        _ => String::new(),
    };
    let verdict = match (ns, state.slowest()) {
        (Some(ns), Some(slowest)) => format!(
            "**The paper's \"nanoseconds\" is {}:** a state in {} ns on this part (the slowest \
             variable, `{}`, through {} lookup tables){software}.",
            claim(Some(ns)),
            sig3(ns),
            slowest.variable,
            slowest.lut_levels
        ),
        _ => format!(
            "**The paper's \"nanoseconds\" is {}:** {}.",
            claim(None),
            unmeasured(state)
        ),
    };
    let _ = writeln!(md, "{verdict}\n");
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use alnlab_circuit::datapath::Form;
    use alnlab_circuit::fpga::{Device, Placed, State};

    /// A state placed and routed, one variable per critical path (none:
    /// it does not fit), combinational.
    pub(in super::super) fn routed(ns: &[Option<f64>]) -> Routed {
        let variables = ns
            .iter()
            .enumerate()
            .map(|(i, &ns)| Placed {
                variable: format!("v.{i}.x"),
                luts: 500 + i as u64,
                lut_levels: 5 + i as u32,
                logic_cells: if ns.is_some() { 520 } else { 9000 },
                available: 7680,
                critical_ns: ns,
                carries: 40,
                flip_flops: 30,
                latency: 0,
                seed: 7,
            })
            .collect();
        Routed {
            state: State {
                device: Device::Ice40Hx8k,
                form: Form::Combinational,
                seed: 7,
                tools: "tools".into(),
                variables,
            },
            pipelined: None,
            rows_equal: 300,
        }
    }

    pub(in super::super) fn cpu() -> Cpu {
        Cpu {
            aln_batched: Some(1550.0),
            aln_single: Some(7870.0),
            simulator: Some(("simulator@2/frame".into(), 2590.0)),
        }
    }

    #[test]
    fn a_state_in_nanoseconds_confirms_the_paper_with_its_slowest_variable() {
        let mut md = String::new();
        fpga_section(
            &mut md,
            &routed(&[Some(8.5), Some(10.75), Some(4.25)]),
            14,
            &cpu(),
        );
        assert!(md.contains("on every one of the 300 test rows"), "{md}");
        assert!(md.contains("| 59 |"), "{md}");
        assert!(md.contains("| 14 | 7 | 10.8 | 93.0 million |"), "{md}");
        assert!(md.contains("| 1550 | 0.645 million |"), "{md}");
        assert!(md.contains("from 4.25 to 10.8 ns (median 8.50)"), "{md}");
        assert!(md.contains("3 parts side by side"), "{md}");
        assert!(
            md.contains(
                "is confirmed (under a microsecond):** a state in 10.8 ns on this part (the \
                 slowest variable, `v.1.x`, through 6 lookup tables), where the software ALN on \
                 one CPU thread takes 1550 ns per state with every test state at once and 7870 ns \
                 one state at a time"
            ),
            "{md}"
        );
    }

    #[test]
    fn the_first_screen_says_the_state_in_ns_and_judges_the_claim() {
        let line = in_hardware("gray", &routed(&[Some(8.5), Some(10.75)]), 21, 29);
        assert!(
            line.contains(
                "`gray`'s forest (replicate 1), each of its 2 variables placed and routed on a \
                 Lattice iCE40 HX8K of its own, predicts a state in 10.8 ns — 21 gate levels \
                 against the paper's estimate of 59 and this model's of 29"
            ),
            "{line}"
        );
        assert!(line.contains("all 300 test rows"), "{line}");
        assert!(
            line.contains("\"nanoseconds\", confirmed (under a microsecond)"),
            "{line}"
        );
        let line = in_hardware("gray", &routed(&[Some(8.5), None]), 21, 29);
        assert!(
            line.contains("has no time for a state: 1 of its variables are too large"),
            "{line}"
        );
        assert!(line.contains("not measured on this part"), "{line}");
    }

    #[test]
    fn a_variable_that_does_not_fit_is_named_and_leaves_the_claim_unmeasured() {
        let mut md = String::new();
        fpga_section(&mut md, &routed(&[Some(8.5), None]), 14, &cpu());
        assert!(md.contains(
            "`v.1.x` does not fit: it needs up to 9000 logic cells (its lookup tables and \
             flip-flops), the part has 7680"
        ));
        assert!(
            md.contains("not measured on this part:** 1 of its variables are too large"),
            "{md}"
        );
        // One that fits but was not routed in time is told apart.
        let mut unrouted = routed(&[Some(8.5), None]);
        unrouted.state.variables[1].logic_cells = 7000;
        let mut md = String::new();
        fpga_section(&mut md, &unrouted, 14, &cpu());
        assert!(
            md.contains(
                "`v.1.x` fits (7000 of the part's 7680 logic cells) but nextpnr did not finish \
                 routing it within 15 minutes"
            ),
            "{md}"
        );
        assert!(
            md.contains("1 of its variables were not routed within 15 minutes"),
            "{md}"
        );
    }

    #[test]
    fn several_variables_without_a_path_are_listed_in_one_sentence_per_reason() {
        let mut state = routed(&[Some(8.5), None, None, None, None]).state;
        state.variables[3].logic_cells = 7000;
        state.variables[4].logic_cells = 6100;
        let mut md = String::new();
        not_fitting(&mut md, &state);
        assert_eq!(
            md,
            "`v.1.x` (9000 logic cells) and `v.2.x` (9000) do not fit: each needs more than \
             the part's 7680 (its lookup tables and flip-flops, at most). `v.3.x` (7000 logic \
             cells) and `v.4.x` (6100) fit the part's 7680 but nextpnr did not finish routing \
             them within 15 minutes each. "
        );
    }
}
