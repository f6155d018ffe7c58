//! Error statistics (paper §4.5–4.6; docs/design.md §6) of absolute errors in
//! quantization levels.
//!
//! Errors are small whole numbers, so everything is computed from their
//! counts: one pass to count, then sums and order statistics from the counts
//! — exact integer sums, and no sort, which keeps 10⁷ errors well under a
//! second.
//!
//! Definitions: std dev is the sample one (n − 1; undefined, NaN, for n = 1),
//! std err = std dev / √n, the 5% trimmed mean drops ⌊0.05·n⌋ values from each
//! end (as `scipy.stats.trim_mean(x, 0.05)`), median and quartiles
//! interpolate linearly between order statistics (numpy's default), IQR =
//! Q3 − Q1, and the histogram counts errors of 0, 1, …, 9 levels (the
//! paper's §4.5 view) and then the tail: 10–19, 20–49, 50–99, 100 or more.

/// The lowest error of each bin of [`ErrorStats::histogram`]; a bin holds
/// errors up to the next bin's lowest, the last bin every larger error.
pub const HISTOGRAM_EDGES: [u32; HISTOGRAM_BINS] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 20, 50, 100];

/// Bins of [`ErrorStats::histogram`].
pub const HISTOGRAM_BINS: usize = 14;

/// The bin of [`ErrorStats::histogram`] holding errors of `error` levels.
pub fn histogram_bin(error: u32) -> usize {
    HISTOGRAM_EDGES.partition_point(|&edge| edge <= error) - 1
}

/// A bin's name: `7`, `10–19`, `100+`.
pub fn histogram_bin_name(bin: usize) -> String {
    let low = HISTOGRAM_EDGES[bin];
    match HISTOGRAM_EDGES.get(bin + 1) {
        Some(&next) if next == low + 1 => low.to_string(),
        Some(&next) => format!("{low}–{}", next - 1),
        None => format!("{low}+"),
    }
}

/// The statistics of one set of errors.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorStats {
    pub n: u64,
    pub mean: f64,
    pub std_dev: f64,
    pub std_err: f64,
    pub trimmed_mean: f64,
    pub median: f64,
    pub iqr: f64,
    /// The 95th percentile (linear interpolation).
    pub p95: f64,
    pub max: u32,
    /// Errors per bin of [`HISTOGRAM_EDGES`].
    pub histogram: [u64; HISTOGRAM_BINS],
}

/// Counts of each error value: `counts[e]` errors of `e` levels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ErrorCounts {
    counts: Vec<u64>,
}

impl ErrorCounts {
    /// Counts `errors` (the tests' way to make counts).
    #[cfg(test)]
    pub fn of(errors: impl IntoIterator<Item = u32>) -> ErrorCounts {
        let mut counts = ErrorCounts::default();
        for e in errors {
            counts.add(e, 1);
        }
        counts
    }

    /// Adds `times` errors of `error` levels.
    pub fn add(&mut self, error: u32, times: u64) {
        let e = error as usize;
        if e >= self.counts.len() {
            self.counts.resize(e + 1, 0);
        }
        self.counts[e] += times;
    }

    /// The statistics, or `None` for no errors at all.
    pub fn stats(&self) -> Option<ErrorStats> {
        let n: u64 = self.counts.iter().sum();
        if n == 0 {
            return None;
        }
        let (mut sum, mut squares) = (0u128, 0u128);
        for (e, &c) in self.counts.iter().enumerate() {
            sum += e as u128 * u128::from(c);
            squares += (e * e) as u128 * u128::from(c);
        }
        let nf = n as f64;
        // Exact: n·Σe² − (Σe)² = n(n − 1)·variance.
        let spread = u128::from(n) * squares - sum * sum;
        let std_dev = if n > 1 {
            (spread as f64 / (nf * (nf - 1.0))).sqrt()
        } else {
            f64::NAN
        };
        let cut = n / 20; // ⌊0.05·n⌋
        let trimmed = sum - self.sum_smallest(cut) - self.sum_largest(cut);
        let quantile = |q: f64| {
            let position = q * (nf - 1.0);
            let below = position.floor() as u64;
            let low = self.nth(below) as f64;
            let high = self.nth((below + 1).min(n - 1)) as f64;
            low + (high - low) * (position - below as f64)
        };
        let mut histogram = [0u64; HISTOGRAM_BINS];
        for (e, &c) in self.counts.iter().enumerate() {
            histogram[histogram_bin(e as u32)] += c;
        }
        Some(ErrorStats {
            n,
            mean: sum as f64 / nf,
            std_dev,
            std_err: std_dev / nf.sqrt(),
            trimmed_mean: trimmed as f64 / (n - 2 * cut) as f64,
            median: quantile(0.5),
            iqr: quantile(0.75) - quantile(0.25),
            p95: quantile(0.95),
            max: self.counts.iter().rposition(|&c| c > 0).unwrap_or(0) as u32,
            histogram,
        })
    }

    /// The k-th smallest error (0-based).
    fn nth(&self, k: u64) -> u32 {
        let mut seen = 0;
        for (e, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen > k {
                return e as u32;
            }
        }
        unreachable!("k = {k} is below the count {seen}")
    }

    /// The sum of the `k` smallest errors.
    fn sum_smallest(&self, k: u64) -> u128 {
        take_sum(self.counts.iter().enumerate(), k)
    }

