//! The four codes of a quantization level (docs/design.md §4), each with its
//! encoder and its decoder, which is defined for every bit pattern, codeword
//! or not:
//!
//! | code | width | decode(bits) |
//! |---|---|---|
//! | `binary` | ⌈log₂ L⌉ | the number the bits spell, clamped to L − 1 |
//! | `gray` | ⌈log₂ L⌉ | the reflected-Gray inverse, clamped to L − 1 |
//! | `walk` | W | the level of the nearest code (Hamming), ties to the lower level |
//! | `thermometer` | L − 1 | the number of ones (level k is k ones) |
//!
//! Codes are stored per level as little-endian u64 words; bit i of a code is
//! bit i % 64 of word i / 64.

use serde::{Deserialize, Serialize};

use crate::near::ChunkIndex;
use crate::walk::WalkSpec;

/// Which code.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Code {
    Binary,
    Gray,
    #[default]
    Walk,
    Thermometer,
}

impl Code {
    /// Every code.
    pub const ALL: [Code; 4] = [Code::Binary, Code::Gray, Code::Walk, Code::Thermometer];

    /// Bits a codeword of `levels` levels has (at least 2 levels); a walk's
    /// width is its own parameter, `walk_width`, which the others ignore.
    pub fn width(self, levels: usize, walk_width: u32) -> u32 {
        match self {
            Code::Binary | Code::Gray => binary_width(levels),
            Code::Thermometer => (levels - 1) as u32,
            Code::Walk => walk_width,
        }
    }
}

// A code's name is its serde name, as in manifests: one mapping for the
// manifest, the codebook file and every message.
serde_plain::derive_display_from_serialize!(Code);
serde_plain::derive_fromstr_from_deserialize!(Code);

/// Bits needed for L levels in binary: ⌈log₂ L⌉ (at least 1).
pub fn binary_width(levels: usize) -> u32 {
    (usize::BITS - (levels - 1).leading_zeros()).max(1)
}

/// A code for L levels with its table of codewords.
#[derive(Clone, Debug, PartialEq)]
pub struct Codec {
    code: Code,
    levels: usize,
    width: u32,
    words: usize,
    /// `levels × words` codewords.
    table: Vec<u64>,
    /// Bits flipped per level (walk only; 0 otherwise).
    walk_step: u32,
    /// Walk only: finds the nearest codeword without a scan when it is near.
    index: Option<ChunkIndex>,
}

impl Codec {
    /// The codec of `code` for `levels` levels; `walk` uses `walk` (its width
    /// and span), the others ignore it. Says why, if the parameters cannot
    /// make a code.
    pub fn new(code: Code, levels: usize, walk: Option<WalkSpec>) -> Result<Codec, String> {
        if levels < 2 {
            return Err(format!("expected at least 2 levels, found {levels}"));
        }
        if levels > usize::from(u16::MAX) + 1 {
            return Err(format!("expected at most 65536 levels, found {levels}"));
        }
        let walk_width = match (code, walk) {
            (Code::Walk, None) => return Err("the walk code needs its width and span".into()),
            (_, walk) => walk.map_or(0, |w| w.width),
        };
        let width = code.width(levels, walk_width);
        let words = width.div_ceil(64) as usize;
        let mut table = vec![0u64; levels * words];
        let walk_step = if code == Code::Walk {
            walk.map_or(0, |w| w.step)
        } else {
            0
        };
        match code {
            Code::Binary => (0..levels).for_each(|k| table[k] = k as u64),
            Code::Gray => (0..levels).for_each(|k| table[k] = (k ^ (k >> 1)) as u64),
            Code::Thermometer => {
                for k in 0..levels {
                    for bit in 0..k {
                        table[k * words + bit / 64] |= 1 << (bit % 64);
                    }
                }
            }
            Code::Walk => {
                let spec = WalkSpec {
                    levels,
                    ..walk.expect("checked above")
                };
                let min = binary_width(levels);
                if spec.width < min {
                    return Err(format!(
                        "{levels} levels need a code of at least {min} bits, found width = {}",
                        spec.width
                    ));
                }
                table = spec.codes()?;
            }
        }
        let index = (code == Code::Walk).then(|| ChunkIndex::new(&table, width));
        Ok(Codec {
            code,
            levels,
            width,
            words,
            table,
            walk_step,
            index,
        })
    }

