//! Residual targets: a variable's change of level Δ = next − current,
//! clamped to ±k and coded as the level Δ + k of a code of 2k + 1 levels of
//! its own. Decoding adds Δ to the current level and clamps to the range.
//!
//! An angle that wraps (roll, whose range is the whole circle) takes Δ on
//! the circle: a step from +179° to −179° is +2°, not −358°, and decoding
//! wraps back into the range. Its period in levels is the circle over the
//! level spacing ([`Entry::period`]).

use serde::{Deserialize, Serialize};

use crate::codebook::Entry;
use crate::codes::{Code, Codec, binary_width};
use crate::walk::WalkSpec;

/// How one variable's change is coded: what a model file records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeltaSpec {
    /// Δ is clamped to ±k (k ≥ 1).
    pub k: u32,
    /// For an angle that wraps, the circle in levels.
    pub period: Option<u32>,
    /// The code of the 2k + 1 values of Δ.
    pub code: Code,
}

/// The change of level from `current` to `next`; with a `period` (an angle
/// that wraps), the shorter way round the circle.
pub fn change(current: u16, next: u16, period: Option<u32>) -> i32 {
    let d = i32::from(next) - i32::from(current);
    match period {
        Some(p) => {
            let p = p as i32;
            let d = d.rem_euclid(p);
            if d > p / 2 { d - p } else { d }
        }
        None => d,
    }
}

/// A variable's change of level: the arithmetic and the code.
#[derive(Clone, Debug, PartialEq)]
pub struct Residual {
    spec: DeltaSpec,
    /// The variable's levels L.
    levels: usize,
    codec: Codec,
}

/// Bits a walk code of Δ spans: levels within this many steps are
/// `WALK_SPAN` bits apart at most, farther ones at least that far.
const WALK_SPAN: u32 = 7;

impl Residual {
    /// The residual of a variable with `levels` levels. A walk code of Δ is
    /// drawn from `seed`, one bit a step over a span of s = min(7, 2k), in
    /// ⌈log₂(2k + 1)⌉ + 2s + 2 bits (at most 64).
    pub fn new(spec: DeltaSpec, levels: usize, seed: u64) -> Result<Residual, String> {
        if spec.k == 0 {
            return Err("Δ must be allowed at least ±1 level, found k = 0".into());
        }
        if let Some(p) = spec.period
            && !(2..=levels as u32).contains(&p)
        {
            return Err(format!(
                "a period of {p} levels does not fit a variable of {levels} levels"
            ));
        }
        let count = 2 * spec.k as usize + 1;
        let walk = (spec.code == Code::Walk).then(|| {
            let span = WALK_SPAN.min(count as u32 - 1);
            WalkSpec {
                levels: count,
                width: (binary_width(count) + 2 * span + 2).min(64),
                step: 1,
                span,
                seed,
            }
        });
        let codec = Codec::new(spec.code, count, walk)?;
        Ok(Residual {
            spec,
            levels,
            codec,
        })
    }

    /// The residual for a codebook entry: its levels, period and seed.
    pub fn for_entry(entry: &Entry, k: u32, code: Code) -> Result<Residual, String> {
        let spec = DeltaSpec {
            k,
            period: entry.period(),
            code,
        };
        Residual::new(spec, entry.quantizer.levels, entry.seed)
    }

    /// What a model file records of it.
    pub fn spec(&self) -> DeltaSpec {
        self.spec
    }

    /// The levels L of the variable the change is applied to.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// The code of Δ + k.
    pub fn codec(&self) -> &Codec {
        &self.codec
    }

    /// The change from `current` to `next` (on the circle, if it wraps),
    /// not clamped.
    pub fn delta(&self, current: u16, next: u16) -> i32 {
        change(current, next, self.spec.period)
    }

    /// The level of the Δ code a tree learns for this pair: Δ clamped to
    /// ±k, plus k.
    pub fn target(&self, current: u16, next: u16) -> u16 {
        let k = self.spec.k as i32;
        (self.delta(current, next).clamp(-k, k) + k) as u16
    }

