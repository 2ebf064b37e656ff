"""The SwarmNav core whose step runs in C: numpy arrays in and out, no torch.

:class:`NativeSwarmNavCore` implements :class:`~swarm_envs.envs.protocol.Core` for the
social potential model with the semi-implicit Euler integrator. Its step is the C step
of ``fused_step.c`` (:mod:`swarm_envs.envs.native.build`): the same physics, step-size
control, neighbour ranking, observation layout and statistics as the shared definitions,
computed per swarm in a few kilobytes of scratch memory, the swarms spread over OpenMP
threads. The reward is the shared definition (:func:`swarm_envs.envs.task.reward`)
applied to the statistics and the effort the C step writes; a statistic the kernel does
not declare is computed by its shared definition from the state
(:mod:`swarm_envs.envs.task.statistics`).

State: positions, velocities and the carried passive force live component first,
``(d, B, N)``, the layout the kernel vectorises; ``x`` and ``v`` read as ``(B, N, d)``
copies. The stable substep ``h*`` of each swarm is carried beside them, ``(B,)``. A step
writes the new state into a second set of buffers and swaps the two, so the state
before the step is still at hand when the guard undoes an unstable step
(``on_unstable="truncate"``, as :meth:`SwarmNavCore.step
<swarm_envs.envs.core.SwarmNavCore.step>`). Observations are written into buffers that
are recycled once nobody else holds them (:class:`_BufferPool`), so a step allocates no
large array. A reset of a few swarms re-measures those swarms only, in place.

Agent statuses (:meth:`NativeSwarmNavCore.set_status`, from the perturbations' wrapper)
are kept as a ``(B, N)`` int8 array that the C step reads, with the numpy core's
semantics (:mod:`swarm_envs.envs.task.agent_status`); until the first call the kernel
gets none and applies no masks.
"""

from __future__ import annotations

import ctypes
import sys
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from swarm_envs._array import NUMPY, SCALAR
from swarm_envs.envs.common import (
    StatisticColumns,
    SwarmUnstableError,
    beyond_bound,
    check_action_shape,
    check_batch,
    check_dtype,
    check_start,
    draw_starts,
    energy_bound,
    unstable_message,
    unstable_swarms,
    wide_dtypes,
)
from swarm_envs.envs.native.build import NATIVE_ENV, Library, load_library, resolve_native
from swarm_envs.envs.native.contract import (
    PACKED_COLUMNS,
    UNSOUND,
    step_error,
    step_params,
    unsupported,
)
from swarm_envs.envs.stiffness import StiffnessWatch
from swarm_envs.envs.task import (
    STAT_KEYS,
    STATISTICS,
    Frame,
    RewardInputs,
    observation_size,
    reward,
)
from swarm_envs.envs.task.agent_status import keep_measured, masks, status_update
from swarm_envs.envs.task.episode import episode_end

__all__ = ["UNAVAILABLE", "NativeSwarmNavCore"]

#: How :meth:`NativeSwarmNavCore.unsupported` starts its reason when the C step cannot be
#: built or loaded here (rather than refusing the config).
UNAVAILABLE = "the C step is not available"

_EFFORT = PACKED_COLUMNS.index("effort")
_OVER_CAP = PACKED_COLUMNS.index("over_cap")
_NEEDED = PACKED_COLUMNS.index("needed")
_SUBSTEPS = PACKED_COLUMNS.index("substeps")


class _FirstSwarm(Mapping[str, float]):
    """The statistics of swarm 0 as floats, each read from its ``(B,)`` array when a
    reward term asks for it (a term reads a few of them)."""

    __slots__ = ("_stats",)

    def __init__(self, stats: Mapping[str, np.ndarray]) -> None:
        self._stats = stats

    def __getitem__(self, key: str) -> float:
        return float(self._stats[key][0])

    def __iter__(self) -> Iterator[str]:
        return iter(self._stats)

    def __len__(self) -> int:
        return len(self._stats)


