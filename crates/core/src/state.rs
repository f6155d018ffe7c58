//! The `/state` message of the trajectory log (`trajectory.mcap`, written
//! and read by `alnlab-common`'s `state_log`): one message per logged frame,
//! encoded as ROS 2 CDR with a `ros2msg` schema stored in the file, so the
//! Python `mcap` reader (with its ROS 2 decoder) and Foxglove can decode it
//! without alnlab. This module holds the message, its codec and a log read
//! into memory; it needs no MCAP.
//!
//! Each scene gets its own channel on the `/state` topic (scenes differ in
//! their variable sets); the channel metadata names the scene and lists the
//! generalized-state components and the variables in message order. Every
//! field is a named `float64` except `run` and `frame` (`uint32`), so the CDR
//! layout is fixed: a 4-byte encapsulation header, then the fields in order,
//! each naturally aligned — which for this schema means no padding at all.

use std::collections::BTreeMap;

/// The topic of the full-rate state messages.
pub const STATE_TOPIC: &str = "/state";
/// Schema encoding of the state channels.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// Message encoding of the state channels.
pub const MESSAGE_ENCODING: &str = "cdr";
/// Name of the metadata record holding the provenance.
pub const PROVENANCE_RECORD: &str = "alnlab.provenance";

/// CDR encapsulation header: plain CDR, little endian.
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Bytes before the first f64 of the state: time (8), run (4), frame (4).
const FIXED_BYTES: usize = 16;

/// What one scene's `/state` messages hold, in order: time, run, frame, the
/// generalized state, then the learned variables.
#[derive(Clone, Debug, PartialEq)]
pub struct StateLayout {
    /// The scene's name (from the manifest).
    pub scene: String,
    /// Names of the generalized-state components (e.g. `root.q.w`).
    pub state: Vec<String>,
    /// Names of the variables (e.g. `omega.1.x`), the stable identifiers of
    /// docs/design.md §3.
    pub variables: Vec<String>,
}

/// One logged frame of one run (the default: an empty frame at time 0, to
/// be written into).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StateFrame {
    /// Simulated time since the start of the run, in seconds.
    pub time: f64,
    /// The run's index within its scene.
    pub run: u32,
    /// The frame's index within its run.
    pub frame: u32,
    /// The generalized state, in layout order.
    pub state: Vec<f64>,
    /// The variables, in layout order.
    pub variables: Vec<f64>,
}

impl StateLayout {
    /// The `ros2msg` schema text of this layout, fields named by [`field_name`].
    pub fn ros2msg(&self) -> String {
        let mut s = String::from(
            "# alnlab frame: simulated time (s), run index, frame index,\n\
             # then the generalized state, then the variables (see channel metadata)\n\
             float64 time\nuint32 run\nuint32 frame\n",
        );
        for name in self.state.iter().chain(&self.variables) {
            s.push_str("float64 ");
            s.push_str(&field_name(name));
            s.push('\n');
        }
        s
    }

    /// The schema name for the scene with index `scene_index` in the log.
    pub fn schema_name(scene_index: usize) -> String {
        format!("alnlab_msgs/msg/Scene{scene_index}State")
    }

