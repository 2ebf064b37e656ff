"""Shared checks for parameter dataclasses and state arrays.

Every check raises :class:`ValueError` whose message names the offending field and
the allowed range, so that a typo in a config or a sign slip never turns into a NaN
several thousand steps later.
"""

from __future__ import annotations

import math
from typing import Any, overload

import numpy as np

SUPPORTED_DIMS = (2, 3)


def check_real(
    owner: str,
    name: str,
    value: Any,
    *,
    low: float,
    high: float = math.inf,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> float:
    """Return ``value`` as a float if it is a finite real inside the given interval.

    Raises:
        ValueError: naming ``owner.name``, the value and the allowed interval.
    """

    def allowed() -> str:  # formatted only for an error (this check runs in resets)
        left = "[" if low_inclusive else "("
        if not math.isfinite(high):
            return f"{left}{low:g}, inf)"
        return f"{left}{low:g}, {high:g}{']' if high_inclusive else ')'}"

    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{owner}.{name} must be a real number in {allowed()}, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{owner}.{name} must be finite and in {allowed()}, got {value!r}")
    too_low = value < low if low_inclusive else value <= low
    too_high = value > high if high_inclusive else value >= high
    if too_low or too_high:
        raise ValueError(f"{owner}.{name} must be in {allowed()}, got {value!r}")
    return value


def as_state(a: Any, name: str, *, min_agents: int = 0) -> np.ndarray:
    """``a`` as a floating array shaped ``(..., N, d)``, d in {2, 3}, ``N ≥ min_agents``.

    Floating arrays keep their dtype (no copy); anything else becomes float64.
    """
    a = np.asarray(a)
    if not np.issubdtype(a.dtype, np.floating):
        a = a.astype(np.float64)
    if a.ndim < 2 or a.shape[-1] not in SUPPORTED_DIMS:
        raise ValueError(
            f"{name} must have shape (..., N, d) with d in {SUPPORTED_DIMS}, got {a.shape}"
        )
    if a.shape[-2] < min_agents:
        raise ValueError(
            f"{name} must hold at least {min_agents} agent(s) (N >= {min_agents}), "
            f"got shape {a.shape}"
        )
    return a


@overload
def check_state(x: Any, v: None = None) -> tuple[np.ndarray, None]: ...


@overload
def check_state(x: Any, v: Any) -> tuple[np.ndarray, np.ndarray]: ...


def check_state(x: Any, v: Any | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Validate positions (and velocities) shaped ``(..., N, d)`` with d in {2, 3}.

    Floating arrays keep their dtype (float32 stays float32); anything else becomes
    float64. Returns the arrays (no copy when already floating). Torch tensors are
    checked the same way and returned as they are (:func:`_check_tensors`).
    """
    if _is_tensor(x):
        return _check_tensors(x, v)
    x = as_state(x, "positions")
    if v is None:
        return x, None
    v = np.asarray(v)
    if not np.issubdtype(v.dtype, np.floating):
        v = v.astype(x.dtype)
    if v.shape != x.shape:
        raise ValueError(f"velocities shape {v.shape} must equal positions shape {x.shape}")
    return x, v


def _check_goal_tensor(goal: Any, x: Any) -> Any:
    """:func:`check_goal` for positions that are a torch tensor: a tensor like ``x``."""
    import torch

    g = torch.as_tensor(goal, dtype=x.dtype, device=x.device)
    if g.ndim < 1 or g.shape[-1] != x.shape[-1]:
        raise ValueError(
            f"goal must have shape (..., {x.shape[-1]}) like the positions, got {tuple(g.shape)}"
        )
    return g


def _is_tensor(a: Any) -> bool:
    return type(a).__module__.startswith("torch")


def _check_tensors(x: Any, v: Any | None) -> tuple[Any, Any | None]:
    """Floating torch tensors shaped ``(..., N, d)``, ``d`` in {2, 3}; ``v`` like ``x``."""
    if not x.is_floating_point():
        raise ValueError(f"positions must be a floating tensor, got dtype {x.dtype}")
    if x.ndim < 2 or x.shape[-1] not in SUPPORTED_DIMS:
        raise ValueError(
            f"positions must have shape (..., N, d) with d in {SUPPORTED_DIMS}, "
            f"got {tuple(x.shape)}"
        )
    if v is None:
        return x, None
    if not _is_tensor(v):
        raise ValueError(f"velocities must be a torch tensor like the positions, got {type(v)}")
    if v.shape != x.shape:
        raise ValueError(
            f"velocities shape {tuple(v.shape)} must equal positions shape {tuple(x.shape)}"
        )
    return x, v


def check_goal(goal: Any, x: np.ndarray) -> np.ndarray:
    """A goal position as an array of ``x``'s dtype with shape ``(..., d)``.

    Raises:
        ValueError: if the goal is not finite or its last dimension is not ``d``.
    """
    if _is_tensor(x):
        return _check_goal_tensor(goal, x)
    g = np.asarray(goal, dtype=x.dtype)
    d = x.shape[-1]
    if g.ndim < 1 or g.shape[-1] != d:
        raise ValueError(f"goal must have shape (..., {d}) like the positions, got {g.shape}")
    if not np.isfinite(g).all():
        raise ValueError("goal must be finite")
    return g


def check_run(owner: str, dt: Any, steps: Any) -> tuple[float, int]:
    """A simulation's step length (``> 0``) and step count (integer ``≥ 0``).

    Raises:
        ValueError: naming ``owner.dt`` or ``owner.steps`` and what is allowed.
    """
    dt = check_real(owner, "dt", dt, low=0.0, low_inclusive=False)
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
        raise ValueError(f"{owner}.steps must be an integer >= 0, got {steps!r}")
    return dt, int(steps)
