//! A piecewise-linear model measured as a circuit: its fixed-point form
//! chosen on the training rows, every output's datapath written in both
//! forms, simulated on the test rows and held to the fixed-point evaluator
//! row by row, and — when asked — mapped onto an FPGA, placed and routed,
//! and the mapped netlist held to the same rows.

use std::path::Path;

use alnlab_aln::pwl::fixed::{self, FixedModel, FixedOutput, Widths};
use alnlab_aln::pwl::predict::{Predictor, states};
use alnlab_aln::runtime::Trained;
use alnlab_codes::Entry;
use alnlab_common::{Error, Progress, Result};
use rayon::prelude::*;

use crate::datapath::{Datapath, Form, module_name};
use crate::fpga::{self, Design, Device, Placed};
use crate::simulate::{Simulator, run_bench};
use crate::tools;

/// The rows a piecewise-linear circuit is measured on: the learned
/// variables' real values (`[variable][row]`) and the next levels, on the
/// training rows and the test rows.
pub struct Rows {
    pub train: Vec<Vec<f64>>,
    pub test: Vec<Vec<f64>>,
    /// The training rows' next levels (`[variable][row]`, every learned
    /// one).
    pub train_truth: Vec<Vec<u16>>,
    /// The test rows' next levels.
    pub truth: Vec<Vec<u16>>,
    /// The test rows' current levels.
    pub current: Vec<Vec<u16>>,
}

/// One output's fixed-point form and what it costs in levels.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct OutputFigures {
    pub variable: String,
    pub widths: Widths,
    pub input_frac: u32,
    pub weight_frac: u32,
    /// Bits of a piece's value.
    pub piece_bits: u32,
    pub pieces: u32,
    pub inputs: u32,
    /// Mean |fixed − float| in levels on the training rows (what chose
    /// the widths) and on the test rows.
    pub train_difference: f64,
    pub test_difference: f64,
    /// Mean |predicted − next| in levels on the test rows: the fixed-point
    /// model's, the floating-point model's and persistence's (the current
    /// level).
    pub fixed_error: f64,
    pub float_error: f64,
    pub persistence_error: f64,
    /// The test rows these figures are on, every one simulated equal to
    /// the evaluator by the circuits as written.
    pub rows: u64,
}

/// What [`measure`] measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    /// Per output, its fixed-point form and errors.
    pub outputs: Vec<OutputFigures>,
    /// Every output placed and routed in both forms, when asked.
    pub placed: Option<[fpga::State; 2]>,
    /// The test rows every output's circuits (as written) were simulated
    /// equal to the evaluator on: all of them.
    pub rows: usize,
    /// The first test rows the mapped netlists were simulated equal on.
    pub mapped_rows: usize,
}

/// How much higher the fixed-point model's error in levels may be than the
/// floating-point model's on the training rows when the widths are chosen
/// (half the acceptance's 0.01, for the held-out rows' noise).
pub const TOLERANCE: f64 = 0.005;

/// The fixed-point form of `trained` (a piecewise-linear model): at
/// `widths` for every output, or per output the narrowest whose error is
/// within `tolerance` levels of the floating-point model's on the training
/// rows.
pub fn fixed_model<'t>(
    trained: &'t Trained,
    rows: &Rows,
    widths: Option<Widths>,
    tolerance: f64,
) -> Result<(FixedModel, Predictor<'t>)> {
    let learned: Vec<&Entry> = trained.codebook.learned().collect();
    if let Some(r) = trained
        .reads
        .iter()
        .find(|r| r.inputs.iter().any(|&i| i >= learned.len()))
    {
        return Err(Error::Invalid(format!(
            "`{}` reads the nominal simulator's prediction: a hybrid has no circuit (the \
             simulator is not in it)",
            learned[r.variable].variable
        )));
    }
    let train: Vec<&[f64]> = rows.train.iter().map(Vec::as_slice).collect();
    let train_rows: Vec<usize> = (0..train.first().map_or(0, |c| c.len())).collect();
    let predictor = Predictor::new(
        &trained.model.pieces,
        &trained.reads,
        &learned,
        &states(&rows.train, &train_rows),
    );
    let widths = match widths {
        Some(w) => vec![w; trained.reads.len()],
        None => {
            let float = predictor.levels(&train, &mut predictor.scratch());
            fixed::choose(
                &trained.model.pieces,
                &trained.reads,
                &learned,
                (&train, &rows.train_truth),
                &float,
                tolerance,
            )
            .map_err(Error::Invalid)?
        }
    };
    let model = FixedModel::new(
        &trained.model.pieces,
        &trained.reads,
        &learned,
        &train,
        &widths,
    )
    .map_err(|e| Error::Invalid(format!("[circuit] widths: {e}")))?;
    Ok((model, predictor))
}

