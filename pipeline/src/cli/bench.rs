//! `alnlab bench …`: the benchmarks, each printing its figures or one JSON
//! object with `--json`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use alnlab_aln::ModelKind;
use alnlab_common::{Error, ModelId, Result};
use clap::Subcommand;

use crate::manifest::Manifest;
use crate::run::{RunOptions, run};

/// The benchmarks.
#[derive(Debug, Subcommand)]
pub enum Bench {
    /// Time the simulator: ns per step for the worm with and without
    /// contacts and for free chains of 1 to 64 links, the simulate stage's
    /// throughput with MCAP writing; and for the worm and each vendored
    /// robot (UR5, Solo 12), on 256 states of a simulated run, ns per state
    /// of the articulated-body algorithm and of a step, one state at a time
    /// and all 256 at once (SIMD lanes) — beside Pinocchio's `aba` on the
    /// same states when given its harness, timed in interleaved rounds.
    /// Medians of REPEAT runs (at least 5 rounds for the models), one core.
    #[command(after_help = "Examples:
  alnlab bench sim --json
  bash bench/pinocchio/build.sh target/pinocchio-aba    # needs pin, Eigen and g++
  alnlab bench sim --pinocchio target/pinocchio-aba")]
    Sim {
        /// How many timed runs per figure.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// The Pinocchio harness (`bench/pinocchio/build.sh` builds it), to
        /// time `pinocchio::aba` on the robots' states beside ours.
        #[arg(long, value_name = "HARNESS")]
        pinocchio: Option<PathBuf>,
    },
    /// Time quantization and coding: values quantized and walk-encoded into
    /// a bit matrix per second, and walk nearest-code decodes per second
    /// (W = 23, L = 214). Medians of REPEAT runs, one core.
    #[command(after_help = "Example:
  alnlab bench quantize --json")]
    Quantize {
        /// How many timed runs per figure.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time ALN training at the paper's scale (8192 leaves, 10 epochs, 1000
    /// samples, 23-bit walk codes, all cores) twice: on paper-shaped data
    /// (64 variables: 1472 trees over 1472 input bits), and on the worm
    /// simulated and quantized by the stages (its 57 learned variables:
    /// 1311 trees; the `worm` object of `--json`).
    #[command(after_help = "Example:
  alnlab bench train --json")]
    Train {
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time the summarize stage on 10⁷ errors (3 models × 64 variables ×
    /// 52 084 rows): reading predictions.parquet, the statistics, writing
    /// summary.parquet.
    #[command(after_help = "Example:
  alnlab bench summarize --json")]
    Summarize {
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time full-state prediction. With --run: a run's own model on its
    /// test rows — the batched path on one thread and on all threads, where
    /// its time goes, and the simulator re-stepping each row's frame once on
    /// one thread — each as min/median/max of REPEAT runs. Without: a
    /// synthetic paper-scale forest (1472 trees), bit-sliced and one sample
    /// at a time, with the fraction of nodes evaluated.
    #[command(after_help = "Examples:
  alnlab bench predict --run runs/strongest --variant strongest --json
  alnlab bench predict --json")]
    Predict {
        /// A run's folder (holding run.json) whose model and data to time.
        #[arg(long)]
        run: Option<PathBuf>,
        /// The run's variant (default: the only one).
        #[arg(long, requires = "run")]
        variant: Option<String>,
        /// How many timed runs per figure (with --run).
        #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=1000))]
        repeat: u32,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Measure a run's model as a circuit: export it as Verilog, synthesize
    /// it with Yosys into two-input gates, simulate the Verilog and the
    /// netlist with Icarus Verilog on the test rows (each must equal the
    /// software's levels) and give gates and depth in gate levels — trees,
    /// votes, decoding — beside the paper's estimate of 59, and how long it
    /// took. Needs `yosys` and `iverilog` (Debian: apt-get install yosys
    /// iverilog). With --fpga, every variable is also placed and routed on
    /// that FPGA between registers (needs nextpnr-ice40), its critical
    /// path read from timing analysis and its mapped netlist simulated on
    /// the same rows: the state's time in ns is the slowest variable's, one
    /// part per variable. A piecewise-linear model is measured in fixed
    /// point: its error and arithmetic at the widths chosen on the training
    /// rows and at each of --widths, and with --fpga its circuits
    /// (combinational and pipelined) placed and routed, their mapped
    /// netlists simulated by Verilator (needs verilator, make and g++) on
    /// the first --rows test rows.
    #[command(after_help = "Examples:
  alnlab bench circuit --run runs/quickstart --variant gray --json
  alnlab bench circuit --run runs/quickstart --variant gray --fpga ice40-hx8k
  alnlab bench circuit --run runs/paper --rows 500
  alnlab bench circuit --run runs/piecewise --variant piecewise --widths 11x6,13x6,14x8")]
    Circuit {
        /// A run's folder (holding run.json) whose model to measure.
        #[arg(long, default_value = "runs/quickstart")]
        run: PathBuf,
        /// The run's variant (default: the only one).
        #[arg(long)]
        variant: Option<String>,
        /// Simulate only the first ROWS test rows (default: all).
        #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
        rows: Option<u64>,
        /// Also place and route every variable on this FPGA.
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(
            alnlab_circuit::Device::ALL.map(alnlab_circuit::Device::name)
        ))]
        fpga: Option<String>,
        /// nextpnr's placement seed (default: the run's seed, as the circuit
        /// stage uses it).
        #[arg(long)]
        seed: Option<u64>,
        /// A piecewise-linear model's widths to tabulate beside the chosen
        /// ones, each INPUTxWEIGHT bits for every output (e.g. 13x6).
        #[arg(long, value_delimiter = ',', value_parser = parse_widths)]
        widths: Vec<alnlab_aln::pwl::fixed::Widths>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time sharded training: the manifest's forest trained in one process
    /// (all cores) against SHARDS processes of `train --shard K/N` side by
    /// side (each given its share of the cores) and the merge; checks the
    /// merged model equals the in-process one byte for byte.
    #[command(after_help = "Example:
  alnlab bench shards experiments/paper.toml --shards 2 --json")]
    Shards {
        /// The experiment manifest (its data are made in a temporary folder).
        #[arg(default_value = "experiments/paper.toml")]
        manifest: PathBuf,
        /// The variant (default: the first).
        #[arg(long)]
        variant: Option<String>,
        /// Training processes.
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
        shards: u32,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time a fully cached `run` of a manifest (the no-op re-run).
    ///
    /// Runs the manifest once to fill the cache, then times REPEAT re-runs
    /// that find everything cached, and reports the median.
    #[command(after_help = "Example:
  alnlab bench cache experiments/quickstart.toml --json")]
    Cache {
        /// The experiment manifest.
        #[arg(default_value = "experiments/quickstart.toml")]
        manifest: PathBuf,
        /// Output folder for the cache.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// How many cached re-runs to time.
        #[arg(long, default_value_t = 10)]
        repeat: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

/// Runs one benchmark.
pub fn execute(bench: Bench, quiet: bool) -> Result<()> {
    match bench {
        Bench::Cache {
            manifest,
            out,
            repeat,
            json,
        } => bench_cache(&manifest, out, repeat.max(1), json, quiet),
        Bench::Shards {
            manifest,
            variant,
            shards,
            json,
        } => {
            let variant = match variant {
                Some(v) => v,
                None => Manifest::load(&manifest)?.variants[0].name.clone(),
            };
            let figures = crate::bench::shards(&manifest, &variant, shards)?;
            print_figures(&figures, json, |f| {
                println!(
                    "{} trees: in-process {:.2} s; {} processes {:.2} s + merge {:.2} s = {:.2}× \
                     ({})",
                    f.trees,
                    f.in_process_seconds,
                    f.shards,
                    f.processes_seconds,
                    f.merge_seconds,
                    f.ratio,
                    if f.identical {
                        "merged model identical"
                    } else {
                        "MERGED MODEL DIFFERS"
                    }
                )
            });
            if figures.identical {
                Ok(())
            } else {
                Err(Error::Invalid("bench: the merged model differs".into()))
            }
        }
        Bench::Summarize { json } => {
            let figures = alnlab_summarize::bench::run()?;
            print_figures(&figures, json, |figures| {
                println!(
                    "summarize: {:.3} s for {} errors ({:.3e} errors/s)",
                    figures.seconds, figures.errors, figures.errors_per_s
                );
            });
            Ok(())
        }
        Bench::Train { json } => {
            let figures = alnlab_train::bench::train();
            let worm = crate::bench::worm_training()?;
            if json {
                let mut value = serde_json::to_value(&figures).expect("figures serialize");
                value["worm"] = serde_json::to_value(&worm).expect("figures serialize");
                println!("{value}");
            } else {
                println!(
                    "paper-shaped data:  {:5.1} s for {} trees on {} threads ({:.3e} node updates/s)",
                    figures.seconds, figures.trees, figures.threads, figures.node_updates_per_s
                );
                println!(
                    "worm (simulated):   {:5.1} s for {} trees on {} threads ({:.3e} node updates/s)",
                    worm.seconds, worm.trees, worm.threads, worm.node_updates_per_s
                );
            }
            Ok(())
        }
        Bench::Circuit {
            run: run_dir,
            variant,
            rows,
            fpga,
            seed,
            widths,
            json,
        } => {
            let seed = match seed {
                Some(seed) => seed,
                None => crate::records::read_record(&run_dir)?.seed,
            };
            let fpga = fpga.map(|name| {
                let device = alnlab_circuit::Device::named(&name).expect("clap checks the name");
                (device, seed)
            });
            let (name, [model, codebook, levels, timings, pairs]) = run_artifacts(
                &run_dir,
                variant.as_deref(),
                ["model", "codebook", "levels", "timings", "pairs"],
            )?;
            let bar = crate::progress::Bar::new("circuit", quiet);
            let kind = alnlab_aln::model::RawModel::read(&model)?.header.model;
            let piecewise = match kind {
                ModelKind::PiecewiseLinear => true,
                ModelKind::BitForest | ModelKind::Threshold => false,
            };
            if piecewise {
                let figures = alnlab_circuit::bench::piecewise_on_run(
                    (&model, &codebook, &levels, &pairs),
                    &widths,
                    rows.map(|r| r as usize),
                    fpga,
                    &run_dir,
                    &bar,
                )?;
                drop(bar);
                print_figures(&figures, json, |f| print_piecewise(&name, f));
                return Ok(());
            }
            if !widths.is_empty() {
                return Err(Error::Invalid(format!(
                    "--widths are a piecewise-linear model's; `{name}` is a bit-forest"
                )));
            }
            let circuit = alnlab_circuit::bench::on_run(
                &model,
                &codebook,
                &levels,
                rows.map(|r| r as usize),
                fpga,
                &run_dir,
                &bar,
            )?;
            drop(bar);
            let figures = CircuitBench {
                cpu_ns_per_state: CpuFigures::of(&alnlab_evaluate::timings::read(&timings)?),
                circuit,
            };
            print_figures(&figures, json, |figures| {
                let f = &figures.circuit;
                let [trees, votes, decode] = f.deepest_parts;
                println!(
                    "{name}: {} variables, {} test rows simulated, every level equal to the software's",
                    f.figures.variables.len(),
                    f.rows
                );
                println!(
                    "longest path: {} gate levels (`{}`: trees {trees}, votes {votes}, decoding {decode}); the paper's estimate: {}",
                    f.depth, f.deepest, f.paper_estimate
                );
                for (part, p) in [
                    ("trees", f.trees),
                    ("votes", f.votes),
                    ("decoding", f.decode),
                ] {
                    println!(
                        "{part:9} {:>10} gates ({} inverters), {} levels deep",
                        p.cells, p.inverters, p.depth
                    );
                }
                println!("all       {:>10} gates; {}", f.cells, f.figures.library);
                println!(
                    "{:.1} s to synthesize{}, and simulate on {} threads ({})",
                    f.seconds,
                    if f.fpga.is_some() {
                        ", place and route"
                    } else {
                        ""
                    },
                    f.threads,
                    f.figures.tools
                );
                if let Some(state) = &f.fpga {
                    let placed = state.variables.iter().filter(|p| p.critical_ns.is_some());
                    let luts: u64 = state.variables.iter().map(|p| p.luts).sum();
                    println!(
                        "{}: {} of {} variables placed and routed (seed {}), {luts} lookup tables in all, at most {} deep; every mapped netlist equal to the software",
                        state.device.name(),
                        placed.count(),
                        state.variables.len(),
                        state.seed,
                        state.lut_levels()
                    );
                    for p in state.variables.iter().filter(|p| p.critical_ns.is_none()) {
                        if p.fits() {
                            println!(
                                "  `{}` fits ({} of {} logic cells) but was not routed in time",
                                p.variable, p.logic_cells, p.available
                            );
                        } else {
                            println!(
                                "  `{}` does not fit: {} logic cells needed, {} available",
                                p.variable, p.logic_cells, p.available
                            );
                        }
                    }
                    match (state.critical_ns(), state.slowest()) {
                        (Some(ns), Some(slowest)) => println!(
                            "a state in {ns:.2} ns ({:.1} MHz), the slowest variable `{}` ({} logic cells, {} lookup tables deep) ({})",
                            1000.0 / ns,
                            slowest.variable,
                            slowest.logic_cells,
                            slowest.lut_levels,
                            state.tools
                        ),
                        _ => {
                            println!("no time for the state: a variable was not placed and routed")
                        }
                    }
                }
                figures.print_table();
            });
            Ok(())
        }
        Bench::Predict {
            run: Some(run_dir),
            variant,
            repeat,
            json,
        } => {
            let (name, [model, codebook, levels, pairs, trajectory]) = run_artifacts(
                &run_dir,
                variant.as_deref(),
                ["model", "codebook", "levels", "pairs", "trajectory"],
            )?;
            let figures = alnlab_evaluate::bench::on_data(
                &model,
                &codebook,
                &levels,
                &pairs,
                &trajectory,
                repeat as usize,
            )?;
            print_figures(&figures, json, |f| {
                let spread = |s: &alnlab_evaluate::bench::Spread| {
                    format!("{:8.0} ns  (min {:.0}, max {:.0})", s.median, s.min, s.max)
                };
                println!(
                    "{} ({}, {} target, {} trees) on {} test states, medians of {} runs:",
                    name, f.model, f.target, f.trees, f.states, f.repeats
                );
                println!(
                    "ALN batched, 1 thread:        {}",
                    spread(&f.aln_batched_one_thread_ns)
                );
                println!(
                    "ALN batched, {} threads:      {}",
                    f.threads,
                    spread(&f.aln_batched_all_threads_ns)
                );
                for (path, s) in f.pwl_one_row_one_thread_ns.iter().flatten() {
                    println!("ALN one row, {path:13} {}", spread(s));
                }
                if let (Some(pieces), Some(per_box)) = (f.pwl_pieces, f.pwl_pieces_per_box) {
                    println!(
                        "  {pieces} pieces in all; a compiled box leaves {per_box:.1} pieces of a tree on average"
                    );
                }
                if let Some(p) = &f.aln_phases_one_thread_ns {
                    println!(
                        "  of which (1 thread): coding inputs {:.0} ns, trees {:.0} ns, decoding {:.0} ns",
                        p.code_inputs, p.trees, p.decode
                    );
                }
                println!(
                    "{}, 1 thread:  {}",
                    ModelId::Simulator { steps: 1 },
                    spread(&f.simulator_one_step_one_thread_ns)
                );
                let ratio = f.aln_speedup_one_thread;
                if ratio >= 1.0 {
                    println!("ALN against simulator, 1 thread: {ratio:.2}× faster");
                } else {
                    println!(
                        "ALN against simulator, 1 thread: {:.2}× slower",
                        1.0 / ratio
                    );
                }
            });
            Ok(())
        }
        Bench::Predict { json, .. } => {
            let figures = alnlab_train::bench::predict();
            print_figures(&figures, json, |figures| {
                println!(
                    "batched (bit-sliced):     {:10.0} ns per state on {} threads, of which decoding {:.0} ns",
                    figures.batched_ns_per_state, figures.threads, figures.decode_ns_per_state
                );
                println!(
                    "batched, one thread:      {:10.0} ns per state",
                    figures.batched_one_thread_ns_per_state
                );
                println!(
                    "single (parsimonious):    {:10.0} ns per state, {:.0} leaves tested",
                    figures.single_ns_per_state, figures.leaves_tested_per_state
                );
                println!(
                    "nodes evaluated:          {:.4} of all (estimate ½·(3/4)^13 = {:.4})",
                    figures.nodes_evaluated_fraction, figures.estimated_fraction
                );
            });
            Ok(())
        }
        Bench::Quantize { repeat, json } => {
            let figures = alnlab_quantize::bench::run(repeat.max(1));
            print_figures(&figures, json, |figures| {
                println!(
                    "quantize + encode: {:12.0} values/s",
                    figures.quantize_encode_values_per_s
                );
                println!(
                    "walk decode:       {:12.0} decodes/s",
                    figures.walk_decodes_per_s
                );
            });
            Ok(())
        }
        Bench::Sim {
            repeat,
            json,
            pinocchio,
        } => {
            let harness = pinocchio.map(|harness| alnlab_simulate::bench::Pinocchio { harness });
            let figures = alnlab_simulate::bench::run(repeat.max(1), harness.as_ref())?;
            print_figures(&figures, json, |figures| {
                println!(
                    "worm without contacts: {:8.0} ns/step",
                    figures.worm_no_contact_ns_per_step
                );
                println!(
                    "worm with contacts:    {:8.0} ns/step",
                    figures.worm_contact_ns_per_step
                );
                for (links, ns) in &figures.chain_ns_per_step {
                    println!("free chain, {links:2} links: {ns:8.0} ns/step");
                }
                println!(
                    "simulate stage:        {:8.0} steps/s",
                    figures.stage_steps_per_s
                );
                let range = |x: &[f64; 3]| format!("{:.0} ({:.0}–{:.0})", x[0], x[1], x[2]);
                for m in &figures.models {
                    println!(
                        "{} ({} DOF), ns per state over {} states, one thread:",
                        m.model, m.dof, m.states
                    );
                    println!(
                        "  ABA   one at a time {}, batched {}: {:.2}× faster batched",
                        range(&m.aba_ns),
                        range(&m.batched_aba_ns),
                        m.aba_ns[0] / m.batched_aba_ns[0]
                    );
                    println!(
                        "  step (held loads) one at a time {}, batched {}: {:.2}× faster batched",
                        range(&m.held_step_ns),
                        range(&m.batched_step_ns),
                        m.held_step_ns[0] / m.batched_step_ns[0]
                    );
                    if let Some(step) = &m.step_ns {
                        println!("  step with controller and joint laws {}", range(step));
                    }
                    if let Some(p) = &m.pinocchio_aba_ns {
                        println!(
                            "  pinocchio::aba {}: ours one at a time {:.2}×, batched {:.2}× its time",
                            range(p),
                            m.aba_ns[0] / p[0],
                            m.batched_aba_ns[0] / p[0]
                        );
                    }
                }
            });
            Ok(())
        }
    }
}

/// The variant of the run in `run_dir` (the only one, or `variant`) and
/// the paths of its artifacts `roles`.
fn run_artifacts<const N: usize>(
    run_dir: &Path,
    variant: Option<&str>,
    roles: [&str; N],
) -> Result<(String, [PathBuf; N])> {
    let record = crate::records::read_record(run_dir)?;
    // A variant's first replicate stands for it, as in the report.
    let chosen = crate::records::pick_variant(
        &record.variants,
        variant,
        Some(1),
        &roles,
        run_dir,
        crate::records::Spelling::Cli,
    )?;
    let mut paths = Vec::with_capacity(N);
    for role in roles {
        let path = chosen
            .artifacts
            .get(role)
            .map(|a| PathBuf::from(&a.path))
            .ok_or_else(|| {
                Error::bad_file(
                    &run_dir.join("run.json"),
                    format!("variant `{}` has no `{role}` artifact", chosen.name),
                )
            })?;
        paths.push(path);
    }
    let paths: [PathBuf; N] = paths.try_into().expect("one path per role");
    Ok((chosen.name.clone(), paths))
}

/// `alnlab bench circuit`'s figures: the circuit's, and the CPU's beside
/// them from the run's own timings.
#[derive(serde::Serialize)]
struct CircuitBench {
    #[serde(flatten)]
    circuit: alnlab_circuit::bench::Bench,
    cpu_ns_per_state: CpuFigures,
}

/// ns per state on one CPU thread, the median of the test stage's timed
/// runs (none when the run did not time that model).
#[derive(serde::Serialize)]
struct CpuFigures {
    aln_batched: Option<f64>,
    aln_single: Option<f64>,
    simulator_1_per_frame: Option<f64>,
}

impl CpuFigures {
    fn of(timings: &[alnlab_evaluate::timings::Row]) -> CpuFigures {
        let ns = |model: ModelId, paths: &[&str]| {
            timings
                .iter()
                .find(|t| t.model == model && paths.contains(&t.path.as_str()) && t.threads == 1)
                .map(|t| t.ns_per_state)
        };
        CpuFigures {
            aln_batched: ns(ModelId::Aln, &["batched"]),
            aln_single: ns(ModelId::Aln, &["single", "threshold-search"]),
            simulator_1_per_frame: ns(ModelId::Simulator { steps: 1 }, &["single"]),
        }
    }
}

impl CircuitBench {
    /// One state's time in hardware beside the paper's estimate and the
    /// CPU, one table.
    fn print_table(&self) {
        let f = &self.circuit;
        let fpga = f.fpga.as_ref();
        let ns = f.fpga_ns_per_state;
        println!(
            "\n{:44} {:>11} {:>10} {:>12} {:>14}",
            "one predicted state", "gate levels", "LUT levels", "ns", "states/s"
        );
        let row = |name: &str, gates: String, luts: String, ns: Option<f64>| {
            let (ns, rate) = ns.map_or(("—".into(), "—".into()), |ns| {
                (format!("{ns:.1}"), format!("{:.3} M", 1e3 / ns))
            });
            println!("{name:44} {gates:>11} {luts:>10} {ns:>12} {rate:>14}");
        };
        row(
            "the paper's estimate (§5)",
            f.paper_estimate.to_string(),
            "—".into(),
            None,
        );
        let device = fpga.map_or("(no --fpga)", |s| s.device.name());
        row(
            &format!("this forest, {device}"),
            f.depth.to_string(),
            fpga.map_or("—".into(), |s| s.lut_levels().to_string()),
            ns,
        );
        let cpu = &self.cpu_ns_per_state;
        row(
            "software ALN, one thread, batched",
            "—".into(),
            "—".into(),
            cpu.aln_batched,
        );
        row(
            "software ALN, one thread, one at a time",
            "—".into(),
            "—".into(),
            cpu.aln_single,
        );
        row(
            &format!("{}, one thread", ModelId::Simulator { steps: 1 }),
            "—".into(),
            "—".into(),
            cpu.simulator_1_per_frame,
        );
    }
}

/// Prints a benchmark's figures: one JSON object with `--json`, else as
/// `text` words them.
/// `INPUTxWEIGHT` bits, as `--widths` takes them.
fn parse_widths(text: &str) -> std::result::Result<alnlab_aln::pwl::fixed::Widths, String> {
    let bits = |t: &str| t.trim().parse::<u32>().map_err(|e| format!("`{t}`: {e}"));
    let (input, weight) = text
        .split_once('x')
        .ok_or_else(|| format!("`{text}`: expected INPUTxWEIGHT bits, e.g. 13x6"))?;
    Ok(alnlab_aln::pwl::fixed::Widths {
        input_bits: bits(input)?,
        weight_bits: bits(weight)?,
    })
}

/// A piecewise-linear model's bench, as text: the trade table, then the
/// circuits placed and routed.
fn print_piecewise(name: &str, f: &alnlab_circuit::bench::PiecewiseBench) {
    println!(
        "{name}: fixed point against floating point (means over the outputs; errors in levels on the test rows)"
    );
    println!(
        "{:>16} {:>12} {:>12} {:>12} {:>12} {:>16}",
        "widths", "train diff", "test diff", "fixed error", "float error", "arithmetic bits"
    );
    for t in &f.trade {
        let widths = t.widths.map_or("chosen".to_string(), |w| {
            format!("{}x{}", w.input_bits, w.weight_bits)
        });
        println!(
            "{widths:>16} {:>12.4} {:>12.4} {:>12.4} {:>12.4} {:>16}",
            t.train_difference, t.test_difference, t.fixed_error, t.float_error, t.arithmetic_bits
        );
    }
    if let Some([combinational, pipelined]) = &f.placed {
        for state in [combinational, pipelined] {
            let luts: u64 = state.variables.iter().map(|p| p.luts).sum();
            let fits = state
                .variables
                .iter()
                .filter(|p| p.critical_ns.is_some())
                .count();
            println!(
                "{} on the {}: {fits} of {} variables fit, {luts} lookup tables in all; {}",
                state.form.name(),
                state.device.name(),
                state.variables.len(),
                state
                    .critical_ns()
                    .map_or("no state time: a variable does not fit".into(), |ns| {
                        format!("{ns:.2} ns a clock ({:.1} MHz)", 1e3 / ns)
                    })
            );
        }
        println!(
            "mapped netlists equal to the fixed-point evaluator on the first {} test rows; {:.1} s on {} threads",
            f.mapped_rows, f.seconds, f.threads
        );
    }
}

fn print_figures<T: serde::Serialize>(figures: &T, json: bool, text: impl FnOnce(&T)) {
    if json {
        println!(
            "{}",
            serde_json::to_string(figures).expect("figures serialize")
        );
    } else {
        text(figures);
    }
}

fn bench_cache(
    manifest: &Path,
    out: PathBuf,
    repeat: usize,
    json: bool,
    quiet: bool,
) -> Result<()> {
    let options = RunOptions {
        out,
        force: false,
        variant: None,
        quiet,
        datasets: PathBuf::from("datasets"),
        until: None,
        reports: None,
    };
    let warm = Manifest::load(manifest)?;
    run(&warm, &options)?;
    let mut seconds = Vec::with_capacity(repeat);
    for _ in 0..repeat {
        let clock = Instant::now();
        // Everything a cached `alnlab run` does after process start.
        let manifest = Manifest::load(manifest)?;
        let record = run(&manifest, &options)?;
        seconds.push(clock.elapsed().as_secs_f64());
        if record
            .variants
            .iter()
            .flat_map(|v| &v.stages)
            .any(|s| !s.cached)
        {
            return Err(Error::Invalid(
                "a stage re-ran although nothing changed".into(),
            ));
        }
    }
    seconds.sort_by(f64::total_cmp);
    let median = seconds[seconds.len() / 2];
    if json {
        println!(
            "{}",
            serde_json::json!({
                "manifest": manifest.display().to_string(),
                "repeat": repeat,
                "cached_run_median_s": median,
                "cached_run_max_s": seconds[seconds.len() - 1],
            })
        );
    } else {
        println!(
            "cached re-run of {}: median {:.1} ms, max {:.1} ms over {repeat} runs",
            manifest.display(),
            median * 1e3,
            seconds[seconds.len() - 1] * 1e3
        );
    }
    Ok(())
}
