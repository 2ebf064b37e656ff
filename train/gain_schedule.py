"""Gain schedules: a learned map from each agent's observation to its baseline's gains.

A residual policy (:mod:`train.residual`) adds a learned correction to a baseline's
action. A gain schedule corrects the baseline's *gains* instead: each agent's gains are
the tuned ones, scaled or shifted by a linear function of a few features of its own
observation,

    z = clip(W f(o), −1, 1),
    g_j = g_j⁰ · e^{z_j}  (a gain),   g_j = max(0, g_j⁰ + ½ z_j)  (a length),

and the agent acts as the baseline does with those gains. With ``W = 0`` it is the
baseline exactly, and whatever ``W`` it stays in the baseline's family: each gain within
a factor ``e`` of its tuned value, each length within ½ of it. The tuned gains are one
point for every state; the schedule lets them depend on what the agent sees (how fast
it moves, whether an informed agent is in view, how far its neighbours are).

``residual_corrects: gains`` in an ``algo: ES`` train config trains ``W`` by evolution
strategies (:mod:`train.es`) for a baseline of :data:`SCHEDULES`; the model records
``W`` with the baseline and its gains (``RESIDUAL``'s ``schedule``), and
:func:`train.residual.as_policy` rebuilds the policy as a :class:`GainScheduledPolicy`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from train.residual import ResidualPolicy

__all__ = [
    "SCHEDULES",
    "GainScheduledPolicy",
    "Schedule",
    "ScheduleActor",
    "check_schedule_record",
    "follow_features",
    "schedule_of",
    "schedule_record",
    "scheduled_actions",
    "scheduled_gains",
]

#: How far a schedule may shift a length (``½ z``, ``|z| ≤ 1``).
LENGTH_SHIFT = 0.5


def follow_features(controller: Any, obs: np.ndarray) -> np.ndarray:
    """``follow``'s schedule features ``(n, 7)`` of per-agent observations ``(n,
    obs_dim)``, each of order one on the default tasks: 1; its own speed / 3; whether an
    informed neighbour is in view; the informed share of its k neighbour slots; the
    distance to its neighbours' centroid / 2; their mean relative speed / 3; its goal
    distance / 10, at most 2 (0 for an agent not informed)."""
    d, k = controller.dim, controller.cfg.n_neighbors
    view = controller.neighbour_view(obs)
    count = np.maximum(view.real.sum(axis=1, keepdims=True), 1.0)
    centroid = np.einsum("nk,nkd->nd", view.real, view.offset) / count
    rel_velocity = np.einsum("nk,nkd->nd", view.real, view.rel_velocity) / count
    velocity = obs[:, d : 2 * d] * controller.obs_velocity_scale
    goal = obs[:, :d] * controller.obs_goal_scale
    told = view.informed.sum(axis=1)
    return np.stack(
        [
            np.ones(len(obs)),
            np.linalg.norm(velocity, axis=1) / 3.0,
            (told > 0).astype(np.float64),
            told / k,
            np.linalg.norm(centroid, axis=1) / 2.0,
            np.linalg.norm(rel_velocity, axis=1) / 3.0,
            np.minimum(np.linalg.norm(goal, axis=1) / 10.0, 2.0),
        ],
        axis=1,
    )


@dataclass(frozen=True)
class Schedule:
    """What a baseline's gain schedule varies and reads.

    Attributes:
        scaled: gains multiplied by ``e^z``.
        shifted: lengths shifted by ``½ z`` (kept ``≥ 0``).
        features: ``(controller, obs (n, obs_dim)) -> (n, len(feature_names))``.
        feature_names: the features, in order (recorded with a model).
    """

    scaled: tuple[str, ...]
    shifted: tuple[str, ...]
    features: Callable[[Any, np.ndarray], np.ndarray]
    feature_names: tuple[str, ...]

    @property
    def gain_names(self) -> tuple[str, ...]:
        """Every scheduled gain, in the order of ``W``'s columns."""
        return self.scaled + self.shifted

    @property
    def shape(self) -> tuple[int, int]:
        """The shape of ``W``: features × gains."""
        return len(self.feature_names), len(self.gain_names)

    @property
    def size(self) -> int:
        """The entries of ``W``."""
        return self.shape[0] * self.shape[1]


#: The baselines a gain schedule can correct, by name (``agents.CONTROLLERS``).
SCHEDULES: dict[str, Schedule] = {
    "follow": Schedule(
        scaled=("k_p", "k_d", "k_l", "k_v", "k_c"),
        shifted=("tether", "lead", "flock_lead"),
        features=follow_features,
        feature_names=(
            "one",
            "speed",
            "informed_in_view",
            "informed_share",
            "neighbour_distance",
            "neighbour_speed",
            "goal_distance",
        ),
    ),
}


def schedule_of(name: str) -> Schedule:
    """The :class:`Schedule` of baseline ``name``, else ``ValueError`` naming those that
    have one."""
    if name not in SCHEDULES:
        raise ValueError(
            f"residual_corrects: gains needs a baseline with a gain schedule "
            f"({', '.join(SCHEDULES)}), got residual {name!r}"
        )
    return SCHEDULES[name]


