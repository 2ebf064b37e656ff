"""The social potential model in PyTorch: forces, energy, one Euler step; compiled or plain.

The same equations as :mod:`swarm_envs.physics.social_potential` (MODELS.md §1, Mabrouk &
McInnes), over torch tensors shaped ``(..., N, d)`` (any leading batch dimensions, ``N``
agents, ``d = 2`` or ``3``), on any device torch runs on (CPU, CUDA), in the tensors'
dtype. With ``r_ij = r_j − r_i``, ``ρ_ij = |r_ij|``, ``u_ij = r_ij/ρ_ij``:

``F_i = Σ_{j≠i} [ (C_a/l_a) e^{−ρ_ij/l_a} − (C_r/l_r) e^{−ρ_ij/l_r}
− C_o ((v_i − v_j)·u_ij) e^{−ρ_ij/l_o} ] u_ij − β v_i + F_goal_i``

(cohesion eq. 10, alignment eq. 11, dissipation eq. 12, goal sink eqs. 19–20 as the
gradient of eq. 19), the total energy φ of eq. 16, and the semi-implicit (symplectic)
Euler step ``v' = v + dt (F(x, v) + u)/m``, ``x' = x + dt v'`` of
:func:`swarm_envs.physics.integrators.step` (the SwarmNav core's default integrator).

Coincident agents follow the numpy module's convention: distances are floored at
:data:`~swarm_envs.physics.social_potential.RHO_FLOOR` before dividing and ``r_ij = 0``
makes the pair's force zero (``u_ij = 0``); their pair energy is ``U(0) = C_r − C_a``.
Nothing returns NaN for finite input.

Compiled or plain. Every pairwise term is an ``(..., N, N)`` tensor expression; run
plainly, torch evaluates each operation as its own pass over memory (about 1.5 M
agent-steps/s at 1024 swarms × 32 agents on a 2-core CPU). Through ``torch.compile``
(TorchInductor) the whole force evaluation and the Euler update fuse into one loop over
the pairs that keeps each pair's terms in registers: C++/OpenMP on the CPU (a C++
compiler must be installed), Triton on CUDA. :class:`MaybeCompiled` wraps a function
either way; ``compile="auto"`` (the default) compiles where :func:`compile_support`
finds it possible and falls back to the plain function, with a warning, if compiling
fails; ``True`` requires it, ``False`` never compiles. The environment variable
``SWARM_ENVS_TORCH_COMPILE`` (``0``/``1``/``auto``) overrides ``"auto"`` (``0`` is handy
to skip compile time in CI). The compile time is measured by :meth:`MaybeCompiled.warmup`,
logged once, and kept out of the timed steps.

>>> x = torch.tensor([[0.0, 0.0], [1.0, 0.0]]); v = torch.zeros_like(x)
>>> f = forces(x, v, SocialPotentialParams())
>>> bool(torch.allclose(f[0], -f[1]))  # pair forces are antisymmetric
True
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
from typing import Any, NamedTuple

import torch

from swarm_envs.physics._validation import SUPPORTED_DIMS
from swarm_envs.physics.social_potential import RHO_FLOOR, SocialPotentialParams

__all__ = [
    "COMPILE_ENV",
    "CudaGraphed",
    "MaybeCompiled",
    "SocialPotentialStepper",
    "TorchPairGeometry",
    "compile_support",
    "energy",
    "forces",
    "goal_force",
    "goal_potential",
    "kinetic_energy",
    "pair_energy",
    "pair_force",
    "pair_geometry",
    "potential_energy",
    "resolve_compile",
    "step",
]

logger = logging.getLogger(__name__)

#: Environment variable that overrides ``compile="auto"``: ``0``, ``1`` or ``auto``.
COMPILE_ENV = "SWARM_ENVS_TORCH_COMPILE"


# --------------------------------------------------------------------------- checks


def _check_state(x: Any, v: Any | None = None) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Floating tensors shaped ``(..., N, d)``, ``d`` in {2, 3}; ``v`` like ``x``."""
    if not isinstance(x, torch.Tensor):
        raise ValueError(f"positions must be a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise ValueError(f"positions must be a floating tensor, got dtype {x.dtype}")
    if x.ndim < 2 or x.shape[-1] not in SUPPORTED_DIMS:
        raise ValueError(
            f"positions must have shape (..., N, d) with d in {SUPPORTED_DIMS}, "
            f"got {tuple(x.shape)}"
        )
    if v is None:
        return x, None
    if not isinstance(v, torch.Tensor):
        raise ValueError(f"velocities must be a torch.Tensor, got {type(v).__name__}")
    if v.shape != x.shape:
        raise ValueError(
            f"velocities shape {tuple(v.shape)} must equal positions shape {tuple(x.shape)}"
        )
    return x, v


def _check_goal(goal: Any, x: torch.Tensor) -> torch.Tensor:
    """``goal`` as a tensor broadcastable to ``x.shape[:-2] + (d,)``."""
    if not isinstance(goal, torch.Tensor):
        goal = torch.as_tensor(goal, dtype=x.dtype, device=x.device)
    if goal.ndim < 1 or goal.shape[-1] != x.shape[-1]:
        raise ValueError(
            f"goal must have shape (..., {x.shape[-1]}) broadcastable to the batch "
            f"{tuple(x.shape[:-2])}, got {tuple(goal.shape)}"
        )
    return goal


# --------------------------------------------------------------------------- geometry


class TorchPairGeometry(NamedTuple):
    """Pairwise offsets and distances of one set of positions (torch twin of ``PairGeometry``).

    ``dx[k]`` is ``r_ij[..., k] = x_j[k] − x_i[k]`` and ``rho`` is ``ρ_ij``, each
    ``(..., N, N)`` with zeros on the diagonal. Separate components (not one
    ``(..., N, N, d)`` tensor) let a compiler fuse each pair's terms into one loop.
    """

    dx: list[torch.Tensor]
    rho: torch.Tensor


def pair_geometry(x: torch.Tensor | Sequence[torch.Tensor]) -> TorchPairGeometry:
    """The :class:`TorchPairGeometry` of positions ``x`` shaped ``(..., N, d)``.

    ``x`` may also be the list of its ``d`` components, each ``(..., N)`` (a compiler
    vectorises contiguous components best). ``ρ_ij = sqrt(Σ_k (x_j[k] − x_i[k])²)`` is
    0 on the diagonal and symmetric.
    """
    xs = _components(x)
    dx = [c[..., None, :] - c[..., :, None] for c in xs]
    rho2 = dx[0] * dx[0]
    for k in range(1, len(dx)):
        rho2 = rho2 + dx[k] * dx[k]
    return TorchPairGeometry(dx, torch.sqrt(rho2))


def _components(a: torch.Tensor | Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """``[a[..., 0], ..., a[..., d−1]]`` for a tensor; a list of components as it is."""
    if isinstance(a, torch.Tensor):
        return [a[..., k] for k in range(a.shape[-1])]
    return list(a)


def _decay(rho: torch.Tensor, length: float) -> torch.Tensor:
    """``e^{−ρ/length}``, computed as numpy's ``exp(ρ · (−1/length))``."""
    return torch.exp(rho * (-1.0 / length))


# --------------------------------------------------------------------------- forces


def goal_force(x: torch.Tensor, params: SocialPotentialParams, goal: Any) -> torch.Tensor:
    """Goal-sink force, the gradient of eq. 19 (MODELS.md §1).

    ``F_goal_i = (C_g/l_g) e^{−|r_g − r_i|/l_g} (r_g − r_i)/|r_g − r_i|``.
    Shape ``(..., N, d)`` like ``x``; ``goal`` broadcasts against ``(..., d)``. An agent
    exactly on the goal feels no force (distance floored at ``RHO_FLOOR``).
    """
    x, _ = _check_state(x)
    offset = _check_goal(goal, x)[..., None, :] - x
    dist = torch.sqrt((offset * offset).sum(-1))
    scale = (params.C_g / params.l_g) * torch.exp(-dist / params.l_g)
    scale = scale / torch.clamp(dist, min=RHO_FLOOR)
    return offset * scale[..., None]


def pair_force(
    geometry: TorchPairGeometry,
    v: torch.Tensor | Sequence[torch.Tensor],
    params: SocialPotentialParams,
) -> tuple[list[torch.Tensor], dict[float, torch.Tensor]]:
    """Pair part of eq. 14, ``Σ_j s_ij r_ij``, per component, and the decays it computed.

    ``s_ij = [ (C_a/l_a) e^{−ρ/l_a} − (C_r/l_r) e^{−ρ/l_r}
    − C_o ((v_i − v_j)·r_ij/ρ) e^{−ρ/l_o} ] / ρ`` with ``ρ`` floored at ``RHO_FLOOR``
    (cohesion eq. 10, alignment eq. 11). ``v`` is ``(..., N, d)`` or its components.
    Returns ``([F_0, ..., F_{d−1}] each (..., N), {l: e^{−ρ/l}})``; the pair energy at
    the same positions can reuse ``e^{−ρ/l_a}`` and ``e^{−ρ/l_r}``.
    """
    p = params
    dx, rho = geometry.dx, geometry.rho
    vs = _components(v)
    inv_rho = 1.0 / torch.clamp(rho, min=RHO_FLOOR)
    decays = {p.l_a: _decay(rho, p.l_a)}
    decays.setdefault(p.l_r, _decay(rho, p.l_r))
    scalar = decays[p.l_a] * (p.C_a / p.l_a) - (p.C_r / p.l_r) * decays[p.l_r]
    if p.C_o > 0:
        decays.setdefault(p.l_o, _decay(rho, p.l_o))
        proj = (vs[0][..., :, None] - vs[0][..., None, :]) * dx[0]
        for k in range(1, len(dx)):
            proj = proj + (vs[k][..., :, None] - vs[k][..., None, :]) * dx[k]
        scalar = scalar - proj * inv_rho * decays[p.l_o] * p.C_o
    scalar = scalar * inv_rho  # F_i = Σ_j scalar_ij r_ij
    return [(scalar * c).sum(-1) for c in dx], decays


def forces(
    x: torch.Tensor,
    v: torch.Tensor,
    params: SocialPotentialParams,
    goal: Any | None = None,
    *,
    geometry: TorchPairGeometry | None = None,
) -> torch.Tensor:
    """Total passive force on every agent (eq. 14 plus eq. 20's goal term), torch twin of
    :func:`swarm_envs.physics.forces`.

    ``F_i = Σ_{j≠i} [ (C_a/l_a) e^{−ρ_ij/l_a} − (C_r/l_r) e^{−ρ_ij/l_r}
    − C_o ((v_i − v_j)·u_ij) e^{−ρ_ij/l_o} ] u_ij − β v_i + F_goal_i``

    Args:
        x: positions ``(..., N, d)``, a floating tensor on any device.
        v: velocities, same shape.
        params: model parameters.
        goal: goal position broadcastable to ``(..., d)``; the sink acts when ``C_g > 0``.
        geometry: ``pair_geometry(x)`` if the caller has it.

    Returns:
        Forces shaped like ``x`` (not divided by the mass).
    """
    x, v = _check_state(x, v)
    assert v is not None
    geo = pair_geometry(x) if geometry is None else geometry
    total = torch.stack(pair_force(geo, v, params)[0], dim=-1)
    if params.beta > 0:
        total = total - params.beta * v
    if goal is not None:
        goal = _check_goal(goal, x)
        if params.C_g > 0:
            total = total + goal_force(x, params, goal)
    return total


# --------------------------------------------------------------------------- energy


def kinetic_energy(v: torch.Tensor, params: SocialPotentialParams) -> torch.Tensor:
    """``Σ_i ½ m |v_i|²``, shaped ``(...)``."""
    return 0.5 * params.m * (v * v).sum((-2, -1))


def goal_potential(x: torch.Tensor, params: SocialPotentialParams, goal: Any) -> torch.Tensor:
    """Goal sink ``V_goal(r_i) = −C_g e^{−|r_i − r_g|/l_g}`` (eq. 19), shaped ``(..., N)``."""
    x, _ = _check_state(x)
    offset = _check_goal(goal, x)[..., None, :] - x
    dist = torch.sqrt((offset * offset).sum(-1))
    return -params.C_g * torch.exp(-dist / params.l_g)


def pair_energy(
    rho: torch.Tensor,
    params: SocialPotentialParams,
    decays: dict[float, torch.Tensor] | None = None,
) -> torch.Tensor:
    """``Σ_{i<j} U(ρ_ij)`` with ``U(ρ) = C_r e^{−ρ/l_r} − C_a e^{−ρ/l_a}`` (eq. 9), ``(...)``.

    As in numpy: all ordered pairs, minus the ``N`` diagonal terms ``U(0) = C_r − C_a``,
    halved, summed row by row first. ``decays`` are those of :func:`pair_force` at the
    same positions, if known (reused: fewer exponentials when run plainly).

    Under ``torch.compile``, leave ``decays`` out: the decays are then recomputed (as
    ``e^{ρ/(−l)}``, a different expression from :func:`pair_force`'s, so that the two
    are not merged into one shared tensor), and TorchInductor fuses this row sum into
    the force loop. Sharing the decays makes it store both ``(..., N, N)`` decays to
    memory and read them back, which costs more than two more exponentials.
    """
    if decays is None:
        e_r = torch.exp(rho / (-params.l_r))
        e_a = torch.exp(rho / (-params.l_a))
    else:
        e_r = decays[params.l_r] if params.l_r in decays else _decay(rho, params.l_r)
        e_a = decays[params.l_a] if params.l_a in decays else _decay(rho, params.l_a)
    u = params.C_r * e_r - params.C_a * e_a
    n = rho.shape[-1]
    return 0.5 * (u.sum(-1).sum(-1) - n * (params.C_r - params.C_a))


def potential_energy(
    x: torch.Tensor, params: SocialPotentialParams, goal: Any | None = None
) -> torch.Tensor:
    """``Σ_{i<j} U(ρ_ij) + Σ_i V_goal(r_i)`` (eqs. 9, 16, 19), shaped ``(...)``."""
    x, _ = _check_state(x)
    pairs = pair_energy(pair_geometry(x).rho, params)
    if goal is not None:
        goal = _check_goal(goal, x)
        if params.C_g > 0:
            pairs = pairs + goal_potential(x, params, goal).sum(-1)
    return pairs


def energy(
    x: torch.Tensor, v: torch.Tensor, params: SocialPotentialParams, goal: Any | None = None
) -> torch.Tensor:
    """Total energy φ (eq. 16): kinetic + pair potential + goal potential, shaped ``(...)``.

    With no control ``dφ/dt = −β Σ|v_i|² − ½ Σ_{i≠j} C_o ((v_ij·u_ij))² e^{−ρ_ij/l_o} ≤ 0``
    (eq. 18 as MODELS.md §1 reads it).

    >>> x = torch.tensor([[0.0, 0.0], [1.0, 0.0]], dtype=torch.float64)
    >>> p = SocialPotentialParams()
    >>> round(float(energy(x, torch.zeros_like(x), p)), 6)  # U(1) = 1.2 e^{-5} − e^{-1}
    -0.359794
    """
    x, v = _check_state(x, v)
    assert v is not None
    return kinetic_energy(v, params) + potential_energy(x, params, goal)


# --------------------------------------------------------------------------- step


def step(
    x: torch.Tensor,
    v: torch.Tensor,
    params: SocialPotentialParams,
    *,
    dt: float,
    goal: Any | None = None,
    control: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """One semi-implicit (symplectic) Euler step, torch twin of
    :func:`swarm_envs.physics.integrators.step`.

    ``v' = v + dt (F(x, v) + u)/m``, ``x' = x + dt v'``, with ``u = control`` (a force
    broadcastable to ``x``; ``None`` is the passive model). Returns new tensors.
    """
    accel = forces(x, v, params, goal)
    if control is not None:
        accel = accel + control
    if params.m != 1.0:
        accel = accel / params.m
    v_new = v + dt * accel
    return x + dt * v_new, v_new


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
    ) -> None:
        self.fn = fn
        self.name = name or getattr(fn, "__name__", "function")
        self._auto = compile == "auto"
        self.compiled, self.reason = resolve_compile(compile, device)
        self.device = torch.device(device)
        self._call = (
            torch.compile(_own_code(fn, key), dynamic=False, fullgraph=True, options=options)
            if self.compiled
            else self.fn
        )
        self.compile_seconds: float | None = None

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self._call(*args, **kwargs)

    def warmup(self, *args: Any, **kwargs: Any) -> Any:
        """Call once (compiling if compiled), time it, log it once, and return the result.

        With ``compile="auto"`` a failure to compile (no working compiler, an unsupported
        operation) falls back to the plain function with a :class:`UserWarning`.
        """
        start = time.perf_counter()
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
