"""Cucker–Smale flocking as a user's own model, in one file.

Importing this file registers the model ``dynamics="cucker_smale"``; every environment of
``swarm_envs`` then runs it on the numpy core (the other cores implement the shipped
social potential and refuse it, and the environment falls back to numpy with a warning)::

    import gymnasium as gym
    import swarm_envs
    import cucker_smale_model  # noqa: F401  (registers "cucker_smale")

    env = gym.make("swarm_envs/SwarmNav-v0", dynamics="cucker_smale",
                   model_params={"cucker_smale": {"K": 2.0}})

The model (F. Cucker and S. Smale, *Emergent behavior in flocks*, IEEE Trans. Automatic
Control 52(5), 2007): each agent steers its velocity toward its neighbours', weighted by a
communication rate that decays with distance,

    ``ẋ_i = v_i``,  ``m v̇_i = (1/N) Σ_j ψ(|x_j − x_i|) (v_j − v_i) + u_i``,
    ``ψ(r) = K / (1 + r²/σ²)^β``,

with the control ``u_i = u_max · a_i`` a force (zero action: the passive flock). For
``β < 1/2`` every start flocks: the velocities converge to their mean. The velocity
disagreement ``Γ = ½ m Σ_i |v_i − v̄|²`` never increases in the passive model (the
alignment is a symmetric, positive semi-definite damping of the velocity differences);
it is the model's ``energy`` statistic. With ``goal_in_physics`` the social potential's
goal sink (``physics.C_g, l_g``) pulls every agent too.

Integration: semi-implicit Euler in equal substeps. The alignment damps the velocity
differences at a rate of at most ``2K/m`` (Gershgorin on the weighted graph Laplacian,
``ψ ≤ K``), whatever the state, so the step-size rule (:func:`cucker_smale_substeps`) is
fixed by the parameters and every step takes the same substeps.

What this file defines, as ``docs/design.md`` ("Adding a model") describes: the
parameters (a frozen dataclass, the config section ``model_params["cucker_smale"]``), the
law and its simulator, the environment's adapter (a ``Dynamics`` subclass), the
step-size rule, and the registry entry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.dynamics import Dynamics
from swarm_envs.models import ModelSpec, register_model
from swarm_envs.physics import PairGeometry, goal_force
from swarm_envs.physics.integrators import euler_update, stable_substep, substep_plan


@dataclass(frozen=True)
class CuckerSmaleParams:
    """Parameters of the Cucker–Smale model (the config section ``cucker_smale``)."""

    K: float = 1.0
    """Coupling strength: the communication rate at distance 0, ``ψ(0) = K``, ``> 0``."""
    sigma: float = 1.0
    """Length scale of the communication rate, ``> 0``."""
    beta: float = 0.25
    """Decay exponent of the communication rate, ``≥ 0`` (``< 1/2``: unconditional
    flocking)."""
    m: float = 1.0
    """Agent mass, ``> 0``."""

    def __post_init__(self) -> None:
        for name, low, strict in (("K", 0.0, True), ("sigma", 0.0, True), ("beta", 0.0, False)):
            value = getattr(self, name)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            if not ok or not math.isfinite(value) or value < low or (strict and value == low):
                allowed = f"{'(' if strict else '['}{low:g}, inf)"
                raise ValueError(f"CuckerSmaleParams.{name} must be in {allowed}, got {value!r}")
            object.__setattr__(self, name, float(value))
        if not (isinstance(self.m, (int, float)) and math.isfinite(self.m) and self.m > 0):
            raise ValueError(f"CuckerSmaleParams.m must be in (0, inf), got {self.m!r}")
        object.__setattr__(self, "m", float(self.m))


def alignment_force(x: np.ndarray, v: np.ndarray, p: CuckerSmaleParams) -> np.ndarray:
    """``(1/N) Σ_j ψ(|x_j − x_i|) (v_j − v_i)`` for every agent, ``(..., N, d)``."""
    diff = x[..., None, :, :] - x[..., :, None, :]  # [i, j] = x_j − x_i
    psi = p.K / (1.0 + np.sum(diff * diff, axis=-1) / p.sigma**2) ** p.beta
    n = x.shape[-2]
    return (psi @ v - psi.sum(axis=-1, keepdims=True) * v) / n


def velocity_disagreement(v: np.ndarray, p: CuckerSmaleParams) -> np.ndarray:
    """``Γ = ½ m Σ_i |v_i − v̄|²``, shaped ``(...)``."""
    dv = v - v.mean(axis=-2, keepdims=True)
    return 0.5 * p.m * np.sum(dv * dv, axis=(-2, -1))


def simulate_cucker_smale(
    params: CuckerSmaleParams,
    x0: Any,
    v0: Any,
    *,
    dt: float,
    steps: int,
    goal: Any | None = None,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The passive model from ``(x0, v0)``, ``(..., N, d)``: ``steps`` semi-implicit
    Euler steps of ``dt``. Returns ``(xs, vs)``, each ``(steps + 1, ..., N, d)``.

    The model is deterministic (``rng`` is not used) and has no goal term (``goal``
    must be ``None``)."""
    del rng  # deterministic
    if goal is not None:
        raise ValueError("simulate_cucker_smale: the model has no goal term; pass goal=None")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"simulate_cucker_smale: dt must be in (0, inf), got {dt!r}")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ValueError(f"simulate_cucker_smale: steps must be an integer >= 0, got {steps!r}")
    x, v = np.array(x0, dtype=np.float64), np.array(v0, dtype=np.float64)
    if x.shape != v.shape or x.ndim < 2:
        raise ValueError(f"simulate_cucker_smale: x0 and v0 must be (..., N, d), got {x.shape}")
    xs, vs = np.empty((steps + 1, *x.shape)), np.empty((steps + 1, *x.shape))
    xs[0], vs[0] = x, v
    for n in range(steps):
        x, v = euler_update(x, v, alignment_force(x, v, params), dt, params.m)
        xs[n + 1], vs[n + 1] = x, v
    return xs, vs


