//! Bit matrices: rows × bits, each row packed into little-endian u64 words
//! (bit i of a row is bit i % 64 of word i / 64). The train and test stages
//! read their inputs and targets in this form.

use crate::codes::{Code, Codec};

/// A rows × bits matrix of packed bits.
#[derive(Clone, Debug, PartialEq)]
pub struct BitMatrix {
    rows: usize,
    bits: usize,
    words_per_row: usize,
    data: Vec<u64>,
}

impl BitMatrix {
    /// An all-zero matrix.
    pub fn zeros(rows: usize, bits: usize) -> BitMatrix {
        let words_per_row = bits.div_ceil(64);
        BitMatrix {
            rows,
            bits,
            words_per_row,
            data: vec![0; rows * words_per_row],
        }
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Bits per row.
    pub fn bits(&self) -> usize {
        self.bits
    }

    /// Row `r` as words.
    pub fn row(&self, r: usize) -> &[u64] {
        &self.data[r * self.words_per_row..(r + 1) * self.words_per_row]
    }

    /// Bit `bit` of row `r`.
    pub fn get(&self, r: usize, bit: usize) -> bool {
        self.row(r)[bit / 64] >> (bit % 64) & 1 == 1
    }

    /// Bits `offset..offset + width` of row `r`, as words (for decoding).
    pub fn extract(&self, r: usize, offset: usize, width: usize, out: &mut [u64]) {
        out.fill(0);
        let row = self.row(r);
        for i in 0..width {
            let bit = offset + i;
            out[i / 64] |= (row[bit / 64] >> (bit % 64) & 1) << (i % 64);
        }
    }
}

/// ORs `width` bits of `src` into `row` starting at bit `offset`.
fn put_bits(row: &mut [u64], offset: usize, src: &[u64], width: usize) {
    let mut done = 0;
    while done < width {
        let take = (width - done).min(64);
        let word = src[done / 64]
            & if take == 64 {
                u64::MAX
            } else {
                (1 << take) - 1
            };
        let (at, shift) = ((offset + done) / 64, (offset + done) % 64);
        row[at] |= word << shift;
        if shift > 0 && shift + take > 64 {
            row[at + 1] |= word >> (64 - shift);
        }
        done += take;
    }
}

/// Encodes level columns (one per variable, equally long) with their codecs
/// into a bit matrix whose rows are the variables' codes side by side.
pub fn encode(codecs: &[&Codec], columns: &[&[u16]]) -> BitMatrix {
    assert_eq!(codecs.len(), columns.len(), "one codec per column");
    let rows = columns.first().map_or(0, |c| c.len());
    let widths: Vec<usize> = codecs.iter().map(|c| c.width() as usize).collect();
    let mut matrix = BitMatrix::zeros(rows, widths.iter().sum());
    let wpr = matrix.words_per_row;
    for (r, row) in matrix
        .data
        .chunks_exact_mut(wpr.max(1))
        .enumerate()
        .take(rows)
    {
        let mut offset = 0;
        for ((codec, column), &width) in codecs.iter().zip(columns).zip(&widths) {
            put_bits(row, offset, codec.codeword(usize::from(column[r])), width);
            offset += width;
        }
    }
    matrix
}

/// The bit-sliced columns of the bits `bits` (ascending indices into the
/// variables' codes side by side, as [`encode`] lays them out) of level
/// columns coded with `codecs`: each column made straight from the levels,
/// without coding whole rows — a model that reads a few bits of long codes
/// pays for those bits only, and thermometer bits (level > j) cost a few
/// operations per 64 rows each.
pub fn encode_columns(codecs: &[&Codec], columns: &[&[u16]], bits: &[u32]) -> Columns {
    assert_eq!(codecs.len(), columns.len(), "one codec per column");
    debug_assert!(bits.is_sorted(), "ascending bits");
    let count = columns.first().map_or(0, |c| c.len());
    let words = count.div_ceil(64).max(1);
    let mut data = vec![0u64; bits.len() * words];
    let (mut first, mut offset) = (0, 0);
    // Each variable's share of `bits`, and where its code starts.
    for (codec, levels) in codecs.iter().zip(columns) {
        let width = codec.width() as usize;
        let last = first + bits[first..].partition_point(|&b| (b as usize) < offset + width);
        let mine = &bits[first..last];
        let out = &mut data[first * words..last * words];
        if codec.code() == Code::Thermometer {
            thermometer_columns(levels, mine, offset, words, out);
        } else {
            for (column, &bit) in out.chunks_exact_mut(words).zip(mine) {
                let j = bit as usize - offset;
                for (word, chunk) in column.iter_mut().zip(levels.chunks(64)) {
                    for (i, &level) in chunk.iter().enumerate() {
                        *word |= (codec.codeword(usize::from(level))[j / 64] >> (j % 64) & 1) << i;
                    }
                }
            }
        }
        (first, offset) = (last, offset + width);
    }
    Columns {
        count,
        bits: bits.len(),
        words,
        data,
    }
}

/// Thermometer bits `bits` (code bit j = `bits[i]` − `offset`, set when
/// level > j) of `levels`: per word of 64 rows, the rows at each level as a
/// mask, then the rows above each j by removing those at j, j − 1, ….
fn thermometer_columns(levels: &[u16], bits: &[u32], offset: usize, words: usize, out: &mut [u64]) {
    let Some(&top) = bits.last() else { return };
    let widest = top as usize - offset + 1;
    let mut at = vec![0u64; widest];
    for (w, chunk) in levels.chunks(64).enumerate() {
        at.fill(0);
        let mut above = 0u64;
        for (i, &level) in chunk.iter().enumerate() {
            above |= 1 << i;
            if let Some(mask) = at.get_mut(usize::from(level)) {
                *mask |= 1 << i;
            }
        }
        let mut next = bits.iter().enumerate().peekable();
        for (j, &mask) in at.iter().enumerate() {
            above &= !mask;
            if let Some((column, _)) = next.next_if(|&(_, &b)| b as usize - offset == j) {
                out[column * words + w] = above;
            }
        }
    }
}

/// Bit-sliced columns: bit `b` of sample `s` is bit `s % 64` of
/// `data[b * words + s / 64]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Columns {
    /// Number of samples.
    pub count: usize,
    /// Number of bits (columns).
    pub bits: usize,
    /// Words per column.
    pub words: usize,
    /// `bits × words` words.
    pub data: Vec<u64>,
}