/// Measures `trained` in fixed point ([`fixed_model`]) on `rows`, writes
/// and simulates every output's circuit in both forms in `dir` (a scratch
/// folder) — each must put out the evaluator's level on every test row —
/// and, with `fpga` (a device and nextpnr's seed), places and routes each
/// and holds its mapped netlist to the first `mapped_rows` test rows (all
/// when none), simulated by Verilator: Icarus Verilog takes a tenth of a
/// second a row on thousands of lookup tables.
pub fn measure(
    trained: &Trained,
    rows: &Rows,
    widths: Option<Widths>,
    fpga: Option<(Device, u64)>,
    mapped_rows: Option<usize>,
    dir: &Path,
    progress: &dyn Progress,
) -> Result<Measured> {
    let (model, predictor) = fixed_model(trained, rows, widths, TOLERANCE)?;
    tools::versions()?;
    // Found (or their absence told) before hours of work.
    let tool_versions = fpga
        .map(|_| -> Result<String> {
            Ok(format!(
                "{}; {}",
                fpga::tool_versions()?,
                tools::version("verilator")?
            ))
        })
        .transpose()?;
    let fpga = fpga.map(|(device, seed)| (device, seed % fpga::NEXTPNR_SEEDS));
    let cell_models = fpga
        .map(|_| tools::yosys_data(fpga::ICE40_MODELS))
        .transpose()?
        .map(|p| p.display().to_string());
    let cell_models = cell_models.as_deref().unwrap_or_default();
    let learned: Vec<&Entry> = trained.codebook.learned().collect();
    let train: Vec<&[f64]> = rows.train.iter().map(Vec::as_slice).collect();
    let test: Vec<&[f64]> = rows.test.iter().map(Vec::as_slice).collect();
    let test_rows = test.first().map_or(0, |c| c.len());
    let mapped_rows = mapped_rows.map_or(test_rows, |n| n.min(test_rows));
    let float_train = predictor.levels(&train, &mut predictor.scratch());
    let float_test = predictor.levels(&test, &mut predictor.scratch());
    let outputs = model.outputs.len();
    progress.start("circuit", outputs as u64, "variables");
    let measured: Vec<(OutputFigures, Option<[Placed; 2]>)> = (0..outputs)
        .into_par_iter()
        .map(|o| {
            let out = &model.outputs[o];
            let entry = learned[out.variable];
            let period = entry.period();
            let fixed_test = fixed::output_levels(out, &test);
            let figures = OutputFigures {
                variable: entry.variable.clone(),
                widths: out.widths,
                input_frac: out.input_frac,
                weight_frac: out.weight_frac,
                piece_bits: out.piece_bits,
                pieces: (out.coefficients.len() / (out.inputs.len() + 1)) as u32,
                inputs: out.inputs.len() as u32,
                train_difference: fixed::mean_level_difference(
                    &fixed::output_levels(out, &train),
                    &float_train[o],
                    period,
                ),
                test_difference: fixed::mean_level_difference(&fixed_test, &float_test[o], period),
                fixed_error: fixed::mean_level_difference(
                    &fixed_test,
                    &rows.truth[out.variable],
                    period,
                ),
                float_error: fixed::mean_level_difference(
                    &float_test[o],
                    &rows.truth[out.variable],
                    period,
                ),
                persistence_error: fixed::mean_level_difference(
                    &rows.current[out.variable],
                    &rows.truth[out.variable],
                    period,
                ),
                rows: test_rows as u64,
            };
            let fpga = fpga.map(|(device, seed)| (device, seed, cell_models, mapped_rows));
            let placed = circuits(out, &entry.variable, &test, &fixed_test, fpga, dir)?;
            progress.advance(1);
            Ok((figures, placed))
        })
        .collect::<Result<_>>()?;
    let (outputs, placed): (Vec<_>, Vec<_>) = measured.into_iter().unzip();
    let placed = fpga.zip(tool_versions).map(|((device, seed), tools)| {
        let mut by_form = [Vec::new(), Vec::new()];
        for [combinational, pipelined] in placed.into_iter().flatten() {
            by_form[0].push(combinational);
            by_form[1].push(pipelined);
        }
        let [combinational, pipelined] = by_form;
        let state = |form, variables| fpga::State {
            device,
            form,
            seed,
            tools: tools.clone(),
            variables,
        };
        [
            state(Form::Combinational, combinational),
            state(Form::Pipelined, pipelined),
        ]
    });
    Ok(Measured {
        outputs,
        placed,
        rows: test_rows,
        mapped_rows,
    })
}

