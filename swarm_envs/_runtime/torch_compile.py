"""Running torch functions fast: ``torch.compile`` where it works, CUDA graphs on a GPU.

Runtime, not physics: the equations live in :mod:`swarm_envs.physics` and
:mod:`swarm_envs.envs.task` and run on torch tensors as they are; this module decides how
a function of them is executed.

- :class:`MaybeCompiled` wraps a function of tensors, run through ``torch.compile``
  (TorchInductor: C++/OpenMP on the CPU, which needs a C++ compiler, Triton on CUDA)
  or plainly. ``compile="auto"`` (the default) compiles where :func:`compile_support`
  finds it possible (else runs the plain function, warning once per reason) and falls
  back to the plain function, with a warning, if compiling fails; ``True`` requires it,
  ``False`` never compiles. The environment variable ``SWARM_ENVS_TORCH_COMPILE``
  (``0``/``1``/``auto``; ``0`` runs plain torch without a warning) overrides ``"auto"``. The compile
  time is measured by :meth:`MaybeCompiled.warmup`, logged once, and kept out of the
  timed steps.
  With ``direct=True`` (a core's step), calls after the warmup go to the compiled graph
  directly (:class:`DirectCall`), without TorchDynamo's per-call guards.
- :class:`CudaGraphed` captures a function of CUDA tensors once and replays it: one
  launch instead of one per kernel.
- :class:`SocialPotentialStepper`: the Euler step of
  :func:`swarm_envs.physics.integrators.step` for fixed parameters, compiled or plain.

>>> import torch
>>> from swarm_envs.physics import SocialPotentialParams
>>> x = torch.tensor([[0.0, 0.0], [1.0, 0.0]]); v = torch.zeros_like(x)
>>> stepper = SocialPotentialStepper(SocialPotentialParams(), dt=0.1, compile=False)
>>> x1, v1 = stepper(x, v)
>>> x1.shape, stepper.compiled
(torch.Size([2, 2]), False)
"""

from __future__ import annotations

import itertools
import logging
import os
import shutil
import time
import types
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import torch

from swarm_envs._runtime.direct_call import NOTED, DirectCall, graphs_run, warn_not_direct
from swarm_envs.physics.integrators import step
from swarm_envs.physics.social_potential import SocialPotentialParams

__all__ = [
    "COMPILE_ENV",
    "CudaGraphed",
    "MaybeCompiled",
    "SocialPotentialStepper",
    "compile_support",
    "resolve_compile",
]

logger = logging.getLogger(__name__)

#: Environment variable that overrides ``compile="auto"``: ``0``, ``1`` or ``auto``.
COMPILE_ENV = "SWARM_ENVS_TORCH_COMPILE"


# --------------------------------------------------------------------------- compiling


def compile_support(device: torch.device | str = "cpu") -> str | None:
    """``None`` if ``torch.compile`` can run on ``device`` here, else the reason it cannot.

    Needs TorchDynamo support for this Python, and a C++ compiler on the CPU (``CXX``,
    ``g++``, ``c++`` or ``clang++`` on the path) or Triton on CUDA.
    """
    device = torch.device(device)
    try:
        from torch import _dynamo

        if not _dynamo.is_dynamo_supported():
            return "TorchDynamo does not support this Python"
    except Exception as err:  # pragma: no cover - depends on the torch build
        return f"torch._dynamo unavailable ({err})"
    if device.type == "cpu":
        candidates = [os.environ.get("CXX", ""), "g++", "c++", "clang++"]
        if not any(c and shutil.which(c) for c in candidates):
            return "no C++ compiler found (CXX, g++, c++, clang++)"
        return None
    if device.type == "cuda":
        try:
            from torch.utils._triton import has_triton
        except ImportError:  # pragma: no cover - depends on the torch build
            return "cannot check for Triton"
        return None if has_triton() else "Triton is not installed"
    return f"torch.compile is not supported here on device type {device.type!r}"


def resolve_compile(compile: bool | str, device: torch.device | str = "cpu") -> tuple[bool, str]:
    """Decide whether to compile: ``(compile?, why)``.

    ``True``/``False`` are obeyed (``True`` raises :class:`ValueError` if
    :func:`compile_support` says no). ``"auto"`` reads :data:`COMPILE_ENV` (``0``, ``1``,
    ``auto``; unset means ``auto``) and then compiles where it is supported.
    """
    if isinstance(compile, str):
        if compile != "auto":
            raise ValueError(f"compile must be True, False or 'auto', got {compile!r}")
        env = os.environ.get(COMPILE_ENV, "auto").strip().lower() or "auto"
        if env in ("0", "false", "no", "off"):
            return False, f"{COMPILE_ENV}={env}"
        if env in ("1", "true", "yes", "on"):
            compile = True
        elif env != "auto":
            raise ValueError(f"{COMPILE_ENV} must be 0, 1 or auto, got {env!r}")
    elif not isinstance(compile, bool):
        raise ValueError(f"compile must be True, False or 'auto', got {compile!r}")
    reason = compile_support(device)
    if compile is True:
        if reason is not None:
            raise ValueError(f"compile=True but torch.compile is unavailable: {reason}")
        return True, "requested"
    if compile is False:
        return False, "compile=False"
    return (reason is None), ("supported" if reason is None else reason)


