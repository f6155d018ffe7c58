//! A piecewise-linear model's circuit: each output of its fixed-point form
//! ([`FixedOutput`]) as Verilog that computes the very integers the
//! evaluator does.
//!
//! A piece is its bias plus every weight times its input word; a weight is
//! a constant, so its product is a few shifted copies of the word added or
//! subtracted (the weight's canonical signed digits: at most half its bits
//! non-zero; copies shifted below the sum's scale floored, as
//! [`alnlab_aln::pwl::fixed::product`] computes), and a piece's terms are
//! summed by a balanced tree of adders.
//! The MIN and MAX nodes are a comparator and a multiplexer each (ties to
//! the first child). Half a level is folded into every bias — adding a
//! constant commutes with MIN and MAX — so that the answer plus the current
//! word is the next level's sum ready to round: wrapped once onto the
//! circle for an angle, shifted down to a level, clamped. Every sum is as
//! wide as its range over every input word ([`FixedOutput::piece_bits`],
//! [`FixedOutput::sum_bits`]), so no overflow is possible.
//!
//! One description, two circuits ([`Form`]): combinational, every node a
//! wire (latency: one path from inputs to level), and pipelined, every
//! node a register one clock after its operands, shorter paths delayed to
//! meet (throughput: one state a clock, the clock as fast as one adder or
//! comparator allows).

use std::fmt::Write as _;

use alnlab_aln::pwl::Node;
use alnlab_aln::pwl::fixed::{FixedOutput, signed_digits};
use serde::{Deserialize, Serialize};

use crate::verilog::ident;

/// How the nodes are built.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Form {
    /// Every node a wire: one combinational path.
    Combinational,
    /// Every node a register: one state a clock.
    Pipelined,
}

impl Form {
    /// Both, combinational first.
    pub const ALL: [Form; 2] = [Form::Combinational, Form::Pipelined];

    /// As tables name it.
    pub fn name(self) -> &'static str {
        match self {
            Form::Combinational => "combinational",
            Form::Pipelined => "pipelined",
        }
    }

    /// The form a table names.
    pub fn named(name: &str) -> Option<Form> {
        Form::ALL.into_iter().find(|f| f.name() == name)
    }
}

/// One operation of the datapath.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Op {
    /// Input word `k` (the tree's inputs in order, then the current word).
    Input(usize),
    /// A constant.
    Constant(i64),
    /// A node shifted left by some bits, or right (floored) when
    /// negative: wiring, no logic.
    Shift(usize, i32),
    /// a + b, or a − b.
    Add(usize, usize, bool),
    /// The second operand when it is less (MIN) or greater (MAX) than the
    /// first, else the first.
    Min(usize, usize),
    Max(usize, usize),
    /// A sum (half a level in it) wrapped once onto the turn.
    Wrap(usize),
    /// A sum's level: shifted down, clamped to the levels.
    Level(usize),
}

/// One node: its operation and its width (bits, signed).
#[derive(Clone, Copy, Debug)]
struct Datum {
    op: Op,
    bits: u32,
}

/// An output's datapath, operands before the nodes that use them.
#[derive(Clone, Debug)]
pub struct Datapath {
    data: Vec<Datum>,
    /// Input words' widths, the current word's last.
    pub ports: Vec<u32>,
    /// The node holding the next level.
    level: usize,
    /// Bits of the level.
    pub level_bits: u32,
    fixed: FixedOutput,
}

