//! A bit-forest as synthesizable Verilog (Verilog-2005).
//!
//! The inputs are the state's code bits, one bus per variable named after
//! it (`pitch.3` → `pitch_3`); a variable's predicted level leaves as
//! `<variable>_next`, in binary. Per learned variable, one file holds:
//!
//! - one module per pruned tree (`tree_<variable>_b<bit>_v<voter>`), whose
//!   ports are the input bits it reads (`roll_2_b5`: bit 5 of `roll.2`'s
//!   code) and `out`; one line per AND/OR gate;
//! - its decoder (`decode_<variable>`): the voted code bits to the level —
//!   the number a binary code spells, the reflected-Gray inverse, the count
//!   of a thermometer's ones (each clamped to the last level as the software
//!   clamps), or the walk code's nearest codeword (Hamming distance to every
//!   codeword, then a tournament that keeps the lower level on ties); a
//!   change-of-level target then adds the change to the current level,
//!   wrapped and clamped as [`alnlab_codes::Residual::apply`] does;
//! - the variable's module (`predict_<variable>`) wiring the trees, the
//!   majority gates of the votes and the decoder.
//!
//! `common.v` holds the majority gates and `top.v` the state's module
//! (`predict_state`), which holds one module per variable.

use std::collections::BTreeSet;
use std::fmt::Write;

use alnlab_aln::tree::{Gate, Literal, Pruned};
use alnlab_aln::{Model, ModelKind, Output};
use alnlab_codes::codes::{Code, Codec, binary_width};

/// The name of the state's module.
pub const TOP: &str = "predict_state";
/// The file of the majority gates.
pub const COMMON_FILE: &str = "common.v";
/// The file of the state's module.
pub const TOP_FILE: &str = "top.v";

/// One input variable: its port and where its code's bits sit among the
/// model's input bits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InputBus {
    /// The variable, as the codebook names it.
    pub variable: String,
    /// Its Verilog name.
    pub ident: String,
    /// The model input bit of its code's bit 0.
    pub offset: usize,
    /// Its code's width.
    pub width: usize,
}

/// One learned variable's part of the circuit.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VariableCircuit {
    /// The variable, as the codebook names it.
    pub variable: String,
    /// Its Verilog name.
    pub ident: String,
    /// The file holding its modules.
    pub file: String,
    /// Its module: the code buses in, `<ident>_next` out.
    pub module: String,
    /// Its trees' modules, in training order (bit, then voter).
    pub trees: Vec<String>,
    /// Its decoder's module.
    pub decoder: String,
    /// The majority gate of its votes and how many it uses (one per code
    /// bit); none with one voter.
    pub majority: Option<(String, usize)>,
    /// The input buses its trees read (indices into [`Circuit::inputs`]).
    pub reads: Vec<usize>,
    /// Whether its decoder takes the current level (`<ident>_current`): a
    /// change-of-level target.
    pub takes_current: bool,
    /// Bits of its level (and current level).
    pub level_bits: u32,
}

/// A model as Verilog: the files and what they hold.
#[derive(Clone, Debug, PartialEq)]
pub struct Circuit {
    /// Every file, as (name, text): `common.v`, one per learned variable,
    /// `top.v`.
    pub files: Vec<(String, String)>,
    /// The input buses, in the model's input order.
    pub inputs: Vec<InputBus>,
    /// The learned variables, in the model's order.
    pub variables: Vec<VariableCircuit>,
}

/// A Verilog identifier for a variable name: letters, digits and `_`, the
/// rest turned into `_` (`v.1.x` → `v_1_x`).
pub fn ident(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic()) {
        s.insert_str(0, "v_");
    }
    s
}