    /// The sum of the `k` largest errors.
    fn sum_largest(&self, k: u64) -> u128 {
        take_sum(self.counts.iter().enumerate().rev(), k)
    }
}

fn take_sum<'a>(counts: impl Iterator<Item = (usize, &'a u64)>, mut k: u64) -> u128 {
    let mut sum = 0u128;
    for (e, &c) in counts {
        if k == 0 {
            break;
        }
        let take = c.min(k);
        sum += e as u128 * u128::from(take);
        k -= take;
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(errors: &[u32]) -> ErrorStats {
        ErrorCounts::of(errors.iter().copied()).stats().unwrap()
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs().max(1.0)
    }

    /// (mean, std dev, std err, 5% trimmed mean, median, IQR, max) as numpy
    /// computed them (np.mean, np.std(ddof=1), /√n, the trimmed mean of
    /// scipy's definition, np.percentile).
    fn check(errors: &[u32], expected: [f64; 7]) {
        let s = stats(errors);
        let got = [
            s.mean,
            s.std_dev,
            s.std_err,
            s.trimmed_mean,
            s.median,
            s.iqr,
            f64::from(s.max),
        ];
        for (k, (g, e)) in got.iter().zip(expected).enumerate() {
            assert!(
                close(*g, e),
                "{errors:?}: statistic {k} is {g}, numpy says {e}"
            );
        }
        assert_eq!(s.n, errors.len() as u64);
        assert_eq!(s.histogram.iter().sum::<u64>(), s.n);
    }

    #[test]
    fn statistics_match_numpy() {
        // Ties.
        check(
            &[0, 0, 1, 1, 1, 2, 5, 5],
            [
                1.875,
                2.03100960115899,
                0.7180703308172536,
                1.875,
                1.0,
                2.0,
                5.0,
            ],
        );
        // A heavy outlier: the mean moves, the robust statistics do not.
        let mut outlier = vec![0; 99];
        outlier.push(1000);
        check(&outlier, [10.0, 100.0, 10.0, 0.0, 0.0, 0.0, 1000.0]);
        // Forty values: the trim drops two from each end; quartiles
        // interpolate between order statistics.
        let forty: Vec<u32> = (0..40).map(|i| i * 7 % 11).collect();
        check(
            &forty,
            [
                5.05,
                3.257732418849116,
                0.5150927225466428,
                5.055555555555555,
                5.0,
                6.0,
                10.0,
            ],
        );
        check(
            &[1, 4],
            [
                2.5,
                2.1213203435596424,
                1.4999999999999998,
                2.5,
                2.5,
                1.5,
                4.0,
            ],
        );
    }

    #[test]
    fn one_error_and_equal_errors() {
        let one = stats(&[3]);
        assert_eq!(
            (one.mean, one.trimmed_mean, one.median, one.iqr),
            (3.0, 3.0, 3.0, 0.0)
        );
        assert!(
            one.std_dev.is_nan() && one.std_err.is_nan(),
            "undefined for n = 1"
        );
        let equal = stats(&[2; 17]);
        assert_eq!(
            (
                equal.mean,
                equal.std_dev,
                equal.trimmed_mean,
                equal.median,
                equal.iqr,
                equal.max
            ),
            (2.0, 0.0, 2.0, 2.0, 0.0, 2)
        );
        assert_eq!(ErrorCounts::default().stats(), None);
    }

    #[test]
    fn the_papers_histogram_gives_the_papers_figures() {
        // §4.5: the best variable of group a, 9000 test samples; the 76
        // errors of 10 or more lie between 10 and 151 (their exact values do
        // not matter to the trimmed mean, median or IQR).
        let mut counts = ErrorCounts::default();
        for (error, count) in [6300, 1854, 343, 185, 109, 48, 31, 12, 21, 21]
            .iter()
            .enumerate()
        {
            counts.add(error as u32, *count);
        }
        for k in 0..76 {
            counts.add(10 + k * 141 / 75, 1);
        }
        let s = counts.stats().unwrap();
        assert_eq!(s.n, 9000);
        assert_eq!(format!("{:.4}", s.trimmed_mean), "0.3332", "2699/8100");
        assert_eq!(s.trimmed_mean, 2699.0 / 8100.0);
        assert_eq!((s.median, s.iqr, s.max), (0.0, 1.0, 151));
        assert_eq!(
            s.histogram[..10],
            [6300, 1854, 343, 185, 109, 48, 31, 12, 21, 21]
        );
        // The paper's one bar of 10 or more, and its tail.
        assert_eq!(s.histogram[10..].iter().sum::<u64>(), 76);
        let tail = |low: u32, high: u32| {
            (0..76)
                .filter(|k| (low..high).contains(&(10 + k * 141 / 75)))
                .count() as u64
        };
        assert_eq!(
            s.histogram[10..],
            [tail(10, 20), tail(20, 50), tail(50, 100), tail(100, 200)]
        );
    }

    #[test]
    fn histogram_bins_cover_every_error_once() {
        let names: Vec<String> = (0..HISTOGRAM_BINS).map(histogram_bin_name).collect();
        assert_eq!(names[9..], ["9", "10–19", "20–49", "50–99", "100+"]);
        for (error, bin) in [
            (0, 0),
            (9, 9),
            (10, 10),
            (19, 10),
            (20, 11),
            (49, 11),
            (50, 12),
            (99, 12),
            (100, 13),
            (u32::MAX, 13),
        ] {
            assert_eq!(histogram_bin(error), bin, "{error}");
        }
    }
}
