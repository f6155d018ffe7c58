//! The Wilcoxon signed-rank test of paired differences, two-sided: whether
//! their median is zero, without assuming they are normal — the companion
//! of the mean's t-interval for heavy-tailed costs. Computed as
//! `scipy.stats.wilcoxon` computes it by default (zeros dropped, no
//! continuity correction): the exact null distribution of R+ for at most 50
//! differences of which no two |differences| tie and none is zero, else the
//! normal approximation with the tie-corrected variance (scipy permutes
//! instead when there are 13 or fewer differences with ties or zeros).

use statrs::distribution::{ContinuousCDF, Normal};

/// The most differences whose p-value is exact (scipy's `auto` rule).
const EXACT_MOST: usize = 50;

/// A signed-rank test's outcome.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignedRank {
    /// min(R+, R−): the smaller sum of the ranks of |d| by sign.
    pub statistic: f64,
    /// The two-sided p-value.
    pub p: f64,
    /// The nonzero differences tested.
    pub n: usize,
    /// Whether `p` is from the exact null distribution.
    pub exact: bool,
}

/// The test of `differences`; `None` when none is nonzero (or one is not a
/// number).
pub fn test(differences: &[f64]) -> Option<SignedRank> {
    if differences.iter().any(|d| d.is_nan()) {
        return None;
    }
    let mut nonzero: Vec<f64> = differences.iter().copied().filter(|&d| d != 0.0).collect();
    let n = nonzero.len();
    if n == 0 {
        return None;
    }
    nonzero.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Average ranks of |d|, and the sizes of tied groups.
    let (mut r_plus, mut r_minus, mut ties) = (0.0, 0.0, 0.0);
    let mut start = 0;
    while start < n {
        let mut end = start + 1;
        while end < n && nonzero[end].abs() == nonzero[start].abs() {
            end += 1;
        }
        let rank = (start + end + 1) as f64 / 2.0;
        for &d in &nonzero[start..end] {
            if d > 0.0 {
                r_plus += rank;
            } else {
                r_minus += rank;
            }
        }
        let t = (end - start) as f64;
        ties += t * t * t - t;
        start = end;
    }
    let zeros = n < differences.len();
    let exact = ties == 0.0 && !zeros && differences.len() <= EXACT_MOST;
    let count = n as f64;
    let p = if exact {
        // R+ is an integer; its null distribution by adding one rank at a
        // time, each with probability ½ of counting.
        let top = n * (n + 1) / 2;
        let mut pmf = vec![0.0; top + 1];
        pmf[0] = 1.0;
        for k in 1..=n {
            for w in (0..=k * (k + 1) / 2).rev() {
                let with = if w >= k { pmf[w - k] } else { 0.0 };
                pmf[w] = (pmf[w] + with) / 2.0;
            }
        }
        let k = r_plus as usize;
        let below: f64 = pmf[..=k].iter().sum();
        let above: f64 = pmf[k..].iter().sum();
        (2.0 * below.min(above)).min(1.0)
    } else {
        let mean = count * (count + 1.0) / 4.0;
        let se = ((count * (count + 1.0) * (2.0 * count + 1.0) - ties / 2.0) / 24.0).sqrt();
        if se == 0.0 {
            1.0
        } else {
            let z = (r_plus - mean) / se;
            let normal = Normal::new(0.0, 1.0).expect("the standard normal");
            2.0 * normal.cdf(-z.abs())
        }
    };
    Some(SignedRank {
        statistic: r_plus.min(r_minus),
        p,
        n,
        exact,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each case's statistic and p-value from `scipy.stats.wilcoxon(d)`
    /// (scipy 1.17, defaults), computed independently.
    #[test]
    fn the_test_is_scipys() {
        // ±1 … ±60, every third negative.
        let sixty: Vec<f64> = (0..60)
            .map(|i| f64::from(i + 1) * if i % 3 == 0 { -1.0 } else { 1.0 })
            .collect();
        let cases: &[(&[f64], f64, f64, bool)] = &[
            // Exact: no ties, no zeros.
            (
                &[1.5, -0.3, 2.2, 0.7, -1.1, 3.4, 0.9, 1.8, -0.2, 2.6],
                SCIPY[0].0,
                SCIPY[0].1,
                true,
            ),
            (
                &[0.5, 1.0, 1.5, 2.0, 2.5, 3.0],
                SCIPY[1].0,
                SCIPY[1].1,
                true,
            ),
            // More than 50, none tied: the normal approximation.
            (&sixty, SCIPY[3].0, SCIPY[3].1, false),
            // Ties and a zero: the normal approximation (n > 13).
            (
                &[
                    1.0, -1.0, 2.0, 2.0, -3.0, 0.0, 4.0, 4.0, 4.0, 5.0, -6.0, 7.0, 8.0, 8.0, 9.0,
                    10.0,
                ],
                SCIPY[2].0,
                SCIPY[2].1,
                false,
            ),
        ];
        for (d, statistic, p, exact) in cases {
            let t = test(d).unwrap();
            assert_eq!(t.exact, *exact, "{d:?}");
            assert_eq!(t.statistic, *statistic, "{d:?}");
            // The normal tail by statrs' erfc agrees with scipy's ndtr to
            // about 1e-11 relative.
            assert!(
                (t.p - p).abs() <= 1e-9 * p,
                "{d:?}: p {} against scipy's {p}",
                t.p
            );
        }
        assert_eq!(test(&[0.0, 0.0]), None);
        assert_eq!(test(&[1.0, f64::NAN]), None);
    }

    /// scipy's (statistic, p) for the cases above.
    const SCIPY: [(f64, f64); 4] = [
        (8.0, 0.048828125),
        (0.0, 0.03125),
        (16.5, 0.013356177488691993),
        (590.0, 0.016733071607703435),
    ];
}
