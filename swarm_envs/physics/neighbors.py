"""O(N) neighbour search for large swarms: a vectorised numpy cell list.

The dense physics builds ``(..., N, N)`` pairwise arrays, which cannot work at
``N = 100,000``. Here the agents are binned into a grid of cubic cells of side ``h``
and sorted by cell key (one ``argsort``; keys run row-major, so the cells of one grid
row are consecutive in the sorted order). A search with ``reach`` ``m`` compares each
agent with the agents of the ``(2m + 1)^d`` cells around its own, which hold every
agent within ``m h``; each row of ``2m + 1`` of those cells is one contiguous run of
the sorted agents, so an agent has only ``(2m + 1)^{d − 1}`` candidate runs. Two
queries share the structure (:class:`CellList`):

:func:`radius_pairs`
    every unordered pair ``{i, j}`` with ``Σ_k (x_j − x_i)_k² ≤ radius²``, each once.
    ``h = radius (1 + CELL_MARGIN) / reach``; by Newton's third law only half of the
    block is searched (the rest of the agent's own row, then the lexicographically
    positive rows). In 2-D the candidates are ``(2m + 1)² / (π m²)`` times the true
    pairs: ``2.9`` for ``m = 1``, ``2.0`` for ``m = 2`` (the default), ``1.7`` for 3.
:func:`knn`
    the ``k`` nearest other agents of every agent, nearest first, with distances.
    Round ``t`` searches the radius ``R_t`` (a grid of side ``R_t / KNN_REACH`` serves
    two rounds, with reach :data:`KNN_REACH` and twice that): an agent with at least
    ``k`` others within ``R_t`` has its exact ``k`` nearest among its candidates; the
    others go to the next round with ``R_{t+1} = 2 R_t``. ``R_0``
    comes from the caller (e.g. the previous step's distances) or from the density
    (:func:`density_radius`); the rounds end at the latest once ``R_t`` exceeds every
    swarm's diameter.

Cost: at bounded density (a bounded number of agents per cell) both queries take
``O(N)`` time and memory, plus one ``O(N log N)`` sort per grid (a few percent of the
time at ``N ≤ 10^6``). Clusters make the cell occupancy, and the cost, grow (all
``N`` agents within ``radius`` of each other is ``O(N²)``, as is then the output of
:func:`radius_pairs`). Python loops run over the rows of a block and over chunks of
about :data:`CHUNK` candidates (bounded temporaries that stay in the cache), never
over agents.

Batches: positions ``(..., N, d)`` with leading batch dimensions are searched as
independent swarms (the swarm is the most significant part of the cell key, and each
swarm's grid is padded by ``reach`` cells, so no pair or neighbour crosses swarms).
Pair indices are *flat* indices into ``x.reshape(-1, d)``; neighbour indices are per
swarm, in ``[0, N)``.

Exactness: pairs and neighbours equal a brute-force search on the same array (the
squared distances are computed the same way, ``Σ_k (x_j[k] − x_i[k])²`` in ``x``'s
dtype, left to right). Cell coordinates are computed in float64, and cells are larger
than ``radius / reach`` by the relative :data:`CELL_MARGIN`, which covers their
rounding error, so agents exactly on cell boundaries or exactly ``radius`` apart are
never missed. Coincident agents are at distance 0 (a pair within every radius; each
other's nearest neighbours). Ties in :func:`knn` are broken deterministically (same
input, same order), not by index. Non-finite positions raise :class:`ValueError`.

>>> x = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
>>> i, j = radius_pairs(x, 2.0)
>>> sorted(zip(i.tolist(), j.tolist()))
[(0, 1), (1, 2)]
>>> idx, dist = knn(x, 1)
>>> idx[:, 0].tolist(), dist[:, 0].tolist()
([1, 0, 1], [1.0, 1.0, 2.0])
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cache
from typing import NamedTuple

import numpy as np

from swarm_envs.physics._validation import as_state, check_real

#: Cells are larger than ``radius / reach`` by this relative margin: it exceeds the
#: rounding error of the float64 cell coordinates (``≤ 4 ε · MAX_CELLS``), so no pair
#: within ``radius`` is ever more than ``reach`` cells apart along any axis.
CELL_MARGIN = 1e-6

#: Largest grid extent, in cells per dimension, that the margin above covers.
MAX_CELLS = 2**30

#: Candidates processed per chunk: bounds the temporaries (about a MiB each), which
#: then stay in the cache.
CHUNK = 1 << 16

#: A dense table of cumulative counts per key replaces binary search when the key
#: range is at most this many times the number of points (at most 256 bytes per point).
#: Fine grids need it: the 3-D k-nearest search of 100,000 agents spans about 23 keys per
#: point, where binary search over the occupied keys would be a large part of the search.
LOOKUP_FACTOR = 32

#: Default ``reach`` of :func:`radius_pairs` (cells per search radius).
REACH = 3

#: ``reach`` of the grids of :func:`knn` (cells per round radius).
KNN_REACH = 2

_KEY_LIMIT = 2**62

_BALL_VOLUME = {2: math.pi, 3: 4.0 * math.pi / 3.0}


def _flat_state(x: np.ndarray) -> tuple[np.ndarray, tuple[int, ...], int, int]:
    """``x`` as ``(B, N, d)`` with its batch shape, ``N`` and ``d``; finite or ValueError."""
    x = as_state(x, "positions", min_agents=1)
    if not np.isfinite(x).all():
        raise ValueError("positions must be finite for the neighbour search (got NaN or inf)")
    n, d = x.shape[-2:]
    return x.reshape(-1, n, d), x.shape[:-2], n, d


def _grouped_state(x: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(M, d)`` (finite, ``M ≥ 1``) and their swarms ``(M,)`` int64 ``≥ 0``."""
    flat = as_state(x, "positions", min_agents=1)
    swarm = np.asarray(groups)
    integer = np.issubdtype(swarm.dtype, np.integer)
    if flat.ndim != 2 or swarm.shape != flat.shape[:1] or not integer:
        raise ValueError(
            f"groups must be integers (M,) for points (M, d), got {swarm.shape} for {flat.shape}"
        )
    if swarm.min() < 0:
        raise ValueError("groups must be >= 0")
    if not np.isfinite(flat).all():
        raise ValueError("positions must be finite for the neighbour search (got NaN or inf)")
    return flat, swarm.astype(np.int64, copy=False)