    /// Channel metadata describing this layout.
    pub fn channel_metadata(&self) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("scene".to_string(), self.scene.clone()),
            ("state".to_string(), self.state.join(",")),
            ("variables".to_string(), self.variables.join(",")),
        ])
    }

    /// Rebuilds a layout from channel metadata.
    pub fn from_channel_metadata(meta: &BTreeMap<String, String>) -> Option<StateLayout> {
        let list = |key: &str| -> Option<Vec<String>> {
            let s = meta.get(key)?;
            Some(if s.is_empty() {
                Vec::new()
            } else {
                s.split(',').map(str::to_string).collect()
            })
        };
        Some(StateLayout {
            scene: meta.get("scene")?.clone(),
            state: list("state")?,
            variables: list("variables")?,
        })
    }

    /// Size of one encoded message.
    pub fn message_len(&self) -> usize {
        CDR_LE.len() + FIXED_BYTES + 8 * (self.state.len() + self.variables.len())
    }

    /// Encodes `frame` into `buf` (cleared first).
    pub fn encode(&self, frame: &StateFrame, buf: &mut Vec<u8>) {
        debug_assert_eq!(frame.state.len(), self.state.len());
        debug_assert_eq!(frame.variables.len(), self.variables.len());
        buf.clear();
        buf.extend_from_slice(&CDR_LE);
        buf.extend_from_slice(&frame.time.to_le_bytes());
        buf.extend_from_slice(&frame.run.to_le_bytes());
        buf.extend_from_slice(&frame.frame.to_le_bytes());
        for v in frame.state.iter().chain(&frame.variables) {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }

    /// Decodes one message; `None` if its length or header does not fit.
    pub fn decode(&self, data: &[u8]) -> Option<StateFrame> {
        if data.len() != self.message_len() || data[..4] != CDR_LE {
            return None;
        }
        let body = &data[4..];
        let f64_at = |i: usize| f64::from_le_bytes(body[i..i + 8].try_into().expect("8 bytes"));
        let u32_at = |i: usize| u32::from_le_bytes(body[i..i + 4].try_into().expect("4 bytes"));
        let values = |from: usize, n: usize| -> Vec<f64> {
            (0..n)
                .map(|k| f64_at(FIXED_BYTES + 8 * (from + k)))
                .collect()
        };
        Some(StateFrame {
            time: f64_at(0),
            run: u32_at(8),
            frame: u32_at(12),
            state: values(0, self.state.len()),
            variables: values(self.state.len(), self.variables.len()),
        })
    }
}

/// The ROS 2 field name of a dotted alnlab name: letters lower case, every
/// other character outside `[a-z0-9]` (a dot, or a `-` of a robot's link
/// name) an underscore, runs of underscores one and none at either end, as
/// ROS 2 allows only `[a-z][a-z0-9_]*` without `__` or a final `_` (readers
/// refuse a schema that breaks it); `f_` before a name that would not start
/// with a letter. So `f_E.1.x` is the field `f_e_1_x`, and a joint
/// `arm_2__j1`'s position `joint_arm_2_j1_q`.
pub fn field_name(name: &str) -> String {
    let mut field = String::with_capacity(name.len() + 2);
    for c in name.chars() {
        match c.to_ascii_lowercase() {
            c @ ('a'..='z' | '0'..='9') => field.push(c),
            _ if field.is_empty() || field.ends_with('_') => {}
            _ => field.push('_'),
        }
    }
    if field.ends_with('_') {
        field.pop();
    }
    if !field.starts_with(|c: char| c.is_ascii_lowercase()) {
        field.insert_str(0, "f_");
    }
    field
}

/// The frames of one scene, in log order.
#[derive(Debug)]
pub struct SceneFrames {
    /// The scene's layout.
    pub layout: StateLayout,
    /// Its frames, runs one after another, frames in order within a run.
    pub frames: Vec<StateFrame>,
}

/// Name of the metadata records holding what re-simulates each scene: its
/// resolved parameters, its index and the experiment seed; for recorded
/// data, where they came from (and which trajectory each run records, `run_trajectories`).
pub const SCENE_RECORD: &str = "alnlab.scene";

/// A whole trajectory log read into memory.
#[derive(Debug)]
pub struct StateLog {
    /// One entry per scene, in channel order.
    pub scenes: Vec<SceneFrames>,
    /// Metadata records (name, entries), in file order; names may repeat.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
}

impl StateLog {
    /// The entries of every metadata record called `name`.
    pub fn records<'a>(
        &'a self,
        name: &'a str,
    ) -> impl Iterator<Item = &'a BTreeMap<String, String>> {
        self.metadata
            .iter()
            .filter(move |(n, _)| n == name)
            .map(|(_, m)| m)
    }
}
