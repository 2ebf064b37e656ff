"""The compiled (numba) cut-off pair pass equals the numpy PairAccumulator it replaces."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from test_cutoff import direct_pair_sums

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.cores.cutoff.core import CutoffSwarmNavCore
from swarm_envs.physics import SocialPotentialParams, compiled_pairs
from swarm_envs.physics.cutoff import PairAccumulator, PairSums
from swarm_envs.physics.neighbors import CELL_MARGIN, REACH, CellList, knn

numba = pytest.importorskip("numba")

NAV = SocialPotentialParams(C_a=1.0, C_r=1.0, l_a=1.0, l_r=0.2, C_o=0.7, l_o=1.5, beta=1.0)


def swarms(B: int, N: int, d: int, seed: int, spread: float = 4.0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    x = rng.normal(scale=spread, size=(B, N, d))
    v = rng.normal(size=(B, N, d))
    return x, v


def both(
    x: np.ndarray,
    v: np.ndarray | None,
    radius: float,
    params: SocialPotentialParams = NAV,
    close_radius: float = 0.3,
) -> tuple[PairSums, PairSums]:
    """(numpy accumulator, compiled pass) over the same cell list, in sorted order."""
    B, N, d = x.shape
    cells = CellList.build(x, radius * (1.0 + CELL_MARGIN) / REACH, REACH)
    vel = None if v is None else v.reshape(B * N, d)[cells.order]
    groups = cells.order // N
    acc = PairAccumulator(
        params, B * N, vel, groups=groups, n_groups=B, potential=True, close_radius=close_radius
    )
    for chunk in cells.iter_pairs(radius):
        acc.add(*chunk)
    fast = compiled_pairs.cell_pair_sums(
        cells, radius, params, vel, groups=groups, n_groups=B, close_radius=close_radius
    )
    return acc.result(d), fast


def assert_same(ref: PairSums, fast: PairSums) -> None:
    assert fast.force.shape == ref.force.shape and fast.force.dtype == np.float64
    scale = max(1.0, float(np.abs(ref.force).max()))
    np.testing.assert_allclose(fast.force, ref.force, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(fast.potential, ref.potential, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(fast.close, ref.close)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("B", [1, 3])
def test_equals_the_numpy_accumulator(d: int, B: int) -> None:
    x, v = swarms(B, 400, d, seed=d * 10 + B)
    ref, fast = both(x, v, radius=5.0)
    assert ref.close.sum() > 0 and np.abs(ref.force).max() > 0  # pairs were found
    assert_same(ref, fast)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("with_v", [True, False])
def test_applies_pair_law(d: int, with_v: bool) -> None:
    """The kernel sums exactly what pair_law gives per pair (so a change of the law
    reaches it): forces, potential and close pairs, coincident agents included."""
    rng = np.random.default_rng(10 + d)
    x = rng.uniform(-2.0, 2.0, (2, 25, d))  # every pair of a swarm within the radius
    x[0, 2] = x[0, 9]  # a coincident pair: no force, U(0)
    v = rng.normal(size=x.shape) if with_v else None
    ref = direct_pair_sums(x, v, NAV, close_radius=0.5)
    cells = CellList.build(x, 8.0 * (1.0 + CELL_MARGIN) / REACH, REACH)
    order = cells.order
    fast = compiled_pairs.cell_pair_sums(
        cells,
        8.0,
        NAV,
        None if v is None else v.reshape(-1, d)[order],
        groups=order // 25,
        n_groups=2,
        close_radius=0.5,
    )
    assert ref.close.sum() > 0
    force = np.empty_like(fast.force)
    force[order] = fast.force
    scale = max(1.0, float(np.abs(ref.force).max()))
    np.testing.assert_allclose(force, ref.force, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(fast.potential, ref.potential, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(fast.close, ref.close)


def test_without_alignment_and_velocities() -> None:
    x, v = swarms(2, 300, 2, seed=1)
    assert_same(*both(x, None, radius=4.0))
    no_align = SocialPotentialParams(C_a=1.0, C_r=2.0, l_a=1.0, l_r=0.5, C_o=0.0, l_o=1.0)
    assert_same(*both(x, v, radius=4.0, params=no_align))


def test_coincident_agents_give_no_nan() -> None:
    x = np.zeros((1, 20, 3))
    x[0, 10:] = 1.0
    v = np.random.default_rng(0).normal(size=(1, 20, 3))
    ref, fast = both(x, v, radius=3.0)
    assert np.isfinite(fast.force).all() and np.isfinite(fast.potential).all()
    assert_same(ref, fast)
    assert fast.close[0] == 2 * (10 * 9 // 2)  # the coincident pairs of both clusters


def test_result_does_not_depend_on_the_thread_count() -> None:
    x, v = swarms(1, 3000, 3, seed=5, spread=6.0)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = both(x, v, radius=5.0)[1]
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = both(x, v, radius=5.0)[1]
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(one.force, many.force)
    np.testing.assert_array_equal(one.potential, many.potential)


def test_switch(monkeypatch) -> None:
    monkeypatch.setenv("SWARM_ENVS_NUMBA", "0")
    assert compiled_pairs.numba_enabled() is False
    monkeypatch.setenv("SWARM_ENVS_NUMBA", "1")
    assert compiled_pairs.numba_enabled() is True
    monkeypatch.setenv("SWARM_ENVS_NUMBA", "fast")
    with pytest.raises(ValueError, match="SWARM_ENVS_NUMBA must be 0, 1 or auto"):
        compiled_pairs.numba_enabled()
    monkeypatch.setattr(compiled_pairs, "AVAILABLE", False)
    monkeypatch.setenv("SWARM_ENVS_NUMBA", "auto")
    assert compiled_pairs.numba_enabled() is False
    monkeypatch.setenv("SWARM_ENVS_NUMBA", "1")
    with pytest.raises(ValueError, match="numba does not import"):
        compiled_pairs.numba_enabled()


def test_an_installed_numba_that_fails_to_import_falls_back_with_a_warning(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "numba", None)  # `import numba` now raises ImportError
    monkeypatch.setattr(compiled_pairs, "_import_tried", False)
    monkeypatch.setattr(compiled_pairs, "_import_error", None)
    monkeypatch.setattr(compiled_pairs, "AVAILABLE", True)
    monkeypatch.setenv("SWARM_ENVS_NUMBA", "auto")
    with pytest.warns(RuntimeWarning, match="numba is installed but does not import"):
        assert compiled_pairs.numba_enabled() is False
    assert compiled_pairs.numba_enabled() is False  # tried once, warned once
    monkeypatch.setenv("SWARM_ENVS_NUMBA", "1")
    with pytest.raises(ValueError, match="does not import: ModuleNotFoundError"):
        compiled_pairs.numba_enabled()


@pytest.mark.parametrize("d", [2, 3])
def test_cutoff_core_steps_alike_with_and_without_numba(monkeypatch, d: int) -> None:
    cfg = SwarmConfig(n_agents=600, dim=d, init_radius=6.0, n_neighbors=4)
    rng = np.random.default_rng(3)
    actions = rng.uniform(-1, 1, (8, 2, 600, d))
    runs = []
    for flag in ("1", "0"):
        monkeypatch.setenv("SWARM_ENVS_NUMBA", flag)
        core = CutoffSwarmNavCore(cfg, batch=2)
        core.reset(np.random.default_rng(0))
        out = []
        for a in actions:
            reward, *_ = core.step(a)
            out.append((core.x.copy(), core.observe().copy(), reward, core.stats()["energy"]))
        runs.append(out)
    for (x1, o1, r1, e1), (x2, o2, r2, e2) in zip(*runs, strict=True):
        np.testing.assert_allclose(x1, x2, rtol=0, atol=1e-10)
        np.testing.assert_allclose(o1, o2, rtol=0, atol=1e-5)
        np.testing.assert_allclose(r1, r2, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(e1, e2, rtol=1e-9)


def test_first_call_time_is_recorded() -> None:
    x, v = swarms(1, 50, 2, seed=9)
    both(x, v, radius=3.0)
    assert compiled_pairs.compile_seconds is not None and compiled_pairs.compile_seconds > 0


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("radius", [None, 0.05])  # 0.05: most queries need more rounds
def test_knn_rounds_equal_the_numpy_rounds(monkeypatch, d: int, dtype: type, radius) -> None:
    rng = np.random.default_rng(d)
    x = rng.uniform(-8.0, 8.0, (3, 700, d)).astype(dtype)
    x[1, :5] = x[1, 5]  # coincident agents
    out = {}
    for flag in ("0", "1"):
        monkeypatch.setenv("SWARM_ENVS_NUMBA", flag)
        out[flag] = knn(x, 6, radius=radius)
    (idx0, dist0), (idx1, dist1) = out["0"], out["1"]
    np.testing.assert_array_equal(dist1, dist0)
    assert dist1.dtype == dtype and np.isfinite(dist1).all()
    # Swarms 0 and 2 have no equal distances: the same neighbours in the same order.
    np.testing.assert_array_equal(idx1[[0, 2]], idx0[[0, 2]])
    # Swarm 1's coincident agents tie: either order is right. Every index is another
    # agent at the distance given, each listed once.
    rows = np.arange(700)[:, None]
    assert not (idx1[1] == rows).any()
    assert all(len(set(r)) == 6 for r in idx1[1].tolist())
    gap = x[1][idx1[1]].astype(np.float64) - x[1][:, None, :].astype(np.float64)
    np.testing.assert_allclose(np.sqrt((gap**2).sum(-1)), dist1[1], rtol=1e-5, atol=1e-6)


def test_knearest_round_needs_k_of_at_least_one() -> None:
    coords = np.zeros((2, 3))
    runs = np.zeros((1, 1), np.int64)
    with pytest.raises(ValueError, match="k must be >= 1"):
        compiled_pairs.knearest_round(coords, np.zeros(1, np.int64), runs, runs, 0, 1.0)
