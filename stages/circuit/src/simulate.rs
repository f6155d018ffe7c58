//! The circuit run by Icarus Verilog: a testbench per learned variable
//! reads every row's input bits (and, for a change target, the current
//! level) from hex files, applies them one by one and writes the level the
//! variable's module puts out.

use std::fmt::Write;
use std::path::Path;

use alnlab_codes::bits::encode;
use alnlab_codes::codes::Codec;
use alnlab_common::{Error, Result};

use crate::tools;
use crate::verilog::Circuit;

/// The file of every row's input bits, one row per line in hex.
const INPUTS: &str = "inputs.hex";

/// Writes the rows' input bits (`x`: levels `[variable][row]`, coded by
/// `codecs`) and each change target's current levels into `dir`, for
/// [`run`].
pub fn write_rows(circuit: &Circuit, codecs: &[Codec], x: &[Vec<u16>], dir: &Path) -> Result<()> {
    let refs: Vec<&Codec> = codecs.iter().collect();
    let columns: Vec<&[u16]> = x.iter().map(Vec::as_slice).collect();
    let bits = encode(&refs, &columns);
    let total = circuit.input_bits();
    let digits = total.div_ceil(4);
    let mut text = String::with_capacity(bits.rows() * (digits + 1));
    for r in 0..bits.rows() {
        let row = bits.row(r);
        for d in (0..digits).rev() {
            let nibble = (0..4).fold(0u32, |n, i| {
                let b = 4 * d + i;
                n | (u32::from(b < total && row[b / 64] >> (b % 64) & 1 == 1) << i)
            });
            text.push(char::from_digit(nibble, 16).expect("a nibble"));
        }
        text.push('\n');
    }
    write(&dir.join(INPUTS), &text)?;
    for (v, variable) in circuit.variables.iter().enumerate() {
        if variable.takes_current {
            let mut text = String::new();
            for level in &x[v] {
                let _ = writeln!(text, "{level:x}");
            }
            write(&dir.join(current_file(&variable.ident)), &text)?;
        }
    }
    Ok(())
}

fn current_file(ident: &str) -> String {
    format!("current_{ident}.hex")
}

fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).map_err(|e| Error::io(path, e))
}

/// The levels variable `v`'s module puts out for the `rows` rows written by
/// [`write_rows`], simulating the Verilog `sources` (files in `dir`: the
/// exported ones or a netlist and its cells' models) with the preprocessor
/// `defines`; `tag` keeps the files of several simulations apart.
pub fn run(
    circuit: &Circuit,
    v: usize,
    sources: &[String],
    defines: &[&str],
    rows: usize,
    dir: &Path,
    tag: &str,
) -> Result<Vec<u16>> {
    let c = &circuit.variables[v];
    let total = circuit.input_bits();
    let out = format!("out_{tag}_{}.txt", c.ident);
    let mut tb = format!(
        "`timescale 1ns/1ns\n// Applies every row to `{}` and writes its level.\nmodule tb;\n  \
         reg [{}:0] rows [0:{}];\n  reg [{}:0] x;\n",
        c.module,
        total - 1,
        rows - 1,
        total - 1
    );
    let mut connections: Vec<String> = c
        .reads
        .iter()
        .map(|&b| {
            let bus = &circuit.inputs[b];
            format!(
                ".{}(x[{}:{}])",
                bus.ident,
                bus.offset + bus.width - 1,
                bus.offset
            )
        })
        .collect();
    if c.takes_current {
        let _ = writeln!(
            tb,
            "  reg [{0}:0] currents [0:{1}];\n  reg [{0}:0] current;",
            c.level_bits - 1,
            rows - 1
        );
        connections.push(format!(".{}_current(current)", c.ident));
    }
    connections.push(format!(".{}_next(next)", c.ident));
    let _ = writeln!(
        tb,
        "  wire [{}:0] next;\n  {} dut ({});\n  integer r, f;\n  initial begin\n    \
         $readmemh(\"{INPUTS}\", rows);",
        c.level_bits - 1,
        c.module,
        connections.join(", ")
    );
    if c.takes_current {
        let _ = writeln!(
            tb,
            "    $readmemh(\"{}\", currents);",
            current_file(&c.ident)
        );
    }
    let _ = writeln!(
        tb,
        "    f = $fopen(\"{out}\", \"w\");\n    for (r = 0; r < {rows}; r = r + 1) begin\n      \
         x = rows[r];{}\n      #1 $fwrite(f, \"%0d\\n\", next);\n    end\n    $fclose(f);\n    \
         $finish;\n  end\nendmodule",
        if c.takes_current {
            " current = currents[r];"
        } else {
            ""
        }
    );
    let bench = format!("tb_{tag}_{}.v", c.ident);
    write(&dir.join(&bench), &tb)?;
    run_bench(Simulator::Icarus, &bench, sources, defines, &out, rows, dir)
}

/// What simulates a testbench.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Simulator {
    /// Icarus Verilog: event-driven, compiles in a blink; a gate-level
    /// netlist of thousands of lookup tables runs a dozen rows a second.
    Icarus,
    /// Verilator: compiled to C++ first (seconds, tens of them for a large
    /// netlist), then thousands of rows a second at any size.
    Verilator,
}

/// Compiles the testbench `bench` (module `tb`) with `sources` and
/// `defines` (by `simulator`, in `dir`), runs it and reads the `rows`
/// levels it writes to `out`, one decimal line a row.
pub fn run_bench(
    simulator: Simulator,
    bench: &str,
    sources: &[String],
    defines: &[&str],
    out: &str,
    rows: usize,
    dir: &Path,
) -> Result<Vec<u16>> {
    let stem = bench.trim_end_matches(".v");
    let defines: Vec<String> = defines.iter().map(|d| format!("-D{d}")).collect();
    match simulator {
        Simulator::Icarus => {
            let compiled = format!("{stem}.vvp");
            let mut args = vec!["-g2005", "-o", compiled.as_str(), "-s", "tb"];
            args.extend(defines.iter().map(String::as_str));
            args.extend(sources.iter().map(String::as_str));
            args.push(bench);
            tools::run("iverilog", &args, dir)?;
            tools::run("vvp", &["-n", &compiled], dir)?;
        }
        Simulator::Verilator => {
            let build = format!("obj_{stem}");
            // One compiler at a time (the stage runs variables side by
            // side), unoptimised: the compile is most of the time.
            let mut args = vec![
                "--binary",
                "-j",
                "1",
                "-Wno-fatal",
                "-Wno-lint",
                "-Wno-style",
                "-MAKEFLAGS",
                "OPT_FAST=-O0 OPT_SLOW=-O0 OPT_GLOBAL=-O0",
                "--top-module",
                "tb",
                "--Mdir",
                build.as_str(),
                "-o",
                "tb",
            ];
            args.extend(defines.iter().map(String::as_str));
            args.extend(sources.iter().map(String::as_str));
            args.push(bench);
            tools::run("verilator", &args, dir)?;
            let build = dir.join(&build);
            tools::run(&build.join("tb").to_string_lossy(), &[], dir)?;
            // Megabytes of C++ and objects a design: gone once run.
            std::fs::remove_dir_all(&build).map_err(|e| Error::io(&build, e))?;
        }
    }
    let path = dir.join(out);
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
    let levels: Vec<u16> = text
        .lines()
        .map(|l| l.trim().parse::<u16>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| Error::bad_file(&path, format!("expected one level per line ({e})")))?;
    if levels.len() != rows {
        return Err(Error::bad_file(
            &path,
            format!("{} levels, expected one per row ({rows})", levels.len()),
        ));
    }
    Ok(levels)
}
