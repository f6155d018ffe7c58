"""Runs, their models and their tables, found as the CLI finds them."""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from alnlab import _alnlab
from alnlab._alnlab import InputError, Model, Scene

if TYPE_CHECKING:
    import pandas
    import pyarrow

PathLike = str | os.PathLike[str]


def _where(run: PathLike, out: PathLike) -> tuple[str, str]:
    """(runs folder, run reference): a run's folder (holding ``run.json``)
    stands for its experiment's latest run in the folder above it."""
    path = Path(run)
    if (path / "run.json").is_file():
        return str(path.parent), path.name
    return str(out), str(run)


#: The models ``load`` finds, by the artifact that holds each.
MODELS = {"aln": "model", "linear": "linear", "boosted": "boosted"}


def load(
    run: PathLike = "quickstart",
    *,
    variant: str | None = None,
    replicate: int = 1,
    out: PathLike = "runs",
    model: str = "aln",
) -> Model:
    """A run's trained model, or one of the baselines its test stage fitted
    on the same training rows.

    Parameters
    ----------
    run
        A run id, a unique prefix of one, an experiment's name (its latest
        run), ``NAME~N`` (N runs before the latest), ``RUN:VARIANT``, or a
        run's folder (``runs/quickstart``).
    variant
        The variant; needed where the run's variants have different models.
    replicate
        The replicate, from 1; the first stands for its variant in the
        report, as here by default.
    out
        The runs folder (``alnlab run --out``; default ``runs``).
    model
        ``aln`` (the trained model), ``linear`` (the robust linear fit of
        each variable's change: a piecewise-linear model of one piece per
        output) or ``boosted`` (the gradient-boosted trees, fitted where the
        manifest sets ``[test] peer = true``). Each predicts as the test stage
        scored it in ``predictions.parquet``.

    Raises
    ------
    InputError
        No such run, variant or model, or its files are gone from the cache;
        the message is the CLI's.
    """
    if model not in MODELS:
        raise InputError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    where, reference = _where(run, out)
    role = MODELS[model]
    *_, files = _alnlab.find_artifacts(
        where, reference, [role, "codebook"], variant=variant, replicate=replicate
    )
    return Model(files[role], files["codebook"])


def scene(
    run: PathLike = "quickstart",
    *,
    variant: str | None = None,
    replicate: int = 1,
    out: PathLike = "runs",
    name: str | None = None,
    plant: bool = False,
) -> Scene:
    """A run's scene, rebuilt from its trajectory log, ready to step: the
    model as written (the simulator a user has), or with ``plant=True`` the
    plant its data were simulated as, where the scene declares one. The run
    is found as ``load`` finds it; ``name`` picks a scene where the log
    holds several."""
    where, reference = _where(run, out)
    *_, files = _alnlab.find_artifacts(
        where, reference, ["trajectory"], variant=variant, replicate=replicate
    )
    return Scene(files["trajectory"], name, plant=plant)


def record(run: PathLike = "quickstart", *, out: PathLike = "runs") -> dict[str, Any]:
    """A run's record as a dict: its manifest, commit, seed, and per variant
    and replicate its artifacts, parameters and headline metrics."""
    where, reference = _where(run, out)
    return json.loads(_alnlab.run_record(where, reference))


def _pyarrow():
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError as e:
        raise ImportError("alnlab's tables need pyarrow: pip install 'alnlab[tables]'") from e
    return pyarrow


def _as_pandas(table: pyarrow.Table) -> pandas.DataFrame:
    """`table` as a pandas DataFrame; a clear error where pandas is missing."""
    try:
        import pandas  # noqa: F401
    except ImportError as e:
        raise ImportError("pandas=True needs pandas: pip install 'alnlab[pandas]'") from e
    return table.to_pandas()


def runs(out: PathLike = "runs", *, pandas: bool = False) -> pyarrow.Table | pandas.DataFrame:
    """Every run recorded under ``out``, oldest first: a row per variant and
    replicate with the run's ``id``, ``experiment``, ``started``,
    ``wall_seconds``, ``git_commit``, the ``variant``, its ``replicate``
    (from 1) and ``seed``, its parameters (``param.<key>``, strings) and
    headline metrics (``metric.<name>``). A record that cannot be read is
    left out with a warning naming it."""
    pa = _pyarrow()
    found, unreadable = _alnlab.run_records(str(out))
    for path, why in unreadable:
        warnings.warn(f"{path}: left out: {why}", stacklevel=2)
    rows = []
    for text in found:
        r = json.loads(text)
        for v in r["variants"]:
            row = {
                "id": r["id"],
                "experiment": r["experiment"],
                "started": r["started"],
                "wall_seconds": r["wall_seconds"],
                "git_commit": r.get("git_commit"),
                "variant": v["name"],
                "replicate": v.get("replicate", 0) + 1,
                "seed": v.get("seed"),
            }
            row.update({f"param.{k}": value for k, value in v.get("parameters", {}).items()})
            metrics = (v.get("metrics") or {}).get("values", {})
            row.update({f"metric.{k}": value for k, value in metrics.items()})
            rows.append(row)
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    types = {"wall_seconds": pa.float64(), "replicate": pa.int32(), "seed": pa.uint64()}

    def type_of(column: str):
        if column.startswith("metric."):
            return pa.float64()
        return types.get(column, pa.string())

    # Every row with every column, null where a run lacks it.
    found = pa.table({c: pa.array([row.get(c) for row in rows], type=type_of(c)) for c in columns})
    return _as_pandas(found) if pandas else found


def table(
    run: PathLike,
    name: str,
    *,
    variant: str | None = None,
    replicate: int = 1,
    out: PathLike = "runs",
    pandas: bool = False,
) -> pyarrow.Table | pandas.DataFrame:
    """A stage's table of a run by its artifact name (``predictions``,
    ``summary``, ``comparisons``, ``pairs``, ``levels``, ``codebook``,
    ``timings``, ``rollout``, ``planning``, …) of a variant's replicate
    (the first by default), found as ``load`` finds a model, its bytes
    checked against the run's record first.

    Raises
    ------
    InputError
        No such run, variant or table, or it is not a table (an MCAP log,
        the model).
    DamagedError
        The file is not what the run recorded.
    """
    pa = _pyarrow()
    where, reference = _where(run, out)
    *_, files = _alnlab.find_artifacts(
        where, reference, [name], variant=variant, replicate=replicate, verify=True
    )
    path = files[name]
    if not path.endswith(".parquet"):
        raise InputError(f"{path}: `{name}` is not a table (Parquet); open it with its own reader")
    found = pa.parquet.read_table(path)
    return _as_pandas(found) if pandas else found
