//! The stage table: every stage of the graph, in order, with what the
//! pipeline needs to know of it — its format version, what it reads (by role,
//! and which stage's artifact holds that role), the files it writes, how its
//! parameters resolve and are checked, how it runs, and what a workflow
//! engine should give it. The run graph (`run`), the stage-alone
//! subcommands (`cli::stage`), the manifest checks (`manifest`) and the
//! Snakemake export (`export`) are all driven by [`STAGES`]: adding a stage
//! is a new crate and one entry here.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use alnlab_aln::ModelKind;
use alnlab_aln::shard::Shard;
use alnlab_common::params::ParamError;
use alnlab_common::{Progress, Provenance, Result};
use serde::{Deserialize, Serialize};

/// The parameters of every stage, one table each.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stages {
    /// `[simulate]`
    #[serde(default)]
    pub simulate: alnlab_simulate::Params,
    /// `[stride]`
    #[serde(default)]
    pub stride: alnlab_stride::Params,
    /// `[quantize]`
    #[serde(default)]
    pub quantize: alnlab_quantize::Params,
    /// `[train]`
    #[serde(default)]
    pub train: alnlab_train::Params,
    /// `[test]`
    #[serde(default)]
    pub test: alnlab_evaluate::Params,
    /// `[plan]`
    #[serde(default)]
    pub plan: alnlab_plan::Params,
    /// `[circuit]`
    #[serde(default)]
    pub circuit: alnlab_circuit::Params,
    /// `[ingest]`: with `[data] recording`, how the recording becomes
    /// frames, and the robot it records.
    #[serde(default)]
    pub ingest: alnlab_ingest::Params,
}

/// One stage of the graph.
pub struct Stage {
    /// Its name: the manifest table, the cache folder, the subcommand.
    pub name: &'static str,
    /// One line on what it does (the subcommand's help).
    pub about: &'static str,
    /// Version of what it writes; part of every cache key.
    pub format_version: u32,
    /// What it reads.
    pub inputs: &'static [Input],
    /// What it writes: (role, file name).
    pub outputs: &'static [(&'static str, &'static str)],
    /// Whether an archived dataset stands for it.
    pub archived: Archived,
    /// Whether it runs for every replicate, or for the first only (a
    /// measurement of one model that takes long and that the replicates'
    /// intervals do not use).
    pub every_replicate: bool,
    /// Its resolved parameter table, as it enters the cache key (`null` for
    /// a stage without parameters).
    pub params: fn(&Stages) -> serde_json::Value,
    /// Checks relations between its parameters; an error names the key.
    /// The flag says whether the simulate stage's parameters describe the
    /// data (false where an archived dataset stands for it).
    pub validate: fn(&Stages, bool) -> std::result::Result<(), ParamError>,
    /// Runs it.
    pub run: fn(&Call) -> Result<()>,
    /// For a stage that can run in shards: joins a complete set of shard
    /// folders into the stage's output folder.
    pub merge_shards: Option<MergeShards>,
    /// Resources a workflow engine should give one job of it.
    pub hints: Hints,
}

/// Joins the folders of a complete set of shards, written with the
/// provenance given, into one output folder.
pub type MergeShards = fn(&[PathBuf], &Provenance, &Path) -> Result<()>;

/// One input of a stage.
pub struct Input {
    /// The role, as the producing stage names its output (`trajectory`, …).
    pub role: &'static str,
    /// The stage whose artifact holds it.
    pub from: &'static str,
}

/// When an archived dataset (`[data] dataset`) stands for a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Archived {
    /// Never: the stage always runs.
    Never,
    /// Always: the dataset holds its outputs.
    Always,
    /// When the dataset was archived with its levels (`--with-levels`).
    WithLevels,
}

impl Archived {
    /// Whether a dataset, with levels or not, holds the stage's outputs.
    pub fn holds(self, with_levels: bool) -> bool {
        match self {
            Archived::Never => false,
            Archived::Always => true,
            Archived::WithLevels => with_levels,
        }
    }
}

/// Resource hints per job: cores, memory (MB), run time (minutes), and
/// whether the stage holds a whole forest in memory (its memory then grows
/// with the forest).
#[derive(Clone, Copy, Debug)]
pub struct Hints {
    pub threads: u32,
    pub mem_mb: u64,
    pub runtime: u32,
    pub holds_forest: bool,
}