def _check_reach(owner: str, reach: object) -> int:
    if isinstance(reach, bool) or not isinstance(reach, (int, np.integer)) or reach < 1:
        raise ValueError(f"{owner}: reach must be an integer >= 1, got {reach!r}")
    return int(reach)


@cache
def _rows(d: int, reach: int, half: bool) -> tuple[tuple[int, ...], ...]:
    """Leading offsets ``(o_0, …, o_{d−2}) ∈ [−reach, reach]^{d−1}`` of a block's rows.

    A row is the ``2 reach + 1`` cells ``(c_0 + o_0, …, c_{d−1} − reach … c_{d−1} +
    reach)``. Rows at least ``h √(Σ_k max(|o_k| − 1, 0)²) > reach · h`` away cannot hold
    a pair within ``reach · h`` and are left out. With ``half``: only the
    lexicographically positive rows (the caller handles the own row, offset 0).
    """
    out = []
    for o in itertools.product(range(-reach, reach + 1), repeat=d - 1):
        if sum(max(abs(c) - 1, 0) ** 2 for c in o) > reach * reach:
            continue
        nz = [c for c in o if c != 0]
        if half and (not nz or nz[0] < 0):
            continue
        out.append(o)
    return tuple(out)


class HalfStencil(NamedTuple):
    """What :meth:`CellList.half_stencil` returns (tables per occupied cell)."""

    radius: float
    """The search radius, checked."""
    cell: np.ndarray
    """``(M,)`` occupied-cell index of the point at each sorted position."""
    own_end: np.ndarray
    """``(U,)`` end (exclusive) of each cell's own-row run."""
    lo: np.ndarray
    """``(R, U)`` start of each positive row's run, per cell."""
    hi: np.ndarray
    """``(R, U)`` end (exclusive) of each positive row's run, per cell."""


