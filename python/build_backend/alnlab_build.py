"""alnlab's build backend: maturin's, refusing to start without Rust.

Building the package compiles alnlab's Rust core, which needs Rust's
`cargo` on PATH. Where it is missing, maturin would quietly download a
toolchain of about 1 GB (puccinialin); this backend says what is missing
instead, and otherwise hands every hook to maturin unchanged.
"""

import os
import shutil

# Read by maturin's hooks: never fetch a toolchain behind the user's back.
os.environ["MATURIN_NO_INSTALL_RUST"] = "1"

import maturin  # noqa: E402


def _require_cargo() -> None:
    if shutil.which("cargo") is None:
        raise RuntimeError(
            "building alnlab compiles its Rust core and needs Rust's `cargo` on PATH, which is "
            "missing: install Rust (https://rustup.rs, or your system's rustc and cargo packages) "
            "and run pip again. The first build takes several minutes; `pip install -v` shows "
            "cargo's progress."
        )


def get_requires_for_build_wheel(config_settings=None):
    return maturin.get_requires_for_build_wheel(config_settings)


def get_requires_for_build_sdist(config_settings=None):
    return maturin.get_requires_for_build_sdist(config_settings)


def get_requires_for_build_editable(config_settings=None):
    return maturin.get_requires_for_build_editable(config_settings)


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    _require_cargo()
    return maturin.prepare_metadata_for_build_wheel(metadata_directory, config_settings)


def prepare_metadata_for_build_editable(metadata_directory, config_settings=None):
    _require_cargo()
    return maturin.prepare_metadata_for_build_editable(metadata_directory, config_settings)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    _require_cargo()
    return maturin.build_wheel(wheel_directory, config_settings, metadata_directory)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    _require_cargo()
    return maturin.build_editable(wheel_directory, config_settings, metadata_directory)


def build_sdist(sdist_directory, config_settings=None):
    return maturin.build_sdist(sdist_directory, config_settings)