impl Datapath {
    /// `fixed`'s datapath: pieces, MIN/MAX tree, advance, wrap, level.
    pub fn new(fixed: &FixedOutput) -> Datapath {
        let inputs = fixed.inputs.len();
        let (piece_bits, sum_bits) = (fixed.piece_bits, fixed.sum_bits);
        let mut data: Vec<Datum> = Vec::new();
        let push = |data: &mut Vec<Datum>, op, bits| {
            data.push(Datum { op, bits });
            data.len() - 1
        };
        let words: Vec<usize> = (0..=inputs)
            .map(|k| push(&mut data, Op::Input(k), fixed.widths.input_bits))
            .collect();
        let mut pieces = Vec::new();
        for piece in fixed.coefficients.chunks_exact(inputs + 1) {
            // The bias (the origin and half a level in it) and every
            // weight's digits.
            let bias = push(
                &mut data,
                Op::Constant(piece[0] + fixed.piece_offset()),
                piece_bits,
            );
            let mut terms: Vec<(usize, bool)> = vec![(bias, false)];
            for (k, &w) in piece[1..].iter().enumerate() {
                for (digit, negative) in signed_digits(w) {
                    let term = match digit as i32 - fixed.dropped as i32 {
                        0 => words[k],
                        s => push(&mut data, Op::Shift(words[k], s), piece_bits),
                    };
                    terms.push((term, negative));
                }
            }
            pieces.push(sum_tree(&mut data, terms, piece_bits));
        }
        // The MIN/MAX tree from the leaves up (children after parents).
        let mut value = vec![usize::MAX; fixed.nodes.len()];
        for (j, node) in fixed.nodes.iter().enumerate().rev() {
            value[j] = match *node {
                Node::Piece(p) => pieces[p as usize],
                Node::Min(a, b) => {
                    let op = Op::Min(value[a as usize], value[b as usize]);
                    push(&mut data, op, piece_bits)
                }
                Node::Max(a, b) => {
                    let op = Op::Max(value[a as usize], value[b as usize]);
                    push(&mut data, op, piece_bits)
                }
            };
        }
        let current = push(
            &mut data,
            Op::Shift(words[inputs], (fixed.weight_frac - fixed.dropped) as i32),
            sum_bits,
        );
        let mut sum = push(&mut data, Op::Add(current, value[0], false), sum_bits);
        if fixed.turn.is_some() {
            sum = push(&mut data, Op::Wrap(sum), sum_bits);
        }
        let level_bits = (u32::BITS - fixed.levels.saturating_sub(1).leading_zeros()).max(1);
        // Signed, a bit above the level's, so that no expression is unsigned.
        let level = push(&mut data, Op::Level(sum), level_bits + 1);
        Datapath {
            data,
            ports: vec![fixed.widths.input_bits; inputs + 1],
            level,
            level_bits,
            fixed: fixed.clone(),
        }
    }

    /// The bits of its arithmetic: every adder's, comparator's (with its
    /// multiplexer) and the level's width, summed — what the circuit's
    /// size grows with.
    pub fn arithmetic_bits(&self) -> u64 {
        self.data
            .iter()
            .filter(|d| !matches!(d.op, Op::Input(_) | Op::Constant(_) | Op::Shift(..)))
            .map(|d| u64::from(d.bits))
            .sum()
    }

    /// Clocks from the inputs to the level in the pipelined form.
    pub fn latency(&self) -> u32 {
        self.clocks()[self.level]
    }

    /// Each node's clock in the pipelined form: one after its latest
    /// operand's; inputs, constants and wiring take none.
    fn clocks(&self) -> Vec<u32> {
        let mut clock = vec![0u32; self.data.len()];
        for (n, d) in self.data.iter().enumerate() {
            clock[n] = match d.op {
                Op::Input(_) | Op::Constant(_) => 0,
                Op::Shift(a, _) => clock[a],
                Op::Add(a, b, _) | Op::Min(a, b) | Op::Max(a, b) => clock[a].max(clock[b]) + 1,
                Op::Wrap(a) | Op::Level(a) => clock[a] + 1,
            };
        }
        clock
    }

    /// The operands of node `n` that hold logic (through shifts).
    fn operands(&self, n: usize) -> Vec<usize> {
        match self.data[n].op {
            Op::Add(a, b, _) | Op::Min(a, b) | Op::Max(a, b) => vec![a, b],
            Op::Wrap(a) | Op::Level(a) | Op::Shift(a, _) => vec![a],
            Op::Input(_) | Op::Constant(_) => Vec::new(),
        }
    }

    /// The register or wire a node's value is in (inputs by their ports).
    fn base(&self, n: usize) -> String {
        match self.data[n].op {
            Op::Input(k) if k + 1 == self.ports.len() => "current".into(),
            Op::Input(k) => format!("x{k}"),
            _ => format!("n{n}"),
        }
    }

