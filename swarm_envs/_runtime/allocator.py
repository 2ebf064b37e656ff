"""Keep freed heap memory for reuse (glibc only): an explicit, process-wide opt-in.

A physics step allocates and frees temporaries of ``B·N·N`` elements (the numpy core's
pair arrays) or of the observation's size. With glibc's defaults every block above
128 KiB is ``mmap``-ed on allocation and returned to the OS on release, so each step
pays page faults and page zeroing again. :func:`tune_allocator` raises glibc's mmap and
trim thresholds (``mallopt``) so that freed blocks stay in the heap and are reused;
``docs/performance.md`` measures what it buys.

It changes the whole process (the process keeps its peak heap instead of returning it
to the OS), so the library never does it on its own: call
:func:`swarm_envs.tune_allocator` (the command-line tools and the benchmarks do), or set
``SWARM_ENVS_TUNE_ALLOCATOR=1`` for a program that does not. Linux with glibc only;
elsewhere it does nothing and returns ``False``.
"""

from __future__ import annotations

import ctypes
import sys

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: glibc caps the mmap threshold at 32 MiB on 64-bit systems.
_THRESHOLD = 32 * 1024 * 1024

_state: dict[str, bool] = {}


def allocator_tuned() -> bool:
    """Whether :func:`tune_allocator` has made the change in this process."""
    return _state.get("active", False)


def tune_allocator() -> bool:
    """Keep freed heap memory for reuse (once per process); return whether it is active."""
    if "active" in _state:
        return _state["active"]
    active = False
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL("libc.so.6")
            active = bool(
                libc.mallopt(_M_MMAP_THRESHOLD, _THRESHOLD)
                and libc.mallopt(_M_TRIM_THRESHOLD, 4 * _THRESHOLD)
            )
        except (OSError, AttributeError):
            active = False
    _state["active"] = active
    return active
