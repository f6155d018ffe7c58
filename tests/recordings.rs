//! Learning from a robot's ROS 2 recording (`[data] recording`): a good
//! recording of the UR5's joint states is ingested in the simulate stage's
//! place, and every bad one — a missing topic, another message type,
//! joints the robot lacks or misses, time going backwards, a gap, damage —
//! and every manifest that cannot go with a recording is refused, naming
//! the file, the topic and the time. The same samples as tables (`[data]
//! tables`, CSV) give the same frames, and bad tables are refused naming
//! the file, the column and the row.

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use mcap::records::MessageHeader;

use crate::common::{
    UR5_JOINTS as JOINTS, alnlab, case, check_all, stderr, ur5_table_header, write_manifest,
};

/// One JointState message: its stamp (ns) and joint names.
struct Message {
    stamp_ns: i64,
    names: Vec<String>,
}

impl Message {
    /// Joint `j`'s position, velocity and effort at the message's stamp.
    fn values(&self, j: usize) -> [f64; 3] {
        let t = (self.stamp_ns % 1_000_000_000_000) as f64 * 1e-9;
        [
            0.3 * (t + j as f64).sin(),
            0.3 * (t + j as f64).cos(),
            1.0 + j as f64,
        ]
    }

    fn at(ms: i64) -> Message {
        Message {
            stamp_ns: 1_700_000_000_000_000_000 + ms * 1_000_000,
            names: JOINTS.iter().map(|j| j.to_string()).collect(),
        }
    }

    /// Little-endian CDR, as ROS 2 writes it: the joints at rest but for a
    /// slow swing of every position.
    fn cdr(&self) -> Vec<u8> {
        fn align(m: &mut Vec<u8>, to: usize) {
            while !(m.len() - 4).is_multiple_of(to) {
                m.push(0);
            }
        }
        fn string(m: &mut Vec<u8>, s: &str) {
            align(m, 4);
            m.extend_from_slice(&(s.len() as u32 + 1).to_le_bytes());
            m.extend_from_slice(s.as_bytes());
            m.push(0);
        }
        let mut m = vec![0, 1, 0, 0];
        m.extend_from_slice(&((self.stamp_ns / 1_000_000_000) as i32).to_le_bytes());
        m.extend_from_slice(&((self.stamp_ns % 1_000_000_000) as u32).to_le_bytes());
        string(&mut m, "base_link");
        align(&mut m, 4);
        m.extend_from_slice(&(self.names.len() as u32).to_le_bytes());
        for name in &self.names {
            string(&mut m, name);
        }
        for field in 0..3 {
            align(&mut m, 4);
            m.extend_from_slice(&(self.names.len() as u32).to_le_bytes());
            align(&mut m, 8);
            for j in 0..self.names.len() {
                m.extend_from_slice(&self.values(j)[field].to_le_bytes());
            }
        }
        m
    }
}

/// A recording at `path` of `messages` on `topic`, of type `schema`.
fn record(path: &Path, topic: &str, schema: &str, messages: &[Message]) {
    let mut w = mcap::Writer::new(Cursor::new(Vec::new())).unwrap();
    let schema = w.add_schema(schema, "ros2msg", b"(definition)").unwrap();
    let channel = w
        .add_channel(schema, topic, "cdr", &BTreeMap::new())
        .unwrap();
    for (k, message) in messages.iter().enumerate() {
        let header = MessageHeader {
            channel_id: channel,
            sequence: k as u32,
            log_time: message.stamp_ns as u64 + 1_000_000,
            publish_time: message.stamp_ns as u64,
        };
        w.write_to_known_channel(&header, &message.cdr()).unwrap();
    }
    w.finish().unwrap();
    std::fs::write(path, w.into_inner().into_inner()).unwrap();
}

/// Messages every 10 ms for `seconds`.
fn steady(seconds: f64) -> Vec<Message> {
    (0..(seconds * 100.0) as i64)
        .map(|k| Message::at(10 * k))
        .collect()
}

/// `messages` as a CSV table: a time column `t` (s from the first), then
/// each joint's `<joint>.position`, `.velocity` and `.effort`.
fn table(path: &Path, messages: &[Message]) {
    let mut text = ur5_table_header() + "\n";
    for m in messages {
        text += &format!("{}", (m.stamp_ns - messages[0].stamp_ns) as f64 * 1e-9);
        for j in 0..JOINTS.len() {
            for x in m.values(j) {
                text += &format!(",{x:?}");
            }
        }
        text += "\n";
    }
    std::fs::write(path, text).unwrap();
}

