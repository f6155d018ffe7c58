//! The model file (`model.aln`): a versioned binary file holding every tree
//! of a forest compactly — node functions packed two bits each, leaf literals
//! as u32 — behind a JSON header naming the codebook it was trained for and
//! the training parameters. Written atomically; reading a wrong or truncated
//! file is a clear error.
//!
//! The header says which model the trees make up (`bit-forest`: one tree
//! per output bit and voter, over the input bits; `threshold`: one tree per
//! output variable and voter, over the input bits and the candidate level's
//! thermometer code; `piecewise-linear`: one MIN/MAX tree of affine pieces
//! per output variable over the real inputs) and what they learn (the
//! [`Target`]: each variable's next level, or its change with each change's
//! code, or — piecewise-linear — its real change in level spacings).
//!
//! Layout (little endian): magic `ALNLAB-MODEL\0\0\0\0` (16 bytes), format
//! version (u32), header length (u32), header (JSON), then per tree:
//! variable, bit, voter, leaves (4 × u32), the leaves' literals (leaves ×
//! u32), the functions of the leaves − 1 internal nodes (2 bits each, node i
//! in bits 2(i % 4).. of byte i / 4; 0 AND, 1 LEFT, 2 RIGHT, 3 OR). A
//! piecewise-linear model holds instead, per output: its inputs, nodes and
//! pieces (3 × u32), each node as 3 × u32 (0 piece p; 1 MIN, 2 MAX of
//! children a, b), then each piece's bias and weights (f64).

use std::io::Write;
use std::path::Path;

use alnlab_codes::Entry;
use alnlab_common::{Error, Result, atomic};
use serde::{Deserialize, Serialize};

use crate::forest::TreeId;
use crate::output::{Output, Target};
use crate::shard::Shard;
use crate::tree::{Function, Tree};

/// Which model the trees make up (docs/design.md §5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// One tree per output bit of every learned variable, decoded by the
    /// variable's code (§4.3).
    #[default]
    BitForest,
    /// One tree per output variable computing [y < f(x)] over the inputs
    /// and a thermometer-coded candidate y; y found by binary search (§6).
    Threshold,
    /// One MIN/MAX tree of affine pieces per output variable over the
    /// current state's real values, computing the variable's change (§6 as
    /// its authors built it next).
    PiecewiseLinear,
}

impl ModelKind {
    /// The kind's manifest name.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::BitForest => "bit-forest",
            ModelKind::Threshold => "threshold",
            ModelKind::PiecewiseLinear => "piecewise-linear",
        }
    }
}

/// What a piecewise-linear model's change is measured from: the current
/// state (a model of the dynamics), or the nominal simulator's prediction
/// of the next state (a hybrid: the nominal model plus a learned
/// correction, issue 43).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Base {
    /// Each output advances from its variable's current value, reading the
    /// current state.
    #[default]
    Current,
    /// Each output advances from the nominal simulator's prediction of its
    /// variable, reading the current state and that prediction: the inputs
    /// are the learned variables, then the same again as predicted
    /// ([`nominal_input`]).
    Nominal,
}

impl Base {
    /// Whether this is the default, [`Base::Current`] (left out of files,
    /// which then read as before).
    pub fn is_current(&self) -> bool {
        *self == Base::Current
    }

    /// The entries of a model's inputs over the `learned` ones: those, and
    /// for [`Base::Nominal`] the same again for their nominal predictions.
    pub fn inputs<'e>(self, learned: &[&'e Entry]) -> Vec<&'e Entry> {
        match self {
            Base::Current => learned.to_vec(),
            Base::Nominal => learned.iter().chain(learned).copied().collect(),
        }
    }
}

/// The name under which a hybrid's tree reads the nominal simulator's
/// prediction of `variable`.
pub fn nominal_input(variable: &str) -> String {
    format!("nominal({variable})")
}