    /// The next level from `current` and a level of the Δ code: current +
    /// Δ, wrapped onto the range if the variable wraps, clamped to it.
    pub fn apply(&self, current: u16, delta_level: usize) -> u16 {
        let mut next = i64::from(current) + delta_level as i64 - i64::from(self.spec.k);
        let top = self.levels as i64 - 1;
        if let Some(p) = self.spec.period {
            let p = i64::from(p);
            if next < 0 {
                next += p;
            } else if next > top {
                next -= p;
            }
        }
        next.clamp(0, top) as u16
    }

    /// The next level a Δ code's bits decode to from `current`; with a
    /// `window`, Δ is limited to ±window (the rate limit, §4.7).
    pub fn decode(&self, bits: &[u64], current: u16, window: Option<usize>) -> u16 {
        let delta_level = match window {
            Some(w) => self.codec.decode_near(bits, self.spec.k as usize, w),
            None => self.codec.decode(bits),
        };
        self.apply(current, delta_level)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn residual(k: u32, period: Option<u32>, code: Code, levels: usize) -> Residual {
        Residual::new(DeltaSpec { k, period, code }, levels, 7).unwrap()
    }

    #[test]
    fn every_delta_within_k_round_trips_in_every_code() {
        for code in Code::ALL {
            for k in [1, 2, 5, 40] {
                let r = residual(k, None, code, 100);
                for current in [0u16, 1, 37, 98, 99] {
                    for d in -(k as i32)..=k as i32 {
                        let next = i32::from(current) + d;
                        if !(0..100).contains(&next) {
                            continue;
                        }
                        let target = r.target(current, next as u16);
                        let bits = r.codec().codeword(usize::from(target));
                        assert_eq!(
                            r.decode(bits, current, None),
                            next as u16,
                            "{code}, k = {k}, {current} → {next}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn large_changes_clamp_to_k_and_decoding_clamps_to_the_range() {
        let r = residual(3, None, Code::Gray, 50);
        assert_eq!(r.target(10, 30), 6, "+20 clamps to +3");
        assert_eq!(r.target(30, 10), 0, "−20 clamps to −3");
        assert_eq!(r.apply(10, 6), 13);
        // At the range's ends a change past them stops there.
        assert_eq!(r.apply(1, 0), 0);
        assert_eq!(r.apply(48, 6), 49);
        // A rate limit of one level bounds Δ to ±1.
        let bits = r.codec().codeword(6);
        assert_eq!(r.decode(bits, 20, Some(1)), 21);
        assert_eq!(r.decode(bits, 20, Some(0)), 20);
    }

    #[test]
    fn angles_wrap_on_the_circle() {
        // 214 levels over [−π, π]: level 0 and level 213 are the same angle.
        let r = residual(4, Some(213), Code::Binary, 214);
        assert_eq!(r.delta(212, 1), 2, "+179° → −179° is a small step");
        assert_eq!(r.delta(1, 212), -2);
        assert_eq!(r.delta(0, 213), 0);
        assert_eq!(r.delta(100, 103), 3);
        for (current, next) in [(212u16, 1u16), (1, 212), (211, 0), (2, 211), (100, 96)] {
            let t = r.target(current, next);
            let back = r.apply(current, usize::from(t));
            assert_eq!(
                r.delta(back, next),
                0,
                "{current} → {next} came back as {back}"
            );
        }
        // A step of −5 on the circle clamps to −4.
        assert_eq!(r.apply(2, usize::from(r.target(2, 210))), 211);
        // Without a period the same step is a big jump, clamped.
        let flat = residual(4, None, Code::Binary, 214);
        assert_eq!(flat.delta(212, 1), -211);
        assert_eq!(flat.target(212, 1), 0);
    }

    #[test]
    fn bad_specs_say_why() {
        let spec = |k, period| DeltaSpec {
            k,
            period,
            code: Code::Gray,
        };
        assert!(
            Residual::new(spec(0, None), 10, 0)
                .unwrap_err()
                .contains("k = 0")
        );
        assert!(
            Residual::new(spec(2, Some(11)), 10, 0)
                .unwrap_err()
                .contains("period of 11")
        );
    }
}