    /// The Verilog module `module` of this datapath in `form`: ports
    /// `x<k>` (the tree's inputs in order), `current` (the predicted
    /// variable's word), `next` (its level), and `clk` when pipelined.
    pub fn verilog(&self, module: &str, variable: &str, form: Form) -> String {
        let f = &self.fixed;
        let pipelined = form == Form::Pipelined;
        let clock = self.clocks();
        let mut text = String::new();
        let _ = writeln!(
            text,
            "// `{variable}`: {} pieces over {} inputs in fixed point ({}-bit input words, {} \
             fractional; {}-bit weights, {} fractional), {}.",
            f.coefficients.len() / (f.inputs.len() + 1),
            f.inputs.len(),
            f.widths.input_bits,
            f.input_frac,
            f.widths.weight_bits,
            f.weight_frac,
            match form {
                Form::Combinational => "combinational".to_string(),
                Form::Pipelined => format!(
                    "pipelined: the level {} clocks after its inputs",
                    self.latency()
                ),
            }
        );
        let mut ports: Vec<String> = Vec::new();
        if pipelined {
            ports.push("input wire clk".into());
        }
        for (k, &w) in self.ports.iter().enumerate() {
            let name = self.base(k);
            ports.push(format!("input wire signed [{}:0] {name}", w - 1));
        }
        ports.push(format!("output wire [{}:0] next", self.level_bits - 1));
        let _ = writeln!(text, "module {module} (\n  {}\n);", ports.join(",\n  "));
        // How many clocks past its own each node's value is still needed:
        // a register chain delays it for operations further down the pipe.
        let mut wait = vec![0u32; self.data.len()];
        for (n, d) in self.data.iter().enumerate() {
            if matches!(d.op, Op::Shift(..) | Op::Input(_) | Op::Constant(_)) {
                continue;
            }
            for a in self.operands(n) {
                let a = self.through_shifts(a);
                if let Op::Constant(_) = self.data[a].op {
                    continue;
                }
                wait[a] = wait[a].max(clock[n] - 1 - clock[a]);
            }
        }
        let kind = if pipelined { "reg" } else { "wire" };
        for (n, d) in self.data.iter().enumerate() {
            if !matches!(d.op, Op::Shift(..) | Op::Input(_) | Op::Constant(_)) {
                let _ = writeln!(text, "  {kind} signed [{}:0] n{n};", d.bits - 1);
            }
        }
        if pipelined {
            for (n, &wait) in wait.iter().enumerate() {
                let (base, bits) = (self.base(n), self.data[n].bits);
                for d in 1..=wait {
                    let from = if d == 1 {
                        base.clone()
                    } else {
                        format!("{base}_d{}", d - 1)
                    };
                    let _ = writeln!(
                        text,
                        "  reg signed [{}:0] {base}_d{d};\n  always @(posedge clk) {base}_d{d} <= \
                         {from};",
                        bits - 1
                    );
                }
            }
        }
        for (n, d) in self.data.iter().enumerate() {
            // Operands as they are one clock before this node's.
            let at = clock[n].saturating_sub(1);
            let operand =
                |a: usize| self.operand(a, if pipelined { Some(at) } else { None }, &clock);
            let bits = |a: usize| self.data[a].bits;
            let expr = match d.op {
                Op::Input(_) | Op::Shift(..) | Op::Constant(_) => continue,
                Op::Add(a, b, minus) => {
                    format!(
                        "{} {} {}",
                        operand(a),
                        if minus { "-" } else { "+" },
                        operand(b)
                    )
                }
                Op::Min(a, b) => {
                    let (a, b) = (operand(a), operand(b));
                    format!("({b} < {a}) ? {b} : {a}")
                }
                Op::Max(a, b) => {
                    let (a, b) = (operand(a), operand(b));
                    format!("({b} > {a}) ? {b} : {a}")
                }
                Op::Wrap(a) => {
                    let w = bits(a);
                    let turn = f.turn.expect("a wrap has a turn");
                    let half = f.half();
                    let a = operand(a);
                    format!(
                        "({a} < {low}) ? {a} + {t} : ({a} >= {high}) ? {a} - {t} : {a}",
                        low = wide_constant(half, w),
                        high = wide_constant(turn + half, w),
                        t = wide_constant(turn, w),
                    )
                }
                Op::Level(a) => {
                    let w = bits(a);
                    let q = format!("({} >>> {})", operand(a), f.scale());
                    format!(
                        "({q} < {zero}) ? {zero} : ({q} > {top}) ? {top} : {q}",
                        zero = wide_constant(0, w),
                        top = wide_constant(i64::from(f.levels) - 1, w),
                    )
                }
            };
            if pipelined {
                let _ = writeln!(text, "  always @(posedge clk) n{n} <= {expr};");
            } else {
                let _ = writeln!(text, "  assign n{n} = {expr};");
            }
        }
        let _ = writeln!(
            text,
            "  assign next = n{}[{}:0];\nendmodule",
            self.level,
            self.level_bits - 1
        );
        text
    }

