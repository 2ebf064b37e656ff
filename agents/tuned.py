"""Tuned gains of the simple baselines, read from ``configs/baselines/tuned.yaml``.

``swarm-tune`` (:mod:`train.tune_baselines`) writes that file: for each baseline and each
scenario key ``"<task>/<dynamics>"``, the gains that scored the highest mean return on
the training seeds. A controller built without explicit gains looks its scenario up
here (:func:`tuned_gains`); a scenario not in the file gets the controller's defaults.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import yaml

from swarm_envs.config import CONFIG_ROOT, SwarmConfig

__all__ = ["TUNED_PATH", "load_tuned", "scenario_key", "tuned_gains"]

#: A tuned value: a gain, or the name of a choice (``saturation``).
Gain = float | str

#: Where ``swarm-tune`` writes the tuned gains, and where controllers read them.
TUNED_PATH: Path = CONFIG_ROOT / "baselines" / "tuned.yaml"


def scenario_key(cfg: SwarmConfig) -> str:
    """The key of ``cfg``'s scenario in the tuned table: ``"<task>/<dynamics>"``.

    >>> scenario_key(SwarmConfig(dynamics="zone"))
    'navigation/zone'
    """
    return f"{cfg.task}/{cfg.dynamics}"


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
    """The tuned gains of ``baseline`` for ``cfg``'s scenario (``{}`` when untuned)."""
    return dict(load_tuned().get(baseline, {}).get(scenario_key(cfg), {}))
