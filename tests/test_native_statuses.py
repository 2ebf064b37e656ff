"""The C step with agent statuses (removed, frozen, passive, absent and joining agents,
``observe_status``) against the numpy reference, and the statuses' rules themselves.

Seeded rollouts through :func:`~swarm_envs.envs.backends.make_core` (the perturbations'
wrapper around each core, with the VecEnv's automatic resets): observations, rewards,
flags and every statistic agree with the numpy core in float64 to round-off, in float32
to 2e-3, also in the ``x86-64-v3`` build (no AVX-512). Then what the masks mean, checked on
both cores: agents that do not move stay put at rest, only present others are
neighbours (an agent never observes itself, an absent one observes nobody), joining
agents are placed at rest, and a kernel that does not apply statuses is refused.
"""

from __future__ import annotations

import dataclasses
import functools
import pickle

import numpy as np
import pytest
from helpers import (
    assert_same_status_rollout,
    mill_about_goal,
    status_perturbations,
    status_rollout,
)

from swarm_envs.config import SwarmConfig
from swarm_envs.envs import backends
from swarm_envs.envs.cores.native import NativeSwarmNavCore, build, contract, native_support
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task import STAT_KEYS
from swarm_envs.envs.task.agent_status import ABSENT, ACTIVE, FAILED, FROZEN
from swarm_envs.envs.task.observation import LAYOUT
from swarm_envs.perturbations import Perturbations
from swarm_envs.physics import SocialPotentialParams

SUPPORTED, WHY = native_support()
needs_native = pytest.mark.skipif(not SUPPORTED, reason=f"C step unavailable: {WHY}")

TOLERANCE = {np.float64: dict(rtol=1e-9, atol=1e-9), np.float32: dict(rtol=2e-3, atol=2e-3)}
BATCH, STEPS = 4, 16

PERTURBATIONS = status_perturbations()

#: Swarm shapes: 2-D with more slots than some agents have present others, and 3-D with
#: the goal sink in the physics and alignment (the sink energy over present agents).
SHAPES = {
    "2d": dict(n_agents=10, n_neighbors=6),
    "3d": dict(
        n_agents=7,
        dim=3,
        n_neighbors=6,
        goal_in_physics=True,
        physics=SocialPotentialParams(C_g=0.3, l_g=4.0, C_o=0.2),
    ),
}


def _config(kind: str, shape: str, observe_status: bool) -> SwarmConfig:
    p, _ = PERTURBATIONS[kind]
    return SwarmConfig(
        **SHAPES[shape],
        max_steps=6,
        collision_radius=0.6,
        perturbations=p,
        observe_status=observe_status,
    )


def _rollout(cfg: SwarmConfig, backend: str, dtype) -> tuple[list, set[int]]:
    core = backends.make_core(dataclasses.replace(cfg, backend=backend), BATCH, dtype)
    assert core.backend == backend
    return status_rollout(core, cfg.n_agents, cfg.dim, STEPS, dtype)


@functools.cache
def _reference(kind: str, shape: str, observe_status: bool) -> tuple[list, set[int]]:
    return _rollout(_config(kind, shape, observe_status), "numpy", np.float64)


def _assert_same_rollout(got: list, want: list, dtype) -> None:
    assert_same_status_rollout(got, want, TOLERANCE[dtype])


@needs_native
@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=["f64", "f32"])
@pytest.mark.parametrize("observe_status", [False, True], ids=["", "observe_status"])
@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("kind", list(PERTURBATIONS))
def test_rollouts_with_statuses_match_the_numpy_core(kind, shape, observe_status, dtype):
    got, seen = _rollout(_config(kind, shape, observe_status), "native", dtype)
    want, ref_seen = _reference(kind, shape, observe_status)
    assert seen == ref_seen
    assert PERTURBATIONS[kind][1] <= seen and ACTIVE in seen  # the statuses did occur
    _assert_same_rollout(got, want, dtype)


