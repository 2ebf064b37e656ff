"""The cut-off core's neighbour search: the k nearest others of each agent, on demand.

:class:`SparseNeighbors` is a part of
:class:`~swarm_envs.envs.sparse_core.SparseSwarmNavCore` (its state, its statuses). The
k nearest neighbours (observations, nearest-neighbour distance) come from the cell-list
structure (:func:`swarm_envs.physics.neighbors.knn`, or among the agents present,
:func:`swarm_envs.physics.present_neighbors.knn_among`), cached per state and started
from the previous state's distances. From :data:`KNN_AHEAD_MIN_AGENTS` agents the search
of a new state starts in a worker thread while the core's last pair pass runs. Swarms
that diverged (non-finite, or beyond :data:`MAX_SPAN` search radii) are searched at the
origin and given NaN distances.
"""

from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from swarm_envs.physics.neighbors import knn
from swarm_envs.physics.present_neighbors import knn_among

__all__ = ["KNN_AHEAD_MIN_AGENTS", "MAX_SPAN", "SparseNeighbors", "sound_swarms"]

#: From this many agents in a core (B·N), the k-nearest-neighbour search of a new state
#: runs in a worker thread while the pair pass runs in the caller's (numpy releases the
#: GIL in its array loops), on machines with more than one core.
KNN_AHEAD_MIN_AGENTS = 4000

_KNN_WORKERS: list[ThreadPoolExecutor] = []  # one pool, made on first use


def _knn_workers() -> ThreadPoolExecutor:
    """The process's pool for the look-ahead neighbour searches (one thread per CPU)."""
    if not _KNN_WORKERS:
        workers = max(1, os.cpu_count() or 1)
        _KNN_WORKERS.append(ThreadPoolExecutor(workers, thread_name_prefix="swarm_envs-knn"))
    return _KNN_WORKERS[0]


#: A swarm with an agent farther than half this many search radii
#: (``max(r_c, collision_radius, 1)``) from the origin along an axis has diverged: like
#: a non-finite one it is left out of the pair pass and the neighbour search (whose
#: grids it would make too coarse for the other swarms), and its energy is NaN, which
#: the step's guard catches.
MAX_SPAN = 2**24


def sound_swarms(x: np.ndarray, v: np.ndarray | None, span: float) -> np.ndarray:
    """``(b,)`` bool: the swarms whose positions ``x`` (and velocities ``v``) ``(b, N, d)``
    are finite and within ``span / 2`` of the origin along every axis (so they span at
    most ``span``)."""
    flat = np.abs(x.reshape(x.shape[0], -1)).max(axis=1) if x.size else np.zeros(x.shape[0])
    ok = flat <= 0.5 * span  # False for NaN
    if v is not None:
        ok &= np.isfinite(v).all(axis=(1, 2))
    return ok


def _neighbors(
    x: np.ndarray, k: int, present: np.ndarray | None, radius: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """The k-nearest search of the core: among every agent, or the ``present`` ones."""
    if present is None:
        return knn(x, k, radius=radius)
    return knn_among(x, k, present, radius=radius)


class SparseNeighbors:
    """The neighbour search of :class:`~swarm_envs.envs.sparse_core.SparseSwarmNavCore`
    (a base class of it; see the module docstring)."""

    cfg: Any
    x: np.ndarray
    cutoff: float
    _state: int
    _present: np.ndarray | None
    _knn_radius: float | None
    _knn_cache: tuple[int, np.ndarray, np.ndarray] | None
    _knn_pending: tuple[int, Future] | None

    @property
    def _span(self) -> float:
        """The widest sound swarm, in length units (:data:`MAX_SPAN`)."""
        return MAX_SPAN * max(self.cutoff, self.cfg.collision_radius, 1.0)

    def _searchable(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(positions, bad)``: ``x`` with the diverged swarms (``bad``: non-finite, or
        beyond :data:`MAX_SPAN`) at the origin, which the neighbour search accepts
        (their distances are replaced by NaN)."""
        bad = ~sound_swarms(x, None, self._span)
        if bad.any():
            x = x.copy()
            x[bad] = 0.0
        return x, bad

    def _start_knn(self) -> None:
        """Search the k nearest neighbours of ``self.x`` in a worker thread, meanwhile."""
        k = max(self.cfg.n_neighbors, 1)
        x, _ = self._searchable(self.x)
        future = _knn_workers().submit(_neighbors, x, k, self._present, self._knn_radius)
        self._knn_pending = (self._state, future)

    def _knn(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices and distances ``(B, N, k)`` of each agent's nearest others, nearest first.

        ``k = min(max(n_neighbors, 1), N − 1)``: the observation's neighbours and, in
        column 0, the nearest neighbour for the NND statistic. Cached per state; the
        search starts from the previous state's 90th percentile of the k-th distance.
        A diverged swarm (:meth:`_searchable`) gets NaN distances. With the statuses'
        masks, the nearest present others of each present agent
        (:func:`~swarm_envs.physics.present_neighbors.knn_among`: the slots beyond
        them, and those of an agent not present, hold the agent itself at ``inf``).
        """
        if self._knn_cache is not None and self._knn_cache[0] == self._state:
            return self._knn_cache[1], self._knn_cache[2]
        k = max(self.cfg.n_neighbors, 1)
        x, bad = self._searchable(self.x)
        pending, self._knn_pending = self._knn_pending, None
        if pending is not None and pending[0] == self._state:
            idx, dist = pending[1].result()
        else:
            idx, dist = _neighbors(x, k, self._present, self._knn_radius)
        if dist.size:
            last = dist[~bad][..., -1]
            if self._present is not None:
                last = last[np.isfinite(last)]
            hint = float(np.quantile(last, 0.9)) if last.size else 0.0
            self._knn_radius = hint if hint > 0 else None
            if bad.any():
                dist = dist.copy()
                dist[bad] = np.nan
        self._knn_cache = (self._state, idx, dist)
        return idx, dist
