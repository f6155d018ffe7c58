//! Synthesis by Yosys to a generic gate library — every two-input gate
//! (AND, NAND, OR, NOR, XOR, XNOR, AND-NOT, OR-NOT) and the inverter, one
//! gate delay each — mapped by ABC for the least delay; then cell counts and
//! the longest path in gate levels of every module (Yosys' `ltp`). Each
//! learned variable is synthesized on its own, its hierarchy kept, so the
//! path splits into its trees, its votes and its decoder.

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::{Error, Result};
use serde::{Deserialize, Serialize};

use crate::tools;
use crate::verilog::{COMMON_FILE, Circuit, VariableCircuit};

/// The gate library, as ABC's `-g` takes it.
pub const GATES: &str = "AND,NAND,OR,NOR,XOR,XNOR,ANDNOT,ORNOT";
/// ABC's script: structural hashing, choices, AIG balancing, then mapping
/// for the least delay. (Yosys' default `&nf` script chains what this
/// balances: a 6-bit Gray decoder came out 5 gates deep instead of 3.)
const ABC_SCRIPT: &str = "+strash;dch;balance;map,-D,1;topo";
/// The gate library, as reports describe it.
pub const LIBRARY: &str =
    "two-input AND, NAND, OR, NOR, XOR, XNOR, AND-NOT and OR-NOT gates and inverters";

/// Gates and depth of one part of a circuit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Part {
    /// Gates, inverters included.
    pub cells: u64,
    /// Of them, inverters.
    pub inverters: u64,
    /// The longest path through it, in gates.
    pub depth: u32,
}

impl Part {
    /// Two parts side by side: their gates added, the deeper one's depth.
    fn beside(self, other: Part) -> Part {
        Part {
            cells: self.cells + other.cells,
            inverters: self.inverters + other.inverters,
            depth: self.depth.max(other.depth),
        }
    }
}

/// One learned variable's synthesized circuit, by part.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct VariableFigures {
    pub variable: String,
    /// All its trees (depth: the deepest).
    pub trees: Part,
    /// The majority gates of its votes (none with one voter).
    pub votes: Part,
    /// Its decoder.
    pub decode: Part,
}

impl VariableFigures {
    /// Gate levels from the input bits to the level: the deepest tree, then
    /// the votes, then the decoder (the sum of the parts' longest paths,
    /// which the hierarchy keeps apart).
    pub fn depth(&self) -> u32 {
        self.trees.depth + self.votes.depth + self.decode.depth
    }

    /// All its gates.
    pub fn cells(&self) -> u64 {
        self.trees.cells + self.votes.cells + self.decode.cells
    }
}

/// A whole model's synthesized circuit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Figures {
    /// The programs that measured it, with their versions.
    pub tools: String,
    /// The gate library.
    pub library: String,
    pub variables: Vec<VariableFigures>,
}

impl Figures {
    /// A part summed over the variables (depth: the deepest).
    pub fn part(&self, part: impl Fn(&VariableFigures) -> Part) -> Part {
        self.variables
            .iter()
            .map(part)
            .fold(Part::default(), Part::beside)
    }

    /// The state's depth: the deepest variable's.
    pub fn depth(&self) -> u32 {
        self.variables
            .iter()
            .map(VariableFigures::depth)
            .max()
            .unwrap_or(0)
    }

    /// The state's gates.
    pub fn cells(&self) -> u64 {
        self.variables.iter().map(VariableFigures::cells).sum()
    }

    /// The variable whose path is the longest.
    pub fn deepest(&self) -> Option<&VariableFigures> {
        // The first of equals.
        self.variables.iter().rev().max_by_key(|v| v.depth())
    }
}

/// The synthesized netlist of variable `c`, as [`synthesize`] writes it.
pub fn netlist_file(c: &VariableCircuit) -> String {
    format!("synth_{}", c.file)
}

