"""The cut-off core's neighbour search: the k nearest others of each agent, on demand.

:class:`NeighborSearch` is held by
:class:`~swarm_envs.envs.cores.cutoff.core.CutoffSwarmNavCore`. The
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

__all__ = ["KNN_AHEAD_MIN_AGENTS", "MAX_SPAN", "NeighborSearch", "sound_swarms"]

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


class NeighborSearch:
    """The k nearest others of each agent of a cut-off core's state, on demand (module
    docstring). A state is named by a key the core bumps whenever ``x`` changes; the
    result of a key is cached, and a search may start ahead in a worker thread."""

    def __init__(self) -> None:
        self._cache: tuple[int, np.ndarray, np.ndarray] | None = None
        self._radius: float | None = None  # where the next search starts
        self._pending: tuple[int, Future] | None = None

    def clear(self) -> None:
        """Forget the cached result (the next :meth:`search` searches)."""
        self._cache = None

    def start(
        self, x: np.ndarray, key: int, k: int, present: np.ndarray | None, span: float
    ) -> None:
        """Search the ``k`` nearest neighbours of ``x`` (state ``key``) in a worker
        thread, meanwhile (``present``: among those agents only; ``span``:
        :func:`sound_swarms`)."""
        x, _ = _searchable(x, span)
        future = _knn_workers().submit(_neighbors, x, k, present, self._radius)
        self._pending = (key, future)

    def search(
        self, x: np.ndarray, key: int, k: int, present: np.ndarray | None, span: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Indices and distances ``(B, N, k)`` of each agent's nearest others in ``x``
        (state ``key``), nearest first.

        ``k = min(max(n_neighbors, 1), N − 1)``: the observation's neighbours and, in
        column 0, the nearest neighbour for the NND statistic. Cached per state; the
        search starts from the previous state's 90th percentile of the k-th distance.
        A diverged swarm (beyond ``span`` or not finite) gets NaN distances. With the
        statuses' masks (``present``), the nearest present others of each present agent
        (:func:`~swarm_envs.physics.present_neighbors.knn_among`: the slots beyond
        them, and those of an agent not present, hold the agent itself at ``inf``).
        """
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1], self._cache[2]
        x, bad = _searchable(x, span)
        pending, self._pending = self._pending, None
        if pending is not None and pending[0] == key:
            idx, dist = pending[1].result()
        else:
            idx, dist = _neighbors(x, k, present, self._radius)
        if dist.size:
            last = dist[~bad][..., -1]
            if present is not None:
                last = last[np.isfinite(last)]
            hint = float(np.quantile(last, 0.9)) if last.size else 0.0
            self._radius = hint if hint > 0 else None
            if bad.any():
                dist = dist.copy()
                dist[bad] = np.nan
        self._cache = (key, idx, dist)
        return idx, dist

    def __getstate__(self) -> dict[str, Any]:
        """The search without its look-ahead in flight (a thread's future)."""
        state = self.__dict__.copy()
        state["_pending"] = None  # searched again on demand
        return state


def _searchable(x: np.ndarray, span: float) -> tuple[np.ndarray, np.ndarray]:
    """``(positions, bad)``: ``x`` with the diverged swarms (``bad``: non-finite, or
    beyond ``span``) at the origin, which the neighbour search accepts (their distances
    are replaced by NaN)."""
    bad = ~sound_swarms(x, None, span)
    if bad.any():
        x = x.copy()
        x[bad] = 0.0
    return x, bad
