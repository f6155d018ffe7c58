//! The trajectory log (`trajectory.mcap`): its `/state` channel, one message
//! per logged frame, encoded as ROS 2 CDR with a `ros2msg` schema stored in the
//! file, so the Python `mcap` reader (with its ROS 2 decoder) and Foxglove can
//! decode it without alnlab.
//!
//! Each scene gets its own channel on the `/state` topic (scenes differ in
//! their variable sets); the channel metadata names the scene and lists the
//! generalized-state components and the variables in message order. Every
//! field is a named `float64` except `run` and `frame` (`uint32`), so the CDR
//! layout is fixed: a 4-byte encapsulation header, then the fields in order,
//! each naturally aligned — which for this schema means no padding at all.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::{Error, Provenance, Result, atomic, mcap_read};

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
    /// DESIGN.md §3.
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

/// Writes a trajectory log under a temporary name; [`StateLogWriter::finish`]
/// renames it into place. Dropped unfinished, it removes the temporary file.
pub struct StateLogWriter {
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channels: Vec<(u16, StateLayout)>,
    sequence: u32,
    buf: Vec<u8>,
    tmp: PathBuf,
    path: PathBuf,
}

impl StateLogWriter {
    /// Starts a log at `path` with one `/state` channel per layout.
    pub fn create(path: &Path, layouts: &[StateLayout]) -> Result<StateLogWriter> {
        for layout in layouts {
            let mut fields = std::collections::BTreeSet::new();
            if let Some(dup) = layout
                .state
                .iter()
                .chain(&layout.variables)
                .find(|n| !fields.insert(field_name(n)))
            {
                return Err(Error::Invalid(format!(
                    "scene `{}`: field `{}` appears twice in the /state layout",
                    layout.scene,
                    field_name(dup)
                )));
            }
        }
        let tmp = atomic::temporary_name(path);
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        let file = File::create(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let mut log = StateLogWriter {
            writer: None,
            channels: Vec::new(),
            sequence: 0,
            buf: Vec::new(),
            tmp: tmp.clone(),
            path: path.to_path_buf(),
        };
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("ros2")
            .library(format!("alnlab {}", crate::ALNLAB_VERSION))
            .create(BufWriter::new(file))
            .map_err(|e| Error::bad_file(&tmp, e))?;
        for (i, layout) in layouts.iter().enumerate() {
            let schema = writer
                .add_schema(
                    &StateLayout::schema_name(i),
                    SCHEMA_ENCODING,
                    layout.ros2msg().as_bytes(),
                )
                .map_err(|e| Error::bad_file(&tmp, e))?;
            let channel = writer
                .add_channel(
                    schema,
                    STATE_TOPIC,
                    MESSAGE_ENCODING,
                    &layout.channel_metadata(),
                )
                .map_err(|e| Error::bad_file(&tmp, e))?;
            log.channels.push((channel, layout.clone()));
        }
        log.writer = Some(writer);
        Ok(log)
    }

    /// Appends one frame of scene `scene_index`, logged at `log_time_ns`
    /// (strictly increasing over the whole log, so readers that order by time
    /// keep runs apart).
    pub fn write(
        &mut self,
        scene_index: usize,
        log_time_ns: u64,
        frame: &StateFrame,
    ) -> Result<()> {
        let (channel_id, layout) = &self.channels[scene_index];
        let channel_id = *channel_id;
        layout.encode(frame, &mut self.buf);
        let buf = std::mem::take(&mut self.buf);
        let written = self.write_message(channel_id, log_time_ns, &buf);
        self.buf = buf;
        written
    }

    /// Writes one message, numbering it in sequence.
    fn write_message(&mut self, channel_id: u16, log_time_ns: u64, data: &[u8]) -> Result<()> {
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.writer
            .as_mut()
            .expect("writer present until finish")
            .write_to_known_channel(&header, data)
            .map_err(|e| Error::bad_file(&self.tmp, e))
    }

    /// Adds a channel of JSON messages with a JSON-schema (e.g. one of
    /// Foxglove's well-known schemas); returns its id for [`Self::write_json`].
    pub fn add_json_channel(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema: &str,
    ) -> Result<u16> {
        let writer = self.writer.as_mut().expect("writer present until finish");
        let schema_id = writer
            .add_schema(schema_name, "jsonschema", schema.as_bytes())
            .map_err(|e| Error::bad_file(&self.tmp, e))?;
        writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| Error::bad_file(&self.tmp, e))
    }

