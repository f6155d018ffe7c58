//! The quantize stage (paper §4.2, §4.4, §6; docs/design.md §4): reads
//! `pairs.parquet` and `stats.parquet`, clamps each variable to its range,
//! quantizes it to L levels and writes
//! - `codebook.parquet`: per variable its range, L, code, width, walk seed,
//!   whether it is learned (a variable constant in the data is not) and how
//!   many values were clamped;
//! - `levels.parquet`: `scene`, `run`, `step`, `split`, then the level (u16)
//!   of every learned `x.` and `y.` value.
//!
//! The codes themselves, and the codebook's format, live in the
//! `alnlab-codes` library, which the stages after this one read it with.

pub mod bench;

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::params::{self, Count, ParamError};
use alnlab_common::{Error, Progress, Provenance, Result};
use alnlab_tables::levels;
use alnlab_tables::pairs::{Pairs, Side};
use arrow_array::Array;
use serde::{Deserialize, Serialize};

use alnlab_codes::codebook::is_control;
use alnlab_codes::codes::{Code, binary_width};
use alnlab_codes::walk::WalkSpec;
use alnlab_codes::{Codebook, Entry, GROUPS, Quantizer, group_of};

/// Version of what this stage writes (part of every cache key).
pub const FORMAT_VERSION: u32 = 3;
/// File name of the codebook.
pub const CODEBOOK_FILE: &str = alnlab_tables::codebook::FILE;

/// Where variable ranges come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RangeSource {
    /// The min and max seen in the data (`stats.parquet`).
    #[default]
    Observed,
    /// The paper's table of §4.2, by group.
    Paper,
}

/// The paper's ranges (§4.2: "All available configuration files for
/// DynaTree were then run"), by variable group.
pub const PAPER_RANGES: [(&str, f64, f64); 8] = [
    ("a", -500.0, 500.0),
    ("f_E", -3000.0, 4000.0),
    ("g_E", -3000.0, 3000.0),
    ("g", -150.0, 150.0),
    ("R", -1.57, 1.57),
    ("omega", -35.0, 35.0),
    ("omega_dot", -1500.0, 2000.0),
    ("v", -18.0, 11.0),
];

/// The `[quantize]` table of a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Levels per variable, L ≥ 2 (paper: 214).
    pub levels: Count,
    /// The code of a level.
    pub code: Code,
    /// Width of the walk code in bits (paper: 23).
    pub width: Count,
    /// Bits flipped per level on the walk.
    pub walk_step: Count,
    /// Levels over which walk distance grows linearly (see [`walk`]).
    pub walk_span: Count,
    /// Where ranges come from.
    pub ranges: RangeSource,
    /// Ranges given by hand, by group (`a`, `R`, …) or variable (`a.1.z`);
    /// a variable's own entry wins over its group's.
    pub range: BTreeMap<String, [f64; 2]>,
    /// Groups no model learns or reads (`qdd`, …): a forward model of a
    /// robot is its state a controller knows and the torque it applies,
    /// and a recording's accelerations are taken from the velocities
    /// around a frame, the next one's included.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub never_learned: Vec<String>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            levels: Count(214),
            code: Code::Walk,
            width: Count(23),
            walk_step: Count(1),
            walk_span: Count(7),
            ranges: RangeSource::Observed,
            range: BTreeMap::new(),
            never_learned: Vec::new(),
        }
    }
}

