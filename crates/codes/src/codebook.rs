//! The codebook: every variable's range, level count and code, written by
//! the quantize stage and read by every stage after it (its file,
//! `codebook.parquet`, is `alnlab_tables::codebook`'s).
//!
//! The codebook is the one source of each learned variable's codec: a stage
//! that needs to encode or decode levels builds it with
//! [`Codebook::learned_codecs`].

use std::path::Path;

use alnlab_core::{Error, Result};

use crate::codes::{Code, Codec};
use crate::walk::WalkSpec;

/// The variable groups of docs/design.md §3 (roll and pitch form the group `R`),
/// and a robot's per-joint groups: position, velocity, acceleration and
/// control effort.
pub const GROUPS: [&str; 12] = [
    "a",
    "f_E",
    "g_E",
    "g",
    "R",
    "omega",
    "omega_dot",
    "v",
    "q",
    "qd",
    "qdd",
    "tau",
];

/// The group of a variable name (`omega_dot.3.x` → `omega_dot`, `roll.2` → `R`).
pub fn group_of(variable: &str) -> &str {
    match variable.split('.').next().unwrap_or("") {
        "roll" | "pitch" => "R",
        g => g,
    }
}

/// Whether a variable is a control a planner or a user sets: the
/// controller's hinge torques `g.<link>.<axis>`, or a robot's joint
/// efforts `tau.<joint>`.
pub fn is_control(variable: &str) -> bool {
    matches!(group_of(variable), "g" | "tau")
}

/// The SI unit of a variable of the paper's groups (§4.1) or a robot's, by
/// its name's quantity (a robot joint's: revolute or prismatic); empty for a
/// name of no known quantity.
pub fn unit_of(variable: &str) -> &'static str {
    match variable.split('.').next().unwrap_or("") {
        "v" => "m/s",
        "a" => "m/s²",
        "omega" => "rad/s",
        "omega_dot" => "rad/s²",
        "g" | "g_E" => "N·m",
        "f_E" => "N",
        "roll" | "pitch" => "rad",
        "q" => "rad or m",
        "qd" => "rad/s or m/s",
        "qdd" => "rad/s² or m/s²",
        "tau" => "N·m or N",
        _ => "",
    }
}

/// Uniform quantization of one variable.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantizer {
    pub min: f64,
    pub max: f64,
    pub levels: usize,
}

impl Quantizer {
    /// The level of `x` (nearest of L evenly spaced values from min to max)
    /// and whether it was clamped into the range.
    #[inline]
    pub fn level(&self, x: f64) -> (u16, bool) {
        let top = (self.levels - 1) as f64;
        let t = (x - self.min) / (self.max - self.min) * top;
        let clamped = !(0.0..=top).contains(&t);
        (t.round().clamp(0.0, top) as u16, clamped)
    }

    /// The value a level stands for.
    pub fn value(&self, level: usize) -> f64 {
        self.min + (self.max - self.min) * level as f64 / (self.levels - 1) as f64
    }
}

/// One variable's line of the codebook.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub variable: String,
    pub learned: bool,
    /// Why a variable is not learned (empty if it is).
    pub note: String,
    pub quantizer: Quantizer,
    pub code: Code,
    pub width: u32,
    pub walk_step: u32,
    pub walk_span: u32,
    pub seed: u64,
    /// How many of its `x.` and `y.` values were clamped into the range.
    pub clamped: u64,
}

/// The codebook: every variable's range, levels and code.
#[derive(Clone, Debug, PartialEq)]
pub struct Codebook {
    pub entries: Vec<Entry>,
}

impl Codebook {
    /// The learned entries, in table order.
    pub fn learned(&self) -> impl Iterator<Item = &Entry> {
        self.entries.iter().filter(|e| e.learned)
    }

    /// The codecs of the learned entries, in table order; an entry whose
    /// parameters make no code is an error naming `path` (the codebook's).
    pub fn learned_codecs(&self, path: &Path) -> Result<Vec<Codec>> {
        self.learned()
            .map(|e| {
                e.codec()
                    .map_err(|m| Error::bad_file(path, format!("{}: {m}", e.variable)))
            })
            .collect()
    }
}

impl Entry {
    /// The entry's codec (a walk is redrawn from its seed).
    pub fn codec(&self) -> std::result::Result<Codec, String> {
        let walk = (self.code == Code::Walk).then_some(WalkSpec {
            levels: self.quantizer.levels,
            width: self.width,
            step: self.walk_step,
            span: self.walk_span,
            seed: self.seed,
        });
        Codec::new(self.code, self.quantizer.levels, walk)
    }

    /// For an angle that wraps — a roll (`roll.*`, in (−π, π]) whose range
    /// covers the circle to within two level spacings — the circle in
    /// levels: 2π over the spacing, rounded. `None` for every other variable.
    pub fn period(&self) -> Option<u32> {
        let q = &self.quantizer;
        let spacing = (q.max - q.min) / (q.levels - 1) as f64;
        let circle = std::f64::consts::TAU;
        (group_of(&self.variable) == "R"
            && self.variable.starts_with("roll.")
            && spacing > 0.0
            && q.max - q.min >= circle - 2.0 * spacing)
            .then(|| (circle / spacing).round() as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
            seed: 0,
            clamped: 0,
        }
    }

    #[test]
    fn only_rolls_over_the_whole_circle_wrap() {
        // The paper data's roll.2: level 0 and level 213 are both ±π.
        assert_eq!(
            entry("roll.2", -3.141573, 3.141497, 214).period(),
            Some(213)
        );
        let pi = std::f64::consts::PI;
        // Observed extremes a little inside ±π still wrap.
        assert_eq!(
            entry("roll.3", -pi + 1e-4, pi - 3e-4, 64).period(),
            Some(63)
        );
        assert_eq!(entry("roll.2", -pi / 2.0, pi / 2.0, 214).period(), None);
        assert_eq!(entry("pitch.2", -pi, pi, 214).period(), None);
        assert_eq!(entry("omega.1.x", -pi, pi, 214).period(), None);
    }
}
