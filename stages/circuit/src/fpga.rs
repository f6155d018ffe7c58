//! Gate levels turned into nanoseconds: each learned variable's predictor
//! placed and routed on an iCE40 FPGA, its clock from timing analysis.
//!
//! The variable's module (its trees, votes and decoder, combinational) sits
//! between an input register and an output register, so the only path that
//! matters is register → predictor → register. The input register is a
//! shift register fed from one pin — a state's hundreds of code bits cannot
//! all be pins (the HX8K's largest package has 206) — and the output
//! register folds to one pin by XOR, which keeps every output bit live.
//! Yosys maps the design onto 4-input lookup tables (`synth_ice40`), the
//! predictor kept a module of its own (`keep_hierarchy`) so that its mapped
//! netlist, which [`crate::check`] simulates on the test rows, is the very
//! logic placed; nextpnr places and routes it (seeded) and its timing
//! analysis gives the maximum clock: the critical path is one period. The
//! clock asked for is 1 MHz, so nextpnr does not push timing and the path
//! is an upper bound of what the part can do. A bit-forest's adders (a
//! walk code's popcounts) go into lookup tables too, not the carry chains:
//! with carry chains nextpnr-ice40 0.4 routed some decoders for over ten
//! minutes without finishing (a 16-bit walk decoder's 3144 arcs), without
//! them in two seconds; lookup-table adders are no faster than carry
//! chains, so this too can only lengthen the path. A piecewise-linear
//! model's wide adders take the carry chains ([`Design::carry_chains`]). Each variable takes a part of its
//! own, the variables side by side, so the state's time is the slowest
//! variable's. A variable whose lookup tables and flip-flops outnumber the
//! part's logic cells is reported as not fitting, with the cells it needs.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use alnlab_common::{Error, Result};
use serde::{Deserialize, Serialize};

use crate::datapath::Form;
use crate::tools;
use crate::verilog::{COMMON_FILE, Circuit};

/// An FPGA to place and route on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Device {
    /// Lattice iCE40 HX8K (7680 logic cells), CT256 package: the largest
    /// iCE40 with an open flow.
    Ice40Hx8k,
}

impl Device {
    /// Every device, for the names a user may give.
    pub const ALL: [Device; 1] = [Device::Ice40Hx8k];

    /// As manifests and reports name it.
    pub fn name(self) -> &'static str {
        match self {
            Device::Ice40Hx8k => "ice40-hx8k",
        }
    }

    /// As a reader knows it.
    pub fn description(self) -> &'static str {
        match self {
            Device::Ice40Hx8k => "Lattice iCE40 HX8K",
        }
    }

    /// The device a manifest or a table names.
    pub fn named(name: &str) -> Option<Device> {
        Device::ALL.into_iter().find(|d| d.name() == name)
    }

    /// nextpnr-ice40's arguments selecting the part.
    fn nextpnr_args(self) -> [&'static str; 3] {
        match self {
            Device::Ice40Hx8k => ["--hx8k", "--package", "ct256"],
        }
    }

    /// Logic cells (a 4-input lookup table and a flip-flop each).
    pub fn logic_cells(self) -> u64 {
        match self {
            Device::Ice40Hx8k => 7680,
        }
    }
}

/// One variable on the part.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Placed {
    /// The learned variable, as the codebook names it.
    pub variable: String,
    /// Lookup tables after mapping (`SB_LUT4`).
    pub luts: u64,
    /// The predictor's longest path in lookup tables (Yosys' `ltp`).
    pub lut_levels: u32,
    /// Carry-chain cells (`SB_CARRY`): adders on the part's carry logic.
    pub carries: u64,
    /// Flip-flops (`SB_DFF*`): the wrapper's registers and a pipeline's.
    pub flip_flops: u64,
    /// Logic cells used after packing; when it does not fit, the lookup
    /// tables and flip-flops it needs (each at most one cell).
    pub logic_cells: u64,
    /// Of the part.
    pub available: u64,
    /// The critical path, register to register, in ns; none when it does
    /// not fit, or nextpnr did not route it within
    /// [`PLACE_AND_ROUTE_LIMIT`].
    pub critical_ns: Option<f64>,
    /// Clocks from the input register's word to the level (0 when
    /// combinational: one clock period is the whole prediction).
    pub latency: u32,
    /// The nextpnr seed of the placement routed (the first tried when
    /// none was).
    pub seed: u64,
}

