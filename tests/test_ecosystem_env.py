"""What RL libraries need from the envs (docs/ecosystem.md), each point checked.

Unknown keyword arguments are ``TypeError`` (and ``ValueError``); the PettingZoo env's
global state has a ``state_space``; positions, velocities and the goal are public, and
optionally in each agent's info; ``reset(options=...)``'s rule; TorchRL's ``GymEnv`` and
``PettingZooWrapper`` pass ``check_env_specs``; the docs page's example runs.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from helpers import strict_warnings
from pettingzoo.test import api_test, parallel_api_test
from pettingzoo.test.state_test import state_test

from swarm_envs import ENV_ID, swarm_nav_v0
from swarm_envs.config import UnknownKeyError
from swarm_envs.envs import OBS_BOUND, SwarmNavEnv, SwarmNavParallelEnv

DOC = Path(__file__).resolve().parents[1] / "docs" / "ecosystem.md"

FACTORIES = {
    "gym_make": lambda **kw: gym.make(ENV_ID, **kw),
    "gym_class": SwarmNavEnv,
    "parallel": swarm_nav_v0.parallel_env,
    "aec": swarm_nav_v0.env,
}


# --------------------------------------------------------------------------- keywords


@pytest.mark.parametrize("factory", FACTORIES.values(), ids=FACTORIES.keys())
def test_unknown_keyword_is_a_type_error_naming_it_and_the_allowed_keys(factory: Any):
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'frameskip'") as info:
        factory(n_agents=3, frameskip=1)
    err = info.value
    assert isinstance(err, UnknownKeyError) and isinstance(err, ValueError)
    message = str(err)
    for allowed in ("allowed keys", "config", "render_mode", "info_kinematics", "n_agents"):
        assert allowed in message


def test_unknown_keyword_of_the_vec_env_is_a_type_error():
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'frameskip'"):
        swarm_nav_v0.vec_env(1, n_agents=2, frameskip=1)


def test_parallel_env_names_its_own_keywords():
    with pytest.raises(TypeError, match=r"SwarmNavParallelEnv\(\).*max_cycles"):
        swarm_nav_v0.parallel_env(max_cycle=3)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"dt": -1}, "dt"),
        ({"physics": {"C_x": 1.0}}, r"unknown config key 'physics\.C_x'"),
        ({"n_agents": 0}, "n_agents"),
        ({"info_kinematics": "yes"}, "info_kinematics must be True or False"),
        ({"info_kinematics": 1}, "info_kinematics"),
    ],
)
@pytest.mark.parametrize("factory", [SwarmNavEnv, swarm_nav_v0.parallel_env])
def test_bad_values_stay_value_errors(factory: Any, kwargs: dict[str, Any], name: str):
    with pytest.raises(ValueError, match=name) as info:
        factory(**kwargs)
    assert not isinstance(info.value, TypeError)


# --------------------------------------------------------------------------- global state


@pytest.mark.parametrize("backend", ["numpy", "auto"])
def test_state_lies_in_state_space(backend: str):
    # A small goal scale pushes the goal offsets to the clip bound of the observations.
    env = swarm_nav_v0.parallel_env(n_agents=4, backend=backend, obs_goal_scale=0.5)
    space = env.state_space
    assert isinstance(space, gym.spaces.Box) and space.dtype == np.float32
    assert space.shape == (4 * env.observation_space("agent_0").shape[0],)
    assert np.all(space.low == -OBS_BOUND) and np.all(space.high == OBS_BOUND)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    hit_bound = False
    for _ in range(30):
        state = env.state()
        assert state.dtype == np.float32 and space.contains(state)
        hit_bound |= bool(np.any(np.abs(state) == OBS_BOUND))
        env.step({a: rng.uniform(-1, 1, 2) for a in env.agents})
    assert hit_bound  # the bounds were exercised, not only the interior


def test_pettingzoo_state_test_passes():
    with strict_warnings():
        state_test(
            swarm_nav_v0.env(n_agents=3, max_cycles=40),
            swarm_nav_v0.parallel_env(n_agents=3, max_cycles=40),
            num_cycles=100,
        )


# --------------------------------------------------------------------------- accessors


def _envs(**kwargs: Any) -> dict[str, Any]:
    return {
        "parallel": swarm_nav_v0.parallel_env(**kwargs),
        "gym": gym.make(ENV_ID, **kwargs),
        "aec": swarm_nav_v0.env(**kwargs),
    }


@pytest.mark.parametrize("kind", ["parallel", "gym", "aec"])
def test_accessors_need_a_reset(kind: str):
    env = _envs(n_agents=3)[kind]
    for name in ("positions", "velocities", "goal", "active"):
        with pytest.raises(RuntimeError, match=f"{name} is defined after reset"):
            getattr(env.unwrapped, name)


@pytest.mark.parametrize("kind", ["parallel", "gym", "aec"])
def test_accessors_give_the_state_without_the_batch_dimension(kind: str):
    env = _envs(n_agents=5, dim=3, backend="numpy")[kind]
    env.reset(seed=1)
    raw = env.unwrapped
    assert isinstance(raw, (SwarmNavParallelEnv, SwarmNavEnv))
    x, v, g, active = raw.positions, raw.velocities, raw.goal, raw.active
    assert x.shape == (5, 3) and v.shape == (5, 3) and g.shape == (3,)
    assert x.dtype == v.dtype == g.dtype == np.float64
    assert active.dtype == bool and active.shape == (5,) and active.all()
    np.testing.assert_array_equal(x, raw.core.x[0])
    np.testing.assert_array_equal(v, raw.core.v[0])
    np.testing.assert_array_equal(g, raw.core.goal[0])
    # the start of the docs: agents in the init disc, goal at its drawn distance
    cfg = raw.cfg
    assert np.all(np.linalg.norm(x, axis=1) <= cfg.init_radius + 1e-12)
    assert cfg.goal_distance_min - 1e-9 <= np.linalg.norm(g) <= cfg.goal_distance_max + 1e-9
    # copies: changing them changes nothing
    x[:] = 99.0
    g[:] = 99.0
    assert not np.any(raw.positions == 99.0) and not np.any(raw.goal == 99.0)


def test_accessors_agree_with_the_observations_and_the_integrator():
    env = swarm_nav_v0.parallel_env(n_agents=4, backend="numpy", obs_goal_scale=100.0)
    obs, _ = env.reset(seed=3)
    scale = env.cfg.obs_goal_scale
    for i, agent in enumerate(env.possible_agents):
        np.testing.assert_allclose(
            obs[agent][:2], (env.goal - env.positions[i]) / scale, rtol=1e-6, atol=1e-7
        )
        np.testing.assert_allclose(
            obs[agent][2:4], env.velocities[i] / env.cfg.obs_velocity_scale, rtol=1e-6
        )
    before = env.positions
    env.step({a: np.full(2, 0.5) for a in env.agents})
    # semi-implicit Euler: x' = x + dt v'
    np.testing.assert_allclose(env.positions, before + env.cfg.dt * env.velocities, atol=1e-12)
    assert not np.allclose(env.positions, before)


# --------------------------------------------------------------------------- info kinematics


def test_parallel_info_kinematics_per_agent():
    env = swarm_nav_v0.parallel_env(n_agents=4, backend="numpy", info_kinematics=True)
    _, infos = env.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(3):
        for i, agent in enumerate(env.possible_agents):
            info = infos[agent]
            for key in ("pos", "vel", "goal_offset"):
                assert info[key].shape == (2,) and info[key].dtype == np.float32
            np.testing.assert_allclose(info["pos"], env.positions[i], rtol=1e-6)
            np.testing.assert_allclose(info["vel"], env.velocities[i], rtol=1e-6)
            np.testing.assert_allclose(
                info["goal_offset"], env.goal - env.positions[i], rtol=1e-5, atol=1e-6
            )
            assert isinstance(info["polarization"], float)  # the statistics stay
        _, _, _, _, infos = env.step({a: rng.uniform(-1, 1, 2) for a in env.agents})


def test_gym_info_kinematics_whole_swarm():
    env = gym.make(ENV_ID, n_agents=3, backend="numpy", info_kinematics=True)
    _, info = env.reset(seed=0)
    _, _, _, _, info = env.step(env.action_space.sample())
    raw = env.unwrapped
    assert info["pos"].shape == info["vel"].shape == info["goal_offset"].shape == (3, 2)
    np.testing.assert_allclose(info["pos"], raw.positions, rtol=1e-6)
    np.testing.assert_allclose(info["vel"], raw.velocities, rtol=1e-6)
    np.testing.assert_allclose(info["goal_offset"], raw.goal - raw.positions, rtol=1e-5)


def test_info_kinematics_off_by_default():
    _, infos = swarm_nav_v0.parallel_env(n_agents=2).reset(seed=0)
    _, info = gym.make(ENV_ID, n_agents=2).reset(seed=0)
    for d in (infos["agent_0"], info):
        assert not {"pos", "vel", "goal_offset"} & set(d)


def test_official_checkers_pass_with_info_kinematics():
    with strict_warnings():
        parallel_api_test(
            swarm_nav_v0.parallel_env(n_agents=3, info_kinematics=True), num_cycles=50
        )
        api_test(swarm_nav_v0.env(n_agents=3, info_kinematics=True), num_cycles=20)
        gym_check_env(gym.make(ENV_ID, n_agents=3, info_kinematics=True).unwrapped)


# --------------------------------------------------------------------------- reset options


@pytest.mark.parametrize("kind", ["parallel", "gym"])
def test_reset_options_dict_is_accepted_and_not_read(kind: str):
    env = _envs(n_agents=3, backend="numpy")[kind]
    obs_a, _ = env.reset(seed=4)
    obs_b, _ = env.reset(seed=4, options={"options": 1, "goal": [0.0, 0.0]})
    if kind == "parallel":
        obs_a, obs_b = np.stack(list(obs_a.values())), np.stack(list(obs_b.values()))
    np.testing.assert_array_equal(obs_a, obs_b)


@pytest.mark.parametrize("kind", ["parallel", "gym"])
@pytest.mark.parametrize("options", [1, "goal", [("goal", 1)]])
def test_reset_options_of_another_type_raise(kind: str, options: Any):
    env = _envs(n_agents=3)[kind]
    with pytest.raises(ValueError, match=r"options must be None or a dict"):
        env.reset(seed=0, options=options)


# --------------------------------------------------------------------------- TorchRL


def test_torchrl_gym_env_passes_check_env_specs():
    pytest.importorskip("torchrl")
    from torchrl.envs import GymEnv
    from torchrl.envs.utils import check_env_specs

    env = GymEnv(ENV_ID, n_agents=3, dt=0.05)
    assert env._env.unwrapped.cfg.n_agents == 3 and env._env.unwrapped.cfg.dt == 0.05
    check_env_specs(env, seed=0)
    td = env.rollout(5)
    assert td["next", "observation"].shape == (5, 3 * env._env.unwrapped.core.obs_dim)


def test_torchrl_pettingzoo_wrapper_with_state_and_kinematics():
    pytest.importorskip("torchrl")
    import torch
    from torchrl.envs import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    par = swarm_nav_v0.parallel_env(n_agents=3, max_cycles=30, info_kinematics=True)
    env = PettingZooWrapper(par, return_state=True)
    check_env_specs(env, seed=0)
    assert env.observation_spec["state"].shape == par.state_space.shape
    td = env.rollout(4)
    assert td["next", "state"].shape == (4, *par.state_space.shape)
    # the last step's state and kinematics are the env's own
    torch.testing.assert_close(td["next", "state"][-1], torch.as_tensor(par.state()))
    pos = td["next", "agent", "info", "pos"]
    assert pos.shape == (4, 3, 2)
    torch.testing.assert_close(pos[-1], torch.as_tensor(par.positions, dtype=torch.float32))


def test_docs_example_runs():
    pytest.importorskip("torchrl")
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.DOTALL)
    assert blocks, f"no python example in {DOC}"
    # The BenchMARL recipe trains and writes its run: tests/test_benchmarl.py runs it.
    blocks = [b for b in blocks if "benchmarl" not in b]
    assert blocks, f"no TorchRL example in {DOC}"
    namespace: dict[str, Any] = {}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), namespace)


# --------------------------------------------------------------------------- SuperSuit


def test_supersuit_vector_env_steps_and_truncates():
    ss = pytest.importorskip("supersuit")
    par = swarm_nav_v0.parallel_env(n_agents=3, max_cycles=5, info_kinematics=True)
    venv = ss.pettingzoo_env_to_vec_env_v1(par)
    obs, infos = venv.reset(seed=0)
    assert obs.shape == (3, par.observation_space("agent_0").shape[0])
    np.testing.assert_allclose(np.stack([i["pos"] for i in infos]), par.positions, rtol=1e-6)
    for step in range(1, 6):
        obs, rewards, terminated, truncated, infos = venv.step(np.zeros((3, 2), np.float32))
        assert rewards.shape == (3,) and not terminated.any()
        assert truncated.all() == (step == 5)
