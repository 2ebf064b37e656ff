"""Neighbour searches among a subset of each swarm's agents (those present in the
physics), for large swarms.

The cell-list searches of :mod:`swarm_envs.physics.neighbors` on only the agents that
``among`` ``(B, N)`` marks: the others are left out of the grid altogether, so they are
nobody's neighbour and have none.

:func:`knn_among`
    each marked agent's ``k`` nearest marked others, nearest first, with distances
    (``knn`` on the subset; a swarm with at most ``k`` marked agents is ranked by brute
    force, by distance then index).
:func:`close_pairs_among`
    per swarm, the pairs of marked agents closer than a radius.

>>> x = np.array([[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [0.5, 0.0]]])
>>> among = np.array([[True, True, True, False]])
>>> idx, dist = knn_among(x, 1, among)
>>> idx[0, :, 0].tolist(), dist[0, :, 0].tolist()
([1, 0, 1, 3], [1.0, 1.0, 2.0, inf])
>>> close_pairs_among(x, among, 1.5, 1.5).tolist()
[1]
"""

from __future__ import annotations

import numpy as np

from swarm_envs.physics._validation import as_state, check_real
from swarm_envs.physics.neighbors import (
    CELL_MARGIN,
    KNN_REACH,
    MAX_CELLS,
    REACH,
    CellList,
    density_radius,
    knn_rounds,
)

__all__ = ["close_pairs_among", "knn_among"]


def _subset(x: np.ndarray, among: np.ndarray, owner: str) -> tuple[np.ndarray, np.ndarray]:
    """``x`` as ``(B, N, d)`` and ``among`` as ``(B, N)`` bool, checked."""
    x = as_state(x, "positions", min_agents=1)
    among = np.asarray(among)
    if among.dtype != bool or among.shape != x.shape[:-1]:
        raise ValueError(
            f"{owner}: among must be a bool array of shape {x.shape[:-1]}, got "
            f"{among.dtype} {among.shape}"
        )
    n, d = x.shape[-2:]
    return x.reshape(-1, n, d), among.reshape(-1, n)


