//! The trajectory log (`trajectory.mcap`): its writer and its reader. The
//! `/state` message it carries, its codec and the log read into memory are
//! `alnlab_core::state`'s, re-exported here.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

pub use alnlab_core::state::*;

use crate::{Error, Provenance, Result, atomic, mcap_read};

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
    fn add_json_channel(&mut self, topic: &str, schema_name: &str, schema: &str) -> Result<u16> {
        let writer = self.writer.as_mut().expect("writer present until finish");
        let schema_id = writer
            .add_schema(schema_name, "jsonschema", schema.as_bytes())
            .map_err(|e| Error::bad_file(&self.tmp, e))?;
        writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| Error::bad_file(&self.tmp, e))
    }

    /// Adds channels of JSON messages, each as `(topic, schema name,
    /// JSON schema)`; their ids, in order.
    pub fn add_json_channels<const N: usize>(
        &mut self,
        channels: [(&str, &str, String); N],
    ) -> Result<[u16; N]> {
        let mut ids = [0; N];
        for (id, (topic, name, schema)) in ids.iter_mut().zip(channels) {
            *id = self.add_json_channel(topic, name, &schema)?;
        }
        Ok(ids)
    }

    /// Writes one JSON message to a channel made by [`Self::add_json_channels`].
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

/// Reads and decodes the log at `path`. A truncated or corrupt file, or a
/// `/state` message that does not fit its schema, is an error naming the
/// file.
pub fn read(path: &Path) -> Result<StateLog> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    from_bytes(path, &bytes)
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
        let log = read(&path).unwrap();
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
            let err = read(&path).unwrap_err();
            assert!(err.to_string().contains("trajectory.mcap"), "{err}");
        }
    }

    #[test]
    fn every_flipped_byte_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("trajectory.mcap");
        write_frames(&path, 100);
        let bytes = std::fs::read(&path).unwrap();
        from_bytes(&path, &bytes).unwrap();
        // Every byte of the file, each bit pattern that changes it once:
        // the CRCs (data, summary, chunks) and the magic cover them all.
        for at in 0..bytes.len() {
            let mut damaged = bytes.clone();
            damaged[at] ^= 0x10;
            let err = from_bytes(&path, &damaged)
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
        let err = from_bytes(&path, &bytes).unwrap_err();
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
