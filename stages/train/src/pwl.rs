//! Training a piecewise-linear ALN ([`alnlab_aln::pwl::Tree`]) as its
//! authors describe it (shared/notes/piecewise-linear-aln.md §2–4):
//!
//! - **Responsibility.** Each sample is credited to the one piece whose
//!   value reaches the root (ties: the first child).
//! - **The update** of that piece alone: a normalised LMS step in centroid
//!   form. The piece is kept as y = c_out + Σ wᵢ(xᵢ − cᵢ): the centroid c
//!   and c_out move toward the sample, each input's variance Dᵢ about the
//!   centroid is tracked, the weights step by −α·e·(xᵢ − cᵢ)/Dᵢ within
//!   bounds, and the bias is derived from the centroid again (for numerical
//!   accuracy). `e` is the piece's error; the robust option steps by a
//!   clipped error (Huber's), since the metric is absolute error and
//!   redraws and contacts make outliers.
//! - **Growth.** After each round of epochs every piece whose error over
//!   its samples is larger than the noise allows — an F-test of its sum of
//!   squared errors against the noise of its samples, estimated from
//!   nearest-neighbour differences of the training rows (halved: a
//!   difference of two noisy values has twice the variance), or a declared
//!   tolerance — splits into a MAX or a MIN of two copies of itself: a MAX
//!   where the data lie above the piece far from its centroid (its
//!   convexity statistic below zero), else a MIN. A piece with too few
//!   samples, or one that fits, stops splitting. Growth ends when a round
//!   splits nothing or the cap on pieces is reached; final epochs at a
//!   lower rate polish the pieces.
//!
//! The copies of a split piece (the authors' [`Split::Copy`]) are tilted
//! apart by a hair along the input whose squared distance from the
//! centroid goes most with the piece's error — a V (MAX) or Λ (MIN) too
//! shallow to change any figure — so that the tie rule does not leave the
//! second copy idle (the authors' fillets break the tie the same way).
//! [`Split::Hinge`] instead fits the kink at once, robustly, on the
//! piece's residuals. Every choice is seeded or fixed: the same data and
//! seed give the same tree, bit for bit.

use alnlab_aln::pwl::Tree;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

/// How a piece that the noise does not explain is split.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Split {
    /// The authors' way: a MAX (convex) or MIN of two copies of the piece,
    /// which the LMS steps then pull apart.
    #[default]
    Copy,
    /// A hinge fitted at once: p becomes p + c·max(0, ±(xᵢ − t)) — the MAX
    /// (c > 0) or MIN (c < 0) of p and p + c·(±(xᵢ − t)) — with the input
    /// i, the knot t (a quantile of the piece's samples), the side and c
    /// that most reduce the Huber loss of the samples it answers for; one
    /// piece a round, since a hinge moves its neighbours' residuals too.
    Hinge,
}

/// How a tree is trained.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Epochs per round, between split passes.
    pub epochs_per_round: usize,
    /// Rounds at most.
    pub rounds: usize,
    /// Learning rate while growing.
    pub rate: f64,
    /// Learning rate of the final polishing epochs.
    pub polish_rate: f64,
    /// Polishing epochs after growth ends.
    pub polish_epochs: usize,
    /// Pieces at most.
    pub max_pieces: usize,
    /// The target's noise, declared (a standard deviation): a piece splits
    /// when its mean squared error exceeds its square. `None`: estimated
    /// from nearest-neighbour differences, with an F-test.
    pub tolerance: Option<f64>,
    /// The F-test's level: a piece splits when its error exceeds the noise
    /// by more than this quantile of the F distribution.
    pub confidence: f64,
    /// Huber's step: errors larger than this many noise standard
    /// deviations count as this many (`None`: plain least squares).
    pub huber: Option<f64>,
    /// Each weight is bounded by this many target spreads per input spread.
    pub weight_bound: f64,
    /// Seeds the order of samples in every epoch.
    pub seed: u64,
    /// How a piece splits.
    pub split: Split,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            epochs_per_round: 20,
            rounds: 100,
            rate: 0.2,
            polish_rate: 0.05,
            polish_epochs: 20,
            max_pieces: 256,
            tolerance: None,
            confidence: 0.75,
            huber: None,
            weight_bound: 100.0,
            seed: 0,
            split: Split::Copy,
        }
    }
}

