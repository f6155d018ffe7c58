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

use alnlab_aln::boosted::{Boosted, Node, Trees};
use alnlab_aln::pwl::predict::{advance, change};
use alnlab_codes::Entry;
use gbdt::config::Config;
use gbdt::decision_tree::{Data, DataVec};
use gbdt::gradient_boost::GBDT;
use serde_json::Value;

/// Boosting rounds, tree depth, shrinkage and least rows in a leaf: a
/// common starting point (scikit-learn's histogram booster's learning rate
/// and depth), checked on seed 7's data as the piecewise-linear model's
/// configuration was.
const ITERATIONS: usize = 300;
const DEPTH: u32 = 4;
const SHRINKAGE: f32 = 0.05;
const LEAF_ROWS: usize = 20;

/// One model per predicted variable, as kept ([`Boosted`]): fitted by the
/// gbdt crate, then predicting through the kept form, so that what the test
/// stage scores is what its file holds.
pub struct Peer {
    pub boosted: Boosted,
    /// The predicted variables' indices among the learned ones.
    variables: Vec<usize>,
}

/// The rows `rows` of `x` (`[variable][row]`) as the crate's samples.
fn samples(x: &[Vec<f64>], rows: &[usize], labels: &[f64]) -> DataVec {
    rows.iter()
        .zip(labels)
        .map(|(&r, &y)| {
            let feature = x.iter().map(|c| c[r] as f32).collect();
            Data::new_training_data(feature, 1.0, y as f32, None)
        })
        .collect()
}

/// A fitted model's trees, as kept: read from its serialized form, the
/// only way the crate shows them (`to_value` keeps every `f32` exactly).
/// Their predictions are checked equal to the crate's in this module's
/// tests, so a crate whose layout changed fails there.
fn kept(model: &GBDT, variable: &str) -> Trees {
    let json = serde_json::to_value(model).expect("a fitted model serializes");
    let f32_of = |v: &Value| v.as_f64().expect("the crate's numbers") as f32;
    let u32_of = |v: &Value| v.as_u64().expect("the crate's indices") as u32;
    let conf = &json["conf"];
    assert_eq!(
        conf["loss"], "LAD",
        "fitted with the least-absolute-deviation loss"
    );
    assert_eq!(conf["initial_guess_enabled"], false, "fitted from the bias");
    let trees = json["trees"]
        .as_array()
        .expect("the crate's trees")
        .iter()
        .map(|tree| {
            let nodes = tree["tree"]["tree"].as_array().expect("a tree's nodes");
            nodes
                .iter()
                .enumerate()
                .map(|(k, node)| {
                    assert_eq!(u32_of(&node["index"]) as usize, k, "nodes stored in order");
                    let value = &node["value"];
                    Node {
                        leaf: value["is_leaf"].as_bool().expect("a leaf flag"),
                        feature: u32_of(&value["feature_index"]),
                        threshold: f32_of(&value["feature_value"]),
                        missing: value["missing"].as_i64().expect("a direction") as i8,
                        value: f32_of(&value["pred"]),
                        left: u32_of(&node["left"]),
                        right: u32_of(&node["right"]),
                    }
                })
                .collect()
        })
        .collect();
    Trees {
        variable: variable.to_string(),
        bias: f32_of(&json["bias"]),
        shrinkage: f32_of(&conf["shrinkage"]),
        trees,
    }
}

/// The crate's model for one variable: `x` (`[feature][row]`) on `rows`
/// to `target` (one per row).
fn fit_one(x: &[Vec<f64>], rows: &[usize], target: &[f64]) -> GBDT {
    let mut data = samples(x, rows, target);
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
        let outputs = variables
            .iter()
            .map(|&v| {
                let target: Vec<f64> = rows
                    .iter()
                    .map(|&r| change(learned[v], base[v][r], y[v][r]))
                    .collect();
                kept(&fit_one(x, rows, &target), &learned[v].variable)
            })
            .collect();
        Peer {
            boosted: Boosted {
                outputs,
                features: x.len(),
            },
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
        let mut next = vec![Vec::with_capacity(rows.len()); self.variables.len()];
        let mut features = vec![0f32; x.len()];
        for &r in rows {
            for (f, column) in features.iter_mut().zip(x) {
                *f = column[r] as f32;
            }
            for ((trees, &v), next) in self
                .boosted
                .outputs
                .iter()
                .zip(&self.variables)
                .zip(&mut next)
            {
                let d = trees.change(&features);
                next.push(advance(learned[v], base[v][r], f64::from(d)));
            }
        }
        next
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The kept trees predict what the crate predicts, bit for bit, on rows
    /// they were not fitted on.
    #[test]
    fn kept_trees_predict_as_the_crate_does() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let x: Vec<Vec<f64>> = (0..3)
            .map(|_| (0..400).map(|_| rng.random_range(-2.0..2.0)).collect())
            .collect();
        let target: Vec<f64> = (0..300)
            .map(|r| x[0][r].sin() + 0.5 * x[1][r] * x[2][r])
            .collect();
        let fitted: Vec<usize> = (0..300).collect();
        let model = fit_one(&x, &fitted, &target);
        let trees = kept(&model, "v");
        assert_eq!(trees.trees.len(), ITERATIONS);
        let held: Vec<usize> = (300..400).collect();
        let zeros = vec![0.0; held.len()];
        let theirs = model.predict(&samples(&x, &held, &zeros));
        for (k, &r) in held.iter().enumerate() {
            let features: Vec<f32> = x.iter().map(|c| c[r] as f32).collect();
            assert_eq!(
                trees.change(&features).to_bits(),
                theirs[k].to_bits(),
                "row {r}"
            );
        }
    }
}
