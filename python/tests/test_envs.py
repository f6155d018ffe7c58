"""The quickstart's scene and its trained model as gymnasium environments:
both pass gymnasium's checker, share their spaces, and one random-shooting
MPC loop, written once, runs on either."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import alnlab
from alnlab.envs import ModelEnv, SceneEnv, observation_columns, scene_state


def mpc(world, model_env, *, decisions=3, candidates=16, horizon=3, seed=0):
    """Random shooting: each decision samples candidate action sequences,
    rolls each out on `model_env` from the world's observation, and applies
    the first action of the one that moves the observation least."""
    rng = np.random.default_rng(seed)
    obs, _ = world.reset(seed=seed)
    low, high = world.action_space.low, world.action_space.high
    costs = []
    for _ in range(decisions):
        plans = rng.uniform(low, high, size=(candidates, horizon, len(low)))
        path = model_env.model.rollout(np.repeat(obs[None, :], candidates, axis=0), plans, threads=1)
        cost = np.square(path[:, 1:] - obs).sum(axis=(1, 2))
        obs, _, _, _, _ = world.step(plans[int(np.argmin(cost)), 0])
        costs.append(float(cost.min()))
    return obs, costs


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
    learned = ModelEnv("quickstart", variant="piecewise", out=runs)
    for world in [SceneEnv("quickstart", variant="piecewise", out=runs), learned]:
        obs, costs = mpc(world, learned)
        assert obs.shape == world.observation_space.shape and np.isfinite(obs).all()
        assert len(costs) == 3 and all(np.isfinite(costs))


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