    /// Writes one JSON message to a channel made by [`Self::add_json_channel`].
    pub fn write_json(&mut self, channel_id: u16, log_time_ns: u64, json: &[u8]) -> Result<()> {
        self.write_message(channel_id, log_time_ns, json)
    }

    /// Adds a metadata record (e.g. the scene model as JSON).
    pub fn metadata(&mut self, name: &str, entries: BTreeMap<String, String>) -> Result<()> {
        let record = mcap::records::Metadata {
            name: name.to_string(),
            metadata: entries,
        };
        self.writer_mut()
            .write_metadata(&record)
            .map_err(|e| Error::bad_file(&self.tmp, e))
    }

    /// Writes the provenance record, finishes the file, syncs it and renames
    /// it to its final path.
    pub fn finish(mut self, provenance: &Provenance) -> Result<()> {
        self.metadata(
            PROVENANCE_RECORD,
            provenance.key_values().into_iter().collect(),
        )?;
        let mut writer = self.writer.take().expect("writer present until finish");
        writer.finish().map_err(|e| Error::bad_file(&self.tmp, e))?;
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| Error::io(&self.tmp, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&self.tmp, e))?;
        std::fs::rename(&self.tmp, &self.path).map_err(|e| Error::io(&self.path, e))
    }

    fn writer_mut(&mut self) -> &mut mcap::Writer<BufWriter<File>> {
        self.writer.as_mut().expect("writer present until finish")
    }
}

impl Drop for StateLogWriter {
    fn drop(&mut self) {
        if self.writer.is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// The frames of one scene, in log order.
#[derive(Debug)]
pub struct SceneFrames {
    /// The scene's layout.
    pub layout: StateLayout,
    /// Its frames, runs one after another, frames in order within a run.
    pub frames: Vec<StateFrame>,
}

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

    /// Reads and decodes the log at `path`. A truncated or corrupt file, or a
    /// `/state` message that does not fit its schema, is an error naming the
    /// file.
    pub fn read(path: &Path) -> Result<StateLog> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        StateLog::from_bytes(path, &bytes)
    }

    /// Decodes a whole log held in `bytes` (`path` names it in errors),
    /// every check of [`mcap_read::read`] made.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<StateLog> {
        use mcap::records::Record;

        let bad = |what: String| Error::bad_file(path, what);
        let mut scenes: Vec<SceneFrames> = Vec::new();
        let mut scene_of_channel = BTreeMap::new();
        let mut metadata = Vec::new();
        let wanted = mcap_read::Wanted {
            schemas: false,
            channels: true,
            messages: true,
            metadata: true,
        };
        mcap_read::read(path, bytes, wanted, |record| {
            match record {
                Record::Channel(channel) if channel.topic == STATE_TOPIC => {
                    let layout =
                        StateLayout::from_channel_metadata(&channel.metadata).ok_or_else(|| {
                            bad(format!(
                                "channel {} on {STATE_TOPIC} lacks its layout metadata",
                                channel.id
                            ))
                        })?;
                    if scene_of_channel.insert(channel.id, scenes.len()).is_some() {
                        return Err(bad(format!("channel {} is defined twice", channel.id)));
                    }
                    scenes.push(SceneFrames {
                        layout,
                        frames: Vec::new(),
                    });
                }
                Record::Metadata(record) => metadata.push((record.name, record.metadata)),
                Record::Message { header, data } => {
                    let Some(&scene) = scene_of_channel.get(&header.channel_id) else {
                        return Ok(());
                    };
                    let entry = &mut scenes[scene];
                    let frame = entry.layout.decode(&data).ok_or_else(|| {
                        bad(format!(
                            "message {} of scene `{}` does not fit its schema ({} bytes, expected {})",
                            header.sequence,
                            entry.layout.scene,
                            data.len(),
                            entry.layout.message_len()
                        ))
                    })?;
                    entry.frames.push(frame);
                }
                _ => {}
            }
            Ok(())
        })?;
        Ok(StateLog { scenes, metadata })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> StateLayout {
        StateLayout {
            scene: "s".into(),
            state: vec!["root.q.w".into()],
            variables: vec!["omega.1.x".into(), "omega.1.y".into()],
        }
    }

    fn frame(i: u32) -> StateFrame {
        StateFrame {
            time: f64::from(i) * 0.01,
            run: 1,
            frame: i,
            state: vec![1.0],
            variables: vec![f64::from(i), -0.5],
        }
    }