/// What one round did: the tree's size and error after it.
#[derive(Clone, Debug, PartialEq)]
pub struct Round {
    /// Pieces after the round's splits.
    pub pieces: usize,
    /// Pieces split at its end.
    pub splits: usize,
    /// Root-mean-square error over the training rows before the splits.
    pub rms: f64,
    /// Mean absolute error likewise.
    pub mean_absolute: f64,
}

/// A piece's training state beside its coefficients.
#[derive(Clone, Debug)]
struct PieceState {
    /// The centroid of its samples' inputs, and of their targets.
    centroid: Vec<f64>,
    out: f64,
    /// Per input, the smoothed variance about the centroid.
    variance: Vec<f64>,
    /// The smoothed error of samples far from the centroid: below zero,
    /// the data lie above the piece there (convex: split into a MAX).
    convexity: f64,
    /// Its weights (the tree holds them too, with the derived bias).
    weights: Vec<f64>,
}

impl PieceState {
    /// Sets piece `p` of the tree to this state: its weights, and the bias
    /// derived from the centroid (y = c_out + Σ wᵢ(xᵢ − cᵢ)).
    fn store(&self, tree: &mut Tree, p: usize) {
        let bias = self.out
            - self
                .weights
                .iter()
                .zip(&self.centroid)
                .map(|(w, c)| w * c)
                .sum::<f64>();
        tree.set_piece(p, bias, &self.weights);
    }
}

/// Training data: `rows` samples of `inputs` numbers, and their targets.
pub struct Samples<'a> {
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub inputs: usize,
}

impl Samples<'_> {
    fn rows(&self) -> usize {
        self.y.len()
    }

    fn row(&self, r: usize) -> &[f64] {
        &self.x[r * self.inputs..(r + 1) * self.inputs]
    }
}

/// Trains a tree on the samples; returns it and what each round did.
pub fn train(samples: &Samples, settings: &Settings) -> (Tree, Vec<Round>) {
    train_from(samples, settings, None)
}

/// [`train`] from a first piece `bias + weights·x` (a fitted linear
/// model) instead of the targets' mean.
pub fn train_from(
    samples: &Samples,
    settings: &Settings,
    start: Option<(f64, &[f64])>,
) -> (Tree, Vec<Round>) {
    let n = samples.inputs;
    let rows = samples.rows();
    assert_eq!(samples.x.len(), rows * n, "x holds rows × inputs numbers");
    assert!(rows > 0, "training needs samples");
    let mean = |v: &dyn Fn(usize) -> f64| (0..rows).map(v).sum::<f64>() / rows as f64;
    let y_mean = mean(&|r| samples.y[r]);
    let y_spread = mean(&|r| (samples.y[r] - y_mean).powi(2)).sqrt().max(1e-12);
    let x_mean: Vec<f64> = (0..n).map(|i| mean(&|r| samples.row(r)[i])).collect();
    let x_variance: Vec<f64> = (0..n)
        .map(|i| mean(&|r| (samples.row(r)[i] - x_mean[i]).powi(2)).max(1e-24))
        .collect();
    // The least variance a piece tracks per input: a piece over few
    // samples must not divide by a vanishing spread.
    let floor: Vec<f64> = x_variance.iter().map(|v| v * 1e-6).collect();
    let bound: Vec<f64> = x_variance
        .iter()
        .map(|v| settings.weight_bound * y_spread / v.sqrt())
        .collect();
    let noise = match settings.tolerance {
        Some(_) => vec![0.0; rows],
        None => neighbour_noise(samples),
    };
    let noise_spread = (noise.iter().sum::<f64>() / rows as f64).sqrt().max(1e-12);
    let huber = settings.huber.map(|k| {
        k * settings
            .tolerance
            .unwrap_or(noise_spread)
            .max(1e-9 * y_spread)
    });

    let zeros = vec![0.0; n];
    let (bias, weights) = start.unwrap_or((y_mean, &zeros));
    let tree_start = Tree::affine(bias, weights);
    let out = tree_start.piece_value(0, &x_mean);
    let mut tree = tree_start;
    let mut states = vec![PieceState {
        centroid: x_mean.clone(),
        out,
        variance: x_variance.clone(),
        convexity: 0.0,
        weights: weights.to_vec(),
    }];
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let mut order: Vec<usize> = (0..rows).collect();
    let mut log = Vec::new();
    let mut epoch = |tree: &mut Tree, states: &mut [PieceState], rate: f64| {
        order.shuffle(&mut rng);
        for &r in &order {
            let x = samples.row(r);
            let (value, p) = tree.responsible(x);
            let mut e = value - samples.y[r];
            if let Some(h) = huber {
                e = e.clamp(-h, h);
            }
            adapt(
                tree,
                &mut states[p],
                p,
                x,
                samples.y[r],
                e,
                rate,
                &floor,
                &bound,
            );
        }
    };
    for _ in 0..settings.rounds {
        for _ in 0..settings.epochs_per_round {
            epoch(&mut tree, &mut states, settings.rate);
        }
        let (rms, mean_absolute, splits) =
            split_pass(&mut tree, &mut states, samples, &noise, settings, y_spread);
        log.push(Round {
            pieces: tree.pieces(),
            splits,
            rms,
            mean_absolute,
        });
        if splits == 0 {
            break;
        }
    }
    for _ in 0..settings.polish_epochs {
        epoch(&mut tree, &mut states, settings.polish_rate);
    }
    (tree, log)
}

