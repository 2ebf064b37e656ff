"""Loading the C step: a library built at install, else compiled at first use.

``pip install`` (and ``make install``) compiles ``fused_step.c`` (with
``fused_step_body.h``, ``fused_step_stats.h`` and the header
:func:`~swarm_envs.envs.cores.native.contract.header` generates) into a few variants
beside the sources (:mod:`~swarm_envs.envs.cores.native.variants`: on x86-64
``portable``, ``x86-64-v3`` and ``x86-64-v4``, elsewhere ``portable``). The first load
picks the best variant this CPU runs (its flags in ``/proc/cpuinfo``), or the one
``$SWARM_ENVS_NATIVE_ARCH`` names, and loads it after the same check as a cache entry
below (its record names the sources, header and flags it was built from).

Where no prebuilt library fits (a source tree that was not installed, sources edited
since the install, another architecture, ``$CFLAGS`` set, an ``-march`` target that is
not built at install such as ``native``, or ``$SWARM_ENVS_NATIVE_PREBUILT=0``), the
library is compiled at first use with the C compiler (``$CC``, else ``cc`` or ``gcc``)
into ``$SWARM_ENVS_CACHE`` (default ``~/.cache/swarm_envs``) as
``fused_step-<sources>-<compiler>.so``, after a one-time :class:`UserWarning` that says
why and how long a build takes: ``<sources>`` hashes the sources, the generated header,
the flags, the machine and, for ``-march=native``, the CPU; ``<compiler>`` the
compiler's resolved path. Later processes load the cached library at once.

The cache is checked, never trusted: beside each library a record
(``fused_step-….json``: source key, parameter layout, size, SHA-256, compiler, flags) is
written after the library, each synced and renamed into place atomically. A library is
loaded only where its record matches it, from a sealed in-memory copy of the very bytes
checked, so a cached file truncated or overwritten later cannot reach the loader (where
in-memory files cannot be loaded, the file itself is loaded right after its check: a file
truncated in place within that moment can still bring the process down). A damaged
library (cut-off build, disk error, edited file, no record) is rebuilt with a
:class:`UserWarning`; without a compiler it is refused (the C step is then unavailable,
which ``auto`` reports in its warning), while an intact library built for the same
sources and flags by any compiler is loaded. A build runs under a per-library file lock
(concurrent processes build once) and is killed after ``$SWARM_ENVS_CC_TIMEOUT`` seconds
(default 600). Build folders left by killed builds are removed at the next load: those
of processes of this host that are gone at once, any older than an hour.

Flags: ``-O3 -fno-gcse -fno-gcse-after-reload -fopenmp -fno-math-errno
-fno-trapping-math -fPIC -shared -march=<arch>``, then the words of ``$CFLAGS``.
``<arch>`` is ``$SWARM_ENVS_NATIVE_ARCH`` (where a build at first use runs without it:
``native``, the best code for this CPU; a target such as ``x86-64-v3`` builds code that
runs on any CPU of that level and exercises the kernel's non-AVX-512 branches).
``portable`` (:data:`PORTABLE`) gives no ``-march`` at all: the compiler's default
target, code for any CPU of this architecture (on x86-64: SSE2 only, without AVX or FMA).

Threads: the kernel spreads the swarms over OpenMP threads. It links ``libgomp.so.1``;
in a process that imported torch that is torch's own copy (same soname), so the step
runs on torch's thread pool and follows ``torch.set_num_threads``. Every swarm is
stepped by one thread in the same way, so the results do not depend on the thread count.

``SWARM_ENVS_NATIVE`` (``0``/``1``/``auto``) overrides the automatic choice (``0``:
never; ``1``: required, an error where it cannot be loaded or built). Where no compiler
works and nothing fits, :func:`native_support` says why.
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import json
import logging
import math
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Iterator
from importlib import resources
from pathlib import Path
from typing import Any

from swarm_envs.envs.cores.native import cache as store
from swarm_envs.envs.cores.native import variants
from swarm_envs.envs.cores.native.cache import LEFTOVER_AGE
from swarm_envs.envs.cores.native.contract import KernelInfo, header, layout_hash
from swarm_envs.envs.cores.native.variants import BASE_FLAGS, PORTABLE

__all__ = [
    "ARCH_ENV",
    "CACHE_ENV",
    "CC_TIMEOUT_ENV",
    "DEFAULT_CC_TIMEOUT",
    "LEFTOVER_AGE",
    "NATIVE_ENV",
    "PORTABLE",
    "PREBUILT_ENV",
    "Library",
    "build_flags",
    "compiler_timeout",
    "load_library",
    "native_support",
    "prebuilt_dir",
    "prebuilt_support",
    "resolve_native",
]

logger = logging.getLogger(__name__)

#: Environment variable overriding the automatic choice: ``0``, ``1`` or ``auto``.
NATIVE_ENV = "SWARM_ENVS_NATIVE"
#: Environment variable naming the variant or ``-march`` target (default: the best
#: prebuilt variant this CPU runs, else ``native``), or :data:`PORTABLE`.
ARCH_ENV = "SWARM_ENVS_NATIVE_ARCH"
#: Environment variable that, set to ``0``, ignores the libraries built at install (the
#: C step is then built at first use into the cache).
PREBUILT_ENV = "SWARM_ENVS_NATIVE_PREBUILT"
#: Environment variable naming the cache folder (default ``~/.cache/swarm_envs``).
CACHE_ENV = "SWARM_ENVS_CACHE"
#: Environment variable limiting a build's time, in seconds.
CC_TIMEOUT_ENV = "SWARM_ENVS_CC_TIMEOUT"
#: A build's time limit where :data:`CC_TIMEOUT_ENV` is not set, in seconds: generous,
#: as one compiler run over the whole kernel is long (``docs/performance.md`` gives its
#: time), and a busy machine stretches it; a hung compiler is still stopped.
DEFAULT_CC_TIMEOUT = 600.0
#: What a build at first use usually takes, for the warning that announces it (the build
#: times of ``docs/performance.md``, "Building the C step").
BUILD_TIME = "10-40 s of CPU"
_SOURCES = variants.SOURCES

_LOCK = threading.Lock()
_LIBRARIES: dict[tuple[str, ...], Library] = {}
_FAILURES: dict[tuple[str, ...], str] = {}
_WARNED: set[str] = set()


class Library:
    """A loaded C step: its two entry points and what it declares it implements.

    ``path`` is the file whose checked bytes were loaded (from an in-memory copy where
    possible, so the file may change later without affecting this library); ``variant``
    names the prebuilt variant it is, or is None for a library of the cache.
    """

    def __init__(self, lib: ctypes.CDLL, path: Path, variant: str | None = None) -> None:
        self.lib, self.path, self.variant = lib, path, variant
        names = ("physics", "stats", "obs_layouts", "statuses")
        for name in names:
            getattr(lib, f"fused_step_{name}").restype = ctypes.c_char_p
        lib.fused_step_layout.restype = ctypes.c_longlong
        self.info = KernelInfo(
            physics=tuple(lib.fused_step_physics().decode().split()),
            statistics=tuple(lib.fused_step_stats().decode().split()),
            obs_layouts=tuple(lib.fused_step_obs_layouts().decode().split("\n")),
            kmax=int(lib.fused_step_kmax()),
            statuses=tuple(lib.fused_step_statuses().decode().split()),
        )
        self.f32, self.f64 = lib.fused_step_f32, lib.fused_step_f64
        for fn in (self.f32, self.f64):
            fn.restype = ctypes.c_int
            args: list[Any] = [ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64]
            fn.argtypes = args + [ctypes.c_void_p] * 15


def _requested_arch() -> str | None:
    return os.environ.get(ARCH_ENV, "").strip() or None


def _extra_flags() -> tuple[str, ...]:
    return tuple(shlex.split(os.environ.get("CFLAGS", "")))


def build_flags(arch: str | None = None) -> tuple[str, ...]:
    """The compiler flags of a build for ``arch`` (default: :data:`ARCH_ENV`, else
    ``native``): the fixed ones, ``-march=<arch>`` (none for :data:`PORTABLE`),
    ``$CFLAGS``."""
    arch = arch or _requested_arch() or "native"
    return (*BASE_FLAGS, *variants.arch_flags(arch), *_extra_flags())


def _source_dir() -> Path:
    return Path(str(resources.files("swarm_envs.envs.cores") / "native"))


def prebuilt_dir() -> Path:
    """The folder of the libraries built at install (``lib/`` beside the sources)."""
    return _source_dir() / variants.LIB_DIR


def _compiler() -> str | None:
    return variants.find_compiler()


def _cache_dir() -> Path:
    root = os.environ.get(CACHE_ENV)
    return Path(root) if root else Path.home() / ".cache" / "swarm_envs"


def compiler_timeout() -> float:
    """The seconds a build may take: :data:`CC_TIMEOUT_ENV`, default
    :data:`DEFAULT_CC_TIMEOUT`.

    Raises:
        ValueError: the variable is set to anything but a finite number of seconds > 0.
    """
    raw = os.environ.get(CC_TIMEOUT_ENV, "").strip()
    if not raw:
        return DEFAULT_CC_TIMEOUT
    try:
        seconds = float(raw)
    except ValueError:
        seconds = math.nan
    if not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"{CC_TIMEOUT_ENV} must be a number of seconds > 0, got {raw!r}")
    return seconds


# --------------------------------------------------------------------------- cache key


def _source_key(flags: tuple[str, ...]) -> str:
    """What a library is built from, without the compiler: the sources, the generated
    header, the flags, the machine and, for ``-march=native``, the CPU (hex SHA-256)."""
    return variants.source_key(_source_dir(), header(), flags)


def _library_path(cache: Path, key: str, compiler: str) -> Path:
    """``fused_step-<sources>-<compiler>.so``: one library per source key and compiler."""
    tag = hashlib.sha256(os.path.realpath(compiler).encode()).hexdigest()[:8]
    return cache / f"fused_step-{key[:16]}-{tag}.so"


# --------------------------------------------------------------------------- building


def _compile(cmd: list[str], timeout: float) -> None:
    """Run the compiler, killing it (and whatever it started) after ``timeout`` seconds.

    Raises:
        RuntimeError: it failed (its error output, cut to 2000 characters) or timed out.
    """
    pipe = subprocess.PIPE
    with subprocess.Popen(
        [*cmd, "-lm"], stdout=pipe, stderr=pipe, text=True, start_new_session=True
    ) as proc:
        try:
            _, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            raise RuntimeError(
                f"the C compiler {cmd[0]} did not finish within {timeout:g} s "
                f"({CC_TIMEOUT_ENV} sets the limit)"
            ) from None
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {err.strip()[:2000]}")


def _build(compiler: str, flags: tuple[str, ...], key: str, target: Path, timeout: float) -> None:
    """Compile into a private folder of the cache, then move the library into place and
    write its record last, each file synced and renamed atomically: a library without a
    matching record is never trusted, so a build cut off at any point is rebuilt."""
    cache, src = target.parent, _source_dir()
    prefix = f"{store.BUILD_PREFIX}{os.getpid()}-{store.host_tag()}-"
    with tempfile.TemporaryDirectory(prefix=prefix, dir=cache) as tmp:
        (Path(tmp) / "step_params.h").write_text(header())
        out = Path(tmp) / target.name
        _compile(
            [compiler, *flags, "-I", tmp, "-I", str(src), "-o", str(out), str(src / _SOURCES[0])],
            timeout,
        )
        data = out.read_bytes()
        store.fsync_path(out)
        record = variants.record(key, layout_hash(), data, compiler, flags)
        record_tmp = Path(tmp) / "record.json"
        store.write_durably(record_tmp, json.dumps(record, indent=1).encode())
        store.record_path(target).unlink(missing_ok=True)  # it described the file replaced now
        os.replace(out, target)
        store.fsync_path(cache)
        os.replace(record_tmp, store.record_path(target))
        store.fsync_path(cache)


@contextlib.contextmanager
def _build_lock(target: Path, timeout: float) -> Iterator[None]:
    """An exclusive lock on ``target``'s build across processes (released by the kernel
    if the holder dies), waited for ``timeout`` seconds at most; where the file system
    cannot lock, builds are not serialised and a library that loses the race to its
    record is rebuilt on its next load.

    Raises:
        RuntimeError: another process held the lock for ``timeout`` seconds.
    """
    import fcntl  # POSIX only; the C step is built on Linux only

    with open(target.with_name(f".{target.stem}.lock"), "a") as fh:
        deadline = time.monotonic() + timeout
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise RuntimeError(
                        f"another process has been building {target} for {timeout:g} s "
                        f"({CC_TIMEOUT_ENV} sets the limit)"
                    ) from None
                time.sleep(0.05)
            except OSError as err:
                logger.debug("cannot lock %s: %s", fh.name, err)
                break
        yield


def _rebuilt(
    compiler: str, flags: tuple[str, ...], key: str, target: Path, timeout: float, reason: str
) -> bytes:
    """The bytes of ``target`` after building it, unless another process did meanwhile;
    a build is announced with a warning that says ``reason`` (why no prebuilt library
    fits), a damaged library is replaced with a warning that says what was wrong."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with _build_lock(target, timeout):
        data, why = store.verified(target, key)
        if data is not None:
            return data
        if why != store.MISSING:
            _warn_once(f"the cached C step {target} was damaged ({why}); rebuilding it")
        else:
            march = " ".join(f for f in flags if f.startswith("-march")) or "(portable)"
            _warn_once(
                f"building the C step now, as {reason}: {os.path.basename(compiler)} "
                f"{march} into {target.parent}, once (a build usually takes {BUILD_TIME})"
            )
        start = time.perf_counter()
        _build(compiler, flags, key, target, timeout)
        logger.info("built %s in %.1f s", target, time.perf_counter() - start)
        data, why = store.verified(target, key)
    if data is None:
        raise RuntimeError(f"the C step just built at {target} fails its check ({why})")
    return data


