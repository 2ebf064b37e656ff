"""The cut-off core with agent statuses (removed, frozen, passive, absent and joining
agents, ``observe_status``) against the numpy reference, and the statuses' rules.

Seeded rollouts through :func:`~swarm_envs.envs.backends.make_core` (the perturbations'
wrapper around each core, with the VecEnv's automatic resets), with a cut-off past
every pair as in ``tests/test_cutoff_core.py``: observations, rewards, flags and every
statistic agree with the numpy core to round-off. Swarms with more and with fewer
present agents than neighbour slots take the two paths of the neighbour search among
present agents. Then what the masks mean, checked on the cut-off core alone: agents that
do not move stay put at rest, an absent agent exerts no force (the swarm moves as if it
did not exist), a close pair of two agents at rest is no collision, and only present
others are neighbours.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from helpers import assert_same_status_rollout, status_perturbations, status_rollout

from swarm_envs.config import SwarmConfig
from swarm_envs.envs import backends
from swarm_envs.envs.cores.cutoff import core as cutoff_core
from swarm_envs.envs.cores.cutoff.core import CUTOFF_MIN_AGENTS, CutoffSwarmNavCore
from swarm_envs.envs.task import STAT_KEYS
from swarm_envs.envs.task.agent_status import ABSENT, ACTIVE, FAILED, FROZEN
from swarm_envs.perturbations import Perturbations
from swarm_envs.physics import SocialPotentialParams
from swarm_envs.physics.neighbors import CellList, knn
from swarm_envs.physics.present_neighbors import close_pairs_among, knn_among

TINY = 1e-12  # cut-off tolerance at which no pair of a small swarm is dropped
TOLERANCE = dict(rtol=1e-9, atol=1e-9)  # as tests/test_cutoff_core.py's run_both
BATCH, STEPS = 4, 16

PERTURBATIONS = status_perturbations()

#: Swarm shapes: 2-D with more present agents than neighbour slots (the cell-list
#: search), and 3-D with fewer (the search by brute force), the goal sink in the
#: physics (its energy over present agents) and alignment.
SHAPES = {
    "2d": dict(n_agents=40, n_neighbors=6, init_radius=2.5),
    "3d": dict(
        n_agents=12,
        dim=3,
        n_neighbors=8,
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


def _rollout(cfg: SwarmConfig, backend: str) -> tuple[list, set[int]]:
    core = backends.make_core(dataclasses.replace(cfg, backend=backend), BATCH)
    assert core.backend == backend
    if backend == "cutoff":
        core.inner.cutoff_tol = TINY
    return status_rollout(core, cfg.n_agents, cfg.dim, STEPS)


@functools.cache
def _reference(kind: str, shape: str, observe_status: bool) -> tuple[list, set[int]]:
    return _rollout(_config(kind, shape, observe_status), "numpy")


#: Each kind in both shapes, once with status flags in the observation and once without.
ROLLOUTS = [
    (kind, shape, (shape == "2d") == (kind in ("removed", "joining")))
    for kind in PERTURBATIONS
    for shape in SHAPES
]


def _assert_same_rollout(got: list, want: list) -> None:
    assert_same_status_rollout(got, want, TOLERANCE)


@pytest.mark.parametrize(("kind", "shape", "observe_status"), ROLLOUTS)
def test_rollouts_with_statuses_match_the_numpy_core(kind, shape, observe_status):
    got, seen = _rollout(_config(kind, shape, observe_status), "cutoff")
    want, ref_seen = _reference(kind, shape, observe_status)
    assert seen == ref_seen
    assert PERTURBATIONS[kind][1] <= seen and ACTIVE in seen  # the statuses did occur
    _assert_same_rollout(got, want)


def test_the_look_ahead_search_takes_the_statuses(monkeypatch):
    # The neighbour search that runs in a worker thread during the last pair pass
    # (from KNN_AHEAD_MIN_AGENTS agents on) searches among the present agents too.
    monkeypatch.setattr(cutoff_core, "KNN_AHEAD_MIN_AGENTS", 1)
    got, _ = _rollout(_config("joining", "2d", True), "cutoff")
    _assert_same_rollout(got, _reference("joining", "2d", True)[0])


def test_the_rollouts_see_collisions_between_agents_at_rest():
    # The frozen rollouts must hold close pairs of two frozen agents (no collision),
    # or the rule that leaves them out would go untested above.
    cfg = _config("frozen", "2d", False)
    core = backends.make_core(dataclasses.replace(cfg, backend="cutoff"), BATCH)
    core.reset(np.random.default_rng(0))
    found = False
    for a in np.random.default_rng(1).uniform(-1, 1, (STEPS, BATCH, cfg.n_agents, cfg.dim)):
        core.step(a)
        for b in range(BATCH):
            rest = core.x[b][core.status[b] == FROZEN]
            rho = np.linalg.norm(rest[:, None] - rest[None], axis=-1)
            found |= bool(np.triu(rho < cfg.collision_radius, 1).any())
    assert found


# --------------------------------------------------------------------------- the rules


def _statuses(batch: int, n: int, seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.choice([ACTIVE, ACTIVE, FAILED, FROZEN, ABSENT], size=(batch, n)).astype(np.int8)


def _core(cfg: SwarmConfig, batch: int = 2) -> CutoffSwarmNavCore:
    core = CutoffSwarmNavCore(cfg, batch, cutoff_tol=TINY)
    core.reset(np.random.default_rng(3))
    return core


def test_agents_that_do_not_move_stay_put_at_rest():
    cfg = SwarmConfig(n_agents=30, perturbations=Perturbations(absent_fraction=0.3))
    status = _statuses(2, 30)
    still = status >= FROZEN
    assert still.any() and (~still).any()
    core = _core(cfg)
    core.set_status(status, start=True)
    x0 = core.x.copy()
    assert (core.v[still] == 0).all()
    for a in np.random.default_rng(0).uniform(-1, 1, (5, 2, 30, 2)):
        core.step(a)  # the core does not zero their actions: its masks hold them
    np.testing.assert_array_equal(core.x[still], x0[still])
    assert (core.v[still] == 0).all()
    assert (np.linalg.norm(core.v[~still], axis=-1) > 0).all()


def test_an_absent_agent_exerts_no_force():
    # A swarm with an absent agent right next to another moves exactly as the swarm
    # without that agent: it is neither a source nor a receiver of a pair term.
    n = 20
    full = SwarmConfig(n_agents=n, perturbations=Perturbations(absent_fraction=0.1))
    less = dataclasses.replace(full, n_agents=n - 1)
    with_absent, without = _core(full, 1), _core(less, 1)
    x = with_absent.x.copy()
    x[0, -1] = x[0, 0] + 0.05  # the absent agent, close enough to repel hard
    v = np.random.default_rng(2).normal(size=(1, n, 2))
    status = np.full((1, n), ACTIVE, np.int8)
    status[0, -1] = ABSENT
    with_absent.x, with_absent.v = x, v
    with_absent.set_status(status, rows=np.ones(1, bool), start=True)
    without.x, without.v, without.goal = x[:, :-1].copy(), v[:, :-1].copy(), with_absent.goal
    without.set_status(status[:, :-1], rows=np.ones(1, bool), start=True)
    for a in np.random.default_rng(4).uniform(-1, 1, (6, 1, n, 2)):
        with_absent.step(a)
        without.step(a[:, :-1])
        np.testing.assert_allclose(with_absent.x[:, :-1], without.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(with_absent.v[:, :-1], without.v, rtol=0, atol=1e-12)
        for key in STAT_KEYS:
            np.testing.assert_allclose(
                with_absent.stats()[key], without.stats()[key], rtol=1e-12, atol=1e-12
            )
    np.testing.assert_array_equal(with_absent.x[0, -1], x[0, -1])  # it stayed where it was


def test_a_close_pair_of_agents_at_rest_is_no_collision():
    cfg = SwarmConfig(
        n_agents=6, collision_radius=0.5, perturbations=Perturbations(absent_fraction=0.1)
    )
    core = _core(cfg, 1)
    x = np.array([[[0.0, 0.0], [0.1, 0.0], [5.0, 0.0], [5.1, 0.0], [10.0, 0.0], [10.1, 0.0]]])
    core.x, core.v = x, np.zeros_like(x)
    cases = {  # statuses of the three close pairs → collisions
        (FROZEN, FROZEN, ACTIVE, ACTIVE, ACTIVE, ACTIVE): 2,
        (FROZEN, ACTIVE, FROZEN, FROZEN, ACTIVE, ABSENT): 1,
        (FROZEN, FROZEN, FROZEN, FROZEN, FAILED, FAILED): 1,
        (ACTIVE, ACTIVE, ACTIVE, ACTIVE, ACTIVE, ACTIVE): 3,
    }
    for status, collisions in cases.items():
        core.set_status(np.array([status], np.int8), rows=np.ones(1, bool))
        assert core.stats()["collisions"][0] == collisions, status


@pytest.mark.parametrize(("n", "k"), [(8, 6), (40, 6)], ids=["few", "many"])
@pytest.mark.parametrize("observe_status", [False, True])
def test_only_present_others_are_neighbours(n, k, observe_status):
    # Each slot that holds a neighbour (mask 1) is one of the agent's nearest present
    # others, nearest first; the rest are padding. An absent agent observes nobody, no
    # agent observes itself, and the status flag is 1 for active neighbours only.
    d = 2
    cfg = SwarmConfig(
        n_agents=n,
        n_neighbors=k,
        observe_status=observe_status,
        perturbations=Perturbations(absent_fraction=0.5),
    )
    status = _statuses(2, n)
    present = status <= FROZEN
    block = 2 * d + 1 + observe_status
    core = _core(cfg)
    core.set_status(status)
    obs, x, v = core.observe(), core.x, core.v
    nearest = core.stats()["nearest_neighbor_distance"]
    for b in range(2):
        gaps = []
        for i in range(n):
            slots = obs[b, i, 2 * d :].reshape(k, block)
            others = [j for j in np.flatnonzero(present[b]) if j != i]
            near = sorted(others, key=lambda j: (np.linalg.norm(x[b, j] - x[b, i]), j))
            if present[b, i] and status[b, i] <= FAILED:  # a member
                gaps.append(np.linalg.norm(x[b, near[0]] - x[b, i]) if near else 0.0)
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
        assert nearest[b] == pytest.approx(np.mean(gaps), rel=1e-12)


def test_an_agent_alone_in_the_physics_has_nearest_distance_zero():
    # Swarm 0: one present agent among absent ones (no present other: 0, not inf);
    # swarm 1: two present agents, their distance.
    cfg = SwarmConfig(n_agents=5, perturbations=Perturbations(absent_fraction=0.5))
    core = _core(cfg)
    status = np.full((2, 5), ABSENT, np.int8)
    status[0, 2] = ACTIVE
    status[1, :2] = ACTIVE
    core.set_status(status, start=True)
    nearest = core.stats()["nearest_neighbor_distance"]
    assert nearest[0] == 0.0
    assert nearest[1] == pytest.approx(np.linalg.norm(core.x[1, 0] - core.x[1, 1]), rel=1e-12)
    assert all(np.isfinite(value).all() for value in core.stats().values())
    core.step(np.random.default_rng(0).uniform(-1, 1, (2, 5, 2)))
    assert core.stats()["nearest_neighbor_distance"][0] == 0.0


def test_joining_agents_are_placed_at_rest_and_the_swarm_measured_again():
    cfg = SwarmConfig(n_agents=6, perturbations=Perturbations(join_fraction=0.5))
    status = np.full((2, 6), ACTIVE, np.int8)
    status[:, :3] = ABSENT
    core = _core(cfg)
    core.set_status(status, start=True)
    core.step(np.zeros((2, 6, 2)))
    substeps = core.stats()["substeps"]
    joined = status.copy()
    joined[0, 0] = ACTIVE
    place = joined != status
    at = np.full((2, 6, 2), 0.25)
    before = core.stats()
    place[1, 4] = True  # an active agent put elsewhere comes to rest too
    assert (np.linalg.norm(core.v[1, 4]) > 0).all()
    core.set_status(joined, place, at)
    assert (core.x[place] == 0.25).all() and (core.v[place] == 0).all()
    stats = core.stats()
    assert stats["energy"][0] != before["energy"][0]  # swarm 0 measured again
    np.testing.assert_array_equal(stats["substeps"], substeps)  # a measure is no step
    for key in STAT_KEYS:  # the next reward compares with the new statistics
        np.testing.assert_array_equal(core.task.records.prev[key], stats[key], err_msg=key)


def test_bad_statuses_are_refused():
    core = _core(SwarmConfig(n_agents=5, perturbations=Perturbations(absent_fraction=0.2)))
    with pytest.raises(ValueError, match="status must be"):
        core.set_status(np.zeros((2, 4), np.int8))
    with pytest.raises(ValueError, match="status must be"):
        core.set_status(np.full((2, 5), 4, np.int8))
    with pytest.raises(ValueError, match="place must be"):
        core.set_status(np.zeros((2, 5), np.int8), np.ones((2, 5), bool), None)


# --------------------------------------------------------------------------- searches


def _brute_rank(x: np.ndarray, among: np.ndarray, i: int) -> list[tuple[float, int]]:
    others = [j for j in np.flatnonzero(among) if j != i]
    return sorted((float(np.sqrt(((x[j] - x[i]) ** 2).sum())), int(j)) for j in others)


@pytest.mark.parametrize("seed", range(4))
def test_knn_among_ranks_the_nearest_marked_others(seed):
    rng = np.random.default_rng(seed)
    B, n, d, k = 5, int(rng.integers(2, 50)), int(rng.choice([2, 3])), int(rng.integers(1, 9))
    x = rng.normal(size=(B, n, d)) * 3
    among = rng.uniform(size=(B, n)) < rng.uniform(0, 1, (B, 1))  # from none to all
    idx, dist = knn_among(x, k, among)
    kk = min(k, n - 1)
    assert idx.shape == dist.shape == (B, n, kk)
    for b in range(B):
        for i in range(n):
            ranked = _brute_rank(x[b], among[b], i)[:kk] if among[b, i] else []
            m = len(ranked)
            assert idx[b, i, :m].tolist() == [j for _, j in ranked]
            np.testing.assert_allclose(dist[b, i, :m], [r for r, _ in ranked], rtol=1e-12)
            assert (idx[b, i, m:] == i).all() and np.isinf(dist[b, i, m:]).all()
    every = np.ones((B, n), bool)
    for got, want in zip(knn_among(x, k, every), knn(x, k), strict=True):
        np.testing.assert_array_equal(got, want)


def test_close_pairs_among_and_grouped_cell_lists_match_brute_force():
    rng = np.random.default_rng(5)
    x = rng.normal(size=(4, 60, 2)) * 2
    among = rng.uniform(size=(4, 60)) < 0.5
    got = close_pairs_among(x, among, 0.8, 2.0)
    for b in range(4):
        p = x[b][among[b]]
        rho = np.linalg.norm(p[:, None] - p[None], axis=-1)
        assert got[b] == np.triu(rho < 0.8, 1).sum()
    pts, groups = x.reshape(-1, 2), rng.integers(0, 3, 240)  # swarms in no order
    i, j = CellList.build(pts, 0.5, 2, groups=groups).pairs(0.9)
    rho = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    want = np.triu((rho <= 0.9) & (groups[:, None] == groups[None]), 1)
    assert want.any()
    pairs = np.stack([i, j], axis=-1).tolist()
    assert sorted(pairs) == np.argwhere(want).tolist()


# --------------------------------------------------------------------------- backends


def test_auto_runs_large_swarms_with_statuses_on_the_cutoff_core():
    assert "cutoff" in backends.STATUS_BACKENDS
    for kind in PERTURBATIONS:
        for observe_status in (False, True):
            small = _config(kind, "2d", observe_status)
            assert backends.unsupported(small, "cutoff") is None
            assert backends.select_backend(small, batch=4) != "cutoff"
            large = dataclasses.replace(small, n_agents=CUTOFF_MIN_AGENTS)
            assert backends.select_backend(large, batch=4) == "cutoff"