/// What a stage is run with.
pub struct Call<'a> {
    /// The variant's resolved parameters (each stage takes its own table).
    pub stages: &'a Stages,
    /// The experiment seed.
    pub seed: u64,
    /// Every input by role.
    pub inputs: BTreeMap<&'static str, PathBuf>,
    /// The shard to train (the train stage; [`Shard::ALL`] otherwise).
    pub shard: Shard,
    /// What the outputs carry as provenance.
    pub provenance: &'a Provenance,
    /// The folder to write into.
    pub out_dir: &'a Path,
    pub progress: &'a dyn Progress,
}

impl Call<'_> {
    /// The path of input `role` (the table guarantees it is there).
    fn input(&self, role: &str) -> &Path {
        &self.inputs[role]
    }
}

fn json(params: &impl Serialize) -> serde_json::Value {
    serde_json::to_value(params).expect("parameters serialize")
}

/// The stages, in the order they run.
pub const STAGES: &[Stage] = &[
    Stage {
        name: "simulate",
        about: "Run the simulate stage alone: write trajectory.mcap and stats.parquet",
        format_version: alnlab_simulate::FORMAT_VERSION,
        inputs: &[],
        outputs: &[
            ("trajectory", alnlab_simulate::TRAJECTORY_FILE),
            ("stats", alnlab_simulate::STATS_FILE),
        ],
        archived: Archived::Always,
        every_replicate: true,
        params: |s| json(&s.simulate),
        validate: |s, _| s.simulate.validate(),
        run: |c| {
            let params = &c.stages.simulate;
            alnlab_simulate::run(params, c.seed, c.provenance, c.out_dir, c.progress)
        },
        merge_shards: None,
        hints: Hints {
            threads: 2,
            mem_mb: 2048,
            runtime: 60,
            holds_forest: false,
        },
    },
    Stage {
        name: "stride",
        about: "Run the stride stage alone: pair every n-th frame with its successor",
        format_version: alnlab_stride::FORMAT_VERSION,
        inputs: &[Input {
            role: "trajectory",
            from: "simulate",
        }],
        outputs: &[("pairs", alnlab_tables::pairs::FILE)],
        archived: Archived::Always,
        every_replicate: true,
        params: |s| json(&s.stride),
        validate: |s, _| s.stride.validate(),
        run: |c| {
            let trajectory = c.input("trajectory");
            let params = &c.stages.stride;
            alnlab_stride::run(
                params,
                c.seed,
                trajectory,
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: None,
        hints: Hints {
            threads: 1,
            mem_mb: 1024,
            runtime: 10,
            holds_forest: false,
        },
    },
    Stage {
        name: "nominal",
        about: "Run the nominal stage alone: what the simulator of the scene as written predicts \
                for every pair",
        format_version: alnlab_nominal::FORMAT_VERSION,
        inputs: &[
            Input {
                role: "trajectory",
                from: "simulate",
            },
            Input {
                role: "pairs",
                from: "stride",
            },
        ],
        outputs: &[("nominal", alnlab_nominal::NOMINAL_FILE)],
        archived: Archived::Never,
        every_replicate: true,
        params: |_| serde_json::Value::Null,
        validate: |_, _| Ok(()),
        run: |c| {
            alnlab_nominal::run(
                &alnlab_nominal::Inputs {
                    trajectory: c.input("trajectory"),
                    pairs: c.input("pairs"),
                },
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: None,
        hints: Hints {
            threads: 1,
            mem_mb: 1024,
            runtime: 10,
            holds_forest: false,
        },
    },
    Stage {
        name: "quantize",
        about: "Run the quantize stage alone: ranges, levels and codes per variable",
        format_version: alnlab_quantize::FORMAT_VERSION,
        inputs: &[
            Input {
                role: "pairs",
                from: "stride",
            },
            Input {
                role: "stats",
                from: "simulate",
            },
        ],
        outputs: &[
            ("codebook", alnlab_quantize::CODEBOOK_FILE),
            ("levels", alnlab_tables::levels::FILE),
        ],
        archived: Archived::WithLevels,
        every_replicate: true,
        params: |s| json(&s.quantize),
        validate: |s, _| s.quantize.validate(),
        run: |c| {
            alnlab_quantize::run(
                &c.stages.quantize,
                c.seed,
                &alnlab_quantize::Inputs {
                    pairs: c.input("pairs"),
                    stats: c.input("stats"),
                },
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: None,
        hints: Hints {
            threads: 1,
            mem_mb: 1024,
            runtime: 10,
            holds_forest: false,
        },
    },
    Stage {
        name: "train",
        about: "Run the train stage alone: an ALN forest over the training rows",
        format_version: alnlab_train::FORMAT_VERSION,
        inputs: &[
            Input {
                role: "codebook",
                from: "quantize",
            },
            Input {
                role: "levels",
                from: "quantize",
            },
            Input {
                role: "pairs",
                from: "stride",
            },
            Input {
                role: "nominal",
                from: "nominal",
            },
        ],
        outputs: &[
            ("model", alnlab_train::MODEL_FILE),
            ("training", alnlab_train::TRAINING_FILE),
        ],
        archived: Archived::Never,
        every_replicate: true,
        params: |s| json(&s.train),
        validate: |s, _| s.train.validate(),
        run: |c| {
            alnlab_train::run(
                &c.stages.train,
                c.seed,
                c.shard,
                &alnlab_train::Inputs {
                    codebook: c.input("codebook"),
                    levels: c.input("levels"),
                    pairs: c.input("pairs"),
                    nominal: c.input("nominal"),
                },
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: Some(alnlab_train::shard::merge),
        hints: Hints {
            threads: 2,
            mem_mb: 1024,
            runtime: 120,
            holds_forest: true,
        },
    },
    Stage {
        name: "test",
        about: "Run the test stage alone: the model's predictions for every test row, beside the \
                persistence, linear and simulator baselines, their timings, and closed-loop \
                rollouts",
        format_version: alnlab_evaluate::FORMAT_VERSION,
        inputs: &[
            Input {
                role: "trajectory",
                from: "simulate",
            },
            Input {
                role: "model",
                from: "train",
            },
            Input {
                role: "codebook",
                from: "quantize",
            },
            Input {
                role: "levels",
                from: "quantize",
            },
            Input {
                role: "pairs",
                from: "stride",
            },
            Input {
                role: "nominal",
                from: "nominal",
            },
        ],
        outputs: &[
            ("predictions", alnlab_evaluate::PREDICTIONS_FILE),
            ("timings", alnlab_evaluate::TIMINGS_FILE),
            ("rollout", alnlab_evaluate::ROLLOUT_FILE),
            ("linear", alnlab_evaluate::LINEAR_FILE),
            ("boosted", alnlab_evaluate::BOOSTED_FILE),
        ],
        archived: Archived::Never,
        every_replicate: true,
        params: |s| json(&s.test),
        validate: |s, _| s.test.validate(),
        run: |c| {
            alnlab_evaluate::run(
                &c.stages.test,
                &alnlab_evaluate::Inputs {
                    trajectory: c.input("trajectory"),
                    model: c.input("model"),
                    codebook: c.input("codebook"),
                    levels: c.input("levels"),
                    pairs: c.input("pairs"),
                    nominal: c.input("nominal"),
                },
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: None,
        hints: Hints {
            threads: 2,
            mem_mb: 1024,
            runtime: 60,
            holds_forest: true,
        },
    },
    Stage {
        name: "summarize",
        about: "Run the summarize stage alone: error statistics per model and variable (all \
                test rows and the held-out ones), the ALN paired against each baseline, and \
                closed-loop error per horizon",
        format_version: alnlab_summarize::FORMAT_VERSION,
        inputs: &[
            Input {
                role: "predictions",
                from: "test",
            },
            Input {
                role: "rollout",
                from: "test",
            },
        ],
        outputs: &[
            ("summary", alnlab_summarize::SUMMARY_FILE),
            ("comparisons", alnlab_summarize::COMPARISONS_FILE),
            ("horizons", alnlab_summarize::HORIZONS_FILE),
        ],
        archived: Archived::Never,
        every_replicate: true,
        // Summarizing has no parameters of its own.
        params: |_| serde_json::Value::Null,
        validate: |_, _| Ok(()),
        run: |c| {
            alnlab_summarize::run(
                &alnlab_summarize::Inputs {
                    predictions: c.input("predictions"),
                    rollout: c.input("rollout"),
                },
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: None,
        hints: Hints {
            threads: 1,
            mem_mb: 2048,
            runtime: 10,
            holds_forest: false,
        },
    },
    Stage {
        name: "plan",
        about: "Run the plan stage alone: model-predictive control of a scene in the simulator, \
                torques chosen by random shooting or the cross-entropy method with the ALN, the \
                linear baseline or the simulator as forward model, against zero and random \
                torques, per task and budget",
        format_version: alnlab_plan::FORMAT_VERSION,
        inputs: &[
            Input {
                role: "trajectory",
                from: "simulate",
            },
            Input {
                role: "model",
                from: "train",
            },
            Input {
                role: "codebook",
                from: "quantize",
            },
            Input {
                role: "levels",
                from: "quantize",
            },
        ],
        outputs: &[
            ("plan", alnlab_plan::PLAN_FILE),
            ("planning", alnlab_plan::PLANNING_FILE),
            ("episodes", alnlab_plan::EPISODES_FILE),
            ("transitions", alnlab_plan::transitions::FILE),
            (
                "transitions-nominal",
                alnlab_plan::transitions::NOMINAL_FILE,
            ),
        ],
        archived: Archived::Never,
        every_replicate: true,
        // Rounds of the planner's own data are the pipeline's: round 0's
        // plans are the same whatever comes after.
        params: |s| {
            let mut params = json(&s.plan);
            if let Some(table) = params.as_object_mut() {
                table.remove("rounds");
            }
            params
        },
        validate: |s, simulated| s.plan.validate(simulated.then_some(&s.simulate.scene[..])),
        run: |c| {
            alnlab_plan::run(
                &c.stages.plan,
                c.seed,
                &alnlab_plan::Inputs {
                    trajectory: c.input("trajectory"),
                    model: c.input("model"),
                    codebook: c.input("codebook"),
                    levels: c.input("levels"),
                },
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: None,
        hints: Hints {
            threads: 1,
            mem_mb: 2048,
            runtime: 60,
            holds_forest: true,
        },
    },
    Stage {
        name: "circuit",
        about: "Run the circuit stage alone: a trained bit-forest as Verilog, synthesized by \
                Yosys into two-input gates (gates and depth in gate levels of its trees, votes \
                and decoders) and simulated by Icarus Verilog on the test rows, equal to the \
                software's levels on every row ([circuit] synthesize = true); a piecewise-linear \
                model in fixed point (widths chosen on the training rows, or [circuit] \
                input_bits and weight_bits), its circuits combinational and pipelined, equal to \
                the fixed-point evaluator on every held-out row; with [circuit] fpga, every \
                variable also placed and routed on an iCE40 by nextpnr, its critical path in ns \
                (a piecewise-linear model's mapped netlists simulated by Verilator)",
        format_version: alnlab_circuit::FORMAT_VERSION,
        inputs: &[
            Input {
                role: "model",
                from: "train",
            },
            Input {
                role: "codebook",
                from: "quantize",
            },
            Input {
                role: "levels",
                from: "quantize",
            },
            Input {
                role: "pairs",
                from: "stride",
            },
        ],
        outputs: &[
            ("circuit", alnlab_circuit::CIRCUIT_FILE),
            ("fpga", alnlab_circuit::FPGA_FILE),
            ("fixed", alnlab_circuit::FIXED_FILE),
        ],
        archived: Archived::Never,
        every_replicate: false,
        params: |s| json(&s.circuit),
        validate: |s, _| {
            s.circuit.validate()?;
            let piecewise = match s.train.model {
                ModelKind::PiecewiseLinear => true,
                ModelKind::BitForest | ModelKind::Threshold => false,
            };
            if s.circuit.synthesize && piecewise && s.train.base == alnlab_aln::model::Base::Nominal
            {
                return Err((
                    "synthesize".into(),
                    "a hybrid advances from the nominal simulator's prediction, which is not \
                     in a circuit: synthesize a model of the dynamics"
                        .into(),
                ));
            }
            if s.circuit.widths().is_some() && !piecewise {
                return Err((
                    "input_bits".into(),
                    "widths are a piecewise-linear model's: a bit-forest computes with code bits"
                        .into(),
                ));
            }
            Ok(())
        },
        run: |c| {
            alnlab_circuit::run(
                &c.stages.circuit,
                c.seed,
                &alnlab_circuit::Inputs {
                    model: c.input("model"),
                    codebook: c.input("codebook"),
                    levels: c.input("levels"),
                    pairs: c.input("pairs"),
                },
                c.provenance,
                c.out_dir,
                c.progress,
            )
        },
        merge_shards: None,
        hints: Hints {
            threads: 2,
            mem_mb: 4096,
            runtime: 120,
            holds_forest: true,
        },
    },
];

/// The stage called `name`.
pub fn find(name: &str) -> Option<&'static Stage> {
    STAGES.iter().find(|s| s.name == name)
}

/// The stage that can run in shards (the one with a shard merge).
pub fn sharded() -> &'static Stage {
    STAGES
        .iter()
        .find(|s| s.merge_shards.is_some())
        .expect("the table has a sharded stage")
}

/// Refuses to train a piecewise-linear model in shards, naming `flag`, the
/// one the user gave (`--shard` of `alnlab train`, `--train-shard` of
/// `alnlab run`): it trains in one process, its trees being few.
pub fn refuse_sharded_piecewise(stages: &Stages, shard: Shard, flag: &str) -> Result<()> {
    match (stages.train.model, shard.is_part()) {
        (ModelKind::PiecewiseLinear, true) => Err(alnlab_common::Error::Invalid(format!(
            "a piecewise-linear model trains in one process (its trees are few): run without \
             {flag}"
        ))),
        (ModelKind::PiecewiseLinear | ModelKind::BitForest | ModelKind::Threshold, _) => Ok(()),
    }
}

/// The names of the stages, in order.
pub fn names() -> Vec<&'static str> {
    STAGES.iter().map(|s| s.name).collect()
}

/// What `run --until` may name: a stage, or [`ROUNDS`].
pub fn until_names() -> Vec<&'static str> {
    let mut names = names();
    names.push(ROUNDS);
    names
}

/// `run --until rounds`: every stage and every round of the planner's own
/// data (`[plan] rounds`), without the run record.
pub const ROUNDS: &str = "rounds";

/// The aggregate stage of the planner's own data (`[plan] rounds`): not in
/// [`STAGES`], since it runs once a round after the plan stage, and the
/// train and plan stages after it again, each on the last round's data.
pub const AGGREGATE: Stage = Stage {
    name: "aggregate",
    about: "The aggregate stage (run by `[plan] rounds`): the frames a round of planning executed join the \
            training pairs, their nominal predictions and levels",
    format_version: alnlab_aggregate::FORMAT_VERSION,
    inputs: &[
        Input {
            role: "pairs",
            from: "stride",
        },
        Input {
            role: "nominal",
            from: "nominal",
        },
        Input {
            role: "codebook",
            from: "quantize",
        },
        Input {
            role: "levels",
            from: "quantize",
        },
        Input {
            role: "transitions",
            from: "plan",
        },
        Input {
            role: "transitions-nominal",
            from: "plan",
        },
    ],
    outputs: &[
        ("pairs", alnlab_aggregate::PAIRS_FILE),
        ("nominal", alnlab_aggregate::NOMINAL_FILE),
        ("levels", alnlab_aggregate::LEVELS_FILE),
    ],
    archived: Archived::Never,
    every_replicate: true,
    params: |_| serde_json::Value::Null,
    validate: |_, _| Ok(()),
    run: |c| {
        alnlab_aggregate::run(
            &alnlab_aggregate::Inputs {
                pairs: c.input("pairs"),
                nominal: c.input("nominal"),
                codebook: c.input("codebook"),
                levels: c.input("levels"),
                transitions: c.input("transitions"),
                transitions_nominal: c.input("transitions-nominal"),
            },
            c.provenance,
            c.out_dir,
            c.progress,
        )
    },
    merge_shards: None,
    hints: Hints {
        threads: 1,
        mem_mb: 1024,
        runtime: 10,
        holds_forest: false,
    },
};

/// The ingest stage (with `[data] recording`): a robot's recording turned
/// into what the simulate stage writes, standing in its place. Its key has
/// no seed: every replicate reads the same recording.
pub const INGEST: Stage = Stage {
    name: "ingest",
    about: "The ingest stage (with [data] recording): a ROS 2 recording of a robot's joint \
            states turned into a trajectory log and its statistics",
    format_version: alnlab_ingest::FORMAT_VERSION,
    inputs: &[],
    outputs: &[
        ("trajectory", alnlab_simulate::TRAJECTORY_FILE),
        ("stats", alnlab_simulate::STATS_FILE),
    ],
    archived: Archived::Never,
    every_replicate: true,
    params: |s| json(&s.ingest),
    validate: |s, _| s.ingest.validate(),
    run: |c| alnlab_ingest::run(&c.stages.ingest, c.provenance, c.out_dir, c.progress),
    merge_shards: None,
    hints: Hints {
        threads: 1,
        mem_mb: 1024,
        runtime: 5,
        holds_forest: false,
    },
};

/// The parameters a stage's cache key and provenance are made of: the
/// experiment seed and the stage's resolved table.
pub fn stage_params(seed: u64, params: serde_json::Value) -> serde_json::Value {
    serde_json::json!({ "seed": seed, "params": params })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_input_comes_from_an_earlier_stage_that_writes_it() {
        for (k, stage) in STAGES.iter().enumerate() {
            for input in stage.inputs {
                let from = STAGES[..k]
                    .iter()
                    .find(|s| s.name == input.from)
                    .unwrap_or_else(|| panic!("{}: no earlier stage {}", stage.name, input.from));
                assert!(
                    from.outputs.iter().any(|(role, _)| *role == input.role),
                    "{}: {} writes no {}",
                    stage.name,
                    from.name,
                    input.role
                );
            }
        }
    }
}
