"""What a config's step-size control predictably needs, checked when an env is built.

Every step of ``dt`` is integrated in as many substeps as the state's stiffness needs
(``docs/models.md`` §7), at most ``SwarmConfig.max_substeps``; a state that needs more
fails the step (:class:`~swarm_envs.envs.common.SwarmUnstableError`, or truncation).
Some configs fail predictably, before any step: :func:`check_step_control` refuses them
when the env is built, with the reason.

- Piecewise model: its rates do not depend on the state, so every step needs the same
  substeps (:func:`~swarm_envs.envs.dynamics.piecewise_substeps`).
- Social potential model: the start. The agents start uniform in a ball of radius
  ``R = start_radius`` (``init_radius``, or from ``init_density``), so the agent at
  its centre feels, on average, ``Σ_j κ(ρ_ij) ≈ (N − 1) E[κ(ρ)]`` with ``ρ`` uniform
  in the ball (and the same for the alignment rate); the Gershgorin rates of
  :func:`~swarm_envs.physics.social_potential.pair_rates` from these sums give the
  substeps an average start needs (:func:`start_substeps`). A config whose average
  start already needs more than ``max_substeps`` is refused; dissipation alone
  (``γ ≥ β/m``) is part of it.
- The zone model is a discrete-time model (its turn per step is part of the model) and
  the Lagrangian model has its own safe substep: nothing to predict.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.physics.integrators import stable_substep, substep_plan

__all__ = ["ball_mean_decay", "check_step_control", "start_substeps"]

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


def start_substeps(cfg: SwarmConfig) -> int:
    """The substeps a step needs at an average start (see the module docstring); 1 for
    the models whose needs are not predicted."""
    if cfg.dynamics == "piecewise":
        from swarm_envs.envs.dynamics import piecewise_substeps

        return piecewise_substeps(cfg)
    if cfg.dynamics != "social_potential":
        return 1
    p, n, R, d = cfg.physics, cfg.n_agents - 1, cfg.start_radius, cfg.dim
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
    if cfg.dynamics == "piecewise":
        what = "every step of the piecewise model (its stiffness is fixed by its parameters)"
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
