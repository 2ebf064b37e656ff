"""The cell-list neighbour search equals a brute-force search (swarm_envs.physics.neighbors)."""

from __future__ import annotations

import numpy as np
import pytest

from swarm_envs.physics import neighbors
from swarm_envs.physics.neighbors import CELL_MARGIN, MAX_CELLS, CellList, knn, radius_pairs


def brute_pairs(x: np.ndarray, radius: float) -> set[tuple[int, int]]:
    """Flat ``(i, j)``, ``i < j``, with ``Σ_k (x_j − x_i)_k² ≤ radius²``, per swarm."""
    n, d = x.shape[-2:]
    x3 = x.reshape(-1, n, d)
    r2 = np.asarray(radius, dtype=x.dtype) ** 2
    out: set[tuple[int, int]] = set()
    for b in range(x3.shape[0]):
        dx = [x3[b, None, :, k] - x3[b, :, None, k] for k in range(d)]
        rho2 = dx[0] * dx[0]
        for k in range(1, d):
            rho2 += dx[k] * dx[k]
        i, j = np.nonzero(np.triu(rho2 <= r2, 1))
        out |= set(zip((i + b * n).tolist(), (j + b * n).tolist(), strict=True))
    return out


def brute_distances(x: np.ndarray) -> np.ndarray:
    """``(..., N, N)`` distances computed like the search, ``inf`` on the diagonal."""
    n, d = x.shape[-2:]
    dx = [x[..., None, :, k] - x[..., :, None, k] for k in range(d)]
    rho2 = dx[0] * dx[0]
    for k in range(1, d):
        rho2 += dx[k] * dx[k]
    rho = np.sqrt(rho2)
    idx = np.arange(n)
    rho[..., idx, idx] = np.inf
    return rho


def as_set(i: np.ndarray, j: np.ndarray) -> set[tuple[int, int]]:
    pairs = set(zip(i.tolist(), j.tolist(), strict=True))
    assert len(pairs) == i.size, "a pair is listed twice"
    return pairs


def check_knn(x: np.ndarray, k: int, **kwargs: float) -> None:
    """Indices and distances of ``knn`` against the sorted brute-force distances."""
    n = x.shape[-2]
    idx, dist = knn(x, k, **kwargs)
    kk = min(k, n - 1)
    assert idx.shape == dist.shape == (*x.shape[:-1], kk)
    rho = brute_distances(x)
    np.testing.assert_array_equal(dist, np.sort(rho, axis=-1)[..., :kk])
    np.testing.assert_array_equal(np.take_along_axis(rho, idx, axis=-1), dist)  # idx ↔ dist
    assert (idx != np.arange(n)[:, None]).all()
    if kk > 1:
        srt = np.sort(idx, axis=-1)
        assert (srt[..., 1:] != srt[..., :-1]).all(), "a neighbour is listed twice"


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("reach", [1, 2, 3])
def test_radius_pairs_equal_brute_force(d: int, reach: int) -> None:
    rng = np.random.default_rng(10 * d + reach)
    for trial in range(12):
        batch = (int(rng.integers(1, 4)),) if trial % 2 else ()
        n = int(rng.integers(1, 70))
        x = rng.normal(size=(*batch, n, d)) * rng.uniform(0.2, 6.0)
        if trial % 3 == 0:
            x = np.round(x)  # lattice points: many pairs exactly `radius` apart
        radius = float(rng.choice([0.5, 1.0, 2.0, 3.7]))
        i, j = radius_pairs(x, radius, reach=reach)
        assert (i < j).all()
        assert as_set(i, j) == brute_pairs(x, radius)


@pytest.mark.parametrize("d", [2, 3])
def test_knn_equals_brute_force(d: int) -> None:
    rng = np.random.default_rng(d)
    for trial in range(12):
        batch = (int(rng.integers(1, 4)),) if trial % 2 else ()
        n = int(rng.integers(1, 80))
        x = rng.normal(size=(*batch, n, d)) * rng.uniform(0.2, 6.0)
        k = int(rng.integers(0, 10))
        check_knn(x, k)


@pytest.mark.parametrize("radius", [1e-3, 0.3, 50.0])
def test_knn_any_first_radius_gives_the_same_answer(radius: float) -> None:
    """A tiny first radius takes many rounds, a huge one a single round."""
    x = np.random.default_rng(0).normal(size=(2, 60, 2)) * 3.0
    check_knn(x, 6, radius=radius)


@pytest.mark.parametrize("d", [2, 3])
def test_agents_on_cell_boundaries(d: int) -> None:
    """A lattice of spacing = radius puts agents on cell edges, pairs exactly radius apart."""
    radius = 0.25  # exact in binary: offsets and squared distances are exact
    axes = [np.arange(5) * radius] * d
    x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    x = x + 7.0 * radius  # the grid origin is min(x): boundaries fall on lattice points
    for reach in (1, 2, 3):
        i, j = radius_pairs(x, radius, reach=reach)
        pairs = as_set(i, j)
        assert pairs == brute_pairs(x, radius)
        assert len(pairs) == d * 4 * 5 ** (d - 1)  # the lattice's nearest-neighbour bonds
    # Cells exactly `radius (1 + CELL_MARGIN)` wide: the same on a grid of that side.
    cells = CellList.build(x, radius * (1 + CELL_MARGIN), reach=1)
    assert as_set(*cells.pairs(radius)) == brute_pairs(x, radius)
    check_knn(x, 2 * d)


def test_one_and_two_agents() -> None:
    one = np.array([[0.5, -1.0]])
    i, j = radius_pairs(one, 1.0)
    assert i.size == j.size == 0
    idx, dist = knn(one, 6)
    assert idx.shape == dist.shape == (1, 0)
    two = np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 4.0]])
    assert as_set(*radius_pairs(two, 5.0)) == {(0, 1)}
    assert radius_pairs(two, 4.999)[0].size == 0
    idx, dist = knn(two, 6)
    assert idx.tolist() == [[1], [0]]
    assert dist.tolist() == [[5.0], [5.0]]


