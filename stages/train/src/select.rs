//! Inputs that matter: for each output variable, the input variables whose
//! levels carry the most information about what its trees learn (its next
//! level or its change), scored on the training rows only — so that each
//! tree's leaves see each useful input bit many times instead of spreading
//! over every bit of every variable.
//!
//! The score is the mutual information between the input's level and the
//! target, each reduced to at most [`BINS`] bins of about equal counts over
//! the training rows, estimated by the plug-in estimate with the
//! Miller–Madow correction (which keeps inputs with many occupied bins from
//! scoring high on noise alone).

/// Bins a column is reduced to for scoring.
pub const BINS: usize = 16;

/// Each row's bin: levels in order of value, cut into `BINS` bins of about
/// equal counts over `rows` (equal levels always share a bin).
fn bins(column: &[u16], rows: &[usize]) -> Vec<u8> {
    let top = rows.iter().map(|&r| column[r]).max().unwrap_or(0);
    let mut count = vec![0usize; usize::from(top) + 1];
    rows.iter()
        .for_each(|&r| count[usize::from(column[r])] += 1);
    let n = rows.len().max(1);
    let mut below = 0;
    let bin_of: Vec<u8> = count
        .iter()
        .map(|&c| {
            // The bin of the level's middle rank.
            let bin = (BINS * (2 * below + c) / (2 * n)).min(BINS - 1);
            below += c;
            bin as u8
        })
        .collect();
    rows.iter()
        .map(|&r| bin_of[usize::from(column[r])])
        .collect()
}

/// Entropy (nats) of a histogram over `n` samples, and its occupied cells.
fn entropy(histogram: &[usize], n: f64) -> (f64, usize) {
    histogram
        .iter()
        .filter(|&&c| c > 0)
        .fold((0.0, 0), |(h, m), &c| {
            let p = c as f64 / n;
            (h - p * p.ln(), m + 1)
        })
}

/// The Miller–Madow estimate of the mutual information (nats) of two
/// binned columns of equal length.
pub fn mutual_information(a: &[u8], b: &[u8]) -> f64 {
    let n = a.len() as f64;
    let (mut ha, mut hb, mut hab) = ([0; BINS], [0; BINS], [0; BINS * BINS]);
    for (&x, &y) in a.iter().zip(b) {
        ha[usize::from(x)] += 1;
        hb[usize::from(y)] += 1;
        hab[usize::from(x) * BINS + usize::from(y)] += 1;
    }
    let ((ea, ma), (eb, mb), (eab, mab)) = (entropy(&ha, n), entropy(&hb, n), entropy(&hab, n));
    // Each entropy's bias is −(m − 1)/2n for m occupied cells.
    let correction = (ma as f64 - 1.0 + mb as f64 - 1.0 - (mab as f64 - 1.0)) / (2.0 * n);
    ea + eb - eab + correction
}

/// For each target column, the `count` input columns (indices, ascending)
/// that score highest against it over `rows`; ties go to the earlier input.
pub fn informative(
    inputs: &[&[u16]],
    targets: &[&[u16]],
    rows: &[usize],
    count: usize,
) -> Vec<Vec<usize>> {
    let inputs: Vec<Vec<u8>> = inputs.iter().map(|c| bins(c, rows)).collect();
    targets
        .iter()
        .map(|t| {
            let t = bins(t, rows);
            let mut scored: Vec<(f64, usize)> = inputs
                .iter()
                .enumerate()
                .map(|(i, x)| (mutual_information(x, &t), i))
                .collect();
            scored.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            let mut chosen: Vec<usize> = scored.iter().take(count).map(|&(_, i)| i).collect();
            chosen.sort_unstable();
            chosen
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn bins_have_about_equal_counts_and_keep_equal_levels_together() {
        let column: Vec<u16> = (0..1600).map(|i| (i % 400) as u16).collect();
        let rows: Vec<usize> = (0..1600).collect();
        let b = bins(&column, &rows);
        let mut counts = [0; BINS];
        b.iter().for_each(|&x| counts[usize::from(x)] += 1);
        assert!(counts.iter().all(|&c| c == 100), "{counts:?}");
        // Mostly one level: it takes one bin, the rare levels the others.
        let skewed: Vec<u16> = (0..1000)
            .map(|i| if i < 900 { 5 } else { i as u16 })
            .collect();
        let b = bins(&skewed, &(0..1000).collect::<Vec<_>>());
        assert!(b[..900].iter().all(|&x| x == b[0]));
        assert!(b[900..].iter().all(|&x| x != b[0]));
    }

    #[test]
    fn mutual_information_is_entropy_for_a_copy_and_near_zero_for_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let a: Vec<u8> = (0..4000).map(|_| rng.random_range(0..4)).collect();
        let noise: Vec<u8> = (0..4000).map(|_| rng.random_range(0..4)).collect();
        let copy = mutual_information(&a, &a);
        // H = ln 4 for four equally likely values (less the sample's wobble).
        assert!((copy - 4f64.ln()).abs() < 0.01, "{copy}");
        let none = mutual_information(&a, &noise);
        assert!(none.abs() < 0.003, "{none}");
    }

    #[test]
    fn the_inputs_that_drive_a_target_are_chosen() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let columns: Vec<Vec<u16>> = (0..6)
            .map(|_| (0..2000).map(|_| rng.random_range(0..100)).collect())
            .collect();
        // The target depends on inputs 4 and 1 (4 more), plus noise.
        let target: Vec<u16> = (0..2000)
            .map(|r| 2 * columns[4][r] + columns[1][r] + rng.random_range(0..20))
            .collect();
        let inputs: Vec<&[u16]> = columns.iter().map(Vec::as_slice).collect();
        let rows: Vec<usize> = (0..2000).collect();
        assert_eq!(informative(&inputs, &[&target], &rows, 2), [[1, 4]]);
        assert_eq!(informative(&inputs, &[&target], &rows, 1), [[4]]);
        // Scored on the rows given only: on rows where the target copies
        // input 0, input 0 wins.
        let copy: Vec<u16> = (0..2000)
            .map(|r| if r < 500 { columns[0][r] } else { target[r] })
            .collect();
        let first: Vec<usize> = (0..500).collect();
        assert_eq!(informative(&inputs, &[&copy], &first, 1), [[0]]);
    }
}
