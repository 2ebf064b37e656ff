"""Random initial conditions, drawn only from a generator passed in (never global state)."""

from __future__ import annotations

import numpy as np

from swarm_envs.physics._validation import SUPPORTED_DIMS, check_real


def uniform_ball(
    rng: np.random.Generator,
    shape: tuple[int, ...],
    radius: float,
    dtype: np.dtype | type = np.float64,
) -> np.ndarray:
    """Points drawn uniformly in the ``d``-ball of the given radius; ``shape = (..., d)``.

    >>> pts = uniform_ball(np.random.default_rng(0), (1000, 2), radius=2.0)
    >>> bool((np.linalg.norm(pts, axis=-1) <= 2.0).all())
    True
    """
    d = shape[-1]
    if d not in SUPPORTED_DIMS:
        raise ValueError(f"uniform_ball: last dimension must be in {SUPPORTED_DIMS}, got {d}")
    check_real("uniform_ball", "radius", radius, low=0.0)
    direction = rng.standard_normal(shape)
    norm = np.linalg.norm(direction, axis=-1, keepdims=True)
    direction /= np.maximum(norm, 1e-300)
    r = radius * rng.random((*shape[:-1], 1)) ** (1.0 / d)
    return (direction * r).astype(dtype, copy=False)


def random_swarm(
    rng: np.random.Generator,
    n_agents: int,
    *,
    dim: int = 2,
    radius: float = 1.0,
    speed: float = 0.1,
    batch_shape: tuple[int, ...] = (),
    dtype: np.dtype | type = np.float64,
) -> tuple[np.ndarray, np.ndarray]:
    """Positions uniform in a ball of ``radius``, velocities uniform in a ball of ``speed``.

    Returns ``(x0, v0)`` shaped ``(*batch_shape, n_agents, dim)``.
    """
    if isinstance(n_agents, bool) or not isinstance(n_agents, (int, np.integer)) or n_agents < 1:
        raise ValueError(f"random_swarm: n_agents must be an integer >= 1, got {n_agents!r}")
    shape = (*batch_shape, int(n_agents), dim)
    return uniform_ball(rng, shape, radius, dtype), uniform_ball(rng, shape, speed, dtype)
