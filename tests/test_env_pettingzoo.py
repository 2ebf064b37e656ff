"""The PettingZoo SwarmNav envs: official tests, spaces, fresh dicts, layout, bad input.

PettingZoo's checkers, seeding, ``max_cycles``, rendering, space identity, fresh dicts,
pickling and bad input (docs/testing.md), for the parallel and AEC envs.
"""

from __future__ import annotations

import math
import pickle
from typing import Any

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest
from helpers import assert_same_rng_states, rng_states, strict_warnings
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    seed_test,
)
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import BaseWrapper, OrderEnforcingWrapper

from swarm_envs import ENV_ID, swarm_informed_v0, swarm_mill_v0, swarm_nav_v0
from swarm_envs.envs import OBS_BOUND, STAT_KEYS, SwarmNavParallelEnv, observation_size


def zeros(env: SwarmNavParallelEnv) -> dict[str, np.ndarray]:
    return {a: np.zeros(env.action_space(a).shape, np.float32) for a in env.agents}


def random_actions(env: SwarmNavParallelEnv, rng: np.random.Generator) -> dict[str, np.ndarray]:
    d = env.cfg.dim
    return {a: rng.uniform(-1, 1, d).astype(np.float32) for a in env.agents}


def assert_info_ok(info: dict[str, Any]) -> None:
    assert set(STAT_KEYS) <= set(info)
    for key in STAT_KEYS:
        assert type(info[key]) is float, f"info[{key!r}] is {type(info[key]).__name__}"
        assert math.isfinite(info[key]), f"info[{key!r}] = {info[key]}"


# --------------------------------------------------------------------------- official tests


@pytest.mark.parametrize(("dim", "cycles"), [(2, 1000), (3, 300)])
def test_parallel_api_test(dim: int, cycles: int):
    with strict_warnings():
        parallel_api_test(swarm_nav_v0.parallel_env(dim=dim), num_cycles=cycles)


def test_parallel_api_test_single_agent():
    with strict_warnings():
        parallel_api_test(swarm_nav_v0.parallel_env(n_agents=1), num_cycles=50)


@pytest.mark.parametrize(("dim", "cycles"), [(2, 1000), (3, 100)])
def test_aec_api_test(dim: int, cycles: int):
    with strict_warnings():
        api_test(swarm_nav_v0.env(dim=dim), num_cycles=cycles)


@pytest.mark.parametrize("module", [swarm_nav_v0, swarm_informed_v0, swarm_mill_v0])
def test_raw_env_is_bare_and_env_wraps_it_once(module: Any):
    """PettingZoo's convention: ``raw_env`` the bare AEC env (``parallel_to_aec`` of the
    parallel env, here checking each action as it is given), ``env`` that env in the
    order-enforcing wrapper, once."""
    raw = module.raw_env(n_agents=3)
    assert isinstance(raw, parallel_to_aec_wrapper) and not isinstance(raw, BaseWrapper)
    wrapped = module.env(n_agents=3)
    assert isinstance(wrapped, OrderEnforcingWrapper)
    assert isinstance(wrapped.env, parallel_to_aec_wrapper)
    assert not isinstance(wrapped.env, BaseWrapper)
    assert wrapped.unwrapped.cfg.task == raw.unwrapped.cfg.task
    with pytest.raises(AttributeError, match="reset"):  # the wrapper's order check
        wrapped.agent_selection  # noqa: B018
    raw.reset(seed=0)
    with pytest.raises(ValueError, match="action of agent_0"):  # checked as it is given
        raw.step(np.array([np.nan, 0.0], np.float32))
    raw.step(np.zeros(2, np.float32))
    assert raw.agent_selection == "agent_1"


def test_parallel_seed_test():
    with strict_warnings():
        parallel_seed_test(swarm_nav_v0.parallel_env)


def test_aec_seed_test():
    with strict_warnings():
        seed_test(swarm_nav_v0.env, num_cycles=200)


def test_max_cycles_test():
    with strict_warnings():
        max_cycles_test(swarm_nav_v0)


def test_max_cycles_sets_the_episode_length():
    env = swarm_nav_v0.parallel_env(max_cycles=6)
    assert env.max_cycles == env.cfg.max_steps == 6
    env.reset(seed=0)
    for t in range(1, 7):
        _, _, terms, truncs, _ = env.step(zeros(env))
        assert not any(terms.values())
        assert all(truncs.values()) is (t == 6)
    assert env.agents == []


