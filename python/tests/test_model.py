"""A run's trained models in Python predict what the test stage predicted,
roll out as chained predictions, on any thread count, and fail as the CLI
fails."""

import ast
import pickle
import shutil
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import alnlab
from alnlab import _alnlab

VARIANTS = ["piecewise", "walk", "gray"]


def load(artifacts, variant: str) -> alnlab.Model:
    found = artifacts(variant)
    return alnlab.Model(found["model"], found["codebook"])


def assert_predicts_as_scored(model: alnlab.Model, found: dict, scored_as: str, what: str) -> None:
    """Every test row's predicted level, state variable by state variable,
    equals predictions.parquet's for the model scored as `scored_as`, bit for
    bit."""
    pairs = pq.read_table(found["pairs"])
    states = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.state_names])
    controls = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.control_names])
    predicted = model.predict(states, controls, levels=True)
    assert predicted.dtype == np.uint16 and predicted.shape == states.shape
    table = pq.read_table(found["predictions"], columns=["model", "variable", "row", "predicted_level"])
    model_of = np.array(table.column("model").to_pylist())
    variable_of = np.array(table.column("variable").to_pylist())
    row_of = table.column("row").to_numpy()
    level_of = table.column("predicted_level").to_numpy()
    compared = 0
    for k, name in enumerate(model.state_names):
        at = (model_of == scored_as) & (variable_of == name)
        assert at.sum() > 100, (what, name)
        got = predicted[row_of[at], k]
        np.testing.assert_array_equal(got, level_of[at], err_msg=f"{what}: {name}")
        compared += int(at.sum())
    assert compared > 1000


def test_predict_levels_equal_the_test_stage_predictions(artifacts):
    """The trained model (`aln`) and the robust linear fit (`linear`)
    predict from Python what the test stage scored."""
    for variant in VARIANTS:
        found = artifacts(variant)
        model = alnlab.Model(found["model"], found["codebook"])
        assert_predicts_as_scored(model, found, "aln", variant)
        linear = alnlab.Model(found["linear"], found["codebook"])
        assert linear.kind == "piecewise-linear"
        assert linear.state_names == model.state_names
        assert_predicts_as_scored(linear, found, "linear", f"{variant}: linear")


def test_values_are_the_levels_values(artifacts):
    """A prediction's values quantize to its levels; a bit-forest's values
    are exactly its levels' values."""
    for variant in VARIANTS:
        model = load(artifacts, variant)
        x0, u = starts(artifacts, variant, model, 64)
        values = model.predict(x0, u)
        levels = model.predict(x0, u, levels=True)
        ranges = dict(model.ranges)
        for k, name in enumerate(model.state_names):
            low, high, count = ranges[name]
            expected = np.clip(np.round((values[:, k] - low) / (high - low) * (count - 1)), 0, count - 1)
            np.testing.assert_array_equal(levels[:, k], expected.astype(np.uint16))
            if model.kind != "piecewise-linear":
                np.testing.assert_array_equal(values[:, k], low + (high - low) * levels[:, k] / (count - 1))


def starts(artifacts, variant: str, model: alnlab.Model, b: int, h: int = 1, seed: int = 0):
    """`b` logged states of the variant's pairs and `h` frames of controls
    drawn from the logged ones."""
    pairs = pq.read_table(artifacts(variant)["pairs"])
    rng = np.random.default_rng(seed)
    rows = rng.choice(pairs.num_rows, size=b, replace=False)
    x0 = np.column_stack([pairs.column(f"x.{n}").to_numpy()[rows] for n in model.state_names])
    logged = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.control_names])
    controls = logged[rng.integers(0, len(logged), size=b * h)].reshape(b, h, len(model.control_names))
    return x0, (controls[:, 0, :] if h == 1 else controls)


