"""The SwarmNav core whose step runs in C: numpy arrays in and out, no torch.

:class:`NativeSwarmNavCore` implements :class:`~swarm_envs.envs.protocol.Core` for the
social potential model with the semi-implicit Euler integrator. Its step is the C step
of ``fused_step.c`` (:mod:`swarm_envs.envs.cores.native.build`): the same physics, step-size
control, neighbour ranking, observation layout and statistics as the shared definitions,
computed per swarm in a few kilobytes of scratch memory, the swarms spread over OpenMP
threads. The reward is the shared definition (:func:`swarm_envs.envs.task.reward`)
applied to the statistics and the effort the C step writes; a statistic the kernel does
not declare is computed by its shared definition from the state
(:mod:`swarm_envs.envs.task.statistics`). The core is an
:class:`~swarm_envs.envs.protocol.Execution` under its task layer
(:mod:`swarm_envs.envs.task.layer`): the reset draws, the episode end, the unstable
guard and the statuses' bookkeeping are the layer's, as on every backend.

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
from typing import Any

import numpy as np

from swarm_envs._array import NUMPY
from swarm_envs.envs.common import (
    StatisticColumns,
    check_action_shape,
    check_batch,
    check_dtype,
    placed_at_rest,
    wide_dtypes,
)
from swarm_envs.envs.cores.native.build import NATIVE_ENV, Library, load_library, resolve_native
from swarm_envs.envs.cores.native.contract import (
    PACKED_COLUMNS,
    UNSOUND,
    step_error,
    step_params,
    unsupported,
)
from swarm_envs.envs.task import STAT_KEYS, STATISTICS, Frame, observation_size
from swarm_envs.envs.task.agent_status import masks
from swarm_envs.envs.task.layer import Advance, HostRecords, TaskCore, TaskLayer

__all__ = ["UNAVAILABLE", "NativeSwarmNavCore"]

#: How :meth:`NativeSwarmNavCore.unsupported` starts its reason when the C step cannot be
#: built or loaded here (rather than refusing the config).
UNAVAILABLE = "the C step is not available"

_EFFORT = PACKED_COLUMNS.index("effort")
_OVER_CAP = PACKED_COLUMNS.index("over_cap")
_NEEDED = PACKED_COLUMNS.index("needed")
_SUBSTEPS = PACKED_COLUMNS.index("substeps")


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


class NativeSwarmNavCore(TaskCore):
    """State and dynamics of ``batch`` SwarmNav swarms, stepped in C.

    Args:
        cfg: the scenario (:class:`~swarm_envs.config.SwarmConfig`).
        batch: number of swarms ``B ≥ 1``.
        dtype: ``np.float64`` (default) or ``np.float32``, the state's precision.

    Raises:
        RuntimeError: the C step cannot be built or loaded here
            (:func:`~swarm_envs.envs.cores.native.build.native_support` says why).
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
        self._wide = wide_dtypes(self.dtype)
        self._columns = StatisticColumns(self.dtype)
        self._x = np.zeros((d, B, N), self.dtype)
        self._v = np.zeros((d, B, N), self.dtype)
        self._f = self._buffers()[2]
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
        #: Each agent's status ``(B, N)`` int8 (agent_status), ``None`` while every agent
        #: is active and always will be (then the kernel applies no masks).
        self._status: np.ndarray | None = None
        self._bind()
        # The statistics the kernel does not write, and the task's success where it is
        # not the kernel's (arrival alone): evaluated on the state by their definitions.
        own_success = cfg.task_spec.success is None
        # (Their indices into STATISTICS: the core pickles, the definitions need not.)
        self._extra = tuple(
            i
            for i, s in enumerate(STATISTICS)
            if s.name not in library.info.statistics or (s.name == "success" and not own_success)
        )
        self._extra_pairs = any(STATISTICS[i].pairwise for i in self._extra)
        self._measure()
        #: The task above this core: reward, episode end, previous and start statistics.
        self.task = TaskLayer(cfg, self.batch, HostRecords(self.stats(), self.stats()))

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
        """Zeroed ``(x, v, f)`` state buffers, ``(d, B, N)`` each; with
        ``"implicit_damping_euler"`` ``f`` has two rows more: the agents' implicit
        damping ``(b_i, w_i)`` (``damping_rates``), carried like the passive force."""
        cfg = self.cfg
        shape = (cfg.dim, self.batch, cfg.n_agents)
        rows = cfg.dim + 2 * int(cfg.integrator == "implicit_damping_euler")
        f = np.zeros((rows, self.batch, cfg.n_agents), self.dtype)
        return np.zeros(shape, self.dtype), np.zeros(shape, self.dtype), f

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

    # ------------------------------------------------------------------ execution
    def begin(
        self,
        idx: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        rng: np.random.Generator,
    ) -> dict[str, np.ndarray]:
        """New starts for the swarms ``idx`` (:meth:`Execution.begin
        <swarm_envs.envs.protocol.Execution.begin>`); a proper subset is re-measured
        alone, in place."""
        self._x[:, idx] = x.transpose(2, 0, 1)
        self._v[:, idx] = v.transpose(2, 0, 1)
        self._goal[idx] = goal
        # As the numpy core's statistics after a reset: no step, no substeps.
        self._packed[idx, _SUBSTEPS] = 0.0
        self._measure(None if idx.size == self.batch else idx.astype(np.int64))
        return self._stats

    def advance(self, actions: Any) -> Advance:
        """One C step of every swarm (:meth:`Execution.advance
        <swarm_envs.envs.protocol.Execution.advance>`): the C step checks the actions
        (NaN or inf: :class:`ValueError` before anything changes) and clips them; it
        writes the new state into the spare buffers, which become the state (the state
        before the step the spare, for :meth:`undo`)."""
        shape = (self.batch, self.cfg.n_agents, self.cfg.dim)
        a = np.ascontiguousarray(check_action_shape(actions, shape), dtype=self.dtype)
        obs = self._pool.get()
        unsound = self._call(a, self._move_all, obs, None, into_spare=True)
        self._swap()
        self._obs, self._obs_given = obs, False
        # Fresh arrays: the caller gets them, the task's records a copy.
        stats = self._stats = self._unpack()
        packed = self._packed
        over_cap = packed[:, _OVER_CAP] > 0 if unsound else None
        return Advance(
            stats, stats, packed[:, _EFFORT], None, over_cap, packed[:, _NEEDED], unsound
        )

    def undo(self, idx: np.ndarray, mark: bool) -> dict[str, np.ndarray]:
        """The swarms ``idx`` back at their state before the step (the spare buffers),
        re-measured (:meth:`Execution.undo <swarm_envs.envs.protocol.Execution.undo>`)."""
        x_old, v_old, _ = self._spare
        self._x[:, idx], self._v[:, idx] = x_old[:, idx], v_old[:, idx]
        self._measure(idx.astype(np.int64))  # their force, h*, observations, statistics
        if mark:
            self._stats["unstable"][idx] = 1.0
        return self._stats

    def measured(self) -> dict[str, np.ndarray]:
        """The current statistics ``{name: (B,)}`` (the core's own; a measure replaces them)."""
        return self._stats

    # ------------------------------------------------------------------ agents
    def take_statuses(
        self, status: np.ndarray, place: np.ndarray | None, at: np.ndarray | None
    ) -> None:
        """Checked statuses ``(B, N)`` (:meth:`Execution.take_statuses
        <swarm_envs.envs.protocol.Execution.take_statuses>`). From then on the C step
        applies their masks: pairs with an agent not present, updates of agents that do
        not move, statistics over the members, the observed status flags."""
        mobile = masks(status).mobile
        if place is not None:
            at = np.moveaxis(np.asarray(at, dtype=self.dtype), -1, 0)
        x, v = placed_at_rest(self._x, self._v, mobile, place, at, NUMPY, component_first=True)
        self._x[...], self._v[...] = x, v  # in place: the kernel's buffers
        if self._status is None:
            self._status = status.copy()
        else:
            self._status[...] = status  # in place: the kernel's array

    def remeasure(self, idx: np.ndarray) -> None:
        """Measure the swarms ``idx`` again, their last step's substep count kept
        (:meth:`Execution.remeasure <swarm_envs.envs.protocol.Execution.remeasure>`)."""
        substeps = self._packed[:, _SUBSTEPS].copy()  # a measure takes none
        self._measure(None if idx.size == self.batch else idx.astype(np.int64))
        self._packed[idx, _SUBSTEPS] = substeps[idx]
        self._stats["substeps"][idx] = substeps[idx]

    @property
    def status(self) -> np.ndarray | None:
        """Each agent's status ``(B, N)`` int8 as last given (``None`` before)."""
        return self._status

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
        skip: tuple[str, ...] = ("_lib", "_params", "_params_ptr", "_fn", "_pool", "_spare")
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