/// The top module wrapping variable `v`'s predictor between registers.
pub fn top_module(circuit: &Circuit, v: usize) -> String {
    format!("fpga_{}", circuit.variables[v].ident)
}

/// The mapped netlist of variable `v` ([`mapped_netlist`]).
pub fn mapped_file(circuit: &Circuit, v: usize) -> String {
    mapped_netlist(&top_module(circuit, v))
}

/// The Verilog of [`top_module`]: variable `v`'s predictor between
/// registers ([`registered`]).
pub fn wrapper(circuit: &Circuit, v: usize) -> String {
    let c = &circuit.variables[v];
    // (port, width) of every input, in the module's port order.
    let mut inputs: Vec<(String, usize)> = c
        .reads
        .iter()
        .map(|&b| (circuit.inputs[b].ident.clone(), circuit.inputs[b].width))
        .collect();
    if c.takes_current {
        inputs.push((format!("{}_current", c.ident), c.level_bits as usize));
    }
    let output = (format!("{}_next", c.ident), c.level_bits as usize);
    registered(
        &top_module(circuit, v),
        &c.module,
        &c.variable,
        &inputs,
        &output,
        false,
    )
}

/// Module `top` (ports `clk`, `din`, `dout`): a shift register of every
/// input bit of `module` (`inputs`: its ports and widths, in order), fed
/// from `din`; the module (given the clock too when `clocked`); its output
/// port (`output`: name and width) registered and folded by XOR to `dout`.
pub fn registered(
    top: &str,
    module: &str,
    variable: &str,
    inputs: &[(String, usize)],
    (output, out): &(String, usize),
    clocked: bool,
) -> String {
    let bits: usize = inputs.iter().map(|(_, w)| w).sum();
    let mut text = String::new();
    let _ = writeln!(
        text,
        "// `{variable}` between registers, for place and route.\n\
         module {top} (input wire clk, input wire din, output wire dout);\n  \
         reg [{}:0] in_q;\n  reg [{}:0] out_q;\n  wire [{}:0] level;",
        bits - 1,
        out - 1,
        out - 1
    );
    // A one-bit shift register is a plain register.
    let shift = if bits > 1 {
        format!("{{in_q[{}:0], din}}", bits - 2)
    } else {
        "din".to_string()
    };
    let _ = writeln!(
        text,
        "  always @(posedge clk) begin\n    in_q <= {shift};\n    out_q <= level;\n  end\n  \
         assign dout = ^out_q;"
    );
    let mut ports = Vec::new();
    if clocked {
        ports.push("    .clk(clk)".to_string());
    }
    let mut at = 0;
    for (name, width) in inputs {
        ports.push(format!("    .{name}(in_q[{}:{at}])", at + width - 1));
        at += width;
    }
    ports.push(format!("    .{output}(level)"));
    let _ = writeln!(
        text,
        "  {module} predictor (\n{}\n  );\nendmodule",
        ports.join(",\n")
    );
    text
}