def test_rollout_is_chained_predictions(artifacts):
    """A rollout starts at x0 and each frame is `predict` of the last."""
    for variant in VARIANTS:
        model = load(artifacts, variant)
        x0, controls = starts(artifacts, variant, model, 70, h=6, seed=1)
        path = model.rollout(x0, controls)
        assert path.shape == (70, 7, len(model.state_names)) and path.dtype == np.float64
        np.testing.assert_array_equal(path[:, 0], x0)
        state = x0
        for h in range(6):
            state = model.predict(state, controls[:, h])
            np.testing.assert_array_equal(path[:, h + 1], state, err_msg=f"{variant}, frame {h + 1}")
        np.testing.assert_array_equal(
            model.rollout(x0, controls, levels=True)[:, 6], model.predict(path[:, 5], controls[:, 5], levels=True)
        )


def test_one_thread_gives_the_same_bytes(artifacts):
    for variant in VARIANTS:
        model = load(artifacts, variant)
        x0, controls = starts(artifacts, variant, model, 300, h=4, seed=2)
        every = model.rollout(x0, controls)
        assert every.tobytes() == model.rollout(x0, controls, threads=1).tobytes()
        assert every.tobytes() == model.rollout(x0, controls, threads=3).tobytes()


def test_the_gil_is_released_while_predicting(artifacts):
    """Another Python thread runs while a long rollout runs: it stamps the
    time in a loop, and stamps fall well inside the call."""
    model = load(artifacts, "piecewise")
    x0, controls = starts(artifacts, "piecewise", model, 1000, h=1, seed=3)
    x0 = np.repeat(x0, 20, axis=0)
    controls = np.repeat(np.repeat(controls[:, None, :], 20, axis=0), 40, axis=1)
    stamps, done = [], threading.Event()

    def stamp():
        while not done.is_set():
            stamps.append(time.perf_counter())

    other = threading.Thread(target=stamp)
    other.start()
    time.sleep(0.02)
    start = time.perf_counter()
    model.rollout(x0, controls, threads=1)
    end = time.perf_counter()
    done.set()
    other.join()
    margin = 0.02
    assert end - start > 4 * margin, "the rollout is too short to tell"
    inside = [s for s in stamps if start + margin < s < end - margin]
    assert inside, "no other thread ran during the rollout: the GIL was held"


def cli_message(alnlab_bin: Path, model: Path, codebook: Path, tmp_path: Path) -> tuple[int, str]:
    """What `alnlab export verilog`, which loads a model as the package
    does, says of these files: its exit code and message."""
    done = subprocess.run(
        [alnlab_bin, "export", "verilog", model, "--codebook", codebook, "--output", tmp_path / "v"],
        capture_output=True,
        text=True,
    )
    lines = [line for line in done.stderr.splitlines() if line.startswith("error: ")]
    assert lines, done.stderr
    return done.returncode, lines[0].removeprefix("error: ")