    /// The node whose value `n` carries: a shift's operand, or itself.
    fn through_shifts(&self, n: usize) -> usize {
        match self.data[n].op {
            Op::Shift(a, _) => self.through_shifts(a),
            _ => n,
        }
    }

    /// Node `a` as an operand: a constant its value, a shift the shifted
    /// operand (signed: extended to the expression's width first), a
    /// node by its name — at clock `at` in the pipelined form, from its
    /// delay chain when it was computed earlier.
    fn operand(&self, a: usize, at: Option<u32>, clock: &[u32]) -> String {
        let d = &self.data[a];
        match d.op {
            Op::Constant(c) => constant(c, d.bits),
            Op::Shift(b, s) if s >= 0 => format!("({} <<< {s})", self.operand(b, at, clock)),
            Op::Shift(b, s) => format!("({} >>> {})", self.operand(b, at, clock), -s),
            _ => {
                let base = self.base(a);
                match at.map_or(0, |at| at - clock[a]) {
                    0 => base,
                    wait => format!("{base}_d{wait}"),
                }
            }
        }
    }
}

impl Datapath {
    /// Every port's word of `rows` (each row: the tree's input words, then
    /// the current word) as hex lines, the first port in the top bits:
    /// what [`Datapath::testbench`] reads.
    pub fn rows_hex(&self, rows: &[Vec<i64>]) -> String {
        let total: u32 = self.ports.iter().sum();
        let digits = total.div_ceil(4) as usize;
        let mut text = String::with_capacity(rows.len() * (digits + 1));
        for row in rows {
            let mut bits = vec![false; total as usize];
            let mut at = total as usize;
            for (&word, &w) in row.iter().zip(&self.ports) {
                at -= w as usize;
                for b in 0..w as usize {
                    bits[at + b] = (word >> b) & 1 == 1;
                }
            }
            for d in (0..digits).rev() {
                let nibble = (0..4).fold(0u32, |n, i| {
                    n | (u32::from(bits.get(4 * d + i).copied().unwrap_or(false)) << i)
                });
                text.push(char::from_digit(nibble, 16).expect("a nibble"));
            }
            text.push('\n');
        }
        text
    }

    /// A testbench (module `tb`) applying every row of `inputs` (hex, as
    /// [`Datapath::rows_hex`]) to `module` in `form` and writing each
    /// row's level to `output`, a decimal line a row: combinationally,
    /// or a row a clock, the levels written as they leave the pipeline.
    pub fn testbench(
        &self,
        module: &str,
        form: Form,
        rows: usize,
        inputs: &str,
        output: &str,
    ) -> String {
        let total: u32 = self.ports.iter().sum();
        let mut text = format!(
            "`timescale 1ns/1ns\n// Applies every row to `{module}` and writes its level.\nmodule tb;\n  \
             reg [{}:0] rows [0:{}];\n  reg [{}:0] x;\n  reg clk;\n  wire [{}:0] next;\n",
            total - 1,
            rows - 1,
            total - 1,
            self.level_bits - 1
        );
        let mut connections = Vec::new();
        if form == Form::Pipelined {
            connections.push(".clk(clk)".to_string());
        }
        let mut at = total;
        for (k, &w) in self.ports.iter().enumerate() {
            connections.push(format!(".{}(x[{}:{}])", self.base(k), at - 1, at - w));
            at -= w;
        }
        connections.push(".next(next)".into());
        let _ = writeln!(
            text,
            "  {module} dut ({});\n  integer r, f;\n  initial begin\n    clk = 0;\n    \
             $readmemh(\"{inputs}\", rows);\n    f = $fopen(\"{output}\", \"w\");",
            connections.join(", ")
        );
        match form {
            Form::Combinational => {
                let _ = writeln!(
                    text,
                    "    for (r = 0; r < {rows}; r = r + 1) begin\n      x = rows[r];\n      \
                     #1 $fwrite(f, \"%0d\\n\", next);\n    end"
                );
            }
            Form::Pipelined => {
                // Row r enters before clock edge r; its level is out after
                // edge r + latency − 1.
                let latency = self.latency();
                let _ = writeln!(
                    text,
                    "    for (r = 0; r < {end}; r = r + 1) begin\n      \
                     x = rows[r < {rows} ? r : {last}];\n      #1 clk = 1;\n      #1 clk = 0;\n      \
                     if (r >= {first}) $fwrite(f, \"%0d\\n\", next);\n    end",
                    end = rows as u32 + latency - 1,
                    last = rows - 1,
                    first = latency - 1,
                );
            }
        }
        let _ = writeln!(text, "    $fclose(f);\n    $finish;\n  end\nendmodule");
        text
    }
}

