"""The evaluation harness: every policy on the same seeded episodes, measured and reported."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agents.base import Controller, swarm_config_of
from swarm_envs import ENV_ID
from swarm_envs.config import SwarmConfig, as_dict
from train.evaluate.bound import bound_of_episodes, bound_reason, free_agent_time
from train.evaluate.episodes import run_episodes
from train.evaluate.measures import METRIC_DOCS, finite, summarize
from train.evaluate.policies import (
    TRAINED_ENV,
    SpaceMismatchError,
    config_for_policy,
    describe_trained_env,
    policy_mode,
    trained_env_differences,
)
from train.evaluate.report import write_outputs

__all__ = [
    "TrainedEnvWarning",
    "best_baseline",
    "check_policies",
    "controller_names",
    "evaluate_policies",
    "measure_row",
]


def controller_names(policies: Mapping[str, Any]) -> list[str]:
    """The names of the :mod:`agents` controllers among ``policies``: the baselines of
    an evaluation (a trained model never is one)."""
    return [name for name, policy in policies.items() if isinstance(policy, Controller)]


def best_baseline(
    measures: Mapping[str, Mapping[str, Any]], baselines: Sequence[str] | None = None
) -> str | None:
    """Among ``baselines`` (``None``: every entry of ``measures``), the one with the
    highest mean return (ties: the higher success rate, then the first named); ``None``
    when there is none.

    >>> best_baseline({"a": {"mean_return": 1.0}, "b": {"mean_return": 2.0},
    ...                "learned": {"mean_return": 3.0}}, ["a", "b"])
    'b'
    """
    names = list(measures if baselines is None else baselines)
    scored = [n for n in names if measures.get(n, {}).get("mean_return") is not None]
    if not scored:
        return None
    return max(
        scored,
        key=lambda n: (measures[n]["mean_return"], measures[n].get("success_rate") or 0.0),
    )


class TrainedEnvWarning(UserWarning):
    """A model is evaluated on an env whose observations or actions mean something else
    than in the env it was trained on (same spaces, other dynamics, layout or scales)."""


def check_policies(policies: Mapping[str, Any], cfg: SwarmConfig) -> None:
    """Check that every policy fits ``cfg`` (:func:`policy_mode`), and warn
    (:class:`TrainedEnvWarning`) about a model that records another env than ``cfg``
    in what its observations or actions mean.

    Raises:
        ValueError: no policies.
        SpaceMismatchError: a policy's spaces do not fit (the message names the policy
            and what a recorded model was trained on).
    """
    if not policies:
        raise ValueError("no policies to evaluate")
    for name, policy in policies.items():
        fitted = config_for_policy(policy, cfg)  # its own observe_status
        try:
            policy_mode(policy, fitted)
        except SpaceMismatchError as err:
            trained = describe_trained_env(policy)
            extra = f"; the model was {trained}" if trained else ""
            raise SpaceMismatchError(f"policy {name!r}: {err}{extra}") from None
        differences = trained_env_differences(getattr(policy, TRAINED_ENV, None), fitted)
        if differences:
            warnings.warn(
                f"policy {name!r} is evaluated on another env than it was trained on: "
                + "; ".join(differences),
                TrainedEnvWarning,
                stacklevel=3,
            )


def measure_row(
    policies: Mapping[str, Any],
    cfg: SwarmConfig,
    episodes: int,
    seed: int,
    *,
    label: str,
    deterministic: bool = True,
    progress: bool = True,
) -> dict[str, Any]:
    """One row of a sweep (size transfer, robustness): every policy on the same
    ``episodes`` episodes of ``cfg`` seeded with ``seed``, measured
    (:func:`~train.evaluate.measures.summarize`).

    Returns ``{"backend", "best_baseline", "policies": {name: measures}}``: the backends
    the episodes ran on (each policy runs with the observation layout it was trained on,
    which may need another; joined with ", " where they differ), the
    :func:`best_baseline` among the controllers, and each policy's measures. Each
    progress bar is named ``"<policy> <label>"``.
    """
    measures, backends = {}, []
    for name, policy in policies.items():
        batch = run_episodes(
            policy,
            cfg,
            episodes,
            seed,
            name=f"{name} {label}",
            deterministic=deterministic,
            progress=progress,
            record_episode=False,
        )
        backends.append(batch.backend)
        measures[name] = summarize(batch)
    return {
        "backend": ", ".join(dict.fromkeys(backends)),
        "best_baseline": best_baseline(measures, controller_names(policies)),
        "policies": measures,
    }


def evaluate_policies(
    policies: Mapping[str, Any],
    cfg: SwarmConfig | Any,
    episodes: int = 20,
    seed: int = 0,
    *,
    out_dir: str | Path | None = None,
    env_id: str = ENV_ID,
    deterministic: bool = True,
    progress: bool = True,
    gif: bool = True,
    plots: bool = True,
    gif_size: int = 300,
    extra: Mapping[str, Any] | None = None,
    baselines: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Evaluate every policy on the same ``episodes`` seeded episodes.

    Args:
        policies: ``{name: policy}``; each policy has SB3's ``predict``.
        cfg: the scenario, a :class:`SwarmConfig` or any swarm_envs env.
        episodes: episodes per policy.
        seed: seed of the start states, shared by all policies.
        out_dir: if given, write ``results.json``, ``summary.md``, ``curves.png`` and
            ``episode0_<name>.gif`` there (see :func:`write_outputs`).
        env_id: recorded in the results as ``"env"``.
        deterministic: passed to every ``predict``.
        progress: show a tqdm progress bar per policy.
        gif, plots: write the GIFs / the curves figure (with ``out_dir``).
        gif_size: GIF width and height in pixels.
        extra: more top-level entries for the results (e.g. the config path).
        baselines: the names among ``policies`` that are baselines: the one with the
            highest mean return is recorded as ``"best_baseline"`` (and marked in the
            tables). ``None``: the controllers of :mod:`agents` among them.

    The episodes run on the backend and device that ``cfg`` names (``backend``,
    ``device``; ``auto`` picks one), recorded as ``"backend"``. A model that records
    the env it was trained on (:func:`~train.evaluate.policies.trained_env_record`)
    and whose observations or actions mean something else here (other dynamics,
    observation layout, scales or ``u_max``) gives a :class:`TrainedEnvWarning`.

    Returns:
        ``{"env", "config", "backend", "episodes", "seed", "policies": {name: measures}}``, the
        content of ``results.json`` (JSON-ready; ``mean_time_to_goal`` may be None).

    Raises:
        SpaceMismatchError: a policy's spaces do not fit (checked for all before running;
            the message says what a recorded model was trained on).
    """
    cfg = swarm_config_of(cfg)
    check_policies(policies, cfg)
    batches = {
        name: run_episodes(
            policy,
            cfg,
            episodes,
            seed,
            name=name,
            deterministic=deterministic,
            progress=progress,
            record_episode=out_dir is not None and gif,
        )
        for name, policy in policies.items()
    }
    first = next(iter(batches.values()))
    start = (first.start["x"], first.start["v"], first.start["goal"])
    bound = bound_of_episodes(cfg, first.start)
    alone = free_agent_time(cfg, *start)
    measures = {name: summarize(b, bound) for name, b in batches.items()}
    results: dict[str, Any] = {
        "env": env_id,
        **dict(extra or {}),
        "config": as_dict(cfg),
        "backend": next(iter(batches.values())).backend,
        "episodes": int(episodes),
        "seed": int(seed),
        "metrics": METRIC_DOCS,
        "policies": measures,
        "time_to_goal_bound": None if bound is None else finite(bound.mean()),
        "time_to_goal_bound_per_episode": None if bound is None else bound.tolist(),
        "bound_undefined": bound_reason(cfg),
        "free_agent_time": None if alone is None else finite(alone.mean()),
        "best_baseline": best_baseline(
            measures, controller_names(policies) if baselines is None else baselines
        ),
    }
    if out_dir is not None:
        write_outputs(results, batches, cfg, out_dir, gif=gif, plots=plots, gif_size=gif_size)
    return results