impl Circuit {
    /// The circuit of a bit-forest `model` whose inputs are the codes of
    /// `names` (its learned variables, in order) by `codecs`, and whose
    /// trees' bits `outputs` decode. Says why when the model cannot be
    /// made one: a threshold model's binary search is sequential, and names
    /// that turn into the same identifier.
    pub fn new(
        model: &Model,
        names: &[String],
        codecs: &[Codec],
        outputs: &[Output],
    ) -> Result<Circuit, String> {
        match model.header.model {
            ModelKind::BitForest => {}
            ModelKind::Threshold => {
                return Err(
                    "a threshold model finds its level by a binary search over repeated \
                     evaluations of its trees, a sequential circuit; only bit-forests are \
                     exported"
                        .into(),
                );
            }
            ModelKind::PiecewiseLinear => {
                return Err(
                    "a piecewise-linear model computes with real numbers (affine pieces under \
                     MIN and MAX), not AND/OR gates; only bit-forests are exported"
                        .into(),
                );
            }
        }
        let idents: Vec<String> = names.iter().map(|n| ident(n)).collect();
        let mut seen = BTreeSet::new();
        for (name, id) in names.iter().zip(&idents) {
            if !seen.insert(id.as_str()) {
                return Err(format!(
                    "`{name}` becomes the Verilog name `{id}`, which another variable has too"
                ));
            }
        }
        let mut offset = 0;
        let inputs: Vec<InputBus> = names
            .iter()
            .zip(&idents)
            .zip(codecs)
            .map(|((variable, ident), codec)| {
                let bus = InputBus {
                    variable: variable.clone(),
                    ident: ident.clone(),
                    offset,
                    width: codec.width() as usize,
                };
                offset += bus.width;
                bus
            })
            .collect();
        let vote = model.header.vote as usize;
        let mut files = vec![(COMMON_FILE.to_string(), common(vote))];
        let mut variables = Vec::new();
        let mut trees = model.trees.iter();
        for (v, output) in outputs.iter().enumerate() {
            let width = output.codec().width() as usize;
            let mut text = String::new();
            let mut tree_modules = Vec::new();
            let mut reads = BTreeSet::new();
            let mut ports_of = Vec::new();
            for bit in 0..width {
                for voter in 0..vote {
                    let (id, tree) = trees.next().ok_or("the model has too few trees")?;
                    if (id.variable as usize, id.bit as usize, id.vote as usize) != (v, bit, voter)
                    {
                        return Err(format!("tree {id:?} is out of training order"));
                    }
                    let pruned = tree.prune();
                    let name = format!("tree_{}_b{bit}_v{voter}", idents[v]);
                    let ports = tree_ports(&pruned, &inputs);
                    reads.extend(ports.iter().map(|p| p.0));
                    write_tree(
                        &mut text,
                        &name,
                        &names[v],
                        bit,
                        voter,
                        tree.leaves(),
                        &pruned,
                        &inputs,
                        &ports,
                    );
                    ports_of.push(ports);
                    tree_modules.push(name);
                }
            }
            let level_bits = binary_width(output_levels(output));
            let decoder = format!("decode_{}", idents[v]);
            write_decoder(&mut text, &decoder, &names[v], output, level_bits);
            let majority = (vote > 1).then(|| (format!("majority{vote}"), width));
            let circuit = VariableCircuit {
                variable: names[v].clone(),
                ident: idents[v].clone(),
                file: format!("{}.v", idents[v]),
                module: format!("predict_{}", idents[v]),
                trees: tree_modules,
                decoder,
                majority,
                reads: reads.into_iter().collect(),
                takes_current: matches!(output, Output::Delta(_)),
                level_bits,
            };
            write_variable(&mut text, &circuit, &inputs, &ports_of, vote, width);
            files.push((circuit.file.clone(), text));
            variables.push(circuit);
        }
        if trees.next().is_some() {
            return Err("the model has more trees than its outputs' bits and voters".into());
        }
        files.push((TOP_FILE.to_string(), top(&inputs, &variables)));
        Ok(Circuit {
            files,
            inputs,
            variables,
        })
    }

    /// Bits of all the input buses together.
    pub fn input_bits(&self) -> usize {
        self.inputs.iter().map(|b| b.width).sum()
    }
}

/// The levels of an output's prediction: its codec's (a level target) or
/// the variable's own (a change target, whose codec codes the change).
fn output_levels(output: &Output) -> usize {
    match output {
        Output::Level(codec) => codec.levels(),
        Output::Delta(residual) => residual.levels(),
    }
}

/// The input bits a tree reads, as (bus, bit of the bus), ascending.
fn tree_ports(tree: &Pruned, inputs: &[InputBus]) -> Vec<(usize, usize)> {
    let bits: BTreeSet<usize> = tree
        .nodes
        .iter()
        .filter_map(|g| match *g {
            Gate::Leaf(l) => Some((l / 2) as usize),
            _ => None,
        })
        .collect();
    bits.into_iter().map(|b| locate(b, inputs)).collect()
}

