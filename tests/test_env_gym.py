"""The Gymnasium SwarmNav env: official checkers, TimeLimit, determinism, physics, bad input.

Gymnasium's checkers, ``gym.make``, edge separations, seeding, pickling and bad input
(docs/testing.md), and the zero-action/``simulate`` equivalence of the env docstring.
"""

from __future__ import annotations

import math
import pickle
import warnings
from typing import Any

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from helpers import assert_same_rng_states, rng_states, strict_warnings
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from swarm_envs import ENV_ID
from swarm_envs.config import SwarmConfig
from swarm_envs.envs import OBS_BOUND, STAT_KEYS, SwarmNavEnv, observation_size
from swarm_envs.physics import simulate


def bound_actions(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Actions at the corners of the box: every entry ±1 with a random sign."""
    return rng.choice(np.array([-1.0, 1.0], np.float32), size=shape)


def assert_in_box(obs: np.ndarray, space: gym.spaces.Box) -> None:
    assert isinstance(obs, np.ndarray)
    assert obs.dtype == np.float32
    assert obs.shape == space.shape
    assert np.isfinite(obs).all()
    assert space.contains(obs), f"observation outside its Box: min {obs.min()}, max {obs.max()}"


def assert_info_ok(info: dict[str, Any]) -> None:
    assert set(STAT_KEYS) <= set(info)
    for key in STAT_KEYS:
        value = info[key]
        assert type(value) is float, f"info[{key!r}] is {type(value).__name__}, not float"
        assert math.isfinite(value), f"info[{key!r}] = {value}"


# --------------------------------------------------------------------------- checkers


@pytest.mark.parametrize("dim", [2, 3])
def test_gymnasium_check_env_passes_without_warnings(dim: int):
    env = gym.make(ENV_ID, dim=dim)
    with strict_warnings():
        gym_check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("dim", [2, 3])
def test_sb3_check_env_passes_without_warnings(dim: int):
    with strict_warnings():
        sb3_check_env(gym.make(ENV_ID, dim=dim), warn=True)
        sb3_check_env(SwarmNavEnv(dim=dim, n_agents=3), warn=True)


def test_gym_make_passive_checker_is_silent():
    with strict_warnings():
        env = gym.make(ENV_ID)
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        for _ in range(20):
            _, reward, terminated, truncated, _ = env.step(
                rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
            )
        env.close()
    assert type(reward) is float
    assert type(terminated) is bool and type(truncated) is bool


def test_registered_spec_has_no_time_limit():
    # The episode length is the config's max_steps alone: no TimeLimit is registered.
    spec = gym.spec(ENV_ID)
    assert spec.max_episode_steps is None
    assert spec.vector_entry_point == "swarm_envs.envs.adapters.gym_vector:SwarmNavVectorEnv"


@pytest.mark.parametrize("max_steps", [7, None, 1000])
def test_gym_make_truncates_at_exactly_max_steps(max_steps: int | None):
    kwargs = {} if max_steps is None else {"max_steps": max_steps}
    env = gym.make(ENV_ID, **kwargs)
    limit = max_steps or SwarmConfig().max_steps
    assert limit == (max_steps or 400)
    env.reset(seed=3)
    zero = np.zeros(env.action_space.shape, np.float32)
    for t in range(1, limit + 1):
        _, _, terminated, truncated, _ = env.step(zero)
        assert terminated is False  # zero action: the swarm does not reach a far goal
        assert truncated is (t == limit), f"step {t}: truncated={truncated}"


def test_gym_make_max_episode_steps_still_adds_a_time_limit():
    env = gym.make(ENV_ID, max_episode_steps=5)
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, np.float32)
    assert [env.step(zero)[3] for _ in range(5)] == [False] * 4 + [True]


def test_env_max_steps_truncates_without_time_limit():
    env = SwarmNavEnv(max_steps=9)
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, np.float32)
    flags = [env.step(zero)[3] for _ in range(9)]
    assert flags == [False] * 8 + [True]


def test_step_before_reset_raises():
    env = gym.make(ENV_ID)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(env.action_space.sample())
    raw = SwarmNavEnv()
    with pytest.raises(RuntimeError, match="reset"):
        raw.step(np.zeros(raw.action_space.shape, np.float32))


# --------------------------------------------------------------------------- spaces


@pytest.mark.parametrize("dim", [2, 3])
def test_spaces_are_finite_float32_boxes_of_documented_size(dim: int):
    env = SwarmNavEnv(n_agents=7, dim=dim, n_neighbors=4)
    per_agent = 2 * dim + 4 * (2 * dim + 1)
    assert observation_size(env.cfg) == per_agent
    obs_space, act_space = env.observation_space, env.action_space
    assert isinstance(obs_space, gym.spaces.Box) and isinstance(act_space, gym.spaces.Box)
    assert obs_space.shape == (7 * per_agent,) and obs_space.dtype == np.float32
    assert np.all(obs_space.low == -OBS_BOUND) and np.all(obs_space.high == OBS_BOUND)
    assert act_space.shape == (7 * dim,) and act_space.dtype == np.float32
    assert np.all(act_space.low == -1.0) and np.all(act_space.high == 1.0)
    obs, info = env.reset(seed=0)
    assert_in_box(obs, obs_space)
    assert_info_ok(info)


def test_random_steps_at_action_bounds_stay_in_box():
    env = SwarmNavEnv()
    rng = np.random.default_rng(1)
    obs, _ = env.reset(seed=1)
    for _ in range(1000):
        obs, reward, terminated, truncated, info = env.step(bound_actions(rng, (20,)))
        assert_in_box(obs, env.observation_space)
        assert math.isfinite(reward)
        if terminated or truncated:
            obs, _ = env.reset()
    assert_info_ok(info)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"init_radius": 0.0, "init_speed": 0.0},  # every agent at the same point
        {"init_radius": 1e-12},  # separations of order 1e-12
        {"init_radius": 1e6, "goal_distance_min": 1e6, "goal_distance_max": 1e6},
    ],
    ids=["coincident", "1e-12", "1e6"],
)
def test_extreme_separations_give_finite_observations_and_rewards(kwargs: dict[str, Any]):
    env = SwarmNavEnv(n_agents=8, **kwargs)
    rng = np.random.default_rng(2)
    obs, info = env.reset(seed=2)
    assert_in_box(obs, env.observation_space)
    assert_info_ok(info)
    for _ in range(10):
        obs, reward, _, _, info = env.step(bound_actions(rng, env.action_space.shape))
        assert_in_box(obs, env.observation_space)
        assert math.isfinite(reward)
        assert_info_ok(info)


# --------------------------------------------------------------------------- seeding


def rollout(env: gym.Env, seed: int, steps: int, action_seed: int = 0) -> list[tuple]:
    """``steps`` uniform random steps; resets (unseeded) when an episode ends."""
    rng = np.random.default_rng(action_seed)
    obs, info = env.reset(seed=seed)
    trace: list[tuple] = [(obs, info)]
    for _ in range(steps):
        out = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        trace.append(out)
        if out[2] or out[3]:
            trace.append(env.reset())
    return trace


def assert_traces_identical(a: list[tuple], b: list[tuple]) -> None:
    assert len(a) == len(b)
    for ta, tb in zip(a, b, strict=True):
        assert len(ta) == len(tb)
        for xa, xb in zip(ta, tb, strict=True):
            if isinstance(xa, np.ndarray):
                assert xa.dtype == xb.dtype and np.array_equal(xa, xb)
            else:
                assert xa == xb  # floats, bools and info dicts of floats, bit for bit


def test_300_step_rollouts_are_bit_identical_for_the_same_seed():
    a = rollout(gym.make(ENV_ID), seed=123, steps=300)
    b = rollout(gym.make(ENV_ID), seed=123, steps=300)
    assert_traces_identical(a, b)


def test_different_seeds_give_different_starts_and_reseeding_repeats():
    env = SwarmNavEnv()
    o1, _ = env.reset(seed=1)
    o2, _ = env.reset(seed=2)
    assert not np.array_equal(o1, o2)
    o_next, _ = env.reset()  # unseeded: continues the generator, a new start
    assert not np.array_equal(o2, o_next)
    o1_again, _ = env.reset(seed=1)
    assert np.array_equal(o1, o1_again)


def test_global_rngs_untouched_by_reset_and_step():
    env = gym.make(ENV_ID)
    before = rng_states()
    env.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(20):
        env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
    env.reset()
    env.reset(seed=5)
    assert_same_rng_states(before, rng_states())


@pytest.mark.parametrize("module", [pickle, cloudpickle], ids=["pickle", "cloudpickle"])
def test_pickle_round_trip_reproduces_rollout(module: Any):
    env = gym.make(ENV_ID)
    env.reset(seed=8)
    rng = np.random.default_rng(8)
    for _ in range(5):
        env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
    clone = module.loads(module.dumps(env))
    actions = rng.uniform(-1, 1, (20, *env.action_space.shape)).astype(np.float32)
    a = [env.step(act) for act in actions]
    b = [clone.step(act) for act in actions]
    assert_traces_identical(a, b)


# --------------------------------------------------------------------------- physics


@pytest.mark.parametrize("goal_in_physics", [False, True])
@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "velocity_verlet"])
def test_zero_action_reproduces_passive_simulate(integrator: str, goal_in_physics: bool):
    # dt small enough that every step is one substep of either integrator's rule
    # (velocity Verlet's is stable to half Euler's damping), as simulate() steps
    env = gym.make(
        ENV_ID, integrator=integrator, goal_in_physics=goal_in_physics, dt=0.05
    ).unwrapped
    env.reset(seed=6)
    core, cfg = env.core, env.cfg
    x0, v0, goal = core.x[0].copy(), core.v[0].copy(), core.goal[0].copy()
    K = 40
    xs, vs = [x0], [v0]
    zero = np.zeros(env.action_space.shape, np.float32)
    for _ in range(K):
        env.step(zero)
        assert core.stats()["substeps"][0] == 1.0
        xs.append(core.x[0].copy())
        vs.append(core.v[0].copy())
    ref_x, ref_v = simulate(
        cfg.physics,
        x0,
        v0,
        dt=cfg.dt,
        steps=K,
        goal=goal if goal_in_physics else None,
        integrator=integrator,
    )
    np.testing.assert_allclose(np.stack(xs), ref_x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.stack(vs), ref_v, rtol=0, atol=1e-12)
    if goal_in_physics:  # the sink really acts: without it the trajectory differs
        free_x, _ = simulate(cfg.physics, x0, v0, dt=cfg.dt, steps=K, integrator=integrator)
        assert np.abs(free_x[-1] - ref_x[-1]).max() > 1e-3


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "velocity_verlet"])
def test_constant_action_is_a_force_u_max_times_a(integrator: str):
    env = SwarmNavEnv(integrator=integrator, u_max=2.0, dt=0.05)  # one substep a step
    env.reset(seed=7)
    core, cfg = env.core, env.cfg
    N, d = cfg.n_agents, cfg.dim
    x0, v0 = core.x[0].copy(), core.v[0].copy()
    a = np.random.default_rng(7).uniform(-1, 1, (N, d)).astype(np.float32)
    K = 30
    for _ in range(K):
        env.step(a.reshape(-1))
        assert core.stats()["substeps"][0] == 1.0  # as simulate() steps
    ref_x, _ = simulate(
        cfg.physics, x0, v0, dt=cfg.dt, steps=K, control=cfg.u_max * a, integrator=integrator
    )
    np.testing.assert_allclose(core.x[0], ref_x[-1], rtol=0, atol=1e-12)
    passive_x, _ = simulate(cfg.physics, x0, v0, dt=cfg.dt, steps=K, integrator=integrator)
    assert np.abs(core.x[0] - passive_x[-1]).max() > 1e-2  # the action changed the path


def test_out_of_range_actions_are_clipped_to_the_box():
    a, b = SwarmNavEnv(), SwarmNavEnv()
    a.reset(seed=9)
    b.reset(seed=9)
    signs = bound_actions(np.random.default_rng(9), a.action_space.shape)
    for _ in range(5):
        oa, ra, *_ = a.step(5.0 * signs)
        ob, rb, *_ = b.step(signs)
    assert np.array_equal(oa, ob) and ra == rb


# --------------------------------------------------------------------------- episode end


def test_success_terminates_on_first_step_with_success_info():
    env = gym.make(ENV_ID, goal_distance_min=0.0, goal_distance_max=0.0, goal_radius=50.0)
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, np.float32))
    assert terminated is True and truncated is False
    assert info["success"] == 1.0 and info["fraction_arrived"] == 1.0
    assert reward > env.unwrapped.cfg.reward.success - 1.0  # the success bonus is paid


def test_success_on_the_last_step_is_termination_not_truncation():
    env = SwarmNavEnv(goal_distance_min=0.0, goal_distance_max=0.0, goal_radius=50.0, max_steps=1)
    env.reset(seed=0)
    _, _, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, np.float32))
    assert terminated is True and truncated is False


def test_info_keys_are_finite_floats_on_reset_and_step():
    env = gym.make(ENV_ID)
    _, info = env.reset(seed=0)
    assert_info_ok(info)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert_info_ok(info)
    assert 0.0 <= info["fraction_arrived"] <= 1.0 and info["success"] in (0.0, 1.0)


# --------------------------------------------------------------------------- bad input


BAD_KWARGS = [
    ({"n_agent": 3}, "n_agent"),
    ({"dt": -1}, "dt"),
    ({"physics": {"l_r": 0}}, "l_r"),
    ({"physics": {"C_x": 1.0}}, "C_x"),
    ({"dim": 4}, "dim"),
    ({"integrator": "rk4"}, "integrator"),
    ({"n_agents": 0}, "n_agents"),
    ({"goal_distance_min": 5.0, "goal_distance_max": 1.0}, "goal_distance_max"),
    ({"reward": {"success": -1.0}}, "success"),
    ({"config": "no/such/file.yaml"}, "not found"),
]


@pytest.mark.parametrize(("kwargs", "name"), BAD_KWARGS, ids=[n for _, n in BAD_KWARGS])
def test_bad_kwargs_raise_value_error_naming_the_problem(kwargs: dict[str, Any], name: str):
    with pytest.raises(ValueError, match=name):
        gym.make(ENV_ID, **kwargs)


def test_bad_value_message_names_the_allowed_range():
    with pytest.raises(ValueError, match=r"dt.*\(0, inf\)"):
        SwarmNavEnv(dt=-1)
    with pytest.raises(ValueError, match="allowed keys"):
        SwarmNavEnv(n_agent=3)


def test_bad_render_mode_raises():
    with pytest.raises(ValueError, match="render_mode"):
        SwarmNavEnv(render_mode="rgb")


def test_config_file_loads_and_kwargs_override_it():
    env = gym.make(ENV_ID, config="configs/env/paper_navigation.yaml")
    cfg = env.unwrapped.cfg
    assert cfg.n_agents == 31 and cfg.physics.C_o == 0.7 and cfg.goal_radius == 2.0
    obs, _ = env.reset(seed=0)
    assert obs.shape == (31 * observation_size(cfg),)

    env = gym.make(
        ENV_ID, config="configs/env/paper_navigation.yaml", n_agents=5, physics={"C_o": 0.3}
    )
    cfg = env.unwrapped.cfg
    assert cfg.n_agents == 5 and cfg.physics.C_o == 0.3
    assert cfg.physics.C_g == 15.0 and cfg.goal_radius == 2.0  # the rest still from the file


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_actions_raise(bad: float):
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, np.float32)
    action[3] = bad
    with pytest.raises(ValueError, match="finite"):
        env.step(action)


@pytest.mark.parametrize("shape", [(19,), (21,), (2, 20), (0,)])
def test_wrong_action_shape_raises(shape: tuple[int, ...]):
    env = SwarmNavEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(shape, np.float32))


def test_non_numeric_action_raises():
    env = SwarmNavEnv(n_agents=1)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="numeric"):
        env.step(np.array(["a", "b"]))


def test_rejected_action_leaves_the_state_unchanged():
    a, b = SwarmNavEnv(), SwarmNavEnv()
    a.reset(seed=5)
    b.reset(seed=5)
    with pytest.raises(ValueError):
        a.step(np.full(a.action_space.shape, np.nan, np.float32))
    act = np.full(a.action_space.shape, 0.5, np.float32)
    oa, ra, *_ = a.step(act)
    ob, rb, *_ = b.step(act)
    assert np.array_equal(oa, ob) and ra == rb


# --------------------------------------------------------------------------- rendering


def test_rgb_array_frames_are_uint8_not_blank_and_change():
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    assert isinstance(first, np.ndarray) and first.dtype == np.uint8
    assert first.ndim == 3 and first.shape[2] == 3
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 2  # more than a background
    for _ in range(10):
        env.step(np.ones(env.action_space.shape, np.float32))
    later = env.render()
    assert later.shape == first.shape and not np.array_equal(first, later)
    env.close()
    env.close()


def test_render_without_render_mode_warns_and_returns_none():
    env = SwarmNavEnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    env.close()
    env.close()


def test_human_render_on_a_headless_machine_warns_but_runs():
    env = SwarmNavEnv(render_mode="human")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset(seed=0)
        env.step(np.zeros(env.action_space.shape, np.float32))
        assert env.render() is None
    for w in caught:  # on a machine with a display nothing is emitted
        assert issubclass(w.category, UserWarning) and "could not open a window" in str(w.message)
    assert len(caught) <= 1  # warned once, not every frame
    env.close()
    env.close()


def test_step_after_the_episode_ended_raises_until_reset():
    env = gym.make(ENV_ID, n_agents=2, max_steps=3).unwrapped
    env.reset(seed=0)
    zeros = np.zeros(env.action_space.shape, np.float32)
    for _ in range(3):
        *_, terminated, truncated, _ = env.step(zeros)
    assert terminated or truncated
    with pytest.raises(RuntimeError, match="after the episode ended"):
        env.step(zeros)
    env.reset(seed=1)
    env.step(zeros)