@needs_native
@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=["f64", "f32"])
@pytest.mark.parametrize(
    ("kind", "shape"), [("removed", "2d"), ("joining", "3d"), ("frozen", "3d")]
)
def test_the_x86_64_v3_build_matches_the_numpy_core(monkeypatch, kind, shape, dtype):
    # x86-64-v3: the kernel's branches without AVX-512 (k-NN, observations).
    monkeypatch.setenv(build.ARCH_ENV, "x86-64-v3")
    got, _ = _rollout(_config(kind, shape, True), "native", dtype)
    _assert_same_rollout(got, _reference(kind, shape, True)[0], dtype)


@needs_native
@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=["f64", "f32"])
@pytest.mark.parametrize("dim", [2, 3])
def test_the_statistics_about_the_goal_over_the_members_match_the_numpy_core(dim, dtype):
    # goal_angular_momentum, mill_speed and mill_order are sums over the members divided
    # by their count (frozen agents are none): the mill, a self-propelled swarm started
    # about its goal, agents inside and outside the arrival radius.
    cfg = mill_about_goal(10, dim)
    cfg = dataclasses.replace(cfg, perturbations=PERTURBATIONS["frozen"][0])
    got, seen = _rollout(cfg, "native", dtype)
    want, ref_seen = _rollout(cfg, "numpy", np.float64)
    assert seen == ref_seen and FROZEN in seen
    _assert_same_rollout(got, want, dtype)
    order = np.array([stats["mill_order"] for _, _, stats in want])
    assert ((order > 0) & (order < 1)).any()


# --------------------------------------------------------------------------- the rules


def _cores(cfg: SwarmConfig, batch: int = 2) -> list:
    cores = [SwarmNavCore(cfg, batch)]
    if SUPPORTED:
        cores.append(NativeSwarmNavCore(cfg, batch))
    for core in cores:
        core.reset(np.random.default_rng(3))
    return cores


