"""The batched SwarmNav core in PyTorch: one fused (compiled) function per step, CPU or CUDA.

:class:`TorchSwarmNavCore` has exactly the public interface and semantics of
:class:`~swarm_envs.envs.core.SwarmNavCore` (``reset``, ``step``, ``observe``, ``stats``;
``x, v, goal, t, batch, obs_dim, cfg``; numpy in, numpy out) for the social potential
model with the semi-implicit Euler integrator, the core's defaults. The same seed and
actions give the same starts, and the same observations, rewards and statistics to
floating-point tolerance (tested against the numpy core over dozens of steps).

On the CPU the step runs by default in C, through :mod:`swarm_envs.envs.native_step`
(the same equations, about 2.5 times as fast as the compiled function at 1,024 × 32 and
built once per machine instead of compiled per batch size; ``native=``). Elsewhere, or
where no C compiler builds it, what runs is one torch function :func:`build_advance`
(compiled by ``torch.compile`` into a handful of fused loops, or run plainly):

1. the Euler step (MODELS.md §1, :func:`swarm_envs.physics.torch_backend.step`)
   ``v' = v + dt (F(x, v) + u)/m``, ``x' = x + dt v'`` with ``u = u_max · a``;
2. one loop over the pairs of the new positions computes the passive force
   ``F(x', v')`` (eqs. 10–12, 20; it is carried into the next step, so each step
   evaluates the pairs once, not twice), the pair energy (eq. 9, summed into φ of
   eq. 16) and stores the distances ``ρ_ij``;
3. from the stored distances: the collision count and the k nearest neighbours
   (:func:`_nearest`, ``k`` minimum passes; ``torch.topk`` on the CPU costs more than
   the whole fused step), which give the observations and the nearest-neighbour
   statistic;
4. the statistics of :data:`~swarm_envs.envs.core.STAT_KEYS` and the reward.

Layout: positions, velocities and forces live component first, ``(d, B, N)``, so that
every per-agent quantity is a contiguous ``(B, N)`` plane; the ``x``/``v`` properties
give the usual ``(B, N, d)``.

The carried force is the force the numpy core computes at the start of the next step
from the same state, so the trajectories agree. A reset (or assigning ``x``, ``v`` or
``goal``) re-evaluates the same function with the integration switched off, so the
observations, statistics and carried force always describe the current state. A reset
of a few swarms (at most :attr:`TorchSwarmNavCore.reset_batch`, 1/16 of a batch of 64
or more) evaluates them alone, through the same function compiled for that sub-batch:
in a VecEnv some swarm ends on most steps, and re-measuring all B swarms each time
would cost a second full step. The C step re-measures any proper subset of the swarms
alone, in place (:meth:`~swarm_envs.envs.native_step.NativeAdvance.measure_rows`).

Compile time: the constructor makes the first (compiling) call, on the all-zero state,
and stores its wall time in :attr:`TorchSwarmNavCore.compile_seconds` (also logged once
at INFO level); steps never compile. ``compile="auto"`` compiles where
:func:`~swarm_envs.physics.torch_backend.compile_support` allows and falls back to plain
torch otherwise; the environment variable ``SWARM_ENVS_TORCH_COMPILE=0`` forces plain.
Shapes are static: the function is compiled for this core's ``(batch, N, d)``.

Host and device: actions arrive as numpy (or as a torch tensor, kept on the device),
state stays on ``device``; per step one ``(B, 11)`` array of statistics and rewards
comes back, and the observations when :meth:`TorchSwarmNavCore.observe` asks (on the
CPU without copying; from a GPU into page-locked memory). The starts are drawn on the
host with the numpy generator, as the numpy core draws them, then moved to the device.
On a GPU the compiled step is captured once as a CUDA graph
(:class:`~swarm_envs.physics.torch_backend.CudaGraphed`) and replayed each step: one
launch instead of one per kernel, which at small batches is most of the step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from swarm_envs._malloc import keep_freed_memory
from swarm_envs.envs.core import (
    NON_FINITE_ACTIONS,
    OBS_BOUND,
    STAT_KEYS,
    check_action_shape,
    check_actions,
    check_batch,
    draw_starts,
    observation_size,
    require_social_potential,
    success_count,
)
from swarm_envs.envs.native_step import NativeAdvance, resolve_native
from swarm_envs.metrics import CENTRE_RTOL
from swarm_envs.physics import SocialPotentialParams
from swarm_envs.physics import torch_backend as tb

__all__ = ["PARTIAL_RESET_MIN_BATCH", "TorchSwarmNavCore", "build_advance", "partial_reset_batch"]

#: Columns of the packed per-swarm result: the statistics, then the reward.
_PACKED = (*STAT_KEYS, "reward")
#: Statistics the numpy core returns in float64 whatever its dtype (bool means, counts).
_FLOAT64_STATS = ("fraction_arrived", "collisions", "success")


#: The smallest batch whose resets of a few swarms measure only those (see
#: :func:`partial_reset_batch`); smaller batches re-measure every swarm on a reset.
PARTIAL_RESET_MIN_BATCH = 64


def partial_reset_batch(batch: int) -> int | None:
    """Sub-batch size ``R = batch // 16`` for resets of at most R swarms, or ``None``.

    With ``batch ≥ PARTIAL_RESET_MIN_BATCH`` a reset of at most ``R`` swarms runs the
    fused function on those swarms only (padded to R): 1/16 of a step. Below that size,
    or for larger resets, every swarm is measured, which costs a whole step.
    """
    return batch // 16 if batch >= PARTIAL_RESET_MIN_BATCH else None


def _nearest(rho: torch.Tensor, k: int) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """The ``k`` nearest neighbours of every agent from symmetric distances ``(B, N, N)``.

    Returns ``([distance (B, N)] * k, [index (B, N) int64] * k)``, nearest first; ties
    break by the lower index (the order ``(ρ_ij, j)``). ``rho`` must be symmetric with
    ``inf`` on the diagonal; agent i's candidates are read down column i (``rho[b, j, i]``
    over ``j``), so that the reductions run over the second-last axis and a compiler
    vectorises them across agents (rows of 32 reduced along themselves spend most of
    their time in horizontal reductions). Pass ``s`` takes the minimum over the entries
    after pass ``s − 1``'s in that order: ``O(k N²)`` per swarm. ``torch.topk`` costs
    about 0.5 µs per row of 32 on the CPU (15 ms at 1024 × 32, several times the whole
    fused step; measured on the development machine).

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
        return dists, indices
    columns = rows.to(rho.dtype)
    cand = rho
    for s in range(k):
        if s > 0:
            d, i = dists[-1][:, None, :], indices[-1][:, None, :]
            cand = torch.where((rho > d) | ((rho == d) & (columns > i)), rho, math.inf)
        dist = cand.amin(-2)
        dists.append(dist)
        indices.append(torch.where(cand == dist[:, None, :], columns, math.inf).amin(-2))
    return dists, [i.to(torch.int64) for i in indices]


