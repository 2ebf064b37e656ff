"""The batched SwarmNav core in PyTorch: one fused (compiled) function per step, CPU or CUDA.

:class:`TorchSwarmNavCore` implements :class:`~swarm_envs.envs.protocol.Core` for the
social potential model with the two semi-implicit Euler integrators. Its step is the torch
function of :func:`swarm_envs.envs.cores.torch.step.build_advance`: the shared definitions of
the physics and the task evaluated on tensors, compiled by ``torch.compile`` into a
handful of fused loops where a compiler is available (TorchInductor: C++ on the CPU,
Triton on CUDA), plain torch otherwise (:mod:`swarm_envs._runtime.torch_compile`). The
same seed and actions give the same starts, and the same observations, rewards and
statistics as the numpy core to floating-point tolerance.

The passive force of the current state is carried from one step to the next, so each
step evaluates the pairs once; so is the stable substep ``h*`` of the step-size control
(computed in the same pass; :mod:`swarm_envs.physics.integrators`). When every swarm's
``h*`` allows the whole ``dt`` in one substep, the step is that one fused call. Otherwise
each swarm's substeps but its last run through a second compiled function (update,
force and ``h*`` only; :func:`~swarm_envs.envs.cores.torch.step.build_substep`), each swarm its
own count, and the fused function takes the last ones and measures the new state. The
substep counts and the cap ``max_substeps`` are the numpy core's; the unstable guard
(``on_unstable``), the reward's previous and start rows, the episode end and the reset
draws are the task layer's (:mod:`swarm_envs.envs.task.layer`), whose reward the fused
step computes in its graph from the same declarations.

A reset (or assigning ``x``, ``v`` or ``goal``) re-evaluates the same function with the
integration switched off, so the observations, statistics and carried force always
describe the current state. A reset of a few swarms (at most
:attr:`TorchSwarmNavCore.reset_batch`, 1/16 of a batch of 64 or more) evaluates them
alone, through the same function compiled for that sub-batch: in a VecEnv some swarm
ends on most steps, and measuring all of them each time would double the step.

Compile time: the constructor makes the first (compiling) calls of both functions, on
the all-zero state, and stores their wall time in
:attr:`TorchSwarmNavCore.compile_seconds`; steps never compile. Shapes are static: the
functions are compiled for this core's ``(batch, N, d)``.

Host and device: actions arrive as numpy (or as a torch tensor, kept on the device),
state stays on ``device``; per step the ``(B, S)`` statistics and the rewards come back,
and the observations when :meth:`TorchSwarmNavCore.observe` asks (on the CPU without
copying; from a GPU into page-locked memory). The starts are drawn on the host with the
numpy generator, as every core draws them, then moved to the device. On a GPU the
compiled step is captured once as a CUDA graph (:class:`~swarm_envs._runtime.
torch_compile.CudaGraphed`) and replayed each step: one launch instead of one per kernel.
The substep function runs compiled but not captured (its count varies from step to
step), and the state before a step is kept for the unstable guard (the graph's inputs,
or a copy when substeps follow).

Agent statuses (:mod:`swarm_envs.envs.cores.torch.statuses`): where the config needs them
(agents that are removed, frozen, absent or join, or ``observe_status``), the statuses
are kept on the device and passed to both functions, which apply the numpy core's masks
(:mod:`swarm_envs.envs.cores.torch.step`); ``set_status`` takes new ones between steps.
Otherwise the functions run without them.

Step-size control on the host: the fused step returns, per swarm, the stable substep
``h*`` of the new state and ``h*`` where that state is finite, NaN where not
(``"h_guard"``), and whether that is at least ``dt`` for the whole batch (``"calm"``;
:data:`~swarm_envs.envs.cores.torch.step.PACKED_KEYS`). That one value, read on the host, says
both that the step went stable and that the next one takes the whole ``dt`` in one
substep for every swarm: the common case costs that read. Otherwise the substep function
plans and takes every swarm's substeps but its last
(:func:`~swarm_envs.envs.cores.torch.step.plan_substep`; one flag read on the host per
substep), and the fused function takes the last ones and measures the new state.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from swarm_envs._array import torch_namespace
from swarm_envs._runtime.torch_compile import CudaGraphed, MaybeCompiled
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.common import (
    NON_FINITE_ACTIONS,
    StatisticColumns,
    check_actions,
    check_batch,
    check_dtype,
    placed_at_rest,
)
from swarm_envs.envs.cores.torch.statuses import DeviceStatuses
from swarm_envs.envs.cores.torch.step import PACKED_KEYS, build_advance, build_substep
from swarm_envs.envs.task import STAT_KEYS, observation_size
from swarm_envs.envs.task.agent_status import masks
from swarm_envs.envs.task.layer import Advance, TaskCore, TaskLayer

__all__ = ["PARTIAL_RESET_MIN_BATCH", "PackedRecords", "TorchSwarmNavCore", "partial_reset_batch"]

#: Pair evaluations per step (``B·N²``) up to which the compiled CPU step runs on one
#: thread: below it the threads' synchronisation costs more than they share.
SINGLE_THREAD_PAIRS = 8192

#: The smallest batch whose resets of a few swarms measure only those (see
#: :func:`partial_reset_batch`); smaller batches re-measure every swarm on a reset.
PARTIAL_RESET_MIN_BATCH = 64

_H_STABLE = PACKED_KEYS.index("h_stable")
_H_GUARD = PACKED_KEYS.index("h_guard")
_CALM = PACKED_KEYS.index("calm")
#: The column of the ``unstable`` statistic in the packed row.
UNSTABLE = STAT_KEYS.index("unstable")

State = tuple[torch.Tensor, torch.Tensor]


def partial_reset_batch(batch: int) -> int | None:
    """Sub-batch size ``R = batch // 16`` for resets of at most R swarms, or ``None``.

    With ``batch ≥ PARTIAL_RESET_MIN_BATCH`` a reset of at most ``R`` swarms runs the
    fused function on those swarms only (padded to R): 1/16 of a step. Below that size,
    or for larger resets, every swarm is measured, which costs a whole step.
    """
    return batch // 16 if batch >= PARTIAL_RESET_MIN_BATCH else None


class PackedRecords:
    """The task layer's previous and start statistics as the fused step reads them: the
    packed rows ``(B, P)`` (:data:`~swarm_envs.envs.cores.torch.step.PACKED_KEYS`) on the
    device (:class:`~swarm_envs.envs.task.layer.Records`). Every update makes new
    tensors: the old ones may be a CUDA graph's inputs or handed to a step."""

    def __init__(self, prev: torch.Tensor, start: torch.Tensor) -> None:
        self.prev, self.start = prev, start

    def take(self, measured: torch.Tensor, idx: np.ndarray) -> None:
        rows = torch.as_tensor(idx, device=measured.device)
        new = measured[rows]
        self.prev = self.prev.index_put((rows,), new)
        self.start = self.start.index_put((rows,), new)

    def follow(self, measured: torch.Tensor) -> None:
        self.prev = measured  # each step's packed rows are a new tensor

    def remeasured(
        self, measured: torch.Tensor, before: torch.Tensor, rows: np.ndarray, start: bool
    ) -> None:
        # The core measured the others alike (same state, same flags): no row to keep.
        idx = torch.as_tensor(np.flatnonzero(rows), device=measured.device)
        new = measured[idx]
        self.prev = self.prev.index_put((idx,), new)
        if start:
            self.start = self.start.index_put((idx,), new)