def knn_among(
    x: np.ndarray, k: int, among: np.ndarray, *, radius: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest marked others of every marked agent, nearest first.

    Args:
        x: positions ``(..., N, d)``; each batch entry is a separate swarm. The marked
            agents' positions must be finite.
        k: neighbours per agent, ``≥ 0``; ``min(k, N − 1)`` slots are returned.
        among: ``(..., N)`` bool, the agents searched (queries and candidates).
        radius: first search radius (a guess, as for
            :func:`~swarm_envs.physics.neighbors.knn`).

    Returns:
        ``(idx, dist)``, each ``(..., N, min(k, N − 1))``: for a marked agent, its marked
        others in ``[0, N)``, nearest first, with their distances ``√Σ_k (x_j − x_i)_k²``;
        the slots beyond its number of marked others, and every slot of an unmarked
        agent, hold the agent's own index at distance ``inf``.
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise ValueError(f"knn_among: k must be an integer >= 0, got {k!r}")
    x3, mask = _subset(x, among, "knn_among")
    B, n, d = x3.shape
    kk = min(int(k), n - 1)
    idx = np.broadcast_to(np.arange(n)[:, None], (B, n, kk)).copy()
    dist = np.full((B, n, kk), np.inf, dtype=x3.dtype)
    sub = np.flatnonzero(mask.ravel())  # flat indices of the marked agents, by swarm
    if kk > 0 and sub.size:
        pts = x3.reshape(-1, d)[sub]
        if not np.isfinite(pts).all():
            raise ValueError("positions must be finite for the neighbour search (got NaN or inf)")
        swarm = sub // n
        count = np.bincount(swarm, minlength=B)
        rich = np.flatnonzero(count[swarm] > kk)  # subset rows with k marked others
        if rich.size:
            r = density_radius(x3, kk) if radius is None else radius
            r = check_real("knn_among", "radius", r, low=0.0, low_inclusive=False)
            span = float((pts.max(axis=0) - pts.min(axis=0)).max())
            r = max(r, 4.0 * KNN_REACH * span / MAX_CELLS)  # the grid within MAX_CELLS
            nb = np.zeros((sub.size, kk), dtype=np.intp)
            nd2 = np.zeros((sub.size, kk), dtype=x3.dtype)
            grid = 2 * KNN_REACH
            knn_rounds(lambda h: CellList.build(pts, h, grid, groups=swarm), rich, kk, r, nb, nd2)
            idx.reshape(-1, kk)[sub[rich]] = sub[nb[rich]] % n
            dist.reshape(-1, kk)[sub[rich]] = np.sqrt(nd2[rich])
        _rank_few(x3, sub, count, kk, idx, dist)
    return idx.reshape(*x.shape[:-1], kk), dist.reshape(*x.shape[:-1], kk)


def _rank_few(
    x3: np.ndarray,
    sub: np.ndarray,
    count: np.ndarray,
    kk: int,
    idx: np.ndarray,
    dist: np.ndarray,
) -> None:
    """Rank the marked agents of the swarms with 2 to ``kk`` of them by brute force (by
    distance, then index), into ``idx, dist`` ``(B, N, kk)``."""
    few = np.flatnonzero((count >= 2) & (count <= kk))
    if few.size == 0:
        return
    B, n, d = x3.shape
    swarm = sub // n
    first = np.searchsorted(swarm, np.arange(B))
    rank = np.arange(sub.size) - first[swarm]  # place among its swarm's marked agents
    chosen = np.isin(swarm, few)
    width = int(count[few].max())
    member = np.full((few.size, width), -1, dtype=np.int64)  # flat index, by index
    member[np.searchsorted(few, swarm[chosen]), rank[chosen]] = sub[chosen]
    valid = member >= 0
    pos = x3.reshape(-1, d)[np.where(valid, member, 0)]  # (f, width, d)
    dx = pos[:, None, :, 0] - pos[:, :, None, 0]
    rho2 = dx * dx
    for c in range(1, d):
        dx = pos[:, None, :, c] - pos[:, :, None, c]
        rho2 += dx * dx
    eye = np.eye(width, dtype=bool)
    rho2[~(valid[:, :, None] & valid[:, None, :]) | eye] = np.inf
    cols = min(kk, width - 1)
    order = np.argsort(rho2, axis=-1, kind="stable")[..., :cols]  # ties by index
    near = np.take_along_axis(rho2, order, axis=-1)
    found = np.isfinite(near)
    own = np.broadcast_to(member[:, :, None] % n, order.shape)
    slots = np.where(found, np.take_along_axis(member[:, None, :], order, axis=-1) % n, own)
    rows = member[valid]
    idx.reshape(-1, kk)[rows, :cols] = slots[valid]
    dist.reshape(-1, kk)[rows, :cols] = np.sqrt(near[valid])


def close_pairs_among(
    x: np.ndarray, among: np.ndarray, close_radius: float, search_radius: float
) -> np.ndarray:
    """Per swarm ``(B,)`` of ``x`` ``(B, N, d)``, the pairs of agents marked in ``among``
    ``(B, N)`` closer than ``close_radius`` (``ρ² < close_radius²``, as the pair passes
    count collisions), from a cell list of radius ``search_radius ≥ close_radius``.
    The marked agents' positions must be finite."""
    x3, mask = _subset(x, among, "close_pairs_among")
    B, n, d = x3.shape
    out = np.zeros(B, dtype=np.int64)
    close = check_real("close_pairs_among", "close_radius", close_radius, low=0.0)
    search = check_real("close_pairs_among", "search_radius", search_radius, low=close)
    sub = np.flatnonzero(mask.ravel())
    if close == 0 or search == 0 or sub.size < 2:
        return out
    swarm = sub // n
    cells = CellList.build(
        x3.reshape(-1, d)[sub], search * (1.0 + CELL_MARGIN) / REACH, REACH, groups=swarm
    )
    close2 = close * close
    for p, _, _, rho2 in cells.iter_pairs(search):
        hit = p[rho2 < close2]
        out += np.bincount(swarm[cells.order[hit]], minlength=B)
    return out
