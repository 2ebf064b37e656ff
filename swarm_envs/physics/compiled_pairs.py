"""The cell list's two hot loops compiled with numba, when numba imports: the cut-off pair
pass (:func:`cell_pair_sums`) and the k-nearest round (:func:`knearest_round`); and
:func:`swarm_pair_sums`, the cut-off core's pass over a batch of swarms (this pass, or
the numpy one without numba).

:func:`cell_pair_sums` gives exactly what feeding every chunk of
:meth:`swarm_envs.physics.neighbors.CellList.iter_pairs` to a
:class:`swarm_envs.physics.pair_sums.PairAccumulator` gives (the forces, pair potential,
close pairs and, with ``rates``, each point's sums of the step-size rule's rates
:func:`~swarm_envs.physics.social_potential.rate_law`, over every unordered pair within
the radius), to float64 round-off. Both apply
the one pair law, :func:`swarm_envs.physics.social_potential.pair_law` (``docs/models.md``
§1, eqs. 9–11): the numpy pass to chunks of candidates (about 40 array passes over
65,536 candidates at a time, bound by memory traffic), this one to each candidate once,
in registers, with ``pair_law`` compiled by numba (``inline="always"``) on scalars. Per
pair within ``r`` (``r_ij = x_j − x_i``, ``ρ = |r_ij|``): ``(s_ij, U(ρ)) = pair_law(...)``,
``+s_ij r_ij`` on ``i`` and ``−s_ij r_ij`` on ``j``; ``U(ρ)`` to the swarm of ``i``; a
close pair when ``ρ² < close_radius²``. ``1/ρ`` is taken of ``max(ρ, RHO_FLOOR)``, so
that coincident agents give no force (``r_ij = 0``), never NaN.

:func:`knearest_round` does one round of
:meth:`swarm_envs.physics.neighbors.CellList.knearest_round` per query, in parallel: it
counts the other points within the radius and keeps the ``k`` nearest by insertion. The
same neighbours and distances as the numpy round (tested); equally distant neighbours
may come in another order (the numpy round's ``argpartition`` breaks such ties
arbitrarily too).

In :func:`cell_pair_sums` the points are split into :data:`BLOCKS` blocks of consecutive
sorted positions, each summed by whichever thread takes it (``numba.prange``) into its
own window of a buffer (the positions from its first point to the farthest run end of
its points: about ``M`` columns in all plus the blocks' overlaps), and the windows are
added in block order: the result does not depend on the number of threads. Both loops
are ``O(M)`` in the number of points ``M`` at bounded density (``O(M)`` candidates of
the cell runs, each visited once).
Without numba (it is optional: ``pip install swarm-envs[fast]``) :data:`AVAILABLE` is
false and the callers keep the numpy pass; ``SWARM_ENVS_NUMBA=0`` forces that too.
The first call compiles (cached on disk by numba where it can write; the pair kernel's
cache entry is keyed on the code of ``pair_law`` and ``rate_law`` too, so a change of
either law recompiles).
Calls are serialised by a lock (numba's fallback threading layer, workqueue, does not
allow concurrent parallel calls). Its OpenMP layer is not fork-safe: processes that use
the cut-off core after a fork should be started with ``spawn`` or ``forkserver`` (as
SB3's ``SubprocVecEnv`` and Ray do by default).
"""

from __future__ import annotations

import hashlib
import importlib.util
import logging
import marshal
import math
import os
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from swarm_envs.physics.neighbors import CELL_MARGIN, REACH, CellList
from swarm_envs.physics.pair_sums import PairAccumulator, PairSums
from swarm_envs.physics.social_potential import (
    RHO_FLOOR,
    SocialPotentialParams,
    pair_law,
    rate_law,
)

__all__ = [
    "AVAILABLE",
    "BLOCKS",
    "cell_pair_sums",
    "compile_seconds",
    "knearest_round",
    "numba_enabled",
    "swarm_pair_sums",
]

#: Blocks of points summed separately, then added in order (see the module docstring).
BLOCKS = 16

logger = logging.getLogger(__name__)

#: Wall time of the process's first kernel call, either kernel (the compile, or loading
#: numba's disk cache), logged once at INFO level; ``None`` until then.
compile_seconds: float | None = None

# One kernel call at a time: numba's fallback threading layer (workqueue) aborts on
# concurrent parallel calls; the kernel uses every core anyway.
_KERNEL_LOCK = threading.Lock()

