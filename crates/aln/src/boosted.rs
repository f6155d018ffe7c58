//! Gradient-boosted regression trees as kept: the test stage's learned peer
//! (`boosted`), not an ALN, but a model the test stage and the Python
//! package both evaluate, so it lives beside the ALN's. Per predicted
//! variable, a bias plus the shrunk sum of its trees' leaves: its change in
//! level spacings, read from every learned variable's current real value
//! (as `f32`, the type the trees were fitted in).
//!
//! The file is `boosted.parquet`, one row per tree node: `variable` (the
//! predicted variable), `tree`, `node` (its index in the tree; the root is
//! 0 and every child comes after its parent), `leaf`, `feature` (an index
//! among the codebook's learned variables), `threshold` (below it, left),
//! `missing` (where a missing value goes: −1 left, 0 this node's value, 1
//! right), `value` (a leaf's prediction), `left` and `right` (child node
//! indices), and per variable its `bias` and `shrinkage` on every row. The
//! provenance names the codebook the trees read, by SHA-256.
//!
//! Evaluation adds in the order the fitting crate (gbdt) does, in `f32`,
//! so its predictions equal that crate's bit for bit.

use std::path::Path;
use std::sync::Arc;

use alnlab_codes::Codebook;
use alnlab_common::hash::sha256_file;
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, BooleanArray, Float32Array, Int8Array, StringArray, UInt32Array};

/// The file's name in the test stage's artifact.
pub const FILE: &str = "boosted.parquet";

/// The feature value the fitting crate reads as missing (its `f32::MIN`).
const MISSING: f32 = f32::MIN;

/// One node of a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// A leaf answers `value`; any other node sends the sample on.
    pub leaf: bool,
    /// The learned variable a split reads.
    pub feature: u32,
    /// A feature below it goes left, otherwise right.
    pub threshold: f32,
    /// Where a missing feature goes: −1 left, 0 this node's value, 1 right.
    pub missing: i8,
    /// The node's prediction (a leaf's answer).
    pub value: f32,
    /// The children's indices in the tree (after this node's).
    pub left: u32,
    pub right: u32,
}

/// One predicted variable's trees.
#[derive(Clone, Debug, PartialEq)]
pub struct Trees {
    /// The predicted variable's name.
    pub variable: String,
    pub bias: f32,
    pub shrinkage: f32,
    /// Each tree's nodes, its root first.
    pub trees: Vec<Vec<Node>>,
}

impl Trees {
    /// The change this variable's trees predict from `features` (every
    /// learned variable's value, in the codebook's order).
    pub fn change(&self, features: &[f32]) -> f32 {
        let mut sum = self.bias;
        for tree in &self.trees {
            sum += self.shrinkage * leaf(tree, features);
        }
        sum
    }
}

/// The value a tree answers for `features`.
fn leaf(tree: &[Node], features: &[f32]) -> f32 {
    let mut k = 0;
    loop {
        let node = &tree[k];
        if node.leaf {
            return node.value;
        }
        let x = features[node.feature as usize];
        let left = match x == MISSING {
            true if node.missing == 0 => return node.value,
            true => node.missing < 0,
            false => x < node.threshold,
        };
        k = if left { node.left } else { node.right } as usize;
    }
}

/// Boosted trees for some of a codebook's learned variables.
#[derive(Clone, Debug, PartialEq)]
pub struct Boosted {
    /// Per predicted variable, in the order fitted.
    pub outputs: Vec<Trees>,
    /// How many features each tree may read: the codebook's learned
    /// variables.
    pub features: usize,
}

