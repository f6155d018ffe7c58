//! Paired comparisons: two models' errors on the same rows, as the mean of
//! their differences with a 95% confidence interval, and the verdict the
//! interval allows.
//!
//! The interval is Student's t: mean ± t(0.975, n − 1) · s / √n, with s the
//! sample standard deviation (n − 1) of the differences — what
//! `scipy.stats.t.interval(0.95, n - 1, loc=mean, scale=s / sqrt(n))` gives.
//! It treats the differences as independent. Rows of one trajectory are
//! not quite (neighbouring frames move together), so a per-row interval is
//! on the narrow side; across replicates, each a new simulation, the
//! differences are independent.
//!
//! A verdict word is earned only by an interval that excludes zero: "lower"
//! or "higher"; an interval that contains zero is "indistinguishable", and
//! differences that are all exactly zero are "tied".

use statrs::distribution::{ContinuousCDF, StudentsT};

/// The confidence of every interval.
pub const CONFIDENCE: f64 = 0.95;

/// The mean of paired differences (A − B) with its confidence interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    pub n: u64,
    pub mean: f64,
    /// Sample standard deviation of the differences (NaN for n = 1).
    pub std_dev: f64,
    pub low: f64,
    pub high: f64,
}

/// What an interval of A − B says of A against B.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// A's values are lower: the whole interval is below zero.
    Lower,
    /// A's values are higher: the whole interval is above zero.
    Higher,
    /// The interval contains zero.
    Indistinguishable,
    /// Every difference is exactly zero.
    Tied,
}

impl Verdict {
    /// The verdict's name in `comparisons.parquet`.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Lower => "lower",
            Verdict::Higher => "higher",
            Verdict::Indistinguishable => "indistinguishable",
            Verdict::Tied => "tied",
        }
    }
}

impl Interval {
    /// The t-interval of the mean of `values`; `None` for no values. With
    /// one value the interval is unbounded.
    pub fn of(values: &[f64]) -> Option<Interval> {
        if values.is_empty() {
            return None;
        }
        let n = values.len();
        let mean = values.iter().sum::<f64>() / n as f64;
        if n == 1 {
            return Some(Interval {
                n: 1,
                mean,
                std_dev: f64::NAN,
                low: f64::NEG_INFINITY,
                high: f64::INFINITY,
            });
        }
        let squares: f64 = values.iter().map(|x| (x - mean) * (x - mean)).sum();
        let std_dev = (squares / (n - 1) as f64).sqrt();
        let half = t_quantile(n - 1) * std_dev / (n as f64).sqrt();
        Some(Interval {
            n: n as u64,
            mean,
            std_dev,
            low: mean - half,
            high: mean + half,
        })
    }

    /// What the interval says of A against B.
    pub fn verdict(&self) -> Verdict {
        if self.mean == 0.0 && self.std_dev == 0.0 {
            Verdict::Tied
        } else if self.high < 0.0 {
            Verdict::Lower
        } else if self.low > 0.0 {
            Verdict::Higher
        } else {
            Verdict::Indistinguishable
        }
    }
}

/// The two-sided [`CONFIDENCE`] quantile of Student's t with `df` degrees
/// of freedom.
fn t_quantile(df: usize) -> f64 {
    StudentsT::new(0.0, 1.0, df as f64)
        .expect("df ≥ 1")
        .inverse_cdf(0.5 + CONFIDENCE / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_quantiles_are_students() {
        // scipy.stats.t.ppf(0.975, df) for df = 1, 4, 30, 1000.
        for (df, q) in [
            (1, 12.706204736174698),
            (4, 2.7764451051977934),
            (30, 2.0422724563012373),
            (1000, 1.9623390808264078),
        ] {
            assert!(
                (t_quantile(df) - q).abs() < 1e-9,
                "df {df}: {}",
                t_quantile(df)
            );
        }
    }

    #[test]
    fn intervals_and_verdicts() {
        // Differences 1, 2, 3: mean 2, s = 1, half-width t(2)·1/√3.
        let i = Interval::of(&[1.0, 2.0, 3.0]).unwrap();
        assert_eq!((i.n, i.mean, i.std_dev), (3, 2.0, 1.0));
        let half = 4.302652729749464 / 3f64.sqrt();
        assert!((i.low - (2.0 - half)).abs() < 1e-9 && (i.high - (2.0 + half)).abs() < 1e-9);
        assert_eq!(i.verdict(), Verdict::Indistinguishable, "contains 0");
        let higher = Interval::of(&[1.0, 1.1, 0.9, 1.0]).unwrap();
        assert_eq!(higher.verdict(), Verdict::Higher);
        let lower = Interval::of(&[-1.0, -1.1, -0.9, -1.0]).unwrap();
        assert_eq!(lower.verdict(), Verdict::Lower);
        assert_eq!(Interval::of(&[0.0; 5]).unwrap().verdict(), Verdict::Tied);
        // A constant nonzero difference is certain.
        assert_eq!(Interval::of(&[-2.0; 4]).unwrap().verdict(), Verdict::Lower);
        let one = Interval::of(&[5.0]).unwrap();
        assert_eq!(
            one.verdict(),
            Verdict::Indistinguishable,
            "one value proves nothing"
        );
        assert!(Interval::of(&[]).is_none());
    }
}
