"""Backend selection and the envs on each backend: the same API, the same results."""

from __future__ import annotations

import dataclasses
import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env as gym_check_env
from helpers import strict_warnings
from pettingzoo.test import parallel_api_test

from swarm_envs import ENV_ID, swarm_nav_v0
from swarm_envs.config import SwarmConfig, load_swarm_config
from swarm_envs.envs.backends import (
    CUTOFF_MIN_AGENTS,
    TORCH_MIN_SLOTS,
    make_core,
    select_backend,
    unsupported,
)
from swarm_envs.envs.cores.cutoff.core import CutoffSwarmNavCore
from swarm_envs.envs.cores.numpy import SwarmNavCore


def test_auto_picks_by_model_size_and_batch(monkeypatch):
    from swarm_envs.envs import backends

    native = backends.unsupported(SwarmConfig(), "native") is None
    small = "native" if native else "numpy"
    assert select_backend(SwarmConfig()) == small
    assert select_backend(SwarmConfig(n_agents=CUTOFF_MIN_AGENTS)) == "cutoff"
    assert select_backend(SwarmConfig(n_agents=CUTOFF_MIN_AGENTS - 1)) == small
    assert select_backend(SwarmConfig(n_agents=32), batch=TORCH_MIN_SLOTS // 32) == (
        "native" if native else "torch"
    )
    for dynamics in ("zone", "piecewise", "lagrangian"):
        cfg = SwarmConfig(dynamics=dynamics, n_agents=CUTOFF_MIN_AGENTS)
        assert select_backend(cfg, batch=1000) == "numpy"
    verlet = SwarmConfig(integrator="velocity_verlet", n_agents=32)
    assert select_backend(verlet, batch=10_000) == "numpy"
    assert select_backend(SwarmConfig(device="cuda")) == "torch"
    assert select_backend(SwarmConfig(backend="cutoff")) == "cutoff"
    # Without the C step: numpy for few slots, torch from TORCH_MIN_SLOTS.
    monkeypatch.setattr(
        backends, "unsupported", lambda cfg, b: "not available" if b == "native" else None
    )
    assert select_backend(SwarmConfig(n_agents=32), batch=TORCH_MIN_SLOTS // 32) == "torch"
    assert select_backend(SwarmConfig(n_agents=32), batch=TORCH_MIN_SLOTS // 32 - 1) == "numpy"


@pytest.mark.parametrize(
    ("kwargs", "reason", "fallback"),
    [
        ({"backend": "cutoff", "dynamics": "zone"}, "social_potential", "numpy"),
        ({"backend": "torch", "integrator": "velocity_verlet"}, "semi_implicit_euler", "numpy"),
        ({"backend": "native", "dynamics": "lagrangian"}, "social_potential", "numpy"),
    ],
)
def test_a_backend_that_cannot_run_a_config_falls_back_with_one_warning(
    monkeypatch, kwargs, reason, fallback
):
    from swarm_envs.envs import backends

    monkeypatch.setattr(backends, "_WARNED", set())
    name = kwargs["backend"]
    with pytest.warns(UserWarning, match=f"backend '{name}' cannot run this config.*{reason}"):
        core = make_core(SwarmConfig(**kwargs))
    assert core.backend == fallback
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once: the second core is quiet
        assert make_core(SwarmConfig(**kwargs)).backend == fallback


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"backend": "gpu"}, "backend must be one of"),
        ({"backend": "numpy", "device": "cuda"}, "needs backend 'torch'"),
        ({"device": ""}, "device must be"),
    ],
)
def test_impossible_backend_choices_are_value_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_core(SwarmConfig(**kwargs))


def test_the_deprecated_name_sparse_is_the_cutoff_backend():
    """``backend="sparse"`` (a deprecated name of the cut-off backend) is accepted, with a
    DeprecationWarning, and the config holds ``"cutoff"``."""
    with pytest.warns(DeprecationWarning, match="'sparse' is deprecated"):
        cfg = SwarmConfig(n_agents=CUTOFF_MIN_AGENTS, backend="sparse")
    assert cfg.backend == "cutoff" and select_backend(cfg) == "cutoff"
    assert dataclasses.replace(cfg, n_agents=8).backend == "cutoff"  # no second warning
    with pytest.warns(DeprecationWarning):
        loaded = load_swarm_config(None, {"backend": "sparse"})
    assert loaded == SwarmConfig(backend="cutoff")


def test_every_core_implements_the_protocol():
    from swarm_envs.envs.protocol import Core

    for backend in ("numpy", "cutoff", "native", "torch"):
        cfg = SwarmConfig(n_agents=4, backend=backend)
        if unsupported(cfg, backend) is not None:
            continue
        core = make_core(cfg, batch=2)
        assert isinstance(core, Core) and core.backend == backend


def test_large_swarms_run_on_the_cutoff_core_through_every_api():
    n = CUTOFF_MIN_AGENTS
    env = gym.make(ENV_ID, n_agents=n, init_radius=15.0)
    assert isinstance(env.unwrapped.core, CutoffSwarmNavCore)
    obs, _ = env.reset(seed=0)
    obs, reward, *_ = env.step(np.zeros(env.action_space.shape, np.float32))
    assert np.isfinite(obs).all() and np.isfinite(reward)
    penv = swarm_nav_v0.parallel_env(n_agents=n, init_radius=15.0)
    assert isinstance(penv.core, CutoffSwarmNavCore)
    venv = swarm_nav_v0.vec_env(2, n_agents=n, init_radius=15.0)
    assert venv.backend == "cutoff" and all(isinstance(c, CutoffSwarmNavCore) for c in venv.cores)
    venv.reset()
    assert np.isfinite(venv.step(np.zeros((2 * n, 2), np.float32))[0]).all()