/// The file's magic bytes.
pub const MAGIC: &[u8; 16] = b"ALNLAB-MODEL\0\0\0\0";
/// The model file format version (4: the file ends with its CRC-32; 5:
/// piecewise-linear models).
pub const MODEL_FORMAT: u32 = 5;
/// Bytes of the smallest tree record: its id and leaf count (16), two
/// literals (8) and one byte of node functions.
const SMALLEST_TREE: usize = 25;

/// The model's header.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// SHA-256 of the codebook the model was trained with.
    pub codebook_sha256: String,
    /// The train stage's parameters, as JSON.
    pub params: serde_json::Value,
    /// Which model the trees make up.
    pub model: ModelKind,
    /// What they learn: each variable's next level or its change.
    pub target: Target,
    /// Input bits per sample (for the threshold model, before the
    /// candidate's bits; for a piecewise-linear model, the input variables:
    /// the codebook's learned ones, then for a hybrid their nominal
    /// predictions).
    pub inputs: usize,
    /// The learned output variables, in tree order, with the widths of
    /// their targets' codes (for the threshold model, the width of the
    /// candidate's thermometer code: levels − 1; for a piecewise-linear
    /// model, its tree's pieces). A piecewise-linear model may predict
    /// fewer variables than it reads (the controls given).
    pub outputs: Vec<(String, usize)>,
    /// For each output, the input variables its trees read, when they do
    /// not read every input (chosen by the train stage). Absent when they do.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub reads: Vec<Vec<String>>,
    /// Voters per bit.
    pub vote: u32,
    /// Counter bound the trees were trained with.
    pub counter_bound: i8,
    /// For a shard's partial model, which shard: the file then holds only
    /// the trees [`Shard::owns`]. Absent from whole models.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
    /// What a piecewise-linear model's changes advance from (absent: the
    /// current state).
    #[serde(default, skip_serializing_if = "Base::is_current")]
    pub base: Base,
}

impl Header {
    /// Checks that the model fits the learned variables it is to be
    /// evaluated with (the codebook's learned entries, in order) and returns
    /// their outputs, which decode the trees' bits: the same variables in
    /// the same order, as many input bits as the codes are wide together,
    /// and each output as wide as its target's code (a bit-forest) or as
    /// that code's thermometer, levels − 1 (a threshold model's candidate).
    /// On a mismatch, what differs.
    pub fn outputs_for(&self, learned: &[&Entry]) -> std::result::Result<Vec<Output>, String> {
        match self.model {
            ModelKind::BitForest | ModelKind::Threshold => {}
            ModelKind::PiecewiseLinear => {
                return Err("a piecewise-linear model has no bit outputs".into());
            }
        }
        let names: Vec<&str> = learned.iter().map(|e| e.variable.as_str()).collect();
        let outputs: Vec<&str> = self.outputs.iter().map(|(n, _)| n.as_str()).collect();
        if names != outputs {
            return Err(format!(
                "predicts {outputs:?}, but the codebook learns {names:?}"
            ));
        }
        let inputs: usize = learned.iter().map(|e| e.width as usize).sum();
        if self.inputs != inputs {
            return Err(format!(
                "reads {} input bits, but the codebook's codes are {inputs} bits wide together",
                self.inputs
            ));
        }
        let decoders = Output::for_entries(&self.target, learned)?;
        for ((name, output), (_, width)) in names.iter().zip(&decoders).zip(&self.outputs) {
            let codec = output.codec();
            let expected = match self.model {
                ModelKind::BitForest => codec.width() as usize,
                ModelKind::Threshold => codec.levels() - 1,
                ModelKind::PiecewiseLinear => unreachable!("refused above"),
            };
            if *width != expected {
                return Err(format!(
                    "`{name}`: the model's output is {width} bits wide, but its {} target's \
                     {} code of {} levels makes it {expected}",
                    self.target.kind(),
                    codec.code(),
                    codec.levels()
                ));
            }
        }
        Ok(decoders)
    }

