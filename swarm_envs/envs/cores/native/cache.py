"""The C step's cache on disk: records, checks, durable writes, leftovers, private loading.

A library in the cache is trusted only with its record beside it (``<library>.json``:
format, key, parameter layout hash, size, SHA-256, compiler, flags), written after the
library is complete, each file synced and renamed into place. :func:`verified` checks a
library against its record and returns the very bytes it checked; :func:`dlopen_private`
loads those bytes from a sealed in-memory copy, so that whatever happens to the cached
file afterwards cannot reach the loader. :func:`clean_leftovers` removes the folders of
builds that were killed. The building and choosing is in
:mod:`swarm_envs.envs.cores.native.build`.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import logging
import os
import platform
import shutil
import time
from pathlib import Path

from swarm_envs.envs.cores.native.contract import layout_hash

__all__ = [
    "BUILD_PREFIX",
    "LEFTOVER_AGE",
    "MISSING",
    "RECORD_FORMAT",
    "clean_leftovers",
    "dlopen_private",
    "fsync_path",
    "host_tag",
    "mtime",
    "record_path",
    "verified",
    "write_durably",
]

logger = logging.getLogger(__name__)

#: Seconds after which a build folder that names no live process here is removed.
LEFTOVER_AGE = 3600.0
#: The version of the record's format.
RECORD_FORMAT = 1
#: The reason :func:`verified` gives where there is no library at all.
MISSING = "missing"
#: The prefix of a build's private folder in the cache (then its pid and host tag).
BUILD_PREFIX = ".fused_step-build-"
_PRIVATE_FDS: list[int] = []  # in-memory copies of the loaded libraries (kept open)


def record_path(library: Path) -> Path:
    return library.with_suffix(".json")


def verified(library: Path, key: str) -> tuple[bytes | None, str]:
    """``(bytes, "intact")`` where ``library`` is a complete build for ``key`` (its record
    names ``key`` and the parameter layout, and its size and SHA-256 match the file),
    else ``(None, why)``; ``why`` is :data:`MISSING` where there is no library at all.
    Reads the file once: the bytes returned are the bytes checked."""
    if not library.exists():
        return None, MISSING
    try:
        record = json.loads(record_path(library).read_text())
    except FileNotFoundError:
        return None, "no record of a completed build beside it"
    except (OSError, ValueError) as err:
        return None, f"unreadable record ({err})"
    if not isinstance(record, dict) or record.get("format") != RECORD_FORMAT:
        return None, "a record in an unknown format"
    if record.get("key") != key or record.get("layout") != layout_hash():
        return None, "recorded for other sources, flags or parameter layout"
    try:
        data = library.read_bytes()
    except OSError as err:
        return None, f"unreadable ({err})"
    if len(data) != record.get("size"):
        return None, f"{len(data)} bytes where {record.get('size')} were written"
    if hashlib.sha256(data).hexdigest() != record.get("sha256"):
        return None, "its SHA-256 differs from the one recorded when it was written"
    return data, "intact"


def mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:
        return 0.0


def host_tag() -> str:
    return hashlib.sha256(platform.node().encode()).hexdigest()[:8]


def fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_durably(path: Path, data: bytes) -> None:
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _only_build_files(folder: str) -> bool:
    names = os.listdir(folder)
    allowed = ("step_params.h", "record.json")
    return "step_params.h" in names and all(
        n in allowed or (n.startswith("fused_step-") and n.endswith(".so")) for n in names
    )


def _is_leftover(entry: os.DirEntry[str], now: float) -> bool:
    """Whether ``entry`` is a build folder that no build will finish: one named by a
    process of this host that is gone, or one older than :data:`LEFTOVER_AGE` (named by
    another host, or an unnamed ``tmp*`` folder holding nothing but build files)."""
    if not entry.is_dir(follow_symlinks=False):
        return False
    old = now - entry.stat(follow_symlinks=False).st_mtime > LEFTOVER_AGE
    if entry.name.startswith(BUILD_PREFIX):
        pid, _, rest = entry.name[len(BUILD_PREFIX) :].partition("-")
        same_host = rest.startswith(host_tag() + "-")
        return old or (same_host and pid.isdigit() and not _alive(int(pid)))
    return entry.name.startswith("tmp") and old and _only_build_files(entry.path)


def clean_leftovers(cache: Path) -> None:
    """Remove the folders of builds that were killed (never raises)."""
    try:
        entries = list(os.scandir(cache))
    except OSError:
        return
    now = time.time()
    for entry in entries:
        try:
            if _is_leftover(entry, now):
                shutil.rmtree(entry.path)
                logger.info("removed the leftover build folder %s", entry.path)
        except OSError as err:
            logger.debug("cannot clean %s: %s", entry.path, err)


def dlopen_private(data: bytes, path: Path) -> ctypes.CDLL:
    """Load ``data`` (the checked bytes of ``path``) from a sealed in-memory copy, so that
    whatever happens to the cached file now cannot reach the loader; where in-memory
    files cannot be loaded, load ``path`` itself (checked a moment before)."""
    import fcntl  # POSIX only; the C step is built on Linux only

    try:
        fd = os.memfd_create("swarm_envs-fused_step", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    except (AttributeError, OSError) as err:
        logger.debug("no in-memory copy (%s); loading %s", err, path)
        return ctypes.CDLL(str(path))
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        seals = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_WRITE | fcntl.F_SEAL_SEAL
        fcntl.fcntl(fd, fcntl.F_ADD_SEALS, seals)
        lib = ctypes.CDLL(f"/proc/self/fd/{fd}")
    except OSError as err:
        os.close(fd)
        logger.debug("cannot load an in-memory copy (%s); loading %s", err, path)
        return ctypes.CDLL(str(path))
    # Kept open: the loader knows the library by this path, which must not name another.
    _PRIVATE_FDS.append(fd)
    return lib
