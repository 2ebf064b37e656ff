"""The SwarmNav step as one torch function: the shared definitions on torch tensors.

:func:`build_advance` returns the function
:class:`~swarm_envs.envs.cores.torch.core.TorchSwarmNavCore` runs (through ``torch.compile``
where it can, plain otherwise; see
:mod:`swarm_envs._runtime.torch_compile`). It calls the same definitions as the numpy
core, on tensors: the Euler update and the pair law of :mod:`swarm_envs.physics`, and the
statistics, observation and reward of :mod:`swarm_envs.envs.task`. What is torch's own
here is how the k nearest neighbours are found (:func:`nearest_neighbors`).

Step-size control (:mod:`swarm_envs.physics.integrators`): the fused step also computes
the stable substep ``h*`` of the new state (the rates of
:func:`~swarm_envs.physics.social_potential.pair_rates`, in the same pair loop as the
force) and returns it in its packed row after the statistics (:data:`PACKED_KEYS`). A
step whose swarms all fit in one substep is that one fused call; otherwise
:func:`build_substep` takes the substeps but the last, each swarm its own count
(:func:`plan_substep`), and the fused function takes each swarm's last one and measures
the result.

Agent statuses (:mod:`~swarm_envs.envs.task.agent_status`): both functions take an
optional last argument, each agent's status ``(B, N)``, passed when the config needs
statuses (``perturbations.needs_masks`` or ``observe_status``). With it, a pair with an
agent not present is at infinite distance
(:func:`~swarm_envs.physics.social_potential.present_geometry`: no force, rate, energy,
collision or neighbour), the total force of an agent that does not move is zero, the
sink's potential counts the present agents, the statistics count the members (the
mobile agents) and the observation shows the statuses; the physics masks apply where
``perturbations.needs_masks``, as in the numpy core. Without it the functions are those
of a config without statuses, operation for operation.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import torch

from swarm_envs._array import torch_namespace
from swarm_envs.envs.common import FINITE_KEYS
from swarm_envs.envs.task import (
    STAT_KEYS,
    Frame,
    RewardInputs,
    observation,
    ranked_neighbors,
    reward,
    statistics,
)
from swarm_envs.envs.task.agent_status import masks
from swarm_envs.physics import kinetic_energy
from swarm_envs.physics.integrators import (
    euler_update,
    implicit_damping_update,
    stable_substep,
    substep_plan,
)
from swarm_envs.physics.social_potential import (
    PairGeometry,
    damping_rates,
    goal_terms,
    pair_geometry,
    pair_rates,
    pair_terms,
    passive_components,
    present_geometry,
    stiffness_rate,
)

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

__all__ = ["PACKED_KEYS", "build_advance", "build_substep", "nearest_neighbors", "plan_substep"]

#: The columns of the fused step's packed row per swarm: the statistics (``STAT_KEYS``),
#: the stable substep ``h*`` of the state (``"h_stable"``), ``h*`` where the state is
#: finite (:data:`~swarm_envs.envs.common.FINITE_KEYS`), NaN where not (``"h_guard"``),
#: and 1 in every row where ``h_guard ≥ dt`` for every swarm of the batch (``"calm"``):
#: that says at once that the next step takes one substep each and that this one went
#: stable, the host's only check in the common case.
PACKED_KEYS = (*STAT_KEYS, "h_stable", "h_guard", "calm")


def nearest_neighbors(
    rho: torch.Tensor, k: int, strict: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
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
    (the minimum, then the smallest index holding it); ``strict`` orders the agents at
    infinite distance (pairs masked out by statuses) by index too, as the keys do:
    without it a pass past the last finite distance repeats the lowest index, which
    no caller reads while every pair is finite and ``k ≤ N − 1``.
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
    later: torch.Tensor | None = None  # (strict) the entries after the last pass's
    for s in range(k):
        if s > 0:
            d, i = dists[-1][:, None, :], indices[-1][:, None, :]
            later = (rho > d) | ((rho == d) & (columns > i))
            cand = torch.where(later, rho, math.inf)
        dist = cand.amin(-2)
        dists.append(dist)
        holds = cand == dist[:, None, :]
        if strict and later is not None:
            holds = holds & later
        # A NaN distance (a state that diverged within the step) holds no entry: clamp,
        # so that the index stays valid and the unstable guard, not a gather, reports it.
        indices.append(torch.where(holds, columns, math.inf).amin(-2).clamp(max=n - 1))
    return _by_rank(dists), _by_rank(indices).to(torch.int64)


def _by_rank(planes: list[torch.Tensor]) -> torch.Tensor:
    """``(B, N)`` planes as ``(B, N, k)``: stacked as contiguous planes ``(k, B, N)`` and
    seen through a permuted view (a compiler writes planes with vector stores; stacking
    on the last axis would write every element with a stride of k)."""
    return torch.stack(planes, dim=0).permute(1, 2, 0)


def _passive(
    geo: PairGeometry,
    xs: list[torch.Tensor],
    vs: list[torch.Tensor],
    goal: torch.Tensor,
    cfg: SwarmConfig,
    energy: bool,
) -> tuple[list[torch.Tensor], torch.Tensor | None, torch.Tensor, torch.Tensor]:
    """The passive force at ``(x, v)`` per component, the pair energy (``None`` without
    ``energy``), and the goal sink's potential and distances per agent
    (:func:`~swarm_envs.physics.social_potential.goal_terms`), for the numpy core's
    semi-implicit Euler force."""
    p = cfg.physics
    pair_forces, pairs = pair_terms(geo, vs, p, energy=energy)
    sink, potential, goal_distance = goal_terms(xs, p, goal)
    fs = passive_components(pair_forces, vs, p, sink if cfg.passive_sink else None)
    return fs, pairs, potential, goal_distance


def _stable(
    geo: PairGeometry, vs: list[torch.Tensor], cfg: SwarmConfig
) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """The stable substep ``h*`` ``(B,)`` of the state of ``geo`` with the velocities
    ``vs`` (the shared rule) and what the state carries beside its force: for
    ``"implicit_damping_euler"`` the agents' implicit damping ``b_i, w_i`` ``(B, N)``
    each (:func:`~swarm_envs.physics.social_potential.damping_rates`), nothing
    otherwise."""
    p = cfg.physics
    if cfg.integrator == "implicit_damping_euler":
        omega2 = stiffness_rate(geo, p, sink=cfg.passive_sink)
        h = stable_substep(omega2, 0.0 * omega2, torch, integrator=cfg.integrator)
        return h, list(damping_rates(geo, vs, p))
    omega2, gamma = pair_rates(geo, p, sink=cfg.passive_sink, v=vs)
    return stable_substep(omega2, gamma, torch), []


def _update(
    x: torch.Tensor,
    v: torch.Tensor,
    f: torch.Tensor,
    a: torch.Tensor,
    step: torch.Tensor,
    keep: torch.Tensor,
    mobile: torch.Tensor | None,
    cfg: SwarmConfig,
) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """The integrator's update of every component with the carried passive force ``f``
    (``(d, B, N)``; with ``"implicit_damping_euler"`` its rows ``d, d + 1`` are the
    implicit damping ``b_i, w_i``) and the control ``u_max a``, the swarms where ``keep``
    is false left as they are: the new ``(x, v)`` as lists of components. The implicit
    damping updates the components together (one sum over the agents for all of them;
    TorchInductor's vectorised CPU code summed them wrongly per component)."""
    d, m = cfg.dim, cfg.physics.m
    if cfg.integrator == "implicit_damping_euler":
        total = _held(f[:d] + cfg.u_max * a.permute(2, 0, 1), mobile)
        align = _held(f[d + 1], mobile)
        xn, vn = implicit_damping_update(x, v, total, step, m, f[d], align, -1)
        xn, vn = torch.where(keep, xn, x), torch.where(keep, vn, v)
        return list(xn.unbind(0)), list(vn.unbind(0))
    xs, vs = [], []
    for c in range(d):
        xc, vc = euler_update(x[c], v[c], _held(f[c] + cfg.u_max * a[..., c], mobile), step, m)
        xs.append(torch.where(keep, xc, x[c]))
        vs.append(torch.where(keep, vc, v[c]))
    return xs, vs


def _masks(
    status: torch.Tensor | None, physics: bool
) -> tuple[torch.Tensor | None, torch.Tensor | None, torch.Tensor | None]:
    """``(members, present, mobile)`` ``(B, N)`` of ``status`` (each ``None`` without
    statuses; ``present`` and ``mobile`` also without ``physics`` masks)."""
    if status is None:
        return None, None, None
    mask = masks(status)
    if not physics:
        return mask.mobile, None, None
    return mask.mobile, mask.present, mask.mobile


def _held(total: torch.Tensor, mobile: torch.Tensor | None) -> torch.Tensor:
    """The total force on each agent, zero on those that do not move (``mobile``
    ``None``: every agent moves)."""
    return total if mobile is None else torch.where(mobile, total, 0.0)


def build_advance(cfg: SwarmConfig) -> Callable[..., tuple[torch.Tensor, ...]]:
    """The fused SwarmNav step for config ``cfg`` (social potential, semi-implicit Euler).

    ``advance(x, v, f, goal, a, h, substeps, prev, start[, status])`` with positions, velocities
    and the passive force at ``(x, v)`` stored component first, ``(d, B, N)``, so that
    every per-agent quantity is a contiguous ``(B, N)`` plane (the layout on which a
    compiler vectorises the pair loop); goals ``(B, d)``; actions ``a`` ``(B, N, d)``
    clipped to [−1, 1]; ``h`` ``(B,)``: each swarm's (last) substep, ``dt`` when it takes
    the step in one, 0 to keep its state and only measure it; ``substeps`` ``(B,)``: the
    ``substeps`` statistic to report (the step's count, 0 after a reset); ``prev`` and
    ``start`` ``(B, P)``: the previous step's and the episode start's packed rows
    (:data:`PACKED_KEYS`); ``status`` ``(B, N)`` int8, each agent's status (module
    docstring; ``None``: none). Returns ``(x', v', f' (d, B, N), obs (B, N, obs_dim) float32,
    packed (B, P), reward (B,), ρ (B, N, N))``; the distances (``inf`` on the diagonal)
    are returned only so that a compiler stores them once (callers drop them).

    The (last) substep: ``v' = v + h (f + u_max a)/m``, ``x' = x + h v'``; then one pass
    over the pairs of ``(x', v')`` gives the passive force carried into the next step,
    the pair energy (:func:`~swarm_envs.physics.social_potential.pair_terms`) and the
    rates of the stable substep ``h*``
    (:func:`~swarm_envs.physics.social_potential.pair_rates`); the ranked neighbours come
    from the distances; the statistics, observation and reward are the shared
    definitions.
    """
    xp = torch_namespace()
    p = cfg.physics
    N = cfg.n_agents
    k_rank = ranked_neighbors(cfg)
    physics_masks = cfg.perturbations.needs_masks

    def unpack(packed: torch.Tensor) -> dict[str, torch.Tensor]:
        return {key: packed[:, i] for i, key in enumerate(STAT_KEYS)}

    def advance(
        x: torch.Tensor,
        v: torch.Tensor,
        f: torch.Tensor,
        goal: torch.Tensor,
        a: torch.Tensor,
        h: torch.Tensor,
        substeps: torch.Tensor,
        prev: torch.Tensor,
        start: torch.Tensor,
        status: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, ...]:
        B = x.shape[1]
        members, present, mobile = _masks(status, physics_masks)
        keep, step = (h > 0)[:, None], h[:, None]
        xs, vs = _update(x, v, f, a, step, keep, mobile, cfg)

        # The new state stored first, component first (d, B, N), as returned: the pair
        # pass reads it (left to itself, the compiler recomputes the update for every
        # pair inside the pair loop); the shared definitions read (B, N, d) views of it.
        x_new, v_new = torch.stack(xs), torch.stack(vs)
        xs, vs = list(x_new.unbind(0)), list(v_new.unbind(0))
        geo = present_geometry(pair_geometry(xs), present)
        fs, pairs, potential, goal_distance = _passive(geo, xs, vs, goal, cfg, energy=True)
        h_stable, carried = _stable(geo, vs, cfg)
        xn, vn = x_new.permute(1, 2, 0), v_new.permute(1, 2, 0)
        energy = kinetic_energy(vn, p) + pairs
        if p.C_g > 0:  # the energy statistic includes the sink whenever it exists
            if present is not None:  # over the agents present
                potential = torch.where(present, potential, 0.0)
            energy = energy + potential.sum(-1)

        agents = torch.arange(N, device=x.device)
        rho = torch.where(agents[:, None] == agents[None, :], math.inf, geo.rho)
        close_pairs = rho < cfg.collision_radius
        if members is not None:  # a pair of agents at rest does not collide
            close_pairs = close_pairs & (members[..., :, None] | members[..., None, :])
        close = torch.floor(close_pairs.to(x.dtype).sum(-2).sum(-1) * 0.5)
        if N > 1:
            near_dist, near = nearest_neighbors(rho, k_rank, strict=status is not None)
            nearest = near_dist[..., 0]
            if present is not None:  # an agent alone in the physics: 0
                nearest = torch.where(torch.isfinite(nearest), nearest, 0.0)
        else:
            near, nearest = None, torch.zeros(B, 1, dtype=x.dtype, device=x.device)

        frame = Frame(xn, vn, goal, goal_distance, nearest, close, energy, substeps, members)
        stats = statistics(frame, cfg, xp)
        columns = [xp.astype(stats[key], x) for key in STAT_KEYS]
        finite = torch.isfinite(columns[STAT_KEYS.index(FINITE_KEYS[0])])
        for key in FINITE_KEYS[1:]:
            finite = finite & torch.isfinite(columns[STAT_KEYS.index(key)])
        guard = torch.where(finite, h_stable, math.nan)
        calm = (guard.to(torch.float64) >= cfg.dt).all().to(x.dtype).expand(B)
        packed = torch.stack([*columns, h_stable, guard, calm], dim=-1)
        obs = observation(xn, vn, goal, near, cfg, xp, status)
        effort = (a * a).sum((-2, -1))
        inputs = RewardInputs(stats, unpack(prev), unpack(start), effort, N, xp)
        r = reward(cfg.reward, inputs) + torch.zeros(B, dtype=x.dtype, device=x.device)
        # rho is returned (and dropped by the caller) so that the compiler stores it once,
        # in the pair loop, instead of recomputing it in every pass of the ranking.
        return x_new, v_new, torch.stack(fs + carried), obs, packed, r, rho

    return advance


def plan_substep(
    remaining: Any, h_stable: Any, used: Any, cap: float, xp: Any
) -> tuple[Any, Any, Any, Any]:
    """The next substep of each swarm, as the numpy core plans it: ``(h, last, late,
    wanted)`` per swarm from the time left of the step, the stable substep ``h*`` of the
    state and the substeps taken (float64 arrays or tensors; ``xp``: ``np`` or ``torch``).

    ``n, h`` from :func:`~swarm_envs.physics.integrators.substep_plan`; ``late`` where
    ``n`` exceeds the substeps left under ``cap``: then ``h`` spreads the time left over
    those (and the swarm is marked over the cap); ``last`` where that substep ends the
    step (``n ≤ 1``; ``True`` too where no time is left, ``h = 0``); ``wanted = used +
    n``, the substeps the swarm needs at least.

    >>> import numpy as np
    >>> h, last, late, wanted = plan_substep(
    ...     np.array([0.1, 0.1, 0.0]), np.array([0.2, 0.03, 1.0]), np.zeros(3), 3.0, np
    ... )
    >>> [round(float(t), 4) for t in h], last.tolist(), late.tolist(), wanted.tolist()
    ([0.1, 0.0333, 0.0], [True, False, True], [False, True, False], [1.0, 4.0, 0.0])
    """
    n, h = substep_plan(remaining, h_stable, xp)
    left = cap - used
    late = n > left
    spread = xp.where(left > 1.0, left, 1.0)
    h = xp.where(late, remaining / spread, h)
    last = xp.where(late, spread, n) <= 1.0
    return h, last, late, used + n


def build_substep(cfg: SwarmConfig) -> Callable[..., tuple[Any, ...]]:
    """One substep of the step-size control for every swarm with time left, batched.

    ``substep(x, v, f, goal, a, h_stable, remaining, used, over, needed[, status])``: the state
    and force as in :func:`build_advance` (``(d, B, N)``), goals, actions; then per
    swarm, ``(B,)``: the stable substep ``h*`` of the state (its dtype), the time left of
    the step, the substeps taken, whether it needed more than ``cfg.max_substeps``
    (bool) and how many it needed at least (float64). Each swarm with time left plans
    its substep (:func:`plan_substep`) and takes it, an Euler substep with the passive
    force ``f`` and the control; the force and ``h*`` of the new state are computed (for
    every swarm: one without time left keeps its state). ``status``: each agent's
    status, as in :func:`build_advance`.

    Returns ``(x', v', f', h*', remaining, used, over, needed, more, last)``: the same
    advanced; ``more``, a 0-d bool, whether a swarm's next substep is not its last; and
    ``last``, each swarm's next substep planned for the fused step
    (:func:`build_advance`'s ``h`` and ``substeps``, in the state's dtype) with
    the step's counts for the host ``stack([over, needed])`` once it is taken. No
    statistics, no observations: the numpy core's
    :meth:`~swarm_envs.envs.dynamics.SocialPotentialDynamics.step`, one substep per call.
    """
    cap = float(cfg.max_substeps)
    physics_masks = cfg.perturbations.needs_masks

    def substep(
        x: torch.Tensor,
        v: torch.Tensor,
        f: torch.Tensor,
        goal: torch.Tensor,
        a: torch.Tensor,
        h_stable: torch.Tensor,
        remaining: torch.Tensor,
        used: torch.Tensor,
        over: torch.Tensor,
        needed: torch.Tensor,
        status: torch.Tensor | None = None,
    ) -> tuple[Any, ...]:
        _, present, mobile = _masks(status, physics_masks)
        wide = remaining.dtype
        h, last, late, wanted = plan_substep(remaining, h_stable.to(wide), used, cap, torch)
        over, needed = over | late, torch.maximum(needed, wanted)
        active = remaining > 0
        keep, step = active[:, None], h.to(x.dtype)[:, None]
        xs, vs = _update(x, v, f, a, step, keep, mobile, cfg)
        used = used + active.to(wide)
        remaining = torch.where(active & ~last, remaining - h, 0.0)
        x_new, v_new = torch.stack(xs), torch.stack(vs)
        xs, vs = list(x_new.unbind(0)), list(v_new.unbind(0))
        geo = present_geometry(pair_geometry(xs), present)
        fs, _, _, _ = _passive(geo, xs, vs, goal, cfg, energy=False)
        h_new, carried = _stable(geo, vs, cfg)
        # The next substep, planned as the next call would plan it: for the fused step
        # when it is every swarm's last.
        h, last, late, wanted = plan_substep(remaining, h_new.to(wide), used, cap, torch)
        left = remaining > 0
        more = (left & ~last).any()
        counts = torch.stack([(over | late).to(wide), torch.maximum(needed, wanted)])
        final = (torch.where(left, h, 0.0).to(x.dtype), (used + left.to(wide)).to(x.dtype), counts)
        f_new = torch.stack(fs + carried)
        return x_new, v_new, f_new, h_new, remaining, used, over, needed, more, final

    return substep
