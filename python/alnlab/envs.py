"""A run's scene and its trained model as gymnasium environments with the
same observation and action spaces, so that a model-predictive control or
reinforcement-learning loop written once runs on either: the simulator (or
the plant, where the scene declares one) as the world, or the learned model
standing in for it.

    >>> from alnlab.envs import SceneEnv, ModelEnv
    >>> world = SceneEnv("quickstart", variant="piecewise")    # the simulator
    >>> learned = ModelEnv("quickstart", variant="piecewise")  # its ALN
    >>> obs, info = world.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = world.step(world.action_space.sample())

Observations are the variables the model reads and predicts, in its
``state_names`` order (D, float64, the variables' own units); actions the
controls (``control_names``, U), bounded by the ranges the model learned.
An episode starts at a logged frame (drawn with the environment's random
generator, or ``options={"frame": k}``) and is truncated after
``max_steps``; nothing terminates it. The reward is ``reward(observation,
action, next_observation)`` where one is given, else 0: an MPC loop costs
its own trajectories. Needs ``pip install alnlab[gym]``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np
import numpy.typing as npt

from alnlab._alnlab import InputError, Model, Scene
from alnlab._runs import PathLike, load, scene

__all__ = ["ModelEnv", "SceneEnv", "observation_columns", "scene_state"]

Reward = Callable[[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]], float]


def observation_columns(scene: Scene, model: Model) -> npt.NDArray[np.intp]:
    """Where each of the model's state variables sits among the scene's
    variables: ``variables[..., observation_columns(scene, model)]`` is a
    scene's step (or logged frame) in the model's columns; ``scene_state``
    goes back."""
    names = scene.variable_names
    missing = [n for n in model.state_names if n not in names]
    if missing:
        raise InputError(
            f"the model reads {', '.join(missing)}, which scene `{scene.name}` does not give: "
            "model and scene are of different runs or variants"
        )
    if model.control_names != scene.control_names:
        raise InputError(
            f"the model's controls ({', '.join(model.control_names)}) are not the scene's "
            f"({', '.join(scene.control_names)})"
        )
    return np.array([names.index(n) for n in model.state_names], dtype=np.intp)


def scene_state(
    scene: Scene,
    model: Model,
    observations: npt.ArrayLike,
    *,
    like: npt.ArrayLike | None = None,
) -> npt.NDArray[np.float64]:
    """The scene's generalized states (…×S, ``scene.state_names``) from
    observations in the model's columns (…×D): each joint's angle and rate
    from the model's ``q.<joint>`` and ``qd.<joint>``; every other component
    (a fixed base's position) from ``like``, a scene state (the log's first
    by default, where that component never changes in the log). A component
    the model does not give and the log varies (a free-floating root, a
    ball joint) is an ``InputError`` naming it, unless ``like`` gives it."""
    obs = np.asarray(observations, dtype=np.float64)
    d = len(model.state_names)
    if obs.shape[-1:] != (d,):
        raise InputError(f"observations: expected shape (..., {d}) in the model's columns, got {obs.shape}")
    # The log, read only where no state is given: its first state, and
    # which components it varies.
    logged: npt.NDArray[np.float64] | None = None
    if like is None:
        _, _, logged, _ = scene.logged()
        base = logged[0]
    else:
        base = np.asarray(like, dtype=np.float64)
        if base.shape != (len(scene.state_names),):
            raise InputError(f"like: expected one scene state of shape ({len(scene.state_names)},), got {base.shape}")
    columns = {n: k for k, n in enumerate(model.state_names)}
    out = np.broadcast_to(base, obs.shape[:-1] + base.shape).copy()
    for k, name in enumerate(scene.state_names):
        parts = name.split(".")
        source = None
        if len(parts) == 3 and parts[0] == "joint" and parts[2] in ("q", "qd"):
            source = columns.get(f"{parts[2]}.{parts[1]}")
        if source is not None:
            out[..., k] = obs[..., source]
        elif logged is not None and np.ptp(logged[:, k]) != 0.0:
            raise InputError(
                f"the scene's `{name}` is not among the model's columns and changes in the log: "
                "give like= a scene state to take it from"
            )
    return out


class _Env(gymnasium.Env[npt.NDArray[np.float64], npt.NDArray[np.float64]]):
    """What both environments share: the spaces, the logged starts, the
    step count and the reward."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        run: PathLike,
        *,
        variant: str | None,
        replicate: int,
        out: PathLike,
        max_steps: int,
        reward: Reward | None,
        plant: bool = False,
    ) -> None:
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise InputError(f"max_steps: expected a whole number of at least 1, got {max_steps!r}")
        if reward is not None and not callable(reward):
            raise InputError(f"reward: expected a function (observation, action, next) -> float, got {reward!r}")
        self.model = load(run, variant=variant, replicate=replicate, out=out)
        self._scene = scene(run, variant=variant, replicate=replicate, out=out, plant=plant)
        self._columns = observation_columns(self._scene, self.model)
        _, _, self._logged_states, variables = self._scene.logged()
        self._logged_observations = np.ascontiguousarray(variables[:, self._columns])
        ranges = dict(self.model.ranges)
        low = np.array([ranges[n][0] for n in self.model.control_names], dtype=np.float64)
        high = np.array([ranges[n][1] for n in self.model.control_names], dtype=np.float64)
        d = len(self.model.state_names)
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (d,), np.float64)
        self.action_space = gymnasium.spaces.Box(low, high, (len(low),), np.float64)
        self.max_steps = max_steps
        self._reward = reward
        self._steps = 0
        self._observation = self._logged_observations[0].copy()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float64], dict[str, Any]]:
        super().reset(seed=seed)
        frames = len(self._logged_observations)
        frame = (options or {}).get("frame")
        if frame is None:
            frame = int(self.np_random.integers(frames))
        elif isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or not 0 <= frame < frames:
            raise InputError(f"options['frame']: expected a logged frame, 0 to {frames - 1}, got {frame!r}")
        self._steps = 0
        self._observation = self._logged_observations[frame].copy()
        self._begin(int(frame))
        return self._observation.copy(), {"frame": int(frame)}

    def _begin(self, frame: int) -> None:
        """What else an environment starts from at a logged frame."""

    def _action(self, action: npt.ArrayLike) -> npt.NDArray[np.float64]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise InputError(f"action: expected shape {self.action_space.shape}, got {a.shape}")
        return a

    def _outcome(
        self, observation: npt.NDArray[np.float64], action: npt.NDArray[np.float64], after: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        self._steps += 1
        reward = 0.0 if self._reward is None else float(self._reward(observation, action, after))
        return after, reward, False, self._steps >= self.max_steps, {"step": self._steps}


class SceneEnv(_Env):
    """The run's scene as the world: each step advances the simulator (the
    plant, with ``plant=True``, where the scene declares one) one frame
    under the action, held; observed in the model's columns."""

    def __init__(
        self,
        run: PathLike = "quickstart",
        *,
        variant: str | None = None,
        replicate: int = 1,
        out: PathLike = "runs",
        plant: bool = False,
        max_steps: int = 200,
        reward: Reward | None = None,
    ) -> None:
        super().__init__(
            run, variant=variant, replicate=replicate, out=out, max_steps=max_steps, reward=reward, plant=plant
        )
        self._state = self._logged_states[0].copy()

    def _begin(self, frame: int) -> None:
        self._state = self._logged_states[frame].copy()

    def step(
        self, action: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        a = self._action(action)
        state, variables = self._scene.step(self._state, a, threads=1)
        before, self._state = self._observation, state
        self._observation = np.ascontiguousarray(variables[self._columns])
        return self._outcome(before, a, self._observation.copy())


class ModelEnv(_Env):
    """The run's trained model standing in for the world: each step is the
    model's prediction of the next frame from the last (its own
    predictions fed back, as a planner rolls it out)."""

    def __init__(
        self,
        run: PathLike = "quickstart",
        *,
        variant: str | None = None,
        replicate: int = 1,
        out: PathLike = "runs",
        max_steps: int = 200,
        reward: Reward | None = None,
    ) -> None:
        super().__init__(run, variant=variant, replicate=replicate, out=out, max_steps=max_steps, reward=reward)

    def step(
        self, action: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], float, bool, bool, dict[str, Any]]:
        a = self._action(action)
        before = self._observation
        self._observation = self.model.predict(before, a, threads=1)
        return self._outcome(before, a, self._observation.copy())
