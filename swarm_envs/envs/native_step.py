"""The fused SwarmNav step in C: the CPU kernel behind the torch core, built at first use.

:class:`NativeAdvance` is a function with the signature and results of
:func:`swarm_envs.envs.torch_core.build_advance`'s ``advance`` (the same equations: the
semi-implicit Euler step of MODELS.md §1 with the carried force, one pass over the pairs
of the new state for the forces of eqs. 10–12, the pair energy of eq. 9 and the
distances, the goal sink of eqs. 19–20, the k nearest neighbours, the observations, the
statistics of MODELS.md §2 and the reward), computed by ``native/fused_step.c`` for CPU
tensors of float32 or float64.

Why C: TorchInductor fuses the pair loop well (the physics alone runs at 34–39 M
agent-steps/s at 1,024 × 32 on the development machine) but not the rest of the step;
the observation's gathers, the k-nearest passes over a stored distance matrix and the
re-layout of the observation planes made its full step cost 4–5 times the physics. The C
kernel keeps each swarm in a few kilobytes of scratch memory (the distance matrix of 32
agents is 4 KB); it evaluates each pair once (16 × 16 tiles, the partners rotated across
the vector lanes, the force added to one agent and subtracted from the other), selects
the neighbours by insertion across 16 agents at a time (float32: on 64-bit keys, the
bits of ρ above the index, so the (ρ, j) order is integer order), and writes every
observation row once. It checks the actions itself (NaN or inf: ``ValueError`` before
anything is written) and clips them to [−1, 1] as it reads them, so the core skips
numpy's passes over them. :meth:`NativeAdvance.measure_rows` re-measures a list of
swarms in place: a reset of a few swarms costs those swarms only.

Build: the first use compiles the source with the C compiler (``$CC``, else ``cc`` or
``gcc``), ``-O3 -march=native -fopenmp``, into a per-user cache (``$SWARM_ENVS_CACHE``
or ``~/.cache/swarm_envs``), keyed by the source, the flags, the compiler and the CPU;
that takes about 8 s on the development machine, once, and later processes load the
cached library at once. In the float32 pair loop ``exp`` is the inlined ``exp_f32`` of
``fused_step.c`` (a call to glibc's vector ``exp`` spills every live register; the
float64 loop does call it). Where no compiler works, :func:`native_support` says why and
the torch core keeps its TorchInductor (or plain torch) step.

Threads: the kernel spreads the swarms over OpenMP threads. It links ``libgomp.so.1``,
and in a process that imported torch that is torch's own copy (same soname), so the step
runs on torch's thread pool and follows ``torch.set_num_threads``. (Python threads
would compete with that pool: its threads keep spinning for a while after every torch
operation, the policy's forward pass included; measured, that made the step 40 %
slower in a training loop.) Every swarm is stepped by one thread in the same way, so the
results do not depend on the number of threads.

The environment variable ``SWARM_ENVS_NATIVE`` (``0``/``1``/``auto``) overrides the
automatic choice (``0``: never; ``1``: required, an error where it cannot be built).
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

from swarm_envs.envs.core import NON_FINITE_ACTIONS, OBS_BOUND, success_count
from swarm_envs.metrics import CENTRE_RTOL
from swarm_envs.physics.social_potential import RHO_FLOOR

__all__ = [
    "NATIVE_ENV",
    "NativeAdvance",
    "native_support",
    "resolve_native",
]

logger = logging.getLogger(__name__)

#: Environment variable overriding the automatic choice: ``0``, ``1`` or ``auto``.
NATIVE_ENV = "SWARM_ENVS_NATIVE"
#: Columns of the packed result (the statistics, then the reward).
_N_PACKED = 11
#: Compiler flags (part of the cache key).
CFLAGS = (
    "-O3",
    "-march=native",
    "-fopenmp",
    "-fno-math-errno",
    "-fno-trapping-math",
    "-fPIC",
    "-shared",
)
#: ``fused_step_abi()`` of a library built from the current sources (9 integer and 27
#: real parameters, version 2: the row list); checked on load.
_ABI = 9 * 1000 + 10 * 27 + 2
_SOURCES = ("fused_step.c", "fused_step_body.h")

_LOCK = threading.Lock()
_LIBRARY: ctypes.CDLL | None = None
_FAILURE: str | None = None


def _source_dir() -> Path:
    return Path(str(resources.files("swarm_envs.envs") / "native"))


def _compiler() -> str | None:
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _cache_dir() -> Path:
    root = os.environ.get("SWARM_ENVS_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "swarm_envs"


def _library_path(compiler: str) -> Path:
    src = _source_dir()
    h = hashlib.sha256()
    for name in _SOURCES:
        h.update((src / name).read_bytes())
    h.update(" ".join(CFLAGS).encode())
    h.update(compiler.encode())
    h.update(platform.machine().encode())
    h.update(_cpu_flags().encode())
    return _cache_dir() / f"fused_step-{h.hexdigest()[:16]}.so"


def _cpu_flags() -> str:
    """The CPU's model and feature flags (``-march=native`` code is built for them)."""
    try:
        with open("/proc/cpuinfo") as fh:
            lines = [ln for ln in fh if ln.startswith(("flags", "model name"))]
        return "".join(sorted(set(lines)))
    except OSError:
        return platform.processor()