def cucker_smale_substeps(cfg: SwarmConfig) -> int:
    """The step-size rule: the substeps of ``dt`` that keep semi-implicit Euler stable
    for the damping rate ``γ = 2K/m`` and, where the goal sink acts passively, its
    curvature ``ω² = C_g/(l_g² m)``."""
    p = cfg.dynamics_params
    omega2 = cfg.physics.C_g / (cfg.physics.l_g**2 * p.m) if cfg.passive_sink else 0.0
    h = stable_substep(np.float64(omega2), np.float64(2.0 * p.K / p.m))
    n, _ = substep_plan(np.float64(cfg.dt), h)
    return int(n)


class CuckerSmaleDynamics(Dynamics):
    """The environment's step: the rule's substeps of the alignment force, the passive
    sink (with ``goal_in_physics``) and the control ``u``, each a semi-implicit Euler
    update; the energy statistic is the velocity disagreement ``Γ``."""

    def __init__(self, cfg: SwarmConfig, batch: int, dtype: np.dtype) -> None:
        super().__init__(cfg, batch, dtype)
        self._n = self.fixed_substeps()

    def step(
        self,
        x: np.ndarray,
        v: np.ndarray,
        goal: np.ndarray | None,
        control: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, None]:
        p, h = self.cfg.dynamics_params, self.cfg.dt / self._n
        for _ in range(self._n):
            f = alignment_force(x, v, p)
            if goal is not None and self.cfg.physics.C_g > 0:
                f = f + goal_force(x, self.cfg.physics, goal)
            if control is not None:
                f = f + control
            x, v = euler_update(x, v, f.astype(self.dtype, copy=False), h, p.m)
        return x, v, None

    def measure(
        self, x: np.ndarray, v: np.ndarray, goal: np.ndarray, geometry: PairGeometry
    ) -> np.ndarray:
        return velocity_disagreement(v, self.cfg.dynamics_params)


CUCKER_SMALE = register_model(
    ModelSpec(
        name="cucker_smale",
        params=CuckerSmaleParams,
        section="cucker_smale",
        simulate=simulate_cucker_smale,
        adapter=CuckerSmaleDynamics,
        source="Cucker–Smale flocking (Cucker & Smale 2007)",
        action="a force added to the alignment force",
        substeps=cucker_smale_substeps,
        substeps_fixed=True,
        baseline="potential",
    ),
    replace=True,  # re-running this file replaces its own entry
)
