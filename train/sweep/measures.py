"""What a sweep trial measures: the statistics of each task and their column names.

>>> measure_columns("navigate")[:3]
('return', 'success', 'time_to_goal')
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from swarm_envs import metrics

__all__ = [
    "DEFAULT_PLOT",
    "NAVIGATE_MEASURES",
    "RELAX_STATISTICS",
    "TASKS",
    "measure_columns",
]

TASKS = ("relax", "navigate")

#: Group statistics of the ``relax`` task, each from ``(x, v)`` shaped ``(T, N, d)``.
RELAX_STATISTICS: dict[str, Callable[..., np.ndarray]] = {
    "polarization": lambda x, v, p: metrics.polarization(v),
    "velocity_polarization": lambda x, v, p: metrics.velocity_polarization(v),
    "angular_momentum": lambda x, v, p: metrics.angular_momentum(x, v),
    "velocity_angular_momentum": lambda x, v, p: metrics.velocity_angular_momentum(x, v),
    "expanse": lambda x, v, p: metrics.expanse(x),
    "nearest_neighbor_distance": lambda x, v, p: metrics.nearest_neighbor_distance(x),
    "mean_speed": lambda x, v, p: np.sqrt(np.einsum("...k,...k->...", v, v)).mean(axis=-1),
    "energy": lambda x, v, p: metrics.total_energy(x, v, p),
}

#: Measures of one ``navigate`` episode (``time_to_goal`` is empty when it failed).
NAVIGATE_MEASURES = (
    "return",
    "success",
    "time_to_goal",
    "episode_length",
    "collisions",
    "control_effort",
    "final_expanse",
    "final_polarization",
    "final_angular_momentum",
    "final_nearest_neighbor_distance",
    "final_centroid_distance",
    "final_fraction_arrived",
)

#: Measures plotted when the config's ``plot`` is empty.
DEFAULT_PLOT = {
    "relax": (
        "final_expanse",
        "final_nearest_neighbor_distance",
        "final_velocity_polarization",
        "final_velocity_angular_momentum",
    ),
    "navigate": ("success", "time_to_goal", "return", "final_expanse"),
}


def measure_columns(task: str) -> tuple[str, ...]:
    """The measure columns a trial of ``task`` reports, in order.

    >>> measure_columns("relax")[:2]
    ('final_polarization', 'time_mean_polarization')
    """
    if task == "relax":
        return tuple(
            col for name in RELAX_STATISTICS for col in (f"final_{name}", f"time_mean_{name}")
        )
    if task == "navigate":
        return NAVIGATE_MEASURES
    raise ValueError(f"task must be one of {TASKS}, got {task!r}")
