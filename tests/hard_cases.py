"""Hard cases (issue 45): every robot of the installed example-robot-data
collection, at a real step.

Usage: python tests/hard_cases.py ALNLAB WORK_DIR [--seconds S] [--json FILE] [--markdown FILE]

For every URDF of PyPI's example-robot-data that Pinocchio (PyPI `pin`)
loads, on a welded base, at dt = 1 ms for S seconds (10 unless given):
`ALNLAB simulate` with no torque and with random torques (of the order of
gravity's, see `amplitude`, held 0.2 s, on every joint that states an
effort limit, each clamped to it, the drives holding the URDF's velocity
limits as a real robot's do), by semi-implicit Euler and by the implicit integrator. Each run ends
one of three ways: it ran, `alnlab` refused it naming why, or it blew up. Every run the implicit integrator completes is
checked frame by frame against Pinocchio as `robots.py` checks its robots
(accelerations within 1e-10 — unless the mass matrix is singular to
rounding, a condition number over 1e12, where only the figure is shown —
and poses within 1e-12); a run that blows up under the implicit
integrator, or a check that fails, fails the script.
Prints a table — per robot, how each run ended and, for a run semi-implicit
Euler's damping check refused, the largest dt it names — and the count of
robots that run at 1 ms under each integrator.
"""

import json
import math
import os
import re
import statistics
import subprocess
import sys
import xml.etree.ElementTree as ET
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pinocchio as pin
from mcap.reader import make_reader

import robots

INTEGRATORS = ("semi-implicit-euler", "implicit")
TORQUES = ("zero", "random")


def collection():
    """(name, URDF path, Pinocchio model) of every robot Pinocchio loads."""
    data = robots.installed_robots()
    found = []
    for urdf in sorted(data.rglob("*.urdf")):
        try:
            # Mimic joints as Pinocchio models them: followers without
            # coordinates of their own.
            model = pin.buildModelFromUrdf(str(urdf), mimic="<mimic" in urdf.read_text())
        except Exception as error:  # Pinocchio's own refusal: not a case here
            print(f"skipped {urdf.name}: Pinocchio does not load it ({error})")
            continue
        found.append((urdf.stem, urdf, model))
    # Two packages may name a file alike (anymal_b's and anymal_c's
    # anymal.urdf): then the package names it.
    stems = [name for name, _, _ in found]
    return [(name if stems.count(name) == 1 else f"{urdf.parents[1].name}-{name}", urdf, model)
            for name, urdf, model in found]


def amplitude(model) -> float:
    """Random torques of the order the robot meets: the largest torque
    gravity puts on a joint in its neutral pose or bent, or a fifth of the median
    effort limit if that is less (or if gravity puts none). Effort limits
    alone will not do: some descriptions state 1000 N m for a leg of
    100 g (solo, bolt), which no drive gives it."""
    limits = [float(e) for e in model.effortLimit if 0.0 < e < 1e10]
    fifth = 0.2 * statistics.median(limits) if limits else 1.0
    # Gravity in the neutral pose and with every joint turned by half a
    # radian (within its limits): legs hanging straight feel none.
    bent = pin.neutral(model)
    for joint in model.joints[1:]:
        at = joint.idx_q
        if joint.nq == 1:
            low, high = model.lowerPositionLimit[at], model.upperPositionLimit[at]
            bent[at] = min(max(0.5, low), high)
        elif joint.nq == 2:
            bent[at:at + 2] = [math.cos(0.5), math.sin(0.5)]
    data = model.createData()
    gravity = max(float(np.max(np.abs(pin.computeGeneralizedGravity(model, data, q)), initial=0.0))
                  for q in (pin.neutral(model), bent))
    return round(min(fifth, gravity) if gravity > 1e-3 else fifth, 4)


def condition(model) -> float:
    """The mass matrix's condition number in the neutral pose."""
    mass = pin.crba(model, model.createData(), pin.neutral(model))
    mass = np.triu(mass) + np.triu(mass, 1).T
    eigenvalues = np.linalg.eigvalsh(mass)
    return float(eigenvalues[-1] / eigenvalues[0]) if eigenvalues[0] > 0 else math.inf


# Beyond this condition number a mass matrix is singular to rounding (a
# joint that moves no inertia): plain aba's accelerations are rounding
# amplified, and no comparison with them means anything.
SINGULAR = 1e12