def test_errors_carry_the_cli_messages(artifacts, alnlab_bin, tmp_path):
    found = artifacts("walk")
    damaged = tmp_path / "model.aln"
    shutil.copy(found["model"], damaged)
    data = bytearray(damaged.read_bytes())
    data[len(data) // 2] ^= 0x10
    damaged.write_bytes(bytes(data))
    cases = [
        (tmp_path / "missing.aln", found["codebook"], alnlab.InputError, "No such file"),
        (found["model"], found["pairs"], alnlab.InputError, "was trained with another codebook than"),
        (damaged, found["codebook"], alnlab.DamagedError, "damaged"),
    ]
    for model, codebook, kind, words in cases:
        with pytest.raises(kind) as raised:
            alnlab.Model(model, codebook)
        code, message = cli_message(alnlab_bin, model, codebook, tmp_path)
        assert str(raised.value) == message
        assert words in message
        assert raised.value.exit_code == code == (2 if kind is alnlab.InputError else 1)
        assert isinstance(raised.value, alnlab.AlnlabError)


def test_a_codebook_given_as_the_model_is_named_as_one(artifacts):
    # The two paths swapped (the package, unlike `export`, also takes
    # Parquet models: the boosted trees).
    found = artifacts("walk")
    with pytest.raises(alnlab.InputError, match=r"codebook.parquet: is a codebook \(the quantize stage's table\), "
                       r"not a model: expected a run's model.aln, linear.aln or boosted.parquet$"):
        alnlab.Model(found["codebook"], found["model"])


def test_bad_arrays_are_refused_with_the_expected_shape(artifacts):
    model = load(artifacts, "piecewise")
    d, u = len(model.state_names), len(model.control_names)
    x0 = np.zeros((5, d))
    with pytest.raises(alnlab.InputError, match=rf"states: expected shape \(B, {d}\).*{model.state_names[0]}.*got \(5, {d + 1}\)$"):
        model.predict(np.zeros((5, d + 1)), np.zeros((5, u)))
    # One state is reported as it was given, without a batch dimension.
    with pytest.raises(alnlab.InputError, match=rf"states: expected shape \({d},\),.*got \({d + 1},\)$"):
        model.predict(np.zeros(d + 1), np.zeros(u))
    with pytest.raises(alnlab.InputError, match=rf"controls: expected shape \({u},\) — a value per control.*got \({u + 1},\)$"):
        model.predict(np.zeros(d), np.zeros(u + 1))
    with pytest.raises(alnlab.InputError, match=rf"x0: expected shape \({d},\),.*got \({d - 1},\)$"):
        model.rollout(np.zeros(d - 1), np.zeros((3, u)))
    with pytest.raises(alnlab.InputError, match=rf"controls: expected shape \(5, H, {u}\).*{model.control_names[0]}"):
        model.rollout(x0, np.zeros((4, 3, u)))
    bad = x0.copy()
    bad[3, 2] = np.nan
    with pytest.raises(alnlab.InputError, match=rf"states: not a finite number at index \(3, 2\) \(`{model.state_names[2]}`\)"):
        model.predict(bad, np.zeros((5, u)))
    # Far outside what the model learned it would extrapolate unchecked.
    far = np.zeros(d)
    far[0] = 1e300
    with pytest.raises(alnlab.InputError, match=rf"states: `{model.state_names[0]}` is 1e300 at index \(0,\), far outside what the model learned"):
        model.predict(far, np.zeros(u))
    low, high = dict(model.ranges)[model.control_names[1]][:2]
    pushed = np.zeros((5, 3, u))
    pushed[2, 1, 1] = high + 1.5 * (high - low)
    with pytest.raises(alnlab.InputError, match=rf"controls: `{model.control_names[1]}` is .* at index \(2, 1, 1\)"):
        model.rollout(x0, pushed)
    pushed[2, 1, 1] = high + 0.5 * (high - low)
    assert np.isfinite(model.rollout(x0, pushed)).all()
    for threads in [0, -1, 1.5, "2", True]:
        with pytest.raises(alnlab.InputError, match="threads: expected a whole number of at least 1, got "):
            model.predict(x0, np.zeros((5, u)), threads=threads)
    for name, call in [
        ("states", lambda: model.predict("fast", np.zeros((5, u)))),
        ("states", lambda: model.predict(np.zeros((5, d), dtype=complex), np.zeros((5, u)))),
        ("states", lambda: model.predict([[1.0, 2.0], [3.0]], np.zeros((5, u)))),
        ("states", lambda: model.predict(np.zeros((2, 5, d)), np.zeros((5, u)))),
        ("controls", lambda: model.predict(x0, None)),
        ("x0", lambda: model.rollout(np.zeros(()), np.zeros((5, 3, u)))),
    ]:
        with pytest.raises(alnlab.InputError, match=rf"^{name}: expected an array of real numbers of shape \("):
            call()


def test_models_and_errors_pickle(artifacts, tmp_path):
    model = load(artifacts, "piecewise")
    again = pickle.loads(pickle.dumps(model))
    assert repr(again) == repr(model) and again.state_names == model.state_names
    x = np.zeros((2, len(model.state_names)))
    u = np.zeros((2, len(model.control_names)))
    np.testing.assert_array_equal(again.predict(x, u), model.predict(x, u))
    with pytest.raises(alnlab.InputError) as raised:
        model.predict(x, u, threads=0)
    back = pickle.loads(pickle.dumps(raised.value))
    assert type(back) is alnlab.InputError and str(back) == str(raised.value) and back.exit_code == 2


def test_any_array_like_of_real_numbers_predicts_as_float64(artifacts):
    """float32 (gymnasium's spaces, torch), ints, bools, lists, a single
    state: each cast to float64, the same predictions as float64 arrays."""
    model = load(artifacts, "piecewise")
    pairs = pq.read_table(artifacts("piecewise")["pairs"])
    x = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.state_names])[:8]
    u = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.control_names])[:8]
    want = model.predict(x, u, threads=1)
    x32, u32 = x.astype(np.float32), u.astype(np.float32)
    np.testing.assert_array_equal(model.predict(x32, u32), model.predict(x32.astype(np.float64), u32.astype(np.float64)))
    np.testing.assert_array_equal(model.predict(x.tolist(), u.tolist()), want)
    np.testing.assert_array_equal(model.predict(np.asfortranarray(x), np.repeat(u, 2, axis=0)[::2]), want)
    ints = np.rint(x).astype(np.int64)
    np.testing.assert_array_equal(model.predict(ints, u), model.predict(ints.astype(np.float64), u))
    np.testing.assert_array_equal(model.predict(x > 0, u), model.predict((x > 0).astype(np.float64), u))
    # One state and its controls give one next state.
    one = model.predict(x[3], u[3])
    assert one.shape == (len(model.state_names),)
    np.testing.assert_array_equal(one, want[3])
    path = model.rollout(x[3], np.repeat(u[3][None, :], 4, axis=0))
    assert path.shape == (5, len(model.state_names))
    np.testing.assert_array_equal(path, model.rollout(x[3:4], np.repeat(u[3:4, None, :], 4, axis=1))[0])
    # Into the caller's arrays, allocating none.
    out = np.empty_like(want)
    assert model.predict(x, u, threads=1, out=out) is out
    np.testing.assert_array_equal(out, want)
    inplace = x.copy()
    assert model.predict(inplace, u, threads=1, out=inplace) is inplace
    np.testing.assert_array_equal(inplace, want)
    one_out = np.empty(len(model.state_names))
    model.predict(x[3], u[3], out=one_out)
    np.testing.assert_array_equal(one_out, want[3])
    levels = np.empty(want.shape, dtype=np.uint16)
    np.testing.assert_array_equal(model.predict(x, u, levels=True, out=levels), model.predict(x, u, levels=True))
    paths = np.empty((8, 4, len(model.state_names)))
    controls = np.repeat(u[:, None, :], 3, axis=1)
    np.testing.assert_array_equal(model.rollout(x, controls, out=paths), model.rollout(x, controls))
    for bad in [np.empty((8, 2)), np.empty(want.shape, dtype=np.float32), np.empty(want.shape)[:, ::-1], [0.0] * 8]:
        with pytest.raises(alnlab.InputError, match=r"^out: expected a writeable C-contiguous float64 array of shape \(8, "):
            model.predict(x, u, out=bad)
    # Any Python int for a count, NumPy's too.
    np.testing.assert_array_equal(model.predict(x, u, threads=np.int64(2)), want)


def test_every_public_name_is_documented_and_stubbed():
    stubs = ast.parse((Path(alnlab.__file__).parent / "_alnlab.pyi").read_text())
    stubbed = {node.name: node for node in stubs.body if isinstance(node, (ast.ClassDef, ast.FunctionDef))}
    public = [name for name in dir(_alnlab) if not name.startswith("__")]
    assert public
    for name in public:
        stub_name = name.lstrip("_") if name.startswith("_") else name
        assert (getattr(_alnlab, name).__doc__ or "").strip(), name
        assert name in stubbed or stub_name in stubbed, f"{name} has no stub"
    for name in ["kind", "state_names", "control_names", "ranges", "predict", "rollout"]:
        assert (getattr(alnlab.Model, name).__doc__ or "").strip(), name
