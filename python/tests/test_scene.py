"""A run's scene stepped from Python reproduces its own log: from a logged
frame, under the torques logged there, the next frame."""

import numpy as np
import pytest

import alnlab


@pytest.fixture(scope="module")
def worm(runs):
    return alnlab.scene("quickstart", variant="walk", out=runs)


def successors(worm, held: bool):
    """Indices f of logged frames followed by f + 1 in the same run (with
    the torques unchanged at f + 1, if `held`), and the control columns."""
    run, frame, _, variables = worm.logged()
    controls = [worm.variable_names.index(n) for n in worm.control_names]
    f = np.flatnonzero((run[:-1] == run[1:]) & (frame[1:] == frame[:-1] + 1))
    if held:
        f = f[np.all(variables[f][:, controls] == variables[f + 1][:, controls], axis=1)]
    return f, controls


def test_a_step_from_a_logged_frame_is_the_next_logged_frame(worm):
    _, _, states, variables = worm.logged()
    assert states.shape[1] == len(worm.state_names) and variables.shape[1] == len(worm.variable_names)
    f, controls = successors(worm, held=False)
    assert len(f) > 10000
    stepped, _ = worm.step(states[f], variables[f][:, controls])
    np.testing.assert_allclose(stepped, states[f + 1], rtol=0, atol=1e-9)
    # Where the torques stay, every variable is the next frame's too (where
    # they change, the next frame reads the new torques and what they do).
    f, controls = successors(worm, held=True)
    stepped, read = worm.step(states[f], variables[f][:, controls])
    np.testing.assert_allclose(read, variables[f + 1], rtol=1e-9, atol=1e-9)


def test_frames_step_on_and_fewer_steps_are_a_coarser_simulator(worm):
    _, _, states, variables = worm.logged()
    f, controls = successors(worm, held=True)
    two = f[np.isin(f + 1, f)][:500]
    stepped, _ = worm.step(states[two], variables[two][:, controls], frames=2)
    np.testing.assert_allclose(stepped, states[two + 2], rtol=0, atol=1e-9)
    coarse, _ = worm.step(states[two], variables[two][:, controls], frames=2, steps=2)
    # Two steps of 5 ms miss what twenty of 0.5 ms make, by far more than
    # rounding.
    assert np.abs(coarse - states[two + 2]).max() > 1e-6


def test_any_thread_count_gives_the_same_bytes(worm):
    _, _, states, variables = worm.logged()
    f, controls = successors(worm, held=False)
    f = f[:333]
    every = worm.step(states[f], variables[f][:, controls])
    for threads in [1, 3]:
        again = worm.step(states[f], variables[f][:, controls], threads=threads)
        assert all(a.tobytes() == b.tobytes() for a, b in zip(every, again))


def test_the_scene_names_what_the_models_read(runs, worm):
    for variant in ["piecewise", "walk"]:
        model = alnlab.load("quickstart", variant=variant, out=runs)
        assert set(model.state_names) <= set(worm.variable_names)
        assert model.control_names == worm.control_names
    assert worm.name == "worm" and not worm.plant
    assert worm.steps_per_frame == 10 and worm.frame_dt == pytest.approx(0.01)


def test_bad_steps_are_refused(runs, worm):
    _, _, states, _ = worm.logged()
    s, u = len(worm.state_names), len(worm.control_names)
    with pytest.raises(alnlab.InputError, match=rf"states: expected shape \(B, {s}\).*root.p.x"):
        worm.step(np.zeros((2, s - 1)), np.zeros((2, u)))
    with pytest.raises(alnlab.InputError, match=rf"controls: expected shape \(2, {u}\).*g.2.x"):
        worm.step(states[:2], np.zeros((2, u + 1)))
    bad = states[:3].copy()
    bad[1, 0] = np.inf
    with pytest.raises(alnlab.InputError, match="states: row 1 is not finite"):
        worm.step(bad, np.zeros((3, u)))
    for steps in [0, -3]:
        with pytest.raises(alnlab.InputError, match="steps: expected a whole number of at least 1, got "):
            worm.step(states[:1], np.zeros((1, u)), steps=steps)
    with pytest.raises(alnlab.InputError, match="frames: expected a whole number of at least 1, got -1"):
        worm.step(states[:1], np.zeros((1, u)), frames=-1)
    with pytest.raises(alnlab.InputError, match="threads: expected a whole number of at least 1, got -2"):
        worm.step(states[:1], np.zeros((1, u)), threads=-2)
    # A state the simulator cannot step is an error, not NaN.
    with pytest.raises(alnlab.InputError, match="states: row 0 is not a state: link 1's orientation is no unit quaternion"):
        worm.step(np.zeros((1, s)), np.zeros((1, u)))
    # One state is reported as it was given, without a batch dimension.
    with pytest.raises(alnlab.InputError, match=rf"states: expected shape \({s},\), .*got \({s + 1},\)$"):
        worm.step(np.zeros(s + 1), np.zeros(u))
    with pytest.raises(alnlab.InputError, match="states: not a state: link 1's orientation"):
        worm.step(np.zeros(s), np.zeros(u))
    # A step that leaves the finite numbers is an error naming the step, or
    # NaN on request (a planner's candidate that blew up).
    spinning = states[5:7].copy()
    spinning[1, worm.state_names.index("w.1.x")] = 1e300
    with pytest.raises(alnlab.InputError, match=r"states: row 1 left the finite numbers at step 1 of 10 \(10 a frame\)"):
        worm.step(spinning, np.zeros((2, u)))
    stepped, variables = worm.step(spinning, np.zeros((2, u)), allow_nan=True)
    assert np.isnan(stepped[1]).all() and np.isnan(variables[1]).all()
    np.testing.assert_array_equal(stepped[0], worm.step(spinning[:1], np.zeros((1, u)))[0][0])
    # One state (float32, as a gymnasium space gives) steps as a batch of one.
    one, variables = worm.step(states[5].astype(np.float32), np.zeros(u, dtype=np.float32))
    batch, _ = worm.step(states[5:6].astype(np.float32).astype(np.float64), np.zeros((1, u)))
    # A strided (not contiguous) batch is taken too.
    strided, _ = worm.step(states[:10:2], np.zeros((5, u)))
    np.testing.assert_array_equal(strided, worm.step(np.ascontiguousarray(states[:10:2]), np.zeros((5, u)))[0])
    assert one.shape == (s,) and variables.shape == (len(worm.variable_names),)
    np.testing.assert_array_equal(one, batch[0])
    with pytest.raises(alnlab.InputError, match="scene `worm` declares no plant"):
        alnlab.scene("quickstart", variant="walk", out=runs, plant=True)
    with pytest.raises(alnlab.InputError, match="has no scene `arm`; it has worm"):
        alnlab.scene("quickstart", variant="walk", out=runs, name="arm")
