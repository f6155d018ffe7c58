//! What a model's trees predict for each variable, and how their bits
//! become the next level: the next level itself, in the variable's code
//! (`level`), or its change Δ in a code of its own (`delta`, see
//! [`alnlab_codes::residual`]). The train stage makes the targets with it
//! and every evaluation path — batched, one row, rate limited, closed loop
//! — decodes with it, so all of them agree.

use alnlab_codes::{Codec, DeltaSpec, Entry, Residual};
use serde::{Deserialize, Serialize};

/// What the trees of a model learn, as its file records it.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Target {
    /// Each variable's next level, in its codebook code.
    #[default]
    Level,
    /// Each variable's change of level, per output in tree order.
    Delta(Vec<DeltaSpec>),
    /// Each variable's change of its real value in level spacings,
    /// unrounded (on the circle for angles that wrap): what a
    /// piecewise-linear model computes. Not decoded from bits.
    Change,
}

impl Target {
    /// `level` or `delta`, as manifests and reports name it.
    pub fn kind(&self) -> &'static str {
        match self {
            Target::Level => "level",
            Target::Delta(_) => "delta",
            Target::Change => "change",
        }
    }
}

/// One variable's output: what its trees learn and how it decodes.
#[derive(Clone, Debug, PartialEq)]
pub enum Output {
    /// The next level in the variable's code.
    Level(Codec),
    /// The change of level.
    Delta(Residual),
}

impl Output {
    /// The outputs for `learned` (the codebook's learned entries, in tree
    /// order) under `target`; on a mismatch, what differs.
    pub fn for_entries(target: &Target, learned: &[&Entry]) -> Result<Vec<Output>, String> {
        match target {
            Target::Level => learned
                .iter()
                .map(|e| e.codec().map(Output::Level))
                .collect::<Result<_, _>>()
                .map_err(|m| format!("the codebook's codes: {m}")),
            Target::Delta(specs) => {
                if specs.len() != learned.len() {
                    return Err(format!(
                        "codes the change of {} variables, but the codebook learns {}",
                        specs.len(),
                        learned.len()
                    ));
                }
                specs
                    .iter()
                    .zip(learned)
                    .map(|(spec, e)| {
                        if spec.period != e.period() {
                            return Err(format!(
                                "`{}`: the model's change wraps every {:?} levels, the \
                                 codebook's range every {:?}",
                                e.variable,
                                spec.period,
                                e.period()
                            ));
                        }
                        Residual::new(*spec, e.quantizer.levels, e.seed)
                            .map(Output::Delta)
                            .map_err(|m| format!("`{}`: {m}", e.variable))
                    })
                    .collect()
            }
            Target::Change => {
                Err("a piecewise-linear model's change is computed, not decoded from bits".into())
            }
        }
    }

    /// The code the trees' bits (or a threshold model's candidate) are in.
    pub fn codec(&self) -> &Codec {
        match self {
            Output::Level(codec) => codec,
            Output::Delta(residual) => residual.codec(),
        }
    }

    /// The level of [`Output::codec`] the trees learn for the pair
    /// `current` → `next`.
    pub fn target(&self, current: u16, next: u16) -> u16 {
        match self {
            Output::Level(_) => next,
            Output::Delta(residual) => residual.target(current, next),
        }
    }

    /// The next level the trees' bits stand for, from `current`; with a
    /// `window`, at most that many levels from it (the rate limit, §4.7).
    #[inline]
    pub fn decode(&self, bits: &[u64], current: u16, window: Option<usize>) -> u16 {
        match self {
            Output::Level(codec) => {
                let level = match window {
                    Some(w) => codec.decode_near(bits, usize::from(current), w),
                    None => codec.decode(bits),
                };
                level as u16
            }
            Output::Delta(residual) => residual.decode(bits, current, window),
        }
    }

    /// The next level for a level of [`Output::codec`] found otherwise (a
    /// threshold model's search), from `current`, rate limited if asked.
    pub fn settle(&self, found: usize, current: u16, window: Option<usize>) -> u16 {
        let (center, codec) = match self {
            Output::Level(codec) => (usize::from(current), codec),
            Output::Delta(residual) => (residual.spec().k as usize, residual.codec()),
        };
        let found = match window {
            Some(w) => found.clamp(center.saturating_sub(w), center + w),
            None => found,
        }
        .min(codec.levels() - 1);
        match self {
            Output::Level(_) => found as u16,
            Output::Delta(residual) => residual.apply(current, found),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use alnlab_codes::{Code, Quantizer};

    /// A learned Gray-coded entry of `levels` levels over `min..max`.
    pub(crate) fn entry_of(variable: &str, min: f64, max: f64, levels: usize) -> Entry {
        Entry {
            variable: variable.into(),
            learned: true,
            note: String::new(),
            quantizer: Quantizer { min, max, levels },
            code: Code::Gray,
            width: usize::BITS - (levels - 1).leading_zeros(),
            walk_step: 0,
            walk_span: 0,
            seed: 1,
            clamped: 0,
        }
    }

    fn entry(variable: &str, min: f64, max: f64) -> Entry {
        entry_of(variable, min, max, 64)
    }

    #[test]
    fn level_and_delta_outputs_decode_the_same_pair() {
        let e = entry("v.1.x", -1.0, 1.0);
        let level = &Output::for_entries(&Target::Level, &[&e]).unwrap()[0];
        let spec = DeltaSpec {
            k: 4,
            period: None,
            code: Code::Gray,
        };
        let delta = &Output::for_entries(&Target::Delta(vec![spec]), &[&e]).unwrap()[0];
        assert_eq!(delta.codec().levels(), 9);
        for (current, next) in [(10u16, 13u16), (13, 10), (0, 0), (63, 60)] {
            for out in [level, delta] {
                let bits = out.codec().codeword(usize::from(out.target(current, next)));
                assert_eq!(out.decode(bits, current, None), next);
                // Rate limited to one level, both move one level towards next.
                let limited = out.decode(bits, current, Some(1));
                assert!(limited.abs_diff(current) <= 1 && limited.abs_diff(next) < 3);
                let found = usize::from(out.target(current, next));
                assert_eq!(out.settle(found, current, None), next);
                assert!(out.settle(found, current, Some(1)).abs_diff(current) <= 1);
            }
        }
    }

    #[test]
    fn a_delta_model_must_agree_with_the_codebook_about_wrapping() {
        let roll = entry("roll.2", -std::f64::consts::PI, std::f64::consts::PI);
        let flat = DeltaSpec {
            k: 2,
            period: None,
            code: Code::Gray,
        };
        let err = Output::for_entries(&Target::Delta(vec![flat]), &[&roll]).unwrap_err();
        assert!(
            err.contains("`roll.2`") && err.contains("Some(63)"),
            "{err}"
        );
        let err = Output::for_entries(&Target::Delta(vec![]), &[&roll]).unwrap_err();
        assert!(err.contains("change of 0 variables"), "{err}");
    }
}
