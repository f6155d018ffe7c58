//! Exact nearest-codeword search by pigeonhole (multi-index hashing): the
//! codes are cut into k chunks, and a codeword within Hamming distance k − 1
//! of a pattern equals it on at least one whole chunk. So the codewords that
//! share a chunk with the pattern — a few buckets' worth — contain every
//! codeword that near, and the nearest of them is the nearest of all when it
//! lies within k − 1. Predicted codes are mostly that near — most of them
//! codewords outright, which a hash table finds with one probe — so walk
//! decoding takes a probe or a handful of popcounts instead of a scan of all
//! levels.

/// Buckets of codewords by the value of each chunk.
#[derive(Clone, Debug, PartialEq)]
pub struct ChunkIndex {
    chunks: u32,
    chunk_bits: u32,
    /// Chunk c's bucket of value x is `levels[starts[i]..starts[i + 1]]`,
    /// i = c·2^chunk_bits + x.
    starts: Vec<u32>,
    /// Levels, ascending within each bucket.
    levels: Vec<u32>,
    /// An open-addressing hash table of the codewords (level + 1 per slot,
    /// 0 empty, linear probing): a pattern that is a codeword — most
    /// predictions — is found with one probe.
    exact: Vec<u32>,
}

impl ChunkIndex {
    /// Indexes single-word codewords of `width` bits (level = position).
    pub fn new(codewords: &[u64], width: u32) -> ChunkIndex {
        // At least four chunks (radius 3), of at most 8 bits (small buckets).
        let chunks = width.div_ceil(8).max(4).min(width);
        let chunk_bits = width.div_ceil(chunks);
        let buckets = (chunks as usize) << chunk_bits;
        let bucket = |c: u32, word: u64| {
            ((c as usize) << chunk_bits)
                | (word >> (c * chunk_bits) & ((1 << chunk_bits) - 1)) as usize
        };
        let mut starts = vec![0u32; buckets + 1];
        for &word in codewords {
            for c in 0..chunks {
                starts[bucket(c, word) + 1] += 1;
            }
        }
        for i in 0..buckets {
            starts[i + 1] += starts[i];
        }
        let mut fill = starts.clone();
        let mut levels = vec![0u32; codewords.len() * chunks as usize];
        for (level, &word) in codewords.iter().enumerate() {
            for c in 0..chunks {
                let i = bucket(c, word);
                levels[fill[i] as usize] = level as u32;
                fill[i] += 1;
            }
        }
        let slots = (2 * codewords.len()).next_power_of_two();
        let mut exact = vec![0u32; slots];
        for (level, &word) in codewords.iter().enumerate() {
            let mut slot = exact_slot(word, slots - 1);
            while exact[slot] != 0 {
                slot = (slot + 1) & (slots - 1);
            }
            exact[slot] = level as u32 + 1;
        }
        ChunkIndex {
            chunks,
            chunk_bits,
            starts,
            levels,
            exact,
        }
    }

    /// The lowest level whose codeword is `bits`, if any.
    fn exact_level(&self, codewords: &[u64], bits: u64) -> Option<usize> {
        let mask = self.exact.len() - 1;
        let mut slot = exact_slot(bits, mask);
        loop {
            let entry = self.exact[slot] as usize;
            if entry == 0 {
                return None;
            }
            if codewords[entry - 1] == bits {
                return Some(entry - 1);
            }
            slot = (slot + 1) & mask;
        }
    }

    /// The level of the codeword nearest to `bits` (the lowest on ties) if
    /// its distance is at most k − 1; `None` when every codeword is farther.
    pub fn nearest_within(&self, codewords: &[u64], bits: u64) -> Option<usize> {
        if let Some(level) = self.exact_level(codewords, bits) {
            return Some(level);
        }
        let (mut best, mut best_level) = (u32::MAX, usize::MAX);
        for c in 0..self.chunks {
            let value = (bits >> (c * self.chunk_bits) & ((1 << self.chunk_bits) - 1)) as usize;
            let i = ((c as usize) << self.chunk_bits) | value;
            for &level in &self.levels[self.starts[i] as usize..self.starts[i + 1] as usize] {
                let level = level as usize;
                let d = (codewords[level] ^ bits).count_ones();
                if (d, level) < (best, best_level) {
                    (best, best_level) = (d, level);
                }
            }
        }
        (best < self.chunks).then_some(best_level)
    }
}

/// Fibonacci hashing of a codeword into a table of `mask + 1` slots.
fn exact_slot(word: u64, mask: usize) -> usize {
    (word.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as usize & mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn within_the_radius_it_is_the_brute_force_nearest() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        for width in [4u32, 9, 23, 40, 64] {
            let mask = u64::MAX >> (64 - width);
            let codewords: Vec<u64> = (0..300).map(|_| rng.random::<u64>() & mask).collect();
            let index = ChunkIndex::new(&codewords, width);
            let radius = index.chunks - 1;
            let (mut found, mut missed) = (0, 0);
            for _ in 0..5000 {
                // Near a codeword, or anywhere.
                let mut bits = codewords[rng.random_range(0..300)];
                for _ in 0..rng.random_range(0..6) {
                    bits ^= 1 << rng.random_range(0..width);
                }
                if rng.random_bool(0.2) {
                    bits = rng.random::<u64>() & mask;
                }
                let brute = (0..300)
                    .min_by_key(|&l| ((codewords[l] ^ bits).count_ones(), l))
                    .unwrap();
                let distance = (codewords[brute] ^ bits).count_ones();
                match index.nearest_within(&codewords, bits) {
                    Some(level) => {
                        assert_eq!(level, brute, "width {width}, bits {bits:#x}");
                        found += 1;
                    }
                    None => {
                        assert!(distance > radius, "width {width}: missed at {distance}");
                        missed += 1;
                    }
                }
            }
            assert!(
                found > 1000,
                "width {width}: {found} found, {missed} missed"
            );
        }
    }
}