#: Whether numba is installed (found without importing it: numba's import costs about a
#: quarter of a second, paid on the first :func:`cell_pair_sums` instead).
AVAILABLE = importlib.util.find_spec("numba") is not None


def _scalar_exp(x: float) -> float:
    """``e^x`` of a float: the ``exp`` that the pair kernel hands to ``pair_law``."""
    return math.exp(x)


# What the kernels read as globals when numba compiles them, set on the first compile:
# `range`, `pair_law` and `_scalar_exp` until then (the kernels also run as plain
# Python), then numba.prange and the two functions through numba.njit(inline="always")
# (inlined into the kernel's loop, where LLVM folds them into the surrounding code).
prange = range
# Called with the default potential=True (U computed): one signature for both bindings.
_law: Callable[..., tuple[Any, Any]] = pair_law
_rates = rate_law
_exp = _scalar_exp
_compiled_fns: dict[Callable[..., Any], Callable[..., Any]] = {}


def _compiled(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` through ``numba.njit(parallel=True)``, made on first use (under the lock)."""
    global prange, _law, _rates, _exp
    if fn not in _compiled_fns:
        import numba

        if prange is range:
            prange = numba.prange
            _law = numba.njit(inline="always")(pair_law)
            _rates = numba.njit(inline="always")(rate_law)
            _exp = numba.njit(inline="always")(_scalar_exp)
        _compiled_fns[fn] = numba.njit(parallel=True, cache=True, nogil=True)(fn)
    return _compiled_fns[fn]


def _run(fn: Callable[..., Any], *args: Any) -> Any:
    """``fn`` compiled, called under the lock; the process's first call is timed."""
    global compile_seconds
    with _KERNEL_LOCK:
        first = compile_seconds is None
        t0 = time.perf_counter()
        out = _compiled(fn)(*args)
        if first:
            compile_seconds = time.perf_counter() - t0
            logger.info("compiled_pairs: first numba call took %.1f s", compile_seconds)
    return out


_import_error: str | None = None  # why an installed numba failed to import, once tried
_import_tried = False


def _numba_imports() -> bool:
    """Whether numba imports; tried once. An installed numba may still fail (a numpy
    newer than it supports, say): then warn once and keep the numpy pass."""
    global _import_error, _import_tried
    if not _import_tried:
        _import_tried = True
        try:
            import numba  # noqa: F401
        except Exception as err:  # numba raises ImportError, or others on a broken install
            _import_error = f"{type(err).__name__}: {err}"
            warnings.warn(
                f"numba is installed but does not import ({_import_error}); the cut-off "
                "core's pair pass runs in numpy",
                RuntimeWarning,
                stacklevel=3,
            )
    return _import_error is None


def numba_enabled() -> bool:
    """Whether the compiled pass runs: numba imports and ``SWARM_ENVS_NUMBA`` is not ``0``.

    ``SWARM_ENVS_NUMBA``: ``auto`` (default) uses numba where it imports; ``0`` never;
    ``1`` always, and raises :class:`ValueError` where numba does not import.
    """
    flag = os.environ.get("SWARM_ENVS_NUMBA", "auto").strip().lower()
    if flag not in ("auto", "0", "1"):
        raise ValueError(f"SWARM_ENVS_NUMBA must be 0, 1 or auto, got {flag!r}")
    if flag == "0":
        return False
    usable = AVAILABLE and _numba_imports()
    if flag == "1" and not usable:
        reason = _import_error or "not installed (pip install numba)"
        raise ValueError(f"SWARM_ENVS_NUMBA=1 but numba does not import: {reason}")
    return usable


def _pair_pass_kernel(law_key: str) -> Callable[..., Any]:
    """The pair kernel, closed over ``law_key``, a hash of the code of :func:`pair_law`
    and :func:`rate_law`.

    numba's disk cache keys a kernel on its own file, bytecode and closure, not on the
    functions it calls from other files: the closure brings the laws into the key, so
    that a changed law is compiled anew instead of loaded stale.
    """

    def _pair_pass(
        coords: np.ndarray,
        vel: np.ndarray,
        cell: np.ndarray,
        own_end: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        groups: np.ndarray,
        n_groups: int,
        r2: float,
        close2: float,
        consts: np.ndarray,
        win_lo: np.ndarray,
        win_off: np.ndarray,
        rates: bool,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kernel that numba compiles (see :func:`cell_pair_sums`).

        ``coords`` and ``vel`` are ``(3, M)``: 2-D points come with a zero third row, so
        that one loop body, on scalars, serves both dimensions. ``consts`` holds
        ``C_a, C_r, l_a, l_r, C_o, l_o`` (``pair_law``'s parameters), ``align`` (1 for
        the alignment term, 0 without) and ``RHO_FLOOR``. Block ``b`` (points
        ``b M // blocks`` to ``(b + 1) M // blocks``, ``blocks = len(win_lo)``) writes
        only positions from ``win_lo[b]`` on, into its window of the buffer, columns
        ``win_off[b] … win_off[b + 1]``: rows 0–2 the force, and with ``rates`` rows 3
        and 4 the sums of ``κ`` and ``w`` of ``rate_law`` over each point's pairs.
        """
        _ = law_key  # in the closure: part of numba's cache key (see above)
        m = coords.shape[1]
        n_rows = lo.shape[0]
        blocks = win_lo.shape[0]
        C_a, C_r, l_a, l_r, C_o, l_o, align, floor = consts
        acc = np.zeros((5 if rates else 3, win_off[blocks]))
        pot = np.zeros((blocks, n_groups))
        close = np.zeros((blocks, n_groups), dtype=np.int64)
        for b in prange(blocks):
            start = b * m // blocks
            stop = (b + 1) * m // blocks
            shift = win_off[b] - win_lo[b]  # position q is column q + shift
            for p in range(start, stop):
                u = cell[p]
                x0, x1, x2 = coords[0, p], coords[1, p], coords[2, p]
                v0, v1, v2 = vel[0, p], vel[1, p], vel[2, p]
                f0 = f1 = f2 = 0.0  # the force on p, added once at the end
                k_p = w_p = 0.0  # its rate sums (with rates)
                pot_p = 0.0
                close_p = 0
                for r in range(n_rows + 1):
                    if r == 0:  # the rest of p's own row
                        q0, q1 = p + 1, own_end[u]
                    else:
                        q0, q1 = lo[r - 1, u], hi[r - 1, u]
                    for q in range(q0, q1):
                        d0 = coords[0, q] - x0
                        d1 = coords[1, q] - x1
                        d2 = coords[2, q] - x2
                        rho2 = d0 * d0 + d1 * d1 + d2 * d2
                        if rho2 > r2:
                            continue
                        if rho2 < close2:
                            close_p += 1
                        rho = math.sqrt(rho2)
                        inv = 1.0 / max(rho, floor)
                        if align:  # vdot = (v_p − v_q)·r_pq
                            vdot = (v0 - vel[0, q]) * d0 + (v1 - vel[1, q]) * d1
                            vdot += (v2 - vel[2, q]) * d2
                            s, u_pq = _law(rho, inv, vdot, C_a, C_r, l_a, l_r, C_o, l_o, _exp)
                        else:
                            s, u_pq = _law(rho, inv, None, C_a, C_r, l_a, l_r, C_o, l_o, _exp)
                        pot_p += u_pq
                        w0, w1, w2 = s * d0, s * d1, s * d2
                        f0 += w0
                        f1 += w1
                        f2 += w2
                        c = q + shift
                        acc[0, c] -= w0
                        acc[1, c] -= w1
                        acc[2, c] -= w2
                        if rates:  # symmetric: both ends of the pair
                            kap, damp = _rates(rho, C_a, C_r, l_a, l_r, C_o, l_o, _exp)
                            k_p += kap
                            acc[3, c] += kap
                            if damp is not None:
                                w_p += damp
                                acc[4, c] += damp
                c = p + shift
                acc[0, c] += f0
                acc[1, c] += f1
                acc[2, c] += f2
                if rates:
                    acc[3, c] += k_p
                    acc[4, c] += w_p
                pot[b, groups[p]] += pot_p
                close[b, groups[p]] += close_p
        return acc, pot, close

    return _pair_pass


#: The pair kernel (see :func:`_pair_pass_kernel`).
_pair_pass = _pair_pass_kernel(
    hashlib.sha256(marshal.dumps((pair_law.__code__, rate_law.__code__))).hexdigest()
)


def _knn_round(
    coords: np.ndarray,
    queries: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    k: int,
    r2: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel of :func:`knearest_round` that numba compiles.

    Per query (in parallel; no query writes another's row): every candidate of its runs
    within ``r2`` is counted, and the ``k`` smallest squared distances are kept sorted by
    insertion, a later candidate after an equal earlier one (numpy's round may order
    such ties otherwise: its ``argpartition`` is not stable).
    """
    d = coords.shape[0]
    n_q, n_rows = lo.shape
    count = np.zeros(n_q, np.int64)
    best_q = np.full((n_q, k), -1, np.int64)
    best_d = np.full((n_q, k), np.inf, coords.dtype)
    for i in prange(n_q):
        p = queries[i]
        for r in range(n_rows):
            for q in range(lo[i, r], hi[i, r]):
                if q == p:
                    continue
                rho2 = (coords[0, q] - coords[0, p]) * (coords[0, q] - coords[0, p])
                for c in range(1, d):
                    rho2 += (coords[c, q] - coords[c, p]) * (coords[c, q] - coords[c, p])
                if rho2 > r2:
                    continue
                count[i] += 1
                if rho2 < best_d[i, k - 1]:
                    j = k - 1
                    while j > 0 and best_d[i, j - 1] > rho2:
                        best_d[i, j] = best_d[i, j - 1]
                        best_q[i, j] = best_q[i, j - 1]
                        j -= 1
                    best_d[i, j] = rho2
                    best_q[i, j] = q
    return count, best_q, best_d


def knearest_round(
    coords: np.ndarray,
    queries: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    k: int,
    r2: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One k-nearest round of :meth:`~swarm_envs.physics.neighbors.CellList.knearest_round`,
    compiled: ``(count, positions (Q, k), squared distances (Q, k))`` per query.

    ``coords`` ``(d, M)`` sorted, ``queries`` ``(Q,)`` sorted positions, ``lo, hi``
    ``(Q, rows)`` their runs; ``count`` is the number of other points within ``r2``
    (a query is resolved when it is at least ``k``), the rest its ``k`` nearest among
    them, nearest first (``-1`` and ``inf`` where fewer). ``k ≥ 1``.
    """
    if k < 1:
        raise ValueError(f"knearest_round: k must be >= 1, got {k!r}")
    return _run(
        _knn_round,
        np.ascontiguousarray(coords),
        np.ascontiguousarray(queries, np.int64),
        np.ascontiguousarray(lo, np.int64),
        np.ascontiguousarray(hi, np.int64),
        int(k),
        coords.dtype.type(r2),
    )


def cell_pair_sums(
    cells: CellList,
    radius: float,
    params: SocialPotentialParams,
    v: np.ndarray | None,
    *,
    groups: np.ndarray | None = None,
    n_groups: int = 1,
    close_radius: float = 0.0,
    rates: bool = False,
) -> PairSums:
    """:class:`PairSums` over every pair within ``radius`` of ``cells``, in sorted order.

    The same as ``PairAccumulator(params, M, v, groups=groups, n_groups=n_groups,
    potential=True, close_radius=close_radius, rates=rates)`` fed with
    ``cells.iter_pairs(radius)``: ``v`` (velocities ``(M, d)`` in the cells' sorted
    order, or ``None`` for no alignment) and ``groups`` (``(M,)`` swarm of each sorted
    point) as there; the force (and, with ``rates``, the rate sums) come back in sorted
    order, float64.
    """
    m_pts = cells.order.size
    d = cells.dim
    stencil = cells.half_stencil(radius, "cell_pair_sums")
    coords = np.zeros((3, m_pts))  # 2-D: a zero third row (see _pair_pass)
    coords[:d] = cells.coords
    align = v is not None and params.C_o != 0
    vel = np.zeros((3, m_pts))  # read for every point; zero without alignment
    if align:
        vel[:d] = np.asarray(v, dtype=np.float64).T
    grp = np.zeros(m_pts, np.int64) if groups is None else np.asarray(groups, np.int64)
    p = params
    consts = np.array([p.C_a, p.C_r, p.l_a, p.l_r, p.C_o, p.l_o, 1.0 if align else 0.0, RHO_FLOOR])
    win_lo, win_off = _windows(stencil, m_pts)
    acc, pot, close = _run(
        _pair_pass,
        coords,
        vel,
        stencil.cell,
        np.asarray(stencil.own_end, np.int64),
        np.ascontiguousarray(stencil.lo, np.int64),
        np.ascontiguousarray(stencil.hi, np.int64),
        grp,
        int(n_groups),
        float(stencil.radius) ** 2,
        float(close_radius) ** 2,
        consts,
        win_lo,
        win_off,
        bool(rates),
    )
    total = np.zeros((acc.shape[0], m_pts))
    for b in range(BLOCKS):  # in block order, whatever thread summed which block
        lo = int(win_lo[b])
        width = int(win_off[b + 1] - win_off[b])
        total[:, lo : lo + width] += acc[:, win_off[b] : win_off[b + 1]]
    return PairSums(
        total[:d].T.copy(),
        pot.sum(axis=0),
        close.sum(axis=0),
        total[3].copy() if rates else None,
        total[4].copy() if rates else None,
    )


def _windows(stencil: Any, m: int) -> tuple[np.ndarray, np.ndarray]:
    """``(win_lo (BLOCKS,), win_off (BLOCKS + 1,))``: the positions each block of the pair
    kernel writes, ``win_lo[b]`` up to its last point's or candidate's position, and
    where each window starts in the kernel's buffer. Every candidate of a point comes
    after it in the sorted order (the half stencil), so a block's window starts at its
    first point and ends at the farthest run end of its points: the buffer holds about
    ``M`` columns plus the blocks' overlaps, not ``BLOCKS · M``."""
    starts = np.arange(BLOCKS, dtype=np.int64) * m // BLOCKS
    stops = np.arange(1, BLOCKS + 1, dtype=np.int64) * m // BLOCKS
    ends = stops.copy()
    if m:
        reach = np.asarray(stencil.own_end, np.int64)
        if stencil.hi.shape[0]:
            reach = np.maximum(reach, stencil.hi.max(axis=0))
        point_end = reach[stencil.cell]
        full = stops > starts
        ends[full] = np.maximum(stops[full], np.maximum.reduceat(point_end, starts[full]))
    win_off = np.zeros(BLOCKS + 1, np.int64)
    np.cumsum(ends - starts, out=win_off[1:])
    return starts, win_off


def swarm_pair_sums(
    x: np.ndarray,
    v: np.ndarray,
    params: SocialPotentialParams,
    radius: float,
    close_radius: float = 0.0,
    present: np.ndarray | None = None,
) -> PairSums:
    """:class:`PairSums` of every pair within ``radius`` in each swarm of ``x`` ``(B, N, d)``
    (velocities ``v`` for the alignment), rates included, in the agents' own order.

    One cell list (cells of ``radius (1 + CELL_MARGIN) / REACH``), then the compiled pass
    (:func:`cell_pair_sums`) where :func:`numba_enabled`, else the numpy
    :class:`~swarm_envs.physics.pair_sums.PairAccumulator` over
    :meth:`~swarm_envs.physics.neighbors.CellList.iter_pairs`; both visit the agents in
    cell order. The force, ``kappa`` and ``damping`` come back flat, ``(B·N, d)`` and
    ``(B·N,)`` in ``x.reshape(-1, d)``'s order (float64), the potential and the close
    pairs per swarm ``(B,)``. ``radius = 0`` or ``N = 1``: no pairs, zeros.
    ``present`` ``(B, N)`` bool: only the pairs of present agents (the others are left
    out of the cell list: zero force and rates).
    """
    B, N, d = x.shape
    m = B * N
    rows = None if present is None else np.flatnonzero(present.reshape(m))
    zero = np.zeros(m)
    if not (radius > 0 and N > 1) or (rows is not None and rows.size == 0):
        return PairSums(np.zeros((m, d)), np.zeros(B), np.zeros(B, np.int64), zero, zero.copy())
    h = radius * (1.0 + CELL_MARGIN) / REACH
    if rows is None:
        cells = CellList.build(x, h, REACH)
        order = cells.order  # flat index of each sorted point
        groups = order // N if B > 1 else None
    else:
        cells = CellList.build(x.reshape(m, d)[rows], h, REACH, groups=rows // N)
        order = rows[cells.order]
        groups = order // N
    vel = v.reshape(m, d)[order]
    if numba_enabled():
        sums = cell_pair_sums(
            cells,
            radius,
            params,
            vel,
            groups=groups,
            n_groups=B,
            close_radius=close_radius,
            rates=True,
        )
    else:
        acc = PairAccumulator(
            params,
            order.size,
            vel,
            groups=groups,
            n_groups=B,
            potential=True,
            close_radius=close_radius,
            rates=True,
        )
        for chunk in cells.iter_pairs(radius):
            acc.add(*chunk)
        sums = acc.result(d)
    assert sums.kappa is not None and sums.damping is not None
    force = np.zeros((m, d))
    force[order] = sums.force
    kappa, damping = zero, zero.copy()
    kappa[order] = sums.kappa
    damping[order] = sums.damping
    return PairSums(force, sums.potential, sums.close, kappa, damping)
