"""The SwarmNav step as one torch function: the shared definitions on torch tensors.

:func:`build_advance` returns the function :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore`
runs (through ``torch.compile`` where it can, plain otherwise; see
:mod:`swarm_envs._runtime.torch_compile`). It calls the same definitions as the numpy
core, on tensors: the Euler update and the pair law of :mod:`swarm_envs.physics`, and the
statistics, observation and reward of :mod:`swarm_envs.envs.task`. What is torch's own
here is how the k nearest neighbours are found (:func:`nearest_neighbors`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import torch

from swarm_envs._array import torch_namespace
from swarm_envs.envs.task import (
    STAT_KEYS,
    Frame,
    RewardInputs,
    observation,
    ranked_neighbors,
    reward,
    statistics,
)
from swarm_envs.physics import kinetic_energy
from swarm_envs.physics.integrators import euler_update
from swarm_envs.physics.social_potential import goal_terms, pair_geometry, pair_terms

__all__ = ["build_advance", "nearest_neighbors"]


def nearest_neighbors(rho: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``k`` nearest neighbours of every agent from symmetric distances ``(B, N, N)``.

    Returns ``(distance (B, N, k), index (B, N, k) int64)``, nearest first; ties break by
    the lower index (the order ``(ρ_ij, j)``). ``rho`` must be symmetric with ``inf`` on
    the diagonal; agent i's candidates are read down column i (``rho[b, j, i]`` over
    ``j``), so that the reductions run over the second-last axis and a compiler
    vectorises them across agents. Pass ``s`` takes the minimum over the entries after
    pass ``s − 1``'s in that order: ``O(k N²)`` per swarm, cheaper than
    ``torch.topk`` on the CPU for the small k of an observation.

    float32: one reduction per pass over exact int64 keys ``bits(ρ) · 2³² + j`` (for
    ``ρ ≥ 0`` the bit pattern orders as the value). float64: two reductions per pass
    (the minimum, then the smallest index holding it).
    """
    n = rho.shape[-1]
    rows = torch.arange(n, device=rho.device)[:, None]  # j, along the reduced axis
    dists: list[torch.Tensor] = []
    indices: list[torch.Tensor] = []
    if rho.dtype == torch.float32:
        key = (rho.view(torch.int32).to(torch.int64) << 32) | rows
        largest = torch.iinfo(torch.int64).max
        best = key.amin(-2)
        for s in range(k):
            if s > 0:
                best = torch.where(key > best[:, None, :], key, largest).amin(-2)
            dists.append((best >> 32).to(torch.int32).view(torch.float32))
            indices.append(best & 0xFFFFFFFF)
        return _by_rank(dists), _by_rank(indices)
    columns = rows.to(rho.dtype)
    cand = rho
    for s in range(k):
        if s > 0:
            d, i = dists[-1][:, None, :], indices[-1][:, None, :]
            cand = torch.where((rho > d) | ((rho == d) & (columns > i)), rho, math.inf)
        dist = cand.amin(-2)
        dists.append(dist)
        indices.append(torch.where(cand == dist[:, None, :], columns, math.inf).amin(-2))
    return _by_rank(dists), _by_rank(indices).to(torch.int64)


def _by_rank(planes: list[torch.Tensor]) -> torch.Tensor:
    """``(B, N)`` planes as ``(B, N, k)``: stacked as contiguous planes ``(k, B, N)`` and
    seen through a permuted view (a compiler writes planes with vector stores; stacking
    on the last axis would write every element with a stride of k)."""
    return torch.stack(planes, dim=0).permute(1, 2, 0)