impl Boosted {
    /// Writes the trees to `path` (atomically), with `provenance` — whose
    /// `codebook` input names the codebook they read.
    pub fn write(&self, path: &Path, provenance: &Provenance) -> Result<()> {
        let mut variable = Vec::new();
        let (mut tree, mut node) = (Vec::new(), Vec::new());
        let (mut leaf, mut feature, mut threshold) = (Vec::new(), Vec::new(), Vec::new());
        let (mut missing, mut value) = (Vec::new(), Vec::new());
        let (mut left, mut right) = (Vec::new(), Vec::new());
        let (mut bias, mut shrinkage, mut features) = (Vec::new(), Vec::new(), Vec::new());
        for output in &self.outputs {
            for (t, nodes) in output.trees.iter().enumerate() {
                for (k, n) in nodes.iter().enumerate() {
                    variable.push(output.variable.as_str());
                    tree.push(t as u32);
                    node.push(k as u32);
                    leaf.push(n.leaf);
                    feature.push(n.feature);
                    threshold.push(n.threshold);
                    missing.push(n.missing);
                    value.push(n.value);
                    left.push(n.left);
                    right.push(n.right);
                    bias.push(output.bias);
                    shrinkage.push(output.shrinkage);
                    features.push(self.features as u32);
                }
            }
        }
        let batch = table::batch(vec![
            (
                "variable",
                Arc::new(StringArray::from(variable)) as Arc<dyn Array>,
            ),
            ("tree", Arc::new(UInt32Array::from(tree))),
            ("node", Arc::new(UInt32Array::from(node))),
            ("leaf", Arc::new(BooleanArray::from(leaf))),
            ("feature", Arc::new(UInt32Array::from(feature))),
            ("threshold", Arc::new(Float32Array::from(threshold))),
            ("missing", Arc::new(Int8Array::from(missing))),
            ("value", Arc::new(Float32Array::from(value))),
            ("left", Arc::new(UInt32Array::from(left))),
            ("right", Arc::new(UInt32Array::from(right))),
            ("bias", Arc::new(Float32Array::from(bias))),
            ("shrinkage", Arc::new(Float32Array::from(shrinkage))),
            ("features", Arc::new(UInt32Array::from(features))),
        ]);
        table::write_parquet(path, &batch, provenance)
    }

    /// Reads the trees at `path`, checked whole: each variable's trees
    /// numbered from 0 and their nodes from 0 in order, one bias and
    /// shrinkage per variable, every split reading a feature there is and
    /// sending samples to later nodes of its tree (so that every walk ends
    /// at a leaf). Also returns the SHA-256 of the codebook the provenance
    /// names, if it names one.
    pub fn read(path: &Path) -> Result<(Boosted, Option<String>)> {
        let table = Table::read(path)?;
        // Another of a run's tables given as the model (its codebook, most
        // likely, the other argument) says what it is; the test stage's own
        // table, which writes the trees, is judged column by column below.
        let stage = table.metadata.get("alnlab.stage").map(String::as_str);
        if table.batch.column_by_name("tree").is_none() && stage != Some("test") {
            let what = match stage {
                Some("quantize") => "a codebook (the quantize stage's table)".to_string(),
                Some(stage) => format!("a table of the {stage} stage"),
                None => "a Parquet table alnlab did not write".to_string(),
            };
            return Err(Error::bad_file(
                path,
                format!(
                    "is {what}, not a model: expected a run's model.aln, linear.aln or \
                     boosted.parquet"
                ),
            ));
        }
        table.require_no_nulls()?;
        let codebook = Provenance::from_key_values(&table.metadata)
            .and_then(|p| p.inputs.get("codebook").cloned());
        let variable = table.column::<StringArray>("variable")?;
        let u32s = |name| table.column::<UInt32Array>(name).map(|c| c.values());
        let f32s = |name| table.column::<Float32Array>(name).map(|c| c.values());
        let (tree, node, feature) = (u32s("tree")?, u32s("node")?, u32s("feature")?);
        let (left, right, features) = (u32s("left")?, u32s("right")?, u32s("features")?);
        let (threshold, value) = (f32s("threshold")?, f32s("value")?);
        let (bias, shrinkage) = (f32s("bias")?, f32s("shrinkage")?);
        let leaf = table.column::<BooleanArray>("leaf")?;
        let missing = table.column::<Int8Array>("missing")?.values();
        let bad = |row: usize, what: String| Error::bad_file(path, format!("row {row}: {what}"));
        let width = features.first().copied().unwrap_or(0);
        let mut outputs: Vec<Trees> = Vec::new();
        for r in 0..table.num_rows() {
            if features[r] != width {
                return Err(bad(r, format!("{} features, row 0 {width}", features[r])));
            }
            let name = variable.value(r);
            let new_output = outputs.last().is_none_or(|o| o.variable != name);
            if new_output {
                if outputs.iter().any(|o| o.variable == name) {
                    return Err(bad(r, format!("`{name}`'s rows are not together")));
                }
                outputs.push(Trees {
                    variable: name.to_string(),
                    bias: bias[r],
                    shrinkage: shrinkage[r],
                    trees: Vec::new(),
                });
            }
            let output = outputs.last_mut().expect("pushed above");
            if (bias[r], shrinkage[r]) != (output.bias, output.shrinkage) {
                return Err(bad(
                    r,
                    format!("`{name}` has another bias or shrinkage than on its first row"),
                ));
            }
            let trees = output.trees.len() as u32;
            let new_tree = node[r] == 0;
            let expected = match new_tree {
                true => (trees, 0),
                false => (
                    trees.saturating_sub(1),
                    output.trees.last().map_or(0, |t| t.len() as u32),
                ),
            };
            if (tree[r], node[r]) != expected || (!new_tree && trees == 0) {
                return Err(bad(
                    r,
                    format!(
                        "`{name}` tree {} node {}, expected tree {} node {} (trees and nodes \
                         numbered from 0, in order)",
                        tree[r], node[r], expected.0, expected.1
                    ),
                ));
            }
            let n = Node {
                leaf: leaf.value(r),
                feature: feature[r],
                threshold: threshold[r],
                missing: missing[r],
                value: value[r],
                left: left[r],
                right: right[r],
            };
            if !n.leaf {
                if n.feature >= width {
                    return Err(bad(
                        r,
                        format!("splits on feature {}, of {width}", n.feature),
                    ));
                }
                if n.left <= node[r] || n.right <= node[r] {
                    return Err(bad(
                        r,
                        format!(
                            "node {} sends samples to nodes {} and {}: children come after \
                             their parent",
                            node[r], n.left, n.right
                        ),
                    ));
                }
            }
            match new_tree {
                true => output.trees.push(vec![n]),
                false => output.trees.last_mut().expect("checked above").push(n),
            }
        }
        for output in &outputs {
            for (t, tree) in output.trees.iter().enumerate() {
                let past = tree.iter().find(|n| {
                    !n.leaf && (n.left as usize >= tree.len() || n.right as usize >= tree.len())
                });
                if past.is_some() {
                    return Err(Error::bad_file(
                        path,
                        format!(
                            "`{}` tree {t} sends samples past its {} nodes",
                            output.variable,
                            tree.len()
                        ),
                    ));
                }
            }
        }
        let boosted = Boosted {
            outputs,
            features: width as usize,
        };
        Ok((boosted, codebook))
    }
}

