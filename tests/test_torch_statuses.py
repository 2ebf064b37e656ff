"""TorchSwarmNavCore with agent statuses: removed, frozen, passive, absent and joining
agents, and ``observe_status``, against the numpy reference.

Seeded rollouts through ``make_core`` (so through the PerturbedCore that hands the
statuses over) give the numpy core's observations, rewards, flags and statistics to
round-off (float64; float32 to its tolerance), through partial resets, with substeps,
the passive goal in 3-D, fewer present agents than observed slots, and the sub-batch
measure of a few swarms (64 swarms). Direct checks: a frozen agent stays put, an absent
agent exerts no force, bad statuses are refused, and a config without statuses runs the
functions without them. One test compiles (where torch.compile runs); the CUDA test runs
where a GPU is present.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from helpers import CORE_TOL as TOL
from helpers import assert_same_rollout, rollout

from swarm_envs._runtime.torch_compile import COMPILE_ENV, compile_support
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.backends import STATUS_BACKENDS, make_core, unsupported
from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore
from swarm_envs.envs.task import STAT_KEYS
from swarm_envs.envs.task.agent_status import ABSENT, ACTIVE, FROZEN
from swarm_envs.perturbations import Perturbations

#: Perturbations that need statuses in the core (and passive failures, observed).
CASES = {
    "removed": dict(failed_fraction=0.3, failure_mode="removed", failure_time=[0, 8]),
    "frozen": dict(failed_fraction=0.3, failure_mode="frozen", failure_time=[0, 8]),
    "passive": dict(failed_fraction=0.3, failure_mode="passive", failure_time=[0, 8]),
    "absent_joining": dict(absent_fraction=[0.0, 0.2], join_fraction=0.3, join_time=[1, 8]),
}


def config(perturbations: dict, backend: str, **overrides) -> SwarmConfig:
    base = dict(n_agents=10, max_steps=15, observe_status=True)
    base.update(overrides)
    return SwarmConfig(backend=backend, perturbations=Perturbations(**perturbations), **base)


def both(perturbations: dict, batch: int, dtype=np.float64, device="cpu", **overrides) -> tuple:
    """``(torch core on device, numpy core)`` from ``make_core`` for the same config."""
    cores = []
    for backend in ("torch", "numpy"):
        cfg = config(perturbations, backend, **overrides)
        if backend == "torch":
            cfg = dataclasses.replace(cfg, device=device)
        core = make_core(cfg, batch=batch, dtype=dtype)
        assert core.backend == backend
        cores.append(core)
    return tuple(cores)


@pytest.fixture(autouse=True)
def plain_torch(monkeypatch):
    monkeypatch.setenv(COMPILE_ENV, "0")


def statuses_seen(core, seed: int, steps: int) -> set[int]:
    """The statuses the agents of a rollout's swarms take (that the case is exercised)."""
    rng = np.random.default_rng(seed)
    core.reset(rng)
    seen = set(np.unique(core.status).tolist())
    for _ in range(steps):
        core.step(np.zeros((core.batch, core.cfg.n_agents, core.cfg.dim)))
        seen |= set(np.unique(core.status).tolist())
    return seen


def test_torch_takes_statuses():
    assert "torch" in STATUS_BACKENDS
    for p in CASES.values():
        assert unsupported(config(p, "torch"), "torch") is None


@pytest.mark.parametrize("name", list(CASES))
def test_same_rollout_as_the_numpy_core(name):
    ours, ref = both(CASES[name], batch=4)
    got = rollout(ours, seed=3, steps=36, reset_every=7)
    assert_same_rollout(got, rollout(ref, seed=3, steps=36, reset_every=7), TOL[np.float64])
    assert len(statuses_seen(ours, seed=4, steps=10)) >= 2  # some agent failed or joined