def scheduled_gains(
    baseline: Any, schedule: Schedule, weights: np.ndarray, obs: np.ndarray
) -> dict[str, np.ndarray]:
    """Each agent's gains ``{name: (n, 1)}`` under the schedule ``weights`` for per-agent
    observations ``(n, obs_dim)``: ``W`` shaped ``(features, gains)`` for all agents, or
    ``(n, features, gains)``, one per agent."""
    obs = np.asarray(obs, np.float64)
    features = schedule.features(baseline, obs)
    per_agent = "nf,nfg->ng" if np.ndim(weights) == 3 else "nf,fg->ng"
    z = np.clip(np.einsum(per_agent, features, weights), -1.0, 1.0)
    own = baseline.gains()
    gains: dict[str, np.ndarray] = {}
    for j, name in enumerate(schedule.gain_names):
        column = z[:, j : j + 1]
        if name in schedule.scaled:
            gains[name] = own[name] * np.exp(column)
        else:
            gains[name] = np.maximum(own[name] + LENGTH_SHIFT * column, 0.0)
    return gains


def scheduled_actions(
    baseline: Any, schedule: Schedule, weights: np.ndarray, obs: np.ndarray
) -> np.ndarray:
    """The baseline's actions ``(n, d)`` (float64) for per-agent observations ``(n,
    obs_dim)`` with each agent's gains from :func:`scheduled_gains`."""
    obs = np.asarray(obs, np.float64)
    return baseline.actions_with_gains(obs, scheduled_gains(baseline, schedule, weights, obs))


def check_schedule_record(record: Any, name: str) -> np.ndarray:
    """The weights ``W`` ``(features, gains)`` of a model's ``schedule`` record for the
    baseline ``name``, checked against today's :data:`SCHEDULES` (a model whose features
    or gains differ was trained on another schedule: ``ValueError``)."""
    schedule = schedule_of(name)
    if not isinstance(record, Mapping) or "weights" not in record:
        raise ValueError(f"a gain schedule record holds weights, got {record!r}")
    for key, today in (("features", schedule.feature_names), ("gains", schedule.gain_names)):
        if tuple(record.get(key, ())) != today:
            raise ValueError(
                f"the model's gain schedule reads {key} {record.get(key)!r}; today's "
                f"`{name}` schedule has {list(today)}: retrain it"
            )
    weights = np.asarray(record["weights"], np.float64)
    if weights.shape != schedule.shape:
        raise ValueError(
            f"the gain schedule's weights are shaped {weights.shape}, expected {schedule.shape}"
        )
    return weights


def schedule_record(name: str, weights: np.ndarray) -> dict[str, Any]:
    """What a model records of its schedule (JSON-safe): features, gains, weights."""
    schedule = schedule_of(name)
    w = np.asarray(weights, np.float64).reshape(schedule.shape)
    return {
        "features": list(schedule.feature_names),
        "gains": list(schedule.gain_names),
        "weights": w.tolist(),
    }


class ScheduleActor:
    """ES's actor for a gain schedule (:class:`train.es.Rollouts`): ``θ`` is ``W``
    flattened, and the actions are the baseline's with the scheduled gains.

    ``load`` writes ``θ`` into ``model``'s residual record (``schedule``), so that the
    saved model is the scheduled policy."""

    def __init__(self, model: Any, baseline: Any, name: str) -> None:
        self.model = model
        self.baseline = baseline
        self.name = name
        self.schedule = schedule_of(name)
        self.size = self.schedule.size
        self.rowwise = True  # every feature, gain and action is computed row by row

    def flat(self) -> np.ndarray:
        """The recorded ``W`` flattened (zeros: the baseline itself, before training)."""
        from train.residual import RESIDUAL

        record = getattr(self.model, RESIDUAL, None) or {}
        if "schedule" in record:
            return check_schedule_record(record["schedule"], self.name).ravel()
        return np.zeros(self.size)

    def load(self, theta: np.ndarray) -> None:
        """Record ``θ`` as the model's schedule."""
        from train.residual import RESIDUAL

        record = dict(getattr(self.model, RESIDUAL))
        record["schedule"] = schedule_record(self.name, theta)
        setattr(self.model, RESIDUAL, record)

    def actions(self, thetas: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """Actions ``(P, n, d)`` (float32) of the ``P`` weight vectors ``thetas`` ``(P,
        size)`` for their observations ``(P, n, obs_dim)``."""
        P, n, od = obs.shape
        weights = np.repeat(thetas.reshape(P, *self.schedule.shape), n, axis=0)
        out = scheduled_actions(self.baseline, self.schedule, weights, obs.reshape(P * n, od))
        return out.reshape(P, n, -1).astype(np.float32)


class GainScheduledPolicy(ResidualPolicy):
    """A gain-scheduled model as one policy (SB3's ``predict``): the baseline's actions
    with each agent's gains from the recorded schedule (:func:`scheduled_actions`)."""

    def __init__(self, model: Any, baseline: Any, name: str, record: Any) -> None:
        super().__init__(model, baseline, 1.0)
        self.schedule = schedule_of(name)
        self.weights = check_schedule_record(record, name)

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        obs = np.asarray(observation)
        if obs.ndim == 0 or obs.shape[-1] != self.baseline.obs_dim:
            raise ValueError(
                f"observation has shape {obs.shape}; a gain-scheduled policy reads per-agent "
                f"observations, last axis {self.baseline.obs_dim}"
            )
        per_agent = obs.reshape(-1, obs.shape[-1])
        actions = scheduled_actions(self.baseline, self.schedule, self.weights, per_agent)
        return actions.astype(np.float32).reshape(*obs.shape[:-1], -1), state
