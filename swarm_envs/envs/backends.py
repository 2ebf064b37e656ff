"""Which core computes a SwarmNav step: numpy, cut-off, C, or torch.

Every core implements :class:`~swarm_envs.envs.protocol.Core` and executes the same
definitions (``docs/design.md``), so the same seed and actions give the same results to
float tolerance (the cut-off core up to the force error of its cut-off,
:mod:`swarm_envs.physics.cutoff`):

===========  =========================================================================
backend      what it is
===========  =========================================================================
``numpy``    :class:`~swarm_envs.envs.cores.numpy.SwarmNavCore`: dense ``(B, N, N)`` pair
             arrays; every ``dynamics`` and integrator. The reference.
``cutoff``   :class:`~swarm_envs.envs.cores.cutoff.core.CutoffSwarmNavCore`: a cut-off
             radius and an O(N) cell list (social potential). Large swarms.
``native``   :class:`~swarm_envs.envs.cores.native.NativeSwarmNavCore`: the step in C, compiled
             at install with the system C compiler (at first use where no library
             built at install fits; social potential, CPU).
``torch``    :class:`~swarm_envs.envs.cores.torch.core.TorchSwarmNavCore`: the step as one
             torch function, compiled where possible; CPU or ``device="cuda"`` (social
             potential, semi-implicit Euler).
===========  =========================================================================

Which models each core implements is the model registry's (``ModelSpec.backends`` of
:mod:`swarm_envs.models`): every model runs on ``numpy``; the others implement the
shipped social potential, and refuse the other models and a user's.

``backend="auto"`` (the default) picks by measured speed among the backends that
support the config (:func:`select_backend`; ``docs/performance.md`` has the
measurements). A backend asked for by name that cannot run a config is refused up front
(each core's ``unsupported(cfg)`` says why); the env then runs on the backend ``auto``
picks among the others and warns once, naming both and the reason.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.cores.cutoff.core import CUTOFF_MIN_AGENTS, CutoffSwarmNavCore
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.protocol import Core
from swarm_envs.envs.step_control import check_step_control
from swarm_envs.models import model_spec, models_on

#: Agent slots ``B·N`` from which ``"auto"`` runs the torch core on the CPU where the C
#: step is not available: below it the compile time (tens of seconds, once) outweighs
#: what the fused step saves over numpy.
TORCH_MIN_SLOTS = 16_384

__all__ = [
    "CUTOFF_MIN_AGENTS",
    "TORCH_MIN_SLOTS",
    "make_core",
    "resolve_backend",
    "select_backend",
    "unsupported",
]

_WARNED: set[tuple[str, ...]] = set()


def _core_class(backend: str) -> Any:
    if backend == "numpy":
        return SwarmNavCore
    if backend == "cutoff":
        return CutoffSwarmNavCore
    if backend == "native":
        from swarm_envs.envs.cores.native import NativeSwarmNavCore

        return NativeSwarmNavCore
    from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore

    return TorchSwarmNavCore


#: The backends whose cores take agent statuses (``set_status``): removed, frozen,
#: absent and joining agents, and ``observe_status``; every backend does. A backend not
#: listed would run only the perturbations that leave every agent in the physics
#: (passive failures, noise, dropout).
STATUS_BACKENDS = ("native", "numpy", "torch", "cutoff")


def _needs_statuses(cfg: SwarmConfig) -> bool:
    return cfg.needs_statuses


def unsupported(cfg: SwarmConfig, backend: str) -> str | None:
    """Why ``backend`` cannot run ``cfg`` here (``None`` if it can).

    >>> unsupported(SwarmConfig(dynamics="zone"), "torch")
    "supports dynamics='social_potential' only, got 'zone'"
    """
    if backend not in model_spec(cfg.dynamics).backends:
        names = " or ".join(f"{name!r}" for name in models_on(backend))
        return f"supports dynamics={names} only, got {cfg.dynamics!r}"
    if backend not in STATUS_BACKENDS and _needs_statuses(cfg):
        return (
            "does not take agent statuses (removed, frozen, absent or joining agents, "
            f"observe_status); backends that do: {', '.join(map(repr, STATUS_BACKENDS))}"
        )
    if backend == "numpy":
        return None if cfg.device == "cpu" else f"runs on the CPU only, got device={cfg.device!r}"
    if backend == "cutoff":
        if cfg.device != "cpu":
            return f"runs on the CPU only, got device={cfg.device!r}"
        return CutoffSwarmNavCore.unsupported(cfg)
    return _core_class(backend).unsupported(cfg)


def _auto(cfg: SwarmConfig, batch: int) -> tuple[str, str | None]:
    """``auto``'s pick and, if the C step would have been picked but cannot run, why."""
    pick, why = _auto_by_speed(cfg, batch)
    if (_needs_statuses(cfg) or cfg.informs_agents) and unsupported(cfg, pick) is not None:
        for name in ("native", "numpy", "torch"):
            if unsupported(cfg, name) is None:
                return name, None
        raise ValueError(f"no backend can run this config: {pick!r} {unsupported(cfg, pick)}")
    return pick, why


