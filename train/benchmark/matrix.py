"""The benchmark matrix: which policies are trained and evaluated where.

A matrix file (``configs/benchmark/results.yaml``) holds one mapping with the key
``entries``, a list of entries. An entry names a task on one dynamics, the training
config of its learned policy and the analytic baselines it is compared with::

    entries:
      - name: navigation/zone          # unique; the folder of its models
        task: navigation               # the task (SwarmConfig.task), for training and evaluation
        dynamics: zone                 # SwarmConfig.dynamics, for training and evaluation
        train: configs/train/demo.yaml # the training config
        env: {n_agents: 10}            # optional SwarmConfig overrides (training and evaluation)
        train_overrides: {}            # optional TrainConfig overrides (total_timesteps, ...)
        evaluations:                   # optional; default: one, label "default", no overrides
          - {label: N10, env: {}}
          - {label: N20, env: {n_agents: 20}}
        baselines: [analytic, simple]  # optional; names of agents.CONTROLLERS, "analytic" (the
                                       # paper's controller) or "simple" (agents.SIMPLE, tuned)

Everything is checked when the file is loaded, before anything is trained: unknown keys
and bad values raise ``ValueError`` naming the entry and the key (building an
:class:`Entry` or :class:`Evaluation` with an unknown keyword raises ``TypeError``), and
each training config and evaluation config is built once, so a typo in an ``env``
override fails at once.

>>> e = Entry(name="navigation/zone", task="navigation", dynamics="zone",
...           train="configs/train/demo.yaml")
>>> e.train_config(seed=1).env["dynamics"], [v.label for v in e.evaluations]
('zone', ['default'])
>>> Entry(name="x", task="mill", dynamics="zone", train="demo", colour="red")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
TypeError: ...got an unexpected keyword argument 'colour'
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from swarm_envs.config import DYNAMICS, SwarmConfig, load_swarm_config, resolve_config_path
from swarm_envs.tasks import TASKS
from train.config import TrainConfig, load_train_config, merge_overrides, read_yaml_mapping

__all__ = ["DEFAULT_MATRIX", "Entry", "Evaluation", "Matrix", "load_matrix"]

#: The matrix ``swarm-benchmark`` runs unless ``--matrix`` names another.
DEFAULT_MATRIX = "configs/benchmark/results.yaml"

#: The top-level keys of a matrix file.
MATRIX_KEYS = ("entries",)

_NAME = re.compile(r"[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)*")
_LABEL = re.compile(r"[A-Za-z0-9_.=+-]+")


def _text(owner: str, key: str, value: Any, pattern: re.Pattern[str] | None = None) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"{owner}.{key} must be a non-empty string, got {value!r}")
    if pattern is not None and not pattern.fullmatch(value):
        raise ValueError(
            f"{owner}.{key} must use letters, digits and {pattern.pattern!r} only, got {value!r}"
        )
    return value


def _mapping(owner: str, key: str, value: Any) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise ValueError(f"{owner}.{key} must be a mapping, got {value!r}")
    return dict(value)


def _strict(owner: str, cls: type, data: Any) -> dict[str, Any]:
    """``data`` as keyword arguments of ``cls``; unknown keys raise ``ValueError``."""
    if not isinstance(data, Mapping):
        raise ValueError(f"{owner} must be a mapping, got {type(data).__name__}")
    allowed = [f.name for f in fields(cls)]
    unknown = [str(k) for k in data if k not in allowed]
    if unknown:
        raise ValueError(
            f"{owner}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}"
        )
    return dict(data)


@dataclass(frozen=True)
class Evaluation:
    """One evaluation of an entry: a ``label`` and env overrides on top of the entry's."""

    label: str = "default"
    env: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        _text("evaluation", "label", self.label, _LABEL)
        object.__setattr__(self, "env", _mapping(f"evaluation {self.label}", "env", self.env))