def _sum_sq(parts: list[torch.Tensor]) -> torch.Tensor:
    """``Σ_k parts[k]²`` (the squared norm of a vector given by its components)."""
    total = parts[0] * parts[0]
    for part in parts[1:]:
        total = total + part * part
    return total


def build_advance(cfg: Any) -> Callable[..., tuple[torch.Tensor, ...]]:
    """The fused step of a :class:`TorchSwarmNavCore` for config ``cfg`` (plain torch).

    ``advance(x, v, f, goal, a, move, prev_distance, prev_arrived, start_distance)``
    with positions, velocities and the passive force at ``(x, v)`` stored component
    first, ``(d, B, N)``; ``goal`` ``(B, d)``; actions ``a`` ``(B, N, d)`` clipped to
    [−1, 1]; ``move`` ``(B,)`` bool (false: keep that swarm's state, only measure it);
    and the reward's running ``(B,)`` tensors. Returns ``(x', v', f' (d, B, N),
    obs (B, N, obs_dim) float32, packed (B, 11), mean goal distance (B,), arrived
    fraction (B,), ρ (B, N, N))``; ``packed`` holds :data:`STAT_KEYS` then the reward;
    the distances ``ρ`` (``inf`` on the diagonal) are returned only so that the compiler
    stores them once (callers drop them).

    Reward (the numpy core's): ``progress · (d_prev − d)/d_0 + arrival · (f − f_prev)
    + success · [success] − collision · pairs/N − effort · Σ|a_i|²/N − time``, with
    ``d`` the mean agent-to-goal distance and ``f`` the fraction within ``goal_radius``.

    Everything is written per component over ``(B, N)`` and ``(B, N, N)`` tensors, the
    shapes on which TorchInductor fuses the pair loop (forces, pair energy, distances)
    and vectorises it.
    """
    p: SocialPotentialParams = cfg.physics
    N, d, k = cfg.n_agents, cfg.dim, cfg.n_neighbors
    k_real = min(k, N - 1)  # observed neighbours; the rest of the k slots are padding
    k_sort = min(max(k, 1), N - 1)  # neighbours ranked (≥ 1 for the NND statistic)
    dt, m, u_max = cfg.dt, p.m, cfg.u_max
    physics_goal = cfg.goal_in_physics and p.C_g > 0
    need = success_count(N, cfg.success_fraction)
    w = cfg.reward
    goal_radius, collision_radius = cfg.goal_radius, cfg.collision_radius
    goal_scale, vel_scale = cfg.obs_goal_scale, cfg.obs_velocity_scale
    inv_nbr_scale, inv_vel_scale = 1.0 / cfg.obs_neighbor_scale, 1.0 / vel_scale

    def advance(
        x: torch.Tensor,
        v: torch.Tensor,
        f: torch.Tensor,
        goal: torch.Tensor,
        a: torch.Tensor,
        move: torch.Tensor,
        prev_distance: torch.Tensor,
        prev_arrived: torch.Tensor,
        start_distance: torch.Tensor,
    ) -> tuple[torch.Tensor, ...]:
        B = x.shape[1]
        dtype, device = x.dtype, x.device
        # 1. Semi-implicit Euler with the carried passive force (integrators.step):
        #    v' = v + dt (F + u)/m, x' = x + dt v'.
        keep = move[:, None]
        xs, vs = [], []
        for c in range(d):
            accel = f[c] + u_max * a[..., c]
            if m != 1.0:
                accel = accel / m
            vc = v[c] + dt * accel
            xc = x[c] + dt * vc
            xs.append(torch.where(keep, xc, x[c]))
            vs.append(torch.where(keep, vc, v[c]))

        # 2. One pass over the pairs of the new state: F(x', v') (eqs. 10–12), pair
        #    energy (eq. 9), then distances with inf on the diagonal.
        geo = tb.pair_geometry(xs)
        fs, _ = tb.pair_force(geo, vs, p)
        if p.beta > 0:
            fs = [fc - p.beta * vc for fc, vc in zip(fs, vs, strict=True)]
        offset = [goal[:, c, None] - xs[c] for c in range(d)]  # r_g − r_i
        goal_dist = torch.sqrt(_sum_sq(offset))  # (B, N)
        if physics_goal:  # tb.goal_force, per component
            scale = (p.C_g / p.l_g) * torch.exp(-goal_dist / p.l_g)
            scale = scale / torch.clamp(goal_dist, min=tb.RHO_FLOOR)
            fs = [fc + oc * scale for fc, oc in zip(fs, offset, strict=True)]
        phi = 0.5 * m * _sum_sq(vs).sum(-1) + tb.pair_energy(geo.rho, p)  # fused, see there
        if p.C_g > 0:  # the energy statistic includes the sink whenever it exists
            phi = phi + (-p.C_g * torch.exp(-goal_dist / p.l_g)).sum(-1)
        agents = torch.arange(N, device=device)
        rho = torch.where(agents[:, None] == agents[None, :], math.inf, geo.rho)
        pairs = (rho < collision_radius).to(dtype).sum(-2).sum(-1)
        collisions = torch.floor(pairs * 0.5)

        # 3. Observations: goal offset, own velocity, k nearest (offset, velocity, mask).
        parts = [oc / goal_scale for oc in offset] + [vc / vel_scale for vc in vs]
        if N > 1:
            near_dist, near = _nearest(rho, k_sort)
            nnd = near_dist[0].mean(-1)
        else:
            nnd = torch.zeros(B, dtype=dtype, device=device)
        rows = torch.arange(B, device=device)[:, None]
        zeros = torch.zeros(B, N, dtype=dtype, device=device)
        ones = torch.ones(B, N, dtype=dtype, device=device)
        for s in range(k):
            if s < k_real:
                j = near[s]  # gathers: indices from _nearest are always in [0, N)
                parts += [(xc[rows, j] - xc) * inv_nbr_scale for xc in xs]
                parts += [(vc[rows, j] - vc) * inv_vel_scale for vc in vs]
                parts.append(ones)
            else:
                parts += [zeros] * (2 * d + 1)
        # Built as contiguous planes (obs_dim, B, N), then transposed in one tiled copy:
        # stacking on the last axis would write each plane with a stride of obs_dim.
        planes = torch.stack(parts, dim=0).clamp(-OBS_BOUND, OBS_BOUND).to(torch.float32)
        obs = planes.permute(1, 2, 0).contiguous()

        # Statistics (swarm_envs.metrics, MODELS.md §2), per component.
        speed = torch.sqrt(_sum_sq(vs))
        safe_speed = torch.where(speed > 0, speed, math.inf)
        heading = [vc / safe_speed for vc in vs]  # unit headings, 0 for agents at rest
        polarization = torch.clamp(torch.sqrt(_sum_sq([h.sum(-1) for h in heading])) / N, max=1.0)
        centre = [xc.mean(-1) for xc in xs]  # (B,) each
        rel = [xc - cc[:, None] for xc, cc in zip(xs, centre, strict=True)]
        radius = torch.sqrt(_sum_sq(rel))
        scale = torch.stack([xc.abs().amax(-1) for xc in xs], dim=-1).amax(-1)[:, None]
        tol = CENTRE_RTOL * torch.finfo(dtype).eps * math.sqrt(N) * scale
        safe_radius = torch.where(radius > tol, radius, math.inf)
        radial = [rc / safe_radius for rc in rel]  # r̂_ic, 0 at the centre
        if d == 2:
            turn = (radial[0] * heading[1] - radial[1] * heading[0]).sum(-1).abs()
        else:
            cross = [
                (radial[1] * heading[2] - radial[2] * heading[1]).sum(-1),
                (radial[2] * heading[0] - radial[0] * heading[2]).sum(-1),
                (radial[0] * heading[1] - radial[1] * heading[0]).sum(-1),
            ]
            turn = torch.sqrt(_sum_sq(cross))
        angular = torch.clamp(turn / N, max=1.0)
        expanse = radius.mean(-1)
        centroid_distance = torch.sqrt(_sum_sq([cc - goal[:, c] for c, cc in enumerate(centre)]))
        arrived_count = (goal_dist <= goal_radius).to(dtype).sum(-1)
        arrived = arrived_count / N
        success = (arrived_count >= need).to(dtype)
        mean_goal_distance = goal_dist.mean(-1)

        effort = (a * a).sum((-2, -1))
        reward = (
            w.progress * (prev_distance - mean_goal_distance) / start_distance
            + w.arrival * (arrived - prev_arrived)
            + w.success * success
            - w.collision * collisions / N
            - w.effort * effort / N
            - w.time
        )
        packed = torch.stack(
            [
                polarization,
                angular,
                expanse,
                nnd,
                phi,
                arrived,
                collisions,
                centroid_distance,
                mean_goal_distance,
                success,
                reward,
            ],
            dim=-1,
        )
        x_new, v_new, f_new = torch.stack(xs), torch.stack(vs), torch.stack(fs)
        # rho is returned (and dropped) so that the compiler stores it once in the pair
        # loop instead of recomputing it in every pass of _nearest.
        return x_new, v_new, f_new, obs, packed, mean_goal_distance, arrived, rho

    return advance