/// One normalised LMS step of piece `p` toward a sample `(x, y)` it answers
/// for with error `e` (the piece's value − y, clipped for robustness).
#[allow(clippy::too_many_arguments)]
fn adapt(
    tree: &mut Tree,
    s: &mut PieceState,
    p: usize,
    x: &[f64],
    y: f64,
    e: f64,
    rate: f64,
    floor: &[f64],
    bound: &[f64],
) {
    let n = x.len();
    let alpha = rate / (2 * (n + 1) - 1) as f64;
    s.out += alpha * (y - s.out);
    let mut far = 0.0;
    for i in 0..n {
        let d = x[i] - s.centroid[i];
        s.variance[i] = (s.variance[i] + rate * (d * d - s.variance[i])).max(floor[i]);
        s.centroid[i] += alpha * d;
        let d = x[i] - s.centroid[i];
        s.weights[i] = (s.weights[i] - alpha * e * d / s.variance[i]).clamp(-bound[i], bound[i]);
        far += d * d / s.variance[i];
    }
    // Far from the centroid: outside the ellipse of one spread per input.
    if far >= n as f64 {
        s.convexity += rate * (e - s.convexity);
    }
    s.store(tree, p);
}

/// Evaluates every sample, splits the pieces whose error the noise does
/// not explain (the largest excess first, up to the cap on pieces), and
/// returns the RMS and mean absolute error before the splits and how many
/// pieces split.
fn split_pass(
    tree: &mut Tree,
    states: &mut Vec<PieceState>,
    samples: &Samples,
    noise: &[f64],
    settings: &Settings,
    y_spread: f64,
) -> (f64, f64, usize) {
    let n = samples.inputs;
    let pieces = tree.pieces();
    let mut count = vec![0usize; pieces];
    let mut squared = vec![0.0f64; pieces];
    let mut noise_sum = vec![0.0f64; pieces];
    // Per piece and input: Σ e·(xᵢ − cᵢ)², which input's distance goes
    // with the error (the direction to tilt the copies apart along).
    let mut spread_error = vec![0.0f64; pieces * n];
    let (mut total_squared, mut total_absolute) = (0.0, 0.0);
    // Each piece's rows and every row's residual, for hinges.
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); pieces];
    let mut residual = vec![0.0f64; samples.rows()];
    for (r, (&y, &noise)) in samples.y.iter().zip(noise).enumerate() {
        let x = samples.row(r);
        let (value, p) = tree.responsible(x);
        let e = value - y;
        members[p].push(r);
        residual[r] = -e;
        count[p] += 1;
        squared[p] += e * e;
        noise_sum[p] += noise;
        total_squared += e * e;
        total_absolute += e.abs();
        for i in 0..n {
            let d = x[i] - states[p].centroid[i];
            spread_error[p * n + i] += e * d * d / states[p].variance[i];
        }
    }
    let rows = samples.rows() as f64;
    let (rms, mean_absolute) = ((total_squared / rows).sqrt(), total_absolute / rows);
    // A piece needs more samples than coefficients to be judged.
    let least = (1.2 * (n + 1) as f64).ceil() as usize + 1;
    let mut candidates: Vec<(f64, usize)> = (0..pieces)
        .filter(|&p| count[p] > least)
        .filter_map(|p| {
            let allowed = match settings.tolerance {
                Some(t) => count[p] as f64 * t * t,
                None => {
                    let dof = (count[p] - n - 1).max(1) as f64;
                    let f = FisherSnedecor::new(dof, count[p] as f64)
                        .map(|d| d.inverse_cdf(settings.confidence))
                        .unwrap_or(f64::INFINITY);
                    noise_sum[p] * f
                }
            };
            (squared[p] > allowed).then_some((squared[p] - allowed, p))
        })
        .collect();
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let room = settings.max_pieces.saturating_sub(pieces);
    let mut splits = 0;
    // A hinge changes its neighbours' residuals too: one at a time.
    let per_round = match settings.split {
        Split::Hinge => room.min(1),
        Split::Copy => room,
    };
    for &(_, p) in candidates.iter().take(per_round) {
        let mut state = states[p].clone();
        let hinge = match settings.split {
            Split::Hinge => best_hinge(samples, &members[p], &residual),
            Split::Copy => None,
        };
        let max = match hinge {
            Some((axis, knot, slope, convex)) => {
                state.weights[axis] += slope;
                state.out += slope * (state.centroid[axis] - knot);
                convex
            }
            None => {
                // The input whose squared distance goes most with the error.
                let axis = (0..n)
                    .max_by(|&a, &b| {
                        spread_error[p * n + a]
                            .abs()
                            .total_cmp(&spread_error[p * n + b].abs())
                            .then(b.cmp(&a))
                    })
                    .unwrap_or(0);
                if n > 0 {
                    let tilt = 1e-6 * y_spread / states[p].variance[axis].sqrt();
                    states[p].weights[axis] += tilt;
                    state.weights[axis] -= tilt;
                }
                states[p].convexity < 0.0
            }
        };
        let copy = tree.split(p, max);
        states[p].convexity = 0.0;
        state.convexity = 0.0;
        states[p].store(tree, p);
        state.store(tree, copy);
        states.push(state);
        splits += 1;
    }
    (rms, mean_absolute, splits)
}