def driven(urdf: Path, model, log: Path, torque: float):
    """Per hinge, in the order of the log's `q.` columns (every moving
    joint, a mimic's follower too), the random torque's amplitude: `torque`,
    or none for a follower (its leader's drive moves it) and for a joint
    whose description states no effort limit — no drive (TIAGo's casters,
    of 50 g, which 0.4 N m spins past any step) — as on the robot. Where no
    joint states one, `torque` on every hinge."""
    with open(log, "rb") as f:
        reader = make_reader(f)
        channel = next(c for c in reader.get_summary().channels.values() if c.topic == "/state")
    names = [n[len("q."):] for n in channel.metadata["variables"].split(",") if n.startswith("q.")]
    followers = {j.get("name") for j in ET.parse(urdf).getroot().iter("joint")
                 if j.find("mimic") is not None}
    amplitudes = [0.0 if n in followers else
                  torque if 0.0 < model.effortLimit[model.joints[model.getJointId(n)].idx_v] < 1e10
                  else 0.0 for n in names]
    return amplitudes if any(amplitudes) else torque


def manifest(name: str, urdf: Path, integrator: str, torque, seconds: float) -> str:
    """One run; random torques (one amplitude, or one per driven joint) with
    drives holding the URDF's velocity limits, as a real robot's drives
    do."""
    amplitudes = torque if isinstance(torque, list) else [torque]
    controller = (f'{{ kind = "random", amplitude = {amplitudes}, hold = 0.2 }}\nvelocity_limits = true'
                  if any(amplitudes) else '{ kind = "none" }')
    plain = re.sub(r"[^A-Za-z0-9_-]", "_", name)  # a name the manifest takes
    return "\n".join([
        "[experiment]", f'name = "{plain}"', "seed = 45", "",
        "[[simulate.scene]]", f'name = "{plain}"', 'kind = "urdf"', f'file = "{urdf}"',
        "runs = 1", f"duration = {seconds}", "dt = 0.001", f'integrator = "{integrator}"',
        f"controller = {controller}",
    ]) + "\n"


def run_case(alnlab: str, work: Path, name: str, urdf: Path, integrator: str, torque,
             seconds: float) -> dict:
    case = f"{name}-{integrator}-{'zero' if torque == 0.0 else 'random'}"
    path = work / f"{case}.toml"
    path.write_text(manifest(name, urdf, integrator, torque, seconds))
    out = work / case
    run = subprocess.run([alnlab, "-q", "simulate", "--manifest", str(path), "--out", str(out)],
                         capture_output=True, text=True)
    message = run.stderr.strip().splitlines()[-1] if run.stderr.strip() else ""
    if run.returncode == 0:
        return {"ended": "ran", "log": str(out / "trajectory.mcap")}
    if "the simulation is unstable" in message:
        return {"ended": "blew up", "why": message}
    if run.returncode == 2:
        bound = re.search(r"expected dt ≤ ([0-9.e+-]+)", message)
        return {"ended": "refused", "why": message,
                "dt_bound": float(bound.group(1)) if bound else None}
    return {"ended": f"exit {run.returncode}", "why": message}


def check_quietly(log: Path):
    """`robots.check` of one implicit run, or why it could not run."""
    try:
        return robots.check(log.parent.name, log, need_velocities=False)
    except Exception as error:
        return str(error) or type(error).__name__


def short(result: dict) -> str:
    if result["ended"] == "refused":
        if result.get("dt_bound"):
            return f"refused: dt ≤ {result['dt_bound']:.2e}"
        if "no dt resolves" in result["why"]:
            return "refused: a damped joint moves no inertia, no dt resolves it"
        # The reason, after the file (and line, element) it names.
        why = re.split(r"(?:\.toml:\d+:\d+|\.urdf): ", result["why"])[-1]
        return "refused: " + (why[:70] + "…" if len(why) > 70 else why)
    return result["ended"]