/// `value` as a signed Verilog constant of at least `bits` bits, wider
/// when it needs more: compared with or added to a narrower operand, which
/// a signed expression extends, it keeps its value.
fn wide_constant(value: i64, bits: u32) -> String {
    let own =
        64 - if value < 0 {
            value.leading_ones()
        } else {
            value.leading_zeros()
        } + 1;
    constant(value, bits.max(own))
}

/// `value` as a `bits`-wide signed Verilog constant.
fn constant(value: i64, bits: u32) -> String {
    let mask = if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    };
    format!("$signed({bits}'h{:x})", (value as u64) & mask)
}

/// The sum of `terms` (node, subtracted; the first one added) as a
/// balanced tree of adders of `bits`: its root.
fn sum_tree(data: &mut Vec<Datum>, mut terms: Vec<(usize, bool)>, bits: u32) -> usize {
    while terms.len() > 1 {
        let mut next = Vec::with_capacity(terms.len().div_ceil(2));
        for pair in terms.chunks(2) {
            next.push(match *pair {
                [one] => one,
                [(a, na), (b, nb)] => {
                    // a − b when their signs differ (the added one first);
                    // a sum of two subtracted terms is subtracted.
                    let (first, second) = if na { (b, a) } else { (a, b) };
                    data.push(Datum {
                        op: Op::Add(first, second, na != nb),
                        bits,
                    });
                    (data.len() - 1, na && nb)
                }
                _ => unreachable!("chunks of two"),
            });
        }
        terms = next;
    }
    let (root, subtracted) = terms[0];
    assert!(!subtracted, "the first term, the bias, is added");
    root
}

