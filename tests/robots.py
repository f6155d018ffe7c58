"""Robots from URDF, verified against Pinocchio (issue 35).

Usage: python tests/robots.py ALNLAB WORK_DIR [--json FILE]

For every robot below — the two vendored under robots/ and further robots
of PyPI's example-robot-data, read from the installed package, and the UR5
as a plant that departs from its description (Pinocchio's model perturbed
to match) — writes a
manifest of one 10 s run with a random controller into WORK_DIR, runs
`ALNLAB simulate` on it, and checks every logged frame with Pinocchio (PyPI
`pin`), which loads the same URDF on its own:

- joint accelerations: `pinocchio.aba` from the logged state, with each
  joint's total effort (the control effort `tau.<joint>`, or the effort its
  actuator applied, `joint.<joint>.applied`, where a plant logs it, plus the
  passive effort `joint.<joint>.passive` logged beside the state: damping,
  friction, limit springs) and, for a robot on the floor, the contact forces
  (`f_E`, `g_E`) as external forces; a free base's accelerations too;
- link velocities `v.<link>`, `omega.<link>` with `getFrameVelocity`
  (LOCAL);
- every URDF link's frame on /tf with `updateFramePlacements`;
- a plant's applied efforts, recomputed from the logged commands with its
  actuators' gain, lag and delay.

Errors are relative: |Δ| / max(1, |reference|) per frame. Fails when an
acceleration is off by more than 1e-10 or a velocity or pose by more than
1e-12, and prints the worst figures per robot.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from interop import field_name

ROOT = Path(__file__).resolve().parent.parent
ACCELERATION_TOLERANCE = 1e-10
KINEMATICS_TOLERANCE = 1e-12
# The actuators' efforts recomputed from the commands: the same operations
# in the same order, so only exp's last bit may differ.
APPLIED_TOLERANCE = 1e-12


def installed_robots() -> Path:
    """The robots folder of the installed example-robot-data wheel."""
    for entry in sys.path:
        candidate = Path(entry) / "cmeel.prefix/share/example-robot-data/robots"
        if candidate.is_dir():
            return candidate
    raise SystemExit("example-robot-data is not installed (pip install example-robot-data)")


def robots():
    """(name, URDF path, scene fields) of every robot checked."""
    data = installed_robots()
    feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
    return [
        ("ur5", ROOT / "robots/ur5/ur5_robot.urdf",
         {"link_velocities": ["wrist_3_link", "forearm_link"], "amplitude": 30.0}),
        ("solo12", ROOT / "robots/solo12/solo12.urdf",
         {"base": "free", "floor": True, "contact_links": feet, "initial_height": 0.4,
          "contact": {"stiffness": 3000.0, "damping": 5.0},
          "link_velocities": ["FL_LOWER_LEG"], "amplitude": 1.0}),
        ("double_pendulum", data / "double_pendulum_description/urdf/double_pendulum_continuous.urdf",
         {"link_velocities": ["link2"], "amplitude": 0.5}),
        ("kinova", data / "kinova_description/robots/kinova.urdf",
         {"amplitude": 2.0, "integrator": "rk4", "link_velocities": ["j2s6s200_link_6"]}),
        # Damped more than an explicit step of 1 ms resolves (issue 45):
        # the implicit integrator takes it, and logs the passive effort
        # each step applied.
        ("xarm7", data / "xarm_description/urdf/xarm7.urdf",
         {"amplitude": 5.0, "integrator": "implicit", "link_velocities": ["link7"]}),
        ("z1", data / "z1_description/urdf/z1.urdf",
         {"amplitude": 2.0, "integrator": "implicit", "link_velocities": ["link06"]}),
        ("allegro", data / "allegro_hand_description/urdf/allegro_right_hand.urdf",
         {"amplitude": 0.05, "integrator": "implicit", "link_velocities": ["link_15.0"]}),
        # A humanoid on a free base, no floor, its limits hit hard by random
        # torques (issue 45: explicitly it blew up at a limit).
        ("g1", data / "g1_description/urdf/g1_29dof_rev_1_0.urdf",
         {"base": "free", "amplitude": 1.0, "integrator": "implicit",
          "link_velocities": ["left_wrist_yaw_link"]}),
        ("gantry", ROOT / "tests/data/gantry.urdf",
         {"amplitude": 5.0, "link_velocities": ["slide", "arm"]}),
        # Mimic joints (issue 60): the right finger follows the left.
        ("panda", data / "panda_description/urdf/panda.urdf",
         {"amplitude": 5.0, "link_velocities": ["panda_leftfinger", "panda_rightfinger"]}),
        ("anymal", data / "anymal_c_simple_description/urdf/anymal.urdf",
         {"base": "free", "amplitude": 5.0, "initial_height": 1.0, "link_velocities": ["LF_SHANK"]}),
        # The real arm whose recordings experiments/lwr4.toml learns
        # (issue 61): its description as FloBaRoID publishes it, damping and
        # friction at every joint.
        ("kuka-lwr4", ROOT / "robots/kuka_lwr4/kuka_lwr4.urdf",
         {"amplitude": 10.0, "link_velocities": ["lwr_7_link"]}),
        # Driven hard, with drives that hold the URDF's velocity limits:
        # the efforts they applied are logged, and must explain the motion.
        ("ur5-held", ROOT / "robots/ur5/ur5_robot.urdf",
         {"link_velocities": ["wrist_3_link"], "amplitude": 60.0, "velocity_limits": True}),
        # A plant that is not its description (issue 43): heavier links, a
        # payload on the flange (a link merged into the last body), friction,
        # and weak, slow and late actuators — checked against Pinocchio's
        # model perturbed the same way, with the efforts the actuators
        # applied, which are recomputed here from the logged commands.
        ("ur5-plant", ROOT / "robots/ur5/ur5_robot.urdf",
         {"link_velocities": ["wrist_3_link"], "amplitude": 30.0,
          "plant": {"mass_scale": 1.2, "viscous_friction": 0.5, "coulomb_friction": 0.3,
                    "actuator_gain": 0.9, "actuator_lag": 0.02, "actuator_delay_frames": 1,
                    "payload": {"link": "tool0", "mass": 2.0, "offset": [0.0, 0.02, 0.05]}}}),
    ]


def manifest(name: str, urdf: Path, fields: dict) -> str:
    lines = [
        "[experiment]", f'name = "{name}"', "seed = 35", "",
        "[[simulate.scene]]", f'name = "{name}"', 'kind = "urdf"', f'file = "{urdf}"',
        "runs = 1", "duration = 10.0",
        f'controller = {{ kind = "random", amplitude = [{fields["amplitude"]}] }}',
    ]
    for key, value in fields.items():
        if key != "amplitude":
            lines.append(f"{key} = {toml_value(value)}")
    return "\n".join(lines) + "\n"


def toml_value(value) -> str:
    """`value` as TOML: tables inline, strings as JSON writes them."""
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return json.dumps(value)


def read_log(path: Path):
    """The scene record, model record and every frame (state and variables
    by name, with its log time) of a one-scene log; /tf transforms by log
    time."""
    frames, tf = [], {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        records = {m.name: m.metadata for m in reader.iter_metadata()}
        for _, _, message in reader.iter_messages(topics=["/tf"]):
            tf[message.log_time] = json.loads(message.data)["transforms"]
        for _, channel, message, decoded in reader.iter_decoded_messages(topics=["/state"]):
            names = channel.metadata["state"].split(",") + channel.metadata["variables"].split(",")
            values = {n: getattr(decoded, field_name(n)) for n in names}
            frames.append((message.log_time, values))
    return records["alnlab.scene"], json.loads(records["alnlab.model"]["json"]), frames, tf


def perturb(model, plant: dict) -> None:
    """Pinocchio's model made the plant: every body's mass and rotational
    inertia scaled, and the payload's point mass added to the body its link
    is fixed to, at the offset in that link's frame."""
    scale = plant.get("mass_scale", 1.0)
    # Rebuilt only when scaled: Pinocchio's Inertia refuses a rotational
    # inertia of pure round-off (icub's head) that its URDF reader took.
    for i in range(model.njoints if scale != 1.0 else 0):
        inertia = model.inertias[i]
        model.inertias[i] = pin.Inertia(inertia.mass * scale, inertia.lever, inertia.inertia * scale)
    payload = plant.get("payload")
    if payload:
        frame = model.frames[model.getFrameId(payload["link"], pin.BODY)]
        at = frame.placement.act(np.array(payload["offset"], dtype=float))
        model.inertias[frame.parentJoint] += pin.Inertia(payload["mass"], at, np.zeros((3, 3)))