def _torch_dtype(dtype: Any) -> tuple[np.dtype, torch.dtype]:
    np_dtype = check_dtype(dtype)
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


class TorchSwarmNavCore(TaskCore):
    """State and dynamics of ``batch`` independent SwarmNav swarms, in torch.

    A :class:`~swarm_envs.envs.protocol.Core` (numpy in, numpy out) for
    ``cfg.dynamics == "social_potential"`` with ``cfg.integrator`` one of
    ``"semi_implicit_euler"`` and ``"implicit_damping_euler"``; :meth:`unsupported` says
    why any other config is refused.

    Args:
        cfg: the scenario (:class:`~swarm_envs.config.SwarmConfig`).
        batch: number of swarms ``B ≥ 1``.
        dtype: ``np.float32`` (default) or ``np.float64``, the state's precision.
        device: a torch device, ``"cpu"`` or ``"cuda"``/``"cuda:1"``, ...
        compile: ``"auto"`` (default), ``True`` or ``False``: run the step through
            ``torch.compile`` (see :mod:`swarm_envs._runtime.torch_compile`).

    Attributes:
        kernel: what runs the step, ``"compiled"`` or ``"plain"``.
        compiled: whether the step runs through ``torch.compile``.
        compile_seconds: wall time of the first calls, made by the constructor (the
            compile time when compiled).
        reset_batch: resets of at most this many swarms evaluate only those
            (:func:`partial_reset_batch`); ``None`` below 64 swarms.

    ``x``, ``v``, ``goal`` read as fresh read-only numpy arrays; assigning one of them
    (a whole array) moves it to the device and re-measures the state. ``t`` is the
    numpy step-counter array itself, writable in place as in the numpy core. ``status``:
    each agent's status ``(B, N)`` int8 as last given to ``set_status`` (``None``
    before). An :class:`~swarm_envs.envs.protocol.Execution` under its
    :class:`~swarm_envs.envs.task.layer.TaskLayer` ``task``.

    >>> from swarm_envs.config import SwarmConfig
    >>> from swarm_envs.envs.task import STAT_KEYS
    >>> core = TorchSwarmNavCore(SwarmConfig(n_agents=4), batch=2, compile=False)
    >>> core.reset(np.random.default_rng(0))
    >>> reward, terminated, truncated, stats = core.step(np.zeros((2, 4, 2)))
    >>> core.observe().shape, reward.shape, list(stats) == list(STAT_KEYS)
    ((2, 4, 34), (2,), True)
    """

    backend = "torch"

    def __init__(
        self,
        cfg: SwarmConfig,
        batch: int = 1,
        dtype: Any = np.float32,
        device: Any = "cpu",
        compile: bool | str = "auto",
    ) -> None:
        reason = self.unsupported(cfg)
        if reason is not None:
            raise ValueError(f"TorchSwarmNavCore: {reason}")
        self.cfg = cfg
        self.batch = check_batch(batch)
        self.dtype, self._tdtype = _torch_dtype(dtype)
        self.device = _device(device)
        B, N, d = self.batch, cfg.n_agents, cfg.dim
        self.obs_dim = observation_size(cfg)
        self.t = np.zeros(B, np.int64)
        self._columns = StatisticColumns(self.dtype)
        zeros = self._zeros
        # State component first, (d, B, N): the layout the fused step vectorises.
        # With "implicit_damping_euler" the force carries two rows more: each agent's
        # implicit damping (b_i, w_i) (build_advance).
        rows = d + 2 * int(cfg.integrator == "implicit_damping_euler")
        self._x, self._v, self._f = zeros(d, B, N), zeros(d, B, N), zeros(rows, B, N)
        self._goal = zeros(B, d)
        P = len(PACKED_KEYS)
        #: The task above this core; its previous and start rows stay on the device.
        self.task = TaskLayer(cfg, self.batch, PackedRecords(zeros(B, P), zeros(B, P)))
        self._no_action = zeros(B, N, d)
        self._one_each, self._none_each = self._zeros(B) + 1.0, zeros(B)
        # Every swarm's substep: dt when it takes the step in one, 0 to only measure it.
        self._dt_each, self._no_step = zeros(B) + cfg.dt, zeros(B)
        self._one_needed = np.ones(B)
        wide, device = torch.float64, self.device
        # A step's first time left, substeps taken and needed (float64; distinct tensors:
        # the compiled substep function is specialised on which arguments alias).
        self._wide_start = (
            torch.full((B,), cfg.dt, dtype=wide, device=device),
            torch.zeros(B, dtype=wide, device=device),
            torch.zeros(B, dtype=wide, device=device),
        )
        # The substeps statistic of the current state (the last step's count, 0 after a
        # reset), and the swarms its step truncated as unstable (host indices, or None).
        self._counted = self._none_each
        self._flagged: np.ndarray | None = None
        self._statuses = DeviceStatuses(cfg, self.batch, self.device)
        self._before: State = (self._x, self._v)  # the state before the last step
        self._compile_request = compile
        self._advance = self._build(self.batch, compile, "TorchSwarmNavCore.step")
        self._substep = self._build(
            self.batch, self._advance.compiled, "TorchSwarmNavCore.substep", build_substep
        )
        self._obs = torch.empty(0)
        self._obs_given = False  # observe() handed out the current observations
        self._obs_shared = False  # observe_tensor() did
        self._packed = torch.empty(0)
        self._packed_host: np.ndarray = np.empty((0, P))
        self._calm = True
        self._reward = torch.empty(0)
        self._graphed: CudaGraphed | None = None
        self._measure(warmup=True)
        self._substep.warmup(*self._substep_inputs(self._no_action))
        if self.device.type == "cuda" and self._advance.compiled:
            # One replay instead of a launch per kernel (captured here, never in a step).
            self._graphed = CudaGraphed(self._advance, self._args(self._no_action, self._no_step))
            self._measure()
        # Resets of a few swarms measure only those, through the same function compiled
        # for a sub-batch of `reset_batch` swarms (padded): in a VecEnv some swarm ends
        # on most steps, and measuring all B swarms each time would double the step.
        self.reset_batch = partial_reset_batch(self.batch)
        self._advance_part: MaybeCompiled | None = None
        if self.reset_batch is not None:
            self._advance_part = self._build(
                self.reset_batch, self._advance.compiled, "TorchSwarmNavCore.reset"
            )
            some = torch.zeros(self.reset_batch, dtype=torch.int64, device=self.device)
            self._advance_part.warmup(*self._row_args(some))

    @staticmethod
    def unsupported(cfg: SwarmConfig) -> str | None:
        """Why this core cannot run ``cfg`` (``None`` if it can)."""
        if cfg.dynamics != "social_potential":
            return f"supports dynamics='social_potential' only, got {cfg.dynamics!r}"
        if cfg.integrator not in ("semi_implicit_euler", "implicit_damping_euler"):
            return (
                "supports integrator='semi_implicit_euler' or 'implicit_damping_euler' "
                f"only, got {cfg.integrator!r}"
            )
        if cfg.informs_agents:
            return "does not write the informed agents' observation (task='informed')"
        if cfg.task_spec.statistics:
            return f"does not carry task {cfg.task!r}'s own statistics"
        return None

    def _build(
        self, batch: int, compile: bool | str, name: str, build: Any = build_advance
    ) -> MaybeCompiled:
        """The fused function (or, with ``build=build_substep``, the substep function)
        for ``batch`` swarms, compiled or plain.

        The neighbour indices come from ``nearest_neighbors``, always in range: no bound
        checks on the gathers. The graph keeps the order of the Python code (no
        ``reorder_for_locality``, which moves each computation next to its first use):
        TorchInductor fuses only reductions that lie close in that order, and the pair
        sums of the force, the energy and the stable substep's rates then share one loop
        and its exponentials. On the CPU a small step (at most
        :data:`SINGLE_THREAD_PAIRS` pair evaluations) is generated for one thread.
        The core builds every argument itself, always of the same shapes, dtypes and
        device: after the first call, the compiled graph is called directly, without
        TorchDynamo's per-call guards (``direct=True``).
        """
        options: dict[str, Any] = {
            "assert_indirect_indexing": False,
            "reorder_for_locality": False,
        }
        if self.device.type == "cpu" and batch * self.cfg.n_agents**2 <= SINGLE_THREAD_PAIRS:
            options["cpp.threads"] = 1
        return MaybeCompiled(
            build(self.cfg),
            compile=compile,
            device=self.device,
            name=name,
            options=options,
            key=(name, repr(self.cfg), batch, str(self.dtype), str(self.device)),
            direct=True,
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
        """What runs the step: ``"compiled"`` or ``"plain"``."""
        return "compiled" if self._advance.compiled else "plain"

    @property
    def compile_seconds(self) -> float | None:
        """Wall time of the constructor's first calls (the compile time when compiled):
        the step's function and the substep function, plus the partial reset's when
        there is one."""
        seconds = self._advance.compile_seconds
        for other in (self._substep, self._advance_part):
            if seconds is not None and other is not None and other.compile_seconds is not None:
                seconds += other.compile_seconds
        return seconds

    def _args(self, a: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The fused function's arguments for the whole batch (``h``: each swarm's
        substep, 0 to only measure it)."""
        return (
            self._x,
            self._v,
            self._f,
            self._goal,
            a,
            h,
            self._counted,
            self.task.records.prev,
            self.task.records.start,
            *self._statuses.args(),
        )

    def _run(
        self,
        a: torch.Tensor,
        h: torch.Tensor,
        warmup: bool = False,
    ) -> None:
        """The fused function on the whole batch; the swarms :attr:`_flagged` keep their
        ``unstable`` mark."""
        args = self._args(a, h)
        if self._graphed is not None:
            # The graph's outputs are overwritten by its next replay: the state is only
            # read before then (or passed back in); what is kept or handed out is copied.
            self._x, self._v, self._f, obs, packed, rew, _ = self._graphed(*args)
            self._obs, self._packed, self._reward = obs.clone(), packed.clone(), rew.clone()
        else:
            out = self._advance.warmup(*args) if warmup else self._advance(*args)
            self._x, self._v, self._f, self._obs, self._packed, self._reward, _ = out
        if self._flagged is not None:  # a fresh tensor (or the graph's output's copy)
            rows = torch.as_tensor(self._flagged, device=self.device)
            self._packed[rows, UNSTABLE] = 1.0
        self._host_packed()
        self._obs_given = self._obs_shared = False

    def _measure(self, warmup: bool = False) -> None:
        """Observations, statistics and passive force of the current state (no step)."""
        self._run(self._no_action, self._no_step, warmup=warmup)

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
        return self._to_device(check_actions(actions, shape))

    def advance(self, actions: Any) -> Advance:
        """One step of every swarm (:meth:`Execution.advance
        <swarm_envs.envs.protocol.Execution.advance>`); ``actions`` ``(B, N, d)`` in
        [−1, 1], validated by :func:`~swarm_envs.envs.common.check_actions` (a torch
        tensor is checked the same way on its device). The reward is the fused step's."""
        a = self._actions(actions)
        self._before, over, needed = self._integrate(a)
        reward = self._reward.cpu().numpy().astype(np.float64)
        suspect = over is not None or not self._calm
        return Advance(self.stats(), self._packed, None, reward, over, needed, suspect)

    def undo(self, idx: np.ndarray, mark: bool) -> dict[str, np.ndarray]:
        """The swarms ``idx`` back at their state before the step, re-measured
        (:meth:`Execution.undo <swarm_envs.envs.protocol.Execution.undo>`); a mark
        stays through re-measures until the next step or reset."""
        rows = torch.as_tensor(idx, device=self.device)
        x0, v0 = self._before
        self._x, self._v = self._x.clone(), self._v.clone()  # out of place, as a reset
        self._x[:, rows], self._v[:, rows] = x0[:, rows], v0[:, rows]
        self._counted = self._counted.index_put((rows,), self._none_each[rows])  # undone
        self._flagged = idx if mark else None
        self._measure()
        return self.stats()

    def measured(self) -> torch.Tensor:
        """The current packed rows ``(B, P)`` on the device (a measure makes new ones)."""
        return self._packed

    def _host_packed(self, whole: bool = True) -> None:
        """Copy the packed rows to the host, and note whether every swarm's state is
        finite and allows the whole ``dt`` in one substep (:attr:`_calm`): the fused
        step's verdict on the batch when it measured all of it (``whole``), else
        recomputed from each row's ``h_guard``."""
        packed = self._packed_host = self._packed.cpu().numpy()
        if whole:
            self._calm = bool(packed[0, _CALM])
        else:  # NaN (a non-finite state) compares False
            self._calm = bool((packed[:, _H_GUARD] >= np.float64(self.cfg.dt)).all())

    def _integrate(self, a: torch.Tensor) -> tuple[State, np.ndarray | None, np.ndarray]:
        """Advance every swarm by ``dt`` with actions ``a`` and measure the new state.

        Returns the state before the step (for :meth:`undo`), where a swarm needed more
        substeps than ``max_substeps`` (``None``: nowhere) and how many it needed.
        """
        self._flagged = None
        before = (self._x, self._v)
        if self._calm:  # every swarm takes dt in one substep: the fused step alone
            self._counted = self._one_each
            self._run(a, self._dt_each)
            if self._graphed is not None:  # its outputs were overwritten, not its inputs
                before = self._graphed.inputs[0], self._graphed.inputs[1]
            return before, None, self._one_needed
        if self._graphed is not None:  # graph outputs: the last substep overwrites them
            before = before[0].clone(), before[1].clone()
        over, needed = self._substeps(a)
        return before, over, needed

    def _substep_inputs(self, a: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The substep function's arguments for the first substep of a step with
        actions ``a``."""
        remaining, used, needed = self._wide_start  # never written: shared by the steps
        no_swarm = torch.zeros(self.batch, dtype=torch.bool, device=self.device)
        h_stable = self._packed[:, _H_STABLE].contiguous()
        x, v, f, goal = self._x, self._v, self._f, self._goal
        status = self._statuses.args()
        return (x, v, f, goal, a, h_stable, remaining, used, no_swarm, needed, *status)

    def _substeps(self, a: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
        """Take the step's substeps, every swarm until its ``dt`` is spent (at most
        ``max_substeps``): all but each swarm's last through the substep function (with
        one host read per substep), the last ones in the fused step, which measures
        the new state. Sets the state and :attr:`_counted`; returns ``(over_cap,
        needed)`` per swarm on the host, as the numpy core counts them."""
        inputs = self._substep_inputs(a)
        x, v, f, goal, _, h_stable, remaining, used, over, needed, *status = inputs
        for _ in range(self.cfg.max_substeps):
            x, v, f, h_stable, remaining, used, over, needed, more, last = self._substep(
                x, v, f, goal, a, h_stable, remaining, used, over, needed, *status
            )
            if not bool(more):
                break
        else:  # the cap leaves at most max_substeps - 1 substeps before the last
            raise RuntimeError("substeps left after max_substeps substeps")
        h, self._counted, counts = last
        self._x, self._v, self._f = x, v, f
        self._run(a, h)  # the last substeps (h > 0), and the measure of every swarm
        over_cap, needed = counts.cpu().numpy()
        return over_cap > 0, needed

    # ------------------------------------------------------------------ starts
    def begin(
        self,
        idx: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray,
        rng: np.random.Generator,
    ) -> dict[str, np.ndarray]:
        """New starts for the swarms ``idx`` (:meth:`Execution.begin
        <swarm_envs.envs.protocol.Execution.begin>`), moved to the device out of place
        (the old tensors may share memory with arrays handed out) and measured: alone
        for a few swarms (at most :attr:`reset_batch`)."""
        rows = torch.as_tensor(idx, device=self.device)
        # No step yet for these swarms; the others keep their last step's substeps.
        self._counted = self._counted.index_put((rows,), self._none_each[rows])
        self._flagged = None
        self._x = self._put(self._x, rows, x)
        self._v = self._put(self._v, rows, v)
        self._goal = self._goal.index_put((rows,), self._to_device(goal))
        self._measure_some(rows)
        return self.stats()

    def _put(self, state: torch.Tensor, rows: torch.Tensor, new: np.ndarray) -> torch.Tensor:
        """A copy of ``state`` ``(d, B, N)`` with swarms ``rows`` set from ``new`` ``(n, N, d)``."""
        out = state.clone()
        out[:, rows] = self._to_device(new).permute(2, 0, 1)
        return out

    def _measure_some(self, rows: torch.Tensor) -> None:
        """Measure the swarms ``rows`` again: alone where they are few enough
        (:meth:`_measure_rows`), else with the whole batch (the others alike)."""
        if self.reset_batch is not None and rows.shape[0] <= self.reset_batch:
            self._measure_rows(rows)
        else:
            self._measure()

    def _row_args(self, rows: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The fused function's arguments for swarms ``rows`` only, measuring (no step)."""
        n = rows.shape[0]
        records = self.task.records
        return (
            self._x[:, rows],
            self._v[:, rows],
            self._f[:, rows],
            self._goal[rows],
            self._no_action[:n],
            self._no_step[:n],
            self._counted[rows],
            records.prev[rows],
            records.start[rows],
            *self._statuses.args(rows),
        )

    def _measure_rows(self, rows: torch.Tensor) -> None:
        """:meth:`_measure` for swarms ``rows`` (at most :attr:`reset_batch`) only.

        The rows are padded to ``reset_batch`` with copies of the first; the results of
        the real ones are written into the force, observations and statistics; the
        ``unstable`` statistic of every swarm but those :attr:`_flagged` becomes 0, as
        the measure of the whole batch makes it (a reset clears the flags first).
        """
        assert self._advance_part is not None and self.reset_batch is not None
        n = rows.shape[0]
        padded = torch.cat([rows, rows[:1].expand(self.reset_batch - n)])
        _, _, f, obs, packed, _, _ = self._advance_part(*self._row_args(padded))
        self._f = self._f.clone()
        self._f[:, rows] = f[:, :n]
        if self._obs_given or self._obs_shared:  # handed out: leave that memory alone
            self._obs = self._obs.clone()
            self._obs_given = self._obs_shared = False
        self._obs[rows] = obs[:n]
        self._packed = self._packed.index_put((rows,), packed[:n])  # a new tensor
        self._packed[:, UNSTABLE] = 0.0
        if self._flagged is not None:
            self._packed[torch.as_tensor(self._flagged, device=self.device), UNSTABLE] = 1.0
        self._host_packed(whole=False)

    # ------------------------------------------------------------------ statuses
    @property
    def status(self) -> np.ndarray | None:
        """Each agent's status ``(B, N)`` int8 as last given (``None`` before)."""
        return self._statuses.host

    def take_statuses(
        self, status: np.ndarray, place: np.ndarray | None, at: np.ndarray | None
    ) -> None:
        """Checked statuses ``(B, N)`` (:meth:`Execution.take_statuses
        <swarm_envs.envs.protocol.Execution.take_statuses>`), passed to both functions
        from now on.

        Raises:
            ValueError: the config needs no statuses (the core's functions were built
                without them).
        """
        self._statuses.take(status)
        device = self.device
        mobile = torch.as_tensor(masks(status).mobile, device=device)
        where = None if place is None else torch.as_tensor(place, device=device)
        at_t = None
        if place is not None:
            assert at is not None  # status_update gives the places with the agents placed
            # (d, B, N) stored contiguous, as every state tensor the compiled functions
            # read: torch.where lays its result out as its inputs are, and a permuted view
            # would hand them another layout than they were traced for.
            at_t = self._to_device(np.ascontiguousarray(np.moveaxis(at, -1, 0)))
        xp = torch_namespace()
        self._x, self._v = placed_at_rest(
            self._x, self._v, mobile, where, at_t, xp, component_first=True
        )

    def remeasure(self, idx: np.ndarray) -> None:
        """Measure the swarms ``idx`` again (:meth:`Execution.remeasure
        <swarm_envs.envs.protocol.Execution.remeasure>`; the others' measure is alike)."""
        self._measure_some(torch.as_tensor(idx, device=self.device))

    # ------------------------------------------------------------------ views
    def stats(self) -> dict[str, np.ndarray]:
        """Group statistics and task measures per swarm, each ``(B,)`` (fresh arrays),
        in the numpy core's dtypes."""
        return self._columns.split(self._packed_host)

    def observe(self, which: np.ndarray | None = None) -> np.ndarray:
        """Local observations ``(B, N, obs_dim)``, float32, inside ``[−OBS_BOUND, OBS_BOUND]``.

        The layout of :mod:`swarm_envs.envs.task.observation`. Every call returns an
        array of the caller's own: the first after a step is the step's result itself
        (no copy on the CPU); a second call on the same state measures it again. From a
        GPU the observations are copied into page-locked host memory.

        ``which`` (bool mask ``(B,)``): the observations of those swarms only, ``(n, N,
        obs_dim)``, copied out.
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

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        """Config, options and state on the host; the (compiled) function is rebuilt."""
        return {
            "cfg": self.cfg,
            "batch": self.batch,
            "dtype": self.dtype,
            "device": str(self.device),
            "compile": self._compile_request,
            "t": self.t.copy(),
            "flagged": self._flagged,
            "status": None if self.status is None else self.status.copy(),
            "tensors": {
                name: getattr(self, name).detach().cpu()
                for name in ("_x", "_v", "_goal", "_counted")
            },
            "records": (self.task.records.prev.cpu(), self.task.records.start.cpu()),
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(  # type: ignore[misc]
            state["cfg"], state["batch"], state["dtype"], state["device"], state["compile"]
        )
        self.t, self._flagged = state["t"], state["flagged"]
        if state.get("status") is not None:
            self._statuses.take(state["status"])
        for name, tensor in state["tensors"].items():
            setattr(self, name, tensor.to(self.device))
        prev, start = (tensor.to(self.device) for tensor in state["records"])
        self.task.records = PackedRecords(prev, start)
        self._measure()