# --------------------------------------------------------------------------- loading


def _open(data: bytes, path: Path, variant: str | None = None) -> Library:
    lib = store.dlopen_private(data, path)
    lib.fused_step_layout.restype = ctypes.c_longlong
    if lib.fused_step_layout() != layout_hash():
        raise RuntimeError(f"{path} was built for another parameter layout; delete it")
    return Library(lib, path, variant)


def _prebuilt_path(variant: str) -> Path:
    return prebuilt_dir() / f"fused_step-{variant}.so"


def _prebuilt(variant: str) -> tuple[bytes | None, str]:
    """The checked bytes of the prebuilt ``variant`` (its record names these sources,
    this header and the variant's flags), else ``(None, why)``."""
    path = _prebuilt_path(variant)
    data, why = store.verified(path, _source_key((*BASE_FLAGS, *variants.arch_flags(variant))))
    if data is None:
        if why == store.MISSING:
            return None, f"{variant} was not built at install (no {path})"
        return None, f"the prebuilt {variant} library {path} does not fit: {why}"
    return data, "intact"


def _prebuilt_choice(arch: str | None) -> tuple[str | None, str]:
    """The prebuilt variant to load for ``arch`` (None: the best this CPU runs), else
    ``(None, why not)``.

    Raises:
        RuntimeError: ``arch`` names a variant that this CPU cannot run.
    """
    if os.environ.get(PREBUILT_ENV, "").strip() == "0":
        return None, f"{PREBUILT_ENV}=0"
    if _extra_flags():
        return None, "$CFLAGS is set"
    shipped = variants.shipped_variants()
    cpu = variants.cpu_flags()
    if arch is not None:
        if arch not in shipped:
            built = ", ".join(shipped)
            return None, f"{ARCH_ENV}={arch} is not a variant built at install ({built})"
        if cpu and not variants.supports(arch, cpu):
            raise RuntimeError(f"this CPU cannot run the {arch} C step ({ARCH_ENV}={arch})")
        return arch, "named"
    present = [v for v in shipped if _prebuilt_path(v).exists()]
    chosen = variants.choose_variant(cpu, present)
    if chosen is None:
        if not present:
            return None, f"no C step was built at install (nothing in {prebuilt_dir()})"
        return None, f"none of the prebuilt variants ({', '.join(present)}) runs on this CPU"
    return chosen, "the best this CPU runs"