/// Boosted trees with the codebook they read, checked to belong together.
pub struct Kept {
    pub boosted: Boosted,
    pub codebook: Codebook,
    /// Each output's variable, an index among the codebook's learned ones.
    pub variables: Vec<usize>,
}

impl Kept {
    /// Reads `boosted.parquet` and `codebook.parquet`: the trees must name
    /// that codebook, read its learned variables and predict some of them,
    /// and there must be trees (the test stage fits them only with
    /// `[test] peer`). An error names the file that does not fit.
    pub fn read(path: &Path, codebook_path: &Path) -> Result<Kept> {
        let (boosted, codebook_sha256) = Boosted::read(path)?;
        if boosted.outputs.is_empty() {
            return Err(Error::bad_file(
                path,
                "holds no boosted trees: the test stage fits them only with `[test] peer = true`",
            ));
        }
        if codebook_sha256 != Some(sha256_file(codebook_path)?) {
            return Err(Error::bad_file(
                path,
                format!(
                    "was fitted with another codebook than {}",
                    codebook_path.display()
                ),
            ));
        }
        let codebook = alnlab_tables::codebook::read(codebook_path)?;
        let learned: Vec<_> = codebook.learned().collect();
        let misfit = |m: String| {
            Error::bad_file(
                path,
                format!("does not fit the codebook {}: {m}", codebook_path.display()),
            )
        };
        if boosted.features != learned.len() {
            return Err(misfit(format!(
                "its trees read {} features, the codebook learns {} variables",
                boosted.features,
                learned.len()
            )));
        }
        let variables = boosted
            .outputs
            .iter()
            .map(|o| {
                learned
                    .iter()
                    .position(|e| e.variable == o.variable)
                    .ok_or_else(|| {
                        misfit(format!(
                            "predicts `{}`, which it does not learn",
                            o.variable
                        ))
                    })
            })
            .collect::<Result<_>>()?;
        Ok(Kept {
            boosted,
            codebook,
            variables,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn split(feature: u32, threshold: f32, left: u32, right: u32) -> Node {
        Node {
            leaf: false,
            feature,
            threshold,
            missing: 1,
            value: 0.5,
            left,
            right,
        }
    }

    fn leaf(value: f32) -> Node {
        Node {
            leaf: true,
            feature: 0,
            threshold: 0.0,
            missing: 0,
            value,
            left: 0,
            right: 0,
        }
    }

    /// Two variables over three features: a stump and a two-level tree.
    fn boosted() -> Boosted {
        Boosted {
            features: 3,
            outputs: vec![
                Trees {
                    variable: "a".into(),
                    bias: 0.25,
                    shrinkage: 0.5,
                    trees: vec![
                        vec![split(2, 1.0, 1, 2), leaf(-1.0), leaf(3.0)],
                        vec![
                            split(0, 0.0, 1, 2),
                            split(1, 5.0, 3, 4),
                            leaf(2.0),
                            leaf(-4.0),
                            leaf(8.0),
                        ],
                    ],
                },
                Trees {
                    variable: "b".into(),
                    bias: -1.0,
                    shrinkage: 0.1,
                    trees: vec![vec![leaf(7.0)]],
                },
            ],
        }
    }

    #[test]
    fn trees_add_their_shrunk_leaves_to_the_bias() {
        let b = boosted();
        // Feature 2 below 1 → −1; feature 0 below 0, feature 1 at 5 → 8.
        assert_eq!(
            b.outputs[0].change(&[-1.0, 5.0, 0.0]),
            0.25 - 0.5 + 0.5 * 8.0
        );
        assert_eq!(
            b.outputs[0].change(&[2.0, 0.0, 1.0]),
            0.25 + 0.5 * 3.0 + 0.5 * 2.0
        );
        // A missing feature 2 goes right (missing = 1): 3.
        assert_eq!(b.outputs[0].change(&[2.0, 0.0, MISSING]), 0.25 + 1.5 + 1.0);
        assert_eq!(b.outputs[1].change(&[0.0; 3]), -1.0 + 0.1 * 7.0);
    }

    #[test]
    fn trees_read_back_as_written_with_their_codebook() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let provenance = Provenance {
            stage: "test".into(),
            params: serde_json::json!({}),
            inputs: [("codebook".to_string(), "c0ffee".to_string())].into(),
        };
        boosted().write(&path, &provenance).unwrap();
        let (read, codebook) = Boosted::read(&path).unwrap();
        assert_eq!(read, boosted());
        assert_eq!(codebook.as_deref(), Some("c0ffee"));
    }

    /// A codebook given where the trees belong (the two paths swapped) is
    /// named as one, not as a table missing a column.
    #[test]
    fn another_table_given_as_the_trees_says_what_it_is() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("codebook.parquet");
        let columns = table::batch(vec![(
            "variable",
            Arc::new(StringArray::from(vec!["q.1"])) as Arc<dyn Array>,
        )]);
        for (stage, says) in [
            (
                "quantize",
                "is a codebook (the quantize stage's table), not a model",
            ),
            ("stride", "is a table of the stride stage, not a model"),
            // The stage that writes the trees: a damaged or older file.
            ("test", "has no column `tree`"),
        ] {
            let provenance = Provenance {
                stage: stage.into(),
                ..Provenance::default()
            };
            table::write_parquet(&path, &columns, &provenance).unwrap();
            let message = Boosted::read(&path).unwrap_err().to_string();
            assert!(message.contains(says), "{message}");
            assert_eq!(
                message.contains("expected a run's model.aln"),
                stage != "test",
                "{message}"
            );
        }
    }

    #[test]
    fn a_split_that_loops_back_or_reads_past_the_features_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let refused = |b: Boosted| {
            b.write(&path, &Provenance::default()).unwrap();
            Boosted::read(&path).unwrap_err().to_string()
        };
        let mut looping = boosted();
        looping.outputs[0].trees[1][1].left = 1;
        let message = refused(looping);
        assert!(
            message.contains("row 4: node 1 sends samples to nodes 1 and 4"),
            "{message}"
        );
        let mut wide = boosted();
        wide.outputs[0].trees[0][0].feature = 3;
        let message = refused(wide);
        assert!(
            message.contains("row 0: splits on feature 3, of 3"),
            "{message}"
        );
        let mut past = boosted();
        past.outputs[0].trees[0][0].right = 9;
        let message = refused(past);
        assert!(
            message.contains("`a` tree 0 sends samples past its 3 nodes"),
            "{message}"
        );
    }
}