#: Half the agents absent, one joining (of N).
def sparse_swarm(n: int) -> dict:
    return dict(absent_fraction=(n // 2) / n + 1e-3, join_fraction=1 / n + 1e-3, join_time=[1, 8])


@pytest.mark.parametrize(
    ("perturbations", "overrides"),
    [
        # the sink in the physics and in the energy, 3-D, a frozen agent in the sink
        (CASES["frozen"], dict(dim=3, n_agents=5, goal_in_physics=True, collision_radius=1.0)),
        # fewer present agents than slots: padding and the order of the absent ones
        (sparse_swarm(6), dict(n_agents=6, n_neighbors=6, observe_status=False)),
        # one agent present at the start: no present other (nearest distance 0)
        (sparse_swarm(3), dict(n_agents=3, n_neighbors=2)),
        # a long dt: substeps, each swarm its own count, with the masks
        (CASES["removed"], dict(dt=0.5, max_substeps=8)),
        (CASES["frozen"], dict(dt=0.5, max_substeps=8)),
    ],
    ids=["frozen_3d_goal_physics", "fewer_than_slots", "alone", "removed_dt", "frozen_dt"],
)
def test_same_rollout_in_harder_configs(perturbations, overrides):
    ours, ref = both(perturbations, batch=3, **overrides)
    got = rollout(ours, seed=8, steps=24, reset_every=9)
    assert_same_rollout(got, rollout(ref, seed=8, steps=24, reset_every=9), TOL[np.float64])
    if "dt" in overrides:
        assert max(stats["substeps"].max() for *_, stats in got) > 1


def test_status_changes_of_a_few_swarms_measure_only_those():
    # 64 swarms: failures at different steps change a few swarms at a time, measured
    # through the sub-batch function (at most 4 swarms), the others left as they are.
    p = dict(failed_fraction=0.2, failure_mode="frozen", failure_time=[1, 30])
    ours, ref = both(p, batch=64, n_agents=6, n_neighbors=3, max_steps=40)
    core = ours.inner
    assert core.reset_batch == 4
    measured: list[int] = []
    measure_rows = core._measure_rows

    def count(rows):
        measured.append(int(rows.shape[0]))
        measure_rows(rows)

    core._measure_rows = count
    got = rollout(ours, seed=5, steps=30, reset_every=10, few=True)
    assert_same_rollout(
        got, rollout(ref, seed=5, steps=30, reset_every=10, few=True), TOL[np.float64]
    )
    assert len(measured) > 10  # most status changes (3 of these are resets)


def test_truncated_swarms_keep_their_unstable_flag_through_status_changes():
    # Steps over the substep cap truncate swarms while other swarms' agents fail in the
    # same step: the torch core re-measures those and keeps the truncated ones' flag,
    # the flags of the numpy core's step before the statuses changed. Everything else
    # is the numpy core's after the change (whose re-measure of every swarm clears the
    # flags).
    p = dict(failed_fraction=0.3, failure_mode="frozen", failure_time=[0, 20])
    overrides = dict(n_agents=8, dt=0.3, max_substeps=2, on_unstable="truncate", max_steps=16)
    ours, ref = both(p, batch=64, **overrides)
    flags: list[np.ndarray] = []
    inner_step = ref.inner.step

    def step(actions):
        out = inner_step(actions)
        flags.append(out[3]["unstable"].copy())
        return out

    ref.inner.step = step
    got = rollout(ours, seed=5, steps=12, reset_every=4, few=True)
    want = rollout(ref, seed=5, steps=12, reset_every=4, few=True)
    steps = 0
    for (obs, rew, term, trunc, stats), (obs_r, rew_r, term_r, trunc_r, stats_r) in zip(
        got, want, strict=True
    ):
        np.testing.assert_allclose(obs, obs_r, **TOL[np.float64])
        for key in STAT_KEYS[:-1]:
            np.testing.assert_allclose(stats[key], stats_r[key], err_msg=key, **TOL[np.float64])
        if rew is None:
            np.testing.assert_array_equal(stats["unstable"], 0.0)  # after a reset
            continue
        np.testing.assert_allclose(rew, rew_r, **TOL[np.float64])
        np.testing.assert_array_equal(term, term_r)
        np.testing.assert_array_equal(trunc, trunc_r)
        np.testing.assert_array_equal(stats["unstable"], flags[steps])
        steps += 1
    assert STAT_KEYS[-1] == "unstable" and np.sum(flags) > 0


def test_float32_rollout_as_the_numpy_core():
    ours, ref = both(CASES["removed"], batch=4, dtype=np.float32)
    got = rollout(ours, seed=6, steps=24, reset_every=7)
    assert_same_rollout(got, rollout(ref, seed=6, steps=24, reset_every=7), TOL[np.float32])


# ---------------------------------------------------------------- direct checks


def frozen_core(**overrides) -> TorchSwarmNavCore:
    cfg = config(CASES["frozen"], "torch", n_agents=6, **overrides)
    core = TorchSwarmNavCore(cfg, batch=2, dtype=np.float64, compile=False)
    core.reset(np.random.default_rng(0))
    return core


def test_a_frozen_agent_stays_put_at_rest():
    core = frozen_core()
    status = np.zeros((2, 6), np.int8)
    status[:, 0] = FROZEN
    core.set_status(status, rows=np.ones(2, bool), start=True)
    x0 = core.x.copy()
    actions = np.random.default_rng(1)
    for _ in range(5):
        core.step(actions.uniform(-1, 1, (2, 6, 2)))
        np.testing.assert_array_equal(core.x[:, 0], x0[:, 0])
        np.testing.assert_array_equal(core.v[:, 0], 0.0)
    assert np.abs(core.x[:, 1:] - x0[:, 1:]).min() > 0  # the others move


def test_a_placed_agent_is_at_rest_where_it_was_put():
    core = frozen_core()
    for _ in range(3):
        core.step(np.full((2, 6, 2), 0.5))
    assert np.abs(core.v[:, 2]).min() > 0
    place = np.zeros((2, 6), bool)
    place[:, 2] = True
    at = np.full((2, 6, 2), 7.0)
    core.set_status(np.zeros((2, 6), np.int8), place, at)
    np.testing.assert_array_equal(core.x[:, 2], 7.0)
    np.testing.assert_array_equal(core.v[:, 2], 0.0)
    assert np.abs(core.v[:, 3]).min() > 0  # the others keep their velocities


def test_an_absent_agent_exerts_no_force():
    # Agent 0 put at two different places: absent, the others' motion is the same;
    # present (frozen), it differs. The energy and the statistics do not see it.
    def run(where: float, missing: int) -> tuple[np.ndarray, dict]:
        core = frozen_core()
        status = np.zeros((2, 6), np.int8)
        status[:, 0] = missing
        place = np.zeros((2, 6), bool)
        place[:, 0] = True
        at = core.x.copy()
        at[:, 0] = core.x[:, 1] + where
        core.set_status(status, place, at, start=True)
        for _ in range(4):
            _, _, _, stats = core.step(np.full((2, 6, 2), 0.3))
        return core.x[:, 1:], stats

    (near_x, near_stats), (far_x, far_stats) = run(0.3, ABSENT), run(3.0, ABSENT)
    np.testing.assert_array_equal(near_x, far_x)
    for key in ("energy", "nearest_neighbor_distance", "collisions", "expanse"):
        np.testing.assert_array_equal(near_stats[key], far_stats[key], err_msg=key)
    (frozen_x, _), (moved_x, _) = run(0.3, FROZEN), run(3.0, FROZEN)
    assert np.abs(frozen_x - moved_x).max() > 1e-6


def test_set_status_refuses_bad_input_and_configs_without_statuses():
    core = frozen_core()
    with pytest.raises(ValueError, match="status must be"):
        core.set_status(np.zeros((2, 5), np.int8))
    with pytest.raises(ValueError, match="status must be"):
        core.set_status(np.full((2, 6), 4, np.int8))
    with pytest.raises(ValueError, match="place must be"):
        core.set_status(np.zeros((2, 6), np.int8), np.ones((2, 6), bool), None)
    plain = TorchSwarmNavCore(SwarmConfig(n_agents=6), batch=2, compile=False)
    with pytest.raises(ValueError, match="set_status needs a config with agent statuses"):
        plain.set_status(np.zeros((2, 6), np.int8))


def test_functions_take_statuses_only_where_the_config_needs_them():
    plain = TorchSwarmNavCore(SwarmConfig(n_agents=6), batch=2, compile=False)
    passive = SwarmConfig(n_agents=6, perturbations=Perturbations(failed_fraction=0.3))
    observed = dataclasses.replace(passive, observe_status=True)
    for cfg, extra in ((plain.cfg, 0), (passive, 0), (observed, 1), (frozen_core().cfg, 1)):
        core = TorchSwarmNavCore(cfg, batch=2, compile=False)
        assert len(core._args(core._no_action, core._no_step)) == 9 + extra
        assert len(core._substep_inputs(core._no_action)) == 10 + extra


def test_statuses_survive_pickling():
    import pickle

    core = frozen_core()
    status = np.full((2, 6), ACTIVE, np.int8)
    status[0, 2] = FROZEN
    core.set_status(status, rows=np.ones(2, bool), start=True)
    copy = pickle.loads(pickle.dumps(core))
    np.testing.assert_array_equal(copy.status, status)
    a = np.random.default_rng(2).uniform(-1, 1, (2, 6, 2))
    np.testing.assert_array_equal(copy.step(a)[0], core.step(a)[0])
    np.testing.assert_array_equal(copy.observe(), core.observe())


@pytest.mark.slow  # compiling the two functions takes about a minute
@pytest.mark.skipif(compile_support("cpu") is not None, reason="torch.compile unavailable")
def test_compiled_rollout_as_the_numpy_core(monkeypatch):
    monkeypatch.setenv(COMPILE_ENV, "1")
    ours, ref = both(CASES["absent_joining"], batch=3, n_agents=6, n_neighbors=3, dt=0.4)
    assert ours.inner.compiled
    got = rollout(ours, seed=2, steps=20, reset_every=6)
    assert_same_rollout(got, rollout(ref, seed=2, steps=20, reset_every=6), TOL[np.float64])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_rollout_as_the_numpy_core(monkeypatch):
    monkeypatch.setenv(COMPILE_ENV, "auto")
    ours, ref = both(CASES["frozen"], batch=8, device="cuda", dt=0.4)
    got = rollout(ours, seed=4, steps=24, reset_every=6)
    assert_same_rollout(got, rollout(ref, seed=4, steps=24, reset_every=6), TOL[np.float64])