def _open_any(cache: Path, key: str) -> Library:
    """Without a compiler: the newest intact library built for ``key`` by any compiler."""
    damaged = []
    found = sorted(cache.glob(f"fused_step-{key[:16]}-*.so"), key=store.mtime, reverse=True)
    for path in found:
        data, why = store.verified(path, key)
        if data is not None:
            return _open(data, path)
        damaged.append(f"{path}: {why}")
    why = "no C compiler found ($CC, cc, gcc)"
    raise RuntimeError(
        f"{why}; the cached C step is damaged ({'; '.join(damaged)})" if damaged else why
    )


def _warn_once(message: str) -> None:
    if message not in _WARNED:
        _WARNED.add(message)
        warnings.warn(message, UserWarning, stacklevel=5)  # load_library's caller


def _load(arch: str | None, timeout: float) -> Library:
    if sys.platform != "linux":
        raise RuntimeError(f"the C step is built on Linux only (this is {sys.platform})")
    variant, reason = _prebuilt_choice(arch)
    if variant is not None:
        data, reason = _prebuilt(variant)
        if data is not None:
            return _open(data, _prebuilt_path(variant), variant)
    flags = build_flags(arch)
    cache, key = _cache_dir(), _source_key(flags)
    store.clean_leftovers(cache)
    compiler = _compiler()
    if compiler is None:
        try:
            return _open_any(cache, key)
        except RuntimeError as err:
            raise RuntimeError(f"{err}; {reason}") from None
    target = _library_path(cache, key, compiler)
    data, _ = store.verified(target, key)
    if data is None:
        data = _rebuilt(compiler, flags, key, target, timeout, reason)
    return _open(data, target)


