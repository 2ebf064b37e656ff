"""Sums over a list of pairs of the social potential's pair terms: forces, potential,
close pairs and the step-size rule's rates (for large swarms).

:class:`PairAccumulator` applies the one pair law
(:func:`~swarm_envs.physics.social_potential.pair_law`) and the one rate law
(:func:`~swarm_envs.physics.social_potential.rate_law`) to chunks of pairs, as
:meth:`swarm_envs.physics.neighbors.CellList.iter_pairs` or :func:`pair_sums` produce
them; the compiled pass of :mod:`swarm_envs.physics.compiled_pairs` applies the same
functions to one pair at a time and returns the same :class:`PairSums`.
:func:`swarm_rates` turns the per-agent rate sums into the per-swarm ``(ω², γ)`` of
:func:`~swarm_envs.physics.integrators.stable_substep`. :mod:`swarm_envs.physics.cutoff`
re-exports all of these (its cut-off radius decides which pairs are listed).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from swarm_envs.physics.social_potential import (
    RHO_FLOOR,
    SocialPotentialParams,
    components,
    dissipation_rate,
    pair_law,
    rate_law,
)

#: Pairs processed per chunk by :func:`pair_sums` (bounded, cache-sized temporaries).
PAIR_CHUNK = 1 << 16


def _check_params(owner: str, params: Any) -> SocialPotentialParams:
    if not isinstance(params, SocialPotentialParams):
        raise ValueError(f"{owner}: params must be SocialPotentialParams, got {type(params)}")
    return params


class PairSums(NamedTuple):
    """What :func:`pair_sums` returns."""

    force: np.ndarray
    """``(M, d)``: ``Σ_j f_ij u_ij`` over the listed pairs (pair terms only)."""
    potential: np.ndarray
    """``(n_groups,)``: ``Σ U(ρ_ij)`` over the listed pairs of each group (float64)."""
    close: np.ndarray
    """``(n_groups,)``: number of listed pairs with ``ρ_ij < close_radius``."""
    kappa: np.ndarray | None = None
    """``(M,)``: ``Σ_j κ(ρ_ij)`` per row over the listed pairs (the stiffness of the
    step-size rule, :func:`~swarm_envs.physics.social_potential.rate_law`; float64), or
    ``None`` when the rates were not asked for."""
    damping: np.ndarray | None = None
    """``(M,)``: ``Σ_j w(ρ_ij)`` per row (the alignment's damping rate; zeros when
    ``C_o = 0``), or ``None`` as :attr:`kappa`."""


def swarm_rates(
    kappa: np.ndarray,
    damping: np.ndarray,
    params: SocialPotentialParams,
    *,
    sink: bool = False,
    v: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(ω², γ)`` per swarm ``(...)`` from the per-agent rate sums ``(..., N)``.

    The rule of :func:`~swarm_envs.physics.social_potential.pair_rates` applied to sums
    over a pair list (:attr:`PairSums.kappa`, :attr:`PairSums.damping`):
    ``ω² = (2/m) max_i Σ_j κ_ij`` (``+ C_g/(l_g² m)`` with ``sink``, the goal sink acting
    passively) and ``γ = (β + 2 max_i Σ_j w_ij)/m``. With every pair listed it equals
    ``pair_rates``; with the pairs within ``r_c`` it drops the rates of the pairs beyond,
    as the force drops their terms. With self-propulsion (``alpha > 0``) ``β`` is
    replaced by :func:`~swarm_envs.physics.social_potential.dissipation_rate` of the
    velocities ``v`` ``(..., N, d)`` (required then).

    >>> p = SocialPotentialParams.navigation()
    >>> omega2, gamma = swarm_rates(np.array([[3.0, 5.0]]), np.array([[0.5, 0.2]]), p)
    >>> omega2.tolist(), gamma.tolist()
    ([10.0], [2.0])
    """
    p = params
    omega2 = (2.0 / p.m) * (kappa.max(axis=-1) if kappa.shape[-1] else np.zeros(kappa.shape[:-1]))
    if sink:
        omega2 = omega2 + p.C_g / (p.l_g * p.l_g * p.m)
    top = damping.max(axis=-1) if damping.shape[-1] else np.zeros(damping.shape[:-1])
    rate = dissipation_rate(None if v is None else components(v), p)
    return omega2, (rate + 2.0 * top) / p.m


