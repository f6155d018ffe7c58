"""Records a simulated robot as a ROS 2 robot records itself: its joint
states as `sensor_msgs/msg/JointState` on `/joint_states` in an MCAP file,
written by mcap-ros2-support's writer (no ROS installation).

The frames come from a trajectory log the simulate stage wrote — of a plant
scene, the frames of the plant — read through the alnlab package
(`alnlab.Scene(...).logged()`). Each message is what a driver publishes:
joint positions, velocities and efforts (the effort the joint's drive
applied, where the log has it, else the command), each with sensor noise and
quantized to an encoder's, a velocity estimate's and a current sensor's
resolution, stamped about every `--period` seconds with jitter, logged a
little later than stamped; between the log's runs the recording pauses
(`--pause` s), a gap a reader must split at.

Example:
    python tests/record_joint_states.py runs/cache/simulate/<key>/trajectory.mcap \\
        recordings/ur5.mcap --plant --seed 43
"""

import argparse
import sys

import numpy as np
from mcap_ros2.writer import Writer

import alnlab

JOINT_STATE = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""


def quantized(x: np.ndarray, step: float) -> np.ndarray:
    return np.round(x / step) * step


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("trajectory", help="a trajectory log (trajectory.mcap) of one robot scene")
    parser.add_argument("out", help="the recording to write (.mcap)")
    parser.add_argument("--plant", action="store_true", help="the scene's plant frames (they are the log's)")
    parser.add_argument("--period", type=float, default=0.01, help="seconds between messages (default: 0.01)")
    parser.add_argument("--jitter", type=float, default=5e-4, help="stamp jitter, s (default: 0.0005)")
    parser.add_argument("--pause", type=float, default=5.0, help="seconds between runs (default: 5)")
    parser.add_argument("--seed", type=int, default=43, help="the noise's seed (default: 43)")
    args = parser.parse_args()

    scene = alnlab.Scene(args.trajectory, plant=args.plant)
    runs, frames, states, variables = scene.logged()
    joints = [n[2:] for n in scene.variable_names if n.startswith("q.")]
    column = {n: i for i, n in enumerate(scene.variable_names)}
    state_column = {n: i for i, n in enumerate(scene.state_names)}
    q = variables[:, [column[f"q.{j}"] for j in joints]]
    qd = variables[:, [column[f"qd.{j}"] for j in joints]]
    if all(f"joint.{j}.applied" in state_column for j in joints):
        effort = states[:, [state_column[f"joint.{j}.applied"] for j in joints]]
    else:
        effort = variables[:, [column[f"tau.{j}"] for j in joints]]
    rng = np.random.default_rng(args.seed)
    frame_dt = scene.frame_dt
    every = max(1, round(args.period / frame_dt))
    start_ns = 1_700_000_000 * 10**9
    with open(args.out, "wb") as f:
        writer = Writer(f)
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        sequence = 0
        for run in np.unique(runs):
            rows = np.flatnonzero(runs == run)
            # Drivers publish about every period, not exactly.
            steps = [max(1, every - 1), every, every + 1] if every > 1 else [1]
            picked, k = [], 0
            while k < len(rows):
                picked.append(rows[k])
                k += int(rng.choice(steps))
            for i in picked:
                stamp = start_ns + int(round(frames[i] * frame_dt * 1e9 + rng.normal(0.0, args.jitter * 1e9)))
                n = len(joints)
                message = {
                    "header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9}, "frame_id": ""},
                    "name": joints,
                    "position": quantized(q[i] + rng.normal(0.0, 1e-4, n), 2.0**-17).tolist(),
                    "velocity": quantized(qd[i] + rng.normal(0.0, 5e-3, n), 2.0**-10).tolist(),
                    "effort": quantized(effort[i] + rng.normal(0.0, 0.2, n), 2.0**-6).tolist(),
                }
                delay = int(rng.uniform(2e5, 2e6))
                writer.write_message(
                    "/joint_states", schema, message, log_time=stamp + delay, publish_time=stamp, sequence=sequence
                )
                sequence += 1
            start_ns += int(round((frames[rows[-1]] * frame_dt + args.pause) * 1e9))
        writer.finish()
    print(f"{args.out}: {sequence} JointState messages of {len(joints)} joints, {len(np.unique(runs))} runs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
