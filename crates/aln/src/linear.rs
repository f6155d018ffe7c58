//! The linear baseline (DESIGN.md §6): least squares from all current
//! levels to each next level, fitted on the training rows, then rounded and
//! clamped to the levels. (The other baseline, persistence, needs no model:
//! the next level is the current one.)

use nalgebra::DMatrix;

/// A linear map from the current levels of all variables (and a constant)
/// to the next level of each.
pub struct Linear {
    /// (1 + inputs) × outputs coefficients.
    coefficients: DMatrix<f64>,
}

impl Linear {
    /// Fits by least squares (SVD, so collinear inputs are fine): `x[i]` and
    /// `y[j]` are input and output level columns over the same rows.
    pub fn fit(x: &[Vec<u16>], y: &[Vec<u16>]) -> Linear {
        let rows = x.first().map_or(0, Vec::len);
        let design = DMatrix::from_fn(rows, x.len() + 1, |r, c| {
            if c == 0 { 1.0 } else { f64::from(x[c - 1][r]) }
        });
        let targets = DMatrix::from_fn(rows, y.len(), |r, c| f64::from(y[c][r]));
        let coefficients = design
            .svd(true, true)
            .solve(&targets, 1e-9)
            .expect("the SVD was computed with both factors");
        Linear { coefficients }
    }

    /// The predicted level of every output for one row of input levels,
    /// rounded and clamped to `0..levels[j]`.
    pub fn predict(&self, x: &[u16], levels: &[usize], out: &mut [u16]) {
        for (j, value) in out.iter_mut().enumerate() {
            let column = self.coefficients.column(j);
            let mut sum = column[0];
            for (i, &level) in x.iter().enumerate() {
                sum += column[i + 1] * f64::from(level);
            }
            *value = sum.round().clamp(0.0, (levels[j] - 1) as f64) as u16;
        }
    }

    /// The predicted levels `[variable][row]` for the current levels `x`
    /// (`[variable][row]`), one row at a time.
    pub fn levels(&self, x: &[Vec<u16>], levels: &[usize]) -> Vec<Vec<u16>> {
        let rows = x.first().map_or(0, Vec::len);
        let mut out = vec![Vec::with_capacity(rows); x.len()];
        let (mut row, mut predicted) = (vec![0u16; x.len()], vec![0u16; x.len()]);
        for r in 0..rows {
            for (v, column) in x.iter().enumerate() {
                row[v] = column[r];
            }
            self.predict(&row, levels, &mut predicted);
            for (v, &p) in predicted.iter().enumerate() {
                out[v].push(p);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_linear_map_and_clamps() {
        // y0 = 2·x0 − x1 + 20, y1 = x1 (x2 a copy of x0: collinear).
        let x0: Vec<u16> = (0..50).map(|i| (i * 7 % 23) as u16).collect();
        let x1: Vec<u16> = (0..50).map(|i| (i * 5 % 17) as u16).collect();
        let y0: Vec<u16> = x0.iter().zip(&x1).map(|(&a, &b)| 2 * a + 20 - b).collect();
        let linear = Linear::fit(&[x0.clone(), x1.clone(), x0], &[y0, x1]);
        let mut out = [0u16; 2];
        linear.predict(&[10, 4, 10], &[100, 100], &mut out);
        assert_eq!(out, [36, 4]);
        linear.predict(&[10, 4, 10], &[12, 3], &mut out);
        assert_eq!(out, [11, 2], "clamped to the last level");
    }
}