impl Columns {
    /// The columns of the rows `rows` of a bit matrix.
    pub fn from_rows(matrix: &BitMatrix, rows: &[usize]) -> Columns {
        let (count, bits) = (rows.len(), matrix.bits());
        let words = count.div_ceil(64).max(1);
        let mut data = vec![0u64; bits * words];
        for (s, &r) in rows.iter().enumerate() {
            let row = matrix.row(r);
            for b in 0..bits {
                data[b * words + s / 64] |= (row[b / 64] >> (b % 64) & 1) << (s % 64);
            }
        }
        Columns {
            count,
            bits,
            words,
            data,
        }
    }

    /// Column `b`.
    pub fn column(&self, b: usize) -> &[u64] {
        &self.data[b * self.words..(b + 1) * self.words]
    }

    /// Hands each sample's bits to `f`, in sample order, as ⌈bits/64⌉ words:
    /// a 64×64 transpose per word of samples and 64 bits.
    pub fn for_each_row(&self, mut f: impl FnMut(usize, &[u64])) {
        let groups = self.bits.div_ceil(64).max(1);
        let mut rows = vec![0u64; 64 * groups];
        let mut square = [0u64; 64];
        for w in 0..self.words {
            for g in 0..groups {
                square.fill(0);
                let bits = 64 * g..self.bits.min(64 * (g + 1));
                for (row, b) in square.iter_mut().zip(bits) {
                    *row = self.data[b * self.words + w];
                }
                transpose(&mut square);
                for (i, &word) in square.iter().enumerate() {
                    rows[i * groups + g] = word;
                }
            }
            let samples = (self.count - 64 * w).min(64);
            for (i, row) in rows.chunks_exact(groups).take(samples).enumerate() {
                f(64 * w + i, row);
            }
        }
    }
}

