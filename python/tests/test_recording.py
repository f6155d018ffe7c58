"""A recording written by a standard ROS 2 writer (mcap-ros2-support, no ROS
installation) from a simulated plant, with sensor noise and jittered
stamps, learned end to end, and its model used from Python."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

import alnlab

ROOT = Path(__file__).resolve().parents[2]
UR5 = ROOT / "robots/ur5/ur5_robot.urdf"

SOURCE = f"""
[experiment]
name = "source"
seed = 5

[[simulate.scene]]
name = "ur5"
kind = "urdf"
file = "{UR5}"
runs = 2
duration = 6.0
dt = 0.001
frame_dt = 0.002
hinge_damping = 2.0
controller = {{ kind = "random", amplitude = [40.0, 60.0, 30.0, 8.0, 8.0, 2.0], hold = 0.25 }}
link_velocities = ["wrist_3_link"]
velocity_limits = true

[simulate.scene.plant]
payload = {{ link = "tool0", mass = 1.5, offset = [0.0, 0.0, 0.05] }}
viscous_friction = 1.0
actuator_gain = 0.95
actuator_lag = 0.005
"""

LEARN = f"""
[experiment]
name = "recorded"
seed = 9

[data]
recording = "arm.mcap"

[ingest]
gaps = "split"

[ingest.robot]
name = "ur5"
kind = "urdf"
file = "{UR5}"
dt = 0.001
frame_dt = 0.01
hinge_damping = 2.0
link_velocities = ["wrist_3_link"]

[stride]
n = 1
split = "disjoint"
test_fraction = 0.5

[quantize]
levels = 64

[train]
model = "piecewise-linear"
controls = "given"
informative_inputs = 4
pwl.max_pieces = 8

[test]
resimulate_steps = [10]
rollout_starts = 20
horizon = 5
peer = true
"""


def run(alnlab_bin: Path, *args, cwd: Path) -> None:
    done = subprocess.run([alnlab_bin, "-q", *map(str, args)], cwd=cwd, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_a_ros2_recording_of_a_plant_is_learned_end_to_end(alnlab_bin, tmp_path):
    (tmp_path / "source.toml").write_text(SOURCE)
    run(alnlab_bin, "run", "source.toml", "--out", tmp_path / "runs", "--until", "simulate", cwd=tmp_path)
    [trajectory] = (tmp_path / "runs/cache/simulate").glob("*/trajectory.mcap")
    writer = ROOT / "tests/record_joint_states.py"
    done = subprocess.run(
        [sys.executable, writer, trajectory, tmp_path / "arm.mcap", "--plant", "--pause", "1"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert "JointState messages of 6 joints, 2 runs" in done.stdout

    (tmp_path / "learn.toml").write_text(LEARN)
    run(alnlab_bin, "run", "learn.toml", "--out", tmp_path / "runs", cwd=tmp_path)
    record = json.loads((tmp_path / "runs/recorded/run.json").read_text())
    assert record["recording"]["topic"] == "/joint_states"
    stages = [s["stage"] for s in record["variants"][0]["stages"]]
    assert stages[0] == "ingest" and "simulate" not in stages
    predictions = pq.read_table(record["variants"][0]["artifacts"]["predictions"]["path"])
    models = set(predictions.column("model").to_pylist())
    assert {"aln", "persistence", "linear", "simulator@10/frame"} <= models
    # The pause between the runs split them: frames of two runs.
    scene = alnlab.scene("recorded", out=tmp_path / "runs")
    runs, frames, states, variables = scene.logged()
    assert set(runs.tolist()) == {0, 1} and frames.min() == 0
    # Its model predicts from Python what the test stage predicted.
    model = alnlab.load("recorded", out=tmp_path / "runs")
    pairs = alnlab.table("recorded", "pairs", out=tmp_path / "runs")
    x = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.state_names])
    u = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.control_names])
    levels = model.predict(x, u, levels=True)
    table = predictions.to_pylist()
    column = {n: k for k, n in enumerate(model.state_names)}
    checked = 0
    for row in table:
        if row["model"] == "aln":
            assert levels[row["row"], column[row["variable"]]] == row["predicted_level"]
            checked += 1
    assert checked > 100
    # So do the baselines the test stage fitted, the boosted trees too.
    for name in ["linear", "boosted"]:
        baseline = alnlab.load("recorded", out=tmp_path / "runs", model=name)
        assert baseline.state_names == model.state_names
        assert baseline.kind == ("boosted" if name == "boosted" else "piecewise-linear")
        levels = baseline.predict(x, u, levels=True)
        rows = [r for r in table if r["model"] == name]
        assert len(rows) > 100
        for row in rows:
            assert levels[row["row"], column[row["variable"]]] == row["predicted_level"], (name, row)
        # A rollout is its predictions chained, on any thread count.
        rolled = baseline.rollout(x[:40], np.repeat(u[:40, None, :], 3, axis=1), threads=2)
        step = x[:40]
        for h in range(3):
            step = baseline.predict(step, u[:40], threads=1)
            np.testing.assert_array_equal(rolled[:, h + 1], step)
