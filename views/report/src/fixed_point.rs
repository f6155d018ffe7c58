//! A piecewise-linear model in hardware: what the circuit stage's
//! `fixed.parquet` and `fpga.parquet` say of it — its fixed-point form and
//! error beside the floating-point model's and persistence's, and its
//! circuits placed and routed (combinational for latency, pipelined for
//! throughput) beside the CPU and any bit-forest of the same run — and
//! whether the paper's "nanoseconds" holds for a model that beats
//! persistence.

use std::fmt::Write as _;

use alnlab_circuit::fpga::State;
use alnlab_circuit::piecewise::{OutputFigures, TOLERANCE};
use alnlab_circuit::routed::Routed;

use super::Loaded;
use super::circuit::{Cpu, claim, not_fitting, unmeasured};
use super::format::{MdTable, sig3};

/// The fastest bit-forest of `variants` placed and routed whole: its
/// variant's name and ns per state.
pub(super) fn routed_forest<'a>(variants: &'a [Loaded]) -> Option<(&'a str, f64)> {
    variants
        .iter()
        .filter(|v| v.circuit.is_some())
        .filter_map(|v| Some((v.info.name.as_str(), v.fpga.as_ref()?.state.critical_ns()?)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Means over the outputs of the fixed-point figures.
struct Errors {
    fixed: f64,
    float: f64,
    persistence: f64,
    difference: f64,
}

fn errors(fixed: &[OutputFigures]) -> Errors {
    let n = fixed.len().max(1) as f64;
    let mean = |f: fn(&OutputFigures) -> f64| fixed.iter().map(f).sum::<f64>() / n;
    Errors {
        fixed: mean(|o| o.fixed_error),
        float: mean(|o| o.float_error),
        persistence: mean(|o| o.persistence_error),
        difference: mean(|o| o.test_difference),
    }
}

/// The most clocks from inputs to level over `state`'s variables.
fn clocks(state: &State) -> u32 {
    state.variables.iter().map(|p| p.latency).max().unwrap_or(0)
}

/// The pipelined state's figures: the slowest clock (ns), the most clocks
/// from inputs to level, and the longest latency (ns) — each variable on
/// a part of its own, at its own clock.
fn pipelined(state: &State) -> Option<(f64, u32, f64)> {
    let period = state.critical_ns()?;
    let clocks = clocks(state);
    let latency = state
        .variables
        .iter()
        .filter_map(|p| Some(p.critical_ns? * f64::from(p.latency)))
        .fold(0.0, f64::max);
    Some((period, clocks, latency))
}

/// The test rows a mapped netlist was simulated on, of `all`.
fn rows_simulated(mapped: u64, all: u64) -> String {
    if mapped == all {
        format!("every one of the {all} test rows")
    } else {
        format!("the first {mapped} of the {all} test rows")
    }
}

/// Whether `state`'s variables, side by side, would fit one part: their
/// logic cells against the part's.
fn one_part(state: &State) -> String {
    let cells: u64 = state.variables.iter().map(|p| p.logic_cells).sum();
    let available = state.variables.first().map_or(0, |p| p.available).max(1);
    if cells <= available {
        format!("the whole state, {cells} logic cells, fits one part")
    } else {
        format!(
            "the whole state, {cells} logic cells, would take at least {} parts like this one",
            cells.div_ceil(available)
        )
    }
}

/// Whether the fixed-point model errs less than persistence on these rows
/// — the mean errors of one replicate, not a verdict: the floating-point
/// model's, with its interval across replicates, is the summary's.
fn against_persistence(e: &Errors) -> &'static str {
    if e.fixed < e.persistence {
        "a model that errs less than persistence on these rows"
    } else {
        "a model that errs no less than persistence on these rows"
    }
}

/// The first screen's sentence on variant `name`'s piecewise-linear model
/// in hardware: ns per state combinational, states per second pipelined,
/// its fixed-point error beside the float model's and persistence's, and
/// the paper's "nanoseconds" judged.
pub(super) fn in_hardware(name: &str, fixed: &[OutputFigures], routed: &Routed) -> String {
    let e = errors(fixed);
    let state = &routed.state;
    let n = state.variables.len();
    let combinational = |ns: f64| {
        format!(
            "predicts a state in {} ns as a combinational circuit between registers (nextpnr's \
             timing analysis)",
            sig3(ns)
        )
    };
    let time = match (
        state.critical_ns(),
        routed.pipelined.as_ref().and_then(pipelined),
    ) {
        (Some(ns), Some((period, clocks, latency))) => format!(
            "{}, and pipelined (at most {clocks} clocks, a state in {} ns) {} million states a \
             second",
            combinational(ns),
            sig3(latency),
            sig3(1e3 / period)
        ),
        (Some(ns), None) => match &routed.pipelined {
            Some(p) => format!(
                "{}; pipelined, {}, so it has no rate",
                combinational(ns),
                unmeasured(p)
            ),
            None => combinational(ns),
        },
        (None, _) => format!("has no time for a state: {}", unmeasured(state)),
    };
    format!(
        "**In hardware** (§5): `{name}`'s piecewise-linear model in fixed point (replicate 1), \
         each of its {n} variables placed and routed on a {} of its own ({n} parts), {time}; \
         in fixed point \
         it errs {} levels against the floating-point model's {} and persistence's {}, and its \
         mapped netlists equal its fixed-point evaluator on {}: the paper's \"nanoseconds\", \
         for {}, {}. The hardware table is in the appendix, under `{name}`.",
        state.device.description(),
        sig3(e.fixed),
        sig3(e.float),
        sig3(e.persistence),
        rows_simulated(routed.rows_equal, fixed.first().map_or(0, |o| o.rows)),
        against_persistence(&e),
        claim(state.critical_ns())
    )
}

/// The fixed-point form and, when placed and routed, the hardware table:
/// error, lookup tables, ns per state and states per second of both
/// circuits beside the CPU, persistence and `forest` (another variant's
/// bit-forest on the same part: its name and ns per state).
pub(super) fn section(
    md: &mut String,
    fixed: &[OutputFigures],
    routed: Option<&Routed>,
    cpu: &Cpu,
    forest: Option<(&str, f64)>,
) {
    let e = errors(fixed);
    let n = fixed.len();
    let range = |f: fn(&OutputFigures) -> u32| {
        let lo = fixed.iter().map(f).min().unwrap_or(0);
        let hi = fixed.iter().map(f).max().unwrap_or(0);
        let mut sorted: Vec<u32> = fixed.iter().map(f).collect();
        sorted.sort_unstable();
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0);
        format!("{median} (from {lo} to {hi})")
    };
    let _ = writeln!(
        md,
        "**In fixed point** (replicate 1; the circuit's arithmetic, exact in software). Each of \
         the {n} variables reads its inputs as signed words in level spacings from a level in \
         the middle of the training rows' — input words of {} bits — and keeps {} significant \
         bits of each weight; a piece's products drop fractional bits below three finer than \
         its inputs'. The widths are chosen per variable on the training rows: the narrowest \
         inputs, then weights, whose training error is at most {TOLERANCE} levels above the \
         floating-point model's. On the {} test rows the fixed-point model errs **{} levels** \
         against the floating-point model's {} and persistence's {} (means over the variables), \
         its levels differing from the floating-point model's by {} on average; both circuits of \
         every variable, as written, simulated by Icarus Verilog, put out its level on every one \
         of them.\n",
        range(|o| o.widths.input_bits),
        range(|o| o.widths.weight_bits),
        fixed.first().map_or(0, |o| o.rows),
        sig3(e.fixed),
        sig3(e.float),
        sig3(e.persistence),
        sig3(e.difference),
    );
    let Some(routed) = routed else {
        return;
    };
    let state = &routed.state;
    let available = state.variables.first().map_or(0, |p| p.available);
    let n = state.variables.len();
    let _ = writeln!(
        md,
        "**On an FPGA** ({}, {available} logic cells, no multipliers; {}; nextpnr seed {}, the next of at most {} when a placement's routing stalls for {} minutes). Each \
         variable's predictor is its pieces as shifts and adds of its input words (a weight's \
         signed digits, summed by a balanced tree of adders on the part's carry chains), its \
         MIN/MAX tree as comparators and multiplexers, and the answer added to the current word, \
         rounded and clamped to a level — built twice: combinational between an input and an \
         output register (its latency the critical path from nextpnr's timing analysis at a 1 \
         MHz target, an upper bound for one seed), and pipelined, a register after every adder \
         and comparator (one state a clock). Each variable takes a part of its own, so a state \
         waits for the slowest: combinational, the slowest variable's path; pipelined, each \
         variable at its own clock, the rate the slowest clock's and the latency the longest \
         variable's (its clocks times its period). {} lookup tables over all {n} variables \
         combinational: {}. Both mapped netlists — the ones placed, without delays — \
         simulated by Verilator put out the fixed-point evaluator's level on {} for every \
         variable.\n",
        state.device.description(),
        state.tools,
        state.seed,
        alnlab_circuit::fpga::ROUTING_ATTEMPTS,
        alnlab_circuit::fpga::ATTEMPT_LIMIT.as_secs() / 60,
        state.variables.iter().map(|p| p.luts).sum::<u64>(),
        one_part(state),
        rows_simulated(routed.rows_equal, fixed.first().map_or(0, |o| o.rows)),
    );
    let mut table = MdTable::new(&["predictor"]).numbers(&[
        "error (levels)",
        "lookup tables (largest variable)",
        "ns per state (latency)",
        "states per second",
    ]);
    let dash = || "—".to_string();
    let per_second = |ns: f64| format!("{} million", sig3(1e3 / ns));
    let largest = |s: &State| {
        s.variables
            .iter()
            .map(|p| p.luts)
            .max()
            .unwrap_or(0)
            .to_string()
    };
    let ns = state.critical_ns();
    table.row(vec![
        format!(
            "fixed point, combinational, on the {}",
            state.device.description()
        ),
        sig3(e.fixed),
        largest(state),
        ns.map_or_else(dash, sig3),
        ns.map_or_else(dash, per_second),
    ]);
    if let Some(p) = &routed.pipelined {
        let figures = pipelined(p);
        table.row(vec![
            format!("fixed point, pipelined (at most {} clocks)", clocks(p)),
            sig3(e.fixed),
            largest(p),
            figures.map_or_else(dash, |f| sig3(f.2)),
            figures.map_or_else(dash, |f| per_second(f.0)),
        ]);
    }
    if let Some((name, ns)) = forest {
        table.row(vec![
            format!("`{name}`'s bit-forest on the same part"),
            dash(),
            dash(),
            sig3(ns),
            per_second(ns),
        ]);
    }
    for (name, figure) in [
        (
            "floating point, one CPU thread, every test state at once (ns: the batch's time over its states)",
            cpu.aln_batched,
        ),
        (
            "floating point, one CPU thread, one state at a time",
            cpu.aln_single,
        ),
    ] {
        if let Some(cpu_ns) = figure {
            table.row(vec![
                name.into(),
                sig3(e.float),
                dash(),
                sig3(cpu_ns),
                per_second(cpu_ns),
            ]);
        }
    }
    if let Some((model, ns)) = &cpu.simulator {
        table.row(vec![
            format!("{model}, one CPU thread, a frame at a time"),
            dash(),
            dash(),
            sig3(*ns),
            per_second(*ns),
        ]);
    }
    table.row(vec![
        "persistence (no change)".into(),
        sig3(e.persistence),
        dash(),
        dash(),
        dash(),
    ]);
    table.write(md);
    not_fitting(md, state);
    if let Some(p) = routed
        .pipelined
        .as_ref()
        .filter(|p| p.critical_ns().is_none())
    {
        md.push_str("Pipelined, a register after every operation: ");
        not_fitting(md, p);
    }
    let verdict = match (ns, state.slowest()) {
        (Some(ns), Some(slowest)) => format!(
            "**The paper's \"nanoseconds\", for {}, is {}:** a state in {} ns on this part (the \
             slowest variable, `{}`, {} lookup tables and {} carry cells, through {} lookup \
             tables).",
            against_persistence(&e),
            claim(Some(ns)),
            sig3(ns),
            slowest.variable,
            slowest.luts,
            slowest.carries,
            slowest.lut_levels
        ),
        _ => format!(
            "**The paper's \"nanoseconds\", for {}, is {}:** {}.",
            against_persistence(&e),
            claim(None),
            unmeasured(state)
        ),
    };
    let _ = writeln!(md, "{verdict}\n");
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::circuit::tests::{cpu, routed};
    use alnlab_aln::pwl::fixed::Widths;
    use alnlab_circuit::datapath::Form;

    fn output(variable: &str, fixed: f64, float: f64, persistence: f64) -> OutputFigures {
        OutputFigures {
            variable: variable.into(),
            widths: Widths {
                input_bits: 13,
                weight_bits: 6,
            },
            input_frac: 5,
            weight_frac: 14,
            piece_bits: 20,
            pieces: 16,
            inputs: 5,
            train_difference: 0.05,
            test_difference: 0.06,
            fixed_error: fixed,
            float_error: float,
            persistence_error: persistence,
            rows: 8000,
        }
    }

    /// Combinational at 90 and 110 ns; pipelined at 5 and 6 ns a clock,
    /// 12 and 20 clocks deep.
    fn both() -> Routed {
        let mut routed = routed(&[Some(90.0), Some(110.0)]);
        let mut pipelined = State {
            form: Form::Pipelined,
            ..routed.state.clone()
        };
        for (p, (ns, clocks)) in pipelined.variables.iter_mut().zip([(5.0, 12), (6.0, 20)]) {
            p.critical_ns = Some(ns);
            p.latency = clocks;
        }
        routed.pipelined = Some(pipelined);
        routed
    }

    #[test]
    fn the_table_sets_both_circuits_beside_the_cpu_and_persistence() {
        let fixed = [
            output("v.0.x", 0.80, 0.79, 1.1),
            output("v.1.x", 0.70, 0.71, 1.3),
        ];
        let mut md = String::new();
        section(
            &mut md,
            &fixed,
            Some(&both()),
            &cpu(),
            Some(("strongest", 13.6)),
        );
        // Means over the variables; 13 and 6 bits for every one.
        assert!(
            md.contains(
                "errs **0.750 levels** against the floating-point model's 0.750 and persistence's 1.20"
            ),
            "{md}"
        );
        assert!(
            md.contains("input words of 13 (from 13 to 13) bits"),
            "{md}"
        );
        assert!(md.contains("| fixed point, combinational, on the Lattice iCE40 HX8K | 0.750 | 501 | 110 | 9.09 million |"), "{md}");
        // Pipelined: the slowest clock (6 ns) sets the rate; the latency is
        // the longest, 20 clocks of 6 ns.
        assert!(
            md.contains(
                "| fixed point, pipelined (at most 20 clocks) | 0.750 | 501 | 120 | 167 million |"
            ),
            "{md}"
        );
        assert!(
            md.contains(
                "| `strongest`'s bit-forest on the same part | — | — | 13.6 | 73.5 million |"
            ),
            "{md}"
        );
        assert!(
            md.contains("| persistence (no change) | 1.20 | — | — | — |"),
            "{md}"
        );
        assert!(
            md.contains("on the first 300 of the 8000 test rows"),
            "{md}"
        );
        assert!(
            md.contains("1001 lookup tables over all 2 variables combinational: the whole state, 1040 logic cells, fits one part"),
            "{md}"
        );
        assert!(md.contains("for a model that errs less than persistence on these rows, is confirmed (under a microsecond):** a state in 110 ns"), "{md}");
        let line = in_hardware("pw", &fixed, &both());
        assert!(line.contains("predicts a state in 110 ns as a combinational circuit between registers (nextpnr's timing analysis), and pipelined (at most 20 clocks, a state in 120 ns) 167 million states a second"), "{line}");
    }

    #[test]
    fn a_variable_that_does_not_fit_leaves_the_state_unmeasured() {
        let fixed = [
            output("v.0.x", 1.9, 0.79, 1.1),
            output("v.1.x", 0.70, 0.71, 1.3),
        ];
        let routed = routed(&[Some(90.0), None]);
        let mut md = String::new();
        section(&mut md, &fixed, Some(&routed), &cpu(), None);
        assert!(
            md.contains("`v.1.x` does not fit: it needs up to 9000 logic cells"),
            "{md}"
        );
        assert!(
            md.contains(
                "the whole state, 9520 logic cells, would take at least 2 parts like this one"
            ),
            "{md}"
        );
        assert!(md.contains("for a model that errs no less than persistence on these rows, is not measured on this part:** 1 of its variables are too large for the part"), "{md}");
        let line = in_hardware("pw", &fixed, &routed);
        assert!(
            line.contains("has no time for a state: 1 of its variables are too large"),
            "{line}"
        );
    }

    #[test]
    fn a_pipelined_variable_that_does_not_fit_is_named_and_leaves_no_rate() {
        let fixed = [
            output("v.0.x", 0.80, 0.79, 1.1),
            output("v.1.x", 0.70, 0.71, 1.3),
        ];
        let mut routed = both();
        let pipelined = routed.pipelined.as_mut().unwrap();
        pipelined.variables[1].critical_ns = None;
        pipelined.variables[1].logic_cells = 9000;
        let mut md = String::new();
        section(&mut md, &fixed, Some(&routed), &cpu(), None);
        assert!(
            md.contains("| fixed point, pipelined (at most 20 clocks) | 0.750 | 501 | — | — |"),
            "{md}"
        );
        assert!(
            md.contains(
                "Pipelined, a register after every operation: `v.1.x` does not fit: it needs up \
                 to 9000 logic cells"
            ),
            "{md}"
        );
        // The combinational state is measured: the verdict stands on it.
        assert!(
            md.contains("is confirmed (under a microsecond):** a state in 110 ns"),
            "{md}"
        );
        let line = in_hardware("pw", &fixed, &routed);
        assert!(
            line.contains(
                "predicts a state in 110 ns as a combinational circuit between registers \
                 (nextpnr's timing analysis); pipelined, 1 of its variables are \
                 too large for the part, so it has no rate;"
            ),
            "{line}"
        );
    }
}
