//! The model file (`model.aln`): a versioned binary file holding every tree
//! of a forest compactly — node functions packed two bits each, leaf literals
//! as u32 — behind a JSON header naming the codebook it was trained for and
//! the training parameters. Written atomically; reading a wrong or truncated
//! file is a clear error.
//!
//! The header says which model the trees make up (`bit-forest`: one tree
//! per output bit and voter, over the input bits; `threshold`: one tree per
//! output variable and voter, over the input bits and the candidate level's
//! thermometer code).
//!
//! Layout (little endian): magic `ALNLAB-MODEL\0\0\0\0` (16 bytes), format
//! version (u32), header length (u32), header (JSON), then per tree:
//! variable, bit, voter, leaves (4 × u32), the leaves' literals (leaves ×
//! u32), the functions of the leaves − 1 internal nodes (2 bits each, node i
//! in bits 2(i % 4).. of byte i / 4; 0 AND, 1 LEFT, 2 RIGHT, 3 OR).

use std::io::Write;
use std::path::Path;

use alnlab_common::{Error, Result, atomic};
use serde::{Deserialize, Serialize};

use crate::ModelKind;
use crate::forest::TreeId;
use crate::shard::Shard;
use crate::tree::{Function, Tree};

/// The file's magic bytes.
pub const MAGIC: &[u8; 16] = b"ALNLAB-MODEL\0\0\0\0";
/// The model file format version.
pub const MODEL_FORMAT: u32 = 2;

/// The model's header.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// SHA-256 of the codebook the model was trained with.
    pub codebook_sha256: String,
    /// The train stage's parameters, as JSON.
    pub params: serde_json::Value,
    /// Which model the trees make up.
    pub model: ModelKind,
    /// Input bits per sample (for the threshold model, before the
    /// candidate's bits).
    pub inputs: usize,
    /// The learned output variables, in tree order, with their code widths
    /// (for the threshold model, the width of the candidate's thermometer
    /// code: levels − 1).
    pub outputs: Vec<(String, usize)>,
    /// Voters per bit.
    pub vote: u32,
    /// Counter bound the trees were trained with.
    pub counter_bound: i8,
    /// For a shard's partial model, which shard: the file then holds only
    /// the trees [`Shard::owns`]. Absent from whole models.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
}

/// A model: its header and its trees.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    pub header: Header,
    pub trees: Vec<(TreeId, Tree)>,
}

fn function_code(f: Function) -> u8 {
    match f {
        Function::And => 0,
        Function::Left => 1,
        Function::Right => 2,
        Function::Or => 3,
    }
}

const FUNCTIONS: [Function; 4] = [Function::And, Function::Left, Function::Right, Function::Or];