@dataclass(frozen=True)
class CellList:
    """Points of ``B`` swarms sorted by grid cell: the structure both queries share.

    Built by :meth:`build`. "Position" means the index of a point in the sorted order;
    "flat index" its index in ``x.reshape(-1, d)`` (``order[position]``).
    """

    coords: tuple[np.ndarray, ...]
    """Coordinates in sorted order, one contiguous ``(M,)`` array per dimension."""
    n_agents: int
    """Agents per swarm, ``N`` (0 for swarms of different sizes, ``groups``)."""
    cell_size: float
    """Side ``h`` of the cubic cells."""
    reach: int
    """Cells each way that :meth:`iter_pairs` searches (padding of the grid)."""
    order: np.ndarray
    """``(M,)`` flat index of the point at each position."""
    point_key: np.ndarray
    """``(M,)`` cell key of the point at each position (non-decreasing)."""
    strides: tuple[int, ...]
    """Key difference of a one-cell step along each dimension."""
    keys: np.ndarray
    """``(U,)`` keys of the occupied cells, increasing."""
    start: np.ndarray
    """``(U + 1,)`` position of each occupied cell's first point, then ``M``."""
    cumulative: np.ndarray | None
    """``cumulative[key]``: number of points in cells with a smaller key, for every key
    of the padded grid (``None`` when the grid has more than :data:`LOOKUP_FACTOR`
    keys per point; :attr:`keys` are then searched)."""

    @classmethod
    def build(
        cls, x: np.ndarray, cell_size: float, reach: int = 1, *, groups: np.ndarray | None = None
    ) -> CellList:
        """Bin positions ``x`` ``(..., N, d)`` into cells of side ``cell_size``.

        Cell coordinates are ``⌊(x − min_swarm x) / h⌋`` per swarm, in float64. The key
        is ``((b S_0 + c_0) S_1 + c_1) …``, every ``c_k`` padded by ``reach`` cells on
        both sides so that an offset of at most ``reach`` never wraps into another row
        or swarm; if that key would overflow int64, each dimension's occupied
        coordinates (and their neighbours within ``reach``) are first renumbered
        consecutively, which keeps neighbours neighbours. Raises :class:`ValueError`
        for a non-positive or non-finite ``cell_size``, a non-finite position or a grid
        wider than :data:`MAX_CELLS`.

        ``groups``: swarms of different sizes (the agents of each swarm that are
        present, say). ``x`` is then ``(M, d)``, at least one point, and ``groups``
        ``(M,)`` the swarm ``b ≥ 0`` of each point; flat indices are rows of ``x``
        and :attr:`n_agents` is 0.
        """
        h = check_real("CellList", "cell_size", cell_size, low=0.0, low_inclusive=False)
        m = _check_reach("CellList", reach)
        if groups is None:
            x3, _, n, d = _flat_state(x)
            B = x3.shape[0]
            lo = x3.min(axis=1, keepdims=True).astype(np.float64)
            t = (x3.astype(np.float64) - lo) / h
            flat = x3.reshape(B * n, d)
            swarm = np.repeat(np.arange(B, dtype=np.int64), n) if B > 1 else None
        else:
            flat, swarm = _grouped_state(x, groups)
            n, d = 0, flat.shape[1]
            B = int(swarm.max()) + 1
            lo = np.full((B, d), np.inf)
            first = np.flatnonzero(np.diff(swarm, prepend=-1))  # each run of one swarm
            if (swarm[first[1:]] > swarm[first[:-1]]).all():  # by swarm: one pass
                lo[swarm[first]] = np.minimum.reduceat(flat, first, axis=0)
            else:
                np.minimum.at(lo, swarm, flat)
            t = (flat.astype(np.float64) - lo[swarm]) / h
        top = float(t.max())
        if top >= MAX_CELLS:
            raise ValueError(
                f"positions span {top:.3g} cells of side {h:g} per dimension; the neighbour "
                f"search supports at most {MAX_CELLS} (is the swarm diverging?)"
            )
        c = np.floor(t).astype(np.int64).reshape(flat.shape[0], d)
        c += m
        size = [int(c[:, k].max()) + m + 1 for k in range(d)]
        if B * math.prod(size) > _KEY_LIMIT:
            c, size = _compress(c, m)
            if B * math.prod(size) > _KEY_LIMIT:
                raise ValueError(
                    "the occupied cells do not fit a 64-bit key; the swarm is too spread out "
                    "for the cell list at this cell size"
                )
        strides = [1] * d
        for k in range(d - 2, -1, -1):
            strides[k] = strides[k + 1] * size[k + 1]
        span = strides[0] * size[0]  # keys per swarm
        key = c @ np.array(strides, dtype=np.int64)
        if swarm is not None:
            key += swarm * span
        order = np.argsort(key, kind="stable")
        point_key = key[order]
        new = np.empty(point_key.size, dtype=bool)
        new[:1] = True
        np.not_equal(point_key[1:], point_key[:-1], out=new[1:])
        start = np.append(np.flatnonzero(new), point_key.size)
        keys = point_key[start[:-1]]
        cumulative = None
        if B * span <= LOOKUP_FACTOR * max(flat.shape[0], 1024):
            cumulative = np.zeros(B * span + 1, dtype=np.int64)
            cumulative[keys + 1] = np.diff(start)
            np.cumsum(cumulative, out=cumulative)
        coords = tuple(np.ascontiguousarray(flat[order, k]) for k in range(d))
        return cls(coords, n, h, m, order, point_key, tuple(strides), keys, start, cumulative)

    @property
    def dim(self) -> int:
        """Spatial dimension ``d``."""
        return len(self.coords)

    def first_position(self, key: np.ndarray) -> np.ndarray:
        """Number of points in cells with a key smaller than ``key`` (elementwise).

        ``key`` must lie within the padded grid (an occupied key plus an offset of at
        most ``reach`` cells per axis, or one past a row's last cell).
        """
        if self.cumulative is not None:
            return self.cumulative[key]
        return self.start[np.searchsorted(self.keys, key)]

    def row_runs(
        self, key: np.ndarray, rows: tuple[tuple[int, ...], ...], reach: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Position runs ``[lo, hi)`` ``(len(rows), len(key))`` of each row around ``key``.

        Row ``o`` around cell ``c`` is the cells ``(c_0 + o_0, …, c_{d−1} − reach …
        c_{d−1} + reach)``: one contiguous run of the sorted points.
        """
        lead = self.strides[:-1]
        lo = np.empty((len(rows), key.size), dtype=np.int64)
        hi = np.empty_like(lo)
        for r, o in enumerate(rows):
            centre = key + sum(a * s for a, s in zip(o, lead, strict=True))
            lo[r] = self.first_position(centre - reach)
            hi[r] = self.first_position(centre + (reach + 1))
        return lo, hi

    def _check_radius(self, owner: str, radius: float, reach: int) -> float:
        r = check_real(owner, "radius", radius, low=0.0, low_inclusive=False)
        if reach > self.reach:
            raise ValueError(f"{owner}: reach {reach} exceeds the grid's padding {self.reach}")
        if r > reach * self.cell_size / (1.0 + CELL_MARGIN) * (1.0 + 1e-12):
            raise ValueError(
                f"{owner}: radius {r:g} exceeds reach × cell_size / (1 + CELL_MARGIN) = "
                f"{reach * self.cell_size / (1.0 + CELL_MARGIN):g} (build larger cells)"
            )
        return r

    def half_stencil(self, radius: float, owner: str = "CellList.half_stencil") -> HalfStencil:
        """The position runs that hold every unordered pair within ``radius`` once.

        Point ``p`` (a sorted position) pairs with the rest of its own row, positions
        ``p + 1 … own_end[cell[p]] − 1`` (its own cell after itself, then the next
        ``reach`` cells), and with each lexicographically positive row ``r``, positions
        ``lo[r, cell[p]] … hi[r, cell[p]] − 1``: the candidates, a superset of the pairs
        within ``radius``. ``radius`` must not exceed ``reach · cell_size / (1 +
        CELL_MARGIN)``; ``owner`` names the caller in that error.
        """
        m = self.reach
        r = self._check_radius(owner, radius, m)
        rows = _rows(self.dim, m, half=True)
        lo, hi = self.row_runs(self.keys, rows, m)
        own_end = self.first_position(self.keys + (m + 1))
        cell = np.repeat(np.arange(self.keys.size), np.diff(self.start))
        return HalfStencil(r, cell, own_end, lo, hi)

    def iter_pairs(
        self, radius: float
    ) -> Iterator[tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]]:
        """Every unordered pair within ``radius``, in chunks of sorted positions.

        Yields ``(p, q, dx, rho2)`` per chunk of about :data:`CHUNK` candidates:
        positions ``p, q`` (flat indices ``order[p]``, either orientation; ``p`` runs
        through the points in order, so a chunk touches a narrow range of positions),
        the offsets ``dx[k] = x_q[k] − x_p[k]`` and ``rho2 = Σ_k dx[k]²`` (``≤
        radius²``). ``radius`` must not exceed ``reach · cell_size / (1 + CELL_MARGIN)``.
        """
        stencil = self.half_stencil(radius, "CellList.iter_pairs")
        cell, own_end, lo, hi = stencil.cell, stencil.own_end, stencil.lo, stencil.hi
        pos = np.arange(self.order.size, dtype=np.int64)
        per_point = own_end[cell] - pos - 1
        if lo.shape[0]:
            per_point += (hi - lo).sum(axis=0)[cell]
        r2 = np.asarray(stencil.radius, dtype=self.coords[0].dtype) ** 2
        for a, b in _chunks_by_total(per_point, CHUNK):
            u = cell[a:b]
            run_lo = np.concatenate([pos[a:b] + 1, lo[:, u].ravel()])
            run_hi = np.concatenate([own_end[u], hi[:, u].ravel()])
            owner = np.tile(pos[a:b], lo.shape[0] + 1)
            p, q = _expand(owner, run_lo, run_hi - run_lo)
            dx, rho2 = _offsets_and_squares(self.coords, p, q)
            keep = np.flatnonzero(rho2 <= r2)
            if keep.size:
                yield p[keep], q[keep], [c[keep] for c in dx], rho2[keep]

    def pairs(self, radius: float, *, positions: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Flat indices ``(i, j)`` of every unordered pair within ``radius``, ``i < j``.

        ``radius`` must not exceed ``reach · cell_size / (1 + CELL_MARGIN)``. With
        ``positions``: sorted positions instead, as :meth:`iter_pairs` yields them.
        """
        chunks = [(p, q) for p, q, _, _ in self.iter_pairs(radius)]
        if not chunks:
            return np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
        p = np.concatenate([c[0] for c in chunks])
        q = np.concatenate([c[1] for c in chunks])
        if positions:
            return p, q
        p = self.order[p]
        q = self.order[q]
        return np.minimum(p, q), np.maximum(p, q)

    def knearest_round(
        self, queries: np.ndarray, k: int, radius: float, reach: int | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One round of :func:`knn` for the points at sorted positions ``queries``.

        Returns ``(resolved, idx, rho2)``: a bool mask over ``queries`` and, for the
        resolved ones (in that order), the flat indices ``(R, k)`` of their ``k`` nearest
        other points and the squared distances, nearest first. A query is resolved when
        at least ``k`` other points lie within ``radius``, which must not exceed
        ``reach · cell_size / (1 + CELL_MARGIN)``: its block then holds all of them.
        ``reach`` (default and at most the grid's padding :attr:`reach`) sets the block.
        Where numba imports, one compiled pass does the round
        (:func:`swarm_envs.physics.compiled_pairs.knearest_round`; the same neighbours
        and distances, except that equally distant ones may come in another order).
        """
        m = self.reach if reach is None else _check_reach("CellList.knearest_round", reach)
        r = self._check_radius("CellList.knearest_round", radius, m)
        dtype = self.coords[0].dtype
        r2 = np.asarray(r, dtype=dtype) ** 2
        rows = ((0,) * (self.dim - 1), *_rows(self.dim, m, half=False))
        rows = tuple(dict.fromkeys(rows))  # the own row once
        lo, hi = self.row_runs(self.point_key[queries], rows, m)
        lo, hi = lo.T, hi.T  # (Q, rows): runs of one query together
        from swarm_envs.physics import compiled_pairs  # imports this module

        if k >= 1 and compiled_pairs.numba_enabled():  # one compiled pass, the same answer
            count, pos, d2 = compiled_pairs.knearest_round(
                np.stack(self.coords), queries, lo, hi, k, float(r2)
            )
            resolved = count >= k
            return resolved, self.order[pos[resolved]], d2[resolved]
        per_query = (hi - lo).sum(axis=1)
        resolved = np.zeros(queries.size, dtype=bool)
        idx_parts: list[np.ndarray] = []
        d2_parts: list[np.ndarray] = []
        for a, b in _chunks_by_padded(per_query, CHUNK):
            ln = (hi[a:b] - lo[a:b]).ravel()
            p, q = _expand(np.repeat(queries[a:b], len(rows)), lo[a:b].ravel(), ln)
            row = np.repeat(np.arange(b - a), per_query[a:b])
            rho2 = _offsets_and_squares(self.coords, p, q)[1]
            keep = (rho2 <= r2) & (q != p)
            cnt = np.bincount(row[keep], minlength=b - a)
            ok = cnt >= k
            resolved[a:b] = ok
            if not ok.any():
                continue
            keep &= ok[row]  # candidates of resolved rows only
            keep = np.flatnonzero(keep)
            cnt = cnt[ok]
            row = (np.cumsum(ok) - 1)[row[keep]]  # compact row numbers
            q, rho2 = q[keep], rho2[keep]
            first = np.cumsum(cnt) - cnt
            width = int(cnt.max())
            dist = np.full((cnt.size, width), np.inf, dtype=dtype)
            dist.ravel()[row * width + (np.arange(row.size) - first[row])] = rho2
            if width > k:
                col = np.argpartition(dist, k - 1, axis=1)[:, :k]
                dist = np.take_along_axis(dist, col, axis=1)
            else:
                col = np.broadcast_to(np.arange(width), dist.shape)
            srt = np.argsort(dist, axis=1, kind="stable")
            d2_parts.append(np.take_along_axis(dist, srt, axis=1))
            col = np.take_along_axis(col, srt, axis=1)
            idx_parts.append(self.order[q[first[:, None] + col]])
        if idx_parts:
            return resolved, np.concatenate(idx_parts), np.concatenate(d2_parts)
        return resolved, np.empty((0, k), np.intp), np.empty((0, k), dtype)


def _compress(c: np.ndarray, reach: int) -> tuple[np.ndarray, list[int]]:
    """Renumber each dimension's cell coordinates consecutively, keeping neighbours.

    The vocabulary of dimension ``k`` is every occupied ``c_k + o``, ``|o| ≤ reach + 1``:
    consecutive integers around an occupied coordinate stay consecutive ranks, so the
    cells up to ``reach`` apart from an occupied cell keep their offsets (and one past a
    row's end stays the next key). Ranks are shifted by ``reach`` for the padding.
    """
    out = np.empty_like(c)
    size = []
    span = np.arange(-reach - 1, reach + 2, dtype=np.int64)
    for k in range(c.shape[1]):
        vocab = np.unique((c[:, k, None] + span).ravel())
        out[:, k] = np.searchsorted(vocab, c[:, k])
        size.append(int(vocab.size))
    return out, size


def _chunks_by_total(cost: np.ndarray, budget: int) -> list[tuple[int, int]]:
    """Consecutive ranges of items whose summed cost is about ``budget`` (≥ 1 item each)."""
    total = np.cumsum(cost)
    if total.size == 0 or total[-1] == 0:
        return []
    cuts = np.searchsorted(total, np.arange(budget, int(total[-1]), budget), side="right")
    bounds = np.unique(np.concatenate(([0], cuts, [cost.size])))
    return [(int(a), int(b)) for a, b in itertools.pairwise(bounds)]


def _chunks_by_padded(cost: np.ndarray, budget: int) -> list[tuple[int, int]]:
    """Ranges whose ``length × max cost`` stays within ``budget`` (≥ 1 item each).

    That bounds the padded ``(rows, width)`` arrays of the k-nearest selection.
    """
    out = []
    s, n = 0, cost.size
    while s < n:
        # length × max ≤ budget needs length ≤ budget / cost[s]: look no further.
        w = np.maximum(cost[s : s + budget // max(int(cost[s]), 1) + 1], 1)
        fits = np.arange(1, w.size + 1) * np.maximum.accumulate(w) <= budget
        e = s + max(1, int(np.count_nonzero(fits)))
        out.append((s, e))
        s = e
    return out


def _expand(
    owner: np.ndarray, run_start: np.ndarray, run_len: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """All ``(p, q)`` with ``q`` in a run ``[start, start + len)`` and ``p`` its owner."""
    end = np.cumsum(run_len)
    q = np.arange(int(end[-1]) if end.size else 0, dtype=np.int64)
    q += np.repeat(run_start - (end - run_len), run_len)
    return np.repeat(owner, run_len), q


def _offsets_and_squares(
    coords: tuple[np.ndarray, ...], p: np.ndarray, q: np.ndarray
) -> tuple[list[np.ndarray], np.ndarray]:
    """``dx[k] = x_q[k] − x_p[k]`` and ``Σ_k dx[k]²``, in the coordinates' dtype."""
    dx = [c[q] - c[p] for c in coords]
    out = dx[0] * dx[0]
    for dk in dx[1:]:
        out += dk * dk
    return dx, out


def radius_pairs(
    x: np.ndarray, radius: float, *, reach: int = REACH
) -> tuple[np.ndarray, np.ndarray]:
    """Every unordered pair of agents within ``radius``: flat indices ``(i, j)``, ``i < j``.

    Args:
        x: positions ``(..., N, d)``, ``d`` in {2, 3}; batch dimensions are separate
            swarms (indices are into ``x.reshape(-1, d)``, so ``i // N`` is the swarm).
        radius: search radius, ``> 0``; pairs with ``Σ_k (x_j − x_i)_k² ≤ radius²``.
        reach: cells per radius (cell side ``radius (1 + CELL_MARGIN) / reach``).

    Returns:
        ``(i, j)`` int arrays of equal length, each pair once, in no particular order.
    """
    r = check_real("radius_pairs", "radius", radius, low=0.0, low_inclusive=False)
    m = _check_reach("radius_pairs", reach)
    return CellList.build(x, r * (1.0 + CELL_MARGIN) / m, m).pairs(r)


def density_radius(x: np.ndarray, k: int) -> float:
    """A first guess of the radius that holds about ``2k`` neighbours of a typical agent.

    From the density ``N / volume`` of each swarm's bounding box (degenerate extents
    floored at 10⁻³ of the largest), refined once with the occupancy of a grid of that
    radius: ``Σ c² / Σ c`` is the mean number of agents sharing an agent's cell, which
    sees clusters that the bounding box hides.
    """
    x3, _, n, d = _flat_state(x)
    ext = (x3.max(axis=1) - x3.min(axis=1)).astype(np.float64)  # (B, d)
    big = float(ext.max())
    if big == 0.0:
        return 1.0
    vol = np.prod(np.maximum(ext, 1e-3 * big), axis=1)
    density = float(np.median(n / vol))
    target = 2.0 * max(k, 1) / _BALL_VOLUME[d]  # per cell of side R, at 2k per ball
    radius = (target / density) ** (1.0 / d)
    cells = CellList.build(x3, radius, 1)
    c = np.diff(cells.start).astype(np.float64)
    occupancy = float((c * c).sum() / c.sum())
    if occupancy > 4.0 * target:
        radius *= (target / occupancy) ** (1.0 / d)
    return radius


def knn_rounds(
    build: Callable[[float], CellList],
    todo: np.ndarray,
    k: int,
    radius: float,
    idx: np.ndarray,
    d2: np.ndarray,
) -> None:
    """The rounds of :func:`knn` for the points with flat indices ``todo``, in place.

    ``build(h)``: the cell list of every point (flat indices ``[0, M)``) with cells of
    side ``h`` and padding ``2 KNN_REACH``. Row ``i`` of ``idx`` ``(M, k)`` gets the flat
    indices of point ``i``'s ``k`` nearest others (``k ≥ 1``), nearest first, and ``d2``
    their squared distances; each point of ``todo`` must have ``k`` others in its
    swarm. The first round searches ``radius``.
    """
    r, m = radius, idx.shape[0]
    while todo.size:
        # One grid serves two rounds: radius r (reach KNN_REACH), then 2r.
        cells = build(r * (1.0 + CELL_MARGIN) / KNN_REACH)
        inverse = np.empty(m, dtype=np.int64)
        inverse[cells.order] = np.arange(m)
        for reach in (KNN_REACH, 2 * KNN_REACH):
            queries = np.sort(inverse[todo])
            ok, nb, nd2 = cells.knearest_round(queries, k, r, reach)
            done = cells.order[queries[ok]]
            idx[done] = nb
            d2[done] = nd2
            todo = cells.order[queries[~ok]]
            r *= 2.0
            if not todo.size:
                break


def knn(x: np.ndarray, k: int, *, radius: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest other agents of every agent, nearest first, and their distances.

    Args:
        x: positions ``(..., N, d)``; each batch entry is a separate swarm.
        k: neighbours per agent, ``≥ 0``; ``min(k, N − 1)`` are returned.
        radius: first search radius (only a guess: any positive value gives the same
            answer, in more or fewer rounds). Default :func:`density_radius`.

    Returns:
        ``(idx, dist)``, each ``(..., N, min(k, N − 1))``: per-swarm agent indices in
        ``[0, N)`` (never the agent itself, no repeats) and the distances
        ``√Σ_k (x_j − x_i)_k²``, non-decreasing along the last axis.
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise ValueError(f"knn: k must be an integer >= 0, got {k!r}")
    x3, batch, n, _ = _flat_state(x)
    kk = min(int(k), n - 1)
    M = x3.shape[0] * n
    idx = np.zeros((M, kk), dtype=np.intp)
    d2 = np.zeros((M, kk), dtype=x3.dtype)
    if kk > 0:
        r = density_radius(x3, kk) if radius is None else radius
        r = check_real("knn", "radius", r, low=0.0, low_inclusive=False)
        span = float((x3.max(axis=1) - x3.min(axis=1)).max())
        r = max(r, 4.0 * KNN_REACH * span / MAX_CELLS)  # keep the grid within MAX_CELLS
        knn_rounds(lambda h: CellList.build(x3, h, 2 * KNN_REACH), np.arange(M), kk, r, idx, d2)
        idx -= (np.arange(M) // n * n)[:, None]
    return idx.reshape(*batch, n, kk), np.sqrt(d2).reshape(*batch, n, kk)


__all__ = [
    "CELL_MARGIN",
    "CHUNK",
    "KNN_REACH",
    "LOOKUP_FACTOR",
    "MAX_CELLS",
    "REACH",
    "CellList",
    "HalfStencil",
    "density_radius",
    "knn",
    "knn_rounds",
    "radius_pairs",
]
