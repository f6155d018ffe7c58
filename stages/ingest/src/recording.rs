//! A topic of `sensor_msgs/msg/JointState` messages read from a ROS 2
//! MCAP recording, every message decoded: a topic that is not there, of
//! another type or encoding, or a message that does not decode is refused
//! naming the file, the topic and the message.

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::mcap_read::{self, Wanted};
use alnlab_common::{Error, Result};
use mcap::records::Record;

use crate::joint_state::{self, JointState};

/// One message of the topic.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Its number on the topic, from 0, in file order.
    pub number: usize,
    /// When it was logged (the MCAP record's log time), in ns.
    pub log_time_ns: u64,
    pub state: JointState,
}

/// The schema encodings a ROS 2 writer gives a message definition.
const SCHEMA_ENCODINGS: [&str; 2] = ["ros2msg", "ros2idl"];

/// Every message on `topic` of the recording `path` held in `bytes`, in
/// file order.
pub fn read(path: &Path, bytes: &[u8], topic: &str) -> Result<Vec<Sample>> {
    let bad = |what: String| Error::bad_file(path, what);
    // Schema id → (name, encoding); every channel's topic and type.
    let mut schemas: BTreeMap<u16, (String, String)> = BTreeMap::new();
    let mut topics: BTreeMap<String, String> = BTreeMap::new();
    let mut ours: Option<u16> = None;
    let mut samples = Vec::new();
    let wanted = Wanted {
        schemas: true,
        channels: true,
        messages: true,
        metadata: false,
    };
    mcap_read::read(path, bytes, wanted, |record| {
        match record {
            Record::Schema { header, .. } => {
                schemas.insert(header.id, (header.name, header.encoding));
            }
            Record::Channel(channel) => {
                let (name, encoding) = schemas
                    .get(&channel.schema_id)
                    .cloned()
                    .unwrap_or_else(|| ("(no schema)".into(), String::new()));
                topics.insert(channel.topic.clone(), name.clone());
                if channel.topic != topic {
                    return Ok(());
                }
                let on = |what: String| bad(format!("topic `{topic}`: {what}"));
                if name != joint_state::SCHEMA_NAME {
                    return Err(on(format!(
                        "carries {name}, not {}",
                        joint_state::SCHEMA_NAME
                    )));
                }
                if !SCHEMA_ENCODINGS.contains(&encoding.as_str()) {
                    return Err(on(format!(
                        "its schema is encoded as `{encoding}`, not as a ROS 2 message \
                         definition ({})",
                        SCHEMA_ENCODINGS.join(" or ")
                    )));
                }
                if channel.message_encoding != "cdr" {
                    return Err(on(format!(
                        "its messages are encoded as `{}`, not as ROS 2's `cdr`",
                        channel.message_encoding
                    )));
                }
                if ours.is_some_and(|id| id != channel.id) {
                    return Err(on("is recorded on two channels".into()));
                }
                ours = Some(channel.id);
            }
            Record::Message { header, data } if Some(header.channel_id) == ours => {
                let number = samples.len();
                let state = joint_state::decode(&data).map_err(|what| {
                    bad(format!(
                        "topic `{topic}`, message {number} (logged at {} ns): {what}",
                        header.log_time
                    ))
                })?;
                samples.push(Sample {
                    number,
                    log_time_ns: header.log_time,
                    state,
                });
            }
            _ => {}
        }
        Ok(())
    })?;
    if ours.is_none() {
        let found: Vec<String> = topics.iter().map(|(t, ty)| format!("{t} ({ty})")).collect();
        return Err(bad(format!(
            "has no topic `{topic}`; it has {}",
            if found.is_empty() {
                "none".to_string()
            } else {
                found.join(", ")
            }
        )));
    }
    if samples.is_empty() {
        return Err(bad(format!("topic `{topic}` has no messages")));
    }
    Ok(samples)
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use mcap::records::MessageHeader;

    use super::*;

    /// A JointState message of one joint at `ns`, little-endian CDR.
    fn message(ns: u32) -> Vec<u8> {
        let mut m = vec![0, 1, 0, 0];
        m.extend_from_slice(&1u32.to_le_bytes()); // sec
        m.extend_from_slice(&ns.to_le_bytes()); // nanosec
        m.extend_from_slice(&[1, 0, 0, 0, 0]); // frame_id ""
        m.extend_from_slice(&[0, 0, 0]); // to 4
        m.extend_from_slice(&1u32.to_le_bytes()); // one name
        m.extend_from_slice(&[2, 0, 0, 0, b'j', 0]);
        m.extend_from_slice(&[0, 0]); // to 4
        for x in [0.5f64, 1.5, 2.5] {
            m.extend_from_slice(&1u32.to_le_bytes());
            // Doubles align to 8 from the body's start (byte 4).
            while (m.len() - 4) % 8 != 0 {
                m.push(0);
            }
            m.extend_from_slice(&x.to_le_bytes());
        }
        m
    }

    /// A recording of `messages` on `topic`, whose schema and encodings
    /// are given.
    fn recording(topic: &str, schema: &str, encoding: &str, messages: &[Vec<u8>]) -> Vec<u8> {
        let mut w = mcap::Writer::new(Cursor::new(Vec::new())).unwrap();
        let other = w
            .add_schema("std_msgs/msg/String", "ros2msg", b"string data")
            .unwrap();
        w.add_channel(other, "/chatter", "cdr", &BTreeMap::new())
            .unwrap();
        let schema = w.add_schema(schema, "ros2msg", b"...").unwrap();
        let channel = w
            .add_channel(schema, topic, encoding, &BTreeMap::new())
            .unwrap();
        for (i, data) in messages.iter().enumerate() {
            let header = MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: 10 + i as u64,
                publish_time: 10 + i as u64,
            };
            w.write_to_known_channel(&header, data).unwrap();
        }
        w.finish().unwrap();
        w.into_inner().into_inner()
    }

    #[test]
    fn reads_every_message_of_its_topic() {
        let bytes = recording(
            "/joint_states",
            joint_state::SCHEMA_NAME,
            "cdr",
            &[message(5), message(7)],
        );
        let samples = read(Path::new("r.mcap"), &bytes, "/joint_states").unwrap();
        assert_eq!(samples.len(), 2);
        assert_eq!(samples[1].number, 1);
        assert_eq!(samples[1].log_time_ns, 11);
        assert_eq!(samples[1].state.stamp_ns, 1_000_000_007);
        assert_eq!(samples[0].state.name, ["j"]);
        assert_eq!(samples[0].state.effort, [2.5]);
    }

    #[test]
    fn another_topic_type_or_encoding_is_named() {
        let path = Path::new("r.mcap");
        let good = [message(5)];
        let bytes = recording("/joint_states", joint_state::SCHEMA_NAME, "cdr", &good);
        let text = read(path, &bytes, "/joints").unwrap_err().to_string();
        assert_eq!(
            text,
            "r.mcap: has no topic `/joints`; it has /chatter (std_msgs/msg/String), \
             /joint_states (sensor_msgs/msg/JointState)"
        );
        let bytes = recording(
            "/joint_states",
            "geometry_msgs/msg/PoseStamped",
            "cdr",
            &good,
        );
        let text = read(path, &bytes, "/joint_states").unwrap_err().to_string();
        assert!(text.ends_with("topic `/joint_states`: carries geometry_msgs/msg/PoseStamped, not sensor_msgs/msg/JointState"), "{text}");
        let bytes = recording("/joint_states", joint_state::SCHEMA_NAME, "json", &good);
        let text = read(path, &bytes, "/joint_states").unwrap_err().to_string();
        assert!(
            text.contains("its messages are encoded as `json`, not as ROS 2's `cdr`"),
            "{text}"
        );
        let mut cut = message(5);
        cut.truncate(30);
        let bytes = recording("/joint_states", joint_state::SCHEMA_NAME, "cdr", &[cut]);
        let text = read(path, &bytes, "/joint_states").unwrap_err().to_string();
        assert!(
            text.starts_with(
                "r.mcap: topic `/joint_states`, message 0 (logged at 10 ns): ends early"
            ),
            "{text}"
        );
        let bytes = recording("/joint_states", joint_state::SCHEMA_NAME, "cdr", &[]);
        let text = read(path, &bytes, "/joint_states").unwrap_err().to_string();
        assert!(
            text.ends_with("topic `/joint_states` has no messages"),
            "{text}"
        );
        // Not MCAP at all.
        let text = read(path, b"PAR1....", "/joint_states")
            .unwrap_err()
            .to_string();
        assert!(text.starts_with("r.mcap: not an MCAP file"), "{text}");
    }
}
