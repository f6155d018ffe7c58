//! The random-walk code of the original ALN software (docs/design.md §4): W-bit
//! codes where each level's code differs from the previous one in exactly
//! `step` bits. The guarantee given, for all levels i, j with m = |i − j|:
//!
//! - d(cᵢ, cⱼ) = step · m exactly while m ≤ `span` (a bit flipped on the walk
//!   is not flipped again within `span` steps), so nearby levels are near;
//! - d(cᵢ, cⱼ) ≥ step · `span` for every m > `span` (enforced while the walk
//!   is drawn), so distant levels are far and no code repeats.
//!
//! Codes are drawn from a seeded generator, so (L, W, step, span, seed)
//! determine them.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// How a walk is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WalkSpec {
    /// Number of levels L.
    pub levels: usize,
    /// Code width W in bits (≤ 64).
    pub width: u32,
    /// Bits flipped per level.
    pub step: u32,
    /// Levels over which distance grows linearly.
    pub span: u32,
    /// Seed of the walk.
    pub seed: u64,
}

/// Attempts at each level before the walk starts over.
const TRIES_PER_LEVEL: usize = 2000;
/// Walks drawn before giving up.
const RESTARTS: u64 = 200;

impl WalkSpec {
    /// Draws the codes, or says why this spec cannot have them.
    pub fn codes(&self) -> Result<Vec<u64>, String> {
        let (w, s, h) = (self.width, self.step, self.span);
        if !(1..=64).contains(&w) {
            return Err(format!(
                "the walk code needs 1 to 64 bits, found width = {w}"
            ));
        }
        if s == 0 || h == 0 || s * h + s > w {
            return Err(format!(
                "a walk of step {s} over span {h} needs width ≥ step·(span + 1) = {}, found {w}",
                s * (h + 1)
            ));
        }
        for restart in 0..RESTARTS {
            let mut rng = ChaCha8Rng::seed_from_u64(
                self.seed.wrapping_add(restart.wrapping_mul(0x9E37_79B9)),
            );
            if let Some(codes) = self.draw(&mut rng) {
                return Ok(codes);
            }
        }
        Err(format!(
            "found no walk of {} levels in {w} bits keeping distant levels {} bits apart; \
             use a wider code or a shorter span",
            self.levels,
            s * h
        ))
    }

    fn draw(&self, rng: &mut ChaCha8Rng) -> Option<Vec<u64>> {
        let (w, s, h) = (self.width, self.step as usize, self.span as usize);
        let mask = if w == 64 { u64::MAX } else { (1u64 << w) - 1 };
        let far = (s * h) as u32;
        let mut codes = vec![rng.random::<u64>() & mask];
        // The level at which each bit was last flipped.
        let mut last_flip = vec![usize::MAX; w as usize];
        for k in 1..self.levels {
            let free: Vec<usize> = (0..w as usize)
                .filter(|&b| last_flip[b] == usize::MAX || k - last_flip[b] > h)
                .collect();
            let accepted = (0..TRIES_PER_LEVEL).find_map(|_| {
                let mut flip = 0u64;
                let mut chosen = Vec::with_capacity(s);
                while chosen.len() < s {
                    let b = free[rng.random_range(0..free.len())];
                    if flip & (1 << b) == 0 {
                        flip |= 1 << b;
                        chosen.push(b);
                    }
                }
                let code = codes[k - 1] ^ flip;
                let far_ok = codes[..k.saturating_sub(h)]
                    .iter()
                    .all(|c| (c ^ code).count_ones() >= far);
                far_ok.then_some((code, chosen))
            });
            let (code, chosen) = accepted?;
            for b in chosen {
                last_flip[b] = k;
            }
            codes.push(code);
        }
        Some(codes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks the stated guarantee over all pairs of levels.
    pub fn check_guarantee(spec: &WalkSpec, codes: &[u64]) {
        let (s, h) = (spec.step, spec.span as usize);
        for i in 0..codes.len() {
            for j in i + 1..codes.len() {
                let d = (codes[i] ^ codes[j]).count_ones();
                let m = j - i;
                if m <= h {
                    assert_eq!(d, s * m as u32, "levels {i} and {j}");
                } else {
                    assert!(d >= s * h as u32, "levels {i} and {j}: distance {d}");
                }
            }
        }
    }

    #[test]
    fn paper_walk_keeps_its_guarantee_over_all_pairs() {
        let spec = WalkSpec {
            levels: 214,
            width: 23,
            step: 1,
            span: 7,
            seed: 42,
        };
        let codes = spec.codes().unwrap();
        assert_eq!(codes.len(), 214);
        assert!(codes.iter().all(|c| c >> 23 == 0));
        check_guarantee(&spec, &codes);
        assert_eq!(codes, spec.codes().unwrap(), "seeded: the same codes again");
    }

    #[test]
    fn impossible_walks_are_refused() {
        let tight = WalkSpec {
            levels: 214,
            width: 8,
            step: 1,
            span: 7,
            seed: 1,
        };
        assert!(tight.codes().unwrap_err().contains("found no walk"));
        let narrow = WalkSpec {
            levels: 10,
            width: 5,
            step: 2,
            span: 3,
            seed: 1,
        };
        assert!(
            narrow
                .codes()
                .unwrap_err()
                .contains("needs width ≥ step·(span + 1) = 8")
        );
    }
}