/// The hinge that most lowers the Huber loss of `rows`' residuals: per
/// input, a knot at five quantiles of the rows' values and both sides, its
/// slope by iteratively reweighted least squares (Huber's weights at 1.345
/// robust spreads of the residuals, so that torque redraws and contacts do
/// not set it). The input, the knot, the slope c·(±1) of the new piece
/// along the input and whether the hinge is convex (c > 0: a MAX); `None`
/// where no hinge lowers the loss.
fn best_hinge(
    samples: &Samples,
    rows: &[usize],
    residual: &[f64],
) -> Option<(usize, f64, f64, bool)> {
    let n = samples.inputs;
    let mut deviations: Vec<f64> = rows.iter().map(|&r| residual[r].abs()).collect();
    deviations.sort_by(f64::total_cmp);
    let spread = 1.4826 * deviations.get(deviations.len() / 2).copied().unwrap_or(0.0);
    let k = 1.345 * spread.max(1e-12);
    let huber = |e: f64| {
        if e.abs() <= k {
            e * e / 2.0
        } else {
            k * (e.abs() - k / 2.0)
        }
    };
    let before: f64 = rows.iter().map(|&r| huber(residual[r])).sum();
    let mut best: Option<(f64, usize, f64, f64, bool)> = None;
    let mut values: Vec<f64> = Vec::with_capacity(rows.len());
    for axis in 0..n {
        values.clear();
        values.extend(rows.iter().map(|&r| samples.row(r)[axis]));
        values.sort_by(f64::total_cmp);
        for q in [0.2, 0.35, 0.5, 0.65, 0.8] {
            let knot = values[((values.len() - 1) as f64 * q) as usize];
            for side in [1.0, -1.0] {
                let hinge = |r: usize| (side * (samples.row(r)[axis] - knot)).max(0.0);
                let mut c = 0.0;
                for _ in 0..4 {
                    let (mut rh, mut hh) = (0.0, 0.0);
                    for &r in rows {
                        let (h, e) = (hinge(r), residual[r] - c * hinge(r));
                        let w = if e.abs() <= k { 1.0 } else { k / e.abs() };
                        rh += w * residual[r] * h;
                        hh += w * h * h;
                    }
                    if hh <= 0.0 {
                        break;
                    }
                    c = rh / hh;
                }
                let gain = before
                    - rows
                        .iter()
                        .map(|&r| huber(residual[r] - c * hinge(r)))
                        .sum::<f64>();
                if c != 0.0 && gain > 0.0 && best.is_none_or(|(g, ..)| gain > g) {
                    best = Some((gain, axis, knot, side * c, c > 0.0));
                }
            }
        }
    }
    best.map(|(_, axis, knot, slope, convex)| (axis, knot, slope, convex))
}