/// Synthesizes variable `v` of `circuit` (its files written in `dir`),
/// writes its netlist ([`netlist_file`]) there and returns its figures.
pub fn synthesize(circuit: &Circuit, v: usize, dir: &Path) -> Result<VariableFigures> {
    let c = &circuit.variables[v];
    let stat = format!("stat_{}.json", c.ident);
    let ltp = format!("ltp_{}.txt", c.ident);
    let script = format!(
        "read_verilog {COMMON_FILE} {file}\n\
         hierarchy -check -top {top}\n\
         synth -top {top} -noabc\n\
         abc -script {ABC_SCRIPT} -g {GATES}\n\
         opt_clean\n\
         tee -q -o {stat} stat -json\n\
         tee -q -o {ltp} ltp -noff\n\
         write_verilog -noattr {netlist}\n",
        file = c.file,
        top = c.module,
        netlist = netlist_file(c),
    );
    let script_file = format!("synth_{}.ys", c.ident);
    let path = dir.join(&script_file);
    std::fs::write(&path, script).map_err(|e| Error::io(&path, e))?;
    tools::run("yosys", &["-q", "-s", &script_file], dir)?;
    let cells = read_cells(&dir.join(&stat))?;
    let depths = read_depths(&dir.join(&ltp))?;
    let part = |module: &str, times: u64| {
        let counts = cells.get(module).cloned().unwrap_or_default();
        Part {
            cells: counts.values().sum::<u64>() * times,
            inverters: counts.get("$_NOT_").copied().unwrap_or(0) * times,
            depth: depths.get(module).copied().unwrap_or(0),
        }
    };
    let trees = c
        .trees
        .iter()
        .map(|t| part(t, 1))
        .fold(Part::default(), Part::beside);
    let votes = c
        .majority
        .as_ref()
        .map_or(Part::default(), |(m, n)| part(m, *n as u64));
    Ok(VariableFigures {
        variable: c.variable.clone(),
        trees,
        votes,
        decode: part(&c.decoder, 1),
    })
}

/// Per module, its gate cells by type (`stat -json`; instances of other
/// modules left out).
fn read_cells(path: &Path) -> Result<BTreeMap<String, BTreeMap<String, u64>>> {
    Ok(read_stat(path)?
        .into_iter()
        .map(|(name, cells)| {
            let gates = cells
                .into_iter()
                .filter(|(cell, _)| cell.starts_with("$_"))
                .collect();
            (name, gates)
        })
        .collect())
}

/// Per module (named without Yosys' leading backslash), its cells by type, from
/// `stat -json`.
pub(crate) fn read_stat(path: &Path) -> Result<BTreeMap<String, BTreeMap<String, u64>>> {
    #[derive(Deserialize)]
    struct Stat {
        modules: BTreeMap<String, Module>,
    }
    #[derive(Deserialize)]
    struct Module {
        num_cells_by_type: BTreeMap<String, u64>,
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let stat: Stat = serde_json::from_str(&text)
        .map_err(|e| Error::bad_file(path, format!("not Yosys' `stat -json` ({e})")))?;
    Ok(stat
        .modules
        .into_iter()
        .map(|(name, m)| {
            (
                name.trim_start_matches('\\').to_string(),
                m.num_cells_by_type,
            )
        })
        .collect())
}

/// Per module, its longest topological path in cells (`ltp -noff`).
pub(crate) fn read_depths(path: &Path) -> Result<BTreeMap<String, u32>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut depths = BTreeMap::new();
    for line in text.lines() {
        if let Some(rest) = line.trim().strip_prefix("Longest topological path in ") {
            let parsed = rest.rsplit_once(" (length=").and_then(|(module, n)| {
                let n = n.trim_end_matches("):").parse::<u32>().ok()?;
                Some((module.trim_start_matches('\\').to_string(), n))
            });
            let (module, n) = parsed
                .ok_or_else(|| Error::bad_file(path, format!("not Yosys' `ltp` line: {line}")))?;
            depths.insert(module, n);
        }
    }
    Ok(depths)
}
