"""What every SwarmNav core shares: input checks, the random starts and the guard's bounds.

Every core validates actions with :func:`check_actions` (or :func:`check_action_shape`
where it checks finiteness itself), and draws its starts with :func:`draw_starts`, so a
seed gives the same starts on every backend; a config whose starts predictably cannot
be drawn is refused when an env is built (:func:`check_start_fits`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from swarm_envs.physics import uniform_ball

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

#: The error message for NaN or infinite actions (every core and the C step raise it).
NON_FINITE_ACTIONS = "actions must be finite (got NaN or inf); allowed range [-1, 1]"


class SwarmUnstableError(RuntimeError):
    """A step went unstable: its state became non-finite, or it needed more substeps
    than ``max_substeps`` for a stable integration. The message names the swarm, the
    cause and the config keys that change it (``SwarmConfig.on_unstable = "truncate"``
    ends such an episode instead)."""


#: Statistics that are finite exactly when a swarm's positions and velocities are: the
#: step checks these ``(B,)`` values instead of every coordinate.
FINITE_KEYS = ("energy", "expanse", "mean_goal_distance")


#: The guard's margin on the derived speed bound (:func:`energy_bound`): the bound holds
#: for the exact dynamics, the margin covers the integration's error.
SPEED_MARGIN = 2.0


def speed_bound(cfg: SwarmConfig) -> float:
    """A bound on every agent's speed in the social potential model: ``inf`` where none
    is derived (other models, or no dissipation at all).

    For the fastest agent the alignment only slows it (it averages velocities), the pair
    forces are at most ``(N − 1)(C_r/l_r + C_a/l_a)``, the sink's ``C_g/l_g`` (where it
    acts) and the control ``u_max √d``; with linear friction ``m d|v|/dt ≤ D − β|v|``
    for that sum ``D``, so no speed passes ``max(init_speed, D/β)``; with the Rayleigh
    term ``(α − β|v|²)|v|`` replaces ``−β|v|`` and the terminal speed is at most
    ``max(√(2α/β), (2D/β)^{1/3})``. Joining and frozen agents are at rest.
    """
    if cfg.dynamics != "social_potential":
        return math.inf
    p = cfg.physics
    drive = (cfg.n_agents - 1) * (p.C_r / p.l_r + p.C_a / p.l_a) + cfg.u_max * math.sqrt(cfg.dim)
    if cfg.goal_in_physics:
        drive += p.C_g / p.l_g
    if p.alpha > 0:
        terminal = max(math.sqrt(2.0 * p.alpha / p.beta), (2.0 * drive / p.beta) ** (1.0 / 3.0))
    elif p.beta > 0:
        terminal = drive / p.beta
    else:
        return math.inf
    return max(cfg.init_speed, terminal)


def energy_bound(cfg: SwarmConfig) -> float:
    """The bound the guard holds the ``energy`` statistic to: ``|φ| ≤ ½ m N (2S)² +
    N(N − 1)/2 (C_r + C_a) + N C_g`` for the speed bound ``S`` (:func:`speed_bound`,
    with :data:`SPEED_MARGIN`), each pair's potential at most ``C_r + C_a`` and each
    agent's sink potential at most ``C_g``; ``inf`` where no speed bound is derived."""
    speed = speed_bound(cfg)
    if not math.isfinite(speed):
        return math.inf
    p, n = cfg.physics, cfg.n_agents
    top = SPEED_MARGIN * speed
    kinetic = 0.5 * p.m * n * top * top  # a product: ``inf``, not an error, past float range
    bound = kinetic + 0.5 * n * (n - 1) * (p.C_r + p.C_a) + n * p.C_g
    return bound if math.isfinite(bound) else math.inf


def beyond_bound(stats: dict[str, np.ndarray], bound: float) -> bool:
    """Whether some swarm's ``energy`` statistic is not within ``±bound`` (NaN
    included); ``False`` at once where ``bound`` is ``inf``."""
    return bound < math.inf and not bool((np.abs(stats["energy"]) <= np.float64(bound)).all())