def test_render_test():
    def not_blank(frame: np.ndarray) -> bool:
        return len(np.unique(frame.reshape(-1, 3), axis=0)) > 2

    with strict_warnings():
        render_test(swarm_nav_v0.env, custom_tests={"rgb_array": not_blank})


def test_parallel_render_frames_change_and_close_twice():
    env = swarm_nav_v0.parallel_env(render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3
    for _ in range(10):
        env.step({a: np.ones(2, np.float32) for a in env.agents})
    later = env.render()
    assert later.shape == first.shape and not np.array_equal(first, later)
    env.close()
    env.close()


def test_parallel_render_without_mode_warns_and_returns_none():
    env = swarm_nav_v0.parallel_env()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    env.close()


# --------------------------------------------------------------------------- spaces, dicts


def test_spaces_are_cached_equal_and_documented():
    env = swarm_nav_v0.parallel_env(n_agents=5)
    first = env.possible_agents[0]
    obs0, act0 = env.observation_space(first), env.action_space(first)
    assert env.possible_agents == [f"agent_{i}" for i in range(5)]
    for a in env.possible_agents:
        assert env.observation_space(a) is env.observation_space(a)
        assert env.action_space(a) is env.action_space(a)
        assert env.observation_space(a) == obs0 and env.action_space(a) == act0
    assert isinstance(obs0, gym.spaces.Box) and obs0.dtype == np.float32
    assert obs0.shape == (observation_size(env.cfg),) == (4 + 6 * 5,)
    assert np.all(obs0.low == -OBS_BOUND) and np.all(obs0.high == OBS_BOUND)
    assert act0.shape == (2,) and np.all(act0.low == -1) and np.all(act0.high == 1)


def test_step_returns_fresh_dicts():
    env = swarm_nav_v0.parallel_env(n_agents=4)
    _, infos = env.reset(seed=0)
    assert infos["agent_0"] is not infos["agent_1"]
    first = env.step(zeros(env))
    # What RLlib and user code do to returned dicts:
    for d in first[1:4]:
        d["__all__"] = True
    first[0]["agent_0"][:] = 99.0
    first[4]["agent_0"]["extra"] = 1.0
    second = env.step(zeros(env))
    for new, old in zip(second, first, strict=True):
        assert new is not old
        assert set(new) == set(env.agents)
    assert all(info is not second[4]["agent_0"] for info in list(second[4].values())[1:])
    assert "extra" not in second[4]["agent_0"] and "extra" not in second[4]["agent_1"]
    assert np.abs(second[0]["agent_0"]).max() < 99.0
    # the mutated observation did not leak into the state: a twin env agrees
    twin = swarm_nav_v0.parallel_env(n_agents=4)
    twin.reset(seed=0)
    twin.step(zeros(twin))
    twin_obs = twin.step(zeros(twin))[0]
    assert all(np.array_equal(twin_obs[a], second[0][a]) for a in env.agents)


def test_reset_and_step_infos_are_finite_floats_for_every_agent():
    env = swarm_nav_v0.parallel_env()
    _, infos = env.reset(seed=0)
    assert set(infos) == set(env.possible_agents)
    for info in infos.values():
        assert_info_ok(info)
    _, rewards, terms, truncs, infos = env.step(random_actions(env, np.random.default_rng(0)))
    for a in env.possible_agents:
        assert_info_ok(infos[a])
        assert type(rewards[a]) is float and math.isfinite(rewards[a])
        assert type(terms[a]) is bool and type(truncs[a]) is bool
    assert len(set(rewards.values())) == 1  # cooperative: one shared reward


def reference_observation(env: SwarmNavParallelEnv) -> np.ndarray:
    """The docstring's observation table, agent by agent, from the core state."""
    cfg, core = env.cfg, env.core
    x, v, goal = core.x[0], core.v[0], core.goal[0]
    N, d, k = cfg.n_agents, cfg.dim, cfg.n_neighbors
    rows = []
    for i in range(N):
        parts = [(goal - x[i]) / cfg.obs_goal_scale, v[i] / cfg.obs_velocity_scale]
        others = sorted((j for j in range(N) if j != i), key=lambda j: np.linalg.norm(x[j] - x[i]))
        for m in range(k):
            if m < len(others):
                j = others[m]
                parts += [
                    (x[j] - x[i]) / cfg.obs_neighbor_scale,
                    (v[j] - v[i]) / cfg.obs_velocity_scale,
                    [1.0],
                ]
            else:
                parts.append(np.zeros(2 * d + 1))
        rows.append(np.clip(np.concatenate(parts), -OBS_BOUND, OBS_BOUND))
    return np.stack(rows)


@pytest.mark.parametrize(
    ("n_agents", "dim", "k"), [(5, 2, 6), (12, 2, 3), (9, 3, 4), (1, 2, 2), (4, 2, 0)]
)
def test_observation_layout_matches_the_docstring_table(n_agents: int, dim: int, k: int):
    env = swarm_nav_v0.parallel_env(
        n_agents=n_agents,
        dim=dim,
        n_neighbors=k,
        obs_goal_scale=7.0,
        obs_neighbor_scale=0.5,
        obs_velocity_scale=0.3,
    )
    obs, _ = env.reset(seed=1)
    rng = np.random.default_rng(1)
    for t in range(4):
        got = np.stack([obs[a] for a in env.possible_agents])
        assert got.shape == (n_agents, 2 * dim + k * (2 * dim + 1))
        np.testing.assert_allclose(got, reference_observation(env), rtol=1e-6, atol=1e-6)
        if t < 3:
            obs = env.step(random_actions(env, rng))[0]
    assert np.array_equal(env.state(), got.reshape(-1))


def test_parallel_and_gym_envs_see_the_same_swarm():
    par = swarm_nav_v0.parallel_env()
    genv = gym.make(ENV_ID)
    pobs, _ = par.reset(seed=21)
    gobs, _ = genv.reset(seed=21)
    rng = np.random.default_rng(21)
    for _ in range(20):
        assert np.array_equal(np.concatenate([pobs[a] for a in par.possible_agents]), gobs)
        actions = random_actions(par, rng)
        pobs, prew, *_ = par.step(actions)
        gobs, grew, *_ = genv.step(np.concatenate([actions[a] for a in par.possible_agents]))
        assert prew["agent_0"] == grew


# --------------------------------------------------------------------------- seeding, pickle


def parallel_rollout(env: SwarmNavParallelEnv, seed: int, steps: int) -> list[tuple]:
    rng = np.random.default_rng(seed + 1000)
    trace: list[tuple] = [env.reset(seed=seed)]
    for _ in range(steps):
        out = env.step(random_actions(env, rng))
        trace.append(out)
        if not env.agents:
            trace.append(env.reset())
    return trace


def assert_parallel_traces_identical(a: list[tuple], b: list[tuple]) -> None:
    assert len(a) == len(b)
    for ta, tb in zip(a, b, strict=True):
        for da, db in zip(ta, tb, strict=True):
            assert list(da) == list(db)
            for key in da:
                if isinstance(da[key], np.ndarray):
                    assert da[key].dtype == db[key].dtype
                    assert np.array_equal(da[key], db[key])
                else:
                    assert da[key] == db[key]


def test_300_step_parallel_rollouts_are_bit_identical():
    a = parallel_rollout(swarm_nav_v0.parallel_env(), seed=11, steps=300)
    b = parallel_rollout(swarm_nav_v0.parallel_env(), seed=11, steps=300)
    assert_parallel_traces_identical(a, b)


def test_300_step_rollouts_through_episode_ends_are_bit_identical():
    a = parallel_rollout(swarm_nav_v0.parallel_env(max_cycles=40), seed=12, steps=300)
    b = parallel_rollout(swarm_nav_v0.parallel_env(max_cycles=40), seed=12, steps=300)
    assert len(a) > 300  # seven episode ends, each followed by an unseeded reset
    assert_parallel_traces_identical(a, b)


def test_different_seeds_give_different_starts():
    env = swarm_nav_v0.parallel_env()
    o1, _ = env.reset(seed=1)
    o2, _ = env.reset(seed=2)
    assert not np.array_equal(o1["agent_0"], o2["agent_0"])
    o1_again, _ = env.reset(seed=1)
    assert all(np.array_equal(o1[a], o1_again[a]) for a in env.agents)


def test_global_rngs_untouched():
    before = rng_states()
    env = swarm_nav_v0.parallel_env()
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(20):
        env.step(random_actions(env, rng))
    env.reset()
    aec = swarm_nav_v0.env()
    aec.reset(seed=3)
    for _agent in aec.agent_iter(30):
        aec.step(np.zeros(2, np.float32) if not any(aec.last()[2:4]) else None)
    assert_same_rng_states(before, rng_states())


@pytest.mark.parametrize("module", [pickle, cloudpickle], ids=["pickle", "cloudpickle"])
def test_pickle_round_trip_reproduces_rollout(module: Any):
    env = swarm_nav_v0.parallel_env()
    env.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(5):
        env.step(random_actions(env, rng))
    clone = module.loads(module.dumps(env))
    actions = [random_actions(env, rng) for _ in range(20)]
    a = [env.step(act) for act in actions]
    b = [clone.step(act) for act in actions]
    assert_parallel_traces_identical(a, b)


def test_aec_env_pickles():
    env = swarm_nav_v0.env(n_agents=3)
    env.reset(seed=0)
    clone = cloudpickle.loads(cloudpickle.dumps(env))
    for e in (env, clone):
        for _ in range(6):
            e.step(np.full(2, 0.5, np.float32))
    assert np.array_equal(env.observe("agent_1"), clone.observe("agent_1"))


# --------------------------------------------------------------------------- episode end


def test_success_terminates_every_agent_on_the_first_step():
    env = swarm_nav_v0.parallel_env(goal_distance_min=0.0, goal_distance_max=0.0, goal_radius=50.0)
    env.reset(seed=0)
    _, rewards, terms, truncs, infos = env.step(zeros(env))
    assert all(terms.values()) and not any(truncs.values())
    assert len(set(rewards.values())) == 1 and rewards["agent_0"] > env.cfg.reward.success - 1
    assert all(info["success"] == 1.0 for info in infos.values())
    assert env.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})