class _BufferPool:
    """Observation buffers ``(B, N, obs_dim)`` float32, reused once only the pool holds
    them (a caller that keeps an observation keeps its buffer out of the pool)."""

    def __init__(self, shape: tuple[int, ...], size: int = 4) -> None:
        self.shape, self.size = shape, size
        self.buffers: list[np.ndarray] = []

    def get(self) -> np.ndarray:
        for buf in self.buffers:
            # The pool's list, this loop's name and getrefcount's argument: nobody else.
            if sys.getrefcount(buf) <= 3:
                return buf
        buf = np.empty(self.shape, np.float32)
        if len(self.buffers) < self.size:
            self.buffers.append(buf)
        return buf

    def __getstate__(self) -> dict[str, Any]:
        return {"shape": self.shape, "size": self.size, "buffers": []}


class NativeSwarmNavCore:
    """State and dynamics of ``batch`` SwarmNav swarms, stepped in C.

    Args:
        cfg: the scenario (:class:`~swarm_envs.config.SwarmConfig`).
        batch: number of swarms ``B ≥ 1``.
        dtype: ``np.float64`` (default) or ``np.float32``, the state's precision.

    Raises:
        RuntimeError: the C step cannot be built or loaded here
            (:func:`~swarm_envs.envs.native.build.native_support` says why).
        ValueError: ``cfg`` needs what the C step does not implement
            (:meth:`unsupported` names it).

    >>> from swarm_envs.config import SwarmConfig
    >>> core = NativeSwarmNavCore(SwarmConfig(n_agents=4), batch=2)
    >>> core.reset(np.random.default_rng(0))
    >>> reward, terminated, truncated, stats = core.step(np.zeros((2, 4, 2)))
    >>> core.observe().shape, reward.shape, list(stats) == list(STAT_KEYS)
    ((2, 4, 34), (2,), True)
    """

    backend = "native"

    def __init__(self, cfg: Any, batch: int = 1, dtype: Any = np.float64) -> None:
        library: Library = load_library()
        reason = unsupported(cfg, library.info)
        if reason is not None:
            raise ValueError(f"NativeSwarmNavCore: {reason}")
        self.cfg = cfg
        self.batch = check_batch(batch)
        self.dtype = check_dtype(dtype)
        B, N, d = self.batch, cfg.n_agents, cfg.dim
        self.obs_dim = observation_size(cfg)
        self.t = np.zeros(B, np.int64)
        self._stiffness = StiffnessWatch(cfg, self.batch)
        self._energy_bound = energy_bound(cfg)  # the unstable guard's (common.energy_bound)
        self._wide = wide_dtypes(self.dtype)
        self._columns = StatisticColumns(self.dtype)
        self._x = np.zeros((d, B, N), self.dtype)
        self._v = np.zeros((d, B, N), self.dtype)
        self._f = np.zeros((d, B, N), self.dtype)
        self._spare = self._buffers()  # a step's output; then the state before it
        self._h = np.full(B, np.inf)  # the stable substep of the current state
        self._goal = np.zeros((B, d), self.dtype)
        self._zero_actions = np.zeros((B, N, d), self.dtype)
        self._move_all = np.ones(B, np.bool_)
        self._move_none = np.zeros(B, np.bool_)
        self._pool = _BufferPool((B, N, self.obs_dim))
        self._obs = self._pool.get()
        self._obs_given = False
        self._packed = np.zeros((B, len(PACKED_COLUMNS)), self.dtype)
        self._stats: dict[str, np.ndarray] = {}
        self._prev: dict[str, np.ndarray] = {}
        self._start: dict[str, np.ndarray] = {}
        #: Each agent's status ``(B, N)`` int8 (agent_status), ``None`` while every agent
        #: is active and always will be (then the kernel applies no masks).
        self._status: np.ndarray | None = None
        self._bind()
        # The statistics the kernel does not write, and the task's success where it is
        # not the kernel's (arrival alone): evaluated on the state by their definitions.
        own_success = cfg.task != "mill"
        # (Their indices into STATISTICS: the core pickles, the definitions need not.)
        self._extra = tuple(
            i
            for i, s in enumerate(STATISTICS)
            if s.name not in library.info.statistics or (s.name == "success" and not own_success)
        )
        self._extra_pairs = any(STATISTICS[i].pairwise for i in self._extra)
        self._measure()
        self._prev, self._start = self.stats(), self.stats()

    @staticmethod
    def unsupported(cfg: Any) -> str | None:
        """Why this core cannot run ``cfg`` here (``None`` if it can): the C step does
        not build, or ``cfg`` needs what it does not implement."""
        use, why = resolve_native("auto")  # SWARM_ENVS_NATIVE=1 raises where it cannot build
        if not use:
            if why == f"{NATIVE_ENV}=0":
                return f"switched off ({NATIVE_ENV}=0)"
            return f"{UNAVAILABLE} ({why})"
        return unsupported(cfg, load_library().info)

    # ------------------------------------------------------------------ the C step
    def _buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        shape = (self.cfg.dim, self.batch, self.cfg.n_agents)
        return tuple(np.zeros(shape, self.dtype) for _ in range(3))  # type: ignore[return-value]

    def _call(
        self,
        actions: np.ndarray,
        move: np.ndarray,
        obs: np.ndarray,
        rows: np.ndarray | None,
        into_spare: bool = False,
    ) -> bool:
        """The C step on all swarms (``rows`` None) or on ``rows``: the new state in
        place, or (``into_spare``) into the spare buffers (:meth:`_swap` then). True
        where a swarm may have gone unstable (the guard's check is needed)."""
        n = self.batch if rows is None else rows.size
        x, v, f = self._state_ptrs
        x_out, v_out, f_out = self._spare_ptrs if into_spare else self._state_ptrs
        h, goal, packed = self._fixed_ptrs
        code = self._fn(
            self._params_ptr,
            0,
            n,
            None if rows is None else rows.ctypes.data,
            x,
            v,
            f,
            h,
            goal,
            actions.ctypes.data,
            move.ctypes.data,
            None if self._status is None else self._status.ctypes.data,
            x_out,
            v_out,
            f_out,
            h,
            obs.ctypes.data,
            packed,
        )
        if code & ~UNSOUND:
            raise step_error(code)
        return bool(code & UNSOUND)

    def _bind(self) -> None:
        """The kernel, its parameters and the addresses of the state (fixed buffers)."""
        self._lib = load_library()
        self._params = step_params(self.cfg, self.dtype)
        self._params.batch = self.batch
        self._params_ptr = ctypes.addressof(self._params)
        self._fn = self._lib.f32 if self.dtype == np.float32 else self._lib.f64
        self._state_ptrs = tuple(a.ctypes.data for a in (self._x, self._v, self._f))
        self._spare_ptrs = tuple(a.ctypes.data for a in self._spare)
        self._fixed_ptrs = tuple(a.ctypes.data for a in (self._h, self._goal, self._packed))

    def _swap(self) -> None:
        """The step wrote the new state into the spare buffers: they become the state,
        and the state before the step the spare."""
        spare = self._spare
        self._spare = (self._x, self._v, self._f)
        self._x, self._v, self._f = spare
        self._state_ptrs, self._spare_ptrs = self._spare_ptrs, self._state_ptrs

    def _measure(self, rows: np.ndarray | None = None) -> None:
        """Observations and statistics of the current state (no step)."""
        if rows is None:
            self._obs = self._pool.get()
            self._obs_given = False
        elif self._obs_given:  # handed out: write the rows into a copy
            fresh = self._pool.get()
            fresh[...] = self._obs
            self._obs, self._obs_given = fresh, False
        self._call(self._zero_actions, self._move_none, self._obs, rows)
        self._stats = self._unpack()

    def _unpack(self) -> dict[str, np.ndarray]:
        """The statistics of the packed columns, plus any the kernel does not write."""
        packed = self._packed
        stats = self._columns.split(packed)
        if self._extra:
            frame = self._frame(packed)
            for s in (STATISTICS[i] for i in self._extra):
                stats[s.name] = np.asarray(s.value(frame, self.cfg, NUMPY), self._wide[s.name])
        return stats

    def _frame(self, packed: np.ndarray) -> Frame:
        """A numpy :class:`Frame` of the current state, for statistics the kernel does
        not write (pairwise distances in numpy: slower, and only for statistics that may
        read them; else the nearest distances are left at 0)."""
        x, v = self.x, self.v
        n = self.cfg.n_agents
        members = None if self._status is None else masks(self._status).mobile
        nearest = np.zeros((self.batch, n), self.dtype)
        if self._extra_pairs and n > 1:
            rho = np.linalg.norm(x[:, :, None, :] - x[:, None, :, :], axis=-1)
            if self._status is not None:  # pairs with an agent not present: none
                present = masks(self._status).present
                rho = np.where(present[:, :, None] & present[:, None, :], rho, np.inf)
            rho[:, np.arange(n), np.arange(n)] = np.inf
            nearest = rho.min(axis=-1)
            if members is not None:  # no present other: 0
                nearest = np.where(np.isfinite(nearest), nearest, 0.0).astype(self.dtype)
        offset = self.goal[:, None, :] - x
        return Frame(
            x,
            v,
            self.goal,
            np.sqrt(np.einsum("bik,bik->bi", offset, offset)),
            nearest,
            packed[:, STAT_KEYS.index("collisions")],
            packed[:, STAT_KEYS.index("energy")],
            packed[:, STAT_KEYS.index("substeps")],
            members,
        )

    # ------------------------------------------------------------------ reset
    def reset(self, rng: np.random.Generator, which: np.ndarray | None = None) -> None:
        """Draw new starts for the swarms in ``which`` (bool mask ``(B,)``; all if None),
        with :func:`~swarm_envs.envs.common.draw_starts` as every core; a proper subset
        is re-measured alone, in place."""
        idx = np.arange(self.batch) if which is None else np.flatnonzero(which)
        if idx.size == 0:
            return
        x, v, goal = draw_starts(self.cfg, rng, idx.size)
        self.t[idx] = 0
        self._x[:, idx] = x.transpose(2, 0, 1)
        self._v[:, idx] = v.transpose(2, 0, 1)
        self._goal[idx] = goal
        # As the numpy core's statistics after a reset: no step, no substeps.
        self._packed[idx, _SUBSTEPS] = 0.0
        self._measure(None if idx.size == self.batch else idx.astype(np.int64))
        check_start(self.cfg, self._stats, idx, self.dtype)
        for key, value in self._stats.items():
            self._prev[key][idx] = value[idx]
            self._start[key][idx] = value[idx]

    # ------------------------------------------------------------------ agents
    def set_status(
        self,
        status: np.ndarray,
        place: np.ndarray | None = None,
        at: np.ndarray | None = None,
        *,
        rows: np.ndarray | None = None,
        start: bool = False,
    ) -> None:
        """Give the agents new statuses ``(B, N)`` (agent_status) between steps, as
        :meth:`SwarmNavCore.set_status <swarm_envs.envs.core.SwarmNavCore.set_status>`.

        ``place`` ``(B, N)`` bool: agents put at ``at`` ``(B, N, d)`` (joining agents).
        Agents that no longer move and placed agents are at rest. The swarms whose
        statuses or places changed, and those in ``rows`` ``(B,)``, are measured again
        (their last step's substep count kept), and their previous statistics become
        these (``start=True``: their episode's start too). From then on the C step
        applies the statuses' masks: pairs with an agent not present, updates of agents
        that do not move, statistics over the members, the observed status flags.
        """
        B = self.batch
        old = self._status
        shape = (B, self.cfg.n_agents, self.cfg.dim)
        status, place, rows = status_update(old, status, place, at, rows, shape)
        if place is not None:
            self._x[:, place] = np.asarray(at, dtype=self.dtype)[place].T
            self._v[:, place] = 0.0
        if old is None:
            self._status = status.copy()
        else:
            old[...] = status  # in place: the kernel's array
        self._v[:, ~masks(status).mobile] = 0.0
        if not rows.any():
            return
        idx = np.flatnonzero(rows)
        substeps = self._packed[:, _SUBSTEPS].copy()  # a measure takes none
        before = self._stats
        self._measure(None if idx.size == B else idx.astype(np.int64))
        self._packed[idx, _SUBSTEPS] = substeps[idx]
        self._stats["substeps"][idx] = substeps[idx]
        keep_measured(self._stats, before, self._prev, self._start, rows, start)

    # ------------------------------------------------------------------ step
    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every swarm by one step.

        Args:
            actions: ``(B, N, d)`` in [−1, 1]; the C step checks them (NaN or inf:
                :class:`ValueError` before anything changes) and clips them.

        Returns:
            ``(reward (B,), terminated (B,), truncated (B,), stats)`` as in every core;
            a swarm whose step went unstable under ``on_unstable="truncate"`` is back
            at its state before the step, with reward 0, ``truncated`` and
            ``stats["unstable"]`` 1.

        Raises:
            SwarmUnstableError: a step went unstable (a non-finite state, or more
                substeps needed than ``max_substeps``) under ``on_unstable="raise"``.
        """
        shape = (self.batch, self.cfg.n_agents, self.cfg.dim)
        a = np.ascontiguousarray(check_action_shape(actions, shape), dtype=self.dtype)
        obs = self._pool.get()
        unsound = self._call(a, self._move_all, obs, None, into_spare=True)
        self._swap()
        self._obs, self._obs_given = obs, False
        self.t += 1
        self._stats = self._unpack()
        bad = None
        if unsound or beyond_bound(self._stats, self._energy_bound):
            bad = unstable_swarms(self._stats, self._packed[:, _OVER_CAP] > 0, self._energy_bound)
            if bad.any():
                self._unstable(bad)
            else:
                bad = None
        stats = self._stats
        effort = self._packed[:, _EFFORT]
        xp = NUMPY
        prev, start = self._prev, self._start
        if self.batch == 1:  # plain floats: the same definitions, no array overhead
            xp = SCALAR
            first = _FirstSwarm(stats), _FirstSwarm(prev), _FirstSwarm(start)
            inputs = RewardInputs(*first, float(effort[0]), self.cfg.n_agents, xp)
            r = np.array([reward(self.cfg.reward, inputs)], dtype=np.float64)
        else:
            inputs = RewardInputs(stats, prev, start, effort, self.cfg.n_agents, xp)
            r = np.asarray(reward(self.cfg.reward, inputs), dtype=np.float64)
        # _unpack made fresh arrays: the caller gets them, the next reward a copy (a reset
        # writes into the copy).
        self._prev = {key: value.copy() for key, value in stats.items()}
        terminated, truncated = episode_end(self.cfg, stats["success"], self.t)
        if bad is not None:
            r[bad], terminated[bad], truncated[bad] = 0.0, False, True
        self._stiffness.observe(stats)
        return r, terminated, truncated, stats

    def _unstable(self, bad: np.ndarray) -> None:
        """Raise :class:`~swarm_envs.envs.common.SwarmUnstableError`, or
        (``on_unstable="truncate"``) put the swarms ``bad`` back to their state before
        the step (the spare buffers), re-measured, marked ``unstable``."""
        cfg = self.cfg
        if cfg.on_unstable == "raise":
            needed = self._packed[:, _NEEDED].astype(np.float64)
            raise SwarmUnstableError(unstable_message(cfg, self._stats, bad, needed, self.t))
        idx = np.flatnonzero(bad)
        x_old, v_old, _ = self._spare
        self._x[:, idx], self._v[:, idx] = x_old[:, idx], v_old[:, idx]
        self._measure(idx.astype(np.int64))  # their force, h*, observations, statistics
        self._stats["unstable"][idx] = 1.0

    # ------------------------------------------------------------------ views
    def stats(self) -> dict[str, np.ndarray]:
        """Group statistics and task measures per swarm, each ``(B,)`` (fresh arrays)."""
        return {key: value.copy() for key, value in self._stats.items()}

    def observe(self, which: np.ndarray | None = None) -> np.ndarray:
        """Local observations ``(B, N, obs_dim)``, float32 (the shared layout).

        The first call after a step returns the step's buffer itself; later calls on the
        same state return copies. ``which`` (bool ``(B,)``): those swarms' rows, copied.
        """
        if which is not None:
            return self._obs[np.flatnonzero(which)]
        if self._obs_given:
            return self._obs.copy()
        self._obs_given = True
        return self._obs

    @property
    def x(self) -> np.ndarray:
        """Positions ``(B, N, d)`` (a copy)."""
        return self._x.transpose(1, 2, 0).copy()

    @property
    def v(self) -> np.ndarray:
        """Velocities ``(B, N, d)`` (a copy)."""
        return self._v.transpose(1, 2, 0).copy()

    @property
    def goal(self) -> np.ndarray:
        """Goals ``(B, d)`` (a copy)."""
        return self._goal.copy()

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        skip = ("_lib", "_params", "_params_ptr", "_fn", "_pool", "_spare")
        skip += ("_state_ptrs", "_spare_ptrs", "_fixed_ptrs")
        state = {k: v for k, v in self.__dict__.items() if k not in skip}
        state["_obs"] = self._obs.copy()
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._spare = self._buffers()
        self._bind()
        B, N = self.batch, self.cfg.n_agents
        self._pool = _BufferPool((B, N, self.obs_dim))
