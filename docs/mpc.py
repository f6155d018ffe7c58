"""Model-predictive control in Python, with a run's ALN as forward model
against its simulator: the quickstart's worm asked to bend (hold pitch.2 at
+0.6 rad and pitch.3 at -0.6 rad, the plan stage's `bend` task).

Every decision draws `--candidates` torque sequences of `--horizon` frames
uniformly within the range the run's data saw, predicts each with the
forward model, and applies the first frame of the cheapest (random
shooting) to the scene's simulator, which plays the robot. The forward
models: the ALN (`Model.rollout`, all candidates together) and the
simulator itself (`Scene.step`, each candidate on its own, frame by frame)
at the scene's own steps a frame and at each of `--coarse` fewer (a cheaper
simulator); "zero" applies no torque. Each runs `--decisions` decisions from the same
logged start, on `--threads` threads, and the script prints each one's cost
(the squared pitch errors summed, per frame, over the closed loop) and its
time a decision (median of the decisions, with their range).

Example:
    python docs/mpc.py --out runs --variant piecewise --decisions 100
"""

import argparse
import statistics
import sys
import time

import numpy as np

import alnlab

TARGETS = {"pitch.2": 0.6, "pitch.3": -0.6}


def at_least(least: int):
    """An argparse type: a whole number of at least `least`."""

    def whole(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"expected at least {least}, got {value}")
        return value

    return whole


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", default="quickstart", help="a run holding the worm (default: quickstart)")
    parser.add_argument("--out", default="runs", help="its runs folder (default: runs)")
    parser.add_argument("--variant", default="piecewise", help="the model's variant (default: piecewise)")
    parser.add_argument("--candidates", type=at_least(1), default=256, help="sequences a decision (default: 256)")
    parser.add_argument("--horizon", type=at_least(1), default=10, help="frames a sequence (default: 10)")
    parser.add_argument("--decisions", type=at_least(1), default=100, help="frames of closed loop (default: 100)")
    parser.add_argument("--threads", type=at_least(1), default=1, help="threads, the same for both (default: 1)")
    parser.add_argument("--seed", type=int, default=0, help="the candidates' random seed (default: 0)")
    parser.add_argument(
        "--coarse", default="2", help="fewer steps a frame for the simulator too, comma-separated (default: 2)"
    )
    args = parser.parse_args()
    try:
        coarse = [int(k) for k in args.coarse.split(",") if k.strip()]
    except ValueError:
        parser.error(f"--coarse: expected whole numbers, comma-separated, got {args.coarse!r}")
    if any(k < 1 for k in coarse):
        parser.error(f"--coarse: expected steps of at least 1 a frame, got {args.coarse!r}")
    try:
        model = alnlab.load(args.run, variant=args.variant, out=args.out)
        scene = alnlab.scene(args.run, variant=args.variant, out=args.out)
    except alnlab.AlnlabError as e:
        parser.error(str(e))

    if model.control_names != scene.control_names:
        parser.error(f"the model's controls {model.control_names} are not the scene's {scene.control_names}")
    ranges = dict(model.ranges)
    low = np.array([ranges[n][0] for n in model.control_names])
    high = np.array([ranges[n][1] for n in model.control_names])
    # The model's state columns among the scene's variables, and the
    # pitches the task reads among both.
    in_scene = [scene.variable_names.index(n) for n in model.state_names]
    model_pitch = [model.state_names.index(n) for n in TARGETS]
    scene_pitch = [scene.variable_names.index(n) for n in TARGETS]
    target = np.array(list(TARGETS.values()))

    def cost(pitches: np.ndarray) -> np.ndarray:
        return ((pitches - target) ** 2).sum(axis=-1)

    def aln(state, variables, candidates):
        x0 = np.repeat(variables[None, in_scene], len(candidates), axis=0)
        path = model.rollout(x0, candidates, threads=args.threads)
        return cost(path[:, 1:, model_pitch]).sum(axis=1)

    def simulator(steps):
        def forward(state, variables, candidates):
            states = np.repeat(state[None, :], len(candidates), axis=0)
            total = np.zeros(len(candidates))
            for h in range(candidates.shape[1]):
                states, read = scene.step(
                    states, candidates[:, h], steps=steps, threads=args.threads, allow_nan=True
                )
                total += cost(read[:, scene_pitch])
            # A candidate that blew up costs the most.
            return np.nan_to_num(total, nan=np.inf)

        return forward

    _, _, logged_states, logged_variables = scene.logged()
    start_state, start_variables = logged_states[0], logged_variables[0]
    print(
        f"{model.kind} ALN of {args.run}:{args.variant} against the simulator "
        f"({scene.steps_per_frame} steps a frame), bend, random shooting of {args.candidates} x "
        f"{args.horizon} frames, {args.decisions} decisions, {args.threads} thread(s)"
    )
    steps = [scene.steps_per_frame] + coarse
    forwards = [("aln", aln)] + [(f"simulator@{k}", simulator(k)) for k in steps] + [("zero", None)]
    for name, forward in forwards:
        rng = np.random.default_rng(args.seed)
        state, variables = start_state.copy(), start_variables.copy()
        costs, seconds = [], []
        for _ in range(args.decisions):
            if forward is None:
                action = np.zeros(len(low))
            else:
                candidates = rng.uniform(low, high, size=(args.candidates, args.horizon, len(low)))
                began = time.perf_counter()
                best = int(np.argmin(forward(state, variables, candidates)))
                seconds.append(time.perf_counter() - began)
                action = candidates[best, 0]
            states, read = scene.step(state[None, :], action[None, :])
            state, variables = states[0], read[0]
            costs.append(float(cost(variables[scene_pitch])))
        timing = ""
        if seconds:
            ms = [s * 1000 for s in seconds]
            timing = f", {statistics.median(ms):.2f} ms a decision [{min(ms):.2f}, {max(ms):.2f}]"
        print(f"  {name:>13}: cost {statistics.fmean(costs):.3f} rad² a frame{timing}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