/// Output `out`'s circuits in both forms, written into `dir` and simulated
/// on the `test` rows, each held to the evaluator's `expected` levels;
/// with `fpga` (a device, nextpnr's seed, Yosys' cell models and the rows
/// to simulate a mapped netlist on), each placed and routed and its mapped
/// netlist held to the first of those rows too.
fn circuits(
    out: &FixedOutput,
    variable: &str,
    test: &[&[f64]],
    expected: &[u16],
    fpga: Option<(Device, u64, &str, usize)>,
    dir: &Path,
) -> Result<Option<[Placed; 2]>> {
    let datapath = Datapath::new(out);
    let rows = expected.len();
    let words: Vec<Vec<i64>> = (0..rows)
        .map(|r| {
            let mut row = vec![0; out.inputs.len()];
            out.words(|v| test[v][r], &mut row);
            row.push(out.current_word(test[out.variable][r]));
            row
        })
        .collect();
    let base = module_name(variable);
    let inputs = format!("{base}_words.hex");
    write(dir, &inputs, &datapath.rows_hex(&words))?;
    let mapped_rows = fpga.map_or(0, |f| f.3);
    let mapped_inputs = format!("{base}_words_mapped.hex");
    write(
        dir,
        &mapped_inputs,
        &datapath.rows_hex(&words[..mapped_rows]),
    )?;
    let mut placed = Vec::new();
    for form in Form::ALL {
        let module = match form {
            Form::Combinational => base.clone(),
            Form::Pipelined => format!("{base}_pipelined"),
        };
        let file = format!("{module}.v");
        write(dir, &file, &datapath.verilog(&module, variable, form))?;
        let mut netlists = vec![(
            "rtl",
            Simulator::Icarus,
            vec![file.clone()],
            &[][..],
            rows,
            &inputs,
        )];
        if let Some((device, seed, models, _)) = fpga {
            let top = format!("fpga_{module}");
            let mut ports: Vec<(String, usize)> = (0..out.inputs.len())
                .map(|k| (format!("x{k}"), datapath.ports[k] as usize))
                .collect();
            ports.push((
                "current".into(),
                *datapath.ports.last().expect("a current word") as usize,
            ));
            let wrapper = fpga::registered(
                &top,
                &module,
                variable,
                &ports,
                &("next".into(), datapath.level_bits as usize),
                form == Form::Pipelined,
            );
            let wrapper_file = format!("{top}.v");
            write(dir, &wrapper_file, &wrapper)?;
            let sources = [file.clone(), wrapper_file];
            let design = Design {
                top: &top,
                module: &module,
                variable,
                sources: &sources,
                carry_chains: true,
                latency: match form {
                    Form::Combinational => 0,
                    Form::Pipelined => datapath.latency(),
                },
            };
            placed.push(fpga::place_and_route_files(&design, device, seed, dir)?);
            netlists.push((
                "mapped",
                Simulator::Verilator,
                vec![fpga::mapped_netlist(&top), models.to_string()],
                fpga::ICE40_DEFINES,
                mapped_rows,
                &mapped_inputs,
            ));
        }
        for (tag, simulator, sources, defines, rows, inputs) in netlists {
            if rows == 0 {
                continue;
            }
            let bench = format!("tb_{tag}_{module}.v");
            let output = format!("out_{tag}_{module}.txt");
            write(
                dir,
                &bench,
                &datapath.testbench(&module, form, rows, inputs, &output),
            )?;
            let got = run_bench(simulator, &bench, &sources, defines, &output, rows, dir)?;
            if let Some(r) = (0..rows).find(|&r| got[r] != expected[r]) {
                return Err(Error::Corrupt(format!(
                    "the {tag} {} circuit of `{variable}` puts out level {} on test row {r}, the \
                     fixed-point evaluator {}",
                    form.name(),
                    got[r],
                    expected[r]
                )));
            }
        }
    }
    Ok(placed.try_into().ok())
}