/// The module name of variable `variable`'s predictor.
pub fn module_name(variable: &str) -> String {
    format!("pwl_{}", ident(variable))
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_aln::model::Reads;
    use alnlab_aln::pwl::Tree;
    use alnlab_aln::pwl::fixed::Widths;
    use alnlab_codes::{Code, Entry, Quantizer};

    fn entry(variable: &str, min: f64, max: f64, levels: usize) -> Entry {
        Entry {
            variable: variable.into(),
            learned: true,
            note: String::new(),
            quantizer: Quantizer { min, max, levels },
            code: Code::Gray,
            width: 8,
            walk_step: 0,
            walk_span: 0,
            seed: 1,
            clamped: 0,
        }
    }

    /// A tree over `inputs` inputs grown by `splits` random MIN/MAX splits.
    fn random_tree(inputs: usize, splits: usize, seed: u64) -> Tree {
        let mut state = seed | 1;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let weights: Vec<f64> = (0..inputs).map(|_| next() * 20.0).collect();
        let mut tree = Tree::affine(next(), &weights);
        for _ in 0..splits {
            let p = ((next() + 1.0) / 2.0 * tree.pieces() as f64) as usize % tree.pieces();
            let copy = tree.split(p, next() > 0.0);
            let weights: Vec<f64> = (0..inputs).map(|_| next() * 20.0).collect();
            tree.set_piece(copy, next() * 3.0, &weights);
        }
        tree
    }

    /// Both forms of random outputs (one an angle that wraps) simulated by
    /// Icarus Verilog on random and saturated words, each row's level the
    /// fixed-point evaluator's.
    #[test]
    #[ignore = "full suite: needs Yosys and Icarus Verilog"]
    fn both_forms_equal_the_evaluator_on_every_row() {
        let tau = std::f64::consts::TAU;
        let entries = [
            entry("a.1.x", -4.0, 4.0, 101),
            entry("roll.2", -tau / 2.0, tau / 2.0, 64),
            entry("v.3.y", -1.0, 1.0, 214),
            // Far more levels than a narrow sum spans: the clamp's top
            // constant is wider than the sum it is compared with.
            entry("g.4.z", -1.0, 1.0, 65536),
        ];
        let learned: Vec<&Entry> = entries.iter().collect();
        let cases = [
            (
                0,
                vec![0, 2],
                9,
                Widths {
                    input_bits: 12,
                    weight_bits: 8,
                },
            ),
            (
                1,
                vec![1, 0, 2],
                6,
                Widths {
                    input_bits: 10,
                    weight_bits: 6,
                },
            ),
            (
                2,
                vec![2],
                0,
                Widths {
                    input_bits: 14,
                    weight_bits: 10,
                },
            ),
            (
                3,
                vec![3],
                3,
                Widths {
                    input_bits: 6,
                    weight_bits: 6,
                },
            ),
        ];
        let dir = tempfile::tempdir().unwrap();
        for (case, (variable, inputs, splits, widths)) in cases.into_iter().enumerate() {
            let tree = random_tree(inputs.len(), splits, case as u64 + 3);
            let reads = Reads { variable, inputs };
            let int = if variable == 3 { 3 } else { 7 };
            let origins = [50, 31, 106, 6];
            let fixed = FixedOutput::new(&tree, &reads, &learned, &origins, int, widths).unwrap();
            let datapath = Datapath::new(&fixed);
            let top = (1i64 << (widths.input_bits - 1)) - 1;
            let mut state = 0x9e37_79b9_7f4a_7c15u64 + case as u64;
            let mut word = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                // Mostly within the levels, some anywhere a word can be.
                match state >> 60 {
                    0 => top,
                    1 => -top - 1,
                    2 | 3 => (state >> 20) as i64 % (top + 1),
                    _ => (((state >> 30) % (100 << fixed.input_frac)) as i64).min(top),
                }
            };
            let rows: Vec<Vec<i64>> = (0..300)
                .map(|_| (0..datapath.ports.len()).map(|_| word()).collect())
                .collect();
            let expected: Vec<u16> = rows
                .iter()
                .map(|r| {
                    let (words, current) = r.split_at(r.len() - 1);
                    fixed.next_level(current[0], fixed.change(words))
                })
                .collect();
            let mut distinct = expected.clone();
            distinct.sort_unstable();
            distinct.dedup();
            assert!(distinct.len() > 5, "case {case}: {distinct:?}");
            let inputs = format!("rows{case}.hex");
            std::fs::write(dir.path().join(&inputs), datapath.rows_hex(&rows)).unwrap();
            for form in Form::ALL {
                let module = format!("m{case}_{}", form.name());
                let file = format!("{module}.v");
                let text = datapath.verilog(&module, "x", form);
                std::fs::write(dir.path().join(&file), text).unwrap();
                let bench = format!("tb_{module}.v");
                let out = format!("out_{module}.txt");
                let tb = datapath.testbench(&module, form, rows.len(), &inputs, &out);
                std::fs::write(dir.path().join(&bench), tb).unwrap();
                let got = crate::simulate::run_bench(
                    crate::simulate::Simulator::Icarus,
                    &bench,
                    &[file],
                    &[],
                    &out,
                    rows.len(),
                    dir.path(),
                )
                .unwrap();
                assert_eq!(got, expected, "case {case}, {form:?}");
            }
            if case == 1 {
                assert!(fixed.turn.is_some());
                assert!(datapath.latency() >= 4, "{}", datapath.latency());
            }
        }
    }
}