    /// The code.
    pub fn code(&self) -> Code {
        self.code
    }

    /// Number of levels L.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// Bits per code.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// The codeword of `level`, as words.
    pub fn codeword(&self, level: usize) -> &[u64] {
        &self.table[level * self.words..(level + 1) * self.words]
    }

    /// The level a bit pattern (as words, bits beyond the width zero) stands
    /// for; defined for every pattern (see the module table).
    pub fn decode(&self, bits: &[u64]) -> usize {
        let last = self.levels - 1;
        match self.code {
            Code::Binary => (bits[0] as usize).min(last),
            Code::Gray => {
                let mut x = bits[0];
                let mut shift = 1;
                while shift < 64 {
                    x ^= x >> shift;
                    shift <<= 1;
                }
                (x as usize).min(last)
            }
            Code::Thermometer => {
                (bits.iter().map(|w| w.count_ones() as usize).sum::<usize>()).min(last)
            }
            Code::Walk => {
                let near = self.index.as_ref().expect("walk codecs have an index");
                near.nearest_within(&self.table, bits[0])
                    .unwrap_or_else(|| self.nearest(bits[0], 0, last))
            }
        }
    }

    /// Like [`Codec::decode`], but only levels within `window` of `previous`
    /// are candidates (paper §4.7: a variable moves little per step, so only
    /// part of the path need be checked).
    pub fn decode_near(&self, bits: &[u64], previous: usize, window: usize) -> usize {
        let lo = previous.saturating_sub(window);
        let hi = (previous + window).min(self.levels - 1);
        match self.code {
            Code::Walk => self.nearest(bits[0], lo, hi),
            _ => self.decode(bits).clamp(lo, hi),
        }
    }

