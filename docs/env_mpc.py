"""One model-predictive control loop, written once against gymnasium's
interface, run on two worlds: the scene's simulator (`SceneEnv`, the robot
as the run simulated it) and the trained model standing in for it
(`ModelEnv`, what the planner believes). The task is the plan stage's
`bend` for the quickstart's worm: hold pitch.2 at +0.6 rad and pitch.3 at
-0.6 rad.

Every decision draws `--candidates` action sequences of `--horizon` frames
uniformly within the action space, rolls each out with the model from the
world's observation (`Model.rollout`, all candidates together), and applies
the first action of the cheapest (random shooting). The script prints, for
each world, the cost a frame over the closed loop (the squared pitch errors
summed, rad²) and the median time a decision. The two worlds differ only
in what plays the robot; one closed loop each is an example, not a
measurement with an interval.

Example:
    python docs/env_mpc.py --out runs --variant piecewise --decisions 50
"""

import argparse
import statistics
import sys
import time

import numpy as np
import numpy.typing as npt

from alnlab import Model
from alnlab.envs import ModelEnv, SceneEnv

TARGETS = {"pitch.2": 0.6, "pitch.3": -0.6}


def bend_cost(model: Model):
    """The task's cost of observations (…, D) in the model's columns: the
    squared pitch errors summed, one value per observation."""
    columns = [model.state_names.index(name) for name in TARGETS]
    targets = np.array(list(TARGETS.values()))

    def cost(observations: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.square(observations[..., columns] - targets).sum(axis=-1)

    return cost


def mpc(world, model: Model, cost, *, decisions: int, candidates: int, horizon: int, seed: int, frame: int = 0):
    """Random-shooting MPC on `world` (any environment with the model's
    spaces), planning with `model`: returns the cost a frame over the
    closed loop, each decision's seconds and the actions applied."""
    rng = np.random.default_rng(seed)
    observation, _ = world.reset(seed=seed, options={"frame": frame})
    low, high = world.action_space.low, world.action_space.high
    total, seconds, applied = 0.0, [], []
    for _ in range(decisions):
        start = time.perf_counter()
        plans = rng.uniform(low, high, size=(candidates, horizon, len(low)))
        starts = np.broadcast_to(observation, (candidates, len(observation)))
        paths = model.rollout(starts, plans, threads=1)
        best = int(np.argmin(cost(paths[:, 1:]).sum(axis=1)))
        seconds.append(time.perf_counter() - start)
        observation, _, _, _, _ = world.step(plans[best, 0])
        applied.append(plans[best, 0])
        total += float(cost(observation))
    return total / decisions, seconds, applied


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
    parser.add_argument("--decisions", type=at_least(1), default=50, help="frames of closed loop (default: 50)")
    parser.add_argument("--seed", type=int, default=0, help="the candidates' random seed (default: 0)")
    args = parser.parse_args()

    worlds = {
        "the simulator": SceneEnv(args.run, variant=args.variant, out=args.out, max_steps=args.decisions),
        "the model": ModelEnv(args.run, variant=args.variant, out=args.out, max_steps=args.decisions),
    }
    model = worlds["the model"].model
    cost = bend_cost(model)
    print(f"bend, {args.decisions} decisions of {args.candidates} sequences × {args.horizon} frames, one thread")
    print("| the robot played by | cost a frame (rad²) | ms a decision (range) |")
    print("|---|---:|---:|")
    for name, world in worlds.items():
        loss, seconds, _ = mpc(
            world,
            model,
            cost,
            decisions=args.decisions,
            candidates=args.candidates,
            horizon=args.horizon,
            seed=args.seed,
        )
        ms = [s * 1e3 for s in seconds]
        print(f"| {name} | {loss:.4f} | {statistics.median(ms):.2f} ({min(ms):.2f}–{max(ms):.2f}) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
