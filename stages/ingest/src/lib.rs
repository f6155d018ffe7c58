//! The ingest stage (issue 44): data from a robot rather than a simulation.
//! A ROS 2 recording (MCAP) of `sensor_msgs/msg/JointState` on one topic is
//! read and decoded ([`recording`], [`joint_state`]), its joints matched to
//! the robot's description by name and resampled onto frames
//! ([`frames`]). What it will write is what the simulate stage writes — the
//! trajectory log and its statistics — so every later stage learns and
//! evaluates as from a simulation; that part is not built yet.

pub mod frames;
pub mod joint_state;
pub mod recording;