_WARNED: set[str] = set()


def _warn_not_compiled(reason: str) -> None:
    """Warn once per reason that ``compile="auto"`` runs plain torch (not where
    :data:`COMPILE_ENV` switched compiling off on purpose)."""
    if reason.startswith(COMPILE_ENV) or reason in _WARNED:
        return
    _WARNED.add(reason)
    warnings.warn(
        f"torch.compile unavailable ({reason}); running plain torch "
        f"(set {COMPILE_ENV}=0 to choose that without this warning)",
        UserWarning,
        stacklevel=4,
    )


_COPIES = itertools.count()
_CODE_FOR: dict[tuple[Any, Any], types.CodeType] = {}


def _own_code(fn: Callable[..., Any], key: Any = None) -> Callable[..., Any]:
    """``fn`` with a code object of its own per ``key`` (same behaviour, a numbered name).

    TorchDynamo caches compiled graphs per code object and, past its recompile limit
    (8 per code object), refuses to compile more (with ``fullgraph=True`` it raises).
    Closures built by one factory share their code, so the ninth differently-shaped or
    differently-configured core in a process (a benchmark sweep, a test session) would
    lose its compilation. Functions with equal ``key`` (``None``: never equal) share one
    copy, so that an identical second instance reuses the compiled graph.
    """
    if not isinstance(fn, types.FunctionType):
        return fn
    cache_key = (fn.__code__, key)
    code = _CODE_FOR.get(cache_key) if key is not None else None
    if code is None:
        name = f"{fn.__code__.co_name}_{next(_COPIES)}"
        code = fn.__code__.replace(co_name=name, co_qualname=name)
        if key is not None:
            _CODE_FOR[cache_key] = code
    own = types.FunctionType(code, fn.__globals__, code.co_name, fn.__defaults__, fn.__closure__)
    own.__kwdefaults__ = fn.__kwdefaults__
    return own


class MaybeCompiled:
    """A function run through ``torch.compile`` or plainly; the choice is automatic.

    Args:
        fn: a function of tensors (traced as one graph: no graph breaks allowed).
        compile: ``"auto"``, ``True`` or ``False`` (see :func:`resolve_compile`).
        device: where the tensors will live (decides the compiler backend).
        name: a label for the compile-time log line.
        options: TorchInductor options for this function only (``torch.compile``'s
            ``options``), e.g. ``{"assert_indirect_indexing": False}``.
        key: a hashable description of what ``fn`` closes over (configuration, shapes):
            instances with equal keys share compiled graphs; ``None`` shares nothing.
        direct: after :meth:`warmup`, call the compiled graph that TorchDynamo chose
            for the warmup's arguments directly (:class:`DirectCall`), without Dynamo's
            per-call guards. Only for a pure function (it writes none of its arguments)
            whose caller builds every argument itself, always of the warmup's shapes,
            dtypes and device, as a core does with its step: a call with other
            arguments is not checked (TorchInductor still asserts sizes and strides).
            The guards run in the warmup call, so a changed library function is seen
            by the next instance built.

    Attributes:
        compiled: whether calls run the compiled function.
        reason: why (``"supported"``, ``"compile=False"``, a fallback's error, ...).
        compile_seconds: wall time of the first (compiling) call made by :meth:`warmup`;
            ``None`` before it, and for the plain function the time of a plain call.

    Compilation happens on the first call with new shapes; call :meth:`warmup` once
    with representative arguments to keep it out of timed work. Shapes are static
    (``dynamic=False``): new shapes recompile.
    """

    def __init__(
        self,
        fn: Callable[..., Any],
        *,
        compile: bool | str = "auto",
        device: torch.device | str = "cpu",
        name: str = "",
        options: dict[str, Any] | None = None,
        key: Any = None,
        direct: bool = False,
    ) -> None:
        self.fn = fn
        self.name = name or getattr(fn, "__name__", "function")
        self._auto = compile == "auto"
        self.compiled, self.reason = resolve_compile(compile, device)
        if self._auto and not self.compiled:
            _warn_not_compiled(self.reason)
        self.device = torch.device(device)
        self._direct_wanted = direct
        self._direct: DirectCall | None = None
        self._call = self.fn
        if self.compiled:
            own = _own_code(fn, key)
            if direct:
                backend = graphs_run(options)
                self._call = torch.compile(own, dynamic=False, fullgraph=True, backend=backend)
            else:
                self._call = torch.compile(own, dynamic=False, fullgraph=True, options=options)
        self.compile_seconds: float | None = None

    @property
    def direct(self) -> bool:
        """Whether calls go to the compiled graph directly (see ``direct``)."""
        return self._direct is not None

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if self._direct is not None and not kwargs and len(args) == self._direct.arity:
            return self._direct(args)
        return self._call(*args, **kwargs)

    def warmup(self, *args: Any, **kwargs: Any) -> Any:
        """Call once (compiling if compiled), time it, log it once, and return the result.

        With ``compile="auto"`` a failure to compile (no working compiler, an unsupported
        operation) falls back to the plain function with a :class:`UserWarning`.
        """
        start = time.perf_counter()
        NOTED.last = None
        try:
            out = self._call(*args, **kwargs)
            self._sync()
        except Exception as err:
            if not (self.compiled and self._auto):
                raise
            warnings.warn(
                f"{self.name}: torch.compile failed ({type(err).__name__}: {err}); "
                "falling back to plain torch",
                UserWarning,
                stacklevel=2,
            )
            self.compiled, self.reason, self._call = False, f"fallback: {err}", self.fn
            start = time.perf_counter()
            out = self._call(*args, **kwargs)
            self._sync()
        seconds = time.perf_counter() - start
        if self._direct_wanted and self.compiled and not kwargs:
            self._direct, why = DirectCall.of(
                getattr(NOTED, "last", None), self.fn, self._call, args, out, self.name
            )
            if self._direct is None:
                warn_not_direct(self.name, why)
        if self.compile_seconds is None:
            self.compile_seconds = seconds
            if self.compiled:
                logger.info("%s: torch.compile took %.1f s (%s)", self.name, seconds, self.device)
        return out

    def _sync(self) -> None:
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)


