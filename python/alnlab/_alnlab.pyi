"""Type stubs of alnlab's native core (python/src)."""

import os
from typing import SupportsIndex, final

from typing_extensions import Self

import numpy as np
import numpy.typing as npt

__all__ = [
    "AlnlabError",
    "InputError",
    "DamagedError",
    "Model",
    "Scene",
    "reference_rollout_ns",
    "reference_predict_ns",
    "find_artifacts",
    "run_record",
    "run_records",
]

class AlnlabError(Exception):
    """An error of alnlab's, with the message its CLI prints after ``error: ``."""

    exit_code: int

class InputError(AlnlabError):
    """Input the user can correct (the CLI's exit code 2)."""

class DamagedError(AlnlabError):
    """Damaged or corrupt stored data (the CLI's exit code 1)."""

@final
class Model:
    """A trained model of a run: predicts the next frame of its state
    variables from the current one and the controls held over the frame.
    ``model_path`` is a run's ``model.aln``, or its test stage's baselines
    ``linear.aln`` and ``boosted.parquet``."""

    def __new__(cls, model_path: str | os.PathLike[str], codebook_path: str | os.PathLike[str]) -> Self: ...
    @property
    def kind(self) -> str:
        """``piecewise-linear`` (the robust linear fit is one, of one piece
        per output), ``bit-forest``, ``threshold`` or ``boosted``."""
    @property
    def state_names(self) -> list[str]:
        """The state variables' names (D), in the columns' order."""
    @property
    def control_names(self) -> list[str]:
        """The controls' names (U)."""
    @property
    def ranges(self) -> list[tuple[str, tuple[float, float, int]]]:
        """Each variable's ``(name, (min, max, levels))``, the controls' too, in the codebook's order."""
    def predict(
        self,
        states: npt.ArrayLike,
        controls: npt.ArrayLike,
        *,
        levels: bool = False,
        threads: SupportsIndex | None = None,
        out: npt.NDArray[np.float64] | npt.NDArray[np.uint16] | None = None,
    ) -> npt.NDArray[np.float64] | npt.NDArray[np.uint16]:
        """The next states (B×D) from ``states`` (B×D) under ``controls`` (B×U);
        any array-like of real numbers (cast to float64); one state (D) and
        its controls (U) give one next state (D). With ``out`` (a writeable
        C-contiguous array of the result's shape and dtype, the inputs' own
        too) the result is written there and ``out`` returned. A value that
        is not finite, or further outside its variable's range (``ranges``)
        than that range is wide, raises ``InputError``: the model would
        extrapolate unchecked."""
    def rollout(
        self,
        x0: npt.ArrayLike,
        controls: npt.ArrayLike,
        *,
        levels: bool = False,
        threads: SupportsIndex | None = None,
        out: npt.NDArray[np.float64] | npt.NDArray[np.uint16] | None = None,
    ) -> npt.NDArray[np.float64] | npt.NDArray[np.uint16]:
        """The states over H frames (B×(H+1)×D) from ``x0`` (B×D) under ``controls`` (B×H×U);
        one state (D) under H×U controls gives one path ((H+1)×D)."""

@final
class Scene:
    """A scene of a run, rebuilt from its trajectory log, ready to step."""

    def __new__(
        cls, trajectory_path: str | os.PathLike[str], scene: str | None = None, *, plant: bool = False
    ) -> Self: ...
    @property
    def name(self) -> str:
        """The scene's name."""
    @property
    def plant(self) -> bool:
        """Whether this is the scene's plant rather than its model as written."""
    @property
    def state_names(self) -> list[str]:
        """The generalized state's components (S)."""
    @property
    def variable_names(self) -> list[str]:
        """The variables (V) a step reads."""
    @property
    def control_names(self) -> list[str]:
        """The controls (U)."""
    @property
    def frame_dt(self) -> float:
        """Seconds per frame."""
    @property
    def steps_per_frame(self) -> int:
        """Integration steps per frame as the scene was simulated."""
    def logged(
        self,
    ) -> tuple[npt.NDArray[np.uint32], npt.NDArray[np.uint32], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The log's frames: (runs F, frames F, states F×S, variables F×V)."""
    def step(
        self,
        states: npt.ArrayLike,
        controls: npt.ArrayLike,
        *,
        frames: SupportsIndex | None = None,
        steps: SupportsIndex | None = None,
        threads: SupportsIndex | None = None,
        allow_nan: bool = False,
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Each state (B×S) advanced ``frames`` frames (1 by default) under its
        controls (B×U): the states (B×S) and variables (B×V) after; one state
        (S) gives one of each. A row that is no state, or a state that leaves
        the finite numbers, raises ``InputError`` (with ``allow_nan``, the
        latter comes back as NaN: a planner's candidate that blew up)."""

def reference_rollout_ns(
    model: Model,
    x0: npt.NDArray[np.float64],
    controls: npt.NDArray[np.float64],
    repeats: int = 7,
) -> list[float]:
    """The Rust batched path's nanoseconds per state, one thread, per repeat."""

def reference_predict_ns(
    model: Model,
    state: npt.NDArray[np.float64],
    controls: npt.NDArray[np.float64],
    calls: int = 2000,
    repeats: int = 7,
) -> list[float]:
    """The Rust one-row path's nanoseconds a call, one thread, per repeat."""

def find_artifacts(
    out: str | os.PathLike[str],
    run: str,
    roles: list[str],
    *,
    variant: str | None = None,
    replicate: int | None = None,
    verify: bool = False,
) -> tuple[str, str, str, int, dict[str, str]]:
    """A run's variant's files by role: (id, experiment, variant, replicate from 1, {role: path})."""

def run_record(out: str | os.PathLike[str], run: str) -> str:
    """A run's record, as JSON."""

def run_records(out: str | os.PathLike[str]) -> tuple[list[str], list[tuple[str, str]]]:
    """Every readable record under ``out`` as JSON, and (path, why) of the unreadable."""
