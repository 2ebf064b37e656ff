"""Tuned gains of the simple baselines, read from ``configs/baselines/tuned.yaml``.

``swarm-tune`` (:mod:`train.tune_baselines`) writes that file: for each baseline and each
scenario key (:func:`scenario_key`), the gains that scored the highest mean return on
the training seeds. A controller built without explicit gains looks its scenario up
here (:func:`tuned_gains`): a config with a fixed informed fraction gets the gains tuned
at that fraction where there are some, else those of its task and dynamics; a scenario
not in the file gets the controller's defaults.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import yaml

from swarm_envs.config import CONFIG_ROOT, SwarmConfig

__all__ = ["TUNED_PATH", "load_tuned", "scenario_key", "scenario_keys", "tuned_gains"]

#: A tuned value: a gain, or the name of a choice (``saturation``).
Gain = float | str

#: Where ``swarm-tune`` writes the tuned gains, and where controllers read them.
TUNED_PATH: Path = CONFIG_ROOT / "baselines" / "tuned.yaml"


def scenario_key(cfg: SwarmConfig) -> str:
    """The key of ``cfg``'s scenario in the tuned table: ``"<task>/<dynamics>"``, and
    ``"<task>/<dynamics>/informed=<f>"`` where ``cfg`` fixes its informed fraction ``f``
    below 1 (a range drawn per episode, the informed task's default, has the plain key).

    >>> scenario_key(SwarmConfig(dynamics="zone"))
    'navigation/zone'
    >>> scenario_key(SwarmConfig(task="informed", informed_fraction=0.1))
    'informed/social_potential/informed=0.1'
    """
    return scenario_keys(cfg)[0]


def scenario_keys(cfg: SwarmConfig) -> tuple[str, ...]:
    """The keys :func:`tuned_gains` looks ``cfg`` up by, the most specific first: its
    :func:`scenario_key`, then (for a fixed informed fraction) its task and dynamics'."""
    plain = f"{cfg.task}/{cfg.dynamics}"
    fraction = cfg.informed_fraction
    if isinstance(fraction, int | float) and fraction < 1:
        return (f"{plain}/informed={fraction:g}", plain)
    return (plain,)


@functools.cache
def load_tuned(path: Path = TUNED_PATH) -> dict[str, dict[str, dict[str, Gain]]]:
    """``{baseline: {scenario key: {gain: value}}}`` from ``path`` (empty if absent);
    a value is a number, or a name (``saturation``).

    Raises:
        ValueError: the file is not such a mapping.
    """
    if not path.is_file():
        return {}
    data: Any = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    tuned = data.get("baselines", {}) if isinstance(data, dict) else None
    if not isinstance(tuned, dict):
        raise ValueError(f"{path}: expected a mapping 'baselines: {{name: {{scenario: gains}}}}'")
    out: dict[str, dict[str, dict[str, Gain]]] = {}
    for name, scenarios in tuned.items():
        if not isinstance(scenarios, dict):
            raise ValueError(f"{path}: baselines.{name} must map scenarios to gains")
        out[name] = {}
        for key, entry in scenarios.items():
            gains = entry.get("gains") if isinstance(entry, dict) else None
            if not isinstance(gains, dict) or not all(
                isinstance(v, int | float | str) and not isinstance(v, bool) for v in gains.values()
            ):
                raise ValueError(
                    f"{path}: baselines.{name}.{key}.gains must map names to numbers or names"
                )
            out[name][key] = {k: v if isinstance(v, str) else float(v) for k, v in gains.items()}
    return out


def tuned_gains(baseline: str, cfg: SwarmConfig) -> dict[str, Gain]:
    """The tuned gains of ``baseline`` for ``cfg``'s scenario: those of the first of
    :func:`scenario_keys` in the table (``{}`` when none is)."""
    table = load_tuned().get(baseline, {})
    for key in scenario_keys(cfg):
        if key in table:
            return dict(table[key])
    return {}