def test_checkers_pass_on_the_cutoff_backend():
    with strict_warnings():
        gym_check_env(gym.make(ENV_ID, backend="cutoff", n_agents=12).unwrapped)
        parallel_api_test(swarm_nav_v0.parallel_env(backend="cutoff", n_agents=6), num_cycles=100)


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "velocity_verlet"])
def test_cutoff_and_numpy_vec_envs_agree_with_a_long_cutoff(integrator: str):
    def rollout(backend: str) -> np.ndarray:
        venv = swarm_nav_v0.vec_env(
            3, n_agents=12, backend=backend, integrator=integrator, dtype=np.float64
        )
        if backend == "cutoff":  # a cut-off past every pair: exact up to round-off
            for core in venv.cores:
                core.cutoff_tol = 1e-300
        venv.seed(3)
        out = [venv.reset()]
        rng = np.random.default_rng(0)
        for _ in range(40):
            out.append(venv.step(rng.uniform(-1, 1, (36, 2)))[0])
        return np.stack(out)

    np.testing.assert_allclose(rollout("cutoff"), rollout("numpy"), rtol=0, atol=1e-5)


def test_dense_core_is_the_numpy_backend():
    assert type(make_core(SwarmConfig(backend="numpy"), batch=2)) is SwarmNavCore


@pytest.mark.parametrize(
    ("dtype", "n_swarms"), [(np.float64, 4), (np.float32, 4), (np.float32, 64)]
)
def test_torch_and_numpy_vec_envs_agree_through_auto_resets(monkeypatch, dtype, n_swarms):
    # 64 swarms with near goals: episodes end at different steps, and the torch core
    # measures the few reset swarms only (TorchSwarmNavCore.reset_batch = 4).
    monkeypatch.setenv("SWARM_ENVS_TORCH_COMPILE", "0")  # plain torch: no compile time here
    tol = 1e-9 if dtype == np.float64 else 2e-3
    goals = (
        {} if n_swarms == 4 else dict(goal_distance_min=2.0, goal_distance_max=9.0, goal_radius=3.0)
    )

    def rollout(backend: str) -> tuple[np.ndarray, ...]:
        venv = swarm_nav_v0.vec_env(
            n_swarms, n_agents=6, backend=backend, max_steps=25, dtype=dtype, **goals
        )
        assert venv.backend == backend
        venv.seed(11)
        obs, rewards, ends, terminal = [venv.reset()], [], [], []
        rng = np.random.default_rng(2)
        for _ in range(60):  # two or more auto-resets of every swarm
            o, r, done, infos = venv.step(rng.uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32))
            obs.append(o)
            rewards.append(r)
            ends.append(done[:: venv.n_agents].sum())
            terminal += [
                info["terminal_observation"] for info in infos if "terminal_observation" in info
            ]
        return np.stack(obs), np.stack(rewards), np.array(ends), np.stack(terminal)

    (obs_t, rew_t, ends_t, term_t) = rollout("torch")
    (obs_n, rew_n, ends_n, term_n) = rollout("numpy")
    np.testing.assert_array_equal(ends_t, ends_n)
    np.testing.assert_allclose(obs_t, obs_n, rtol=0, atol=tol)
    np.testing.assert_allclose(rew_t, rew_n, rtol=0, atol=tol)
    np.testing.assert_allclose(term_t, term_n, rtol=0, atol=tol)
    if n_swarms == 64:
        assert ((ends_t >= 1) & (ends_t <= 4)).any()  # the sub-batch reset ran


def test_checkers_pass_on_the_torch_backend(monkeypatch):
    monkeypatch.setenv("SWARM_ENVS_TORCH_COMPILE", "0")
    with strict_warnings():
        gym_check_env(gym.make(ENV_ID, backend="torch", n_agents=5).unwrapped)
        parallel_api_test(swarm_nav_v0.parallel_env(backend="torch", n_agents=4), num_cycles=50)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_vec_env_agrees_with_the_cpu_through_auto_resets(monkeypatch):
    # 64 swarms: the sub-batch resets run on the GPU too. Compiled on the GPU (Triton),
    # plain torch on the CPU; float32 both.
    goals = dict(goal_distance_min=2.0, goal_distance_max=9.0, goal_radius=3.0)

    def rollout(device: str) -> tuple[np.ndarray, ...]:
        if device == "cpu":
            monkeypatch.setenv("SWARM_ENVS_TORCH_COMPILE", "0")
        venv = swarm_nav_v0.vec_env(
            64, n_agents=6, max_steps=25, backend="torch", device=device, **goals
        )
        assert venv.backend == "torch" and venv.core.device.type == device
        venv.seed(3)
        obs, rewards, ends = [venv.reset()], [], []
        rng = np.random.default_rng(4)
        for _ in range(60):
            o, r, done, _ = venv.step(rng.uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32))
            obs.append(o)
            rewards.append(r)
            ends.append(done[:: venv.n_agents].sum())
        return np.stack(obs), np.stack(rewards), np.array(ends)

    obs_g, rew_g, ends_g = rollout("cuda")
    obs_c, rew_c, ends_c = rollout("cpu")
    np.testing.assert_array_equal(ends_g, ends_c)
    np.testing.assert_allclose(obs_g, obs_c, rtol=0, atol=2e-3)
    np.testing.assert_allclose(rew_g, rew_c, rtol=0, atol=2e-3)
    assert ((ends_g >= 1) & (ends_g <= 4)).any()  # the sub-batch reset ran
