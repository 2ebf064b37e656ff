"""Keep freed heap memory for reuse (glibc only), so per-step temporaries stop page-faulting.

A physics step allocates and frees a few dozen ``(..., N, N)`` temporaries. With glibc's
defaults, every block above 128 KiB is ``mmap``-ed on allocation and returned to the OS
on release, so each step pays page faults and page zeroing again: measured on the
development machine, ``forces()`` at N = 100 (float64) ran 2.6x slower and the 1024 × 32
VecEnv step 1.4x slower than with the memory kept. :func:`keep_freed_memory` raises
glibc's mmap and trim thresholds (``mallopt``) so that freed blocks stay in the heap.

Trade-off: the process keeps its peak heap instead of returning it to the OS. It is
process-wide, done at most once, only on Linux with glibc, and skipped when the
environment variable ``SWARM_ENVS_NO_MALLOPT`` is set.
"""

from __future__ import annotations

import ctypes
import os
import sys

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: glibc caps the mmap threshold at 32 MiB on 64-bit systems.
_THRESHOLD = 32 * 1024 * 1024

_state: dict[str, bool] = {}


def keep_freed_memory() -> bool:
    """Apply the glibc tuning once; return whether it is active."""
    if "active" in _state:
        return _state["active"]
    active = False
    if not os.environ.get("SWARM_ENVS_NO_MALLOPT") and sys.platform.startswith("linux"):
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