    /// The level in `lo..=hi` whose (single-word) walk code is nearest to
    /// `bits`, the lowest on ties.
    ///
    /// Exact, but skips levels that cannot win: consecutive walk codes differ
    /// in `step` bits, so j levels past a code at distance d lie at distance
    /// ≥ d − step·j, and none of them beats the best b found so far while
    /// j ≤ (d − b) / step.
    fn nearest(&self, bits: u64, lo: usize, hi: usize) -> usize {
        let step = self.walk_step.max(1);
        let (mut best, mut best_level) = (u32::MAX, lo);
        let mut k = lo;
        while k <= hi {
            let d = (self.table[k] ^ bits).count_ones();
            if d < best {
                (best, best_level) = (d, k);
            }
            // (Division is slow; the common one-bit walk needs none.)
            let skip = if step == 1 {
                d - best
            } else {
                (d - best) / step
            };
            k += skip as usize + 1;
        }
        best_level
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walk(width: u32, span: u32) -> Option<WalkSpec> {
        Some(WalkSpec {
            levels: 0,
            width,
            step: 1,
            span,
            seed: 3,
        })
    }

    fn codecs(levels: usize) -> Vec<Codec> {
        let w = match levels {
            0..=16 => 8,
            17..=214 => 23,
            _ => 32,
        };
        let span = if levels > 16 { 7 } else { 2 };
        [Code::Binary, Code::Gray, Code::Walk, Code::Thermometer]
            .into_iter()
            .map(|c| Codec::new(c, levels, walk(w, span)).unwrap())
            .collect()
    }

    #[test]
    fn every_level_round_trips() {
        for levels in [2, 3, 214, 1000] {
            for codec in codecs(levels) {
                for k in 0..levels {
                    assert_eq!(
                        codec.decode(codec.codeword(k)),
                        k,
                        "{:?} L={levels} k={k}",
                        codec.code()
                    );
                }
            }
        }
    }

    #[test]
    fn widths() {
        assert_eq!(binary_width(2), 1);
        assert_eq!(binary_width(3), 2);
        assert_eq!(binary_width(214), 8);
        assert_eq!(binary_width(1000), 10);
        let c = codecs(214);
        assert_eq!(
            c.iter().map(Codec::width).collect::<Vec<_>>(),
            [8, 8, 23, 213]
        );
    }

    #[test]
    fn gray_neighbours_differ_in_one_bit() {
        let gray = Codec::new(Code::Gray, 1000, None).unwrap();
        for k in 1..1000 {
            assert_eq!(
                (gray.codeword(k)[0] ^ gray.codeword(k - 1)[0]).count_ones(),
                1
            );
        }
    }

    #[test]
    fn non_codewords_decode_as_defined() {
        let binary = Codec::new(Code::Binary, 214, None).unwrap();
        assert_eq!(binary.decode(&[250]), 213, "beyond L − 1: clamped");
        let gray = Codec::new(Code::Gray, 214, None).unwrap();
        // 255 in Gray is the inverse of 170 (10101010) → clamped.
        assert_eq!(gray.decode(&[255]), 170);
        assert_eq!(gray.decode(&[0b1000_0000]), 213, "Gray 128 → 255 → clamped");
        let thermo = Codec::new(Code::Thermometer, 214, None).unwrap();
        // Ones anywhere count: 0b1011 has three.
        assert_eq!(thermo.decode(&[0b1011, 0, 0, 0]), 3);
        let walk = Codec::new(Code::Walk, 214, walk(23, 7)).unwrap();
        // One bit off a codeword decodes to it (distance 1 < any other's).
        for k in [0, 50, 213] {
            let flipped = walk.codeword(k)[0] ^ (1 << 5);
            let d = walk.decode(&[flipped]);
            let dist = |l: usize| (walk.codeword(l)[0] ^ flipped).count_ones();
            assert!(
                dist(d) <= 1 && (0..d).all(|l| dist(l) > dist(d)),
                "k={k} → {d}"
            );
        }
        // Ties go to the lower level: with two bits per step, flipping one of
        // them leaves a pattern one bit from each neighbour.
        let exact_tie = Codec::new(
            Code::Walk,
            214,
            Some(WalkSpec {
                levels: 0,
                width: 23,
                step: 2,
                span: 3,
                seed: 9,
            }),
        )
        .unwrap();
        let (a, b) = (exact_tie.codeword(20)[0], exact_tie.codeword(21)[0]);
        let diff = a ^ b; // two bits
        let one = diff & diff.wrapping_neg(); // lowest of them
        assert_eq!(
            exact_tie.decode(&[a ^ one]),
            20,
            "one bit from each: the lower level"
        );
    }

    #[test]
    fn skipping_search_equals_brute_force() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for (step, span) in [(1, 7), (2, 3), (3, 2)] {
            let spec = WalkSpec {
                levels: 0,
                width: 23,
                step,
                span,
                seed: 5,
            };
            let walk = Codec::new(Code::Walk, 214, Some(spec)).unwrap();
            for _ in 0..20_000 {
                let bits = rng.random::<u64>() & ((1 << 23) - 1);
                let (lo, hi) = (rng.random_range(0..100), rng.random_range(100..214));
                let brute = (lo..=hi)
                    .min_by_key(|&k| ((walk.codeword(k)[0] ^ bits).count_ones(), k))
                    .unwrap();
                assert_eq!(
                    walk.nearest(bits, lo, hi),
                    brute,
                    "step {step}, bits {bits:#x}"
                );
                // decode, through the chunk index, near a codeword and not.
                let near =
                    walk.codeword(rng.random_range(0..214))[0] ^ (1 << rng.random_range(0..23));
                for bits in [bits, near] {
                    let brute = (0..214)
                        .min_by_key(|&k| ((walk.codeword(k)[0] ^ bits).count_ones(), k))
                        .unwrap();
                    assert_eq!(walk.decode(&[bits]), brute, "step {step}, bits {bits:#x}");
                }
            }
        }
    }

    #[test]
    fn window_limits_the_candidates() {
        let walk = Codec::new(Code::Walk, 214, walk(23, 7)).unwrap();
        let far = walk.codeword(200)[0];
        assert_eq!(
            walk.decode_near(&[far], 20, 10),
            walk.decode_near(&[far], 20, 10).clamp(10, 30)
        );
        assert_eq!(walk.decode_near(walk.codeword(25), 20, 10), 25);
        let binary = Codec::new(Code::Binary, 214, None).unwrap();
        assert_eq!(binary.decode_near(&[200], 20, 10), 30);
    }

    #[test]
    fn bad_parameters_say_why() {
        assert!(
            Codec::new(Code::Binary, 1, None)
                .unwrap_err()
                .contains("at least 2 levels")
        );
        let narrow = Codec::new(Code::Walk, 1000, walk(8, 2)).unwrap_err();
        assert!(
            narrow.contains("1000 levels need a code of at least 10 bits"),
            "{narrow}"
        );
    }
}
