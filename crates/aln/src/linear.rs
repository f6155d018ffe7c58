//! Linear baselines (docs/design.md §6). [`Linear`]: least squares from all
//! current levels to each next level, fitted on the training rows, then
//! rounded and clamped to the levels — the first form, kept labelled. And
//! [`least_absolute`], the fit of the strongest fair form: a variable's
//! *change* from real inputs by least absolute deviations, which the test
//! stage's robust linear baseline uses and which a piecewise-linear tree
//! starts from. (The other baseline, persistence, needs no model: the next
//! level is the current one.)

use nalgebra::{DMatrix, DVector};

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

/// Reweightings of [`least_absolute`]: enough for the sum of absolute
/// errors to settle to a few digits on the data of the experiments.
const REWEIGHTINGS: usize = 40;

/// The affine map `bias + weights·x` of least absolute deviations from the
/// rows of `x` (`inputs` numbers a row) to `y`, by iteratively reweighted
/// least squares (each row weighted by 1/√|its last residual|, residuals
/// floored at a millionth of y's spread) over inputs standardized
/// internally; SVD solves, so collinear and constant inputs are fine.
/// Returns the bias and weights for the inputs as given.
pub fn least_absolute(x: &[f64], y: &[f64], inputs: usize) -> (f64, Vec<f64>) {
    let rows = y.len();
    assert_eq!(x.len(), rows * inputs, "x holds rows × inputs numbers");
    let mean = |f: &dyn Fn(usize) -> f64| (0..rows).map(f).sum::<f64>() / rows.max(1) as f64;
    let centre: Vec<f64> = (0..inputs).map(|i| mean(&|r| x[r * inputs + i])).collect();
    let scale: Vec<f64> = (0..inputs)
        .map(|i| {
            let v = mean(&|r| (x[r * inputs + i] - centre[i]).powi(2)).sqrt();
            if v > 0.0 { v } else { 1.0 }
        })
        .collect();
    let y_mean = mean(&|r| y[r]);
    let floor = 1e-6 * mean(&|r| (y[r] - y_mean).powi(2)).sqrt().max(1e-12);
    let design = DMatrix::from_fn(rows, inputs + 1, |r, c| {
        if c == 0 {
            1.0
        } else {
            (x[r * inputs + c - 1] - centre[c - 1]) / scale[c - 1]
        }
    });
    let target = DVector::from_column_slice(y);
    let mut weight = DVector::from_element(rows, 1.0);
    let mut beta = DVector::zeros(inputs + 1);
    for _ in 0..REWEIGHTINGS {
        let weighted = DMatrix::from_fn(rows, inputs + 1, |r, c| design[(r, c)] * weight[r]);
        let weighted_target = target.component_mul(&weight);
        beta = least_squares(weighted, weighted_target);
        let residual = &target - &design * &beta;
        weight = residual.map(|e| 1.0 / e.abs().max(floor).sqrt());
    }
    let weights: Vec<f64> = (0..inputs).map(|i| beta[i + 1] / scale[i]).collect();
    let bias = beta[0] - weights.iter().zip(&centre).map(|(w, c)| w * c).sum::<f64>();
    (bias, weights)
}

/// Singular values below this are taken as zero: the minimum-norm solution
/// over the rest.
const SINGULAR: f64 = 1e-9;

/// The least-squares solution of `a·β ≈ b` of least norm: Householder QR of
/// `a`, then the SVD of its small triangle R, whose singular values are
/// `a`'s — the answer of an SVD of `a` itself (collinear and constant
/// columns included) for a fraction of the work, as R has only as many rows
/// as `a` has columns.
fn least_squares(a: DMatrix<f64>, b: DVector<f64>) -> DVector<f64> {
    let columns = a.ncols();
    if a.nrows() < columns {
        return a
            .svd(true, true)
            .solve(&b, SINGULAR)
            .expect("the SVD was computed with both factors");
    }
    let qr = a.qr();
    let mut projected = b;
    qr.q_tr_mul(&mut projected);
    qr.r()
        .svd(true, true)
        .solve(&projected.rows(0, columns), SINGULAR)
        .expect("the SVD was computed with both factors")
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

    #[test]
    fn least_absolute_deviations_ignore_gross_outliers() {
        // y = 3 + 2·x0 − 0.5·x1 on 200 rows, 20 of them thrown far off: the
        // least-squares fit moves, the least-absolute one does not.
        let rows = 200;
        let x: Vec<f64> = (0..rows)
            .flat_map(|r| [(r % 17) as f64 * 10.0, ((r * 7) % 13) as f64 - 6.0])
            .collect();
        let y: Vec<f64> = (0..rows)
            .map(|r| {
                let clean = 3.0 + 2.0 * x[2 * r] - 0.5 * x[2 * r + 1];
                if r % 10 == 3 { clean + 500.0 } else { clean }
            })
            .collect();
        let (bias, weights) = least_absolute(&x, &y, 2);
        assert!((bias - 3.0).abs() < 1e-3, "{bias}");
        assert!(
            (weights[0] - 2.0).abs() < 1e-4 && (weights[1] + 0.5).abs() < 1e-3,
            "{weights:?}"
        );
        // A constant input gets no weight and breaks nothing.
        let with_constant: Vec<f64> = x.chunks(2).flat_map(|c| [c[0], 4.0, c[1]]).collect();
        let (bias, weights) = least_absolute(&with_constant, &y, 3);
        assert!(
            (bias - 3.0).abs() < 1e-3 && weights[1].abs() < 1e-9,
            "{bias} {weights:?}"
        );
    }

    #[test]
    fn least_squares_through_qr_is_the_full_svd_solution() {
        // 300 rows; columns: a constant, two inputs, their sum (collinear),
        // and a column of zeros — rank 3 of 5.
        let rows = 300;
        let a = DMatrix::from_fn(rows, 5, |r, c| {
            let (u, v) = (((r * 37) % 101) as f64 / 7.0, ((r * 11) % 53) as f64 - 20.0);
            [1.0, u, v, u + v, 0.0][c]
        });
        let b = DVector::from_fn(rows, |r, _| ((r * 13) % 29) as f64 - 0.5 * r as f64);
        let full = a
            .clone()
            .svd(true, true)
            .solve(&b, SINGULAR)
            .expect("both factors");
        let fast = least_squares(a.clone(), b.clone());
        assert!((&fast - &full).amax() < 1e-10, "{fast} against {full}");
        // Fewer rows than columns: the full SVD's answer itself.
        let wide = a.rows(0, 3).into_owned();
        let short = b.rows(0, 3).into_owned();
        assert_eq!(
            least_squares(wide.clone(), short.clone()),
            wide.svd(true, true)
                .solve(&short, SINGULAR)
                .expect("both factors")
        );
    }
}
