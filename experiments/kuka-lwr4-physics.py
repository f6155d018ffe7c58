"""Where the URDF's physics stands on the real arm of kuka-lwr4.toml, joint by
joint, in torque: the notes' figures on it come from here.

For every sample of the archived recordings (`kuka-lwr4@1`, read from
`datasets/objects/` by the catalog's hashes), Pinocchio's inverse dynamics
of the arm's URDF (`robots/kuka_lwr4/kuka_lwr4.urdf`) at the recorded
positions and velocities and the accelerations the ingest stage takes (the
central difference of the recorded velocities) gives the torque the URDF
says the joint needs; the joint torque sensor says what it had. Per joint:
the recorded torque's RMS, the URDF's residual (recorded minus URDF), the
residual left on the other trajectory once the grey-box a practitioner
fits first — a torque gain on the URDF's torque, viscous and Coulomb
friction and an offset, by least squares on one trajectory — is fitted on
the other (each trajectory held out in turn, as the experiment's folds),
and what the URDF's forward dynamics make of the recorded torques: its
accelerations' error, which the simulator of the experiment integrates —
alone, and with per-joint friction (viscous, Coulomb, offset) fitted on
the other trajectory taken off the recorded torques.

    python experiments/kuka-lwr4-physics.py [--markdown FILE]

(NumPy, pyarrow and Pinocchio, as `xtask/requirements.txt` pins them.)
"""
import argparse
import sys
import tomllib
from pathlib import Path

import numpy as np
import pinocchio as pin
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parent.parent
JOINTS = [f"lwr_{j}_joint" for j in range(7)]


def tables():
    """Each archived table of kuka-lwr4@1 by name, verified by its sha256."""
    catalog = tomllib.loads((ROOT / "datasets/catalog.toml").read_text())
    entry = next(d for d in catalog["dataset"] if d["name"] == "kuka-lwr4" and d["version"] == 1)
    found = {}
    for f in entry["files"]:
        if f["role"] == "table":
            found[f["name"]] = pq.read_table(ROOT / "datasets/objects" / f["sha256"])
    return found


def samples(table, model, data):
    """q, q̇, the recorded torque, the URDF's torque (inverse dynamics), q̈
    (central differences of q̇ over the recorded times) and the URDF's q̈
    under the recorded torque (forward dynamics), for one table."""
    t = table.column("time").to_numpy()
    column = lambda j, quantity: table.column(f"{j}.{quantity}").to_numpy()
    q = np.column_stack([column(j, "position") for j in JOINTS])
    qd = np.column_stack([column(j, "velocity") for j in JOINTS])
    tau = np.column_stack([column(j, "effort") for j in JOINTS])
    qdd = np.gradient(qd, t, axis=0)
    urdf = np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]).copy() for k in range(len(t))])
    forward = np.array([pin.aba(model, data, q[k], qd[k], tau[k]).copy() for k in range(len(t))])
    return q, qd, tau, urdf, qdd, forward


def friction(qd, j):
    """Friction's regressors for joint j: viscous, Coulomb, an offset."""
    return np.column_stack([qd[:, j], np.sign(qd[:, j]), np.ones(len(qd))])


def features(urdf, qd, j):
    """The grey-box's regressors for joint j: the URDF's torque (its gain),
    then friction's."""
    return np.column_stack([urdf[:, j], friction(qd, j)])


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--markdown", help="write the table here as well")
    args = parser.parse_args()
    model = pin.buildModelFromUrdf(str(ROOT / "robots/kuka_lwr4/kuka_lwr4.urdf"))
    data = model.createData()
    if [model.names[i] for i in range(1, model.njoints)] != JOINTS:
        sys.exit(f"the URDF's joints are {list(model.names)[1:]}, not {JOINTS}")
    read = tables()
    # The trajectories as kuka-lwr4.toml groups its tables: a repeat with
    # its twin, every other table alone.
    manifest = tomllib.loads((ROOT / "experiments/kuka-lwr4.toml").read_text())
    repeats = manifest["ingest"].get("repeats", [])
    grouped = {name for group in repeats for name in group}
    trajectories = repeats + [[n] for n in sorted(read) if n not in grouped]
    per_trajectory = []
    for names in trajectories:
        parts = [samples(read[n], model, data) for n in names]
        per_trajectory.append(tuple(np.vstack([p[k] for p in parts]) for k in range(6)))
    _, qd, tau, urdf, qdd, forward = (np.vstack([p[k] for p in per_trajectory]) for k in range(6))
    # The URDF plus per-joint friction fitted on the other trajectory (the
    # residual torque's least squares), under the recorded torques: its
    # accelerations' error on each held-out trajectory.
    friction_error = []
    for test in range(2):
        q_a, qd_a, tau_a, urdf_a = per_trajectory[1 - test][:4]
        q_b, qd_b, tau_b, _, qdd_b, _ = per_trajectory[test]
        fitted = np.column_stack([
            friction(qd_b, j)
            @ np.linalg.lstsq(friction(qd_a, j), tau_a[:, j] - urdf_a[:, j], rcond=None)[0]
            for j in range(len(JOINTS))
        ])
        applied = tau_b - fitted
        accelerations = np.array(
            [pin.aba(model, data, q_b[k], qd_b[k], applied[k]).copy() for k in range(len(q_b))]
        )
        friction_error.append(accelerations - qdd_b)

    lines = [
        "| joint | recorded torque RMS (N m) | URDF residual RMS | grey-box residual RMS, held out "
        "(trajectory 1 / 2) | torque gain fitted (1 / 2) | viscous (N m s/rad) | Coulomb (N m) "
        "| offset (N m) | recorded q̈ RMS (rad/s²) | URDF's q̈ error RMS | URDF + friction's q̈ "
        "error RMS, held out (1 / 2) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for j, name in enumerate(JOINTS):
        held, fitted = [], []
        for test in range(2):
            train = 1 - test
            qd_a, tau_a, urdf_a = per_trajectory[train][1:4]
            w, *_ = np.linalg.lstsq(features(urdf_a, qd_a, j), tau_a[:, j], rcond=None)
            qd_b, tau_b, urdf_b = per_trajectory[test][1:4]
            held.append(rms(tau_b[:, j] - features(urdf_b, qd_b, j) @ w))
            fitted.append(w)
        w = np.mean(fitted, axis=0)
        lines.append(
            f"| {name} | {rms(tau[:, j]):.2f} | {rms(tau[:, j] - urdf[:, j]):.2f} "
            f"| {held[0]:.2f} / {held[1]:.2f} | {fitted[1][0]:.3f} / {fitted[0][0]:.3f} "
            f"| {w[1]:.2f} | {w[2]:.2f} | {w[3]:.2f} "
            f"| {rms(qdd[:, j]):.2f} | {rms(forward[:, j] - qdd[:, j]):.2f} "
            f"| {rms(friction_error[0][:, j]):.2f} / {rms(friction_error[1][:, j]):.2f} |"
        )
    lines.append("")
    lines.append(
        "Trajectory 1 is tables 1 and 2 (one trajectory recorded twice), 2 is table 3; a held-out "
        "figure is fitted on the other trajectory. Gains and friction: the fit on trajectory 1 / on "
        "trajectory 2 for the gain, their mean for the rest. The URDF's q̈: forward dynamics under "
        "the recorded torques, against the recorded velocities' central differences."
    )
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")


if __name__ == "__main__":
    main()