    /// A log of `frames` frames of one scene at `path`.
    fn write_frames(path: &Path, frames: u32) {
        let mut writer = StateLogWriter::create(path, &[layout()]).unwrap();
        for i in 0..frames {
            writer
                .write(0, u64::from(i) * 10_000_000, &frame(i))
                .unwrap();
        }
        writer.finish(&Provenance::default()).unwrap();
    }

    #[test]
    fn schema_names_every_field() {
        let text = layout().ros2msg();
        assert!(text.contains("float64 time\nuint32 run\nuint32 frame\nfloat64 root_q_w\n"));
        assert!(text.ends_with("float64 omega_1_x\nfloat64 omega_1_y\n"));
        // ROS 2 field names are lower case.
        assert_eq!(field_name("f_E.3.z"), "f_e_3_z");
        assert_eq!(
            field_name("joint.flying_arm_2__j_bl_link1.q"),
            "joint_flying_arm_2_j_bl_link1_q"
        );
        assert_eq!(field_name("v.link_._"), "v_link");
        assert_eq!(field_name("_1.x"), "f_1_x");
    }

    #[test]
    fn codec_round_trip_and_rejects_wrong_length() {
        let mut buf = Vec::new();
        layout().encode(&frame(3), &mut buf);
        assert_eq!(buf.len(), layout().message_len());
        assert_eq!(layout().decode(&buf), Some(frame(3)));
        assert_eq!(layout().decode(&buf[..buf.len() - 1]), None);
    }

    #[test]
    fn log_round_trip_and_truncation_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("trajectory.mcap");
        write_frames(&path, 100);
        let log = StateLog::read(&path).unwrap();
        assert_eq!(log.scenes.len(), 1);
        assert_eq!(log.scenes[0].layout, layout());
        assert_eq!(log.scenes[0].frames.len(), 100);
        assert_eq!(log.scenes[0].frames[42], frame(42));
        assert_eq!(
            log.metadata,
            [(
                PROVENANCE_RECORD.to_string(),
                Provenance::default().key_values().into_iter().collect()
            )]
        );

        let bytes = std::fs::read(&path).unwrap();
        for cut in [0, 8, bytes.len() / 2, bytes.len() - 3] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let err = StateLog::read(&path).unwrap_err();
            assert!(err.to_string().contains("trajectory.mcap"), "{err}");
        }
    }

    #[test]
    fn every_flipped_byte_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("trajectory.mcap");
        write_frames(&path, 100);
        let bytes = std::fs::read(&path).unwrap();
        StateLog::from_bytes(&path, &bytes).unwrap();
        // Every byte of the file, each bit pattern that changes it once:
        // the CRCs (data, summary, chunks) and the magic cover them all.
        for at in 0..bytes.len() {
            let mut damaged = bytes.clone();
            damaged[at] ^= 0x10;
            let err = StateLog::from_bytes(&path, &damaged)
                .err()
                .unwrap_or_else(|| panic!("a flip at byte {at} was not noticed"));
            assert!(err.to_string().contains("trajectory.mcap"), "{err}");
        }
    }

    #[test]
    fn a_huge_declared_chunk_is_refused_without_allocating_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("trajectory.mcap");
        let mut writer = StateLogWriter::create(&path, &[layout()]).unwrap();
        writer.write(0, 0, &frame(0)).unwrap();
        writer.finish(&Provenance::default()).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        // The chunk record (opcode 0x06) follows the header record; its
        // uncompressed_size is the third u64 of its body.
        let chunk = bytes.iter().position(|&b| b == 0x06).unwrap();
        let size_at = chunk + 1 + 8 + 16;
        bytes[size_at..size_at + 8].copy_from_slice(&(1u64 << 61).to_le_bytes());
        let err = StateLog::from_bytes(&path, &bytes).unwrap_err();
        assert!(err.to_string().contains("trajectory.mcap"), "{err}");
    }

    #[test]
    fn duplicate_fields_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut bad = layout();
        bad.state.push("omega.1.x".into());
        let err = StateLogWriter::create(&dir.path().join("t.mcap"), &[bad])
            .err()
            .unwrap();
        assert!(
            err.to_string().contains("`omega_1_x` appears twice"),
            "{err}"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn unfinished_writer_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.mcap");
        {
            let mut writer = StateLogWriter::create(&path, &[layout()]).unwrap();
            writer.write(0, 0, &frame(0)).unwrap();
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