/// The bus and bit of model input bit `b`.
fn locate(b: usize, inputs: &[InputBus]) -> (usize, usize) {
    let bus = inputs.partition_point(|i| i.offset + i.width <= b);
    (bus, b - inputs[bus].offset)
}

fn port_name(inputs: &[InputBus], (bus, bit): (usize, usize)) -> String {
    format!("{}_b{bit}", inputs[bus].ident)
}

/// The expression of a leaf's literal: the port, or its complement.
fn literal(l: Literal, inputs: &[InputBus]) -> String {
    let name = port_name(inputs, locate((l / 2) as usize, inputs));
    if l & 1 == 1 { format!("~{name}") } else { name }
}

#[allow(clippy::too_many_arguments)]
fn write_tree(
    text: &mut String,
    name: &str,
    variable: &str,
    bit: usize,
    voter: usize,
    leaves: usize,
    tree: &Pruned,
    inputs: &[InputBus],
    ports: &[(usize, usize)],
) {
    let gates = tree.gates();
    let _ = writeln!(
        text,
        "// `{variable}`, code bit {bit}, voter {voter}: {leaves} leaves pruned to {gates} \
         AND/OR gates, {} deep.",
        tree.depth()
    );
    let _ = writeln!(text, "module {name} (");
    for &p in ports {
        let _ = writeln!(text, "  input wire {},", port_name(inputs, p));
    }
    let _ = writeln!(text, "  output wire out\n);");
    // Each node's expression: a leaf's literal, or the wire of its gate.
    let mut expr: Vec<String> = Vec::with_capacity(tree.nodes.len());
    let mut wire = 0;
    for gate in &tree.nodes {
        let e = match *gate {
            Gate::Leaf(l) => literal(l, inputs),
            Gate::And(a, b) | Gate::Or(a, b) => {
                let op = if matches!(gate, Gate::And(..)) {
                    '&'
                } else {
                    '|'
                };
                let _ = writeln!(
                    text,
                    "  wire n{wire} = {} {op} {};",
                    expr[a as usize], expr[b as usize]
                );
                wire += 1;
                format!("n{}", wire - 1)
            }
        };
        expr.push(e);
    }
    let _ = writeln!(
        text,
        "  assign out = {};\nendmodule\n",
        expr.last().expect("a root")
    );
}

/// A balanced sum of one-bit terms, `width` bits wide: the depth of a
/// popcount grows with the log of the terms, not their number.
fn balanced_sum(terms: &[String]) -> String {
    match terms {
        [] => "0".into(),
        [one] => one.clone(),
        _ => {
            let (a, b) = terms.split_at(terms.len() / 2);
            format!("({} + {})", balanced_sum(a), balanced_sum(b))
        }
    }
}