/// Per row, half the squared difference of its target and its nearest
/// neighbour's (L1 distance over the inputs; ties: the lower row): an
/// estimate of the target's noise variance there that needs no model.
pub fn neighbour_noise(samples: &Samples) -> Vec<f64> {
    let rows = samples.rows();
    (0..rows)
        .into_par_iter()
        .map(|r| {
            let x = samples.row(r);
            let mut best = (f64::INFINITY, usize::MAX);
            for other in (0..rows).filter(|&o| o != r) {
                let distance: f64 = x
                    .iter()
                    .zip(samples.row(other))
                    .map(|(a, b)| (a - b).abs())
                    .sum();
                if distance < best.0 {
                    best = (distance, other);
                }
            }
            match best.1 {
                usize::MAX => 0.0,
                o => (samples.y[r] - samples.y[o]).powi(2) / 2.0,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;

    /// `rows` points uniform in [−1, 1]^inputs, and f at each plus noise.
    fn data(
        rows: usize,
        inputs: usize,
        noise: f64,
        seed: u64,
        f: impl Fn(&[f64]) -> f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x: Vec<f64> = (0..rows * inputs)
            .map(|_| rng.random::<f64>() * 2.0 - 1.0)
            .collect();
        let y = x
            .chunks_exact(inputs)
            .map(|row| f(row) + noise * (rng.random::<f64>() * 2.0 - 1.0) * 3f64.sqrt())
            .collect();
        (x, y)
    }

    /// A tree trained on `rows` samples of `f` (from [`data`]), with the
    /// samples.
    fn fitted(
        (rows, inputs, noise, seed): (usize, usize, f64, u64),
        f: impl Fn(&[f64]) -> f64,
        settings: &Settings,
    ) -> (Tree, Vec<Round>, Vec<f64>, Vec<f64>) {
        let (x, y) = data(rows, inputs, noise, seed, f);
        let samples = Samples {
            x: &x,
            y: &y,
            inputs,
        };
        let (tree, log) = train(&samples, settings);
        (tree, log, x, y)
    }

    fn rms(tree: &Tree, x: &[f64], y: &[f64], inputs: usize) -> f64 {
        let sum: f64 = x
            .chunks_exact(inputs)
            .zip(y)
            .map(|(row, t)| (tree.value(row) - t).powi(2))
            .sum();
        (sum / y.len() as f64).sqrt()
    }

    #[test]
    fn learns_a_min_of_maxes_of_planes() {
        // min(max(x + y, 1 − 2x), max(0.5 − y, 2x − 1)): spread about 1.
        let f = |v: &[f64]| {
            let (x, y) = (v[0], v[1]);
            (x + y).max(1.0 - 2.0 * x).min((0.5 - y).max(2.0 * x - 1.0))
        };
        let settings = Settings {
            tolerance: Some(0.01),
            ..Settings::default()
        };
        let (tree, log, _, _) = fitted((2000, 2, 0.0, 1), f, &settings);
        let (tx, ty) = data(1000, 2, 0.0, 2, f);
        let error = rms(&tree, &tx, &ty, 2);
        assert!(
            error < 0.03,
            "held-out RMS {error} with {} pieces; rounds {log:?}",
            tree.pieces()
        );
    }

    #[test]
    fn a_convex_target_grows_max_nodes_only() {
        // |x| + |y|/2 + x²: convex.
        let f = |v: &[f64]| v[0].abs() + v[1].abs() / 2.0 + v[0] * v[0];
        let settings = Settings {
            tolerance: Some(0.02),
            ..Settings::default()
        };
        let (tree, _, x, y) = fitted((2000, 2, 0.0, 3), f, &settings);
        let (mins, maxes) = tree.operators();
        assert!(maxes >= 3, "{maxes} MAX nodes");
        assert_eq!(mins, 0, "{mins} MIN nodes beside {maxes} MAX");
        assert!(rms(&tree, &x, &y, 2) < 0.05);
    }

    #[test]
    fn on_pure_noise_growth_stops_by_the_f_test() {
        let (tree, log, _, _) = fitted((1000, 3, 0.5, 4), |_| 0.0, &Settings::default());
        assert!(
            tree.pieces() <= 2,
            "{} pieces on noise: {log:?}",
            tree.pieces()
        );
        // A linear target under the same noise: one piece, fitted.
        let plane = |v: &[f64]| 2.0 * v[0] - v[2];
        let (tree, _, _, _) = fitted((1000, 3, 0.5, 5), plane, &Settings::default());
        assert!(tree.pieces() <= 2, "{} pieces on a plane", tree.pieces());
        let (_, w) = tree.piece(0);
        assert!(
            (w[0] - 2.0).abs() < 0.2 && (w[2] + 1.0).abs() < 0.2,
            "{w:?}"
        );
    }

    #[test]
    fn a_fitted_plane_as_the_first_piece_stays_one_piece() {
        let (x, y) = data(800, 3, 0.3, 8, |v| 1.5 * v[0] - 0.5 * v[1] + 0.25);
        let samples = Samples {
            x: &x,
            y: &y,
            inputs: 3,
        };
        let (tree, log) = train_from(
            &samples,
            &Settings::default(),
            Some((0.25, &[1.5, -0.5, 0.0])),
        );
        assert_eq!(tree.pieces(), 1, "{log:?}");
        let (bias, w) = tree.piece(0);
        assert!(
            (bias - 0.25).abs() < 0.1 && (w[0] - 1.5).abs() < 0.15,
            "{bias} {w:?}"
        );
    }

    #[test]
    fn a_hinge_split_finds_a_kink_at_once() {
        let settings = Settings {
            tolerance: Some(0.005),
            split: Split::Hinge,
            ..Settings::default()
        };
        // Convex kinks opening to either side, and a concave one; the
        // second input does not matter.
        type Target = fn(&[f64]) -> f64;
        let kinks: [(Target, bool); 3] = [
            (|v| 0.5 * v[0] + (2.0 * (v[0] - 0.3)).max(0.0), true),
            (|v| 0.5 * v[0] + (-1.5 * (v[0] + 0.2)).max(0.0), true),
            (|v| 0.5 * v[0] - (2.0 * (v[0] - 0.1)).max(0.0), false),
        ];
        for (k, (f, convex)) in kinks.into_iter().enumerate() {
            let (tree, log, _, _) = fitted((2000, 2, 0.0, 9 + k as u64), f, &settings);
            let (tx, ty) = data(1000, 2, 0.0, 20 + k as u64, f);
            let error = rms(&tree, &tx, &ty, 2);
            assert!(error < 0.01, "kink {k}: RMS {error}: {log:?}");
            let (mins, maxes) = tree.operators();
            let wrong = if convex { mins } else { maxes };
            assert_eq!(wrong, 0, "kink {k}: {mins} MIN, {maxes} MAX");
            assert!(tree.pieces() <= 4, "kink {k}: {} pieces", tree.pieces());
        }
    }

    #[test]
    fn the_noise_estimate_is_the_noise_variance() {
        // A smooth target under uniform noise of spread 0.1: the halved
        // squared neighbour differences average about 0.01.
        let (x, y) = data(2000, 2, 0.1, 6, |v| v[0] + v[1]);
        let samples = Samples {
            x: &x,
            y: &y,
            inputs: 2,
        };
        let noise = neighbour_noise(&samples);
        let mean = noise.iter().sum::<f64>() / noise.len() as f64;
        assert!((mean - 0.01).abs() < 0.002, "{mean}");
    }

    #[test]
    fn the_same_seed_gives_the_same_tree_on_any_thread_count() {
        let f = |v: &[f64]| (v[0] - v[1]).abs() + v[2];
        let (x, y) = data(600, 3, 0.05, 7, f);
        let samples = Samples {
            x: &x,
            y: &y,
            inputs: 3,
        };
        let settings = Settings {
            seed: 11,
            ..Settings::default()
        };
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| train(&samples, &settings).0);
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| train(&samples, &settings).0);
        assert_eq!(one, two);
        assert!(one.pieces() > 1);
    }
}