def unstable_swarms(
    stats: dict[str, np.ndarray], over_cap: np.ndarray, bound: float = math.inf
) -> np.ndarray:
    """Where a step went unstable, ``(B,)`` bool: a non-finite state (seen in
    :data:`FINITE_KEYS`), an energy beyond ``bound`` (:func:`energy_bound`), or more
    substeps needed than the cap (``over_cap``)."""
    bad = np.array(over_cap, dtype=bool, copy=True)
    for key in FINITE_KEYS:
        bad |= ~np.isfinite(stats[key])
    if bound < math.inf:  # compared in float64: the bound may pass float32's range
        bad |= ~(np.abs(stats["energy"]) <= np.float64(bound))
    return bad


def check_start(
    cfg: SwarmConfig, stats: dict[str, np.ndarray], idx: np.ndarray, dtype: Any
) -> None:
    """Raise :class:`SwarmUnstableError` if a new start (swarms ``idx``) is not finite in
    the state's ``dtype`` (a start too large for it: its speeds, distances or energy)."""
    bad = np.zeros(next(iter(stats.values())).shape, dtype=bool)
    bad[idx] = unstable_swarms(stats, bad)[idx]
    if bad.any():
        b = int(np.flatnonzero(bad)[0])
        raise SwarmUnstableError(
            f"the start of swarm {b} is not finite in {np.dtype(dtype).name} (its energy, "
            f"expanse or goal distance overflows): lower init_speed, init_radius, the goal "
            f"distances or the physics' amplitudes, or use float64"
        )


def unstable_message(
    cfg: SwarmConfig, stats: dict[str, np.ndarray], bad: np.ndarray, needed: np.ndarray, step: Any
) -> str:
    """The :class:`SwarmUnstableError` message for the first unstable swarm of ``bad``."""
    b = int(np.flatnonzero(bad)[0])
    finite = all(np.isfinite(stats[key][b]) for key in FINITE_KEYS)
    where = f"swarm {b} of {bad.size}, step {int(step[b])}"
    bound = energy_bound(cfg)
    if finite and not abs(float(stats["energy"][b])) <= bound:
        cause = (
            f"the energy {float(stats['energy'][b]):.3g} left its bound ±{bound:.3g} (speeds "
            f"beyond the terminal speed {speed_bound(cfg):.3g} of the forces, control and "
            f"dissipation: the integration diverges)"
        )
    elif finite:
        cause = (
            f"the state needs at least {int(needed[b])} substeps of dt={cfg.dt:g} for a stable "
            f"integration, more than max_substeps={cfg.max_substeps}"
        )
    else:
        cause = "the state became NaN or infinite"
    hint = "raise max_substeps, lower dt"
    if cfg.dynamics == "social_potential":
        hint += (
            ", use fewer agents or an H-stable parameter set (physics with C_r/C_a * "
            "(l_r/l_a)^d > 1 in d dimensions, e.g. SocialPotentialParams.large_swarm()), "
            "or start less dense (init_radius or init_density)"
        )
    return (
        f"unstable step ({where}, {cfg.n_agents} agents, dynamics={cfg.dynamics!r}): {cause}. "
        f"To fix: {hint}; or pass on_unstable='truncate' to end such episodes instead."
    )


