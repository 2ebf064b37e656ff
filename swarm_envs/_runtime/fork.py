"""Forked processes: the envs' OpenMP code made safe in children of a process that ran it.

Two backends run on OpenMP threads: the C step (``libgomp``; the swarms of a batch are
spread over its threads) and the cut-off core's compiled passes (numba, whose default
threading layer on Linux, ``omp``, is GNU OpenMP too). GNU OpenMP is not fork-safe: a
child made by ``fork()`` inherits the parent's thread pool without its threads. The
child's first parallel region with more than one thread then waits forever for them
(the C step of a batch), or numba terminates the child ("fork() called from a process
already using GNU OpenMP"). Gymnasium's ``AsyncVectorEnv`` and SuperSuit's multiprocess
``concat_vec_envs_v1`` fork their workers by default on Linux.

:func:`install_fork_handlers` (called by ``import swarm_envs``) registers a handler that
runs in every forked child (``os.register_at_fork``):

- where ``libgomp`` is loaded, OpenMP regions run on one thread in the child
  (``omp_set_num_threads(1)``, for every ``libgomp`` of the process); the swarms of a
  batch are then stepped one after the other, with the same results (each swarm is
  stepped by one thread in the same way). torch's CPU operators, on the same library,
  run on one thread there too;
- where the parent launched numba's ``omp`` threading layer, the child runs the
  cut-off core's passes in numpy (``SWARM_ENVS_NUMBA=0`` in its environment, unless
  ``SWARM_ENVS_NUMBA=1`` asks for numba everywhere) and warns once: the same results,
  at numpy's speed.

Children started with ``spawn`` or ``forkserver`` (``vector_kwargs={"context":
"forkserver"}`` for ``gym.make_vec``, ``start_method`` for SB3's ``SubprocVecEnv``) do
not run the handler and keep every thread and the compiled passes. numba's ``tbb`` and
``workqueue`` layers are fork-safe and left alone
(``NUMBA_THREADING_LAYER=workqueue`` keeps the compiled passes in forked children, at
some cost to large swarms).
"""

from __future__ import annotations

import ctypes
import os
import sys
import warnings

__all__ = ["install_fork_handlers", "numba_layer_unsafe_after_fork"]

_installed = False


def numba_layer_unsafe_after_fork() -> bool:
    """Whether this process launched numba's GNU OpenMP threading layer (``omp`` on
    Linux), which a forked child cannot use. Never imports numba."""
    parallel = sys.modules.get("numba.np.ufunc.parallel")
    if parallel is None or not getattr(parallel, "_is_initialized", False):
        return False
    return sys.platform.startswith("linux") and getattr(parallel, "_threading_layer", "") == "omp"


def _libgomp_paths() -> list[str]:
    """The ``libgomp`` files loaded in this process (``/proc/self/maps``; Linux)."""
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "libgomp" in line}
    except OSError:
        return []
    return sorted(p for p in paths if p.startswith("/"))


def _one_openmp_thread() -> None:
    for path in _libgomp_paths():
        try:
            lib = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | ctypes.RTLD_GLOBAL)
            lib.omp_set_num_threads(1)
        except (OSError, AttributeError):  # gone, or not an OpenMP runtime after all
            continue


def _after_fork_in_child() -> None:
    _one_openmp_thread()
    if numba_layer_unsafe_after_fork():
        if os.environ.get("SWARM_ENVS_NUMBA", "auto").strip() != "1":
            os.environ["SWARM_ENVS_NUMBA"] = "0"
            warnings.warn(
                "swarm_envs: this process was forked from one that ran numba's GNU OpenMP "
                "threading layer, which is not fork-safe; the cut-off core's "
                "passes run in numpy here. Start workers with 'forkserver' or 'spawn' "
                "(gym.make_vec(..., vector_kwargs={'context': 'forkserver'})) to keep "
                "them compiled",
                RuntimeWarning,
                stacklevel=1,
            )


def install_fork_handlers() -> None:
    """Register the child handler (once per process; see the module docstring)."""
    global _installed
    if not _installed and hasattr(os, "register_at_fork"):
        os.register_at_fork(after_in_child=_after_fork_in_child)
        _installed = True
