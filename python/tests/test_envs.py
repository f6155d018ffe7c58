"""The quickstart's scene and its trained model as gymnasium environments:
both pass gymnasium's checker, share their spaces, and one random-shooting
MPC loop, written once, runs on either."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import alnlab
from alnlab.envs import ModelEnv, SceneEnv, observation_columns, scene_state


def docs_mpc():
    """`docs/env_mpc.py`, the loop the docs show, as a module."""
    path = Path(__file__).resolve().parents[2] / "docs" / "env_mpc.py"
    spec = importlib.util.spec_from_file_location("env_mpc", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_scene_and_its_model_are_gymnasium_environments_with_one_space(runs):
    world = SceneEnv("quickstart", variant="piecewise", out=runs, max_steps=5)
    learned = ModelEnv("quickstart", variant="piecewise", out=runs, max_steps=5)
    check_env(world, skip_render_check=True)
    check_env(learned, skip_render_check=True)
    assert world.observation_space == learned.observation_space
    assert world.action_space == learned.action_space
    assert world.observation_space.shape == (len(learned.model.state_names),)
    # The same logged frame starts both; the model's step is its prediction.
    a, _ = world.reset(options={"frame": 7})
    b, _ = learned.reset(options={"frame": 7})
    np.testing.assert_array_equal(a, b)
    action = learned.action_space.sample()
    predicted, reward, terminated, truncated, _ = learned.step(action)
    np.testing.assert_array_equal(predicted, learned.model.predict(b, action))
    assert (reward, terminated, truncated) == (0.0, False, False)
    # The world's step is the simulator's, in the model's columns.
    stepped, *_ = world.step(action)
    scene = alnlab.scene("quickstart", variant="piecewise", out=runs)
    _, _, states, variables = scene.logged()
    _, after = scene.step(states[7], action, threads=1)
    np.testing.assert_array_equal(stepped, after[observation_columns(scene, learned.model)])
    for _ in range(4):
        *_, truncated, _ = world.step(action)
    assert truncated


def test_one_mpc_loop_runs_on_the_simulator_and_on_the_model(runs):
    docs = docs_mpc()
    learned = ModelEnv("quickstart", variant="piecewise", out=runs)
    world = SceneEnv("quickstart", variant="piecewise", out=runs)
    cost = docs.bend_cost(learned.model)
    plan = {"decisions": 3, "candidates": 16, "horizon": 3, "seed": 0}
    on_scene, _, _ = docs.mpc(world, learned.model, cost, **plan)
    on_model, seconds, applied = docs.mpc(learned, learned.model, cost, **plan)
    assert np.isfinite(on_scene) and np.isfinite(on_model) and len(seconds) == 3
    # On the model's world every frame is the model's own prediction of the
    # action applied: replayed through predict, the loop's cost comes back.
    observation, _ = learned.reset(seed=0, options={"frame": 0})
    replayed = 0.0
    for action in applied:
        observation = learned.model.predict(observation, action, threads=1)
        replayed += float(cost(observation))
    assert replayed / len(applied) == on_model
    # Only the world differs, and the model is not the simulator.
    assert on_scene != on_model


def test_a_free_root_is_not_guessed_back_from_the_models_columns(runs):
    scene = alnlab.scene("quickstart", variant="piecewise", out=runs)
    model = alnlab.load("quickstart", variant="piecewise", out=runs)
    _, _, states, variables = scene.logged()
    observations = variables[:, observation_columns(scene, model)]
    with pytest.raises(alnlab.InputError, match=r"the scene's `root\.p\.x` is not among the model's columns and changes"):
        scene_state(scene, model, observations)
    # Given a state to take them from, the rest comes from it.
    back = scene_state(scene, model, observations[3], like=states[3])
    np.testing.assert_array_equal(back, states[3])


def test_bad_environment_arguments_are_refused_by_name(runs):
    with pytest.raises(alnlab.InputError, match="max_steps: expected a whole number of at least 1, got 0"):
        ModelEnv("quickstart", variant="piecewise", out=runs, max_steps=0)
    with pytest.raises(alnlab.InputError, match="reward: expected a function"):
        ModelEnv("quickstart", variant="piecewise", out=runs, reward=3)
    env = ModelEnv("quickstart", variant="piecewise", out=runs, reward=lambda o, a, n: -float(np.square(n - o).sum()))
    with pytest.raises(alnlab.InputError, match=r"options\['frame'\]: expected a logged frame"):
        env.reset(options={"frame": -1})
    env.reset(seed=1)
    with pytest.raises(alnlab.InputError, match="action: expected shape"):
        env.step(np.zeros(1))
    _, reward, *_ = env.step(env.action_space.sample())
    assert reward <= 0.0