def test_step_before_reset_raises():
    env = swarm_nav_v0.parallel_env()
    with pytest.raises(RuntimeError, match="reset"):
        env.step({a: np.zeros(2, np.float32) for a in env.possible_agents})


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"n_agent": 3}, "n_agent"),
        ({"dt": -1}, "dt"),
        ({"physics": {"l_r": 0}}, "l_r"),
        ({"render_mode": "rgb"}, "render_mode"),
        ({"max_cycles": 0}, "max_steps"),
    ],
)
@pytest.mark.parametrize("factory", [swarm_nav_v0.parallel_env, swarm_nav_v0.env])
def test_bad_kwargs_raise_value_error(factory: Any, kwargs: dict[str, Any], name: str):
    with pytest.raises(ValueError, match=name):
        factory(**kwargs)


def test_config_file_loads_and_kwargs_override_it():
    env = swarm_nav_v0.parallel_env(config="configs/env/paper_navigation.yaml")
    assert env.cfg.n_agents == 31 and len(env.possible_agents) == 31
    env = swarm_nav_v0.parallel_env(config="paper_navigation", n_agents=4, max_cycles=7)
    assert env.cfg.n_agents == 4 and env.cfg.max_steps == 7 and env.cfg.physics.C_o == 0.7


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda acts: acts.pop("agent_2"), "missing"),
        (lambda acts: acts.update(agent_99=np.zeros(2, np.float32)), "unknown"),
        (lambda acts: acts.update(agent_0=np.zeros(3, np.float32)), "shape"),
        (lambda acts: acts.update(agent_0=np.zeros((2, 2), np.float32)), "shape"),
        (lambda acts: acts.update(agent_1=np.array([np.nan, 0.0])), "finite"),
        (lambda acts: acts.update(agent_1=np.array([0.0, np.inf])), "finite"),
        (lambda acts: acts.update(agent_1=None), "numeric"),
    ],
    ids=["missing", "unknown", "size", "ndim", "nan", "inf", "none"],
)
def test_bad_actions_raise_and_leave_the_env_usable(mutate: Any, match: str):
    env = swarm_nav_v0.parallel_env(n_agents=4)
    env.reset(seed=0)
    twin = swarm_nav_v0.parallel_env(n_agents=4)
    twin.reset(seed=0)
    actions = zeros(env)
    mutate(actions)
    with pytest.raises(ValueError, match=match):
        env.step(actions)
    obs = env.step(zeros(env))[0]
    twin_obs = twin.step(zeros(twin))[0]
    assert all(np.array_equal(obs[a], twin_obs[a]) for a in env.agents)