def _auto_by_speed(cfg: SwarmConfig, batch: int) -> tuple[str, str | None]:
    if cfg.device != "cpu":
        return "torch", None
    implemented = model_spec(cfg.dynamics).backends
    if (
        "cutoff" in implemented
        and cfg.n_agents >= CUTOFF_MIN_AGENTS
        and unsupported(cfg, "cutoff") is None
    ):
        return "cutoff", None
    why = unsupported(cfg, "native")
    if why is None:
        return "native", None
    from swarm_envs.envs.cores.native.core import UNAVAILABLE

    missing = why if why.startswith(UNAVAILABLE) else None  # not built here: say so
    if "native" in implemented and cfg.integrator != "velocity_verlet":
        if batch * cfg.n_agents >= TORCH_MIN_SLOTS and unsupported(cfg, "torch") is None:
            return "torch", missing
        return "numpy", missing
    return "numpy", None


def select_backend(cfg: SwarmConfig, batch: int = 1) -> str:
    """The backend that runs ``batch`` swarms of ``cfg``: ``cfg.backend`` where it
    supports ``cfg``, else ``auto``'s pick.

    ``"auto"``: a ``device`` other than the CPU → ``"torch"``; the social potential with
    at least ``CUTOFF_MIN_AGENTS`` agents per swarm → ``"cutoff"``; wherever the C step
    runs the config → ``"native"`` (the fastest at every batch size measured); where it
    is not available, the social potential with the Euler integrator and at least
    ``TORCH_MIN_SLOTS`` agent slots → ``"torch"``; anything else → ``"numpy"``.

    >>> select_backend(SwarmConfig(dynamics="zone"), batch=4096)
    'numpy'
    >>> select_backend(SwarmConfig(n_agents=100_000))
    'cutoff'
    """
    if cfg.backend != "auto" and unsupported(cfg, cfg.backend) is None:
        return cfg.backend
    return _auto(cfg, batch)[0]


def _warn_once(key: tuple[str, ...], message: str) -> None:
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(message, UserWarning, stacklevel=3)


def resolve_backend(cfg: SwarmConfig, batch: int = 1) -> str:
    """:func:`select_backend`, warning where a backend cannot be used.

    A backend named in ``cfg.backend`` that cannot run ``cfg`` falls back to ``auto``'s
    pick with a :class:`UserWarning` (once per backend and reason) naming both; so does
    ``auto`` where the C step would run the config but cannot be built here.

    Raises:
        ValueError: a ``device`` other than the CPU with a backend that runs on the CPU
            only.
    """
    if cfg.device != "cpu" and cfg.backend not in ("auto", "torch"):
        raise ValueError(
            f"device={cfg.device!r} needs backend 'torch' (or 'auto'), got {cfg.backend!r}"
        )
    if cfg.backend == "auto":
        backend, why = _auto(cfg, batch)
        if why is not None:
            _warn_once(("native", why), f"backend 'native' unavailable ({why}); using {backend!r}")
        return backend
    why = unsupported(cfg, cfg.backend)
    if why is None:
        return cfg.backend
    chosen = _auto(cfg, batch)[0]
    _warn_once(
        (cfg.backend, chosen, why),
        f"backend {cfg.backend!r} cannot run this config ({why}); using {chosen!r}",
    )
    return chosen


def make_core(cfg: SwarmConfig, batch: int = 1, dtype: Any = np.float64) -> Core:
    """A core for ``batch`` swarms of ``cfg`` on the backend :func:`resolve_backend`
    gives (warning there if the requested one cannot run ``cfg``).

    Raises:
        ValueError: a torch device that is not available, a ``device`` other than the
            CPU with a backend that runs on the CPU only, or a config whose steps
            predictably need more than ``max_substeps`` substeps
            (:func:`~swarm_envs.envs.step_control.check_step_control`).
    """
    check_step_control(cfg)
    backend = resolve_backend(cfg, batch)
    cls = _core_class(backend)
    if backend == "torch":
        core = cls(cfg, batch=batch, dtype=dtype, device=cfg.device)
    else:
        core = cls(cfg, batch=batch, dtype=dtype)
    if cfg.perturbations.any:
        from swarm_envs.envs.perturbed import PerturbedCore

        return PerturbedCore(core)
    return core