    /// For a piecewise-linear model evaluated with `learned` (the
    /// codebook's learned entries, in order): per output, its variable's
    /// index among them and the indices of the inputs its tree reads — the
    /// learned variables, then for a hybrid ([`Base::Nominal`]) their
    /// nominal predictions at `learned.len()` on. On a mismatch, what
    /// differs.
    pub fn piecewise_for(&self, learned: &[&Entry]) -> std::result::Result<Vec<Reads>, String> {
        let width = learned.len();
        let variable = |name: &str| learned.iter().position(|e| e.variable == name);
        let unknown =
            |name: &str| format!("reads or predicts `{name}`, which the codebook does not learn");
        let input = |name: &str| {
            let nominal = (self.base == Base::Nominal)
                .then(|| (0..width).find(|&v| nominal_input(&learned[v].variable) == name))
                .flatten();
            variable(name)
                .or(nominal.map(|v| width + v))
                .ok_or_else(|| unknown(name))
        };
        let inputs = match self.base {
            Base::Current => width,
            Base::Nominal => 2 * width,
        };
        if self.inputs != inputs {
            return Err(format!(
                "reads {} inputs, but the codebook learns {width} variables{}",
                self.inputs,
                match self.base {
                    Base::Current => "",
                    Base::Nominal => ", which with their nominal predictions make twice as many",
                }
            ));
        }
        if self.reads.len() != self.outputs.len() {
            return Err(format!(
                "names the inputs of {} outputs, but has {}",
                self.reads.len(),
                self.outputs.len()
            ));
        }
        self.outputs
            .iter()
            .zip(&self.reads)
            .map(|((name, _), reads)| {
                Ok(Reads {
                    variable: variable(name).ok_or_else(|| unknown(name))?,
                    inputs: reads.iter().map(|r| input(r)).collect::<Result<_, _>>()?,
                })
            })
            .collect()
    }
}

/// Which learned variable a piecewise-linear output predicts, and which it
/// reads (indices among the codebook's learned variables, in the order of
/// the tree's inputs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Reads {
    pub variable: usize,
    pub inputs: Vec<usize>,
}

/// A model: its header and its trees.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    pub header: Header,
    /// A bit-forest's or threshold model's trees (none for a
    /// piecewise-linear model).
    pub trees: Vec<(TreeId, Tree)>,
    /// A piecewise-linear model's trees, one per output (none otherwise).
    pub pieces: Vec<crate::pwl::Tree>,
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

/// A model file's header and its trees' records as stored, unparsed: what
/// merging shards needs (a sort of records) without rebuilding any tree.
#[derive(Clone, Debug, PartialEq)]
pub struct RawModel {
    pub header: Header,
    /// Each tree's identity and its whole record (identity, leaves,
    /// literals, packed functions), in file order.
    pub records: Vec<(TreeId, Vec<u8>)>,
}

/// The bytes of one tree's record.
fn tree_record(id: TreeId, tree: &Tree) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(16 + 4 * tree.leaves() + tree.leaves() / 4);
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
    bytes
}

/// Writes a model file: magic, version, header, the tree records, then the
/// CRC-32 of everything before it (so a damaged byte is noticed on read).
fn write_file<'a>(
    path: &Path,
    header: &Header,
    records: impl Iterator<Item = std::borrow::Cow<'a, [u8]>>,
) -> Result<()> {
    let json = serde_json::to_vec(header).expect("headers serialize");
    atomic::write_file(path, |out| {
        let io = |e| Error::io(path, e);
        let mut crc = crc32fast::Hasher::new();
        let mut put = |bytes: &[u8]| {
            crc.update(bytes);
            out.write_all(bytes).map_err(io)
        };
        put(MAGIC)?;
        put(&MODEL_FORMAT.to_le_bytes())?;
        put(&(json.len() as u32).to_le_bytes())?;
        put(&json)?;
        for record in records {
            put(&record)?;
        }
        out.write_all(&crc.finalize().to_le_bytes()).map_err(io)
    })
}