impl Params {
    /// Checks the parameters; on error, the key and what is allowed.
    pub fn validate(&self) -> std::result::Result<(), ParamError> {
        let levels = self.levels.get();
        if levels < 2 {
            return Err((
                "levels".into(),
                format!("expected at least 2 levels, found {levels}"),
            ));
        }
        if levels > 65536 {
            return Err((
                "levels".into(),
                format!("expected at most 65536 levels, found {levels}"),
            ));
        }
        if self.code == Code::Walk {
            let (w, s, h) = (self.width.0, self.walk_step.0, self.walk_span.0);
            let min = u64::from(binary_width(levels));
            if w < min || w > 64 {
                return Err((
                    "width".into(),
                    format!("{levels} levels need a walk code of {min} to 64 bits, found {w}"),
                ));
            }
            if s * (h + 1) > w {
                return Err((
                    "walk_span".into(),
                    format!(
                        "a walk of step {s} over span {h} needs width ≥ {}, found {w}",
                        s * (h + 1)
                    ),
                ));
            }
        }
        for group in &self.never_learned {
            if !GROUPS.contains(&group.as_str()) || is_control(&format!("{group}.")) {
                return Err((
                    "never_learned".into(),
                    format!(
                        "`{group}` is not a group of state variables (expected some of {}; the \
                         controls are [train] controls')",
                        GROUPS
                            .iter()
                            .filter(|g| !is_control(&format!("{g}.")))
                            .copied()
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
        }
        for (name, [lo, hi]) in &self.range {
            let known_group =
                GROUPS.contains(&name.as_str()) || ["roll", "pitch"].contains(&name.as_str());
            let looks_like_variable = name.contains('.') && GROUPS.contains(&group_of(name));
            if !known_group && !looks_like_variable {
                return Err((
                    format!("range.{name}"),
                    format!(
                        "unknown group or variable `{name}`; groups are {}",
                        GROUPS.join(", ")
                    ),
                ));
            }
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err((
                    format!("range.{name}"),
                    format!("expected [min, max] with min < max, found [{lo}, {hi}]"),
                ));
            }
        }
        Ok(())
    }

    /// The walk of a variable (its seed derived from the experiment seed and
    /// the variable's name), if the code is `walk`.
    fn walk(&self, seed: u64, variable: &str) -> Option<WalkSpec> {
        (self.code == Code::Walk).then(|| WalkSpec {
            levels: self.levels.get(),
            width: self.width.0 as u32,
            step: self.walk_step.0 as u32,
            span: self.walk_span.0 as u32,
            seed: variable_seed(seed, variable),
        })
    }
}

/// A seed per variable: FNV-1a of the name mixed into the experiment seed.
pub fn variable_seed(seed: u64, variable: &str) -> u64 {
    alnlab_common::hash::fnv1a(variable.as_bytes(), seed)
}

/// The files the stage reads.
pub struct Inputs<'a> {
    /// The pairs table to quantize.
    pub pairs: &'a Path,
    /// Its per-variable statistics.
    pub stats: &'a Path,
}

/// Reads `pairs` and `stats`, writes the codebook and the levels table into
/// `out_dir`.
pub fn run(
    params: &Params,
    seed: u64,
    inputs: &Inputs,
    provenance: &Provenance,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let Inputs {
        pairs: pairs_path,
        stats: stats_path,
    } = *inputs;
    params
        .validate()
        .map_err(|e| params::invalid("quantize", e))?;
    let pairs = Pairs::read(pairs_path)?;
    let stats = alnlab_tables::stats::read(stats_path)?;
    let variables = pairs.variables();
    for name in params.range.keys() {
        let known = variables.iter().any(|v| {
            v == name || group_of(v) == name || v.split('.').next() == Some(name.as_str())
        });
        if !known {
            return Err(Error::Invalid(format!(
                "quantize.range.{name}: the data has no such variable or group; its variables are {}",
                variables.join(", ")
            )));
        }
    }
    let observed = observed_ranges(&stats);
    let scales = group_scales(&observed);
    progress.start("quantize", variables.len() as u64, "variables");

    let mut entries = Vec::new();
    // The learned variables' levels, `[variable][row]`, on each side.
    let (mut x_levels, mut y_levels) = (Vec::new(), Vec::new());
    for v in variables {
        let x = pairs.column(Side::Current, v)?;
        let y = pairs.column(Side::Next, v)?;
        let (lo, hi) = observed
            .get(v.as_str())
            .copied()
            .ok_or_else(|| Error::bad_file(stats_path, format!("has no statistics for `{v}`")))?;
        let (min, max) = params
            .range
            .get(v)
            .or_else(|| params.range.get(group_of(v)))
            .or_else(|| params.range.get(v.split('.').next().unwrap_or("")))
            .map(|[a, b]| (*a, *b))
            .or_else(|| match params.ranges {
                RangeSource::Observed => (lo < hi).then_some((lo, hi)),
                RangeSource::Paper => PAPER_RANGES
                    .iter()
                    .find(|g| g.0 == group_of(v))
                    .map(|g| (g.1, g.2)),
            })
            .unwrap_or((lo, hi));
        let walk = params.walk(seed, v);
        let mut entry = Entry {
            variable: v.clone(),
            learned: true,
            note: String::new(),
            quantizer: Quantizer {
                min,
                max,
                levels: params.levels.get(),
            },
            code: params.code,
            // The walk's width; the other codes' width follows from L below.
            width: walk.map_or(0, |w| w.width),
            walk_step: walk.map_or(0, |w| w.step),
            walk_span: walk.map_or(0, |w| w.span),
            seed: walk.map_or(0, |w| w.seed),
            clamped: 0,
        };
        if x.null_count() > 0 || y.null_count() > 0 {
            // A scene without the variable has neither side of it.
            if let Some(r) = (0..x.len()).find(|&r| x.is_null(r) != y.is_null(r)) {
                return Err(Error::bad_file(
                    pairs_path,
                    format!(
                        "row {r}: `{v}` is null on one side of the pair only (x.{v} {}, y.{v} {})",
                        if x.is_null(r) { "null" } else { "present" },
                        if y.is_null(r) { "null" } else { "present" }
                    ),
                ));
            }
            entry.learned = false;
            entry.note = "missing in some scene".into();
        } else if lo == hi {
            entry.learned = false;
            entry.note = format!("constant ({lo}) in the data");
        } else if is_round_off(hi - lo, scales[group_of(v)]) {
            entry.learned = false;
            entry.note = format!(
                "constant but for round-off: spread {:.3e} against {:.3e}, the largest magnitude \
                 of {} in the data",
                hi - lo,
                scales[group_of(v)],
                group_of(v)
            );
        }
        if entry.learned && params.never_learned.iter().any(|g| g == group_of(v)) {
            entry.learned = false;
            entry.note = format!(
                "never learned: [quantize] never_learned names `{}`",
                group_of(v)
            );
        }
        let codec = entry
            .codec()
            .map_err(|e| Error::Invalid(format!("quantize: {v}: {e}")))?;
        entry.width = codec.width();
        if entry.learned {
            for (values, levels) in [(x, &mut x_levels), (y, &mut y_levels)] {
                let mut clamped = 0u64;
                levels.push(
                    values
                        .values()
                        .iter()
                        .map(|&value| {
                            let (level, was_clamped) = entry.quantizer.level(value);
                            clamped += u64::from(was_clamped);
                            level
                        })
                        .collect(),
                );
                entry.clamped += clamped;
            }
        }
        entries.push(entry);
        progress.advance(1);
    }
    let learned: Vec<&str> = entries
        .iter()
        .filter(|e| e.learned)
        .map(|e| e.variable.as_str())
        .collect();
    levels::write(
        &out_dir.join(levels::FILE),
        pairs.keys(),
        &learned,
        &x_levels,
        &y_levels,
        provenance,
    )?;
    alnlab_tables::codebook::write(
        &Codebook { entries },
        &out_dir.join(CODEBOOK_FILE),
        provenance,
    )
}

/// A variable whose spread is at most this fraction of its group's scale
/// (the largest magnitude any variable of the same quantity, and so the same
/// unit, takes in the data) is constant but for floating-point round-off.
/// Measured on the committed scenes: round-off spreads are ~1e-14 of the
/// scale (ω̇ₓ of symmetric links: no torque about a link's own axis), real
/// ones at least 0.06 — the tolerance sits in between with room either side.
pub const ROUND_OFF_RELATIVE: f64 = 1e-9;
/// … or at most this much in SI units, for a quantity that is round-off
/// throughout (its scale itself is round-off).
pub const ROUND_OFF_ABSOLUTE: f64 = 1e-12;

/// Whether a spread is round-off for a variable of a group with `scale`.
fn is_round_off(spread: f64, scale: f64) -> bool {
    spread <= ROUND_OFF_RELATIVE * scale || spread <= ROUND_OFF_ABSOLUTE
}

/// The scale of every group: the largest magnitude its variables take.
fn group_scales<'a>(observed: &BTreeMap<&'a str, (f64, f64)>) -> BTreeMap<&'a str, f64> {
    let mut scales: BTreeMap<&str, f64> = BTreeMap::new();
    for (variable, (lo, hi)) in observed {
        let scale = scales.entry(group_of(variable)).or_default();
        *scale = scale.max(lo.abs()).max(hi.abs());
    }
    scales
}