/// A manifest learning from `recording`, with `extra` appended.
fn manifest(recording: &str, extra: &str) -> String {
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/ur5/ur5_robot.urdf");
    format!(
        r#"
[experiment]
name = "recorded"
seed = 3

[data]
recording = "{recording}"

[ingest.robot]
name = "ur5"
kind = "urdf"
file = "{}"
dt = 0.001
frame_dt = 0.01
link_velocities = ["wrist_3_link"]

[stride]
n = 1
split = "disjoint"
test_fraction = 0.5
{extra}"#,
        urdf.display()
    )
}

#[test]
fn a_recording_is_ingested_where_the_simulation_would_be() {
    let dir = tempfile::tempdir().unwrap();
    record(
        &dir.path().join("r.mcap"),
        "/joint_states",
        "sensor_msgs/msg/JointState",
        &steady(1.0),
    );
    let m = write_manifest(dir.path(), "m.toml", &manifest("r.mcap", ""));
    let out = dir.path().join("out");
    let o = alnlab(
        dir.path(),
        &[
            "-q",
            "run",
            m.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--until",
            "stride",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    // The ingest stage's artifact, in the simulate stage's place: no
    // simulation ran.
    let made = |stage: &str| -> Vec<std::path::PathBuf> {
        std::fs::read_dir(out.join("cache").join(stage))
            .map(|d| d.map(|e| e.unwrap().path()).collect())
            .unwrap_or_default()
    };
    assert!(made("simulate").is_empty());
    let [ingested] = made("ingest").try_into().expect("one ingest artifact");
    assert_eq!(made("stride").len(), 1);
    // 100 messages over 0.99 s: 100 frames, 98 logged (each needs one on
    // either side for its acceleration).
    let log = alnlab_common::state_log::read(&ingested.join("trajectory.mcap")).unwrap();
    assert_eq!(log.scenes[0].frames.len(), 98);
    assert!(ingested.join("stats.parquet").is_file());
}

/// A manifest learning from the CSV tables `tables` (a TOML value), with
/// `extra` appended.
fn tables_manifest(tables: &str, extra: &str) -> String {
    manifest("-", extra).replace(
        "recording = \"-\"",
        &format!("tables = {tables}\n\n[ingest.table]\ntime = \"t\""),
    )
}

/// The ingest stage's trajectory log in the run folder `out`.
fn ingested(out: &Path) -> alnlab_common::state_log::StateLog {
    let [dir]: [std::path::PathBuf; 1] = std::fs::read_dir(out.join("cache/ingest"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect::<Vec<_>>()
        .try_into()
        .expect("one ingest artifact");
    alnlab_common::state_log::read(&dir.join("trajectory.mcap")).unwrap()
}

#[test]
fn tables_of_the_same_samples_give_the_recordings_frames_one_run_a_table() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |manifest: &str, text: String| {
        let m = write_manifest(d, manifest, &text);
        let out = d.join(format!("out-{manifest}"));
        let (m, o) = (m.to_str().unwrap(), out.to_str().unwrap());
        let o = alnlab(d, &["-q", "run", m, "--out", o, "--until", "stride"]);
        assert!(o.status.success(), "{}", stderr(&o));
        ingested(&out)
    };
    // The recording split by a gap where the tables split by file: its
    // messages 60.. 0.2 s later, a run of their own; the same messages in
    // two tables.
    let mut gapped = steady(1.0);
    for m in &mut gapped[60..] {
        m.stamp_ns += 200_000_000;
    }
    record(
        &d.join("gapped.mcap"),
        "/joint_states",
        "sensor_msgs/msg/JointState",
        &gapped,
    );
    table(&d.join("a.csv"), &gapped[..60]);
    table(&d.join("b.csv"), &gapped[60..]);
    let from_mcap = run(
        "mcap.toml",
        manifest("gapped.mcap", "").replace(
            "[ingest.robot]",
            "[ingest]\ngaps = \"split\"\n\n[ingest.robot]",
        ),
    );
    let from_tables = run("tables.toml", tables_manifest("\"*.csv\"", ""));
    let (a, b) = (&from_mcap.scenes[0].frames, &from_tables.scenes[0].frames);
    // Two runs of 60 and 40 samples: 58 and 38 frames logged.
    assert_eq!(b.len(), 96);
    assert_eq!(b.iter().filter(|f| f.run == 1).count(), 38);
    for (x, y) in a.iter().zip(b) {
        assert_eq!((x.run, x.frame), (y.run, y.frame));
        // The same samples; the tables' times count from each file's first.
        let close = |u: &[f64], v: &[f64]| u.iter().zip(v).all(|(u, v)| (u - v).abs() < 1e-12);
        assert!(
            close(&x.state, &y.state) && close(&x.variables, &y.variables),
            "run {} frame {}: {:?} {:?} against {:?} {:?}",
            x.run,
            x.frame,
            x.state,
            x.variables,
            y.state,
            y.variables
        );
    }
    assert_eq!(a.len(), b.len());
    let scene = |log: &alnlab_common::state_log::StateLog| -> BTreeMap<String, String> {
        log.metadata
            .iter()
            .find(|(name, _)| name == "alnlab.scene")
            .expect("a scene record")
            .1
            .clone()
    };
    let record = scene(&from_tables);
    assert_eq!(record["source"], "tables");
    assert_eq!(record["table.0.file"], "a.csv");
    assert_eq!(record["table.1.samples"], "40");
    assert_eq!(record["run_trajectories"], "0,1");
    assert_eq!(record["table.1.trajectory"], "1");
    let hz: f64 = record["table.0.implied_hz"].parse().unwrap();
    assert!((hz - 100.0).abs() < 0.5, "{hz}");
    // Named as repeats of one trajectory, the two tables are one.
    let repeated = run(
        "repeats.toml",
        tables_manifest("\"*.csv\"", "").replace(
            "[ingest.table]",
            "[ingest]\nrepeats = [[\"b.csv\", \"a.csv\"]]\n\n[ingest.table]",
        ),
    );
    let record = scene(&repeated);
    assert_eq!(record["run_trajectories"], "0,0");
    assert_eq!(record["table.1.trajectory"], "0");
}

#[test]
fn bad_recordings_and_what_cannot_go_with_one_are_refused_by_name_and_time() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = steady(1.0);
    let joint_states = "sensor_msgs/msg/JointState";
    record(
        &d.join("other-topic.mcap"),
        "/joint_state",
        joint_states,
        &good,
    );
    record(
        &d.join("other-type.mcap"),
        "/joint_states",
        "geometry_msgs/msg/PoseStamped",
        &good,
    );
    let mut gripper = steady(1.0);
    gripper[10].names.push("gripper_joint".into());
    record(
        &d.join("gripper.mcap"),
        "/joint_states",
        joint_states,
        &gripper,
    );
    let mut five = steady(1.0);
    five[20].names.pop();
    record(&d.join("five.mcap"), "/joint_states", joint_states, &five);
    let mut backwards = steady(1.0);
    backwards[50].stamp_ns = backwards[48].stamp_ns;
    record(
        &d.join("backwards.mcap"),
        "/joint_states",
        joint_states,
        &backwards,
    );
    let mut gap = steady(1.0);
    for m in &mut gap[30..] {
        m.stamp_ns += 200_000_000;
    }
    record(&d.join("gap.mcap"), "/joint_states", joint_states, &gap);
    record(
        &d.join("damaged.mcap"),
        "/joint_states",
        joint_states,
        &good,
    );
    let mut bytes = std::fs::read(d.join("damaged.mcap")).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x40;
    std::fs::write(d.join("damaged.mcap"), bytes).unwrap();

    table(&d.join("good.csv"), &good);
    let mut nan = steady(1.0);
    nan[40].stamp_ns = nan[38].stamp_ns;
    table(&d.join("backwards.csv"), &nan);
    let text = std::fs::read_to_string(d.join("good.csv")).unwrap();
    std::fs::write(d.join("nan.csv"), text.replacen(",1.0,", ",NaN,", 1)).unwrap();
    std::fs::write(
        d.join("no-effort.csv"),
        text.replace("wrist_3_joint.effort", "wrist_3_joint.torque"),
    )
    .unwrap();

    let run = |name: &str, text: String, mentions: &[&str]| {
        let m = write_manifest(d, &format!("{name}.toml"), &text);
        let out = d.join(format!("out-{name}"));
        let (m, out) = (m.to_str().unwrap(), out.to_str().unwrap());
        case(
            name,
            &["-q", "run", m, "--out", out, "--until", "stride"],
            mentions,
            None,
        )
        .exits(2)
    };
    let with = |recording: &str| manifest(recording, "");
    let cases = vec![
        run(
            "missing-topic",
            with("other-topic.mcap"),
            &[
                "other-topic.mcap: has no topic `/joint_states`; it has /joint_state (sensor_msgs/msg/JointState)",
            ],
        ),
        run(
            "another-type",
            with("other-type.mcap"),
            &[
                "other-type.mcap: topic `/joint_states`: carries geometry_msgs/msg/PoseStamped, not sensor_msgs/msg/JointState",
            ],
        ),
        run(
            "a-joint-the-robot-lacks",
            with("gripper.mcap"),
            &[
                "gripper.mcap: topic `/joint_states`, at 0.100 s (message 10, stamp 1700000000.100000000)",
                "joint `gripper_joint` is not one of the moving joints of",
                "ur5_robot.urdf (shoulder_pan_joint, shoulder_lift_joint",
            ],
        ),
        run(
            "a-joint-missing",
            with("five.mcap"),
            &[
                "five.mcap: topic `/joint_states`, at 0.200 s (message 20",
                "lacks joint `wrist_3_joint`",
            ],
        ),
        run(
            "time-going-backwards",
            with("backwards.mcap"),
            &[
                "backwards.mcap: topic `/joint_states`, at 0.480 s (message 50, stamp 1700000000.480000000): time goes backwards: message 49 before it is stamped 1700000000.490000000",
            ],
        ),
        run(
            "a-gap",
            with("gap.mcap"),
            &[
                "gap.mcap: topic `/joint_states`, at 0.500 s (message 30, stamp 1700000000.500000000): a gap of 0.210 s after message 29, longer than max_gap = 0.05 s",
                "ingest.gaps = \"split\"",
            ],
        ),
        run("damaged", with("damaged.mcap"), &["damaged.mcap: damaged"]).exits(1),
        run(
            "no-such-file",
            with("none.mcap"),
            &["data.recording", "none.mcap"],
        ),
        run(
            "a-plan-task",
            manifest(
                "other-topic.mcap",
                "\n[[plan.task]]\nkind = \"hold-angles\"\nname = \"t\"\ntargets = { \"q.elbow_joint\" = 0.5 }\n",
            ),
            &[
                "plan.task",
                "recorded data have none",
                "remove [[plan.task]]",
            ],
        ),
        run(
            "simulate-beside",
            manifest("other-topic.mcap", "\n[[simulate.scene]]\nname = \"w\"\n"),
            &["simulate", "the data come from `[data]`'s recorded data"],
        ),
        run(
            "a-table-lacks-a-column",
            tables_manifest("[\"good.csv\", \"no-effort.csv\"]", ""),
            &[
                "no-effort.csv: no column `wrist_3_joint.effort` (its columns: t, shoulder_pan_joint.position",
            ],
        ),
        run(
            "a-table-goes-backwards",
            tables_manifest("\"backwards.csv\"", ""),
            &["backwards.csv: column `t`, row 41: time goes backwards"],
        ),
        run(
            "a-table-holds-nan",
            tables_manifest("\"nan.csv\"", ""),
            &["nan.csv: column `shoulder_pan_joint.effort`, row 1: NaN"],
        ),
        run(
            "a-rate-the-data-contradict",
            tables_manifest("\"good.csv\"", "").replace("time = \"t\"", "rate = 50"),
            &[
                "good.csv: the positions and velocities imply samples 10.00 ms apart (100.0 Hz",
                "rate = 50 Hz puts them 20.00 ms apart",
            ],
        ),
        run(
            "repeats-naming-no-table",
            tables_manifest("\"good.csv\"", "").replace(
                "[ingest.table]",
                "[ingest]\nrepeats = [[\"good.csv\", \"god.csv\"]]\n\n[ingest.table]",
            ),
            &[
                "ingest.repeats[0]",
                "`god.csv` is none of the tables (`good.csv`)",
            ],
        ),
        run(
            "a-glob-matching-nothing",
            tables_manifest("\"trajectories/*.parquet\"", ""),
            &["data.tables", "`trajectories/*.parquet` matches no file"],
        ),
        run(
            "a-recording-and-tables",
            manifest("good.mcap", "").replace("[data]", "[data]\ntables = \"good.csv\""),
            &["data", "not more"],
        ),
        run(
            "columns-for-a-recording",
            manifest("other-topic.mcap", "").replace(
                "[ingest.robot]",
                "[ingest.table]\ntime = \"t\"\n\n[ingest.robot]",
            ),
            &[
                "ingest.table",
                "a recording's joints are named in its messages",
            ],
        ),
        run(
            "not-a-robot",
            with("other-topic.mcap").replace("kind = \"urdf\"", "kind = \"worm\""),
            &["ingest.robot.kind", "expected \"urdf\""],
        ),
    ];
    check_all(d, &cases);
}