/// Maps variable `v` of `circuit` (its files already written in `dir`, as
/// [`crate::check::write_files`] does) onto `device` and places and routes
/// it ([`place_and_route_files`], adders in lookup tables).
pub fn place_and_route(
    circuit: &Circuit,
    v: usize,
    device: Device,
    seed: u64,
    dir: &Path,
) -> Result<Placed> {
    let c = &circuit.variables[v];
    let top = top_module(circuit, v);
    let wrapper_file = format!("{top}.v");
    let path = dir.join(&wrapper_file);
    std::fs::write(&path, wrapper(circuit, v)).map_err(|e| Error::io(&path, e))?;
    let sources = [COMMON_FILE.to_string(), c.file.clone(), wrapper_file];
    let design = Design {
        top: &top,
        module: &c.module,
        variable: &c.variable,
        sources: &sources,
        carry_chains: false,
        latency: 0,
    };
    place_and_route_files(&design, device, seed, dir)
}

/// A predictor between registers, ready to map: its files in the scratch
/// folder and what to call things.
pub struct Design<'a> {
    /// The top module ([`registered`]).
    pub top: &'a str,
    /// The predictor's module, kept whole through mapping.
    pub module: &'a str,
    /// The learned variable it predicts.
    pub variable: &'a str,
    /// The Verilog files, in reading order.
    pub sources: &'a [String],
    /// Adders on the part's carry chains (else in lookup tables).
    pub carry_chains: bool,
    /// Clocks from inputs to output inside the predictor.
    pub latency: u32,
}

/// The mapped netlist of a design's top module (its predictor in the
/// part's cells, the wrapper's registers in `SB_DFF`s), as
/// [`place_and_route_files`] writes it.
pub fn mapped_netlist(top: &str) -> String {
    format!("{top}_mapped.v")
}

/// Maps `design` (its files in `dir`) onto `device`, writes the mapped
/// netlist ([`mapped_netlist`]: the one placed) and places and routes it
/// with nextpnr's `seed` (below [`NEXTPNR_SEEDS`]). The predictor stays a
/// module of its own through mapping (`keep_hierarchy`), so the netlist
/// simulated on the test rows is the very logic placed; the registers
/// around it keep synthesis from merging logic across them either way.
pub fn place_and_route_files(
    design: &Design,
    device: Device,
    seed: u64,
    dir: &Path,
) -> Result<Placed> {
    let Design {
        top,
        module,
        variable,
        ..
    } = *design;
    let netlist = format!("{top}.json");
    let stat = format!("{top}_stat.json");
    let ltp = format!("{top}_ltp.txt");
    let script = format!(
        "read_verilog {sources}\n\
         hierarchy -check -top {top}\n\
         setattr -mod -set keep_hierarchy 1 {module}\n\
         synth_ice40 {carry}-top {top} -json {netlist}\n\
         write_verilog -noattr {mapped}\n\
         tee -q -o {stat} stat -json\n\
         tee -q -o {ltp} ltp -noff {module}\n",
        sources = design.sources.join(" "),
        carry = if design.carry_chains { "" } else { "-nocarry " },
        mapped = mapped_netlist(top),
    );
    let script_file = format!("{top}.ys");
    let path = dir.join(&script_file);
    std::fs::write(&path, script).map_err(|e| Error::io(&path, e))?;
    tools::run("yosys", &["-q", "-s", &script_file], dir)?;
    let cells = crate::synth::read_stat(&dir.join(&stat))?;
    let count = |kind: fn(&str) -> bool| -> u64 {
        cells
            .values()
            .flat_map(|by_type| by_type.iter())
            .filter(|(cell, _)| kind(cell))
            .map(|(_, n)| n)
            .sum()
    };
    let luts = count(|cell| cell == "SB_LUT4");
    let flip_flops = count(|cell| cell.starts_with("SB_DFF"));
    let carries = count(|cell| cell == "SB_CARRY");
    let ltp = dir.join(&ltp);
    let lut_levels = *crate::synth::read_depths(&ltp)?
        .get(module)
        .ok_or_else(|| Error::bad_file(&ltp, format!("no path of module `{module}`")))?;
    let available = device.logic_cells();
    let mut placed = Placed {
        variable: variable.to_string(),
        luts,
        lut_levels,
        carries,
        flip_flops,
        logic_cells: luts + flip_flops,
        available,
        critical_ns: None,
        latency: design.latency,
        seed,
    };
    // A cell holds a lookup table and a flip-flop, but a shift register's
    // flip-flops have no table of their own to share one with.
    if luts + flip_flops > available {
        return Ok(placed);
    }
    // nextpnr-ice40 0.4's router can stall on one placement and finish on
    // another (omega_dot.2.z's pipelined form, 9 % of the part: 673 arcs
    // ripped up and rerouted for over a million iterations with one seed,
    // routed in seconds with the next): each attempt is limited, and the
    // next one places with the next seed.
    for attempt in 0..ROUTING_ATTEMPTS {
        let seed = (seed + attempt) % NEXTPNR_SEEDS;
        let report = format!("{top}_pnr.json");
        let seed_text = seed.to_string();
        let mut args: Vec<&str> = device.nextpnr_args().to_vec();
        args.extend([
            "--json",
            &netlist,
            "--seed",
            &seed_text,
            // A clock every design meets: the figure is what it achieves
            // (and one that does not, over 1 µs, is still reported, not
            // failed).
            "--freq",
            "1",
            "--timing-allow-fail",
            "--report",
            &report,
            "--quiet",
        ]);
        let log = format!("{top}_pnr.log");
        let ended = tools::run_for("nextpnr-ice40", &args, dir, &log, ATTEMPT_LIMIT)
            .map_err(|e| e.context(&format!("placing and routing `{variable}`")))?;
        if ended == tools::Ended::Finished {
            let (logic_cells, mhz) = read_report(&dir.join(&report))?;
            placed.logic_cells = logic_cells;
            placed.critical_ns = Some(1000.0 / mhz);
            placed.seed = seed;
            return Ok(placed);
        }
    }
    // Routing that converged with no seed in the time allowed: it fits,
    // but has no critical path.
    Ok(placed)
}