class CudaGraphed:
    """A function of CUDA tensors, captured once as a CUDA graph and replayed.

    A compiled step is a couple of dozen GPU kernels; launched one by one from Python
    they cost far more host time than the GPU needs to run them (benchmarks/gpu.py). A
    replay launches them all at once. The function must take and return tensors of
    fixed shapes and make no host synchronisation.

    ``graphed(*args)`` copies ``args`` into the graph's own input tensors, replays, and
    returns the graph's own output tensors: the next call overwrites them, so a caller
    copies whatever it keeps longer (reading them until the next call is fine, and so is
    passing them back as the next call's arguments).

    Args:
        fn: the function (compiled or not); it is run twice on a side stream to warm
            up, then captured.
        example: arguments of the shapes, dtypes and device of every later call.
    """

    def __init__(self, fn: Callable[..., Any], example: Sequence[torch.Tensor]) -> None:
        self._inputs = [t.clone() for t in example]
        side = torch.cuda.Stream(device=self._inputs[0].device)
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            for _ in range(2):
                fn(*self._inputs)
        torch.cuda.current_stream().wait_stream(side)
        self._graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self._graph):
            self._outputs = fn(*self._inputs)

    @property
    def inputs(self) -> list[torch.Tensor]:
        """The graph's own input tensors: after a call, the arguments it was given (until
        the next call copies new ones in)."""
        return self._inputs

    def __call__(self, *args: torch.Tensor) -> Any:
        for static, arg in zip(self._inputs, args, strict=True):
            if static is not arg:
                static.copy_(arg)
        self._graph.replay()
        return self._outputs


class SocialPotentialStepper:
    """``(x, v) → (x', v')``: :func:`step` for fixed parameters and ``dt``, compiled or plain.

    Args:
        params: model parameters (constants of the compiled code).
        dt: time step, ``> 0``.
        compile: ``"auto"``, ``True`` or ``False`` (see :func:`resolve_compile`).
        device: where the state lives.

    ``stepper(x, v, goal=None, control=None)`` takes tensors shaped ``(..., N, d)``.
    Call :meth:`warmup` once with representative tensors to compile outside timed code;
    :attr:`compile_seconds` then holds the compile time.
    """

    def __init__(
        self,
        params: SocialPotentialParams,
        dt: float,
        *,
        compile: bool | str = "auto",
        device: torch.device | str = "cpu",
    ) -> None:
        if not isinstance(params, SocialPotentialParams):
            raise ValueError(f"params must be SocialPotentialParams, got {type(params).__name__}")
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not dt > 0:
            raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
        self.params, self.dt = params, float(dt)
        dt = self.dt

        def euler_step(
            x: torch.Tensor,
            v: torch.Tensor,
            goal: torch.Tensor | None = None,
            control: torch.Tensor | None = None,
        ) -> tuple[torch.Tensor, torch.Tensor]:
            return step(x, v, params, dt=dt, goal=goal, control=control)

        self._fn = MaybeCompiled(
            euler_step,
            compile=compile,
            device=device,
            name="euler_step",
            key=("euler_step", repr(params), dt, str(device)),
        )

    @property
    def compiled(self) -> bool:
        """Whether the steps run compiled."""
        return self._fn.compiled

    @property
    def compile_seconds(self) -> float | None:
        """Time of the :meth:`warmup` call (the compile time when compiled)."""
        return self._fn.compile_seconds

    def __call__(
        self,
        x: torch.Tensor,
        v: torch.Tensor,
        goal: torch.Tensor | None = None,
        control: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        return self._fn(x, v, goal, control)

    def warmup(
        self,
        x: torch.Tensor,
        v: torch.Tensor,
        goal: torch.Tensor | None = None,
        control: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One step that compiles (timed into :attr:`compile_seconds`)."""
        return self._fn.warmup(x, v, goal, control)
