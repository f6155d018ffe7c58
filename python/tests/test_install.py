"""The install says what it does: extras install every package the code
behind them imports, and a build without Rust stops and says so instead of
downloading a toolchain. The docs' MPC examples check their arguments."""

import ast
import importlib.metadata
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

PACKAGE = Path(__file__).resolve().parents[1]
ROOT = PACKAGE.parent


def imported(*files: Path) -> set[str]:
    """The third-party distributions the files import, by their
    canonical names (standard library and alnlab itself left out), as the
    installed packages map import names to distributions."""
    distributions = importlib.metadata.packages_distributions()
    found = set()
    for file in files:
        for node in ast.walk(ast.parse(file.read_text())):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top not in ("alnlab", "conftest"):
                    found.update(canonicalize_name(d) for d in distributions.get(top, [top]))
    return found


def requirements(specs: list[str]) -> set[str]:
    return {canonicalize_name(Requirement(spec).name) for spec in specs}


def test_each_extra_installs_what_the_code_behind_it_imports():
    project = tomllib.loads((PACKAGE / "pyproject.toml").read_text())["project"]
    core = requirements(project["dependencies"])
    extras = {name: requirements(specs) | core for name, specs in project["optional-dependencies"].items()}
    # What each promises (README): Arrow tables; DataFrames too; the
    # gymnasium environments; everything the package's tests import.
    assert {"pyarrow"} <= extras["tables"]
    assert {"pyarrow", "pandas"} <= extras["pandas"]
    # Each module within the extra that serves it: the environments with
    # gymnasium, the rest with the tables (pandas only where asked for).
    assert imported(PACKAGE / "alnlab/envs.py") <= extras["gym"]
    rest = [f for f in (PACKAGE / "alnlab").glob("*.py") if f.name != "envs.py"]
    assert imported(*rest) <= extras["pandas"], imported(*rest)
    # The tests, the ROS 2 writer they run and the build backend they import.
    tests = imported(*(PACKAGE / "tests").glob("*.py"), ROOT / "tests/record_joint_states.py",
                     PACKAGE / "build_backend/alnlab_build.py")
    assert tests <= extras["test"], tests - extras["test"]


def test_a_build_without_cargo_stops_and_says_what_is_missing(tmp_path):
    # PATH holds nothing but an empty folder: no cargo, no rustup.
    script = (
        "import os, sys\n"
        f"sys.path.insert(0, {str(PACKAGE / 'build_backend')!r})\n"
        "import alnlab_build\n"
        "assert os.environ['MATURIN_NO_INSTALL_RUST'] == '1'\n"
        f"alnlab_build.build_wheel({str(tmp_path)!r})\n"
    )
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env={**os.environ, "PATH": str(tmp_path)})
    assert run.returncode != 0
    assert "RuntimeError: building alnlab compiles its Rust core and needs Rust's `cargo` on PATH" in run.stderr
    assert "install Rust (https://rustup.rs" in run.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("script", ["docs/mpc.py", "docs/env_mpc.py"])
@pytest.mark.parametrize(("flag", "value", "says"), [
    ("--candidates", "0", "expected at least 1, got 0"),
    ("--horizon", "-3", "expected at least 1, got -3"),
    ("--decisions", "ten", "expected a whole number, got 'ten'"),
    ("--candidates", "1.5", "expected a whole number, got '1.5'"),
])
def test_the_mpc_examples_refuse_bad_arguments_by_name(script, flag, value, says):
    run = subprocess.run([sys.executable, ROOT / script, flag, value], capture_output=True, text=True)
    assert run.returncode == 2
    assert f"error: argument {flag}: {says}" in run.stderr