/// (min, max) per variable from `stats.parquet`'s rows.
fn observed_ranges(stats: &[alnlab_tables::stats::Row]) -> BTreeMap<&str, (f64, f64)> {
    stats
        .iter()
        .map(|r| (r.variable.as_str(), (r.min, r.max)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use alnlab_common::Silent;
    use alnlab_common::params::Positive;
    use alnlab_common::table::{self, Table};
    use alnlab_tables::pairs;
    use arrow_array::{Float64Array, UInt16Array};
    use std::sync::Arc;

    /// Simulates `scene` with `seed` and strides it; returns the folder.
    fn simulated(scene: alnlab_simulate::Scene, seed: u64) -> tempfile::TempDir {
        simulated_scenes(vec![scene], seed)
    }

    /// Simulates `scenes` together with `seed` and strides them; returns
    /// the folder.
    fn simulated_scenes(scenes: Vec<alnlab_simulate::Scene>, seed: u64) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let sim = alnlab_simulate::Params {
            scene: scenes,
            ..Default::default()
        };
        let provenance = Provenance::default();
        alnlab_simulate::run(&sim, seed, &provenance, dir.path(), &Silent).unwrap();
        let trajectory = dir.path().join(alnlab_simulate::TRAJECTORY_FILE);
        let stride = alnlab_stride::Params::default();
        alnlab_stride::run(&stride, seed, &trajectory, &provenance, dir.path(), &Silent).unwrap();
        dir
    }

    /// A short worm run, simulated and strided.
    fn data() -> tempfile::TempDir {
        simulated(
            alnlab_simulate::Scene {
                duration: Positive(3.0),
                ..Default::default()
            },
            5,
        )
    }

    fn quantize(params: &Params, dir: &Path) -> Result<()> {
        let (pairs, stats) = (dir.join(pairs::FILE), dir.join(alnlab_simulate::STATS_FILE));
        run(
            params,
            5,
            &Inputs {
                pairs: &pairs,
                stats: &stats,
            },
            &Provenance::default(),
            dir,
            &Silent,
        )
    }

    #[test]
    fn levels_are_the_quantized_pairs_and_the_codebook_reads_back() {
        let dir = data();
        let params = Params {
            levels: Count(50),
            ..Params::default()
        };
        quantize(&params, dir.path()).unwrap();
        let codebook = alnlab_tables::codebook::read(&dir.path().join(CODEBOOK_FILE)).unwrap();
        let levels = Table::read(&dir.path().join(levels::FILE)).unwrap();
        let pairs = Table::read(&dir.path().join(pairs::FILE)).unwrap();
        assert_eq!(levels.num_rows(), pairs.num_rows());
        assert!(codebook.learned().count() > 40);
        for entry in codebook.learned() {
            assert_eq!(
                (entry.quantizer.levels, entry.width, entry.clamped),
                (50, 23, 0)
            );
            for side in ["x", "y"] {
                let name = format!("{side}.{}", entry.variable);
                let got = levels.column::<UInt16Array>(&name).unwrap();
                let values = pairs.f64_column(&name).unwrap();
                for r in 0..values.len() {
                    // Independently: nearest of 50 evenly spaced values.
                    let q = entry.quantizer;
                    let step = (q.max - q.min) / 49.0;
                    let expected = ((values.value(r) - q.min) / step).round() as u16;
                    assert_eq!(got.value(r), expected, "{name} row {r}");
                }
            }
        }
    }

    #[test]
    fn paper_ranges_clamp_and_count() {
        let dir = data();
        let params = Params {
            ranges: RangeSource::Paper,
            range: [("omega".to_string(), [-1.0, 1.0])].into(),
            ..Params::default()
        };
        quantize(&params, dir.path()).unwrap();
        let codebook = alnlab_tables::codebook::read(&dir.path().join(CODEBOOK_FILE)).unwrap();
        let find = |v: &str| codebook.entries.iter().find(|e| e.variable == v).unwrap();
        assert_eq!(
            (find("a.1.x").quantizer.min, find("a.1.x").quantizer.max),
            (-500.0, 500.0)
        );
        assert_eq!(find("roll.2").quantizer.max, 1.57);
        let omega = find("omega.1.y");
        assert_eq!(
            (omega.quantizer.min, omega.quantizer.max),
            (-1.0, 1.0),
            "a manual group range wins"
        );
        let pairs = Table::read(&dir.path().join(pairs::FILE)).unwrap();
        let outside = ["x", "y"]
            .iter()
            .flat_map(|s| {
                let c = pairs.f64_column(&format!("{s}.omega.1.y")).unwrap();
                (0..c.len()).map(move |r| c.value(r)).collect::<Vec<_>>()
            })
            .filter(|x| x.abs() > 1.0)
            .count() as u64;
        assert!(outside > 0);
        assert_eq!(omega.clamped, outside);
    }

    #[test]
    fn a_variable_missing_in_one_scene_is_not_learned() {
        // A pendulum's first link hangs from a fixed hinge: it has no
        // linear velocity a worm's free root has.
        let scene = |name: &str, kind| alnlab_simulate::Scene {
            name: name.into(),
            kind,
            duration: Positive(1.0),
            ..Default::default()
        };
        let dir = simulated_scenes(
            vec![
                scene("worm", alnlab_simulate::SceneKind::Worm),
                scene("pendulum", alnlab_simulate::SceneKind::Pendulum),
            ],
            3,
        );
        quantize(&Params::default(), dir.path()).unwrap();
        let codebook = alnlab_tables::codebook::read(&dir.path().join(CODEBOOK_FILE)).unwrap();
        let missing: Vec<&Entry> = codebook
            .entries
            .iter()
            .filter(|e| e.note == "missing in some scene")
            .collect();
        assert!(!missing.is_empty(), "{:?}", codebook.entries);
        assert!(missing.iter().all(|e| !e.learned));
        let levels = alnlab_tables::levels::Levels::read(
            &dir.path().join(levels::FILE),
            &dir.path().join(CODEBOOK_FILE),
        )
        .unwrap();
        let scenes: std::collections::BTreeSet<&str> =
            levels.keys().iter().map(|k| k.scene.as_str()).collect();
        assert_eq!(scenes, ["pendulum", "worm"].into());
    }

    #[test]
    fn a_group_never_learned_is_not_learned_and_says_why() {
        let dir = data();
        let params = Params {
            never_learned: vec!["a".into()],
            ..Params::default()
        };
        quantize(&params, dir.path()).unwrap();
        let codebook = alnlab_tables::codebook::read(&dir.path().join(CODEBOOK_FILE)).unwrap();
        let a: Vec<&Entry> = codebook
            .entries
            .iter()
            .filter(|e| group_of(&e.variable) == "a")
            .collect();
        assert!(!a.is_empty());
        assert!(
            a.iter().all(
                |e| !e.learned && e.note == "never learned: [quantize] never_learned names `a`"
            )
        );
        assert!(
            codebook.learned().count() > 30,
            "the other groups are learned"
        );
        for bad in ["tau", "g", "speed"] {
            let p = Params {
                never_learned: vec![bad.into()],
                ..Params::default()
            };
            assert_eq!(p.validate().unwrap_err().0, "never_learned", "{bad}");
        }
    }

    #[test]
    fn constant_variables_are_not_learned() {
        // Without a controller the hinge torques are absent; make the floor
        // absent too and hold the worm still in zero gravity: nothing moves.
        let dir = simulated(
            alnlab_simulate::Scene {
                kind: alnlab_simulate::SceneKind::Tumbler,
                initial_spin: Some(0.0),
                duration: Positive(1.0),
                ..Default::default()
            },
            1,
        );
        quantize(&Params::default(), dir.path()).unwrap();
        let codebook = alnlab_tables::codebook::read(&dir.path().join(CODEBOOK_FILE)).unwrap();
        assert_eq!(codebook.learned().count(), 0);
        assert!(
            codebook
                .entries
                .iter()
                .all(|e| e.note.starts_with("constant (")),
            "{:?}",
            codebook.entries[0].note
        );
        let levels = Table::read(&dir.path().join(levels::FILE)).unwrap();
        assert_eq!(
            levels.batch.num_columns(),
            4,
            "only scene, run, step, split"
        );
    }

    #[test]
    fn round_off_is_relative_to_the_group_and_absolute_at_the_floor() {
        // The pendulum's ω̇ₓ: spread 8.9e-13 against a scale of 125 rad/s².
        assert!(is_round_off(8.85e-13, 124.9));
        // The smallest real relative spread in the committed scenes.
        assert!(!is_round_off(0.06 * 50.0, 50.0));
        assert!(!is_round_off(1e-7, 1.0));
        assert!(is_round_off(1e-9, 1.0));
        // A quantity that is round-off throughout.
        assert!(is_round_off(5e-13, 5e-13));
        assert!(!is_round_off(2e-12, 2e-12));
        let observed = BTreeMap::from([
            ("omega_dot.1.x", (-1e-13, 1e-13)),
            ("omega_dot.1.y", (-30.0, 125.0)),
            ("roll.2", (-3.0, 1.0)),
            ("pitch.2", (-0.5, 0.5)),
        ]);
        let scales = group_scales(&observed);
        assert_eq!((scales["omega_dot"], scales["R"]), (125.0, 3.0));
    }

    #[test]
    fn round_off_variables_of_a_pendulum_are_not_learned() {
        // A pendulum of symmetric links: no torque about a link's own axis,
        // so ω̇ₓ is zero but for round-off.
        let dir = simulated(
            alnlab_simulate::Scene {
                name: "pendulum".into(),
                kind: alnlab_simulate::SceneKind::Pendulum,
                duration: Positive(2.0),
                ..Default::default()
            },
            3,
        );
        quantize(&Params::default(), dir.path()).unwrap();
        let codebook = alnlab_tables::codebook::read(&dir.path().join(CODEBOOK_FILE)).unwrap();
        let stats =
            alnlab_tables::stats::read(&dir.path().join(alnlab_simulate::STATS_FILE)).unwrap();
        let observed = observed_ranges(&stats);
        let round_off: Vec<&str> = codebook
            .entries
            .iter()
            .filter(|e| e.note.starts_with("constant but for round-off"))
            .map(|e| e.variable.as_str())
            .collect();
        assert_eq!(
            round_off,
            ["omega_dot.1.x", "omega_dot.2.x", "omega_dot.3.x"],
            "{:?}",
            codebook
                .entries
                .iter()
                .map(|e| (&e.variable, &e.note))
                .collect::<Vec<_>>()
        );
        for v in &round_off {
            let (lo, hi) = observed[v];
            assert!(hi > lo && hi - lo < 1e-10, "{v}: spread {}", hi - lo);
        }
        // Every variable that moves is learned.
        for e in codebook.learned() {
            let (lo, hi) = observed[e.variable.as_str()];
            assert!(hi - lo > 1e-3, "{}: spread {}", e.variable, hi - lo);
        }
    }

    #[test]
    fn bad_parameters_and_names_are_refused() {
        let err = |p: Params| p.validate().unwrap_err();
        let e = err(Params {
            range: [("a".into(), [5.0, 5.0])].into(),
            ..Params::default()
        });
        assert_eq!(e.0, "range.a");
        assert!(e.1.contains("min < max"));
        assert!(
            err(Params {
                levels: Count(1),
                ..Params::default()
            })
            .1
            .contains("at least 2 levels")
        );
        let e = err(Params {
            levels: Count(1000),
            width: Count(8),
            ..Params::default()
        });
        assert_eq!(e.0, "width");
        assert!(e.1.contains("1000 levels need a walk code of 10 to 64 bits, found 8"));
        let e = err(Params {
            range: [("speed".into(), [0.0, 1.0])].into(),
            ..Params::default()
        });
        assert!(e.1.contains("unknown group or variable `speed`"));
        // Well formed but absent from the data: refused when the data is seen.
        let dir = data();
        let p = Params {
            range: [("a.9.x".into(), [0.0, 1.0])].into(),
            ..Params::default()
        };
        let e = quantize(&p, dir.path()).unwrap_err();
        assert!(
            e.to_string()
                .contains("quantize.range.a.9.x: the data has no such variable"),
            "{e}"
        );
        assert_eq!(e.exit_code(), 2);
    }

    /// Rewrites the pairs in `dir` with column `name`'s values edited.
    fn edit_pairs(dir: &Path, name: &str, edit: impl Fn(&mut Vec<Option<f64>>)) {
        let pairs_path = dir.join(pairs::FILE);
        let pairs = Table::read(&pairs_path).unwrap();
        let mut columns: Vec<(String, Arc<dyn Array>)> = Vec::new();
        for (field, column) in pairs
            .batch
            .schema()
            .fields()
            .iter()
            .zip(pairs.batch.columns())
        {
            let mut column = column.clone();
            if field.name() == name {
                let mut values: Vec<Option<f64>> = pairs.f64_column(name).unwrap().iter().collect();
                edit(&mut values);
                column = Arc::new(Float64Array::from(values));
            }
            columns.push((field.name().clone(), column));
        }
        let batch = table::batch(
            columns
                .iter()
                .map(|(n, c)| (n.as_str(), c.clone()))
                .collect(),
        );
        table::write_parquet(&pairs_path, &batch, &Provenance::default()).unwrap();
    }

    #[test]
    fn a_variable_on_one_side_of_its_pairs_only_is_damage() {
        let dir = data();
        edit_pairs(dir.path(), "y.v.2.z", |values| values.fill(None));
        let e = quantize(&Params::default(), dir.path()).unwrap_err();
        assert!(
            e.to_string()
                .contains("row 0: `v.2.z` is null on one side of the pair only (x.v.2.z present, y.v.2.z null)"),
            "{e}"
        );
    }

    #[test]
    fn non_finite_values_name_row_and_column() {
        let dir = data();
        edit_pairs(dir.path(), "y.v.2.z", |values| values[7] = Some(f64::NAN));
        let e = quantize(&Params::default(), dir.path()).unwrap_err();
        assert!(
            e.to_string()
                .contains("pairs.parquet: row 7, column `y.v.2.z`: NaN is not a finite number"),
            "{e}"
        );
        assert_eq!(e.exit_code(), 2);
    }
}
