"""Building and loading the C step: compiled at first use into a per-user cache.

The first use compiles ``fused_step.c`` (with ``fused_step_body.h`` and the header
:func:`~swarm_envs.envs.native.contract.header` generates) with the C compiler (``$CC``,
else ``cc`` or ``gcc``) into ``$SWARM_ENVS_CACHE`` (default ``~/.cache/swarm_envs``),
keyed by the sources, the generated header, the flags, the compiler and, for
``-march=native``, the CPU; later processes load the cached library at once.

Flags: ``-O3 -march=<arch> -fopenmp -fno-math-errno -fno-trapping-math -fPIC -shared``,
then the words of ``$CFLAGS``. ``<arch>`` is ``$SWARM_ENVS_NATIVE_ARCH`` (default
``native``: the best code for this CPU; a portable target such as ``x86-64-v3`` or
``x86-64-v2`` builds code that runs on any CPU of that level and exercises the kernel's
non-AVX-512 branches).

Threads: the kernel spreads the swarms over OpenMP threads. It links ``libgomp.so.1``;
in a process that imported torch that is torch's own copy (same soname), so the step
runs on torch's thread pool and follows ``torch.set_num_threads``. Every swarm is
stepped by one thread in the same way, so the results do not depend on the thread count.

``SWARM_ENVS_NATIVE`` (``0``/``1``/``auto``) overrides the automatic choice (``0``:
never; ``1``: required, an error where it cannot be built). Where no compiler works,
:func:`native_support` says why.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from importlib import resources
from pathlib import Path

from swarm_envs.envs.native.contract import KernelInfo, header, layout_hash

__all__ = [
    "ARCH_ENV",
    "NATIVE_ENV",
    "Library",
    "build_flags",
    "load_library",
    "native_support",
    "resolve_native",
]

logger = logging.getLogger(__name__)

#: Environment variable overriding the automatic choice: ``0``, ``1`` or ``auto``.
NATIVE_ENV = "SWARM_ENVS_NATIVE"
#: Environment variable naming the ``-march`` target (default ``native``).
ARCH_ENV = "SWARM_ENVS_NATIVE_ARCH"
_BASE_FLAGS = ("-O3", "-fopenmp", "-fno-math-errno", "-fno-trapping-math", "-fPIC", "-shared")
_SOURCES = ("fused_step.c", "fused_step_body.h")

_LOCK = threading.Lock()
_LIBRARIES: dict[tuple[str, ...], Library] = {}
_FAILURES: dict[tuple[str, ...], str] = {}


class Library:
    """A loaded C step: its two entry points and what it declares it implements."""

    def __init__(self, lib: ctypes.CDLL, path: Path) -> None:
        self.lib, self.path = lib, path
        for name in ("fused_step_physics", "fused_step_stats", "fused_step_obs_layout"):
            getattr(lib, name).restype = ctypes.c_char_p
        lib.fused_step_layout.restype = ctypes.c_longlong
        self.info = KernelInfo(
            physics=tuple(lib.fused_step_physics().decode().split()),
            statistics=tuple(lib.fused_step_stats().decode().split()),
            obs_layout=lib.fused_step_obs_layout().decode(),
            kmax=int(lib.fused_step_kmax()),
        )
        self.f32, self.f64 = lib.fused_step_f32, lib.fused_step_f64
        for fn in (self.f32, self.f64):
            fn.restype = ctypes.c_int
            fn.argtypes = [ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64] + [ctypes.c_void_p] * 12


def build_flags() -> tuple[str, ...]:
    """The compiler flags: the fixed ones, ``-march`` from :data:`ARCH_ENV`, ``$CFLAGS``."""
    arch = os.environ.get(ARCH_ENV, "native").strip() or "native"
    extra = tuple(shlex.split(os.environ.get("CFLAGS", "")))
    return (*_BASE_FLAGS, f"-march={arch}", *extra)


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


def _library_path(compiler: str, flags: tuple[str, ...]) -> Path:
    src = _source_dir()
    h = hashlib.sha256()
    for name in _SOURCES:
        h.update((src / name).read_bytes())
    h.update(header().encode())
    h.update(" ".join(flags).encode())
    h.update(compiler.encode())
    h.update(platform.machine().encode())
    if "-march=native" in flags:
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


def _build(compiler: str, flags: tuple[str, ...], target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    src = _source_dir()
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        (Path(tmp) / "step_params.h").write_text(header())
        out = Path(tmp) / target.name
        cmd = [compiler, *flags, "-I", tmp, "-I", str(src), "-o", str(out), str(src / _SOURCES[0])]
        result = subprocess.run([*cmd, "-lm"], capture_output=True, text=True, check=False)
        if result.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed: {result.stderr.strip()[:2000]}")
        os.replace(out, target)  # atomic: concurrent builders never load half a file


def load_library() -> Library:
    """The C step for the current flags, built on first use; ``RuntimeError`` with the
    reason where it cannot be built or loaded."""
    flags = build_flags()
    with _LOCK:
        if flags in _LIBRARIES:
            return _LIBRARIES[flags]
        if flags in _FAILURES:
            raise RuntimeError(_FAILURES[flags])
        try:
            if sys.platform != "linux":
                raise RuntimeError(f"the C step is built on Linux only (this is {sys.platform})")
            compiler = _compiler()
            if compiler is None:
                raise RuntimeError("no C compiler found ($CC, cc, gcc)")
            path = _library_path(compiler, flags)
            if not path.exists():
                start = time.perf_counter()
                _build(compiler, flags, path)
                logger.info("built %s in %.1f s", path, time.perf_counter() - start)
            lib = ctypes.CDLL(str(path))
            lib.fused_step_layout.restype = ctypes.c_longlong
            if lib.fused_step_layout() != layout_hash():
                raise RuntimeError(f"{path} was built for another parameter layout; delete it")
            library = Library(lib, path)
        except (OSError, RuntimeError, AttributeError) as err:
            _FAILURES[flags] = str(err)
            raise RuntimeError(_FAILURES[flags]) from err
        _LIBRARIES[flags] = library
        return library


def native_support() -> tuple[bool, str]:
    """``(True, "supported")`` where the C step builds and loads, else ``(False, why)``."""
    try:
        load_library()
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
        return False, f"{NATIVE_ENV}=0"
    ok, why = native_support()
    if not ok and request is True:
        raise RuntimeError(f"the C step was required but cannot be used: {why}")
    return ok, why
