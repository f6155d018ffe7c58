//! The learned peer: gradient-boosted regression trees, what a practitioner
//! would try first, trained here on the same training rows and target as
//! the piecewise-linear model — each predicted variable's change in level
//! spacings, from every learned variable's current real value — and scored
//! and timed like every model.
//!
//! The trees come from the `gbdt` crate (gbdt-rs): pure Rust, and the one
//! crate that fits with the least-absolute-deviation loss the metric calls
//! for (`forust-ml` fits squared loss only and scored 1.35 levels against
//! its 1.20 on the configuration-choosing data; `perpetual` needs a nightly
//! compiler). One thread, no sampling: deterministic.

use alnlab_aln::pwl::predict::{advance, change};
use alnlab_codes::Entry;
use gbdt::config::Config;
use gbdt::decision_tree::{Data, DataVec};
use gbdt::gradient_boost::GBDT;

/// Boosting rounds, tree depth, shrinkage and least rows in a leaf: a
/// common starting point (scikit-learn's histogram booster's learning rate
/// and depth), checked on seed 7's data as the piecewise-linear model's
/// configuration was.
const ITERATIONS: usize = 300;
const DEPTH: u32 = 4;
const SHRINKAGE: f32 = 0.05;
const LEAF_ROWS: usize = 20;

/// One model per predicted variable.
pub struct Peer {
    models: Vec<GBDT>,
    /// The predicted variables' indices among the learned ones.
    variables: Vec<usize>,
}

/// The rows `rows` of `x` (`[variable][row]`) as the crate's samples.
fn samples(x: &[Vec<f64>], rows: &[usize], labels: Option<&[f64]>) -> DataVec {
    rows.iter()
        .enumerate()
        .map(|(k, &r)| {
            let feature = x.iter().map(|c| c[r] as f32).collect();
            match labels {
                Some(y) => Data::new_training_data(feature, 1.0, y[k] as f32, None),
                None => Data::new_test_data(feature, None),
            }
        })
        .collect()
}

impl Peer {
    /// Fits one model per variable of `variables` on the training `rows`
    /// of the current and next real values `x`, `y` (`[variable][row]`):
    /// the change from `base` (`x` itself, or another model's prediction
    /// for a hybrid) to `y`.
    pub fn fit(
        learned: &[&Entry],
        variables: &[usize],
        x: &[Vec<f64>],
        base: &[Vec<f64>],
        y: &[Vec<f64>],
        rows: &[usize],
    ) -> Peer {
        let models = variables
            .iter()
            .map(|&v| {
                let target: Vec<f64> = rows
                    .iter()
                    .map(|&r| change(learned[v], base[v][r], y[v][r]))
                    .collect();
                let mut data = samples(x, rows, Some(&target));
                let mut config = Config::new();
                config.set_feature_size(x.len());
                config.set_max_depth(DEPTH);
                config.set_iterations(ITERATIONS);
                config.set_shrinkage(SHRINKAGE);
                config.set_min_leaf_size(LEAF_ROWS);
                config.set_loss("LAD");
                let mut model = GBDT::new(&config);
                model.fit(&mut data);
                model
            })
            .collect();
        Peer {
            models,
            variables: variables.to_vec(),
        }
    }

    /// The next real values `[output][row]` of the states `rows` of `x`,
    /// each advanced from its value in `base` (as fitted).
    pub fn next_values(
        &self,
        learned: &[&Entry],
        x: &[Vec<f64>],
        base: &[Vec<f64>],
        rows: &[usize],
    ) -> Vec<Vec<f64>> {
        let data = samples(x, rows, None);
        self.models
            .iter()
            .zip(&self.variables)
            .map(|(model, &v)| {
                model
                    .predict(&data)
                    .iter()
                    .zip(rows)
                    .map(|(&d, &r)| advance(learned[v], base[v][r], f64::from(d)))
                    .collect()
            })
            .collect()
    }

    /// The next levels `[output][row]` of the states `rows` of `x`, each
    /// advanced from its value in `base`.
    pub fn levels(
        &self,
        learned: &[&Entry],
        x: &[Vec<f64>],
        base: &[Vec<f64>],
        rows: &[usize],
    ) -> Vec<Vec<u16>> {
        self.next_values(learned, x, base, rows)
            .iter()
            .zip(&self.variables)
            .map(|(values, &v)| {
                values
                    .iter()
                    .map(|&n| learned[v].quantizer.level(n).0)
                    .collect()
            })
            .collect()
    }
}