def load_library() -> Library:
    """The C step for the current settings: the prebuilt variant that :data:`ARCH_ENV`
    names, or else the best one this CPU runs; where none fits, built at first use into
    the cache (announced with a one-time warning that says why); ``RuntimeError`` with
    the reason where it cannot be loaded or built.

    A prebuilt or cached library is loaded only where its record vouches for it (same
    sources, flags and layout; same size and SHA-256), from a private in-memory copy of
    the bytes checked; a damaged cached one is rebuilt (with a warning) or, without a
    compiler, refused. Without a compiler, an intact library built by any compiler for
    the same sources and flags is loaded. Outcomes, failures included, are kept for the
    process.

    Raises:
        RuntimeError: no intact library and none can be built here, with the reason.
        ValueError: :data:`CC_TIMEOUT_ENV` is not a number of seconds > 0.
    """
    arch = _requested_arch()
    flags = (arch or "", os.environ.get(PREBUILT_ENV, ""), *_extra_flags())
    timeout = compiler_timeout()
    with _LOCK:
        if flags in _LIBRARIES:
            return _LIBRARIES[flags]
        if flags in _FAILURES:
            raise RuntimeError(_FAILURES[flags])
        try:
            library = _load(arch, timeout)
        except (OSError, RuntimeError, AttributeError) as err:
            _FAILURES[flags] = str(err)
            raise RuntimeError(_FAILURES[flags]) from err
        _LIBRARIES[flags] = library
        return library


def prebuilt_support() -> dict[str, tuple[bool, str]]:
    """For each variant built at install that this CPU runs: ``(True, "intact")`` where
    its library is present, fits these sources and loads, else ``(False, why)``."""
    found: dict[str, tuple[bool, str]] = {}
    for variant in variants.runnable_variants(variants.cpu_flags()):
        data, why = _prebuilt(variant)
        if data is not None:
            try:
                _open(data, _prebuilt_path(variant), variant)
            except (OSError, RuntimeError, AttributeError) as err:
                data, why = None, f"{_prebuilt_path(variant)} does not load: {err}"
        found[variant] = (data is not None, why)
    return found


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
        choices: dict[str, bool | str] = {"0": False, "1": True, "auto": "auto"}
        request = choices[env]
    if request is False:
        return False, f"{NATIVE_ENV}=0"
    ok, why = native_support()
    if not ok and request is True:
        raise RuntimeError(f"the C step was required but cannot be used: {why}")
    return ok, why