fn u32_of(b: &[u8]) -> u32 {
    u32::from_le_bytes(b.try_into().expect("4 bytes"))
}

impl RawModel {
    /// Reads a model file's header and splits its trees' records, checking
    /// the layout: magic, version, the number of trees the header implies
    /// (for a shard's part, the shard's trees), power-of-two leaves, and
    /// nothing after the last tree. Returns each tree's input bits too, for
    /// the checks that need a parsed tree.
    fn read_checked(path: &Path) -> Result<(RawModel, Vec<usize>)> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Self::parse_checked(path, &bytes)
    }

    /// [`RawModel::read_checked`] on the file's bytes.
    fn parse_checked(path: &Path, bytes: &[u8]) -> Result<(RawModel, Vec<usize>)> {
        let bad = |what: String| Error::bad_file(path, what);
        if bytes.len() >= 24 && bytes[..16] == *MAGIC && u32_of(&bytes[16..20]) == MODEL_FORMAT {
            let (body, stored) = bytes.split_at(bytes.len() - 4);
            // Fuzzing explores the parser behind the checksum.
            if crc32fast::hash(body) != u32_of(stored) && !cfg!(fuzzing) {
                return Err(Error::damaged(path, "its CRC-32 does not match its bytes"));
            }
        }
        let bytes = &bytes[..bytes.len().saturating_sub(4)];
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
        let version = u32_of(take(4, "the format version")?);
        if version != MODEL_FORMAT {
            return Err(bad(format!(
                "model format {version}, this alnlab reads format {MODEL_FORMAT}"
            )));
        }
        let header_len = u32_of(take(4, "the header length")?) as usize;
        let header: Header = serde_json::from_slice(take(header_len, "the header")?)
            .map_err(|e| bad(format!("corrupt header ({e})")))?;
        // Each tree's input bits, in file order.
        let vote = header.vote as usize;
        // Bound what the header implies by what the file can hold before
        // allocating for it.
        let trees_per_vote = match header.model {
            ModelKind::BitForest => header
                .outputs
                .iter()
                .try_fold(0usize, |sum, &(_, width)| sum.checked_add(width)),
            ModelKind::Threshold | ModelKind::PiecewiseLinear => Some(header.outputs.len()),
        };
        trees_per_vote
            .and_then(|n| n.checked_mul(vote))
            .filter(|&n| n <= bytes.len() / SMALLEST_TREE)
            .ok_or_else(|| {
                bad(format!(
                    "its header promises more trees than {} bytes can hold",
                    bytes.len()
                ))
            })?;
        let piecewise = match header.model {
            ModelKind::PiecewiseLinear => true,
            ModelKind::BitForest | ModelKind::Threshold => false,
        };
        if piecewise {
            let mut records = Vec::with_capacity(header.outputs.len());
            for o in 0..header.outputs.len() {
                let what = format!("the tree of output {o}");
                let head = take(12, &what)?;
                let [inputs, nodes, pieces] = [0, 4, 8].map(|i| u32_of(&head[i..i + 4]) as usize);
                let body = nodes
                    .checked_mul(12)
                    .zip(pieces.checked_mul(inputs.saturating_add(1)))
                    .and_then(|(n, c)| c.checked_mul(8).and_then(|c| c.checked_add(n)))
                    .ok_or_else(|| bad(format!("{what}: its sizes overflow")))?;
                let mut record = head.to_vec();
                record.extend_from_slice(take(body, &what)?);
                let id = TreeId {
                    variable: o as u32,
                    bit: 0,
                    vote: 0,
                };
                records.push((id, record));
            }
            if at != bytes.len() {
                return Err(bad(format!(
                    "{} bytes after the last tree",
                    bytes.len() - at
                )));
            }
            return Ok((RawModel { header, records }, Vec::new()));
        }
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
            ModelKind::PiecewiseLinear => unreachable!("read above"),
        };
        let shard = header.shard.unwrap_or(Shard::ALL);
        let tree_inputs: Vec<usize> = all_inputs
            .into_iter()
            .enumerate()
            .filter(|&(position, _)| shard.owns(position))
            .map(|(_, inputs)| inputs)
            .collect();
        let mut records = Vec::with_capacity(tree_inputs.len());
        for t in 0..tree_inputs.len() {
            let what = format!("tree {t}");
            let head = take(16, &what)?;
            let fields: Vec<u32> = head.chunks_exact(4).map(u32_of).collect();
            let id = TreeId {
                variable: fields[0],
                bit: fields[1],
                vote: fields[2],
            };
            let leaves = fields[3] as usize;
            if leaves < 2 || !leaves.is_power_of_two() {
                return Err(bad(format!(
                    "tree {t}: {leaves} leaves is not a power of two ≥ 2"
                )));
            }
            let mut record = head.to_vec();
            record.extend_from_slice(take(4 * leaves + (leaves - 1).div_ceil(4), &what)?);
            records.push((id, record));
        }
        if at != bytes.len() {
            return Err(bad(format!(
                "{} bytes after the last tree",
                bytes.len() - at
            )));
        }
        Ok((RawModel { header, records }, tree_inputs))
    }

    /// Reads a model file without parsing its trees.
    pub fn read(path: &Path) -> Result<RawModel> {
        RawModel::read_checked(path).map(|(raw, _)| raw)
    }

    /// Writes the model file (atomically).
    pub fn write(&self, path: &Path) -> Result<()> {
        write_file(
            path,
            &self.header,
            self.records.iter().map(|(_, r)| r.as_slice().into()),
        )
    }
}