def _check_pairs(i: Any, j: Any, m: int) -> tuple[np.ndarray, np.ndarray]:
    i = np.asarray(i)
    j = np.asarray(j)
    if i.shape != j.shape or i.ndim != 1:
        raise ValueError(f"pair indices i, j must be 1-D of equal length, got {i.shape}, {j.shape}")
    if i.size and not (np.issubdtype(i.dtype, np.integer) and np.issubdtype(j.dtype, np.integer)):
        raise ValueError("pair indices i, j must be integer arrays")
    if i.size and (min(i.min(), j.min()) < 0 or max(i.max(), j.max()) >= m):
        raise ValueError(f"pair indices must lie in [0, {m})")
    return i, j


class PairAccumulator:
    """Sums the pair forces, pair potential and close pairs of a pair list, chunk by chunk.

    Feed it chunks ``(i, j, dx, rho2)`` (rows ``i, j`` of the flat ``(M, d)`` arrays,
    ``dx[k] = x_j[k] − x_i[k]``, ``rho2 = Σ_k dx[k]²``; each unordered pair once) with
    :meth:`add`, as :func:`pair_sums` or
    :meth:`swarm_envs.physics.neighbors.CellList.iter_pairs` produce them; read the
    :class:`PairSums` from :meth:`result`. Per pair, ``(s_ij, U(ρ_ij))`` from
    :func:`~swarm_envs.physics.social_potential.pair_law` (``docs/models.md`` §1,
    eqs. 9–11), on the chunk's arrays: ``s_ij r_ij`` is added to row ``i`` and
    subtracted from row ``j`` (antisymmetric; no force between coincident agents, as
    ``1/ρ`` is taken of ``max(ρ, RHO_FLOOR)``); ``U(ρ_ij)`` goes to the group of ``i``.

    Args:
        params: model parameters.
        m: number of rows ``M``.
        v: velocities ``(M, d)`` for the alignment term, or ``None`` to skip it.
        groups: ``(M,)`` group (swarm) of each row in ``[0, n_groups)``; default all 0.
        n_groups: number of groups.
        potential: whether to sum ``U(ρ_ij)``.
        close_radius: count the pairs with ``ρ_ij < close_radius`` (0: none).
        rates: whether to sum each row's ``κ(ρ_ij)`` and ``w(ρ_ij)`` of
            :func:`~swarm_envs.physics.social_potential.rate_law` (both ends of a pair),
            for the step-size rule (:attr:`PairSums.kappa`, :attr:`PairSums.damping`).
    """

    def __init__(
        self,
        params: SocialPotentialParams,
        m: int,
        v: np.ndarray | None = None,
        *,
        groups: np.ndarray | None = None,
        n_groups: int = 1,
        potential: bool = False,
        close_radius: float = 0.0,
        rates: bool = False,
    ) -> None:
        self.params = _check_params("PairAccumulator", params)
        self.m = int(m)
        d = 0 if v is None else v.shape[-1]
        self.vel = (  # v per component, for (v_i − v_j)·r_ij
            None if v is None or params.C_o == 0 else [v[:, k] for k in range(d)]
        )
        self.groups = groups
        self.n_groups = int(n_groups)
        self.potential = bool(potential)
        self.close2 = float(close_radius) ** 2
        self._force: list[np.ndarray] | None = None
        self._pot = np.zeros(self.n_groups)
        self._close = np.zeros(self.n_groups, dtype=np.int64)
        self._kappa = np.zeros(self.m) if rates else None
        self._damping = np.zeros(self.m) if rates else None

    def add(self, i: np.ndarray, j: np.ndarray, dx: list[np.ndarray], rho2: np.ndarray) -> None:
        """Add one chunk of pairs (see the class docstring)."""
        p = self.params
        if self._force is None:
            self._force = [np.zeros(self.m) for _ in dx]
        if i.size == 0:
            return
        groups, n_groups = self.groups, self.n_groups
        if self.close2 > 0:
            hit = rho2 < self.close2
            if groups is None:
                self._close[0] += np.count_nonzero(hit)
            else:
                self._close += np.bincount(groups[i[hit]], minlength=n_groups)
        rho = np.sqrt(rho2)
        inv = np.maximum(rho, RHO_FLOOR)
        np.reciprocal(inv, out=inv)
        vdot = None
        if self.vel is not None:  # (v_i − v_j)·r_ij, not normalised
            vel = self.vel
            vdot = vel[0][i] - vel[0][j]
            vdot *= dx[0]
            for k in range(1, len(dx)):
                t = vel[k][i] - vel[k][j]
                t *= dx[k]
                vdot += t
        scalar, u = pair_law(rho, inv, vdot, p.C_a, p.C_r, p.l_a, p.l_r, p.C_o, p.l_o, np.exp)
        if self.potential:
            if groups is None:
                self._pot[0] += float(u.sum())
            else:
                self._pot += np.bincount(groups[i], weights=u, minlength=n_groups)
        # the pair force on i is scalar · r_ij
        lo = int(min(i.min(), j.min()))
        hi = int(max(i.max(), j.max())) + 1
        il, jl = i - lo, j - lo
        for k, dk in enumerate(dx):
            w = scalar * dk
            out = self._force[k][lo:hi]
            out += np.bincount(il, weights=w, minlength=hi - lo)
            out -= np.bincount(jl, weights=w, minlength=hi - lo)
        if self._kappa is not None and self._damping is not None:
            kappa, damp = rate_law(rho, p.C_a, p.C_r, p.l_a, p.l_r, p.C_o, p.l_o, np.exp)
            for total, rate in ((self._kappa, kappa), (self._damping, damp)):
                if rate is not None:  # symmetric: both ends of the pair
                    out = total[lo:hi]
                    out += np.bincount(il, weights=rate, minlength=hi - lo)
                    out += np.bincount(jl, weights=rate, minlength=hi - lo)

    def result(self, d: int, dtype: Any = np.float64) -> PairSums:
        """The sums so far; ``d`` and ``dtype`` shape the force when no chunk came."""
        force = self._force if self._force is not None else [np.zeros(self.m)] * d
        return PairSums(
            np.stack(force, axis=-1).astype(dtype, copy=False),
            self._pot.copy(),
            self._close.copy(),
            None if self._kappa is None else self._kappa.copy(),
            None if self._damping is None else self._damping.copy(),
        )