def _statuses(batch: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.choice([ACTIVE, ACTIVE, FAILED, FROZEN, ABSENT], size=(batch, n)).astype(np.int8)


def test_agents_that_do_not_move_stay_put_at_rest():
    cfg = SwarmConfig(n_agents=9, perturbations=Perturbations(absent_fraction=0.3))
    status = _statuses(2, 9)
    still = status >= FROZEN
    assert still.any() and (~still).any()
    for core in _cores(cfg):
        core.set_status(status, start=True)
        x0 = core.x
        assert (core.v[still] == 0).all()
        for a in np.random.default_rng(0).uniform(-1, 1, (5, 2, 9, 2)):
            core.step(a)  # the core does not zero their actions: its masks hold them
        np.testing.assert_array_equal(core.x[still], x0[still], err_msg=core.backend)
        assert (core.v[still] == 0).all()
        assert (np.linalg.norm(core.v[~still], axis=-1) > 0).all()


@pytest.mark.parametrize("observe_status", [False, True])
def test_only_present_others_are_neighbours(observe_status):
    # Each slot that holds a neighbour (mask 1) is one of the agent's nearest present
    # others, nearest first; the rest are padding. An absent agent observes nobody, no
    # agent observes itself, and the status flag is 1 for active neighbours only.
    n, k, d = 8, 6, 2
    cfg = SwarmConfig(
        n_agents=n,
        n_neighbors=k,
        observe_status=observe_status,
        perturbations=Perturbations(absent_fraction=0.5),
    )
    status = _statuses(2, n)
    present = status <= FROZEN
    block = 2 * d + 1 + observe_status
    for core in _cores(cfg):
        core.set_status(status)
        obs, x, v = core.observe(), core.x, core.v
        for b in range(2):
            for i in range(n):
                slots = obs[b, i, 2 * d :].reshape(k, block)
                others = [j for j in np.flatnonzero(present[b]) if j != i]
                near = sorted(others, key=lambda j: (np.linalg.norm(x[b, j] - x[b, i]), j))
                near = near[:k] if present[b, i] else []
                real = slots[:, 2 * d]
                assert real.tolist() == [1.0] * len(near) + [0.0] * (k - len(near))
                assert not slots[len(near) :].any()
                for q, j in enumerate(near):
                    want = (x[b, j] - x[b, i]) / cfg.obs_neighbor_scale
                    np.testing.assert_allclose(slots[q, :d], want, rtol=1e-6, atol=1e-6)
                    want = (v[b, j] - v[b, i]) / cfg.obs_velocity_scale
                    np.testing.assert_allclose(slots[q, d : 2 * d], want, rtol=1e-6, atol=1e-6)
                    if observe_status:
                        assert slots[q, -1] == float(status[b, j] == ACTIVE)


def test_joining_agents_are_placed_at_rest_and_the_swarm_measured_again():
    cfg = SwarmConfig(n_agents=6, perturbations=Perturbations(join_fraction=0.5))
    status = np.full((2, 6), ACTIVE, np.int8)
    status[:, :3] = ABSENT
    for core in _cores(cfg):
        core.set_status(status, start=True)
        core.step(np.zeros((2, 6, 2)))
        substeps = core.stats()["substeps"]
        joined = status.copy()
        joined[0, 0] = ACTIVE
        place = joined != status
        at = np.full((2, 6, 2), 0.25)
        before = core.stats()
        core.set_status(joined, place, at)
        assert (core.x[place] == 0.25).all() and (core.v[place] == 0).all()
        stats = core.stats()
        assert stats["energy"][0] != before["energy"][0]  # swarm 0 measured again
        np.testing.assert_array_equal(stats["substeps"], substeps)  # a measure is no step
        for key in STAT_KEYS:  # the next reward compares with the new statistics
            np.testing.assert_array_equal(core.task.records.prev[key], stats[key], err_msg=key)


@needs_native
def test_a_core_with_statuses_pickles():
    cfg = SwarmConfig(n_agents=6, perturbations=Perturbations(absent_fraction=0.5))
    core = NativeSwarmNavCore(cfg, 2)
    core.reset(np.random.default_rng(0))
    core.set_status(_statuses(2, 6), start=True)
    copy = pickle.loads(pickle.dumps(core))
    a = np.random.default_rng(1).uniform(-1, 1, (2, 6, 2))
    for got, want in zip(copy.step(a), core.step(a), strict=True):
        if isinstance(got, dict):
            for key in got:
                np.testing.assert_array_equal(got[key], want[key])
        else:
            np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(copy.observe(), core.observe())


# --------------------------------------------------------------------------- contract


def test_a_kernel_without_statuses_is_refused_where_a_config_needs_them():
    info = contract.KernelInfo(
        physics=tuple(f.name for f in dataclasses.fields(SocialPotentialParams)),
        statistics=(),
        obs_layouts=(LAYOUT,),
        kmax=64,
    )
    assert contract.unsupported(SwarmConfig(), info) is None
    passive = Perturbations(failed_fraction=0.5, action_noise=0.1)  # no statuses needed
    assert contract.unsupported(SwarmConfig(perturbations=passive), info) is None
    removed = Perturbations(failed_fraction=0.5, failure_mode="removed")
    reason = contract.unsupported(SwarmConfig(perturbations=removed), info)
    assert "statuses (present, mobile, members, active)" in reason
    reason = contract.unsupported(SwarmConfig(observe_status=True), info)
    assert "observation layouts" in reason and ",status" in reason
    full = dataclasses.replace(
        info, obs_layouts=(LAYOUT, LAYOUT + ",status"), statuses=("present",)
    )
    reason = contract.unsupported(SwarmConfig(observe_status=True), full)
    assert "(mobile, members, active)" in reason


@needs_native
def test_auto_runs_configs_with_statuses_on_the_c_step():
    assert backends.STATUS_BACKENDS[0] == "native"
    for kind in PERTURBATIONS:
        cfg = _config(kind, "2d", True)
        assert backends.unsupported(cfg, "native") is None
        assert backends.select_backend(cfg, batch=64) == "native"
