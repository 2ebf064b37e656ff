"""Which core computes a SwarmNav step: dense numpy, sparse (cut-off), or fused torch.

Every core has the interface of :class:`~swarm_envs.envs.core.SwarmNavCore` and gives
the same results for the same seed and actions (to float tolerance; the sparse core up
to the force error of its cut-off, :mod:`swarm_envs.physics.cutoff`):

===========  =========================================================================
backend      what it is, and where it pays
===========  =========================================================================
``numpy``    :class:`~swarm_envs.envs.core.SwarmNavCore`: dense ``(B, N, N)`` pair
             arrays, every ``dynamics`` and integrator. Small swarms, few swarms.
``sparse``   :class:`~swarm_envs.envs.sparse_core.SparseSwarmNavCore`: a cut-off
             radius and an O(N) cell list (social potential only). Large swarms,
             from :data:`~swarm_envs.envs.sparse_core.SPARSE_MIN_AGENTS` agents.
``torch``    :class:`~swarm_envs.envs.torch_core.TorchSwarmNavCore`: the whole step as
             one ``torch.compile``-d function, on the CPU or ``device="cuda"``
             (social potential, semi-implicit Euler). Many swarms at once: from
             :data:`TORCH_MIN_SLOTS` agent slots (``B·N``) on the CPU; any size on a GPU.
===========  =========================================================================

``backend="auto"`` (the default) applies the rules of :func:`select_backend`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.core import SwarmNavCore
from swarm_envs.envs.sparse_core import SPARSE_MIN_AGENTS, SparseSwarmNavCore

#: Agent slots ``B·N`` from which ``"auto"`` runs the torch core on the CPU: below it
#: the compile time (tens of seconds, once) outweighs what the fused step saves.
TORCH_MIN_SLOTS = 16_384

__all__ = ["SPARSE_MIN_AGENTS", "TORCH_MIN_SLOTS", "make_core", "select_backend"]


def _torch_fits(cfg: SwarmConfig) -> bool:
    return cfg.dynamics == "social_potential" and cfg.integrator == "semi_implicit_euler"


def select_backend(cfg: SwarmConfig, batch: int = 1) -> str:
    """The backend that runs ``batch`` swarms of ``cfg`` (``cfg.backend`` unless "auto").

    ``"auto"``: a ``device`` other than the CPU → ``"torch"``; the social potential with
    at least ``SPARSE_MIN_AGENTS`` agents per swarm → ``"sparse"``; the social potential
    with the Euler integrator and at least ``TORCH_MIN_SLOTS`` agent slots → ``"torch"``;
    anything else → ``"numpy"``.

    >>> select_backend(SwarmConfig()), select_backend(SwarmConfig(), batch=4096)
    ('numpy', 'torch')
    >>> select_backend(SwarmConfig(n_agents=100_000))
    'sparse'
    >>> select_backend(SwarmConfig(dynamics="zone"), batch=4096)
    'numpy'
    """
    if cfg.backend != "auto":
        return cfg.backend
    if cfg.device != "cpu":
        return "torch"
    if cfg.dynamics == "social_potential" and cfg.n_agents >= SPARSE_MIN_AGENTS:
        return "sparse"
    if _torch_fits(cfg) and batch * cfg.n_agents >= TORCH_MIN_SLOTS:
        return "torch"
    return "numpy"


def make_core(cfg: SwarmConfig, batch: int = 1, dtype: Any = np.float64) -> Any:
    """A core for ``batch`` swarms of ``cfg`` on the backend :func:`select_backend` picks.

    Raises:
        ValueError: an explicit backend that does not support ``cfg`` (naming what
            it supports), or a torch device that is not available.
    """
    backend = select_backend(cfg, batch)
    if backend != "torch" and cfg.device != "cpu":
        raise ValueError(
            f"device={cfg.device!r} needs backend 'torch' (or 'auto'), got {backend!r}"
        )
    if backend == "numpy":
        return SwarmNavCore(cfg, batch=batch, dtype=dtype)
    if backend == "sparse":
        return SparseSwarmNavCore(cfg, batch=batch, dtype=dtype)
    from swarm_envs.envs.torch_core import TorchSwarmNavCore

    return TorchSwarmNavCore(cfg, batch=batch, dtype=dtype, device=cfg.device)