@dataclass(frozen=True)
class Entry:
    """One row group of the results: a task on one dynamics, its learned policy and
    baselines (see the module docstring for the keys)."""

    name: str
    task: str
    dynamics: str
    train: str
    env: dict = field(default_factory=dict)
    train_overrides: dict = field(default_factory=dict)
    evaluations: tuple = (Evaluation(),)
    baselines: tuple = ("analytic", "simple")

    def __post_init__(self) -> None:
        owner = f"entry {self.name!r}" if isinstance(self.name, str) else "entry"
        _text(owner, "name", self.name, _NAME)
        if any(part in (".", "..") for part in self.name.split("/")):
            raise ValueError(f"{owner}.name must not hold '.' or '..' parts")
        if self.task not in TASKS:
            raise ValueError(f"{owner}.task must be one of {', '.join(TASKS)}, got {self.task!r}")
        if self.dynamics not in DYNAMICS:
            raise ValueError(
                f"{owner}.dynamics must be one of {', '.join(DYNAMICS)}, got {self.dynamics!r}"
            )
        _text(owner, "train", self.train)
        env = _mapping(owner, "env", self.env)
        if env.get("dynamics", self.dynamics) != self.dynamics:
            raise ValueError(
                f"{owner}.env.dynamics ({env['dynamics']!r}) contradicts "
                f"dynamics ({self.dynamics!r}); give it once"
            )
        if env.get("task", self.task) != self.task:
            raise ValueError(
                f"{owner}.env.task ({env['task']!r}) contradicts task ({self.task!r}); give it once"
            )
        object.__setattr__(self, "env", {**env, "dynamics": self.dynamics, "task": self.task})
        overrides = _mapping(owner, "train_overrides", self.train_overrides)
        if "seed" in overrides:
            raise ValueError(f"{owner}.train_overrides.seed: the seeds come from --seeds")
        object.__setattr__(self, "train_overrides", overrides)
        object.__setattr__(self, "evaluations", self._evaluations(owner))
        object.__setattr__(self, "baselines", self._baselines(owner))

    def _evaluations(self, owner: str) -> tuple[Evaluation, ...]:
        items = self.evaluations
        if isinstance(items, (str, bytes, Mapping)) or not isinstance(items, Sequence):
            raise ValueError(f"{owner}.evaluations must be a list of {{label, env}} mappings")
        if not items:
            raise ValueError(f"{owner}.evaluations must not be empty (leave it out for one)")
        out = []
        for i, item in enumerate(items):
            if not isinstance(item, Evaluation):
                item = Evaluation(**_strict(f"{owner}.evaluations[{i}]", Evaluation, item))
            out.append(item)
        labels = [e.label for e in out]
        twice = sorted({x for x in labels if labels.count(x) > 1})
        if twice:
            raise ValueError(f"{owner}.evaluations: label(s) {', '.join(twice)} given twice")
        return tuple(out)

    def _baselines(self, owner: str) -> tuple[str, ...]:
        from agents import CONTROLLERS

        items = self.baselines
        if isinstance(items, (str, bytes)) or not isinstance(items, Sequence):
            raise ValueError(f"{owner}.baselines must be a list of policy names, got {items!r}")
        known = [*CONTROLLERS, "analytic", "simple"]
        for name in items:
            if name not in known:
                raise ValueError(
                    f"{owner}.baselines: unknown policy {name!r}; known: {', '.join(known)}"
                )
        if len(set(items)) != len(items):
            raise ValueError(f"{owner}.baselines names a policy twice: {list(items)}")
        if "learned" in items:
            raise ValueError(f"{owner}.baselines: 'learned' is the trained policy's name")
        return tuple(items)

    def train_config(self, seed: int, extra: Mapping[str, Any] | None = None) -> TrainConfig:
        """The training config of seed ``seed``: the ``train`` file, then
        ``train_overrides``, ``extra`` (e.g. the quick run's), the seed and ``env``."""
        data = merge_overrides(self.train_overrides, extra)
        data = merge_overrides(data, {"seed": seed, "env": self.env})
        return load_train_config(self.train, data)

    def eval_config(self, evaluation: Evaluation, tc: TrainConfig) -> SwarmConfig:
        """The env of ``evaluation``: the training env (``tc``) with its overrides on top."""
        return load_swarm_config(tc.env_config, merge_overrides(tc.env, evaluation.env))

    def check(self) -> None:
        """Build the training config and every evaluation config once (``ValueError``
        naming the entry where one is wrong)."""
        owner = f"entry {self.name!r}"
        try:
            tc = self.train_config(seed=0)
        except ValueError as err:
            raise ValueError(f"{owner}: train {self.train}: {err}") from None
        for ev in self.evaluations:
            try:
                self.eval_config(ev, tc)
            except ValueError as err:
                raise ValueError(f"{owner}: evaluation {ev.label!r}: env: {err}") from None


@dataclass(frozen=True)
class Matrix:
    """A loaded matrix: its ``path`` and its entries, in file order."""

    path: str
    entries: tuple[Entry, ...]

    @property
    def names(self) -> list[str]:
        return [e.name for e in self.entries]

    def select(self, names: Sequence[str] | None) -> list[Entry]:
        """The entries named ``names`` (all when None), in matrix order.

        Raises:
            ValueError: a name that no entry has (the known names are listed).
        """
        if not names:
            return list(self.entries)
        unknown = [n for n in names if n not in self.names]
        if unknown:
            raise ValueError(
                f"--only: no entry named {', '.join(unknown)}; entries: {', '.join(self.names)}"
            )
        return [e for e in self.entries if e.name in names]


def matrix_from_mapping(data: Mapping[str, Any], path: str = "<matrix>") -> Matrix:
    """Build and check a :class:`Matrix` from the mapping of a matrix file."""
    if not isinstance(data, Mapping):
        raise ValueError(f"matrix {path} must hold a mapping with the key 'entries'")
    unknown = [str(k) for k in data if k not in MATRIX_KEYS]
    if unknown:
        raise ValueError(
            f"matrix {path}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(MATRIX_KEYS)}"
        )
    items = data.get("entries")
    if not isinstance(items, list) or not items:
        raise ValueError(f"matrix {path}: 'entries' must be a non-empty list of entries")
    entries = []
    for i, item in enumerate(items):
        owner = f"matrix {path}: entries[{i}]"
        kwargs = _strict(owner, Entry, item)
        missing = [f.name for f in fields(Entry) if f.name not in kwargs and f.name in _REQUIRED]
        if missing:
            raise ValueError(f"{owner}: missing key(s) {', '.join(missing)}")
        try:
            entry = Entry(**kwargs)
        except ValueError as err:
            raise ValueError(f"matrix {path}: {err}") from None
        entry.check()
        entries.append(entry)
    names = [e.name for e in entries]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"matrix {path}: entry name(s) {', '.join(twice)} given twice")
    return Matrix(path=path, entries=tuple(entries))


_REQUIRED = ("name", "task", "dynamics", "train")


def load_matrix(path: str | Path = DEFAULT_MATRIX) -> Matrix:
    """Load and check the matrix file ``path``."""
    found = resolve_config_path(path, "benchmark", "matrix")
    return matrix_from_mapping(read_yaml_mapping(found, "matrix"), str(path))
