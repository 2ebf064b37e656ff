"""What a config's step-size control predictably needs, checked when an env is built.

Every step of ``dt`` is integrated in as many substeps as the state's stiffness needs
(``docs/models.md`` §7), at most ``SwarmConfig.max_substeps``; a state that needs more
fails the step (:class:`~swarm_envs.envs.common.SwarmUnstableError`, or truncation).
Some configs fail predictably, before any step: :func:`check_step_control` refuses them
when the env is built, with the reason. Each model's step-size rule
(``ModelSpec.substeps`` of :mod:`swarm_envs.models`) says what a step needs
(:func:`start_substeps`); the shipped rules are here:

- Piecewise model: its rates do not depend on the state, so every step needs the same
  substeps (:func:`piecewise_substeps`; ``ModelSpec.substeps_fixed``, and the model's
  adapter takes that many).
- Social potential model: the start. The agents start uniform in a ball of radius
  ``R = start_radius`` (``init_radius``, or from ``init_density``), so the agent at
  its centre feels, on average, ``Σ_j κ(ρ_ij) ≈ (N − 1) E[κ(ρ)]`` with ``ρ`` uniform
  in the ball (and the same for the alignment rate); the Gershgorin rates of
  :func:`~swarm_envs.physics.social_potential.pair_rates` from these sums give the
  substeps an average start needs (:func:`social_potential_substeps`). A config whose
  average start already needs more than ``max_substeps`` is refused; dissipation alone
  (``γ ≥ β/m``) is part of it. With ``integrator="implicit_damping_euler"`` the rule is
  the block bound of :func:`~swarm_envs.physics.social_potential.stiffness_rate` and
  the damping does not limit the step: the agent at the centre has neighbours in every
  direction, so its ``Q`` is isotropic, ``(N − 1) E[p(ρ)]/d · I``, and its bound
  ``(N − 1) (E[k(ρ)] + E[p(ρ)]/d)`` (:func:`ball_mean` of
  :func:`~swarm_envs.physics.social_potential.stiffness_law`).
- The zone model is a discrete-time model (its turn per step is part of the model) and
  the Lagrangian model has its own safe substep: they have no rule, nothing to predict.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.models import model_spec
from swarm_envs.physics.integrators import stable_substep, substep_plan
from swarm_envs.physics.piecewise import piecewise_rates
from swarm_envs.physics.social_potential import RHO_FLOOR, stiffness_law

__all__ = [
    "ball_mean",
    "ball_mean_decay",
    "check_step_control",
    "piecewise_substeps",
    "social_potential_substeps",
    "start_substeps",
]

#: Quadrature points of :func:`ball_mean_decay`.
_QUADRATURE = 4097


def ball_mean_decay(radius: float, length: float, dim: int) -> float:
    """``E[e^{−ρ/l}]`` for ``ρ`` the distance from the centre of a uniform ``dim``-ball
    of ``radius`` to a uniform point in it: ``(d/R^d) ∫_0^R e^{−ρ/l} ρ^{d−1} dρ``.

    >>> round(ball_mean_decay(0.0, 1.0, 2), 6), round(ball_mean_decay(1e-9, 1.0, 3), 6)
    (1.0, 1.0)
    >>> round(ball_mean_decay(100.0, 1.0, 2), 6)  # 2 l² / R² far out
    0.0002
    """
    if radius <= 0:
        return 1.0
    s = np.linspace(0.0, 1.0, _QUADRATURE)  # ρ = R s
    weight = dim * s ** (dim - 1) * np.exp(-s * (radius / length))
    return float(np.trapezoid(weight, s))


def ball_mean(radius: float, fn: Callable[[np.ndarray], np.ndarray], dim: int) -> float:
    """``E[fn(ρ)]`` for ``ρ`` the distance from the centre of a uniform ``dim``-ball of
    ``radius`` to a uniform point in it: ``(d/R^d) ∫_0^R fn(ρ) ρ^{d−1} dρ`` (``fn(0)``
    where ``radius = 0``); ``fn`` is evaluated on an array of distances.

    >>> round(ball_mean(2.0, lambda rho: rho, 2), 6)  # E[ρ] = 2R/3 in a disc
    1.333333
    """
    if radius <= 0:
        return float(np.asarray(fn(np.zeros(1)))[0])
    s = np.linspace(0.0, 1.0, _QUADRATURE)
    weight = dim * s ** (dim - 1) * fn(radius * s)
    return float(np.trapezoid(weight, s))


def start_substeps(cfg: SwarmConfig) -> int:
    """The substeps a step needs at an average start, by the step-size rule of the
    model (``ModelSpec.substeps``); 1 for the models whose needs are not predicted."""
    rule = model_spec(cfg.dynamics).substep_rule()
    return 1 if rule is None else int(rule(cfg))


def piecewise_substeps(cfg: SwarmConfig) -> int:
    """The substeps every step of the piecewise model needs (its rates are fixed by the
    parameters, :func:`~swarm_envs.physics.piecewise.piecewise_rates`; the goal sink's
    curvature ``C_g/l_g²`` joins them when it acts passively)."""
    omega2, gamma = piecewise_rates(cfg.piecewise)
    if cfg.passive_sink:
        omega2 += cfg.physics.C_g / (cfg.physics.l_g**2 * cfg.piecewise.m)
    n, _ = substep_plan(np.float64(cfg.dt), stable_substep(np.float64(omega2), np.float64(gamma)))
    return int(n)


def social_potential_substeps(cfg: SwarmConfig) -> int:
    """The substeps a step of the social potential model needs at an average start
    (the module docstring)."""
    p, n, R, d = cfg.physics, cfg.n_agents - 1, cfg.start_radius, cfg.dim
    if cfg.integrator == "implicit_damping_euler":

        def centre(rho: np.ndarray) -> np.ndarray:
            inv = 1.0 / np.maximum(rho, RHO_FLOOR)
            k, q = stiffness_law(rho, inv, p.C_a, p.C_r, p.l_a, p.l_r, np.exp, np.maximum)
            return k + q / d

        omega2 = n * ball_mean(R, centre, d) / p.m
        if cfg.passive_sink:
            omega2 += p.C_g / (p.l_g**2 * p.m)
        h = stable_substep(np.float64(omega2), np.float64(0.0), integrator=cfg.integrator)
        needed, _ = substep_plan(np.float64(cfg.dt), h)
        return int(needed) if math.isfinite(needed) else 2**62
    kappa = n * (
        p.C_r / p.l_r**2 * ball_mean_decay(R, p.l_r, d)
        + p.C_a / p.l_a**2 * ball_mean_decay(R, p.l_a, d)
    )
    omega2 = 2.0 * kappa / p.m
    if cfg.passive_sink:
        omega2 += p.C_g / (p.l_g**2 * p.m)
    # self-propelled agents cruise at v₀, where the Rayleigh rate 3β v₀² − α is 2α
    rate = 2.0 * p.alpha if p.alpha > 0 else p.beta
    gamma = (rate + 2.0 * n * p.C_o * ball_mean_decay(R, p.l_o, d)) / p.m
    h = stable_substep(np.float64(omega2), np.float64(gamma), integrator=cfg.integrator)
    needed, _ = substep_plan(np.float64(cfg.dt), h)
    return int(needed) if math.isfinite(needed) else 2**62


def check_step_control(cfg: SwarmConfig) -> None:
    """Refuse (:class:`ValueError`) a config whose steps predictably need more
    substeps than ``max_substeps`` (see the module docstring)."""
    needed = start_substeps(cfg)
    if needed <= cfg.max_substeps:
        return
    if model_spec(cfg.dynamics).substeps_fixed:
        what = f"every step of dynamics={cfg.dynamics!r} (its stiffness is fixed by its parameters)"
    else:
        what = (
            f"an average start of {cfg.n_agents} agents in a ball of radius "
            f"{cfg.start_radius:g} (init_radius or init_density)"
        )
    raise ValueError(
        f"predictably unstable config: {what} needs about {needed} substeps of dt={cfg.dt:g} "
        f"for a stable integration, more than max_substeps={cfg.max_substeps}. Raise "
        f"max_substeps, lower dt, start less dense (init_radius or init_density), or soften "
        f"the physics (docs/models.md §7)"
    )