def actuated(frames, joints, scene, plant, effort) -> dict:
    """Each joint's applied effort at every frame, recomputed from the
    logged commands `tau.<joint>` as the plant states its actuators: a gain,
    a first-order lag and a delay in frames, updated every integration step
    (the command held over a frame's steps), clamped to the effort limit."""
    dt, frame_dt = scene["dt"], scene["frame_dt"]
    per_frame = round(frame_dt / dt)
    # The command held over a frame's steps: a controller that redraws on
    # frame boundaries only (a held random draw, a whole number of frames).
    controller = scene["controller"]
    assert controller["kind"] in ("random", "constant"), controller
    frames_per_hold = controller["hold"] / frame_dt
    assert abs(frames_per_hold - round(frames_per_hold)) < 1e-9, controller
    delay = plant.get("actuator_delay_frames", 0) * per_frame
    gain = plant.get("actuator_gain", 1.0)
    lag = plant.get("actuator_lag", 0.0)
    follow = 1.0 - math.exp(-dt / lag) if lag > 0 else None
    expected = {}
    for j in joints:
        command = [x[f"tau.{j}"] for _, x in frames]
        y, out = 0.0, []
        for s in range((len(frames) - 1) * per_frame + 1):
            arrived = command[(s - delay) // per_frame] if s >= delay else 0.0
            y = y + (arrived * gain - y) * follow if follow is not None else arrived * gain
            if s % per_frame == 0:
                out.append(min(max(y, -effort[j]), effort[j]))
        expected[j] = out
    return expected


def check(name: str, log: Path, need_velocities: bool = True) -> dict:
    """Every frame of `log` against Pinocchio; with `need_velocities`, the
    log must name link velocities to compare."""
    scene_record, model_record, frames, tf = read_log(log)
    scene = json.loads(scene_record["json"])
    urdf = scene_record["urdf"]
    free = scene["base"] == "free"
    # Mimic joints as Pinocchio models them: a follower has no coordinate
    # of its own (nq = nv = 0), its leader's scaled and offset.
    mimic = "<mimic" in urdf
    root_joint = (pin.JointModelFreeFlyer(),) if free else ()
    model = pin.buildModelFromXML(urdf, *root_joint, mimic=mimic)
    model.gravity.linear = np.array(scene["gravity"])
    plant = scene.get("plant") or {}
    perturb(model, plant)
    data = model.createData()
    links = model_record["links"]
    joints = [l["joint_name"] for l in links[1:]]
    root_link = links[0]["link"]
    # Which Pinocchio joint each model link is.
    ids = {j: model.getJointId(j) for j in joints}
    assert all(i < model.njoints for i in ids.values()), f"{name}: joints Pinocchio does not have"
    # Each follower's scaling and offset, and its leader's velocity index.
    followers = {j: model.joints[ids[j]].extract() for j in joints
                 if model.joints[ids[j]].shortname() == "JointModelMimic"}
    assert model.nv == len(joints) - len(followers) + (6 if free else 0), (model.nv, len(joints))
    worst = {"acceleration": 0.0, "velocity": 0.0, "pose": 0.0, "applied": 0.0}
    actuators = ("actuator_gain", "actuator_lag", "actuator_delay_frames", "torque_noise")
    recomputed = None
    if any(k in plant for k in actuators[:3]) and "torque_noise" not in plant:
        limits = {j: float(model.effortLimit[model.joints[ids[j]].idx_v]) for j in joints}
        recomputed = actuated(frames, joints, scene, plant, limits)
    # A log of applied efforts says its total effort is theirs plus the
    # passive one, as summed below.
    total = model_record["robot_conventions"]["passive"]
    if any(k.endswith(".applied") for k in frames[0][1]):
        assert total.endswith("applied + passive"), (name, total)
    else:
        assert total.endswith("tau + passive"), (name, total)
    compared = {"velocity": 0, "pose": 0}
    largest_acceleration = largest_command = 0.0
    for index, (log_time, x) in enumerate(frames):
        q = pin.neutral(model)
        v = np.zeros(model.nv)
        tau = np.zeros(model.nv)
        logged = np.zeros(model.nv)
        if free:
            q[0:3] = [x[f"root.p.{a}"] for a in "xyz"]
            q[3:7] = [x[f"q.{root_link}.{a}"] for a in "xyzw"]
            v[0:3] = [x[f"root.v.{a}"] for a in "xyz"]
            v[3:6] = [x[f"w.{root_link}.{a}"] for a in "xyz"]
            # The base's logged a is the acceleration of its origin
            # (a_spatial + ω × v); Pinocchio's ddq is the spatial one.
            omega, vel = v[3:6], v[0:3]
            a = np.array([x[f"a.{root_link}.{c}"] for c in "xyz"])
            logged[0:3] = a - np.cross(omega, vel)
            logged[3:6] = [x[f"omega_dot.{root_link}.{c}"] for c in "xyz"]
        for j in joints:
            joint = model.joints[ids[j]]
            angle, rate = x[f"joint.{j}.q"], x[f"joint.{j}.qd"]
            if j in followers:
                continue  # after every leader's
            if joint.nq == 2:  # continuous: cos, sin
                q[joint.idx_q:joint.idx_q + 2] = [math.cos(angle), math.sin(angle)]
            else:
                q[joint.idx_q] = angle
            v[joint.idx_v] = rate
            # The actuator's effort where the plant logs it (a gain), else
            # the command.
            effort = x.get(f"joint.{j}.applied", x.get(f"tau.{j}", 0.0))
            largest_command = max(largest_command, abs(x.get(f"tau.{j}", 0.0)))
            if any(k in plant for k in actuators):
                assert f"joint.{j}.applied" in x, (name, j)
            if recomputed is not None:
                want = recomputed[j][index]
                worst["applied"] = max(worst["applied"], abs(effort - want) / max(1.0, abs(want)))
            tau[joint.idx_v] = effort + x[f"joint.{j}.passive"]
            logged[joint.idx_v] = x[f"qdd.{j}"]
        # A follower's effort acts on its leader through the coupling; its
        # logged position and velocity are its leader's scaled and offset.
        for j, follower in followers.items():
            leader = follower.idx_v
            effort = x.get(f"joint.{j}.applied", x.get(f"tau.{j}", 0.0))
            tau[leader] += follower.scaling * (effort + x[f"joint.{j}.passive"])
            position = follower.scaling * q[follower.idx_q] + follower.offset
            for got, want in ((x[f"joint.{j}.q"], position), (x[f"joint.{j}.qd"], follower.scaling * v[leader])):
                worst["pose"] = max(worst["pose"], abs(got - want) / max(1.0, abs(want)))
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        for i, link in enumerate(links):
            key = link["link"]
            if f"f_E.{key}.x" in x:
                force = np.array([x[f"f_E.{key}.{c}"] for c in "xyz"])
                torque = np.array([x.get(f"g_E.{key}.{c}", 0.0) for c in "xyz"])
                if i == 0 and not free:
                    continue  # a welded base does not move, whatever touches it
                joint_id = 1 if i == 0 else ids[link["joint_name"]]
                fext[joint_id] = pin.Force(force, torque)
        if followers:
            # No aba for mimic joints: CRBA and RNEA on the reduced model.
            mass = pin.crba(model, data, q)
            mass = np.triu(mass) + np.triu(mass, 1).T
            ddq = np.linalg.solve(mass, tau - pin.rnea(model, data, q, v, np.zeros(model.nv), fext))
        else:
            ddq = pin.aba(model, data, q, v, tau, fext)
        for j, follower in followers.items():
            want = follower.scaling * ddq[follower.idx_v]
            worst["acceleration"] = max(worst["acceleration"],
                                        abs(x[f"qdd.{j}"] - want) / max(1.0, float(np.max(np.abs(ddq)))))
        scale = max(1.0, float(np.max(np.abs(ddq))))
        largest_acceleration = max(largest_acceleration, float(np.max(np.abs(ddq))))
        worst["acceleration"] = max(worst["acceleration"], float(np.max(np.abs(ddq - logged))) / scale)
        pin.forwardKinematics(model, data, q, v)
        pin.updateFramePlacements(model, data)
        for key in x:
            if key.startswith("v.") and key.endswith(".x"):
                link = key[2:-2]  # a link's name may hold dots (allegro's link_15.0)
                motion = pin.getFrameVelocity(model, data, model.getFrameId(link, pin.BODY), pin.LOCAL)
                for reference, prefix in ((motion.linear, "v"), (motion.angular, "omega")):
                    got = np.array([x[f"{prefix}.{link}.{c}"] for c in "xyz"])
                    error = float(np.max(np.abs(got - reference))) / max(1.0, float(np.max(np.abs(reference))))
                    worst["velocity"] = max(worst["velocity"], error)
                    compared["velocity"] += 1
        for t in tf.get(log_time, []):
            link = t["child_frame_id"].split("/", 2)[2]
            placement = data.oMf[model.getFrameId(link, pin.BODY)]
            position = np.array([t["translation"][c] for c in "xyz"])
            r = t["rotation"]
            rotation = pin.Quaternion(r["w"], r["x"], r["y"], r["z"]).toRotationMatrix()
            error = max(float(np.max(np.abs(position - placement.translation))),
                        float(np.max(np.abs(rotation - placement.rotation))))
            worst["pose"] = max(worst["pose"], error / max(1.0, float(np.max(np.abs(placement.translation)))))
            compared["pose"] += 1
    assert compared["pose"] > 0 and (compared["velocity"] > 0 or not need_velocities), (name, compared)
    return {"robot": name, "frames": len(frames), "velocities": compared["velocity"],
            "poses": compared["pose"], "nv": model.nv,
            "largest_acceleration": largest_acceleration, "largest_command": largest_command, **{f"worst_{k}": v for k, v in worst.items()}}


def main(alnlab: str, work: str, json_out=None) -> int:
    work_dir = Path(work)
    work_dir.mkdir(parents=True, exist_ok=True)
    results, failed = [], []
    for name, urdf, fields in robots():
        path = work_dir / f"{name}.toml"
        path.write_text(manifest(name, urdf, fields))
        out = work_dir / name
        run = subprocess.run([alnlab, "-q", "simulate", "--manifest", str(path), "--out", str(out)],
                             capture_output=True, text=True)
        if run.returncode != 0:
            failed.append(f"{name}: alnlab simulate failed: {run.stderr.strip()}")
            continue
        result = check(name, out / "trajectory.mcap")
        results.append(result)
        print(f"{name}: {result['frames']} frames, nv {result['nv']}, |q̈| up to {result['largest_acceleration']:.3g}; "
              f"worst relative error: accelerations {result['worst_acceleration']:.2e}, "
              f"applied efforts {result['worst_applied']:.2e}, "
              f"link velocities {result['worst_velocity']:.2e} ({result['velocities']} compared), "
              f"poses {result['worst_pose']:.2e} ({result['poses']} frames on /tf)")
        if result["worst_acceleration"] > ACCELERATION_TOLERANCE:
            failed.append(f"{name}: accelerations off by {result['worst_acceleration']:.2e}")
        if result["worst_applied"] > APPLIED_TOLERANCE:
            failed.append(f"{name}: applied efforts off by {result['worst_applied']:.2e}")
        if max(result["worst_velocity"], result["worst_pose"]) > KINEMATICS_TOLERANCE:
            failed.append(f"{name}: kinematics off by {max(result['worst_velocity'], result['worst_pose']):.2e}")
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=1) + "\n")
    for f in failed:
        print("FAILED", f, file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    args = sys.argv[1:]
    json_out = None
    if "--json" in args:
        i = args.index("--json")
        json_out = args[i + 1]
        del args[i:i + 2]
    sys.exit(main(*args, json_out=json_out))