/// Placements tried before a variable is reported unrouted.
pub const ROUTING_ATTEMPTS: u64 = 3;
/// How long one placement may take to route.
pub const ATTEMPT_LIMIT: std::time::Duration = std::time::Duration::from_secs(300);

/// Yosys' simulation models of the iCE40's cells, in its data folder.
pub const ICE40_MODELS: &str = "ice40/cells_sim.v";
/// The simulators read the models without their ports' default values
/// (a SystemVerilog form Icarus Verilog lacks); the mapped netlist
/// connects every port.
pub const ICE40_DEFINES: &[&str] = &["NO_ICE40_DEFAULT_ASSIGNMENTS"];

/// nextpnr reads its seed as a C `int`: seeds are taken modulo 2³¹.
pub const NEXTPNR_SEEDS: u64 = 1 << 31;

/// How long one variable may take to place and route, over all its
/// attempts: a walk decoder's carry chains once kept nextpnr routing for
/// over ten minutes; mapped without them the largest forests here take
/// seconds. Past it the variable is reported unrouted.
pub const PLACE_AND_ROUTE_LIMIT: std::time::Duration =
    std::time::Duration::from_secs(ATTEMPT_LIMIT.as_secs() * ROUTING_ATTEMPTS);

/// Logic cells used and the achieved clock (MHz) from nextpnr's
/// `--report` JSON.
fn read_report(path: &Path) -> Result<(u64, f64)> {
    #[derive(Deserialize)]
    struct Report {
        fmax: BTreeMap<String, Clock>,
        utilization: BTreeMap<String, Use>,
    }
    #[derive(Deserialize)]
    struct Clock {
        achieved: f64,
    }
    #[derive(Deserialize)]
    struct Use {
        used: u64,
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let report: Report = serde_json::from_str(&text)
        .map_err(|e| Error::bad_file(path, format!("not nextpnr's `--report` ({e})")))?;
    let mhz = report
        .fmax
        .values()
        .map(|c| c.achieved)
        .reduce(f64::min)
        .filter(|f| f.is_finite() && *f > 0.0)
        .ok_or_else(|| Error::bad_file(path, "no clock with an achieved frequency"))?;
    let cells = report
        .utilization
        .get("ICESTORM_LC")
        .map(|u| u.used)
        .ok_or_else(|| Error::bad_file(path, "no ICESTORM_LC utilization"))?;
    Ok((cells, mhz))
}

/// Yosys' and nextpnr-ice40's versions, as they print them.
pub fn tool_versions() -> Result<String> {
    Ok(format!(
        "{}; {}",
        tools::run("yosys", &["-V"], Path::new("."))?.trim(),
        tools::version("nextpnr-ice40")?
    ))
}

/// The state on `device`: every variable placed and routed, and the
/// slowest one's critical path (the variables run side by side, one part
/// each).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct State {
    /// The part, one per variable.
    pub device: Device,
    /// How the predictors are built.
    pub form: Form,
    /// nextpnr's first seed (a variable whose placement did not route
    /// takes the next: [`Placed::seed`]).
    pub seed: u64,
    /// Yosys' and nextpnr's versions (and Verilator's, which simulated a
    /// piecewise-linear model's mapped netlists).
    pub tools: String,
    /// Every learned variable, in the codebook's order.
    pub variables: Vec<Placed>,
}