def main(alnlab: str, work: str, seconds: float = 10.0, json_out=None, markdown_out=None) -> int:
    work_dir = Path(work)
    work_dir.mkdir(parents=True, exist_ok=True)
    rows, failed = [], []
    robots_found = collection()
    # Every run, then every check, on all cores: each run is its own
    # process, each check Pinocchio's in one of a pool of processes.
    cases = [(name, urdf, model, integrator, kind) for name, urdf, model in robots_found
             for integrator in INTEGRATORS for kind in TORQUES]
    torques = {name: amplitude(model) for name, _, model in robots_found}
    workers = os.cpu_count() or 2
    # Without torque first: its log names the joints the random torques drive.
    with ThreadPoolExecutor(workers) as pool:
        ended = dict(zip((i for i, c in enumerate(cases) if c[4] == "zero"), pool.map(
            lambda c: run_case(alnlab, work_dir, c[0], c[1], c[3], 0.0, seconds),
            (c for c in cases if c[4] == "zero"))))

    def torque(i: int):
        name, urdf, model, _, _ = cases[i]
        still = next((ended[j] for j, c in enumerate(cases) if c[0] == name and c[4] == "zero"
                      and ended[j]["ended"] == "ran"), None)
        return driven(urdf, model, Path(still["log"]), torques[name]) if still else torques[name]
    with ThreadPoolExecutor(workers) as pool:
        randomly = [i for i, c in enumerate(cases) if c[4] == "random"]
        ended.update(zip(randomly, pool.map(
            lambda i: run_case(alnlab, work_dir, cases[i][0], cases[i][1], cases[i][3], torque(i),
                               seconds), randomly)))
    ended = [ended[i] for i in range(len(cases))]
    checked = [(i, Path(r["log"])) for i, (c, r) in enumerate(zip(cases, ended))
               if c[3] == "implicit" and r["ended"] == "ran"]
    with ProcessPoolExecutor(workers) as pool:
        reports = dict(zip((i for i, _ in checked), pool.map(check_quietly, (log for _, log in checked))))
    for name, urdf, model in robots_found:
        cond = condition(model) if model.nv else 1.0
        row = {"robot": name, "file": str(urdf.relative_to(robots.installed_robots())),
               "nv": model.nv, "amplitude": torques[name], "condition": cond}
        for i, (case, result) in enumerate(zip(cases, ended)):
            if case[0] != name:
                continue
            integrator, kind = case[3], case[4]
            report = reports.get(i)
            if isinstance(report, str):  # a check that cannot run is a failure too
                failed.append(f"{name} ({kind} torques): the Pinocchio check failed: {report}")
            elif report:
                result["worst_acceleration"] = report["worst_acceleration"]
                result["worst_pose"] = report["worst_pose"]
                if report["worst_acceleration"] > robots.ACCELERATION_TOLERANCE and cond < SINGULAR:
                    failed.append(f"{name} ({kind} torques): accelerations off by "
                                  f"{report['worst_acceleration']:.2e}")
                if report["worst_pose"] > robots.KINEMATICS_TOLERANCE:
                    failed.append(f"{name} ({kind} torques): poses off by {report['worst_pose']:.2e}")
                if kind == "random" and report["largest_command"] == 0.0:
                    failed.append(f"{name}: the random torques drove no joint")
            if integrator == "implicit" and result["ended"] not in ("ran", "refused"):
                failed.append(f"{name} ({kind} torques) {result['ended']} under the implicit "
                              f"integrator: {result['why']}")
            still = row.get(f"{integrator}/zero", {}).get("ended")
            if kind == "random" and result["ended"] == "refused" and still == "ran":
                failed.append(f"{name}: its random torques were refused where it ran without: "
                              f"{result['why']}")
            result.pop("log", None)
            row[f"{integrator}/{kind}"] = result
        rows.append(row)
        print(f"{name}: " + "; ".join(f"{k} {short(row[k])}" for k in row if "/" in k), flush=True)
    lines = ["| robot | nv | semi-implicit Euler, no torque | semi-implicit Euler, random | "
             "implicit, no torque | implicit, random | worst q̈ error (implicit) |",
             "|---|---:|---|---|---|---|---:|"]
    for row in rows:
        errors = [row[f"implicit/{k}"].get("worst_acceleration") for k in TORQUES]
        errors = [e for e in errors if e is not None]
        cells = [short(row[f"{i}/{k}"]) for i in INTEGRATORS for k in TORQUES]
        worst = f"{max(errors):.1e}" if errors else ""
        if errors and row["condition"] >= SINGULAR:
            worst += f" (M singular to rounding: cond {row['condition']:.0e})"
        lines.append(f"| {row['robot']} | {row['nv']} | " + " | ".join(cells) + f" | {worst} |")
    both = {i: sum(all(row[f"{i}/{k}"]["ended"] == "ran" for k in TORQUES) for row in rows)
            for i in INTEGRATORS}
    summary = (f"{len(rows)} robots Pinocchio loads; at dt = 1 ms for {seconds:g} s, with no torque "
               f"and with random torques, {both['semi-implicit-euler']} run under semi-implicit Euler "
               f"and {both['implicit']} under the implicit integrator.")
    print("\n".join(lines))
    print(summary)
    if json_out:
        Path(json_out).write_text(json.dumps({"summary": summary, "robots": rows}, indent=1) + "\n")
    if markdown_out:
        Path(markdown_out).write_text("\n".join(lines) + "\n\n" + summary + "\n")
    for f in failed:
        print("FAILED", f, file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    args = sys.argv[1:]
    options = {}
    for flag, key, kind in (("--json", "json_out", str), ("--markdown", "markdown_out", str),
                            ("--seconds", "seconds", float)):
        if flag in args:
            i = args.index(flag)
            options[key] = kind(args[i + 1])
            del args[i:i + 2]
    sys.exit(main(*args, **options))
