//! Per-variable statistics over all frames (paper §4.2), by Welford's
//! numerically stable running update.

use std::path::Path;

use alnlab_common::{Provenance, Result};
use alnlab_tables::stats::Row;

#[derive(Clone, Copy, Debug)]
struct Running {
    n: u64,
    mean: f64,
    m2: f64,
    min: f64,
    max: f64,
}

impl Running {
    fn new() -> Self {
        Running {
            n: 0,
            mean: 0.0,
            m2: 0.0,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
        }
    }

    fn add(&mut self, x: f64) {
        self.n += 1;
        let delta = x - self.mean;
        self.mean += delta / self.n as f64;
        self.m2 += delta * (x - self.mean);
        self.min = self.min.min(x);
        self.max = self.max.max(x);
    }

    /// Sample standard deviation (n − 1); 0 for fewer than two values.
    fn std(&self) -> f64 {
        if self.n < 2 {
            0.0
        } else {
            (self.m2 / (self.n - 1) as f64).sqrt()
        }
    }
}

/// Running statistics per variable name, in first-seen order.
#[derive(Default)]
pub struct VariableStats {
    names: Vec<String>,
    running: Vec<Running>,
}

impl VariableStats {
    /// Adds one frame's values of the variables `names`.
    pub fn add(&mut self, names: &[String], values: &[f64]) {
        for (name, &x) in names.iter().zip(values) {
            let i = match self.names.iter().position(|n| n == name) {
                Some(i) => i,
                None => {
                    self.names.push(name.clone());
                    self.running.push(Running::new());
                    self.running.len() - 1
                }
            };
            self.running[i].add(x);
        }
    }

    /// Writes `stats.parquet` ([`alnlab_tables::stats`]).
    pub fn write(&self, path: &Path, provenance: &Provenance) -> Result<()> {
        let rows: Vec<Row> = self
            .names
            .iter()
            .zip(&self.running)
            .map(|(name, r)| Row {
                variable: name.clone(),
                n: r.n,
                min: r.min,
                max: r.max,
                mean: r.mean,
                std: r.std(),
            })
            .collect();
        alnlab_tables::stats::write(path, &rows, provenance)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welford_matches_two_pass_on_offset_data() {
        // A large offset defeats the naive sum-of-squares formula.
        // The reference works on the offsets, which are exact in f64.
        let offsets: Vec<f64> = (0..10_000).map(|i| (i % 7) as f64 * 0.5).collect();
        let mut r = Running::new();
        offsets.iter().for_each(|&d| r.add(1e9 + d));
        let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
        let var =
            offsets.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (offsets.len() - 1) as f64;
        assert!((r.mean - (1e9 + mean)).abs() < 1e-3, "1e-12 relative");
        assert!(
            (r.std() - var.sqrt()).abs() < 1e-9,
            "{} vs {}",
            r.std(),
            var.sqrt()
        );
        assert_eq!((r.min, r.max), (1e9, 1e9 + 3.0));
    }
}