fn write(dir: &Path, name: &str, text: &str) -> Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, text).map_err(|e| Error::io(&path, e))
}

/// One line of the trade between width and error: every output at the
/// same `widths` (or its own chosen ones).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Trade {
    /// The widths every output takes; none for each its chosen ones.
    pub widths: Option<Widths>,
    /// Mean over outputs of |fixed − float| in levels on the training rows.
    pub train_difference: f64,
    /// … on the test rows.
    pub test_difference: f64,
    /// Mean over outputs of the error in levels on the test rows: the
    /// fixed-point model's and the floating-point model's.
    pub fixed_error: f64,
    pub float_error: f64,
    /// The circuits' arithmetic, in bits summed over the outputs
    /// ([`Datapath::arithmetic_bits`]): what their size grows with.
    pub arithmetic_bits: u64,
}

/// The fixed-point model of `trained` on `rows` at each of `widths` (and
/// at the chosen ones, first): its difference from the floating-point
/// model and its error. Widths too narrow for a weight are skipped.
pub fn trade(trained: &Trained, rows: &Rows, widths: &[Widths]) -> Result<Vec<Trade>> {
    let learned: Vec<&Entry> = trained.codebook.learned().collect();
    let (chosen, predictor) = fixed_model(trained, rows, None, TOLERANCE)?;
    let train: Vec<&[f64]> = rows.train.iter().map(Vec::as_slice).collect();
    let test: Vec<&[f64]> = rows.test.iter().map(Vec::as_slice).collect();
    let float_train = predictor.levels(&train, &mut predictor.scratch());
    let float_test = predictor.levels(&test, &mut predictor.scratch());
    let line = |model: &FixedModel, widths| {
        let mean = |f: &dyn Fn(usize, &FixedOutput) -> f64| {
            let n = model.outputs.len().max(1) as f64;
            model
                .outputs
                .iter()
                .enumerate()
                .map(|(o, out)| f(o, out))
                .sum::<f64>()
                / n
        };
        let differ = |levels: &[u16], other: &[u16], out: &FixedOutput| {
            fixed::mean_level_difference(levels, other, learned[out.variable].period())
        };
        Trade {
            widths,
            train_difference: mean(&|o, out| {
                differ(&fixed::output_levels(out, &train), &float_train[o], out)
            }),
            test_difference: mean(&|o, out| {
                differ(&fixed::output_levels(out, &test), &float_test[o], out)
            }),
            fixed_error: mean(&|_, out| {
                differ(
                    &fixed::output_levels(out, &test),
                    &rows.truth[out.variable],
                    out,
                )
            }),
            float_error: mean(&|o, out| differ(&float_test[o], &rows.truth[out.variable], out)),
            arithmetic_bits: model
                .outputs
                .iter()
                .map(|out| Datapath::new(out).arithmetic_bits())
                .sum(),
        }
    };
    let mut lines = vec![line(&chosen, None)];
    for &w in widths {
        let pieces = &trained.model.pieces;
        if let Ok(model) = FixedModel::new(
            pieces,
            &trained.reads,
            &learned,
            &train,
            &[w].repeat(pieces.len()),
        ) {
            lines.push(line(&model, Some(w)));
        }
    }
    Ok(lines)
}