def check_action_shape(actions: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Actions as a numeric array of exactly ``shape`` (a same-size array of another
    rank is reshaped); a non-numeric dtype or another size → :class:`ValueError`."""
    a = np.asarray(actions)
    if a.dtype == object or not (
        np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)
    ):
        raise ValueError(f"actions must be a numeric array of shape {shape}, got dtype {a.dtype}")
    if a.shape != shape:
        if a.size == int(np.prod(shape)) and a.ndim != len(shape):
            a = a.reshape(shape)
        else:
            raise ValueError(f"actions must have shape {shape}, got {a.shape}")
    return a


def check_actions(actions: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Actions as a float array of exactly ``shape``; NaN/inf or wrong shape → ValueError.

    Finite values outside [−1, 1] are clipped (the Box convention of SB3 and RLlib).
    """
    a = check_action_shape(actions, shape)
    if not np.isfinite(a).all():
        raise ValueError(NON_FINITE_ACTIONS)
    return np.clip(a, -1.0, 1.0)


def check_batch(batch: Any) -> int:
    """The number of swarms of a core: an integer ``≥ 1``, else :class:`ValueError`."""
    if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 1:
        raise ValueError(f"batch must be an integer >= 1, got {batch!r}")
    return int(batch)


def check_dtype(dtype: Any) -> np.dtype:
    """A core's state dtype: float32 or float64, else :class:`ValueError`."""
    try:
        out = None if dtype is None else np.dtype(dtype)  # np.dtype(None) is float64
    except TypeError:
        out = None
    if out is None or out not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype must be float32 or float64, got {dtype!r}")
    return out


def draw_starts(
    cfg: SwarmConfig, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` new starts ``(x (n, N, d), v (n, N, d), goal (n, d))``, float64: the task's
    start law (its spec's ``start``) where it has one, else :func:`uniform_starts`."""
    law = cfg.task_spec.start
    return uniform_starts(cfg, rng, n) if law is None else law(cfg, rng, n)


def uniform_starts(
    cfg: SwarmConfig, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The default start law: ``n`` starts ``(x, v, goal)``, float64.

    Agents uniform in a disc (ball) of ``cfg.start_radius`` around the origin
    (``init_radius``, or the radius of ``init_density``), velocities uniform in a disc of
    ``init_speed``; the goal at a uniform random bearing and a distance uniform in
    ``[goal_distance_min, goal_distance_max]``, plus the start radius when
    ``goal_distance_scale == "relative"`` (measured from the start disc's edge).
    """
    N, d = cfg.n_agents, cfg.dim
    radius = cfg.start_radius
    x = uniform_ball(rng, (n, N, d), radius)
    v = uniform_ball(rng, (n, N, d), cfg.init_speed)
    bearing = rng.standard_normal((n, d))
    bearing /= np.maximum(np.linalg.norm(bearing, axis=-1, keepdims=True), 1e-12)
    dist = rng.uniform(cfg.goal_distance_min, cfg.goal_distance_max, size=(n, 1))
    if cfg.goal_distance_scale == "relative":
        dist += radius
    return x, v, bearing * dist


#: Trial starts that must fit, out of ``MAX_START_DRAWS``, for :func:`check_start_fits`.
START_FITS_NEEDED = 15


def check_start_fits(cfg: SwarmConfig) -> None:
    """Refuse a Lagrangian config whose random starts rarely place the bins apart.

    The Lagrangian model needs every pair of bins apart at the start, by a small gap
    (:func:`~swarm_envs.physics.lagrangian.well_separated`);
    a reset redraws a swarm's start up to ``MAX_START_DRAWS`` (1000) times, then raises.
    The config itself refuses a start radius at which the bins can never fit
    (:func:`swarm_envs.config.lagrangian_min_init_radius`); this check draws trial
    starts from a fixed generator and refuses the config (``ValueError`` naming
    ``init_radius`` and ``lagrangian.r``) when fewer than :data:`START_FITS_NEEDED` of
    ``MAX_START_DRAWS`` fit: a start fitting with a probability of about 1.5 % or less,
    at which a reset would fail with a probability of about ``1e-7`` or more. So such a
    config fails when the env is built rather than at some ``reset``. A usable config
    costs :data:`START_FITS_NEEDED` draws or a few more.
    """
    if cfg.dynamics != "lagrangian" or cfg.n_agents < 2:
        return
    from swarm_envs.envs.dynamics import MAX_START_DRAWS
    from swarm_envs.physics.lagrangian import well_separated

    n, d = cfg.n_agents, cfg.dim
    rng = np.random.default_rng(0)
    cap = max(1, 2**20 // (n * n))  # draws per batch: at most ~1M pair clearances
    drawn, fits, batch = 0, 0, START_FITS_NEEDED
    while fits < START_FITS_NEEDED:
        if fits + MAX_START_DRAWS - drawn < START_FITS_NEEDED:
            raise ValueError(
                f"SwarmConfig.init_radius={cfg.init_radius:g} is too small for {n} agents "
                f"with dynamics='lagrangian': fewer than {START_FITS_NEEDED} of "
                f"{MAX_START_DRAWS} random starts in a disc of that radius keep every pair "
                f"of bins (lagrangian.r) apart, so resets would fail; allowed: a larger "
                f"init_radius, or smaller lagrangian.r"
            )
        k = min(batch, cap, MAX_START_DRAWS - drawn)
        x = uniform_ball(rng, (k, n, d), cfg.init_radius)
        fits += int(well_separated(x, cfg.lagrangian).sum())
        drawn += k
        batch *= 4


def placed_at_rest(
    x: Any, v: Any, mobile: Any, place: Any, at: Any, xp: Any, *, component_first: bool = False
) -> tuple[Any, Any]:
    """New positions and velocities after a status change (numpy arrays or tensors, of
    ``x``'s dtype): the agents ``place`` ``(B, N)`` at ``at``, and every agent that does
    not move (``mobile`` ``(B, N)`` false) or was placed at rest.

    ``x``, ``v`` (and ``at``) are ``(B, N, d)``, or ``(d, B, N)`` with
    ``component_first``; ``place`` (and ``at``) may be ``None``: nobody is placed.
    ``xp``: the arrays' namespace (:mod:`swarm_envs._array`).
    """

    def spread(mask: Any) -> Any:
        return mask[None] if component_first else mask[..., None]

    still = ~mobile
    if place is not None:
        x = xp.astype(xp.where(spread(place), at, x), x)
        still = still | place
    return x, xp.astype(xp.where(spread(still), 0.0, v), v)


def wide_dtypes(dtype: np.dtype, cfg: SwarmConfig | None = None) -> dict[str, np.dtype]:
    """The dtype of each statistic a core reports (those of ``cfg``'s task; without
    ``cfg`` the common ones): float64 for the ``wide`` ones (counts, fractions, flags),
    ``dtype`` for the rest."""
    from swarm_envs.envs.task.statistics import task_statistics

    wide, narrow = np.dtype(np.float64), np.dtype(dtype)
    return {s.name: wide if s.wide else narrow for s in task_statistics(cfg)}


class StatisticColumns:
    """The statistics of a packed ``(B, P)`` array whose first columns are
    :data:`~swarm_envs.envs.task.STAT_KEYS`, as fresh ``(B,)`` arrays in the dtypes of
    :func:`wide_dtypes`.

    One copy per dtype (the core's, float64) holds every statistic of that dtype, one
    row each; each statistic is a row of its copy. The arrays of one call share no
    memory with the packed array, another call's, or each other's.
    """

    def __init__(self, dtype: np.dtype) -> None:
        from swarm_envs.envs.task.statistics import STATISTICS

        self._dtype = np.dtype(dtype)
        dtypes = wide_dtypes(self._dtype)  # the dtype of each statistic, defined there
        wide = [dtypes[s.name] != self._dtype for s in STATISTICS]
        self._narrow = [i for i, w in enumerate(wide) if not w]
        self._wide = [i for i, w in enumerate(wide) if w]
        row = {i: j for j, i in enumerate(self._narrow)} | {i: j for j, i in enumerate(self._wide)}
        self._rows = [(s.name, wide[i], row[i]) for i, s in enumerate(STATISTICS)]

    def split(self, packed: np.ndarray) -> dict[str, np.ndarray]:
        """``{key: (B,) array}`` of the statistics in ``packed``'s first columns."""
        columns = packed.T
        narrow = columns[self._narrow].astype(self._dtype, copy=False)  # a copy: indexed
        wide = columns[self._wide].astype(np.float64, copy=False)
        return {key: (wide if w else narrow)[j] for key, w, j in self._rows}