def pair_sums(
    x: np.ndarray,
    v: np.ndarray | None,
    params: SocialPotentialParams,
    i: np.ndarray,
    j: np.ndarray,
    *,
    groups: np.ndarray | None = None,
    n_groups: int = 1,
    potential: bool = False,
    close_radius: float = 0.0,
    rates: bool = False,
) -> PairSums:
    """Pair forces, pair potential and close-pair count (and, with ``rates``, the
    step-size rule's rate sums) over a pair list, in one pass.

    ``x, v`` are flat ``(M, d)``; ``(i, j)`` index their rows, each unordered pair once;
    the other arguments are those of :class:`PairAccumulator`. Pairs are processed in
    chunks of :data:`PAIR_CHUNK` (bounded temporaries); the accumulation covers only the
    rows a chunk touches, so pairs listed in cell order run fastest.
    """
    m, d = x.shape
    i, j = _check_pairs(i, j, m)
    acc = PairAccumulator(
        params,
        m,
        v,
        groups=groups,
        n_groups=n_groups,
        potential=potential,
        close_radius=close_radius,
        rates=rates,
    )
    coords = [np.ascontiguousarray(x[:, k]) for k in range(d)]
    for s in range(0, i.size, PAIR_CHUNK):
        ii = i[s : s + PAIR_CHUNK]
        jj = j[s : s + PAIR_CHUNK]
        dx = [c[jj] - c[ii] for c in coords]
        rho2 = dx[0] * dx[0]
        for k in range(1, d):
            rho2 += dx[k] * dx[k]
        acc.add(ii, jj, dx, rho2)
    return acc.result(d, x.dtype)


__all__ = ["PAIR_CHUNK", "PairAccumulator", "PairSums", "pair_sums", "swarm_rates"]
