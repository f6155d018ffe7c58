//! The whole measurement: write the circuit, synthesize every variable,
//! simulate both the exported Verilog and the synthesized netlist on rows
//! of levels, and hold both to the software's predictions, row by row.

use std::path::Path;

use alnlab_codes::codes::Codec;
use alnlab_common::{Error, Progress, Result};
use rayon::prelude::*;

use crate::fpga::{self, Device};
use crate::synth::{self, Figures, LIBRARY, VariableFigures};
use crate::verilog::{COMMON_FILE, Circuit};
use crate::{simulate, tools};

/// Writes the circuit's files into `dir`.
pub fn write_files(circuit: &Circuit, dir: &Path) -> Result<()> {
    for (name, text) in &circuit.files {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(|e| Error::io(&path, e))?;
    }
    Ok(())
}

/// What [`measure`] measured: the synthesized circuit and, when asked,
/// every variable placed and routed on an FPGA.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    /// The synthesized circuit: gates and gate levels per variable.
    pub figures: Figures,
    /// Every variable placed and routed, when asked.
    pub fpga: Option<fpga::State>,
}

/// Synthesizes `circuit` in `dir` (a scratch folder) and, for the rows of
/// levels `x` (`[variable][row]`, coded by `codecs`), simulates the
/// exported Verilog and the synthesized netlist of every variable; both
/// must put out the `expected` levels (`[variable][row]`: the software's),
/// or the error names the variable, the row and both levels. With `fpga`
/// (a device and a seed, taken modulo [`fpga::NEXTPNR_SEEDS`] for nextpnr),
/// every variable is also mapped, placed
/// and routed on it ([`fpga::place_and_route`]) and its mapped netlist
/// held to the same rows. Variables run in parallel on rayon's threads.
pub fn measure(
    circuit: &Circuit,
    codecs: &[Codec],
    x: &[Vec<u16>],
    expected: &[Vec<u16>],
    fpga: Option<(Device, u64)>,
    dir: &Path,
    progress: &dyn Progress,
) -> Result<Measurement> {
    let tools = tools::versions()?;
    let fpga = fpga.map(|(device, seed)| (device, seed % fpga::NEXTPNR_SEEDS));
    let fpga_tools = fpga.map(|_| fpga::tool_versions()).transpose()?;
    let cell_models = fpga
        .map(|_| tools::yosys_data(fpga::ICE40_MODELS))
        .transpose()?
        .map(|p| p.display().to_string());
    write_files(circuit, dir)?;
    let rows = x.first().map_or(0, Vec::len);
    if rows > 0 {
        simulate::write_rows(circuit, codecs, x, dir)?;
    }
    progress.start("circuit", circuit.variables.len() as u64, "variables");
    let measured: Vec<(VariableFigures, Option<fpga::Placed>)> = (0..circuit.variables.len())
        .into_par_iter()
        .map(|v| {
            let c = &circuit.variables[v];
            let figures = synth::synthesize(circuit, v, dir)?;
            let placed = fpga
                .map(|(device, seed)| fpga::place_and_route(circuit, v, device, seed, dir))
                .transpose()?;
            if rows > 0 {
                let exported = vec![COMMON_FILE.to_string(), c.file.clone()];
                let mut netlists = vec![("exported", exported, &[][..])];
                netlists.push(("synthesized", vec![synth::netlist_file(c)], &[]));
                if let Some(models) = &cell_models {
                    let mapped = vec![fpga::mapped_file(circuit, v), models.clone()];
                    netlists.push(("mapped", mapped, fpga::ICE40_DEFINES));
                }
                for (tag, sources, defines) in netlists {
                    let got = simulate::run(circuit, v, &sources, defines, rows, dir, tag)?;
                    if let Some(r) = (0..rows).find(|&r| got[r] != expected[v][r]) {
                        return Err(Error::Corrupt(format!(
                            "the {tag} circuit of `{}` puts out level {} on row {r}, the \
                             software predicts {}",
                            c.variable, got[r], expected[v][r]
                        )));
                    }
                }
            }
            progress.advance(1);
            Ok((figures, placed))
        })
        .collect::<Result<_>>()?;
    let (variables, placed): (Vec<_>, Vec<_>) = measured.into_iter().unzip();
    let fpga = fpga
        .zip(fpga_tools)
        .map(|((device, seed), tools)| fpga::State {
            device,
            form: crate::datapath::Form::Combinational,
            seed,
            tools,
            variables: placed.into_iter().flatten().collect(),
        });
    Ok(Measurement {
        figures: Figures {
            tools,
            library: LIBRARY.to_string(),
            variables,
        },
        fpga,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_aln::forest::TreeId;
    use alnlab_aln::model::Header;
    use alnlab_aln::runtime::Runtime;
    use alnlab_aln::tree::{Tree, TreeSpec};
    use alnlab_aln::{Model, ModelKind, Output, Target};
    use alnlab_codes::walk::WalkSpec;
    use alnlab_codes::{Code, DeltaSpec, Residual};
    use alnlab_common::Silent;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn walk(levels: usize, width: u32) -> Codec {
        let spec = WalkSpec {
            levels,
            width,
            step: 1,
            span: 3,
            seed: 5,
        };
        Codec::new(Code::Walk, levels, Some(spec)).unwrap()
    }

    /// A model of random trees over the codes of `codecs`, for `outputs`.
    fn model(codecs: &[Codec], outputs: &[Output], target: Target, vote: u32) -> Model {
        let inputs: usize = codecs.iter().map(|c| c.width() as usize).sum();
        let spec = TreeSpec {
            leaves: 64,
            inputs,
            counter_bound: 7,
            initial_spread: 1,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut trees = Vec::new();
        for (v, output) in outputs.iter().enumerate() {
            for bit in 0..output.codec().width() {
                for voter in 0..vote {
                    let id = TreeId {
                        variable: v as u32,
                        bit,
                        vote: voter,
                    };
                    trees.push((id, Tree::new(&spec, &mut rng)));
                }
            }
        }
        let header = Header {
            codebook_sha256: String::new(),
            params: serde_json::Value::Null,
            model: ModelKind::BitForest,
            target,
            inputs,
            outputs: outputs
                .iter()
                .enumerate()
                .map(|(v, o)| (format!("x.{v}"), o.codec().width() as usize))
                .collect(),
            reads: Vec::new(),
            vote,
            counter_bound: 7,
            shard: None,
            base: alnlab_aln::model::Base::Current,
        };
        Model {
            header,
            trees,
            pieces: Vec::new(),
        }
    }

    /// Random rows, the circuit measured on them against the software.
    fn check(names: &[&str], codecs: &[Codec], outputs: &[Output], model: &Model) -> Figures {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<Vec<u16>> = codecs
            .iter()
            .map(|c| {
                (0..200)
                    .map(|_| rng.random_range(0..c.levels() as u16))
                    .collect()
            })
            .collect();
        let expected = Runtime::new(model, codecs, outputs)
            .unwrap()
            .levels(&x, None);
        let names: Vec<String> = names.iter().map(|n| n.to_string()).collect();
        let circuit = Circuit::new(model, &names, codecs, outputs).unwrap();
        let dir = tempfile::tempdir().unwrap();
        measure(&circuit, codecs, &x, &expected, None, dir.path(), &Silent)
            .unwrap()
            .figures
    }

    #[test]
    #[ignore = "full suite: needs Yosys and Icarus Verilog"]
    fn every_code_with_votes_equals_the_software_on_every_row() {
        let codecs = vec![
            walk(20, 10),
            Codec::new(Code::Gray, 13, None).unwrap(),
            Codec::new(Code::Binary, 10, None).unwrap(),
            Codec::new(Code::Thermometer, 6, None).unwrap(),
        ];
        let outputs: Vec<Output> = codecs.iter().cloned().map(Output::Level).collect();
        let model = model(&codecs, &outputs, Target::Level, 3);
        let figures = check(
            &["v.1.x", "roll.2", "g.0.z", "pitch.3"],
            &codecs,
            &outputs,
            &model,
        );
        assert_eq!(figures.variables.len(), 4);
        for v in &figures.variables {
            // 64-leaf trees are at most 6 AND/OR gates deep, plus inverters.
            assert!((1..=12).contains(&v.trees.depth), "{v:?}");
            assert!(v.votes.depth >= 2 && v.votes.cells > 0, "{v:?}");
        }
        // Gray to binary needs gates; a 10-level binary code only a clamp.
        assert!(figures.variables[1].decode.cells > 0);
        assert!(figures.variables[0].decode.depth > figures.variables[2].decode.depth);
    }

    #[test]
    #[ignore = "full suite: needs Yosys and Icarus Verilog"]
    fn change_targets_add_the_change_and_wrap_like_the_software() {
        let codecs = vec![walk(30, 12), Codec::new(Code::Gray, 40, None).unwrap()];
        let specs = [
            DeltaSpec {
                k: 4,
                period: Some(30),
                code: Code::Walk,
            },
            DeltaSpec {
                k: 3,
                period: None,
                code: Code::Gray,
            },
        ];
        let outputs: Vec<Output> = specs
            .iter()
            .zip(&codecs)
            .map(|(s, c)| Output::Delta(Residual::new(*s, c.levels(), 9).unwrap()))
            .collect();
        let model = model(&codecs, &outputs, Target::Delta(specs.to_vec()), 1);
        let figures = check(&["roll.1", "v.2.y"], &codecs, &outputs, &model);
        assert!(
            figures
                .variables
                .iter()
                .all(|v| v.votes == Default::default())
        );
    }
}