def _torch_dtype(dtype: Any) -> tuple[np.dtype, torch.dtype]:
    try:
        np_dtype = np.dtype(dtype)
    except TypeError:
        np_dtype = None
    if np_dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype must be float32 or float64, got {dtype!r}")
    return np_dtype, (torch.float32 if np_dtype == np.float32 else torch.float64)


def _device(device: Any) -> torch.device:
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError) as err:
        raise ValueError(
            f"device must be a torch device such as 'cpu' or 'cuda', got {device!r}"
        ) from err
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} requested but torch.cuda.is_available() is False")
    return dev


class TorchSwarmNavCore:
    """State and dynamics of ``batch`` independent SwarmNav swarms, in torch.

    A drop-in for :class:`~swarm_envs.envs.core.SwarmNavCore` (same methods, same
    numpy results) for ``cfg.dynamics == "social_potential"`` with
    ``cfg.integrator == "semi_implicit_euler"``; any other config raises
    :class:`ValueError`.

    Args:
        cfg: the scenario (:class:`~swarm_envs.config.SwarmConfig`).
        batch: number of swarms ``B ≥ 1``.
        dtype: ``np.float32`` (default) or ``np.float64``, the state's precision.
        device: a torch device, ``"cpu"`` or ``"cuda"``/``"cuda:1"``, ...
        compile: ``"auto"`` (default), ``True`` or ``False``: run the step through
            ``torch.compile`` (see :mod:`swarm_envs.physics.torch_backend`).
        native: ``"auto"`` (default), ``True`` or ``False``: run the step on the CPU
            through the C step of :mod:`swarm_envs.envs.native_step` (the same results,
            about 2.5× as fast as the compiled step at 1,024 × 32, and built in a
            second instead of compiled per batch size). ``"auto"`` uses it wherever it
            builds unless ``compile`` is given as ``True``/``False``;
            ``SWARM_ENVS_NATIVE=0`` turns it off.

    Attributes:
        kernel: what runs the step, ``"native"``, ``"compiled"`` or ``"plain"``.
        native_reason: why the C step is used or not.
        compiled: whether the step runs through ``torch.compile``.
        compile_seconds: wall time of the first calls, made by the constructor (the
            compile time when compiled).
        reset_batch: resets of at most this many swarms evaluate only those
            (:func:`partial_reset_batch`); ``None`` below 64 swarms. With the C step
            a reset evaluates only its swarms whenever they are not all of them.

    ``x``, ``v``, ``goal`` read as fresh read-only numpy arrays; assigning one of them
    (a whole array) moves it to the device and re-measures the state. ``t`` is the
    numpy step-counter array itself, writable in place as in the numpy core.

    >>> from swarm_envs.config import SwarmConfig
    >>> core = TorchSwarmNavCore(SwarmConfig(n_agents=4), batch=2, compile=False)
    >>> core.reset(np.random.default_rng(0))
    >>> reward, terminated, truncated, stats = core.step(np.zeros((2, 4, 2)))
    >>> core.observe().shape, reward.shape, sorted(stats) == sorted(STAT_KEYS)
    ((2, 4, 34), (2,), True)
    """

    def __init__(
        self,
        cfg: Any,
        batch: int = 1,
        dtype: Any = np.float32,
        device: Any = "cpu",
        compile: bool | str = "auto",
        native: bool | str = "auto",
    ) -> None:
        require_social_potential(cfg, "TorchSwarmNavCore")
        if cfg.integrator != "semi_implicit_euler":
            raise ValueError(
                "TorchSwarmNavCore supports integrator='semi_implicit_euler' only, got "
                f"{cfg.integrator!r} (use SwarmNavCore, the numpy core, for velocity_verlet)"
            )
        self.cfg = cfg
        self.batch = check_batch(batch)
        self.dtype, self._tdtype = _torch_dtype(dtype)
        self.device = _device(device)
        if self.device.type == "cpu":
            keep_freed_memory()  # per-step temporaries stay in the heap (swarm_envs._malloc)
        B, N, d = self.batch, cfg.n_agents, cfg.dim
        self.obs_dim = observation_size(cfg)
        self.t = np.zeros(B, np.int64)
        zeros = self._zeros
        # State component first, (d, B, N): the layout the fused step vectorises.
        self._x, self._v, self._f = zeros(d, B, N), zeros(d, B, N), zeros(d, B, N)
        self._goal = zeros(B, d)
        self._start_distance = torch.ones(B, dtype=self._tdtype, device=self.device)
        self._prev_distance = torch.ones(B, dtype=self._tdtype, device=self.device)
        self._prev_arrived = zeros(B)
        self._no_action = zeros(B, N, d)
        self._move_all = torch.ones(B, dtype=torch.bool, device=self.device)
        self._move_none = torch.zeros(B, dtype=torch.bool, device=self.device)
        self._compile_request, self._native_request = compile, native
        self._native, self.native_reason = self._native_step(native, compile)
        self._advance = self._build(self.batch, compile, "TorchSwarmNavCore.step")
        self._obs = torch.empty(0)
        self._obs_given = False  # observe() handed out the current observations
        self._obs_shared = False  # observe_tensor() did
        self._packed: np.ndarray = np.empty((0, len(_PACKED)))
        self._graphed: tb.CudaGraphed | None = None
        self._measure(warmup=True)
        if self.device.type == "cuda" and self._advance.compiled:
            # One replay instead of a launch per kernel (tb.CudaGraphed; captured here,
            # never in a step).
            self._graphed = tb.CudaGraphed(
                self._advance, self._args(self._no_action, self._move_none)
            )
            self._measure()
        # Resets of a few swarms measure only those, through the same function compiled
        # for a sub-batch of `reset_batch` swarms (padded): in a VecEnv some swarm ends
        # on most steps, and measuring all B swarms each time would double the step.
        self.reset_batch = partial_reset_batch(self.batch)
        self._advance_part: tb.MaybeCompiled | NativeAdvance | None = None
        # The C step needs none: it re-measures reset swarms in place, any number of them.
        if self.reset_batch is not None:
            self._advance_part = self._build(
                self.reset_batch, self._advance.compiled, "TorchSwarmNavCore.reset"
            )
        if self._advance_part is not None and self._advance_part is not self._advance:
            R = self.reset_batch
            rows = torch.zeros(R, dtype=torch.int64, device=self.device)
            self._advance_part.warmup(*self._row_args(rows))

    def _native_step(
        self, native: bool | str, compile: bool | str
    ) -> tuple[NativeAdvance | None, str]:
        """The C step (:mod:`swarm_envs.envs.native_step`) if it is to be used, and why.

        ``native="auto"`` uses it on the CPU where it builds, unless ``compile`` asks
        for a torch path explicitly (``True`` or ``False``); ``True`` requires it.
        """
        if native not in ("auto", True, False):
            raise ValueError(f"native must be 'auto', True or False, got {native!r}")
        if self.device.type != "cpu":
            if native is True:
                raise ValueError(f"native=True needs device='cpu', got {str(self.device)!r}")
            return None, f"device {self.device}"
        if native == "auto" and compile != "auto":
            return None, f"compile={compile!r} asks for the torch step"
        use, why = resolve_native(native)
        if not use:
            return None, why
        try:
            return NativeAdvance(self.cfg), "native"
        except ValueError as err:  # more neighbours than the kernel ranks
            if native is True:
                raise
            return None, str(err)

    def _build(
        self, batch: int, compile: bool | str, name: str
    ) -> tb.MaybeCompiled | NativeAdvance:
        """The fused function for ``batch`` swarms: the C step, or torch compiled or plain."""
        if self._native is not None:
            return self._native  # one function for every batch size
        return tb.MaybeCompiled(
            build_advance(self.cfg),
            compile=compile,
            device=self.device,
            name=name,
            # The neighbour indices come from _nearest, always in range: no bound checks
            # on the gathers (they cost a third of the observation).
            options={"assert_indirect_indexing": False},
            key=("TorchSwarmNavCore", repr(self.cfg), batch, str(self.dtype), str(self.device)),
        )

    # ------------------------------------------------------------------ helpers
    def _zeros(self, *shape: int) -> torch.Tensor:
        return torch.zeros(shape, dtype=self._tdtype, device=self.device)

    @property
    def compiled(self) -> bool:
        """Whether the step runs through ``torch.compile``."""
        return self._advance.compiled

    @property
    def kernel(self) -> str:
        """What runs the step: ``"native"`` (the C step), ``"compiled"`` or ``"plain"``."""
        if self._native is not None:
            return "native"
        return "compiled" if self._advance.compiled else "plain"

    @property
    def compile_seconds(self) -> float | None:
        """Wall time of the constructor's first calls (the compile time when compiled):
        the step's function, plus the partial reset's when there is one."""
        seconds = self._advance.compile_seconds
        part = self._advance_part
        if part is self._advance:  # the C step: one function, timed once
            return seconds
        if seconds is not None and part is not None and part.compile_seconds is not None:
            seconds += part.compile_seconds
        return seconds

    def _args(self, a: torch.Tensor, move: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The fused function's arguments for the whole batch."""
        return (
            self._x,
            self._v,
            self._f,
            self._goal,
            a,
            move,
            self._prev_distance,
            self._prev_arrived,
            self._start_distance,
        )

    def _run(self, a: torch.Tensor, move: torch.Tensor, warmup: bool = False) -> tuple:
        args = self._args(a, move)
        if self._graphed is not None:
            # The graph's outputs are overwritten by its next replay: the state and the
            # running reward terms are only read before then (or passed back in); the
            # observations, which are handed out, are copied.
            out = self._graphed(*args)
            self._x, self._v, self._f, obs, packed, mean_dist, arrived, _ = out
            self._obs = obs.clone()
        else:
            out = self._advance.warmup(*args) if warmup else self._advance(*args)
            self._x, self._v, self._f, self._obs, packed, mean_dist, arrived, _ = out
        self._packed = packed.cpu().numpy()
        self._obs_given = self._obs_shared = False
        return mean_dist, arrived

    def _measure(self, warmup: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """Observations, statistics and passive force of the current state (no step)."""
        return self._run(self._no_action, self._move_none, warmup=warmup)

    def _row_args(self, rows: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The fused function's arguments for swarms ``rows`` only, measuring (no step)."""
        n = rows.shape[0]
        return (
            self._x[:, rows],
            self._v[:, rows],
            self._f[:, rows],
            self._goal[rows],
            self._no_action[:n],
            self._move_none[:n],
            self._prev_distance[rows],
            self._prev_arrived[rows],
            self._start_distance[rows],
        )

    def _measure_rows(
        self, idx: np.ndarray, rows: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`_measure` for swarms ``idx`` (at most :attr:`reset_batch`) only.

        ``rows`` holds the same indices on the device.

        The rows are padded to ``reset_batch`` with copies of the first; the results of
        the real ones are written into the force, observations and statistics.
        """
        assert self._advance_part is not None and self.reset_batch is not None
        n = rows.shape[0]
        padded = torch.cat([rows, rows[:1].expand(self.reset_batch - n)])
        _, _, f, obs, packed, mean_dist, arrived, _ = self._advance_part(*self._row_args(padded))
        self._f[:, rows] = f[:, :n]
        if self._obs_given or self._obs_shared:  # handed out: leave that memory alone
            self._obs = self._obs.clone()
            self._obs_given = self._obs_shared = False
        self._obs[rows] = obs[:n]
        self._packed[idx] = packed[:n].cpu().numpy()
        return mean_dist[:n], arrived[:n]

    # ------------------------------------------------------------------ reset
    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """Draw new starts for the swarms in ``which`` (bool mask ``(B,)``; all if None).

        The same generator calls as :meth:`SwarmNavCore.reset`: agents uniform in a disc
        (ball) of ``init_radius``, velocities uniform in a disc of ``init_speed``, the
        goal at a uniform random bearing and a distance uniform in
        ``[goal_distance_min, goal_distance_max]``.
        """
        cfg = self.cfg
        idx = np.arange(self.batch) if which is None else np.flatnonzero(which)
        if idx.size == 0:
            return
        x, v, goal = draw_starts(cfg, rng, idx.size)
        self.t[idx] = 0
        if self._native is not None and idx.size < self.batch:
            self._reset_rows_in_place(idx, x, v, goal)
            return
        # Out of place: the old tensors may share memory with arrays handed out.
        rows = torch.as_tensor(idx, device=self.device)
        self._x = self._put(self._x, rows, x)
        self._v = self._put(self._v, rows, v)
        goal_t = self._goal.clone()
        goal_t[rows] = self._to_device(goal)
        self._goal = goal_t
        if self.reset_batch is not None and idx.size <= self.reset_batch:
            mean_dist, arrived = self._measure_rows(idx, rows)
        else:
            mean_dist, arrived = self._measure()
            mean_dist, arrived = mean_dist[rows], arrived[rows]
        # Out of place, as above.
        self._start_distance = self._start_distance.index_put(
            (rows,), torch.clamp(mean_dist, min=1e-6)
        )
        self._prev_distance = self._prev_distance.index_put((rows,), mean_dist)
        self._prev_arrived = self._prev_arrived.index_put((rows,), arrived)

    def _reset_rows_in_place(
        self, idx: np.ndarray, x: np.ndarray, v: np.ndarray, goal: np.ndarray
    ) -> None:
        """The C step's reset of swarms ``idx`` (not all B): the new starts written
        into the state, then those swarms re-measured in place
        (:meth:`NativeAdvance.measure_rows`). On the CPU path every state tensor is the
        core's own (``x``, ``v``, ``goal`` and the distances read as copies; each step
        makes new ones), so only observations handed out need a copy first."""
        assert self._native is not None
        if self._obs_given or self._obs_shared:  # handed out: leave that memory alone
            self._obs = self._obs.clone()
            self._obs_given = self._obs_shared = False
        # numpy views of the CPU tensors: cheaper indexing than torch's for a few rows
        # (assignment casts as numpy casts, like _to_device).
        self._x.numpy()[:, idx] = x.transpose(2, 0, 1)
        self._v.numpy()[:, idx] = v.transpose(2, 0, 1)
        self._goal.numpy()[idx] = goal
        args = self._args(self._no_action, self._move_none)
        self._native.measure_rows(idx, args, self._obs, torch.from_numpy(self._packed))
        start = self._start_distance.numpy()
        start[idx] = np.maximum(self._prev_distance.numpy()[idx], 1e-6)

    def _put(self, state: torch.Tensor, rows: torch.Tensor, new: np.ndarray) -> torch.Tensor:
        """A copy of ``state`` ``(d, B, N)`` with swarms ``rows`` set from ``new`` ``(n, N, d)``."""
        out = state.clone()
        out[:, rows] = self._to_device(new).permute(2, 0, 1)
        return out

    def _to_device(self, a: np.ndarray) -> torch.Tensor:
        """A host array in the core's dtype (cast as numpy casts), on the device."""
        host = np.ascontiguousarray(a, dtype=self.dtype)
        if not host.flags.writeable:  # torch.from_numpy warns on read-only arrays
            host = host.copy()
        return torch.from_numpy(host).to(self.device)

    # ------------------------------------------------------------------ step
    @property
    def _shape(self) -> tuple[int, int, int]:
        return (self.batch, self.cfg.n_agents, self.cfg.dim)

    def _actions(self, actions: Any) -> torch.Tensor:
        shape = self._shape
        if isinstance(actions, torch.Tensor):
            a = actions.detach()
            if a.is_complex() or a.dtype == torch.bool:
                raise ValueError(f"actions must be a real tensor of shape {shape}, got {a.dtype}")
            if tuple(a.shape) != shape:
                if a.numel() == math.prod(shape) and a.ndim != len(shape):
                    a = a.reshape(shape)
                else:
                    raise ValueError(f"actions must have shape {shape}, got {tuple(a.shape)}")
            a = a.to(self.device, self._tdtype)
            if not bool(torch.isfinite(a).all()):
                raise ValueError(NON_FINITE_ACTIONS)
            return a.clamp(-1.0, 1.0)
        if self._native is not None:
            # The C step checks finiteness and clips as it reads the actions (raising
            # before anything is written): two numpy passes over them saved per step.
            return self._to_device(check_action_shape(actions, shape))
        a = check_actions(actions, shape)  # numpy: shape, finiteness, clipping
        return self._to_device(a)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every swarm by one step.

        Args:
            actions: ``(B, N, d)`` in [−1, 1] (validated by
                :func:`~swarm_envs.envs.core.check_actions`; a torch tensor is checked
                the same way on its device).

        Returns:
            ``(reward (B,), terminated (B,), truncated (B,), stats)`` as numpy arrays,
            ``stats`` mapping each of :data:`STAT_KEYS` to a ``(B,)`` array.
        """
        a = self._actions(actions)
        mean_dist, arrived = self._run(a, self._move_all)
        self._prev_distance, self._prev_arrived = mean_dist, arrived
        self.t += 1
        stats = self.stats()
        reward = self._packed[:, -1].astype(np.float64)
        success = stats["success"].astype(bool)
        truncated = (self.t >= self.cfg.max_steps) & ~success
        return reward, success, truncated, stats

    # ------------------------------------------------------------------ views
    def stats(self) -> dict[str, np.ndarray]:
        """Group statistics and task measures per swarm, each ``(B,)`` (fresh arrays).

        Dtypes as in the numpy core: the core's dtype, float64 for ``fraction_arrived``,
        ``collisions`` and ``success`` (and for the nearest-neighbour distance, 0, when
        ``N = 1``).
        """
        packed = self._packed
        wide = _FLOAT64_STATS
        if self.cfg.n_agents == 1:
            wide = (*wide, "nearest_neighbor_distance")
        return {
            key: packed[:, i].astype(np.float64 if key in wide else self.dtype, copy=True)
            for i, key in enumerate(STAT_KEYS)
        }

    def observe(self, which: np.ndarray | None = None) -> np.ndarray:
        """Local observations ``(B, N, obs_dim)``, float32, inside ``[−OBS_BOUND, OBS_BOUND]``.

        The layout of :meth:`SwarmNavCore.observe`: ``(r_g − r_i)/obs_goal_scale`` (d),
        ``v_i/obs_velocity_scale`` (d), then per nearest neighbour j, nearest first,
        ``(r_j − r_i)/obs_neighbor_scale`` (d), ``(v_j − v_i)/obs_velocity_scale`` (d) and
        a mask (1 real, 0 padding). Every call returns an array of the caller's own: the
        first after a step is the step's result itself (no copy on the CPU); a second
        call on the same state measures it again. From a GPU the observations are copied
        into page-locked host memory (torch's caching host allocator), several times
        faster than into a fresh numpy array for large batches.

        ``which`` (bool mask ``(B,)``): the observations of those swarms only, ``(n, N,
        obs_dim)``, copied out. This hands out no memory of the core, so a reset that
        follows writes its swarms' rows in place rather than into a copy of the whole
        array (what the VecEnv does when some swarms end: it keeps their last
        observations, resets them and then observes).
        """
        if which is not None:
            if self.device.type == "cpu":
                return self._obs.numpy()[np.flatnonzero(which)]
            rows = torch.as_tensor(np.flatnonzero(which), device=self.device)
            return self._obs[rows].cpu().numpy()
        if self.device.type == "cpu":
            if self._obs_given:
                self._measure()  # the array handed out shares memory with self._obs
            self._obs_given = True
            return self._obs.numpy()
        self._obs_given = True
        host = torch.empty(
            self._obs.shape, dtype=self._obs.dtype, pin_memory=self.device.type == "cuda"
        )
        host.copy_(self._obs)  # synchronous: the array is complete when returned
        return host.numpy()

    def observe_tensor(self) -> torch.Tensor:
        """The observations as a float32 tensor on the device (no copy; do not modify).

        The tensor keeps its values: later steps and resets write to new memory.
        """
        self._obs_shared = True
        return self._obs

    # ------------------------------------------------------------------ state as numpy
    def _host(self, a: torch.Tensor) -> np.ndarray:
        out = np.array(a.detach().cpu().numpy(), copy=True)
        out.flags.writeable = False
        return out

    def _assign(self, name: str, value: Any, shape: tuple[int, ...]) -> None:
        a = np.asarray(value)
        if a.shape != shape or not np.issubdtype(a.dtype, np.number) or not np.isfinite(a).all():
            raise ValueError(
                f"{name} must be a finite numeric array of shape {shape}, got shape {a.shape}"
            )
        t = self._to_device(a)
        setattr(self, f"_{name}", t.permute(2, 0, 1).contiguous() if t.ndim == 3 else t)
        self._measure()

    @property
    def x(self) -> np.ndarray:
        """Positions ``(B, N, d)`` (a read-only copy; assign a whole array to change them)."""
        return self._host(self._x.permute(1, 2, 0))

    @x.setter
    def x(self, value: Any) -> None:
        self._assign("x", value, self._shape)

    @property
    def v(self) -> np.ndarray:
        """Velocities ``(B, N, d)`` (a read-only copy; assign a whole array to change them)."""
        return self._host(self._v.permute(1, 2, 0))

    @v.setter
    def v(self, value: Any) -> None:
        self._assign("v", value, self._shape)

    @property
    def goal(self) -> np.ndarray:
        """Goals ``(B, d)`` (a read-only copy; assign a whole array to change them)."""
        return self._host(self._goal)

    @goal.setter
    def goal(self, value: Any) -> None:
        self._assign("goal", value, tuple(self._goal.shape))

    @property
    def start_distance(self) -> np.ndarray:
        """Mean agent-to-goal distance at each swarm's start ``(B,)`` (reward normaliser)."""
        return self._host(self._start_distance)

    @property
    def prev_distance(self) -> np.ndarray:
        """Mean agent-to-goal distance after the last step ``(B,)``."""
        return self._host(self._prev_distance)

    @property
    def prev_arrived(self) -> np.ndarray:
        """Fraction of agents within the goal radius after the last step ``(B,)``."""
        return self._host(self._prev_arrived)

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        """Config, options and state on the host; the (compiled) function is rebuilt."""
        return {
            "cfg": self.cfg,
            "batch": self.batch,
            "dtype": self.dtype,
            "device": str(self.device),
            "compile": self._compile_request,
            "native": self._native_request,
            "t": self.t.copy(),
            "tensors": {
                name: getattr(self, name).detach().cpu()
                for name in (
                    "_x",
                    "_v",
                    "_goal",
                    "_start_distance",
                    "_prev_distance",
                    "_prev_arrived",
                )
            },
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(  # type: ignore[misc]
            state["cfg"],
            state["batch"],
            state["dtype"],
            state["device"],
            state["compile"],
            state.get("native", "auto"),
        )
        self.t = state["t"]
        for name, tensor in state["tensors"].items():
            setattr(self, name, tensor.to(self.device))
        self._measure()