/// The bytes of one piecewise-linear tree's record.
fn piecewise_record(tree: &crate::pwl::Tree) -> Vec<u8> {
    use crate::pwl::Node;
    let (nodes, pieces) = (tree.nodes(), tree.pieces());
    let mut bytes = Vec::with_capacity(12 * (1 + nodes.len()) + 8 * pieces * (tree.inputs() + 1));
    for x in [tree.inputs(), nodes.len(), pieces] {
        bytes.extend_from_slice(&(x as u32).to_le_bytes());
    }
    for node in nodes {
        let fields = match *node {
            Node::Piece(p) => [0, p, 0],
            Node::Min(a, b) => [1, a, b],
            Node::Max(a, b) => [2, a, b],
        };
        for x in fields {
            bytes.extend_from_slice(&x.to_le_bytes());
        }
    }
    for p in 0..pieces {
        let (bias, weights) = tree.piece(p);
        for c in std::iter::once(&bias).chain(weights) {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    bytes
}

/// A piecewise-linear tree from its record (as [`RawModel`] split it).
fn piecewise_tree(record: &[u8]) -> std::result::Result<crate::pwl::Tree, String> {
    use crate::pwl::Node;
    let [inputs, nodes, _] = [0, 4, 8].map(|i| u32_of(&record[i..i + 4]) as usize);
    let node_bytes = &record[12..12 + 12 * nodes];
    let nodes = node_bytes
        .chunks_exact(12)
        .map(|n| {
            let [tag, a, b] = [0, 4, 8].map(|i| u32_of(&n[i..i + 4]));
            match tag {
                0 => Ok(Node::Piece(a)),
                1 => Ok(Node::Min(a, b)),
                2 => Ok(Node::Max(a, b)),
                _ => Err(format!("node kind {tag} is none of piece, MIN, MAX")),
            }
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let coefficients = record[12 + node_bytes.len()..]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    crate::pwl::Tree::from_parts(inputs, nodes, coefficients).map_err(|m| m.0)
}

impl Model {
    /// Writes the model to `path` (atomically).
    pub fn write(&self, path: &Path) -> Result<()> {
        let pieces = self.pieces.iter().map(|t| piecewise_record(t).into());
        write_file(
            path,
            &self.header,
            self.trees
                .iter()
                .map(|(id, tree)| tree_record(*id, tree).into())
                .chain(pieces),
        )
    }

    /// Reads a model file.
    pub fn read(path: &Path) -> Result<Model> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Model::from_bytes(path, &bytes)
    }

    /// Reads a model file held in `bytes` (`path` names it in errors).
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Model> {
        let (raw, tree_inputs) = RawModel::parse_checked(path, bytes)?;
        let bad = |what: String| Error::bad_file(path, what);
        let piecewise = match raw.header.model {
            ModelKind::PiecewiseLinear => true,
            ModelKind::BitForest | ModelKind::Threshold => false,
        };
        if piecewise {
            let pieces = raw
                .records
                .iter()
                .enumerate()
                .map(|(o, (_, record))| {
                    piecewise_tree(record).map_err(|m| bad(format!("the tree of output {o}: {m}")))
                })
                .collect::<Result<Vec<_>>>()?;
            return Ok(Model {
                header: raw.header,
                trees: Vec::new(),
                pieces,
            });
        }
        let mut trees = Vec::with_capacity(raw.records.len());
        for (t, ((id, record), inputs)) in raw.records.iter().zip(tree_inputs).enumerate() {
            let leaves = u32_of(&record[12..16]) as usize;
            let literals: Vec<u32> = record[16..16 + 4 * leaves]
                .chunks_exact(4)
                .map(u32_of)
                .collect();
            if let Some(l) = literals.iter().find(|&&l| l as usize >= 2 * inputs) {
                return Err(bad(format!(
                    "tree {t}: literal {l} beyond its {inputs} inputs"
                )));
            }
            let packed = &record[16 + 4 * leaves..];
            let functions: Vec<Function> = (0..leaves - 1)
                .map(|i| FUNCTIONS[usize::from(packed[i / 4] >> (2 * (i % 4)) & 3)])
                .collect();
            trees.push((
                *id,
                Tree::from_functions(&functions, literals, raw.header.counter_bound),
            ));
        }
        Ok(Model {
            header: raw.header,
            trees,
            pieces: Vec::new(),
        })
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
                target: Target::Level,
                inputs: 10,
                outputs: vec![("a.1.x".into(), 3), ("a.1.y".into(), 3)],
                reads: Vec::new(),
                vote: 1,
                counter_bound: 3,
                shard: None,
                base: Base::Current,
            },
            trees,
            pieces: Vec::new(),
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
        // 16 + 4 + 4 + header + 6 × (16 + 256 + 16) + 4 bytes.
        let header = serde_json::to_vec(&m.header).unwrap().len();
        assert_eq!(
            std::fs::metadata(&path).unwrap().len() as usize,
            24 + header + 6 * 288 + 4
        );
    }

    #[test]
    fn raw_records_and_shard_parts_round_trip_byte_for_byte() {
        let dir = tempfile::tempdir().unwrap();
        let (whole, again) = (dir.path().join("whole.aln"), dir.path().join("again.aln"));
        let m = model();
        m.write(&whole).unwrap();
        let raw = RawModel::read(&whole).unwrap();
        assert_eq!(raw.records.len(), m.trees.len());
        raw.write(&again).unwrap();
        assert_eq!(
            std::fs::read(&whole).unwrap(),
            std::fs::read(&again).unwrap()
        );

        // A shard's part holds its trees only, and reads back as such.
        let shard = Shard { index: 2, count: 4 };
        let mut part = m.clone();
        part.header.shard = Some(shard);
        part.trees = m
            .trees
            .iter()
            .enumerate()
            .filter(|(p, _)| shard.owns(*p))
            .map(|(_, t)| t.clone())
            .collect();
        let path = dir.path().join("part.aln");
        part.write(&path).unwrap();
        assert_eq!(Model::read(&path).unwrap(), part);
        // A whole model's trees under a part's header are too many.
        let mut wrong = m.clone();
        wrong.header.shard = Some(shard);
        wrong.write(&path).unwrap();
        let err = Model::read(&path).unwrap_err().to_string();
        assert!(err.contains("bytes after the last tree"), "{err}");
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
            let named = e.contains("model.aln: truncated") || e.contains("model.aln: damaged");
            assert!(named, "cut {cut}: {e}");
        }
        for at in 0..bytes.len() {
            let mut damaged = bytes.clone();
            damaged[at] ^= 0x40;
            let e = Model::from_bytes(&path, &damaged)
                .err()
                .unwrap_or_else(|| panic!("a flip at byte {at} was not noticed"));
            assert!(e.to_string().contains("model.aln"), "{e}");
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

    #[test]
    fn a_piecewise_linear_model_round_trips_and_a_malformed_tree_is_named() {
        use crate::pwl::{Node, Tree as Pwl};
        let mut m = model();
        m.header.model = ModelKind::PiecewiseLinear;
        m.header.target = Target::Change;
        m.header.inputs = 3;
        m.header.outputs = vec![("a.1.x".into(), 2), ("a.1.y".into(), 1)];
        m.header.reads = vec![vec!["a.1.x".into(), "b".into()], vec!["a.1.y".into()]];
        m.trees = Vec::new();
        let hinge = Pwl::from_parts(
            2,
            vec![Node::Max(1, 2), Node::Piece(0), Node::Piece(1)],
            vec![0.5, 1.0, -2.0, 0.25, 0.0, 3.0],
        )
        .unwrap();
        m.pieces = vec![hinge, Pwl::affine(-1.0, &[0.125])];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.aln");
        m.write(&path).unwrap();
        assert_eq!(Model::read(&path).unwrap(), m);
        // It has no level runtime, and says so rather than panicking.
        let refused = crate::runtime::Runtime::new(&m, &[], &[]).err();
        assert!(
            refused
                .as_deref()
                .is_some_and(|m| m.contains("real values")),
            "{refused:?}"
        );
        // The first tree's MAX names node 7 of 3, under a valid checksum.
        let mut bytes = std::fs::read(&path).unwrap();
        let header = serde_json::to_vec(&m.header).unwrap().len();
        let first_child = 24 + header + 12 + 4;
        assert_eq!(u32_of(&bytes[first_child..first_child + 4]), 1);
        bytes[first_child] = 7;
        let body = bytes.len() - 4;
        let crc = crc32fast::hash(&bytes[..body]);
        bytes[body..].copy_from_slice(&crc.to_le_bytes());
        let error = Model::from_bytes(&path, &bytes).unwrap_err().to_string();
        assert!(
            error.contains("the tree of output 0") && error.contains("child 7"),
            "{error}"
        );
        // Its header asking for more bytes than there are.
        let mut short = std::fs::read(&path).unwrap();
        short.truncate(short.len() - 20);
        let error = Model::from_bytes(&path, &short).unwrap_err().to_string();
        assert!(error.contains("model.aln"), "{error}");
    }

    /// A hybrid's trees read the learned variables and their nominal
    /// predictions, after them; its header says so, and a model of the
    /// dynamics never reads a nominal prediction.
    #[test]
    fn a_hybrids_trees_read_nominal_predictions_after_the_state() {
        let entry = |variable: &str| Entry {
            variable: variable.into(),
            learned: true,
            note: String::new(),
            quantizer: alnlab_codes::Quantizer {
                min: 0.0,
                max: 1.0,
                levels: 8,
            },
            code: alnlab_codes::Code::Gray,
            width: 3,
            walk_step: 0,
            walk_span: 0,
            seed: 0,
            clamped: 0,
        };
        let (a, b) = (entry("a"), entry("b"));
        let mut header = model().header;
        header.model = ModelKind::PiecewiseLinear;
        header.target = Target::Change;
        header.base = Base::Nominal;
        header.inputs = 4;
        header.outputs = vec![("b".into(), 1)];
        header.reads = vec![vec!["a".into(), nominal_input("a"), nominal_input("b")]];
        let reads = header.piecewise_for(&[&a, &b]).unwrap();
        assert_eq!(
            reads,
            [Reads {
                variable: 1,
                inputs: vec![0, 2, 3]
            }]
        );
        let json = serde_json::to_string(&header).unwrap();
        assert!(json.contains(r#""base":"nominal""#), "{json}");
        header.inputs = 2;
        let narrow = header.piecewise_for(&[&a, &b]).unwrap_err();
        assert!(
            narrow.contains("reads 2 inputs") && narrow.contains("twice as many"),
            "{narrow}"
        );
        header.base = Base::Current;
        let unknown = header.piecewise_for(&[&a, &b]).unwrap_err();
        assert!(unknown.contains("`nominal(a)`"), "{unknown}");
        // A model of the dynamics leaves `base` out of its header.
        let json = serde_json::to_string(&header).unwrap();
        assert!(!json.contains("base"), "{json}");
    }

    #[test]
    fn a_model_fits_only_codes_of_its_widths() {
        use alnlab_codes::{Code, DeltaSpec, Quantizer};
        let entry = |variable: &str, code, levels| {
            let codec = alnlab_codes::Codec::new(code, levels, None).unwrap();
            Entry {
                variable: variable.into(),
                learned: true,
                note: String::new(),
                quantizer: Quantizer {
                    min: 0.0,
                    max: 1.0,
                    levels,
                },
                code,
                width: codec.width(),
                walk_step: 0,
                walk_span: 0,
                seed: 0,
                clamped: 0,
            }
        };
        let (a, b) = (entry("a", Code::Gray, 8), entry("b", Code::Gray, 8));
        let (c, b16) = (entry("c", Code::Gray, 8), entry("b", Code::Binary, 16));
        let mut header = model().header;
        header.inputs = 6;
        header.outputs = vec![("a".into(), 3), ("b".into(), 3)];
        let outputs = header.outputs_for(&[&a, &b]).unwrap();
        assert_eq!(outputs.len(), 2);
        let renamed = header.outputs_for(&[&a, &c]).unwrap_err();
        assert!(renamed.contains("the codebook learns"), "{renamed}");
        let wider = header.outputs_for(&[&a, &b16]).unwrap_err();
        assert!(wider.contains("codes are 7 bits wide"), "{wider}");
        header.inputs = 7;
        let output = header.outputs_for(&[&a, &b16]).unwrap_err();
        assert!(
            output.contains("`b`") && output.contains("binary code of 16 levels makes it 4"),
            "{output}"
        );
        // A threshold model's outputs are the candidates' thermometer codes.
        header.model = ModelKind::Threshold;
        header.inputs = 6;
        header.outputs = vec![("a".into(), 7), ("b".into(), 7)];
        assert!(header.outputs_for(&[&a, &b]).is_ok());
        // A delta model's outputs are its changes' codes: ±2 is 5 levels.
        let spec = DeltaSpec {
            k: 2,
            period: None,
            code: Code::Gray,
        };
        header.target = Target::Delta(vec![spec; 2]);
        header.outputs = vec![("a".into(), 4), ("b".into(), 4)];
        assert!(header.outputs_for(&[&a, &b]).is_ok());
        header.model = ModelKind::BitForest;
        let err = header.outputs_for(&[&a, &b]).unwrap_err();
        assert!(
            err.contains("delta target's gray code of 5 levels makes it 3"),
            "{err}"
        );
    }
}