impl Model {
    /// Writes the model to `path` (atomically).
    pub fn write(&self, path: &Path) -> Result<()> {
        let header = serde_json::to_vec(&self.header).expect("headers serialize");
        let mut bytes = Vec::new();
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&MODEL_FORMAT.to_le_bytes());
        bytes.extend_from_slice(&(header.len() as u32).to_le_bytes());
        bytes.extend_from_slice(&header);
        for (id, tree) in &self.trees {
            for x in [id.variable, id.bit, id.vote, tree.leaves() as u32] {
                bytes.extend_from_slice(&x.to_le_bytes());
            }
            for literal in tree.literals() {
                bytes.extend_from_slice(&literal.to_le_bytes());
            }
            let functions = tree.functions();
            let mut packed = vec![0u8; functions.len().div_ceil(4)];
            for (i, f) in functions.iter().enumerate() {
                packed[i / 4] |= function_code(*f) << (2 * (i % 4));
            }
            bytes.extend_from_slice(&packed);
        }
        atomic::write_file(path, |out| {
            out.write_all(&bytes).map_err(|e| Error::io(path, e))
        })
    }

    /// Reads a model file.
    pub fn read(path: &Path) -> Result<Model> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let bad = |what: String| Error::bad_file(path, what);
        let mut at = 0usize;
        let mut take = |n: usize, what: &str| -> Result<&[u8]> {
            let end = at
                .checked_add(n)
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| {
                    bad(format!(
                        "truncated: {what} needs {n} bytes at offset {at}, the file has {}",
                        bytes.len()
                    ))
                })?;
            let slice = &bytes[at..end];
            at = end;
            Ok(slice)
        };
        if take(16, "the magic")? != MAGIC {
            return Err(bad("not an alnlab model file (wrong magic bytes)".into()));
        }
        let u32_of = |b: &[u8]| u32::from_le_bytes(b.try_into().expect("4 bytes"));
        let version = u32_of(take(4, "the format version")?);
        if version != MODEL_FORMAT {
            return Err(bad(format!(
                "model format {version}, this alnlab reads format {MODEL_FORMAT}"
            )));
        }
        let header_len = u32_of(take(4, "the header length")?) as usize;
        let header: Header = serde_json::from_slice(take(header_len, "the header")?)
            .map_err(|e| bad(format!("corrupt header ({e})")))?;
        let mut trees = Vec::new();
        // Each tree's input bits, in file order.
        let vote = header.vote as usize;
        let all_inputs: Vec<usize> = match header.model {
            ModelKind::BitForest => header
                .outputs
                .iter()
                .flat_map(|&(_, width)| std::iter::repeat_n(header.inputs, width * vote))
                .collect(),
            ModelKind::Threshold => header
                .outputs
                .iter()
                .flat_map(|&(_, width)| std::iter::repeat_n(header.inputs + width, vote))
                .collect(),
        };
        let shard = header.shard.unwrap_or(Shard::ALL);
        let tree_inputs: Vec<usize> = all_inputs
            .into_iter()
            .enumerate()
            .filter(|&(position, _)| shard.owns(position))
            .map(|(_, inputs)| inputs)
            .collect();
        for (t, &inputs) in tree_inputs.iter().enumerate() {
            let what = format!("tree {t}");
            let fields: Vec<u32> = (0..4)
                .map(|_| take(4, &what).map(u32_of))
                .collect::<Result<_>>()?;
            let (id, leaves) = (
                TreeId {
                    variable: fields[0],
                    bit: fields[1],
                    vote: fields[2],
                },
                fields[3] as usize,
            );
            if leaves < 2 || !leaves.is_power_of_two() {
                return Err(bad(format!(
                    "tree {t}: {leaves} leaves is not a power of two ≥ 2"
                )));
            }
            let literals: Vec<u32> = take(4 * leaves, &what)?
                .chunks_exact(4)
                .map(u32_of)
                .collect();
            if let Some(l) = literals.iter().find(|&&l| l as usize >= 2 * inputs) {
                return Err(bad(format!(
                    "tree {t}: literal {l} beyond its {inputs} inputs"
                )));
            }
            let packed = take((leaves - 1).div_ceil(4), &what)?;
            let functions: Vec<Function> = (0..leaves - 1)
                .map(|i| FUNCTIONS[usize::from(packed[i / 4] >> (2 * (i % 4)) & 3)])
                .collect();
            trees.push((
                id,
                Tree::from_functions(&functions, literals, header.counter_bound),
            ));
        }
        if at != bytes.len() {
            return Err(bad(format!(
                "{} bytes after the last tree",
                bytes.len() - at
            )));
        }
        Ok(Model { header, trees })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tree::TreeSpec;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn model() -> Model {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let spec = TreeSpec {
            leaves: 64,
            inputs: 10,
            counter_bound: 3,
            initial_spread: 1,
        };
        let trees = (0..6)
            .map(|k| {
                (
                    TreeId {
                        variable: k / 3,
                        bit: k % 3,
                        vote: 0,
                    },
                    Tree::new(&spec, &mut rng),
                )
            })
            .collect();
        Model {
            header: Header {
                codebook_sha256: "ab".into(),
                params: serde_json::json!({"leaves": 64}),
                model: ModelKind::BitForest,
                inputs: 10,
                outputs: vec![("a.1.x".into(), 3), ("a.1.y".into(), 3)],
                vote: 1,
                counter_bound: 3,
                shard: None,
            },
            trees,
        }
    }

    #[test]
    fn a_threshold_model_round_trips_with_its_candidate_inputs() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        // Two variables of 6 levels: 10 input bits + 5 candidate bits.
        let spec = TreeSpec {
            leaves: 64,
            inputs: 15,
            counter_bound: 3,
            initial_spread: 1,
        };
        let mut m = model();
        m.header.model = ModelKind::Threshold;
        m.header.outputs = vec![("a.1.x".into(), 5), ("a.1.y".into(), 5)];
        m.trees = (0..2)
            .map(|v| {
                let id = TreeId {
                    variable: v,
                    bit: 0,
                    vote: 0,
                };
                (id, Tree::new(&spec, &mut rng))
            })
            .collect();
        assert!(
            m.trees[0].1.literals().iter().any(|&l| l >= 20),
            "candidate bits used"
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.aln");
        m.write(&path).unwrap();
        assert_eq!(Model::read(&path).unwrap(), m);
        // Read as a bit-forest, the same trees have literals out of range.
        m.header.model = ModelKind::BitForest;
        m.header.outputs = vec![("a.1.x".into(), 1), ("a.1.y".into(), 1)];
        m.write(&path).unwrap();
        let error = Model::read(&path).unwrap_err().to_string();
        assert!(error.contains("beyond its 10 inputs"), "{error}");
    }

    #[test]
    fn round_trip_keeps_every_function_and_literal() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.aln");
        let m = model();
        m.write(&path).unwrap();
        let back = Model::read(&path).unwrap();
        assert_eq!(back.header, m.header);
        for ((id, a), (id2, b)) in m.trees.iter().zip(&back.trees) {
            assert_eq!(id, id2);
            assert_eq!(a.functions(), b.functions());
            assert_eq!(a.literals(), b.literals());
        }
        // 16 + 4 + 4 + header + 6 × (16 + 256 + 16) bytes.
        let header = serde_json::to_vec(&m.header).unwrap().len();
        assert_eq!(
            std::fs::metadata(&path).unwrap().len() as usize,
            24 + header + 6 * 288
        );
    }

    #[test]
    fn wrong_and_truncated_files_are_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.aln");
        model().write(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        for cut in [0, 10, 20, 30, bytes.len() - 1] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let e = Model::read(&path).unwrap_err().to_string();
            assert!(e.contains("model.aln: truncated"), "cut {cut}: {e}");
        }
        std::fs::write(&path, b"PAR1 not a model at all").unwrap();
        assert!(
            Model::read(&path)
                .unwrap_err()
                .to_string()
                .contains("not an alnlab model file")
        );
        let mut newer = bytes.clone();
        newer[16] = 9;
        std::fs::write(&path, &newer).unwrap();
        assert!(
            Model::read(&path)
                .unwrap_err()
                .to_string()
                .contains("model format 9")
        );
    }
}
