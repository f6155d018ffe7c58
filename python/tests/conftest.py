"""What the package's tests share: the suite's quickstart run (three
replicates of walk and Gray bit-forests and a piecewise-linear ALN, made by
`cargo xtask test` before this step) and the alnlab binary that made it."""

import json
import os
from pathlib import Path

import pytest


def _required(name: str, what: str) -> Path:
    value = os.environ.get(name)
    if not value:
        pytest.fail(f"set {name} to {what} (`cargo xtask test` sets it)", pytrace=False)
    return Path(value)


@pytest.fixture(scope="session")
def runs() -> Path:
    """The runs folder holding the quickstart."""
    return _required("ALNLAB_TEST_RUNS", "a runs folder holding the quickstart experiment")


@pytest.fixture(scope="session")
def alnlab_bin() -> Path:
    """The alnlab binary, whose messages the package's errors must repeat."""
    return _required("ALNLAB_BIN", "the alnlab binary")


@pytest.fixture(scope="session")
def quickstart(runs: Path) -> dict:
    """The quickstart's run record."""
    return json.loads((runs / "quickstart" / "run.json").read_text())


@pytest.fixture(scope="session")
def artifacts(quickstart: dict):
    """A quickstart variant's artifact paths, by role (its first replicate)."""

    def of(variant: str) -> dict[str, Path]:
        for v in quickstart["variants"]:
            if v["name"] == variant and v["replicate"] == 0:
                return {role: Path(a["path"]) for role, a in v["artifacts"].items()}
        raise KeyError(f"the quickstart has no variant {variant}")

    return of