/// The decoder: `code` (the voted bits) to `level`; for a change target,
/// from `current` as well.
fn write_decoder(text: &mut String, name: &str, variable: &str, output: &Output, level_bits: u32) {
    let codec = output.codec();
    let (w, levels) = (codec.width() as usize, codec.levels());
    let vb = binary_width(levels);
    let last = levels - 1;
    let what = match output {
        Output::Level(_) => "its next level",
        Output::Delta(_) => "its change of level, added to the current level",
    };
    let _ = writeln!(
        text,
        "// `{variable}`: the {} code's {w} bits of {what} ({levels} levels) to the level.",
        codec.code()
    );
    let _ = writeln!(text, "module {name} (\n  input wire [{}:0] code,", w - 1);
    if matches!(output, Output::Delta(_)) {
        let _ = writeln!(text, "  input wire [{}:0] current,", level_bits - 1);
    }
    let _ = writeln!(text, "  output wire [{}:0] level\n);", level_bits - 1);
    let _ = writeln!(text, "  wire [{}:0] value;", vb - 1);
    let clamp = |text: &mut String, raw: &str| {
        if levels.is_power_of_two() {
            let _ = writeln!(text, "  assign value = {raw};");
        } else {
            let _ = writeln!(
                text,
                "  assign value = {raw} > {vb}'d{last} ? {vb}'d{last} : {raw};"
            );
        }
    };
    match codec.code() {
        Code::Binary => clamp(text, "code"),
        Code::Gray => {
            // Binary bit i is the XOR of Gray bits i and above.
            let _ = writeln!(text, "  wire [{}:0] binary;", w - 1);
            for i in 0..w {
                let _ = writeln!(text, "  assign binary[{i}] = ^code[{}:{i}];", w - 1);
            }
            clamp(text, "binary");
        }
        Code::Thermometer => {
            let ones: Vec<String> = (0..w).map(|i| format!("code[{i}]")).collect();
            let _ = writeln!(text, "  assign value = {};", balanced_sum(&ones));
        }
        Code::Walk => write_nearest(text, codec, vb),
    }
    match output {
        Output::Level(_) => {
            let _ = writeln!(text, "  assign level = value;");
        }
        Output::Delta(residual) => {
            let spec = residual.spec();
            let top = residual.levels() - 1;
            // Signed arithmetic wide enough for current + change − k.
            let s = level_bits.max(vb) + 2;
            let _ = writeln!(text, "  // next = current + value − k, k = {}", spec.k);
            let _ = writeln!(
                text,
                "  wire signed [{}:0] raw = $signed({{{}'d0, current}}) + $signed({{{}'d0, value}}) - {s}'sd{};",
                s - 1,
                s - level_bits,
                s - vb,
                spec.k
            );
            let wrapped = if let Some(p) = spec.period {
                let _ = writeln!(
                    text,
                    "  // the angle wraps every {p} levels\n  wire signed [{}:0] wrapped = raw < {s}'sd0 ? raw + {s}'sd{p} : raw > {s}'sd{top} ? raw - {s}'sd{p} : raw;",
                    s - 1
                );
                "wrapped"
            } else {
                "raw"
            };
            let _ = writeln!(
                text,
                "  assign level = {wrapped} < {s}'sd0 ? {lb}'d0 : {wrapped} > {s}'sd{top} ? {lb}'d{top} : {wrapped}[{}:0];",
                level_bits - 1,
                lb = level_bits
            );
        }
    }
    let _ = writeln!(text, "endmodule\n");
}

/// The walk decoder: every codeword's Hamming distance to `code` as a
/// balanced popcount of the bits that differ, then a tournament of pairs
/// (the nearer, the lower level on ties — the software's rule), the level
/// of the winner in `value`.
fn write_nearest(text: &mut String, codec: &Codec, vb: u32) {
    let w = codec.width() as usize;
    let db = binary_width(w + 1);
    let mut round: Vec<(String, String)> = Vec::with_capacity(codec.levels());
    for k in 0..codec.levels() {
        let word = codec.codeword(k);
        let differ: Vec<String> = (0..w)
            .map(|i| {
                // `!` keeps the term one bit wide where `~` would widen it.
                if word[i / 64] >> (i % 64) & 1 == 1 {
                    format!("!code[{i}]")
                } else {
                    format!("code[{i}]")
                }
            })
            .collect();
        let _ = writeln!(
            text,
            "  wire [{}:0] d{k} = {};",
            db - 1,
            balanced_sum(&differ)
        );
        round.push((format!("d{k}"), format!("{vb}'d{k}")));
    }
    let mut stage = 0;
    while round.len() > 1 {
        stage += 1;
        let mut next = Vec::with_capacity(round.len().div_ceil(2));
        for (j, pair) in round.chunks(2).enumerate() {
            if let [(da, ia), (db_, ib)] = pair {
                let (d, i, c) = (
                    format!("d{stage}_{j}"),
                    format!("i{stage}_{j}"),
                    format!("c{stage}_{j}"),
                );
                let _ = writeln!(text, "  wire {c} = {db_} < {da};");
                let _ = writeln!(text, "  wire [{}:0] {d} = {c} ? {db_} : {da};", db - 1);
                let _ = writeln!(text, "  wire [{}:0] {i} = {c} ? {ib} : {ia};", vb - 1);
                next.push((d, i));
            } else {
                next.push(pair[0].clone());
            }
        }
        round = next;
    }
    let _ = writeln!(text, "  assign value = {};", round[0].1);
}