/// Transposes a 64×64 bit matrix in place (bit c of `m[r]` ↔ bit r of
/// `m[c]`) by swapping off-diagonal blocks of 32, 16, … 1: 6·32 masked swaps
/// rather than a loop per bit.
fn transpose(m: &mut [u64; 64]) {
    let mut j = 32;
    let mut mask: u64 = 0x0000_0000_FFFF_FFFF;
    while j != 0 {
        for k in (0..64).filter(|k| k & j == 0) {
            let t = ((m[k] >> j) ^ m[k + j]) & mask;
            m[k + j] ^= t;
            m[k] ^= t << j;
        }
        j >>= 1;
        mask ^= mask << j;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codes::Code;
    use crate::walk::WalkSpec;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn encoded_rows_decode_back() {
        let walk = Codec::new(
            Code::Walk,
            214,
            Some(WalkSpec {
                levels: 0,
                width: 23,
                step: 1,
                span: 7,
                seed: 1,
            }),
        )
        .unwrap();
        let thermo = Codec::new(Code::Thermometer, 100, None).unwrap();
        let gray = Codec::new(Code::Gray, 214, None).unwrap();
        let a: Vec<u16> = (0..500).map(|i| (i * 7 % 214) as u16).collect();
        let b: Vec<u16> = (0..500).map(|i| (i * 13 % 100) as u16).collect();
        let c: Vec<u16> = (0..500).map(|i| (i * 3 % 214) as u16).collect();
        let codecs = [&walk, &thermo, &gray, &walk];
        let m = encode(&codecs, &[&a, &b, &c, &c]);
        assert_eq!(m.bits(), 23 + 99 + 8 + 23);
        let mut buf = [0u64; 2];
        for r in 0..500 {
            let mut offset = 0;
            for (codec, column) in codecs.iter().zip([&a, &b, &c, &c]) {
                let w = codec.width() as usize;
                m.extract(r, offset, w, &mut buf);
                assert_eq!(codec.decode(&buf[..w.div_ceil(64)]), usize::from(column[r]));
                offset += w;
            }
        }
        assert!(m.get(0, 0) == (walk.codeword(0)[0] & 1 == 1));

        // Columns of some bits straight from the levels: the same as the
        // encoded rows' columns.
        let all = Columns::from_rows(&m, &(0..500).collect::<Vec<_>>());
        let bits: Vec<u32> = vec![0, 5, 22, 23, 24, 90, 121, 122, 129, 130, 152];
        let some = encode_columns(&codecs, &[&a, &b, &c, &c], &bits);
        assert_eq!((some.count, some.bits, some.words), (500, bits.len(), 8));
        for (i, &bit) in bits.iter().enumerate() {
            assert_eq!(some.column(i), all.column(bit as usize), "bit {bit}");
        }
    }

    #[test]
    fn every_row_comes_out_whole_however_wide() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        for bits in [1, 5, 23, 64, 130] {
            let columns = Columns {
                count: 100,
                bits,
                words: 2,
                data: (0..2 * bits).map(|_| rng.random()).collect(),
            };
            let mut seen = 0;
            columns.for_each_row(|s, row| {
                assert_eq!(s, seen);
                assert_eq!(row.len(), bits.div_ceil(64));
                for b in 0..64 * row.len() {
                    let expected = if b < bits {
                        columns.column(b)[s / 64] >> (s % 64) & 1
                    } else {
                        0
                    };
                    assert_eq!(
                        row[b / 64] >> (b % 64) & 1,
                        expected,
                        "bits {bits}, sample {s}"
                    );
                }
                seen += 1;
            });
            assert_eq!(seen, 100);
        }
    }
}