def _build(compiler: str, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    src = _source_dir()
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        out = Path(tmp) / target.name
        cmd = [compiler, *CFLAGS, "-I", str(src), "-o", str(out), str(src / _SOURCES[0]), "-lm"]
        result = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if result.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed: {result.stderr.strip()[:2000]}")
        os.replace(out, target)  # atomic: concurrent builders never load half a file


def _load() -> ctypes.CDLL:
    """The compiled kernel, built on first use; raises ``RuntimeError`` with the reason."""
    global _LIBRARY, _FAILURE
    with _LOCK:
        if _LIBRARY is not None:
            return _LIBRARY
        if _FAILURE is not None:
            raise RuntimeError(_FAILURE)
        try:
            if sys.platform != "linux":
                raise RuntimeError(f"the C step is built on Linux only (this is {sys.platform})")
            compiler = _compiler()
            if compiler is None:
                raise RuntimeError("no C compiler found ($CC, cc, gcc)")
            path = _library_path(compiler)
            if not path.exists():
                start = time.perf_counter()
                _build(compiler, path)
                logger.info("built %s in %.1f s", path, time.perf_counter() - start)
            lib = ctypes.CDLL(str(path))
            if lib.fused_step_abi() != _ABI:
                raise RuntimeError(f"{path} has another parameter layout; delete it")
            for name in ("fused_step_f32", "fused_step_f64"):
                fn = getattr(lib, name)
                fn.restype = ctypes.c_int
                fn.argtypes = [ctypes.c_void_p] * 2 + [ctypes.c_int64] * 2 + [ctypes.c_void_p] * 17
        except (OSError, RuntimeError) as err:
            _FAILURE = str(err)
            raise RuntimeError(_FAILURE) from err
        _LIBRARY = lib
        return lib


def native_support() -> tuple[bool, str]:
    """``(True, "supported")`` where the C step builds and loads, else ``(False, why)``."""
    try:
        _load()
    except RuntimeError as err:
        return False, str(err)
    return True, "supported"


def resolve_native(request: bool | str = "auto") -> tuple[bool, str]:
    """Whether to use the C step: ``request`` ``True``/``False``/``"auto"``, and why.

    ``"auto"`` follows :data:`NATIVE_ENV` if set, else uses the C step where it builds.
    ``True`` (or ``SWARM_ENVS_NATIVE=1``) raises ``RuntimeError`` where it does not.
    """
    if request == "auto":
        env = os.environ.get(NATIVE_ENV, "auto").strip().lower()
        if env not in ("0", "1", "auto"):
            raise ValueError(f"{NATIVE_ENV} must be 0, 1 or auto, got {env!r}")
        request = {"0": False, "1": True, "auto": "auto"}[env]
    if request is False:
        return False, "native=False"
    ok, why = native_support()
    if not ok and request is True:
        raise RuntimeError(f"the C step was required but cannot be used: {why}")
    return ok, why


class NativeAdvance:
    """The C step for one config, called as ``advance(x, v, f, goal, a, move,
    prev_distance, prev_arrived, start_distance)`` like the function of
    :func:`~swarm_envs.envs.torch_core.build_advance`, for any batch size.

    Returns ``(x', v', f', obs, packed, mean goal distance, arrived fraction, None)``
    (the torch function's last result, the distance matrix, is not kept). Inputs are
    CPU tensors of one dtype, float32 or float64 (``move`` bool); non-contiguous ones
    are copied first.

    Attributes (those of :class:`~swarm_envs.physics.torch_backend.MaybeCompiled` that
    the core reads): ``compiled`` (False: this is not ``torch.compile``), ``reason``,
    ``compile_seconds`` (loading, and building if this process built the library, plus
    the first call, timed by :meth:`warmup`).

    Raises:
        RuntimeError: the library cannot be built or loaded (:func:`native_support`).
        ValueError: more ranked neighbours than the kernel holds (``KMAX_SORT`` = 64).
    """

    compiled = False
    reason = "native"

    def __init__(self, cfg: Any) -> None:
        start = time.perf_counter()
        lib = _load()
        self._load_seconds = time.perf_counter() - start
        self.compile_seconds: float | None = None
        p = cfg.physics
        N, d, k = cfg.n_agents, cfg.dim, cfg.n_neighbors
        k_real = min(k, N - 1)
        k_sort = min(max(k, 1), N - 1)  # ranked neighbours (≥ 1 for the NND statistic)
        if k_sort > lib.fused_step_kmax():
            raise ValueError(
                f"the C step ranks at most {lib.fused_step_kmax()} neighbours, "
                f"got n_neighbors={k} with n_agents={N}"
            )
        self.obs_dim = 2 * d + k * (2 * d + 1)
        w = cfg.reward
        goal_force = int(cfg.goal_in_physics and p.C_g > 0)
        need = success_count(N, cfg.success_fraction)
        self._ints = np.array(
            [0, N, d, k, k_real, max(k_sort, 0), need, self.obs_dim, goal_force], dtype=np.int64
        )
        # In the order of the DP_* enum of fused_step.c.
        reals = [
            cfg.dt, p.m, cfg.u_max, p.C_a, p.C_r, p.l_a, p.l_r, p.C_o, p.l_o, p.beta, p.C_g,
            p.l_g, cfg.goal_radius, cfg.collision_radius, cfg.obs_goal_scale,
            cfg.obs_velocity_scale, 1.0 / cfg.obs_neighbor_scale, 1.0 / cfg.obs_velocity_scale,
            OBS_BOUND, None, RHO_FLOOR,
            w.progress, w.arrival, w.success, w.collision, w.effort, w.time,
        ]  # fmt: skip
        self._reals = {}
        for dtype in (torch.float32, torch.float64):
            reals[19] = CENTRE_RTOL * float(torch.finfo(dtype).eps) * math.sqrt(N)
            self._reals[dtype] = np.array(reals, dtype=np.float64)
        self._fns = {torch.float32: lib.fused_step_f32, torch.float64: lib.fused_step_f64}

    def warmup(self, *args: torch.Tensor) -> tuple:
        """Call once and record :attr:`compile_seconds` (the first call only)."""
        start = time.perf_counter()
        out = self(*args)
        if self.compile_seconds is None:
            self.compile_seconds = self._load_seconds + time.perf_counter() - start
        return out

    def __call__(self, *args: torch.Tensor) -> tuple:
        x, v, f, goal, a, move, prev_distance, prev_arrived, start_distance = (
            t.contiguous() for t in args
        )
        dtype = x.dtype
        _, B, N = x.shape
        x_out, v_out, f_out = torch.empty_like(x), torch.empty_like(x), torch.empty_like(x)
        obs = torch.empty((B, N, self.obs_dim), dtype=torch.float32)
        packed = torch.empty((B, _N_PACKED), dtype=dtype)
        mean_dist, arrived = torch.empty(B, dtype=dtype), torch.empty(B, dtype=dtype)
        inputs = (x, v, f, goal, a, move.to(torch.bool), prev_distance, prev_arrived)
        outputs = (x_out, v_out, f_out, obs, packed, mean_dist, arrived)
        tensors = (*inputs, start_distance, *outputs)
        self._call(dtype, B, None, tensors)
        return x_out, v_out, f_out, obs, packed, mean_dist, arrived, None

    def measure_rows(
        self,
        rows: np.ndarray,
        args: tuple[torch.Tensor, ...],
        obs: torch.Tensor,
        packed: torch.Tensor,
    ) -> None:
        """Re-measure swarms ``rows`` of a whole batch's state in place (a reset).

        ``args``: the arguments of :meth:`__call__` for the whole batch (``move`` false
        for ``rows``, to measure); ``obs`` ``(B, N, obs_dim)`` and ``packed`` ``(B, 11)``:
        the observations and statistics to write the rows' results into. The state
        goes back into ``x``, ``v`` and ``f``, the mean goal distance and the arrived
        fraction into ``prev_distance`` and ``prev_arrived``. The C step reads a swarm's
        inputs before it writes its outputs, so the aliasing is safe. Every tensor must
        be contiguous: nothing is copied.
        """
        x, v, f, _, _, move, prev_distance, prev_arrived, _ = args
        dtype, B, N = x.dtype, x.shape[1], x.shape[2]
        idx = np.ascontiguousarray(rows, dtype=np.int64)
        if idx.size and not (0 <= idx.min() and idx.max() < B):
            raise ValueError(f"rows must be swarms in [0, {B}), got {idx.min()}..{idx.max()}")
        # Written in place: their layout must be the one the C step writes.
        if obs.shape != (B, N, self.obs_dim) or obs.dtype != torch.float32:
            raise ValueError(
                f"obs must be float32 {(B, N, self.obs_dim)}, got {obs.dtype} {tuple(obs.shape)}"
            )
        if packed.shape != (B, _N_PACKED) or packed.dtype != dtype or move.dtype != torch.bool:
            raise ValueError(f"packed must be {dtype} {(B, _N_PACKED)} and move bool")
        tensors = (*args, x, v, f, obs, packed, prev_distance, prev_arrived)
        if not all(t.is_contiguous() for t in tensors):
            raise ValueError("measure_rows writes in place: every tensor must be contiguous")
        self._call(dtype, B, idx, tensors)

    def _call(
        self, dtype: torch.dtype, B: int, rows: np.ndarray | None, tensors: tuple[torch.Tensor, ...]
    ) -> None:
        """The C step on swarms ``rows`` (all B if None); its error codes as exceptions."""
        if dtype not in self._fns or tensors[0].device.type != "cpu":
            raise ValueError(f"the C step needs float32 or float64 CPU tensors, got {dtype}")
        for t in tensors[:9]:
            if t.dtype != dtype and t.dtype != torch.bool:
                raise ValueError(f"the C step needs one dtype, got {t.dtype} and {dtype}")
        ints = self._ints.copy()
        ints[0] = B
        fn, ip, dp = self._fns[dtype], ints.ctypes.data, self._reals[dtype].ctypes.data
        ptrs = [t.data_ptr() for t in tensors]
        if rows is None:
            code = fn(ip, dp, 0, B, None, *ptrs)
        else:
            code = fn(ip, dp, 0, rows.size, rows.ctypes.data, *ptrs)
        if code == 3:
            raise ValueError(NON_FINITE_ACTIONS)
        if code:
            raise MemoryError("the C step could not allocate its scratch memory")
