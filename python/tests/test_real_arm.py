"""The real arm's experiment (`experiments/kuka-lwr4.toml`, its recordings
read from the repository's dataset archive), cut down, and its model used
from Python in the recording's units."""

import json
import subprocess
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import alnlab
from alnlab.envs import observation_columns, scene_state

ROOT = Path(__file__).resolve().parents[2]


def cut_down(text: str) -> str:
    """The committed manifest with few rows, no peer or hybrids, brief
    timings; the robot's description by its absolute path."""
    for old, new in [
        ('file = "../robots/', f'file = "{ROOT}/robots/'),
        ("[stride]\nn = 1\n", "[stride]\nn = 1\ntrain_rows = 400\ntest_rows = 300\n"),
        ("pwl.max_pieces = 16", "pwl.max_pieces = 4"),
        ("peer = true\nhybrids = true", "peer = false\nhybrids = false\nrollout_starts = 10\nrun_seconds = 0.001"),
    ]:
        assert old in text, old
        text = text.replace(old, new)
    return text


def test_the_real_arms_model_predicts_from_python_in_the_recordings_units(alnlab_bin, tmp_path):
    text = cut_down((ROOT / "experiments/kuka-lwr4.toml").read_text())
    (tmp_path / "kuka.toml").write_text(text)
    runs = tmp_path / "runs"
    done = subprocess.run(
        [alnlab_bin, "-q", "run", "kuka.toml", "--out", runs, "--datasets", ROOT / "datasets"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    record = json.loads((runs / "kuka-lwr4/run.json").read_text())
    assert [t["file"] for t in record["tables"]] == [
        f"kuka-lwr4@1/measurements_{k}.parquet" for k in (1, 2, 3)
    ]
    for replicate in (1, 2):
        model = alnlab.load("kuka-lwr4", out=runs, replicate=replicate)
        # A forward model: the state and the torque, never an acceleration.
        assert model.control_names == [f"tau.lwr_{j}_joint" for j in range(7)]
        assert not [n for n in model.state_names if n.startswith("qdd.")]
        pairs = alnlab.table("kuka-lwr4", "pairs", out=runs, replicate=replicate)
        x = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.state_names])
        u = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.control_names])
        # In the recording's units: joint angles (rad) and torques (N m)
        # within the recorded ranges.
        recorded = pq.read_table(
            ROOT / "datasets/objects/03a424dffe70a7f86d5ff059e09897ac483f44b205d99799fe2ba8bbfdb5ed84"
        )
        q0 = recorded.column("lwr_1_joint.position").to_numpy()
        column = {n: k for k, n in enumerate(model.state_names)}
        assert np.all(np.abs(x[:, column["q.lwr_1_joint"]]) < np.pi)
        assert np.abs(u).max() < 200.0 and np.abs(q0).max() < np.pi
        # Its predictions from NumPy are the test stage's, level for level.
        levels = model.predict(x, u, levels=True)
        predictions = alnlab.table("kuka-lwr4", "predictions", out=runs, replicate=replicate).to_pylist()
        checked = 0
        for row in predictions:
            if row["model"] == "aln":
                assert levels[row["row"], column[row["variable"]]] == row["predicted_level"]
                checked += 1
        assert checked >= 300
        # And in units: the next joint angles near the current ones (5 ms on).
        nxt = model.predict(x, u)
        step = np.abs(nxt[:, column["q.lwr_1_joint"]] - x[:, column["q.lwr_1_joint"]])
        assert np.median(step) < 0.05
    # A scene's states to the model's columns and back: the arm's joints
    # from q and qd; what else the recorded scene carries (each joint's
    # passive torque) from a state given, never guessed.
    scene = alnlab.scene("kuka-lwr4", out=runs)
    _, _, states, variables = scene.logged()
    observations = variables[:, observation_columns(scene, model)]
    with pytest.raises(alnlab.InputError, match=r"the scene's `joint\.lwr_0_joint\.passive` is not among"):
        scene_state(scene, model, observations)
    back = scene_state(scene, model, observations[5], like=states[0])
    joints = [k for k, n in enumerate(scene.state_names) if n.endswith((".q", ".qd"))]
    assert len(joints) == 14
    np.testing.assert_array_equal(back[joints], states[5][joints])
