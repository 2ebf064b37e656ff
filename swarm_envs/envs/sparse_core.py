"""``swarm_envs.envs.sparse_core``: the cut-off core under the backend's other name,
``"sparse"`` (deprecated; the backend is ``"cutoff"``).

The core is defined in :mod:`swarm_envs.envs.cores.cutoff.core`. Its names are here
too; the names with ``sparse`` in them warn (:class:`DeprecationWarning`) and give the
``cutoff`` ones: ``SparseSwarmNavCore`` is :class:`CutoffSwarmNavCore`,
``SPARSE_MIN_AGENTS`` is :data:`CUTOFF_MIN_AGENTS` and ``use_sparse_core`` is
:func:`use_cutoff_core`.
"""

from __future__ import annotations

import warnings
from typing import Any

from swarm_envs.envs.cores.cutoff import core as _core
from swarm_envs.envs.cores.cutoff.core import (
    CUTOFF_MIN_AGENTS,
    DEFAULT_CUTOFF_SPEED,
    DEFAULT_CUTOFF_TOL,
    CutoffSwarmNavCore,
    density_preserving_radius,
    use_cutoff_core,
)

#: The names with ``sparse`` in them, and the names they stand for.
RENAMED = {
    "SparseSwarmNavCore": "CutoffSwarmNavCore",
    "SPARSE_MIN_AGENTS": "CUTOFF_MIN_AGENTS",
    "use_sparse_core": "use_cutoff_core",
}

__all__ = [
    "CUTOFF_MIN_AGENTS",
    "DEFAULT_CUTOFF_SPEED",
    "DEFAULT_CUTOFF_TOL",
    "CutoffSwarmNavCore",
    "density_preserving_radius",
    "use_cutoff_core",
]


def __getattr__(name: str) -> Any:
    """A name with ``sparse`` in it: its ``cutoff`` name's object, with a warning."""
    if name in RENAMED:
        new = RENAMED[name]
        warnings.warn(
            f"swarm_envs.envs.sparse_core.{name} is deprecated: use {new} from "
            "swarm_envs.envs.cores.cutoff.core (the backend is 'cutoff')",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(_core, new)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