/// The variable's module: trees, votes, decoder.
fn write_variable(
    text: &mut String,
    c: &VariableCircuit,
    inputs: &[InputBus],
    ports: &[Vec<(usize, usize)>],
    vote: usize,
    width: usize,
) {
    let _ = writeln!(
        text,
        "// `{}`: its next level from the state's codes; {} trees{}.",
        c.variable,
        c.trees.len(),
        if vote > 1 {
            format!(", {vote} voters per code bit")
        } else {
            String::new()
        }
    );
    let _ = writeln!(text, "module {} (", c.module);
    for &b in &c.reads {
        let _ = writeln!(
            text,
            "  input wire [{}:0] {},",
            inputs[b].width - 1,
            inputs[b].ident
        );
    }
    if c.takes_current {
        let _ = writeln!(
            text,
            "  input wire [{}:0] {}_current,",
            c.level_bits - 1,
            c.ident
        );
    }
    let _ = writeln!(
        text,
        "  output wire [{}:0] {}_next\n);",
        c.level_bits - 1,
        c.ident
    );
    let _ = writeln!(text, "  wire [{}:0] code;", width - 1);
    for bit in 0..width {
        let target = if vote > 1 {
            let _ = writeln!(text, "  wire [{}:0] votes_b{bit};", vote - 1);
            Some(format!("votes_b{bit}"))
        } else {
            None
        };
        for voter in 0..vote {
            let t = bit * vote + voter;
            let mut connections: Vec<String> = ports[t]
                .iter()
                .map(|&(bus, i)| {
                    format!(
                        ".{}({}[{i}])",
                        port_name(inputs, (bus, i)),
                        inputs[bus].ident
                    )
                })
                .collect();
            connections.push(match &target {
                Some(v) => format!(".out({v}[{voter}])"),
                None => format!(".out(code[{bit}])"),
            });
            let _ = writeln!(
                text,
                "  {} t_b{bit}_v{voter} ({});",
                c.trees[t],
                connections.join(", ")
            );
        }
        if let Some((majority, _)) = &c.majority {
            let _ = writeln!(
                text,
                "  {majority} m_b{bit} (.votes(votes_b{bit}), .out(code[{bit}]));"
            );
        }
    }
    let current = if c.takes_current {
        format!(".current({}_current), ", c.ident)
    } else {
        String::new()
    };
    let _ = writeln!(
        text,
        "  {} decode (.code(code), {current}.level({}_next));\nendmodule",
        c.decoder, c.ident
    );
}

/// The majority gate of `n` votes (none for one voter).
fn common(n: usize) -> String {
    let mut text = String::from("// The majority gates of the votes (paper §4.3).\n");
    if n > 1 {
        let ones: Vec<String> = (0..n).map(|i| format!("votes[{i}]")).collect();
        let _ = writeln!(
            text,
            "module majority{n} (\n  input wire [{}:0] votes,\n  output wire out\n);\n  \
             // At least {} of {n}.\n  assign out = {} >= {};\nendmodule\n",
            n - 1,
            n / 2 + 1,
            balanced_sum(&ones),
            n / 2 + 1
        );
    }
    text
}

/// The state's module: every variable's.
fn top(inputs: &[InputBus], variables: &[VariableCircuit]) -> String {
    let mut text = format!(
        "// The next state from the current state's codes: one module per learned variable, \
         all in parallel.\nmodule {TOP} (\n"
    );
    let read: BTreeSet<usize> = variables
        .iter()
        .flat_map(|v| v.reads.iter().copied())
        .collect();
    let mut ports = Vec::new();
    for &b in &read {
        ports.push(format!(
            "  input wire [{}:0] {}",
            inputs[b].width - 1,
            inputs[b].ident
        ));
    }
    for v in variables.iter().filter(|v| v.takes_current) {
        ports.push(format!(
            "  input wire [{}:0] {}_current",
            v.level_bits - 1,
            v.ident
        ));
    }
    for v in variables {
        ports.push(format!(
            "  output wire [{}:0] {}_next",
            v.level_bits - 1,
            v.ident
        ));
    }
    let _ = writeln!(text, "{}\n);", ports.join(",\n"));
    for v in variables {
        let mut connections: Vec<String> = v
            .reads
            .iter()
            .map(|&b| format!(".{0}({0})", inputs[b].ident))
            .collect();
        if v.takes_current {
            connections.push(format!(".{0}_current({0}_current)", v.ident));
        }
        connections.push(format!(".{0}_next({0}_next)", v.ident));
        let _ = writeln!(
            text,
            "  {} {} ({});",
            v.module,
            v.ident,
            connections.join(", ")
        );
    }
    let _ = writeln!(text, "endmodule");
    text
}