def build_advance(cfg: Any) -> Callable[..., tuple[torch.Tensor, ...]]:
    """The fused SwarmNav step for config ``cfg`` (social potential, semi-implicit Euler).

    ``advance(x, v, f, goal, a, move, prev, start)`` with positions, velocities and the
    passive force at ``(x, v)`` stored component first, ``(d, B, N)``, so that every
    per-agent quantity is a contiguous ``(B, N)`` plane (the layout on which a compiler
    vectorises the pair loop); goals ``(B, d)``; actions ``a`` ``(B, N, d)`` clipped to
    [−1, 1]; ``move`` ``(B,)`` bool (false: keep that swarm's state, only measure it);
    ``prev`` and ``start`` ``(B, S)``: the previous step's and the episode start's
    statistics in the order of ``STAT_KEYS``. Returns ``(x', v', f' (d, B, N), obs (B, N,
    obs_dim) float32, stats (B, S), reward (B,), ρ (B, N, N))``; the distances (``inf`` on
    the diagonal) are returned only so that a compiler stores them once (callers drop
    them).

    The step: ``v' = v + dt (f + u_max a)/m``, ``x' = x + dt v'``; then one pass over
    the pairs of ``(x', v')`` gives the passive force carried into the next step and the
    pair energy (:func:`~swarm_envs.physics.social_potential.pair_terms`); the ranked
    neighbours come from the distances; the statistics, observation and reward are the
    shared definitions.
    """
    xp = torch_namespace()
    p = cfg.physics
    N, d = cfg.n_agents, cfg.dim
    k_rank = ranked_neighbors(cfg)
    physics_goal = cfg.goal_in_physics and p.C_g > 0

    def unpack(packed: torch.Tensor) -> dict[str, torch.Tensor]:
        return {key: packed[:, i] for i, key in enumerate(STAT_KEYS)}

    def advance(
        x: torch.Tensor,
        v: torch.Tensor,
        f: torch.Tensor,
        goal: torch.Tensor,
        a: torch.Tensor,
        move: torch.Tensor,
        prev: torch.Tensor,
        start: torch.Tensor,
    ) -> tuple[torch.Tensor, ...]:
        B = x.shape[1]
        keep = move[:, None]
        xs, vs = [], []
        for c in range(d):
            xc, vc = euler_update(x[c], v[c], f[c] + cfg.u_max * a[..., c], cfg.dt, p.m)
            xs.append(torch.where(keep, xc, x[c]))
            vs.append(torch.where(keep, vc, v[c]))

        # The new state stored first, component first (d, B, N), as returned: the pair
        # pass reads it (left to itself, the compiler recomputes the update for every
        # pair inside the pair loop); the shared definitions read (B, N, d) views of it.
        x_new, v_new = torch.stack(xs), torch.stack(vs)
        xs, vs = list(x_new.unbind(0)), list(v_new.unbind(0))
        geo = pair_geometry(xs)
        fs, pairs = pair_terms(geo, vs, p)
        if p.beta > 0:
            fs = [fc - p.beta * vc for fc, vc in zip(fs, vs, strict=True)]
        sink, potential, goal_distance = goal_terms(xs, p, goal)
        if physics_goal:
            fs = [fc + gc for fc, gc in zip(fs, sink, strict=True)]
        xn, vn = x_new.permute(1, 2, 0), v_new.permute(1, 2, 0)
        energy = kinetic_energy(vn, p) + pairs
        if p.C_g > 0:  # the energy statistic includes the sink whenever it exists
            energy = energy + potential.sum(-1)

        agents = torch.arange(N, device=x.device)
        rho = torch.where(agents[:, None] == agents[None, :], math.inf, geo.rho)
        close = torch.floor((rho < cfg.collision_radius).to(x.dtype).sum(-2).sum(-1) * 0.5)
        if N > 1:
            near_dist, near = nearest_neighbors(rho, k_rank)
            nearest = near_dist[..., 0]
        else:
            near, nearest = None, torch.zeros(B, 1, dtype=x.dtype, device=x.device)

        frame = Frame(xn, vn, goal, goal_distance, nearest, close, energy)
        stats = statistics(frame, cfg, xp)
        packed = torch.stack([xp.astype(stats[key], x) for key in STAT_KEYS], dim=-1)
        obs = observation(xn, vn, goal, near, cfg, xp)
        effort = (a * a).sum((-2, -1))
        inputs = RewardInputs(stats, unpack(prev), unpack(start), effort, N, xp)
        r = reward(cfg.reward, inputs) + torch.zeros(B, dtype=x.dtype, device=x.device)
        # rho is returned (and dropped by the caller) so that the compiler stores it once,
        # in the pair loop, instead of recomputing it in every pass of the ranking.
        return x_new, v_new, torch.stack(fs), obs, packed, r, rho

    return advance