impl Placed {
    /// Whether its lookup tables and flip-flops fit the part (a variable
    /// that fits but has no critical path was not routed in time).
    pub fn fits(&self) -> bool {
        self.logic_cells <= self.available
    }
}

impl State {
    /// The slowest variable's critical path (ns), when every variable fits.
    pub fn critical_ns(&self) -> Option<f64> {
        self.variables
            .iter()
            .map(|p| p.critical_ns)
            .try_fold(0f64, |worst, ns| Some(worst.max(ns?)))
    }

    /// The slowest variable.
    pub fn slowest(&self) -> Option<&Placed> {
        self.variables
            .iter()
            .filter(|p| p.critical_ns.is_some())
            .max_by(|a, b| a.critical_ns.partial_cmp(&b.critical_ns).expect("finite"))
    }

    /// The longest path in lookup tables, over the variables.
    pub fn lut_levels(&self) -> u32 {
        self.variables
            .iter()
            .map(|p| p.lut_levels)
            .max()
            .unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nextpnr_reports_are_read_for_the_worst_clock_and_the_cells() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.json");
        std::fs::write(
            &path,
            r#"{"fmax": {"clk": {"achieved": 92.5, "constraint": 1}},
                "utilization": {"ICESTORM_LC": {"available": 7680, "used": 823},
                                "SB_IO": {"available": 256, "used": 3}}}"#,
        )
        .unwrap();
        assert_eq!(read_report(&path).unwrap(), (823, 92.5));
        std::fs::write(&path, r#"{"fmax": {}, "utilization": {}}"#).unwrap();
        let error = read_report(&path).unwrap_err().to_string();
        assert!(error.contains("no clock"), "{error}");
    }

    #[test]
    fn the_state_waits_for_its_slowest_variable() {
        let placed = |name: &str, ns: Option<f64>| Placed {
            variable: name.into(),
            luts: 1,
            logic_cells: 1,
            available: 7680,
            lut_levels: 3,
            carries: 0,
            flip_flops: 2,
            latency: 0,
            seed: 1,
            critical_ns: ns,
        };
        let mut state = State {
            device: Device::Ice40Hx8k,
            form: Form::Combinational,
            seed: 1,
            tools: String::new(),
            variables: vec![placed("a", Some(4.5)), placed("b", Some(10.8))],
        };
        assert_eq!(state.critical_ns(), Some(10.8));
        assert_eq!(state.slowest().unwrap().variable, "b");
        state.variables.push(placed("c", None));
        assert_eq!(state.critical_ns(), None, "a variable that does not fit");
    }
}
