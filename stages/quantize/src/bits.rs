//! Bit matrices: rows × bits, each row packed into little-endian u64 words
//! (bit i of a row is bit i % 64 of word i / 64). The train and test stages
//! read their inputs and targets in this form.

use crate::codes::Codec;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codes::Code;
    use crate::walk::WalkSpec;

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
    }
}
