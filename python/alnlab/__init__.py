"""alnlab in Python: a run's trained model over NumPy arrays, and its
records and tables as Arrow tables.

    >>> import alnlab
    >>> model = alnlab.load("quickstart", variant="piecewise")   # under ./runs
    >>> model.state_names, model.control_names                  # D and U columns
    >>> nxt = model.predict(states, controls)      # B×D, B×U   -> B×D
    >>> path = model.rollout(x0, controls)         # B×D, B×H×U -> B×(H+1)×D
    >>> sim = alnlab.scene("quickstart")                          # its simulator
    >>> states, variables = sim.step(s, torques)   # B×S, B×U   -> B×S, B×V
    >>> alnlab.table("quickstart", "predictions", variant="piecewise").to_pandas()

What is here:

- ``load(run, variant=, replicate=, out=, model=)``: a run's trained model
  (piecewise-linear, bit-forest or threshold), or with ``model="linear"`` or
  ``"boosted"`` a baseline its test stage fitted, found as the CLI finds runs:
  a run id, a unique prefix of one, an experiment's name (its latest run),
  ``NAME~N`` (N runs before it), or ``RUN:VARIANT``; or a run's folder.
  ``Model(model_path, codebook_path)`` loads the files themselves.
- ``Model``: its ``state_names`` (D) and ``control_names`` (U) give the
  columns; ``ranges`` each variable's range and levels. ``predict`` and
  ``rollout`` take any array-like of real numbers in the variables' own
  units (float32, ints, bools and lists cast to float64; one state, without
  the batch dimension, gives one result) and return float64 (or levels,
  uint16, with ``levels=True``), computed by the stages' own code with the
  GIL released, on all threads or ``threads=n``.
- ``scene(run, variant=, plant=)``: the run's scene rebuilt from its
  trajectory log — the model as written, or the plant it was simulated as
  where it declares one. ``Scene.step(states, controls, *, frames=1,
  steps=None)`` advances B generalized states (``state_names``, S) under
  B×U torques held over the frames and returns the states and their
  variables (``variable_names``, V: the names a model's columns use), a
  state the simulator cannot step an ``InputError``;
  ``logged()`` gives the log's own frames.
- ``runs(out=)``: every run recorded under ``out``, one row per variant and
  replicate, with parameters (``param.<key>``) and headline metrics
  (``metric.<name>``); ``record(run)``: one run's record as a dict;
  ``table(run, name)``: a stage's table by its artifact name
  (``predictions``, ``summary``, ``pairs``, …), its bytes checked against
  the record. Tables need pyarrow (``pip install alnlab[tables]``);
  ``pandas=True`` gives a pandas DataFrame (``pip install alnlab[pandas]``).
- ``alnlab.envs`` (``pip install alnlab[gym]``): ``SceneEnv`` and
  ``ModelEnv``, the run's scene and its model as gymnasium environments of
  one observation and action space, so a control loop runs on either.
- ``AlnlabError`` and its kinds ``InputError`` (what the user can correct:
  the CLI's exit code 2) and ``DamagedError`` (damaged data: exit code 1),
  whose messages are the CLI's.
"""

from alnlab._alnlab import AlnlabError, DamagedError, InputError, Model, Scene
from alnlab._runs import load, record, runs, scene, table

__all__ = [
    "AlnlabError",
    "DamagedError",
    "InputError",
    "Model",
    "Scene",
    "load",
    "record",
    "runs",
    "scene",
    "table",
]