def test_coincident_agents() -> None:
    """Agents on one point are all pairs at distance 0; no NaN anywhere."""
    x = np.zeros((2, 20, 3))
    x[1, 10:] = 1.0  # two stacks in the second swarm
    i, j = radius_pairs(x, 0.5)
    assert as_set(i, j) == brute_pairs(x, 0.5)
    assert i.size == 190 + 2 * 45
    _, dist = knn(x, 5)
    assert not np.isnan(dist).any()
    np.testing.assert_array_equal(dist, 0.0)
    check_knn(x, 5)
    mixed = np.random.default_rng(0).normal(size=(40, 2))
    mixed[20:] = mixed[:20]  # every agent has a twin
    assert as_set(*radius_pairs(mixed, 0.7)) == brute_pairs(mixed, 0.7)
    check_knn(mixed, 4)


def test_float32_equals_float32_brute_force() -> None:
    x = (np.random.default_rng(3).normal(size=(3, 50, 2)) * 4.0).astype(np.float32)
    assert as_set(*radius_pairs(x, 1.5)) == brute_pairs(x, 1.5)
    _, dist = knn(x, 6)
    assert dist.dtype == np.float32
    check_knn(x, 6)


def test_far_apart_swarms_and_agents() -> None:
    """Huge grids: the key is renumbered per axis (3-D), or binary search replaces the table."""
    rng = np.random.default_rng(4)
    x = rng.normal(size=(2, 30, 3))
    x[0, 15:] += 1e8  # 10^8 cells per axis: ~10^24 keys, beyond int64 → renumbered
    x[1, :10] -= 3e7
    assert as_set(*radius_pairs(x, 1.0)) == brute_pairs(x, 1.0)
    check_knn(x, 4)
    y = rng.normal(size=(40, 2))
    y[20:] += 1e4  # sparse 2-D grid: binary search instead of the dense table
    cells = CellList.build(y, 0.5 * (1 + CELL_MARGIN), reach=2)
    assert cells.cumulative is None
    assert as_set(*cells.pairs(1.0)) == brute_pairs(y, 1.0)
    check_knn(y, 3)


def test_dense_table_and_binary_search_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    x = np.random.default_rng(5).normal(size=(3, 60, 2)) * 2.0
    expected = brute_pairs(x, 1.2)
    assert CellList.build(x, 0.4, reach=3).cumulative is not None
    assert as_set(*radius_pairs(x, 1.2)) == expected
    monkeypatch.setattr(neighbors, "LOOKUP_FACTOR", 0)
    assert CellList.build(x, 0.4, reach=3).cumulative is None
    assert as_set(*radius_pairs(x, 1.2)) == expected
    check_knn(x, 5)


def test_chunks_do_not_change_the_answer(monkeypatch: pytest.MonkeyPatch) -> None:
    x = np.random.default_rng(6).normal(size=(200, 2)) * 3.0
    expected = brute_pairs(x, 1.0)
    monkeypatch.setattr(neighbors, "CHUNK", 37)  # many tiny chunks
    assert as_set(*radius_pairs(x, 1.0)) == expected
    check_knn(x, 6)


def test_iter_pairs_offsets_and_positions() -> None:
    x = np.random.default_rng(7).normal(size=(2, 50, 2)) * 2.0
    cells = CellList.build(x, 1.0 * (1 + CELL_MARGIN) / 3, reach=3)
    flat = x.reshape(-1, 2)
    for p, q, dx, rho2 in cells.iter_pairs(1.0):
        i, j = cells.order[p], cells.order[q]
        for k in range(2):
            np.testing.assert_array_equal(dx[k], flat[j, k] - flat[i, k])
        np.testing.assert_array_equal(rho2, dx[0] * dx[0] + dx[1] * dx[1])
    p, q = cells.pairs(1.0, positions=True)
    i, j = cells.order[p], cells.order[q]
    assert as_set(np.minimum(i, j), np.maximum(i, j)) == brute_pairs(x, 1.0)


def test_invalid_input_raises() -> None:
    x = np.zeros((5, 2))
    for bad in (0.0, -1.0, np.inf, np.nan, "1"):
        with pytest.raises(ValueError, match="radius"):
            radius_pairs(x, bad)  # type: ignore[arg-type]
    for reach in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="reach"):
            radius_pairs(x, 1.0, reach=reach)  # type: ignore[arg-type]
    for k in (-1, 1.5, True):
        with pytest.raises(ValueError, match="k must be"):
            knn(x, k)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="radius"):
        knn(x, 2, radius=0.0)
    nan = np.zeros((5, 2))
    nan[2, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        radius_pairs(nan, 1.0)
    with pytest.raises(ValueError, match="finite"):
        knn(nan, 2)
    with pytest.raises(ValueError, match="shape"):
        radius_pairs(np.zeros((5, 4)), 1.0)
    with pytest.raises(ValueError, match="at least 1"):
        knn(np.zeros((0, 2)), 1)
    wide = np.array([[0.0, 0.0], [1e3 * MAX_CELLS, 0.0]])
    with pytest.raises(ValueError, match="cells"):
        radius_pairs(wide, 1.0)
    cells = CellList.build(np.random.default_rng(0).normal(size=(9, 2)), 0.5, reach=1)
    with pytest.raises(ValueError, match="exceeds"):
        cells.pairs(0.6)
    with pytest.raises(ValueError, match="exceeds"):
        cells.knearest_round(np.arange(9), 2, 0.5, reach=2)
